"""The hoop rings' own bending stiffness: the outer wall's nodes as a polygon, each node's turning angle.

    sum_i 1/2 B (theta_i - Theta_i)^2 / l_i      (B = E I / pitch of the thread; l_i the reference
                                                  length the node stands for: half its two sides)

Without it a compressed ring (a string) has no resistance to wrinkling but the silicone's, which
at the element scale vanishes with the element: the ring wrinkles at a strain proportional to h.
"""
from __future__ import annotations

import numpy as np

from . import Contribution


def _turning(P):
    """Turning angle at the middle of each node triplet P (b,3,2), and a, b (the two sides)."""
    a, b = P[:, 1] - P[:, 0], P[:, 2] - P[:, 1]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return np.arctan2(cross, np.einsum("bi,bi->b", a, b)), a, b


def _perp_over_r2(v):
    """d(polar angle of v)/dv = (-v_y, v_x) / |v|^2 and its Hessian (b,2,2)."""
    r2 = np.einsum("bi,bi->b", v, v)
    g = np.stack([-v[:, 1], v[:, 0]], -1) / r2[:, None]
    xy, d = 2 * v[:, 0] * v[:, 1], v[:, 1] ** 2 - v[:, 0] ** 2
    H = np.stack([np.stack([xy, d], -1), np.stack([d, -xy], -1)], -2) / (r2 ** 2)[:, None, None]
    return g, H


# a = x1 - x0, b = x2 - x1: the signs of their (x_k, x_l) blocks in the Hessian of theta
_SIGNS_A = np.kron(np.outer([-1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]), np.ones((2, 2)))
_SIGNS_B = np.kron(np.outer([0.0, -1.0, 1.0], [0.0, -1.0, 1.0]), np.ones((2, 2)))


class RingBending:
    def __init__(self, X, outer_edges: np.ndarray, stiffness: float, dofs_of, n_u: int):
        """``stiffness`` B / (c_ref R^3); ``dofs_of(triplets)``: their global unknowns (b,9)."""
        ring = outer_edges[:, :2].ravel()      # corner and midside nodes in order (the mesher's closed chain)
        self.triplets = np.stack([np.roll(ring, 1), ring, np.roll(ring, -1)], -1)    # (b,3)
        self.X, self.n_u = X, n_u
        self.dofs = dofs_of(self.triplets)
        self.theta0, a, b = _turning(X[self.triplets])
        self.w = stiffness / (0.5 * (np.linalg.norm(a, axis=-1) + np.linalg.norm(b, axis=-1)))

    def _angles(self, x):
        u = x[:self.n_u].reshape(-1, 2)
        theta, a, b = _turning(self.X[self.triplets] + u[self.triplets])
        return theta - self.theta0, a, b

    def energy(self, x, pressures) -> float:
        d, _, _ = self._angles(x)
        return float(np.sum(0.5 * self.w * d ** 2))

    def assemble(self, x, pressures) -> Contribution:
        d, a, b = self._angles(x)
        ga, Ha = _perp_over_r2(a)
        gb, Hb = _perp_over_r2(b)
        # theta = angle(b) - angle(a); a = x1 - x0, b = x2 - x1
        G = np.concatenate([ga, -ga - gb, gb], -1)                 # d theta / d(x0, x1, x2)
        Hth = _SIGNS_B * np.tile(Hb, (1, 3, 3)) - _SIGNS_A * np.tile(Ha, (1, 3, 3))
        nb = len(d)
        E = float(np.sum(0.5 * self.w * d ** 2))
        g9 = np.zeros((nb, 9))
        g9[:, :6] = (self.w * d)[:, None] * G
        h9 = np.zeros((nb, 9, 9))
        h9[:, :6, :6] = self.w[:, None, None] * (G[:, :, None] * G[:, None, :] + d[:, None, None] * Hth)
        return Contribution(E, g9, h9)
