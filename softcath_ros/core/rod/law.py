"""Moment-curvature laws M(kappa, p) for the rod: tabulated from the section rung, or linear.

kappa is the rotation rate of the cross-sections per unit reference length along the bending
direction e (so kappa l is the tip angle of a uniformly bent body), p the pressure magnitude
(Pa) along the law's pressure direction. ``law.at(p)`` gives a ``LawSlice``: M(kappa), its
slope, the stretch lambda(kappa) at zero axial force, and the kappa range it is valid on.
Outside the pressures or curvatures a law was built on it raises ``LawRangeError``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..continuation import OUTSIDE_MODEL
from ..errors import ModelError
from ..units import PA_PER_BAR


class LawRangeError(ModelError):
    """A pressure or curvature outside the range a moment-curvature law was built on."""

    stop_reason = OUTSIDE_MODEL


@dataclass
class LawSlice:
    """M(kappa) = law moment + extra_stiffness kappa at one pressure, on [kappa_lo, kappa_hi]."""

    pressure: float
    kappa_lo: float
    kappa_hi: float
    _moment: object            # callable kappa -> M (N m), with .derivative() for splines
    _slope: object
    _stretch: object
    source: str
    _linear_root: float | None = None   # free curvature of a linear law
    peak: tuple[float, float] | None = None   # (M, kappa): the bent-back peak interpolated between grid columns

    def moment(self, kappa):
        return self._moment(kappa)

    def slope(self, kappa):
        return self._slope(kappa)

    def stretch(self, kappa):
        return self._stretch(kappa)

    def stretch_slope(self, kappa):
        s = getattr(self._stretch, "derivative", None)
        return s()(kappa) if s is not None else np.zeros_like(np.asarray(kappa, dtype=float))

    def check(self, kappa) -> None:
        k = np.asarray(kappa, dtype=float)
        lo, hi = float(k.min()), float(k.max())
        if lo < self.kappa_lo - 1e-9 or hi > self.kappa_hi + 1e-9:
            raise LawRangeError(
                f"{self.source}: curvatures {lo:.4g}..{hi:.4g} 1/m at p = {self.pressure / PA_PER_BAR:.4f} bar "
                f"leave the moment-curvature table, valid there for {self.kappa_lo:.4g}..{self.kappa_hi:.4g} 1/m "
                "(the held section does not converge beyond: the lumen closes or Newton fails)")

    def limit_moment(self, n: int = 401) -> tuple[float, float]:
        """(M, kappa) with the largest |M| the section carries bent back (kappa in [kappa_lo, 0]).

        Bent back against the pressure (a blocked base), the section flattens and its moment
        saturates and then falls (section rung: at kappa ~ -50..-100 1/m); a rod whose base needs
        more than this moment kinks there, which the law cannot follow (it refuses beyond its table).
        So |M| / (tip lever arm) caps the blocking force the law can carry."""
        lo = max(self.kappa_lo, -1e6)
        k = np.linspace(lo, min(0.0, self.kappa_hi), n)
        m = np.asarray(self.moment(k), dtype=float)
        i = int(np.argmax(np.abs(m)))
        return float(m[i]), float(k[i])

    def limit_moment_if_peaked(self, n: int = 401, drop: float = 2e-3) -> tuple[float, float] | None:
        """The moment the section carries at most bent back, where that is a genuine peak: (M, kappa).

        Bent back against its pressure the held section's |M| rises, may dip where the lumen closes
        (a snap under a growing moment, after which the lumen's contact stiffens it again), and then
        falls (the section flattens; the held section soon stops converging). The limit is the
        largest |M| on the table's negative side if |M| falls by more than ``drop`` (relative)
        beyond it; otherwise, if |M| is still rising where the table ends, the first peak (before a
        dip), which the section is known to pass: a lower bound of its capacity. None when there is
        no peak before the table ends, when |M| falls from kappa = 0 on, or for a linear law. A slice
        between two grid pressures whose columns both peak has that peak interpolated (``peak``,
        ``TabulatedLaw``): it is the limit, even where the slice's range ends before |M| falls much."""
        if self.peak is not None:
            return self.peak
        if not np.isfinite(self.kappa_lo):
            return None
        k = np.linspace(min(0.0, self.kappa_hi), self.kappa_lo, n)
        m = np.abs(np.asarray(self.moment(k), dtype=float))
        i = int(np.argmax(m))
        if 0 < i and m[i:].min() < m[i] * (1 - drop):
            return float(self.moment(k[i])), float(k[i])
        fell = np.flatnonzero(m < np.maximum.accumulate(m) * (1 - drop))
        if not len(fell):
            return None
        i = int(np.argmax(m[:fell[0]]))
        return (float(self.moment(k[i])), float(k[i])) if i > 0 else None

    def snap_fold(self, n: int = 401) -> tuple[float, float, float] | None:
        """Where the bent-back section snaps before its limit: (kappa_fold, kappa_dip, kappa_lim).

        Bent back, |M| may peak first at kappa_fold, dip to kappa_dip (the lumen closing) and rise
        again to the limit at kappa_lim (``limit_moment_if_peaked``). A segment asked for more than
        |M(kappa_fold)| cannot stay on the inner branch (kappa_fold < kappa < 0): it snaps across the
        dip to the outer one (kappa_lim < kappa < kappa_dip), where the lumen's contact stiffens it.
        None when |M| rises without a dip up to the limit, or there is no limit."""
        limit = self.limit_moment_if_peaked(n)
        if limit is None:
            return None
        k_lim = limit[1]
        k = np.linspace(min(0.0, self.kappa_hi), k_lim, n)
        m = np.abs(np.asarray(self.moment(k), dtype=float))
        falls = np.flatnonzero(m < np.maximum.accumulate(m) * (1 - 1e-4))   # past interpolation noise
        if not len(falls):
            return None
        i_fold = int(np.argmax(m[:falls[0]]))
        i_dip = i_fold + int(np.argmin(m[i_fold:]))
        if i_dip == len(k) - 1:
            return None
        return float(k[i_fold]), float(k[i_dip]), float(k_lim)

    def outer_branch(self, n: int = 401) -> tuple[float, float] | None:
        """(kappa_start, kappa_lim): the outer branch, where bent back |M| rises with |kappa| up to
        the limit: from the dip (``snap_fold``), or, without a dip, from 0. None without a limit."""
        fold = self.snap_fold(n)
        if fold is not None:
            return fold[1], fold[2]
        limit = self.limit_moment_if_peaked(n)
        return None if limit is None else (min(0.0, self.kappa_hi), limit[1])

    def outer_branch_curvature(self, moment: float, n: int = 401,
                               branch: tuple[float, float] | None = None) -> float | None:
        """The curvature with this (bent-back) moment on the outer branch (``branch``, as
        ``outer_branch`` gives it; found here when not given). None without a limit or if |moment|
        is outside |M| there."""
        branch = self.outer_branch(n) if branch is None else branch
        if branch is None:
            return None
        k_start, k_lim = branch
        k = np.linspace(k_start, k_lim, n)
        m = np.abs(np.asarray(self.moment(k), dtype=float))
        target = abs(float(moment))
        if not m[0] <= target <= m[-1]:
            return None
        m = np.maximum.accumulate(m)       # monotone for the lookup (it is, to interpolation noise)
        return float(np.interp(target, m, k))

    def free_curvature(self) -> float | None:
        """The curvature with zero moment (the free body), None if it is outside the range."""
        roots = getattr(self._moment, "roots", None)
        if roots is not None:
            r = [float(x) for x in roots(extrapolate=False) if self.kappa_lo <= x <= self.kappa_hi]
            return min(r, key=abs) if r else None
        return self._linear_root


class LinearLaw:
    """M = EI (kappa - kappa_free(p)): a body of constant stiffness EI whose pressure acts as the end
    moment EI kappa_free(p) (the closed form exactly; any rung's free curvature to first order)."""

    def __init__(self, stiffness: float, free_curvature, pressure_range=(0.0, math.inf),
                 source: str = "linear law"):
        self.stiffness = float(stiffness)
        self._free = free_curvature
        self.pressure_range = tuple(float(v) for v in pressure_range)
        self.source = source

    def at(self, pressure: float, extra_stiffness: float = 0.0) -> LawSlice:
        lo, hi = self.pressure_range
        if not lo <= pressure <= hi:
            raise LawRangeError(f"{self.source}: p = {pressure / PA_PER_BAR:.4f} bar is outside "
                                f"{lo / PA_PER_BAR:.4f}..{hi / PA_PER_BAR:.4f} bar")
        ei, kf = self.stiffness, float(self._free(pressure))
        total = ei + extra_stiffness
        return LawSlice(pressure, -math.inf, math.inf,
                        lambda k: ei * (np.asarray(k) - kf) + extra_stiffness * np.asarray(k),
                        lambda k: np.full_like(np.asarray(k, dtype=float), total),
                        lambda k: np.ones_like(np.asarray(k, dtype=float)), self.source,
                        _linear_root=ei * kf / total if total > 0 else None)


class TabulatedLaw:
    """M(kappa, p) from a ``MomentTable`` (section rung): local cubic interpolation in p (4 grid
    pressures, linear where a neighbour is missing), a cubic spline in kappa over the curvatures
    valid at that pressure. No extrapolation: outside the table it refuses.

    Bent back (kappa < 0) between grid pressures p_j < p < p_j+1 whose columns both peak
    (``LawSlice.limit_moment_if_peaked`` on each column) every column n is read at the same fraction
    of its own peak's curvature, M_n(kappa kappa_pk,n / kappa_pk(p)), with kappa_pk(p) linear between
    the two columns' peaks: the peak (the moment the base hinge carries) moves continuously from one
    column's to the next one's and its moment is interpolated between theirs. Read at the same
    curvature, a column whose peak lies beyond where its neighbour's table ends (across the lumen's
    fold: -120 1/m at 0.30 bar, -45 at 0.325 bar on implemented_5mm D/20) leaves the pressures in
    between without a peak. Where either column has no peak (|M| still rising where its table ends,
    or falling from kappa = 0) none is invented: the columns are read at the same curvature."""

    def __init__(self, table, source: str = "section law"):
        self.table = table
        self.source = source
        ks, ps, M = table.curvatures, table.pressures, table.moment
        i0 = int(np.flatnonzero(ks == 0)[0])
        ok = np.isfinite(M[i0])
        # the law ends where the held-straight section stops or fewer than 4 curvatures remain
        blocks = [self._block(np.isfinite(M[:, j]), i0) for j in range(len(ps))]
        n_valid = np.array([hi - lo for lo, hi in blocks])
        good = ok & (n_valid >= 4)
        last = int(np.argmin(good)) - 1 if not good.all() else len(ps) - 1
        if last < 1:
            raise ModelError(f"{source}: the table has fewer than two usable pressures")
        self._i0 = i0
        self._last = last
        self.pressure_range = (float(ps[0]), float(ps[last]))
        self._splines: dict[int, tuple] = {}        # grid column -> (curvatures, moment, stretch splines)
        self._peaks: dict[tuple, float] = {}        # (grid column, extra stiffness) -> its peak's curvature

    @staticmethod
    def _block(valid: np.ndarray, i0: int) -> tuple[int, int]:
        """The contiguous run of True around index i0: [lo, hi)."""
        if not valid[i0]:
            return i0, i0
        lo = i0
        while lo > 0 and valid[lo - 1]:
            lo -= 1
        hi = i0 + 1
        while hi < len(valid) and valid[hi]:
            hi += 1
        return lo, hi

    def _column(self, j: int) -> tuple:
        """Grid column j: its valid curvatures and cubic splines of M and lambda on them."""
        if j not in self._splines:
            from scipy.interpolate import CubicSpline

            m, lam = self.table.moment[:, j], self.table.stretch[:, j]
            a, b = self._block(np.isfinite(m) & np.isfinite(lam), self._i0)
            ks = self.table.curvatures[a:b]
            self._splines[j] = (ks, CubicSpline(ks, m[a:b]), CubicSpline(ks, lam[a:b]))
        return self._splines[j]

    def _peak(self, j: int, extra_stiffness: float) -> float:
        """The curvature of grid column j's bent-back peak (with ``extra_stiffness``), NaN without one:
        as ``at`` finds it on its grid pressure."""
        key = (j, float(extra_stiffness))
        if key not in self._peaks:
            ks, ms, ls = self._column(j)
            extra = float(extra_stiffness)

            def moment(k):
                return ms(k) + extra * np.asarray(k)

            limit = LawSlice(float(self.table.pressures[j]), float(ks[0]), float(ks[-1]), moment, None, ls,
                             self.source).limit_moment_if_peaked()
            self._peaks[key] = math.nan if limit is None else limit[1]
        return self._peaks[key]

    def _weights(self, p: float):
        """(j, t, lo, w): p between grid pressures j and j + 1 at fraction t; the cubic Lagrange
        weights w on the 4 grid pressures from lo (None where a neighbour is missing)."""
        ps = self.table.pressures[:self._last + 1]
        j = int(np.clip(np.searchsorted(ps, p, side="right") - 1, 0, len(ps) - 2))
        t = (p - ps[j]) / (ps[j + 1] - ps[j])
        lo = j - 1
        if lo < 0 or j + 2 >= len(ps):
            return j, t, lo, None
        x = ps[lo:lo + 4]
        w = np.array([np.prod([(p - x[m]) / (x[n] - x[m]) for m in range(4) if m != n]) for n in range(4)])
        return j, t, lo, w

    @staticmethod
    def _combine(column, j: int, t: float, lo: int, w) -> np.ndarray:
        """Cubic over the 4 columns where all are finite, else linear between j and j + 1."""
        lin = (1 - t) * column(j) + t * column(j + 1)
        if w is None:
            return lin
        cub = np.column_stack([column(n) for n in range(lo, lo + 4)]) @ w
        return np.where(np.isfinite(cub), cub, lin)

    def _bent_back(self, kappa: np.ndarray, p: float, k_peak: float, extra_stiffness: float, which: int):
        """M (``which`` 1) or lambda (2) at the bent-back curvatures ``kappa``, each column read at the same
        fraction of its peak's curvature as kappa is of ``k_peak`` (NaN beyond a column's table or peak)."""
        def column(n: int) -> np.ndarray:
            scale = self._peak(n, extra_stiffness) / k_peak
            if not np.isfinite(scale):
                return np.full(len(kappa), np.nan)
            col = self._column(n)
            k = kappa * scale
            return np.where(k >= col[0][0] * (1 + 1e-9), col[which](k), np.nan)

        return self._combine(column, *self._weights(p))

    def at(self, pressure: float, extra_stiffness: float = 0.0) -> LawSlice:
        lo_p, hi_p = self.pressure_range
        if not lo_p <= pressure <= hi_p:
            raise LawRangeError(
                f"{self.source}: p = {pressure / PA_PER_BAR:.4f} bar is outside the moment-curvature table "
                f"({lo_p / PA_PER_BAR:.4f}..{hi_p / PA_PER_BAR:.4f} bar; beyond it the held section does not "
                "converge)")
        ks = self.table.curvatures
        j, t, lo, w = self._weights(pressure)
        if t < 1e-9 or t > 1 - 1e-9:     # on a grid pressure: its own column (its own kappa range)
            n = j + int(round(t))
            m, lam = self.table.moment[:, n].copy(), self.table.stretch[:, n].copy()
            k_peak = math.nan
        else:
            m = self._combine(lambda n: self.table.moment[:, n], j, t, lo, w)
            lam = self._combine(lambda n: self.table.stretch[:, n], j, t, lo, w)
            k_peak = (1 - t) * self._peak(j, extra_stiffness) + t * self._peak(j + 1, extra_stiffness)
        if np.isfinite(k_peak):
            # bent back at the fraction of the peak; to where the first of the two columns ends there
            k_end = max(self._column(n)[0][0] * k_peak / self._peak(n, extra_stiffness) for n in (j, j + 1))
            neg = ks[(ks < 0) & (ks > k_end + 0.25 * (ks[1] - ks[0]))]
            ks = np.concatenate([[k_end], neg, ks[ks >= 0]])
            m = np.concatenate([self._bent_back(ks[:len(neg) + 1], pressure, k_peak, extra_stiffness, 1),
                                m[self.table.curvatures >= 0]])
            lam = np.concatenate([self._bent_back(ks[:len(neg) + 1], pressure, k_peak, extra_stiffness, 2),
                                  lam[self.table.curvatures >= 0]])
        i0 = int(np.flatnonzero(ks == 0)[0])
        a, b = self._block(np.isfinite(m) & np.isfinite(lam), i0)
        if b - a < 4:
            raise LawRangeError(f"{self.source}: at p = {pressure / PA_PER_BAR:.4f} bar fewer than 4 curvatures "
                                "of the table are valid")
        # imported here: scipy.interpolate costs every node that imports the rod (the simulated rig) 0.5 s
        from scipy.interpolate import CubicSpline

        ks = ks[a:b]
        spline = CubicSpline(ks, m[a:b] + extra_stiffness * ks, extrapolate=True)
        stretch = CubicSpline(ks, lam[a:b], extrapolate=True)
        peak = None
        if np.isfinite(k_peak) and ks[0] <= k_peak:
            peak = (float(spline(k_peak)), float(k_peak))
        return LawSlice(pressure, float(ks[0]), float(ks[-1]), spline, spline.derivative(), stretch, self.source,
                        peak=peak)
