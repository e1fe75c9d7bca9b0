"""Newton's method for the section problem (mixed u-p, element pressures condensed).

Each iteration solves the symmetric tangent system with a sparse LDL^T (``linear_solver.py``:
``qdldl``, its symbolic analysis reused while the pattern stays; SuperLU if qdldl is missing),
then backtracks only to stay admissible (no inverted element, no negative axial stretch).
Converged when the Newton step is below ``tol`` in every non-dimensional unknown (displacement / R, lambda, k R), or a hundred times that while
contracting quadratically: the error left is then of the order of the step squared.
"""
from __future__ import annotations

import numpy as np

from ..continuation import Correction
from .linear_solver import LinearSolver
from .problem import SectionProblem

ARMIJO = 1e-4               # sufficient decrease of the potential, as a fraction of the slope
MIN_DESCENT_STEP = 1 / 64   # the descent test stops cutting here (admissibility does not)
ROUND_OFF = 1e-11           # potential differences below this (relative) are round-off
ENERGY_AGREEMENT = 1e-9    # the energy alone and the assembly's differ by round-off, far below this (relative)
ESCAPE_STEP = 1e-2          # the stable minimiser's step off a saddle (largest non-dimensional entry)


def _minimiser_step(linear: LinearSolver, K, g: np.ndarray, n: int, tol: float, minimise: bool,
                    stable_only: bool) -> tuple[np.ndarray, int | None, bool]:
    """Newton's step with the factorised tangent ``K``, made a minimiser's: (step, the tangent's
    negative pivots when ``stable_only`` asks for them, whether the tangent was shifted). The
    tangent's inertia is needed by the stable-only minimiser at every iteration (else only at the
    end); where it is indefinite there, Newton's own step is not needed (not solved for)."""
    negative = linear.negative_pivots() if stable_only else None
    if stable_only and negative:
        # the tangent is indefinite here: a Newton step may head for a saddle, so step with the
        # tangent shifted until positive definite (it descends, and leaves along the negative
        # directions); converged only where the unshifted tangent is positive definite
        dz, _ = linear.solve_positive_definite(K, -g)
        if np.max(np.abs(dz[:n])) < 100 * tol:
            # at (or next to) a saddle the shifted step vanishes with the gradient: leave it
            # downhill along the tangent's most negative direction of curvature
            v = linear.negative_curvature_direction()
            dz = dz + ESCAPE_STEP * (v if float(g @ v) <= 0 else -v)
        return dz, negative, True
    dz = linear.solve_factored(K, -g)
    if minimise and float(g @ dz) >= 0:
        dz = _descent_direction(K, g)
    return dz, negative, False


def newton(problem: SectionProblem, x0: np.ndarray, pressures: np.ndarray, tol: float = 1e-7,
           max_iterations: int = 12, linear: LinearSolver | None = None, constraint=None,
           line_search: bool = False, minimise: bool = False, stable_only: bool = False) -> Correction:
    """``constraint`` (optional) fixes some unknowns as functions of the others (``moment.HeldSection``):
    ``reduce(x, g, K) -> (g, K)`` in the free unknowns, ``expand(x, dz) -> dz`` for the full step, and
    ``project(x) -> x`` onto the constraint. ``line_search``: backtrack on the potential too (Armijo),
    not only to stay admissible. ``minimise``: a line search, a tangent shifted towards positive
    definite where the Newton step is not a descent direction, and no test for wandering: the
    potential's minimiser, which finds the stable state a snap lands in (slow: use it there only).
    ``stable_only``: a minimiser that may not end at a saddle: where the tangent is indefinite (its
    LDL^T has negative pivots) it steps with the tangent shifted until positive definite, and it
    converges only where the unshifted tangent is positive definite (slower: ``leave_saddle``).
    A converged state's ``info["negative_directions"]`` is the last tangent's inertia (qdldl)."""
    minimise = minimise or stable_only
    line_search = line_search or minimise
    linear = LinearSolver() if linear is None else linear
    x = x0.copy()
    n = problem.n
    steps: list[float] = []
    assembled = None                 # the assembly at the accepted trial point, when it was made
    for it in range(1, max_iterations + 1):
        E, g, K, aux = problem.assemble(x, pressures) if assembled is None else assembled
        if not np.isfinite(E):
            return Correction(x, False, it, "inverted element, negative axial stretch or crossed walls in the "
                                            "predictor", info={"inadmissible_start": True})
        if constraint is not None:
            g, K = constraint.reduce(x, g, K)
        try:
            linear.factor(K)
        except (RuntimeError, ValueError) as exc:  # singular factor
            return Correction(x, False, it, f"singular tangent ({exc})")
        dz, negative, shifted = _minimiser_step(linear, K, g, n, tol, minimise, stable_only)
        if constraint is not None:
            dz = constraint.expand(x, dz)
        dx = np.concatenate([dz[:n], problem.pressure_update(dz[:n], aux)])
        if not np.all(np.isfinite(dx)):
            return Correction(x, False, it, "singular tangent")
        # Backtrack to stay admissible (no inverted element, positive axial stretch, walls
        # apart), and with ``line_search`` on the potential (Armijo): with the element pressures
        # condensed the potential is minimised, and near the contact barrier full steps can
        # overshoot (Newton cycled at the creased lumen shoulders of fine meshes without it).
        slope = float(g @ dz) if line_search else 0.0
        step = float(np.max(np.abs(dz[:n])))
        # far from convergence the full step is assembled at once (the next iteration needs it);
        # near it only its energy (the step may be the last)
        searched = _line_search(problem, x, dx, pressures, constraint, E, slope, shifted, step >= 100 * tol)
        if searched is None:
            return Correction(x, False, it, "every step length inverts an element")
        alpha, trial, assembled = searched
        x = trial
        # Converged when the step is below tol, or below 100 tol while shrinking 20-fold per
        # iteration (quadratic convergence observed): what is left is then below ~5 tol.
        if alpha == 1.0 and not shifted and (step < tol or (steps and step < 100 * tol and step < 0.05 * steps[-1])):
            # the inertia of the last tangent (a step below tol before x): 0 at a stable state
            if negative is None:
                negative = linear.negative_pivots()
            return Correction(x, True, it, info={} if negative is None else {"negative_directions": negative})
        # Newton converges quadratically near a solution; a step that has not halved in two
        # iterations after the fourth means it is wandering (a limit point or a bifurcation).
        steps.append(step)
        if not minimise and it >= 5 and step > 0.5 * steps[-3]:
            return Correction(x, False, it, f"Newton is not converging (step {step:.2e} after {it} iterations)")
    return Correction(x, False, max_iterations, f"no convergence in {max_iterations} Newton iterations "
                                                 f"(last step {steps[-1]:.2e})")


def _line_search(problem: SectionProblem, x, dx, pressures, constraint, E: float, slope: float, shifted: bool,
                 full: bool):
    """(step length, trial state, its assembly if made at the full step) of the first of 1, 1/2, ...
    that is admissible and, where the step must descend (``slope`` < 0, or a ``shifted`` tangent's),
    meets Armijo's test (down to MIN_DESCENT_STEP); None if all 12 lengths are inadmissible.
    ``full``: the full step is assembled at once (the next iteration needs it); where Armijo may
    reject it, its energy is looked at first, so a rejected full step costs no assembly (a trial
    only rejected that way when its energy is clearly above the bound: the decisions are those the
    assembly's energy would make)."""
    tolerance = ROUND_OFF * (1.0 + abs(E))
    must_descend = not (slope >= 0 and not shifted)
    alpha = 1.0
    for _ in range(12):
        trial = x + alpha * dx if constraint is None else constraint.project(x + alpha * dx)
        bound = E + ARMIJO * alpha * slope + tolerance
        assembled = None
        if full and alpha == 1.0:
            if must_descend and not problem.energy(trial, pressures) <= bound + ENERGY_AGREEMENT * (1.0 + abs(E)):
                e_trial = np.inf        # rejected without its assembly
            else:
                assembled = problem.assemble(trial, pressures)
                e_trial = assembled[0]
        else:
            e_trial = problem.energy(trial, pressures)
        if np.isfinite(e_trial) and (not must_descend or alpha <= MIN_DESCENT_STEP or e_trial <= bound):
            return alpha, trial, assembled if alpha == 1.0 else None
        alpha *= 0.5
    return None


def unstable_directions(problem: SectionProblem, x: np.ndarray, pressures: np.ndarray) -> int:
    """The tangent's negative eigenvalues at ``x`` (pressures / c1), counted as the negative pivots
    of its LDL^T (Sylvester's law of inertia): 0 at a stable equilibrium of the pressure-controlled
    problem, more on an unstable branch (past a limit point or a bifurcation)."""
    K = problem.assemble(x, pressures)[2]
    linear = LinearSolver()
    if not linear._have_qdldl:
        return int(problem.smallest_tangent_eigenvalue(x, pressures) < 0)
    linear.factor(K)
    return linear.negative_pivots()


def _descent_direction(K, g) -> np.ndarray:
    """A step -(K + sigma I)^-1 g that descends (g . dz < 0), sigma growing tenfold from 1e-3 of
    the tangent's largest diagonal entry; steepest descent if none does."""
    diag = np.flatnonzero(np.repeat(np.arange(K.shape[0]), np.diff(K.indptr)) == K.indices)
    scale = float(np.max(np.abs(K.data[diag])))
    sigma = 1e-3 * scale
    for _ in range(8):
        data = K.data.copy()
        data[diag] += sigma
        try:
            dz = LinearSolver().solve(K.__class__((data, K.indices, K.indptr), shape=K.shape), -g)
        except (RuntimeError, ValueError):
            dz = None
        if dz is not None and np.all(np.isfinite(dz)) and float(g @ dz) < 0:
            return dz
        sigma *= 10
    return -g / scale


class PathStep:
    """One pseudo-arc-length step of the section's equilibrium path in (x, mu), channel pressures
    p = base + mu d (``direction`` d; p, base and mu in units of c1): the corrector of
    ``continuation.arc_length``.

    The path's tangent (dx/dmu = K^-1 b, b = d(d.V)/dx) is kept with its orientation (the load
    grows at the start). The arc norm is |(dx / s, dmu)| with ``scale`` s a typical |dx/dmu| of the
    path (the mean rate from rest: near a limit point the local rate is unbounded), so state and
    load share a step and the step is in units of mu. Each Newton iteration solves the
    bordered system
        [K       -b ] [dx ]     [g                                     ]
        [t_x / s  t_m] [dmu] = - [t_x . (x - x0) / s + t_m (mu - mu0) - ds]
    by block elimination with one factorisation of K (two solves), backtracking to stay admissible."""

    def __init__(self, problem: SectionProblem, direction, scale: float, base=None, tol: float = 1e-6,
                 max_iterations: int = 12, linear: LinearSolver | None = None, towards=None):
        """``towards``: (dx (n,), dmu), a step along the path so far (the ramp's last secant): the
        first tangent is oriented along it (near the limit point the load's share of the tangent is
        too small to say which way is forward)."""
        self.problem, self.d = problem, np.asarray(direction, dtype=float)
        self.base = np.zeros_like(self.d) if base is None else np.asarray(base, dtype=float)
        self.tol, self.max_iterations = tol, max_iterations
        self.linear = LinearSolver() if linear is None else linear
        self.scale = float(scale)
        # (t_x (n,), t_mu) of the last converged state, unit in the arc norm (only its direction matters)
        self.tangent = None if towards is None else (np.asarray(towards[0]) / self.scale, float(towards[1]))

    def _tangent(self, x, mu):
        p = self.problem
        K = p.assemble(x, self.base + mu * self.d)[2]
        _, b = p.load_vector(x, self.d)
        w = self.linear.solve(K, b)                     # dx/dmu
        t = np.concatenate([w / self.scale, [1.0]])
        t /= np.linalg.norm(t)
        reference = np.append(*self.tangent) if self.tangent is not None else np.eye(len(t))[-1]
        if t @ reference < 0:
            t = -t                                      # keep walking the same way along the path
        return t[:-1], float(t[-1])

    def __call__(self, x0, mu0: float, previous, ds: float) -> Correction:
        p, n = self.problem, self.problem.n
        tx, tm = self._tangent(x0, mu0)
        s = self.scale
        x = x0.copy()
        x[:n] += ds * s * tx
        mu = mu0 + ds * tm
        for it in range(1, self.max_iterations + 1):
            E, g, K, aux = p.assemble(x, self.base + mu * self.d)
            if not np.isfinite(E):
                return Correction(x0, False, it, "inadmissible predictor on the arc")
            _, b = p.load_vector(x, self.d)
            try:
                self.linear.factor(K)
                a = self.linear.solve_factored(K, -g)
                w = self.linear.solve_factored(K, b)
            except (RuntimeError, ValueError) as exc:
                return Correction(x0, False, it, f"singular tangent ({exc})")
            r = tx @ (x[:n] - x0[:n]) / s + tm * (mu - mu0) - ds
            dmu = (-r - tx @ a / s) / (tx @ w / s + tm)
            dz = a + dmu * w
            dx = np.concatenate([dz, p.pressure_update(dz, aux)])
            if not np.all(np.isfinite(dx)):
                return Correction(x0, False, it, "singular bordered system")
            alpha = 1.0
            for _ in range(12):
                if np.isfinite(p.energy(x + alpha * dx, self.base + (mu + alpha * dmu) * self.d)):
                    break
                alpha *= 0.5
            else:
                return Correction(x0, False, it, "every step length inverts an element")
            x, mu = x + alpha * dx, mu + alpha * dmu
            if alpha == 1.0 and max(float(np.max(np.abs(dz))), abs(dmu)) < self.tol:
                self.tangent = (tx, tm)
                return Correction(x, True, it, info={"load": mu})
        return Correction(x0, False, self.max_iterations, "no convergence on the arc")


def leave_saddle(problem: SectionProblem, x: np.ndarray, pressures: np.ndarray, tol: float = 1e-7,
                 max_iterations: int = 40, linear: LinearSolver | None = None, size: float = 1e-2):
    """The stable state next to the saddle ``x`` (an equilibrium at ``pressures`` / c1 whose tangent
    has negative directions): step off it by ``size`` (largest non-dimensional entry) along its most
    negative direction of curvature (``LinearSolver.negative_curvature_direction``), both ways,
    minimise the potential from each (``newton(stable_only=True)``, which converges only where the
    tangent is positive definite) and keep the lower-energy state. Returns (Correction or None,
    the negative directions at ``x``); None when neither way reaches a stable state below the
    saddle's energy, or when ``x`` has no negative direction (count 0: it is stable itself)."""
    linear = LinearSolver() if linear is None else linear
    E0, _, K, _ = problem.assemble(x, pressures)
    linear.factor(K)
    count = linear.negative_pivots()
    if not count:
        return None, count
    v = linear.negative_curvature_direction()
    n = problem.n
    best, best_energy = None, E0 - ROUND_OFF * (1.0 + abs(E0))
    for sign in (1.0, -1.0):
        a = size
        for _ in range(12):          # stay admissible (walls apart, no inverted element)
            trial = x.copy()
            trial[:n] += sign * a * v
            if np.isfinite(problem.energy(trial, pressures)):
                break
            a *= 0.5
        else:
            continue
        corr = newton(problem, trial, pressures, tol=tol, max_iterations=max_iterations, linear=linear,
                      stable_only=True)
        if corr.converged and corr.info.get("negative_directions") == 0:
            energy = problem.energy(corr.state, pressures)
            if energy < best_energy:
                best, best_energy = corr, energy
    if best is not None:
        best.info.update({"left_saddle": count, "energy_drop": float(E0 - best_energy)})
    return best, count
