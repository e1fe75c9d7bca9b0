"""The section held at a prescribed curvature: the moment it carries, M(kappa, p).

The free section (``SectionModel``) minimises the potential over curvature and stretch, so
its moment is zero. A rod needs the moment at *other* curvatures (a blocked tip holds the
body nearly straight under pressure). Here the section's rotation rate per unit reference
length, kappa0 = lambda k (the tip angle is kappa0 l, independent of which line is the
backbone), is prescribed along a unit direction e in the section plane, and the in-plane
displacements and the stretch lambda stay free; with k = kappa0 e / lambda the Newton
system is the problem's own, reduced by the chain rule dk/dlambda = -k / lambda.

Keeping kappa0 (not k) fixed while lambda moves makes the axial force conjugate to lambda
zero, so the law is the zero-axial-force law and its moment does not depend on the
reference line. The moment is the generalised reaction (envelope theorem)
    M = dPi*/dkappa0 = (e . dPi/dk) / lambda     (N m; Pi per unit reference length),
zero at the free curvature, E I kappa for small kappa at p = 0, and negative at kappa = 0
under pressure: -M(0, p) is the blocking moment the pressure exerts on a straight body.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..continuation import Correction, StepControl, ramp
from ..design import Design
from ..errors import ModelError
from ..units import describe_pressure
from .problem import SectionProblem
from .settings import SectionSettings
from .linear_solver import LinearSolver
from .solver import newton


STABLE_ITERATIONS = 200  # the held section's minimiser (where Newton reaches a saddle, or stalls on a snap): 60
                         # ended implemented_5mm's D/20 bent-back branch at 0.325 bar inside the lumen's fold,
                         # before the moment's peak, so the rod knew no base capacity there


@dataclass
class HeldResult:
    moment: float          # N m about the direction e (positive: resists bending towards e)
    stretch: float         # lambda of the backbone, dimensionless
    channel_area: np.ndarray  # m^2 per channel


class HeldSection:
    """Newton on the section with its rotation rate kappa0 (1/m) prescribed along ``direction``."""

    def __init__(self, problem: SectionProblem, direction, tol: float = 1e-6, max_newton: int = 12,
                 min_hole_gap: float = 0.05):
        e = np.asarray(direction, dtype=float)
        if e.shape != (2,) or not np.isfinite(e).all() or np.hypot(*e) == 0:
            raise ValueError(f"bending direction {direction!r} must be a non-zero 2-vector")
        self.problem = problem
        self.e = e / np.hypot(*e)
        self.tol, self.max_newton, self.min_hole_gap = tol, max_newton, min_hole_gap
        self.linear = LinearSolver()
        p = problem
        self.i_lam, self.i_k = p.n_u, p.n_u + np.array([1, 2])
        # CSR positions of the entries in the lambda column and the k rows/columns (the global
        # dofs share one sparsity pattern: every element and edge couples to all three).
        K0 = p.assemble(p.consistent_pressures(p.initial_state()), np.zeros(p.design.n_channels))[2]
        rows = np.repeat(np.arange(p.n), np.diff(K0.indptr))
        cols = K0.indices
        self._rows, self._cols = rows, cols
        self._col_lam = np.flatnonzero(cols == self.i_lam)
        is_k = np.isin(rows, self.i_k) | np.isin(cols, self.i_k)
        self._k_entries = is_k
        self._k_diag = is_k & (rows == cols)

    # ------------------------------------------------------------------ the constraint k = kappa0 e / lambda
    def set_curvature(self, x: np.ndarray, kappa0: float) -> np.ndarray:
        """x with k = kappa0 e / lambda (non-dimensional k R)."""
        out = x.copy()
        out[self.i_k] = kappa0 * self.problem.R * self.e / out[self.i_lam]
        return out

    def project(self, x: np.ndarray) -> np.ndarray:
        return self.set_curvature(x, self._kappa0)

    def reduce(self, x, g, K):
        """Gradient and tangent in (u, lambda) with k = kappa0 e / lambda (chain rule; same pattern)."""
        lam = x[self.i_lam]
        k = x[self.i_k]
        a = -k / lam                                  # dk/dlambda
        gk = g[self.i_k].copy()
        Kd = K[:, [self.i_lam, *self.i_k]].toarray()   # (n, 3): the three global columns (K symmetric)
        col = Kd[:, 0] + Kd[:, 1:] @ a                 # d(grad)/dlambda through lambda and k
        kll = (K[self.i_lam, self.i_lam] + 2 * a @ Kd[self.i_lam, 1:] + a @ Kd[self.i_k][:, 1:] @ a
               + gk @ (2 * k / lam**2))                # + g_k d2k/dlambda2
        data = K.data.copy()
        data[self._col_lam] = col[self._rows[self._col_lam]]
        row_lam = slice(K.indptr[self.i_lam], K.indptr[self.i_lam + 1])
        data[row_lam] = col[K.indices[row_lam]]
        data[self._col_lam[self._rows[self._col_lam] == self.i_lam]] = kll
        data[self._k_entries] = 0.0
        data[self._k_diag] = 1.0
        gr = g.copy()
        gr[self.i_lam] += gk @ a
        gr[self.i_k] = 0.0
        return gr, K.__class__((data, K.indices, K.indptr), shape=K.shape)

    def expand(self, x, dz):
        out = dz.copy()
        out[self.i_k] = -x[self.i_k] / x[self.i_lam] * dz[self.i_lam]
        return out

    def solve(self, x0: np.ndarray, kappa0: float, pressures: np.ndarray, snap: bool = False) -> Correction:
        """Stable equilibrium at rotation rate ``kappa0`` (1/m) and channel ``pressures`` (Pa).

        Newton first; where it reaches a saddle of the potential (an unstable held state: the
        lumen's shoulders folding), the potential's minimiser with kappa0 held (line search, the
        tangent shifted to positive definite where it is not; converged only where it is) finds the
        stable state. ``snap``: also where Newton stalls (past a limit point of the path: the stable
        state the section snaps to)."""
        p = self.problem
        self._kappa0 = float(kappa0)
        load = np.asarray(pressures, dtype=float) / p.c_ref
        guess = self.set_curvature(x0, kappa0)
        corr = newton(p, guess, load, tol=self.tol, max_iterations=self.max_newton, linear=self.linear,
                      constraint=self)
        stalled = snap and not corr.converged and not corr.info.get("inadmissible_start")
        if stalled or (corr.converged and corr.info.get("negative_directions")):
            corr = newton(p, guess, load, tol=self.tol, max_iterations=STABLE_ITERATIONS, linear=self.linear,
                          constraint=self, stable_only=True)
            turn = abs(p.frame_motion(corr.state)[1])
            if corr.converged and turn > np.pi / 2:
                # the gauge (one node pinned, one held on its vertical) lets a far descent turn the
                # section over, where the held rate bends it the other way: not this state
                corr.converged = False
                corr.message = f"the minimiser turned the section over ({np.degrees(turn):.0f} deg)"
        if corr.converged:
            gaps = p.open_hole_gaps(corr.state)     # a filled lumen resists closing: not a stop
            crossed = p.crossed_walls(corr.state)
            if gaps.min() < self.min_hole_gap:
                corr.converged, corr.outside_domain = False, True
                corr.message = (f"the walls of a hole touch (gap {gaps.min():.1%} of its diameter); "
                                "self-contact is not modelled")
            elif crossed:
                corr.converged, corr.outside_domain = False, True
                corr.message = "the wall of a hole crosses itself; self-contact is not modelled"
        return corr

    def result(self, x: np.ndarray, pressures: np.ndarray) -> HeldResult:
        """The moment carried at a converged state (the reaction to the prescribed curvature)."""
        p = self.problem
        _, g, _, _ = p.assemble(x, np.asarray(pressures, dtype=float) / p.c_ref)
        lam = float(x[self.i_lam])
        # g is dPi/d(kR) in units c1 R^2: dPi/dk = c1 R^3 g_k (SI)
        m_vec = p.c_ref * p.R**3 * g[self.i_k] / lam
        lam_frame, _ = p.frame_state(x)
        return HeldResult(moment=float(self.e @ m_vec), stretch=float(lam_frame),
                          channel_area=p.channel_areas(x) * p.R**2)


@dataclass
class MomentTable:
    """M(kappa_i, s_j) on a grid; NaN where the section could not be solved."""

    curvatures: np.ndarray       # (K,) 1/m, rotation rate per unit reference length along e
    pressures: np.ndarray        # (P,) Pa, magnitudes along the pressure direction
    moment: np.ndarray           # (K, P) N m
    stretch: np.ndarray          # (K, P)
    messages: list[str]          # why branches stop early
    direction: np.ndarray | None = None           # (2,) unit bending direction e in the section
    pressure_direction: np.ndarray | None = None  # (C,) channel pressures per unit magnitude


def moment_table(held: HeldSection, curvatures, pressures, pressure_direction, control: StepControl,
                 on_point=None) -> MomentTable:
    """Solve the held section on the grid (``pressures`` ascending from 0, ``curvatures`` containing 0).

    The straight section is pressurised through the pressure grid (continuation in p); from each
    straight state the section is bent through the positive and the negative curvatures
    (continuation in kappa). A branch stops at the first point it cannot reach; the rest of it
    stays NaN, so the table's valid region is what one continuation path reaches, as on a bench."""
    ks = np.asarray(curvatures, dtype=float)
    ps = np.asarray(pressures, dtype=float)
    if ps[0] != 0 or np.any(np.diff(ps) <= 0):
        raise ValueError("pressures must ascend from 0")
    if not np.any(ks == 0) or np.any(np.diff(ks) <= 0):
        raise ValueError("curvatures must ascend and contain 0")
    pdir = np.asarray(pressure_direction, dtype=float)
    prob = held.problem
    moment = np.full((len(ks), len(ps)), np.nan)
    stretch = np.full((len(ks), len(ps)), np.nan)
    messages: list[str] = []
    i0 = int(np.flatnonzero(ks == 0)[0])
    rest = prob.consistent_pressures(prob.initial_state())
    # the pressure ramp follows the straight section's snaps (the lumen closing) as a bench does;
    # a curvature branch ends at its limit point (past it the law would jump)
    straight = ramp(lambda guess, t, prev: held.solve(guess, 0.0, t * pdir, snap=True), rest, ps[1:], control,
                    describe=describe_pressure)
    if not straight.converged:
        messages.append(f"held straight: {straight.message}")
    states = [rest] + [pt.state for pt in straight.points]
    k_scale = float(np.max(np.abs(ks))) or 1.0
    k_control = StepControl(initial_step=0.05, max_step=0.1, min_step=2e-4)
    for j, x0 in enumerate(states):
        pv = ps[j] * pdir
        r = held.result(x0, pv)
        moment[i0, j], stretch[i0, j] = r.moment, r.stretch
        for sign, idx in ((1.0, np.arange(i0 + 1, len(ks))), (-1.0, np.arange(i0 - 1, -1, -1))):
            if not len(idx):
                continue

            def corrector(guess, t, prev, sign=sign, pv=pv):
                return held.solve(guess, sign * t * k_scale, pv)

            res = ramp(corrector, x0, np.abs(ks[idx]) / k_scale, k_control,
                       describe=lambda t, sign=sign: f"kappa = {sign * t * k_scale:.4g} 1/m")
            for i, pt in zip(idx, res.points):
                r = held.result(pt.state, pv)
                moment[i, j], stretch[i, j] = r.moment, r.stretch
            if not res.converged:
                messages.append(f"{describe_pressure(ps[j])}: {res.message}")
        if on_point is not None:
            on_point()
    return MomentTable(curvatures=ks, pressures=ps, moment=moment, stretch=stretch, messages=messages,
                       direction=held.e.copy(), pressure_direction=pdir.copy())


def bending_direction(design: Design, pressure_direction) -> np.ndarray:
    """Unit vector the section bends towards when its channels are pressurised in proportion to
    ``pressure_direction``: away from their pressure-weighted centre."""
    w = np.asarray(pressure_direction, dtype=float)
    c = sum(wi * np.asarray(ch.center) for wi, ch in zip(w, design.channels))
    if np.hypot(*c) == 0:
        raise ModelError("model 'section': these channels pressurised together do not bend the section "
                         "(their pressure-weighted centre is on the axis); give a bending direction")
    return -c / np.hypot(*c)


def moment_curvature(problem: SectionProblem, settings: SectionSettings, pressures, curvatures, direction=None,
                     pressure_direction=None, progress: bool = False) -> MomentTable:
    """The moment (N m) the section carries when held at a curvature.

    ``curvatures`` (1/m, ascending, containing 0) are rotation rates per unit reference length
    (kappa = |k| lambda, so kappa l is the tip angle) along the unit ``direction`` (default: the
    bending direction of ``pressure_direction``); ``pressures`` (Pa, ascending from 0) are
    magnitudes along ``pressure_direction`` (default: all channels equally; one channel: [1]).
    Returns a ``MomentTable``: NaN where the held section could not be solved (``messages``
    say where and why). The free state of the section rung is where the moment is zero."""
    from tqdm import tqdm

    n = problem.design.n_channels
    pdir = np.ones(n) if pressure_direction is None else np.asarray(pressure_direction, float)
    if pdir.shape != (n,) or np.any(pdir < 0) or not np.any(pdir > 0):
        raise ModelError(f"model 'section': pressure_direction {pressure_direction!r} must be "
                         f"{n} non-negative weight(s), not all zero")
    e = bending_direction(problem.design, pdir) if direction is None else direction
    s = settings
    held = HeldSection(problem, e, tol=s.tol, max_newton=max(s.max_newton, 12), min_hole_gap=s.min_hole_gap)
    control = StepControl(initial_step=s.initial_step, max_step=s.max_step, min_step=s.min_step,
                          adaptive=s.adaptive, domain_step=s.contact_resolution)
    bar = tqdm(total=len(pressures), desc="section M(kappa, p)", unit="p", disable=not progress)
    try:
        return moment_table(held, curvatures, pressures, pdir, control, on_point=bar.update)
    finally:
        bar.close()
