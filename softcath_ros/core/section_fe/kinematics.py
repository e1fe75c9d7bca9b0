"""The section's deformation gradient at the sample points of an element rule, and its derivatives.

Every section deforms in its own plane by x = X + u(X) (P2 displacement u), and the backbone
is an arc of curvature k = (kx, ky) per unit deformed length with axial stretch lambda, so

    F = [[dx/dX, dx/dY, 0], [dy/dX, dy/dY, 0], [0, 0, F33]],   F33 = lambda (1 - k . x).

A term works with the five non-zero entries a = (F11, F12, F21, F22, F33) at each sample
point; their derivatives with respect to an element's 15 local unknowns (12 displacements
u_x, u_y of its six nodes interleaved, then lambda, kx R, ky R) are ``strain_rows``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .quadrature import map_rule

N_GLOBAL = 3  # lambda, kx R, ky R


class ElementRule:
    """A quadrature rule on some elements, with what the kinematics needs at its points:
    node indices (e,6), shape values N (q,6), physical gradients dNdX (e,q,6,2), weights dA
    (e,q), reference positions Xq (e,q,2) and the constant in-plane rows D0 (e,q,5,15) of
    da/d(local unknowns)."""

    def __init__(self, X, triangles, points, weights):
        self.triangles = triangles
        self.N, self.dNdX, self.dA, self.Xq = map_rule(X, triangles, points, weights)
        D0 = np.zeros((len(triangles), len(weights), 5, 15))
        D0[..., 0, 0:12:2] = self.dNdX[..., 0]
        D0[..., 1, 0:12:2] = self.dNdX[..., 1]
        D0[..., 2, 1:12:2] = self.dNdX[..., 0]
        D0[..., 3, 1:12:2] = self.dNdX[..., 1]
        self.D0 = D0
        self.D = D0.copy()   # strain_rows' result: D0 with the row of F33 written in at each call
        self.last_kinematics = None   # (displacements and globals, their Kinematics): ``kinematics``


@dataclass
class Kinematics:
    """F at a rule's sample points: in-plane block F2 (e,q,2,2), F33 (e,q), deformed points
    (e,q,2) and the globals (lambda, kx R, ky R)."""

    F2: np.ndarray
    f33: np.ndarray
    xq: np.ndarray
    globals: tuple

    @property
    def det2(self) -> np.ndarray:
        F2 = self.F2
        return F2[..., 0, 0] * F2[..., 1, 1] - F2[..., 0, 1] * F2[..., 1, 0]

    def entries(self) -> np.ndarray:
        """a = (F11, F12, F21, F22, F33) (e,q,5)."""
        F2 = self.F2
        return np.stack([F2[..., 0, 0], F2[..., 0, 1], F2[..., 1, 0], F2[..., 1, 1], self.f33], -1)


def kinematics(rule: ElementRule, x, n_u: int) -> Kinematics:
    """F at the sample points of ``rule`` for the state ``x`` = [u (n_u), lambda, kx R, ky R, ...];
    the rule keeps the last one (read-only) for the same displacements and globals (a trial's
    energy, then its assembly)."""
    key = x[:n_u + N_GLOBAL]
    last = rule.last_kinematics
    if last is not None and np.array_equal(key, last[0]):
        return last[1]
    u = x[:n_u].reshape(-1, 2)
    lam, kx, ky = x[n_u:n_u + N_GLOBAL]
    ue = u[rule.triangles]                                          # (e,6,2)
    F2 = np.matmul(ue.transpose(0, 2, 1)[:, None], rule.dNdX)      # (e,q,2,2): sum_a u_ai dN_a/dX_j
    F2[..., 0, 0] += 1.0
    F2[..., 1, 1] += 1.0
    xq = rule.Xq + np.matmul(rule.N, ue)                            # (e,q,2)
    f33 = lam * (1 - kx * xq[..., 0] - ky * xq[..., 1])
    for a in (F2, f33, xq):
        a.setflags(write=False)
    kin = Kinematics(F2, f33, xq, (lam, kx, ky))
    rule.last_kinematics = (key.copy(), kin)
    return kin


def strain_rows(rule: ElementRule, kin: Kinematics) -> np.ndarray:
    """da/d(local unknowns) (e,q,5,15): the constant in-plane rows plus the row of F33.

    The array is the rule's own buffer (rows 0-3 never change, row 4 is rewritten whole), so it
    holds only until the next call on the same rule: a term uses it within its assembly."""
    lam, kx, ky = kin.globals
    return f33_rows(rule.D, rule.N, kin.xq, lam, kx, ky)


def f33_rows(D, N, xq, lam, kx, ky):
    """Write the row of F33 = lam (1 - k.x) into D (e,q,5,15), whose rows 0-3 are the in-plane
    ones, and return it."""
    D[..., 4, 0:12:2] = -lam * kx * N
    D[..., 4, 1:12:2] = -lam * ky * N
    D[..., 4, 12] = 1 - kx * xq[..., 0] - ky * xq[..., 1]
    D[..., 4, 13] = -lam * xq[..., 0]
    D[..., 4, 14] = -lam * xq[..., 1]
    return D


def add_f33_hessian(H, s, N, xq, lam, kx, ky):
    """H += sum_q s_q d2F33/d(local unknowns)^2 (F33 is bilinear in x and the globals).

    H (e,15,15), s (e,q), N (q,6), xq (e,q,2)."""
    sn = s @ N                                   # (e,6)
    sx = np.sum(s * xq[..., 0], -1)
    sy = np.sum(s * xq[..., 1], -1)
    for (rows, col, val) in ((slice(0, 12, 2), 12, -kx * sn), (slice(1, 12, 2), 12, -ky * sn),
                             (slice(0, 12, 2), 13, -lam * sn), (slice(1, 12, 2), 14, -lam * sn)):
        H[:, rows, col] += val
        H[:, col, rows] += val
    H[:, 12, 13] -= sx
    H[:, 13, 12] -= sx
    H[:, 12, 14] -= sy
    H[:, 14, 12] -= sy


def jacobian_gradient(a, det2, f33):
    """dJ/da (..., 5) for J = det F = det2 f33."""
    return np.stack([a[..., 3] * f33, -a[..., 2] * f33, -a[..., 1] * f33, a[..., 0] * f33, det2], -1)


def add_jacobian_hessian(M, c, a, f33):
    """M += c d2J/da2 (M (..., 5, 5), c (...)): d2J/da2 has eight non-zero entries, written in place."""
    for (i, j), value in (((0, 3), c * f33), ((1, 2), -c * f33), ((0, 4), c * a[..., 3]),
                          ((3, 4), c * a[..., 0]), ((1, 4), -c * a[..., 2]), ((2, 4), -c * a[..., 1])):
        M[..., i, j] += value
        M[..., j, i] += value


def jacobian_derivatives(a, det2, f33):
    """dJ/da (..., 5) and d2J/da2 (..., 5, 5) for J = det F = det2 f33."""
    Jaa = np.zeros(a.shape + (5,))
    add_jacobian_hessian(Jaa, np.ones(a.shape[:-1]), a, f33)
    return jacobian_gradient(a, det2, f33), Jaa


def block_dofs(nodes, i_glob) -> np.ndarray:
    """Global unknown indices (b, 2m + 3) of blocks of m nodes each (``nodes`` (b, m): an element's
    six or an edge's three): (u_x, u_y) of each node interleaved, then the globals."""
    m = nodes.shape[1]
    dofs = np.empty((len(nodes), 2 * m + N_GLOBAL), dtype=np.int64)
    dofs[:, 0:2 * m:2] = 2 * nodes
    dofs[:, 1:2 * m:2] = 2 * nodes + 1
    dofs[:, 2 * m:] = i_glob
    return dofs
