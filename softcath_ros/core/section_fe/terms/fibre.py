"""Strain-limiting fibre: a point fibre inside one element under uniaxial stretch F33.

    A_f W_fibre(lambda_f),   W_fibre = Yeoh at I1 = lambda_f^2 + 2 / lambda_f (incompressible)
"""
from __future__ import annotations

import numpy as np

from ...energy import yeoh, yeoh_derivatives
from ..kinematics import add_f33_hessian
from . import INADMISSIBLE, Contribution


class Fibre:
    def __init__(self, X, triangles, element: int, N: np.ndarray, area: float, yeoh_coefficients,
                 dofs: np.ndarray, n_u: int):
        """``element`` holding the fibre and its P2 shape values ``N`` (6,) there; ``area`` / R^2;
        Yeoh c1..c3 / c_ref; ``dofs`` (1,15) of that element."""
        self.X, self.nodes, self.N = X, triangles[element], N
        self.area, self.yeoh, self.dofs, self.n_u = area, yeoh_coefficients, dofs, n_u

    def _stretch(self, x):
        u = x[:self.n_u].reshape(-1, 2)
        lam, kx, ky = x[self.n_u:self.n_u + 3]
        xf = (self.X[self.nodes] + u[self.nodes]).T @ self.N
        return lam * (1 - kx * xf[0] - ky * xf[1]), xf, (lam, kx, ky)

    def energy(self, x, pressures) -> float:
        s, _, _ = self._stretch(x)
        return self.area * yeoh(s * s + 2 / s, *self.yeoh) if s > 0 else np.inf

    def assemble(self, x, pressures) -> Contribution:
        s, xf, (lam, kx, ky) = self._stretch(x)
        if not s > 0:
            return INADMISSIBLE
        W, W1, W2 = yeoh_derivatives(s * s + 2 / s, *self.yeoh)
        W, W1, W2 = self.area * W, self.area * W1, self.area * W2
        di = 2 * s - 2 / s**2
        ws = W1 * di
        wss = W2 * di**2 + W1 * (2 + 4 / s**3)
        ds = np.zeros(15)
        ds[0:12:2] = -lam * kx * self.N
        ds[1:12:2] = -lam * ky * self.N
        ds[12] = 1 - kx * xf[0] - ky * xf[1]
        ds[13] = -lam * xf[0]
        ds[14] = -lam * xf[1]
        H = wss * np.outer(ds, ds)[None]
        add_f33_hessian(H, np.array([[ws]]), self.N[None], xf[None, None], lam, kx, ky)
        return Contribution(W, (ws * ds)[None], H)
