"""The work of a channel's pressure: -p V, V = lambda int_{channel, deformed} (1 - k . x) dA.

V is the channel volume per unit reference length; its variation gives the follower
pressure on the walls, the axial end force p A and its moment p A lambda (lever arm). It is
integrated by Green's theorem on the channel's quadratic boundary. With ``end_cap_only`` the
channel keeps its reference cross-section here: the pressure acts only through the end caps
(axial force p A at the reference channel centre), as the closed form assumes.
"""
from __future__ import annotations

import numpy as np

from ..quadrature import EDGE_POINTS, EDGE_WEIGHTS
from ..shape import p2_edge
from . import Contribution


def _edge_samples(xe, Ne, dNe):
    """x, y and their derivatives along the edge, x', y' (each (b,g)), at the edge rule's points."""
    return xe[..., 0] @ Ne.T, xe[..., 1] @ Ne.T, xe[..., 0] @ dNe.T, xe[..., 1] @ dNe.T


def green_moments(xe, Ne, dNe):
    """Per-edge area and first moments (A, Sx, Sy) of the region left of the oriented
    quadratic edges ``xe`` (b,3,2) (Green's theorem; summed over a closed boundary)."""
    x, y, xp, yp = _edge_samples(xe, Ne, dNe)
    A = 0.5 * (x * yp - y * xp) @ EDGE_WEIGHTS
    Sx = 0.5 * (x * x * yp) @ EDGE_WEIGHTS
    Sy = -0.5 * (y * y * xp) @ EDGE_WEIGHTS
    return A, Sx, Sy


class ChannelPressure:
    def __init__(self, X, edges: np.ndarray, channel: int, end_cap_only: bool, dofs: np.ndarray, n_u: int):
        """``edges`` (b,3) of channel number ``channel`` (its pressure is ``pressures[channel]``)."""
        self.X, self.edges, self.channel, self.end_cap_only = X, edges, channel, end_cap_only
        self.dofs, self.n_u = dofs, n_u
        self.Ne, self.dNe = p2_edge(EDGE_POINTS)

    def _wall(self, x):
        """The channel's boundary nodes in the volume term (reference ones with end_cap_only)."""
        if self.end_cap_only:
            return self.X[self.edges]
        u = x[:self.n_u].reshape(-1, 2)
        return self.X[self.edges] + u[self.edges]

    def area(self, x) -> float:
        """The deformed cross-section's area (/ R^2)."""
        u = x[:self.n_u].reshape(-1, 2)
        return green_moments(self.X[self.edges] + u[self.edges], self.Ne, self.dNe)[0].sum()

    def volume(self, x) -> float:
        lam, kx, ky = x[self.n_u:self.n_u + 3]
        A, Sx, Sy = green_moments(self._wall(x), self.Ne, self.dNe)
        return lam * (A.sum() - kx * Sx.sum() - ky * Sy.sum())

    def energy(self, x, pressures) -> float:
        p = pressures[self.channel]
        return 0.0 if p == 0 else -p * self.volume(x)      # (a channel at rest does no work)

    def assemble(self, x, pressures) -> Contribution:
        if pressures[self.channel] == 0:
            nb = len(self.edges)
            return Contribution(0.0, np.zeros((nb, 9)), np.zeros((nb, 9, 9)))
        lam, kx, ky = x[self.n_u:self.n_u + 3]
        v, gv, hv = self._volume_derivatives(self._wall(x), lam, kx, ky)
        if self.end_cap_only:
            gv[:, :6] = 0.0
            hv[:, :6, :] = 0.0
            hv[:, :, :6] = 0.0
        p = pressures[self.channel]
        return Contribution(-p * v, -p * gv, -p * hv)

    def _volume_derivatives(self, xe, lam, kx, ky):
        """V = lam sum_edges (A - kx Sx - ky Sy), gradient (b,9) and Hessian (b,9,9) per edge.

        Local order: (x_s, y_s, x_m, y_m, x_e, y_e, lam, kx, ky)."""
        N, dN, w = self.Ne, self.dNe, EDGE_WEIGHTS
        x, y, xp, yp = _edge_samples(xe, N, dN)
        A, Sx, Sy = green_moments(xe, N, dN)
        # first derivatives w.r.t. nodal x (X) and y (Y): (b,3)
        A_X = 0.5 * np.einsum("g,bg,ga->ba", w, yp, N) - 0.5 * np.einsum("g,bg,ga->ba", w, y, dN)
        A_Y = 0.5 * np.einsum("g,bg,ga->ba", w, x, dN) - 0.5 * np.einsum("g,bg,ga->ba", w, xp, N)
        Sx_X = np.einsum("g,bg,ga->ba", w, x * yp, N)
        Sx_Y = 0.5 * np.einsum("g,bg,ga->ba", w, x * x, dN)
        Sy_Y = -np.einsum("g,bg,ga->ba", w, y * xp, N)
        Sy_X = -0.5 * np.einsum("g,bg,ga->ba", w, y * y, dN)
        # second derivatives (b,3,3): XY block [i,j] = d2/dX_i dY_j
        A_XY = 0.5 * np.einsum("g,ga,gc->ac", w, N, dN) - 0.5 * np.einsum("g,ga,gc->ac", w, dN, N)
        Sx_XX = np.einsum("g,bg,ga,gc->bac", w, yp, N, N)
        Sx_XY = np.einsum("g,bg,ga,gc->bac", w, x, N, dN)
        Sy_YY = -np.einsum("g,bg,ga,gc->bac", w, xp, N, N)
        Sy_XY = -np.einsum("g,bg,ga,gc->bac", w, y, dN, N)
        Q = A - kx * Sx - ky * Sy
        QX = A_X - kx * Sx_X - ky * Sy_X
        QY = A_Y - kx * Sx_Y - ky * Sy_Y
        nb = len(xe)
        g = np.zeros((nb, 9))
        g[:, 0:6:2] = lam * QX
        g[:, 1:6:2] = lam * QY
        g[:, 6] = Q
        g[:, 7] = -lam * Sx
        g[:, 8] = -lam * Sy
        H = np.zeros((nb, 9, 9))
        XY = lam * (A_XY[None] - kx * Sx_XY - ky * Sy_XY)
        H[:, 0:6:2, 0:6:2] = lam * (-kx * Sx_XX)
        H[:, 1:6:2, 1:6:2] = lam * (-ky * Sy_YY)
        H[:, 0:6:2, 1:6:2] = XY
        H[:, 1:6:2, 0:6:2] = np.swapaxes(XY, 1, 2)
        H[:, 0:6:2, 6] = H[:, 6, 0:6:2] = QX
        H[:, 1:6:2, 6] = H[:, 6, 1:6:2] = QY
        H[:, 0:6:2, 7] = H[:, 7, 0:6:2] = -lam * Sx_X
        H[:, 1:6:2, 7] = H[:, 7, 1:6:2] = -lam * Sx_Y
        H[:, 0:6:2, 8] = H[:, 8, 0:6:2] = -lam * Sy_X
        H[:, 1:6:2, 8] = H[:, 8, 1:6:2] = -lam * Sy_Y
        H[:, 6, 7] = H[:, 7, 6] = -Sx
        H[:, 6, 8] = H[:, 8, 6] = -Sy
        return lam * Q.sum(), g, H
