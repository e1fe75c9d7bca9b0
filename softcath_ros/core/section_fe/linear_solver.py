"""Sparse symmetric factorisations of the section problem's tangent: LDL^T (``qdldl``) whose
symbolic analysis is kept while the pattern of non-zeros stays the same, its inertia (negative
pivots), a direction of negative curvature, and shifted factors that are positive definite
(SuperLU if qdldl is missing: solves only)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

UNION_SLACK = 0.1           # the factorised pattern may keep this fraction more entries than the tangent's non-zeros


class LinearSolver:
    """Sparse symmetric solves: ``factor(K)`` then ``solve_factored(K, rhs)`` (or ``solve`` for both),
    a symbolic factor kept while the pattern of non-zeros stays the same, refactored numerically.

    The problem's tangent has a fixed pattern that reserves every pair of wall nodes of a hole for
    self-contact (``terms/contact.py``), but only the pairs within the barrier's range are non-zero:
    the entries that are exactly zero are left out of the factor (keeping them triples its fill and
    costs ten times the time), and the symbolic analysis is redone when that set changes."""

    def __init__(self):
        self._ldl = None
        self._layout = None           # K's pattern: (indptr, indices, its upper entries, which of them are
                                      # diagonal, their rows, their columns)
        self._kept = None             # the factorised pattern: (kept upper entries, CSC indices, CSC indptr)
        self._shifted = None          # the factor of shifted tangents (solve_positive_definite)
        self._diagonal = None         # (indptr, indices, positions of K's diagonal entries in its data)
        self._negative = None         # the last factor's negative pivots, once counted
        try:
            import qdldl  # noqa: F401
            self._have_qdldl = True
        except ImportError:
            self._have_qdldl = False

    def _layout_of(self, K) -> tuple[tuple, bool]:
        """K's pattern's upper triangle (computed once per pattern), and whether it is the last one's."""
        lay = self._layout
        if lay is not None and (lay[0] is K.indptr and lay[1] is K.indices or (
                len(lay[1]) == len(K.indices) and np.array_equal(lay[0], K.indptr)
                and np.array_equal(lay[1], K.indices))):
            return lay, True
        rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
        up = np.flatnonzero(K.indices <= rows)
        self._layout = (K.indptr, K.indices, up, K.indices[up] == rows[up], rows[up], K.indices[up])
        return self._layout, False

    def _upper(self, K):
        """K's upper triangle without its zero entries (diagonal kept) as CSC arrays, and whether
        its pattern is the one last factorised (then the symbolic factor is reused).

        The entries kept are those of the last factorised pattern as well, as long as they are at
        most UNION_SLACK more than K's own: contact pairs entering and leaving the barrier's range
        then reuse one symbolic analysis instead of redoing it at almost every iteration."""
        (_, _, up, diagonal, rows, cols), same_layout = self._layout_of(K)
        data = K.data[up]
        keep = (data != 0) | diagonal
        kept = self._kept if same_layout else None
        same = False
        if kept is not None:
            union = keep | kept[0]
            if np.count_nonzero(union) <= (1 + UNION_SLACK) * np.count_nonzero(keep):
                keep, same = union, np.array_equal(union, kept[0])
        if same:
            indices, indptr = kept[1], kept[2]
        else:
            # K symmetric: the CSR arrays of its lower triangle are the CSC arrays of its upper one.
            indices = cols[keep]
            indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=K.shape[0]))])
            self._kept = (keep, indices, indptr)
        return sp.csc_matrix((data[keep], indices, indptr), shape=K.shape), same

    def _diagonal_of(self, K) -> np.ndarray:
        """Positions of K's diagonal entries in its data (computed once per pattern)."""
        d = self._diagonal
        if d is None or not (d[0] is K.indptr and d[1] is K.indices):
            rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
            self._diagonal = d = (K.indptr, K.indices, np.flatnonzero(rows == K.indices))
        return d[2]

    def factor(self, K) -> None:
        """Factorise the symmetric CSR matrix K for ``solve_factored`` (and, with qdldl, its inertia)."""
        if self._have_qdldl:
            import qdldl

            upper, same = self._upper(K)
            if self._ldl is None or not same:
                self._ldl = qdldl.Solver(upper, upper=True)
            else:
                self._ldl.update(upper, upper=True)
            self._negative = None
            return
        # A symmetric ordering without row pivoting keeps SuperLU's factor sparse.
        K = K.copy()
        K.eliminate_zeros()
        self._lu = spla.splu(K.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                             options={"SymmetricMode": True})

    def solve_factored(self, K, rhs: np.ndarray) -> np.ndarray:
        """Solve K z = rhs with K's factor (``factor(K)`` the last call)."""
        if not self._have_qdldl:
            return self._lu.solve(rhs)
        z = self._ldl.solve(rhs)
        z += self._ldl.solve(rhs - K @ z)  # one step of iterative refinement (no pivoting)
        return z

    def solve(self, K, rhs: np.ndarray) -> np.ndarray:
        """Solve K z = rhs for a symmetric CSR matrix K."""
        self.factor(K)
        return self.solve_factored(K, rhs)

    def negative_pivots(self) -> int | None:
        """The last factorised matrix's negative eigenvalues, counted as the negative pivots of its
        LDL^T (Sylvester's law of inertia); None without qdldl (SuperLU's LU does not tell)."""
        if not self._have_qdldl or self._ldl is None:
            return None
        if self._negative is None:
            self._negative = int(np.count_nonzero(self._ldl.factors()[1] < 0))
        return self._negative

    def negative_curvature_direction(self) -> np.ndarray:
        """For the most negative pivot d_j of the last LDL^T = P K P^T, the direction
        v = P^T L^-T e_j, along which v.K.v = d_j < 0: a way down from a saddle (qdldl only),
        scaled to a largest entry of one."""
        L, d, perm = self._ldl.factors()
        n = len(d)
        e = np.zeros(n)
        e[int(np.argmin(d))] = 1.0
        y = spla.spsolve_triangular((sp.eye(n, format="csr") + L.T).tocsr(), e, lower=False)
        v = np.empty(n)
        v[perm] = y
        return v / np.max(np.abs(v))

    def solve_positive_definite(self, K, rhs: np.ndarray) -> tuple[np.ndarray, float]:
        """(z, sigma): solve (K + sigma I) z = rhs with a shift sigma just large enough that the
        LDL^T has no negative pivot (growing threefold from a third of the last one, or from 1e-6
        of K's largest diagonal entry): the step of a minimiser that may not head for a saddle
        (qdldl only; a second factor of the same pattern)."""
        if self._shifted is None:
            self._shifted = LinearSolver()
            self._sigma = None
        diag = self._diagonal_of(K)
        scale = float(np.max(np.abs(K.data[diag])))
        sigma = 1e-6 * scale if self._sigma is None else max(self._sigma / 3, 1e-9 * scale)
        for _ in range(24):
            data = K.data.copy()
            data[diag] += sigma
            shifted = K.__class__((data, K.indices, K.indptr), shape=K.shape)
            self._shifted.factor(shifted)
            if self._shifted.negative_pivots() == 0:        # (a factor with negative pivots is not solved with)
                z = self._shifted.solve_factored(shifted, rhs)
                if np.all(np.isfinite(z)):
                    self._sigma = sigma
                    return z, sigma
            sigma *= 3
        return rhs / scale, scale


__all__ = ["LinearSolver", "UNION_SLACK"]
