"""Newton's method for the section problem (mixed u-p, element pressures condensed).

Each iteration solves the symmetric tangent system with a sparse LDL^T (``qdldl``, whose
symbolic analysis is reused since the pattern never changes; SuperLU if qdldl is missing),
then backtracks only to stay admissible (no inverted element, no negative axial stretch).
Converged when the Newton step is below ``tol`` in every non-dimensional unknown (displacement / R, lambda, k R), or a hundred times that while
contracting quadratically: the error left is then of the order of the step squared.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..continuation import Correction
from .problem import SectionProblem


class LinearSolver:
    """Sparse symmetric solves with a fixed pattern: factor once symbolically, then refactor."""

    def __init__(self):
        self._ldl = None
        try:
            import qdldl  # noqa: F401
            self._have_qdldl = True
        except ImportError:
            self._have_qdldl = False

    def solve(self, K, rhs: np.ndarray) -> np.ndarray:
        """Solve K z = rhs for a symmetric CSR matrix K whose pattern is the same at every call."""
        if self._have_qdldl:
            import qdldl

            if self._ldl is None:
                n = K.shape[0]
                rows = np.repeat(np.arange(n), np.diff(K.indptr))
                self._lower = K.indices <= rows
                self._upper_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[self._lower], minlength=n))])
            # K symmetric: the CSR arrays of its lower triangle are the CSC arrays of its upper one.
            upper = sp.csc_matrix((K.data[self._lower], K.indices[self._lower], self._upper_indptr),
                                  shape=K.shape)
            if self._ldl is None:
                self._ldl = qdldl.Solver(upper, upper=True)
            else:
                self._ldl.update(upper, upper=True)
            z = self._ldl.solve(rhs)
            z += self._ldl.solve(rhs - K @ z)  # one step of iterative refinement (no pivoting)
            return z
        # A symmetric ordering without row pivoting keeps SuperLU's factor sparse.
        return spla.splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                         options={"SymmetricMode": True}).solve(rhs)


def newton(problem: SectionProblem, x0: np.ndarray, pressures: np.ndarray, tol: float = 1e-7,
           max_iterations: int = 12, linear: LinearSolver | None = None, constraint=None) -> Correction:
    """``constraint`` (optional) fixes some unknowns as functions of the others (``moment.HeldSection``):
    ``reduce(x, g, K) -> (g, K)`` in the free unknowns, ``expand(x, dz) -> dz`` for the full step, and
    ``project(x) -> x`` onto the constraint."""
    linear = LinearSolver() if linear is None else linear
    x = x0.copy()
    n = problem.n
    steps: list[float] = []
    for it in range(1, max_iterations + 1):
        E, g, K, aux = problem.assemble(x, pressures)
        if not np.isfinite(E):
            return Correction(x, False, it, "inverted element or negative axial stretch in the predictor")
        if constraint is not None:
            g, K = constraint.reduce(x, g, K)
        try:
            dz = linear.solve(K, -g)
        except (RuntimeError, ValueError) as exc:  # singular factor
            return Correction(x, False, it, f"singular tangent ({exc})")
        if constraint is not None:
            dz = constraint.expand(x, dz)
        dx = np.concatenate([dz[:n], problem.pressure_update(dz[:n], aux)])
        if not np.all(np.isfinite(dx)):
            return Correction(x, False, it, "singular tangent")
        # The mixed (u, p) problem is a saddle point, so no descent test: backtrack only to
        # stay admissible (no inverted element, positive axial stretch everywhere).
        alpha = 1.0
        for _ in range(12):
            trial = x + alpha * dx if constraint is None else constraint.project(x + alpha * dx)
            if np.isfinite(problem.energy(trial, pressures)):
                break
            alpha *= 0.5
        else:
            return Correction(x, False, it, "every step length inverts an element")
        x = trial
        step = float(np.max(np.abs(dz[:n])))
        # Converged when the step is below tol, or below 100 tol while shrinking 20-fold per
        # iteration (quadratic convergence observed): what is left is then below ~5 tol.
        if alpha == 1.0 and (step < tol or (steps and step < 100 * tol and step < 0.05 * steps[-1])):
            return Correction(x, True, it)
        # Newton converges quadratically near a solution; a step that has not halved in two
        # iterations after the fourth means it is wandering (a limit point or a bifurcation).
        steps.append(step)
        if it >= 5 and step > 0.5 * steps[-3]:
            return Correction(x, False, it, f"Newton is not converging (step {step:.2e} after {it} iterations)")
    return Correction(x, False, max_iterations, f"no convergence in {max_iterations} Newton iterations "
                                                 f"(last step {steps[-1]:.2e})")
