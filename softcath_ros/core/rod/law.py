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
        no peak before the table ends, when |M| falls from kappa = 0 on, or for a linear law."""
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
    valid at that pressure. No extrapolation: outside the table it refuses."""

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

    def _interp_p(self, values: np.ndarray, p: float) -> np.ndarray:
        """values (K, P) -> (K,) at pressure p: cubic Lagrange on 4 neighbours, else linear."""
        ps = self.table.pressures[:self._last + 1]
        j = int(np.clip(np.searchsorted(ps, p, side="right") - 1, 0, len(ps) - 2))
        t = (p - ps[j]) / (ps[j + 1] - ps[j])
        if t < 1e-9 or t > 1 - 1e-9:     # on a grid pressure: its own column (its own kappa range)
            return values[:, j + int(round(t))].copy()
        lin = (1 - t) * values[:, j] + t * values[:, j + 1]
        lo, hi = j - 1, j + 2
        if lo < 0 or hi >= len(ps):
            return lin
        x = ps[lo:hi + 1]
        w = np.array([np.prod([(p - x[m]) / (x[n] - x[m]) for m in range(4) if m != n]) for n in range(4)])
        cub = values[:, lo:hi + 1] @ w
        return np.where(np.isfinite(cub), cub, lin)

    def at(self, pressure: float, extra_stiffness: float = 0.0) -> LawSlice:
        lo_p, hi_p = self.pressure_range
        if not lo_p <= pressure <= hi_p:
            raise LawRangeError(
                f"{self.source}: p = {pressure / PA_PER_BAR:.4f} bar is outside the moment-curvature table "
                f"({lo_p / PA_PER_BAR:.4f}..{hi_p / PA_PER_BAR:.4f} bar; beyond it the held section does not "
                "converge)")
        m = self._interp_p(self.table.moment, pressure)
        lam = self._interp_p(self.table.stretch, pressure)
        a, b = self._block(np.isfinite(m) & np.isfinite(lam), self._i0)
        if b - a < 4:
            raise LawRangeError(f"{self.source}: at p = {pressure / PA_PER_BAR:.4f} bar fewer than 4 curvatures "
                                "of the table are valid")
        # imported here: scipy.interpolate costs every node that imports the rod (the simulated rig) 0.5 s
        from scipy.interpolate import CubicSpline

        ks = self.table.curvatures[a:b]
        spline = CubicSpline(ks, m[a:b] + extra_stiffness * ks, extrapolate=True)
        stretch = CubicSpline(ks, lam[a:b], extrapolate=True)
        return LawSlice(pressure, float(ks[0]), float(ks[-1]), spline, spline.derivative(), stretch, self.source)
