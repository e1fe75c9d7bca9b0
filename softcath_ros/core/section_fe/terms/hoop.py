"""Hoop reinforcement: rings on the outer boundary as a line spring on its quadratic edges.

    oint 1/2 k_h (ds/dS - 1)^2 dS     (optionally tension only: no resistance to shortening)
"""
from __future__ import annotations

import numpy as np

from ..quadrature import EDGE_POINTS, EDGE_WEIGHTS
from ..shape import p2_edge
from . import Contribution


class HoopRings:
    def __init__(self, X, edges: np.ndarray, stiffness: float, tension_only: bool, dofs: np.ndarray, n_u: int):
        """``edges`` (b,3) outer-boundary nodes; ``stiffness`` k_h / (c_ref R); ``dofs`` (b,9)."""
        self.X, self.edges, self.k, self.tension_only = X, edges, stiffness, tension_only
        self.dofs, self.n_u = dofs, n_u
        _, self.dNe = p2_edge(EDGE_POINTS)
        self.L0 = np.linalg.norm(np.einsum("ga,bai->bgi", self.dNe, X[edges]), axis=-1)   # (b,g)
        # T = sum_a dNe[g,a] x_a: local unknown (a, i) -> index 2a+i
        self.Bg = np.zeros((len(EDGE_POINTS), 2, 6))
        self.Bg[:, 0, 0::2] = self.dNe
        self.Bg[:, 1, 1::2] = self.dNe

    def _tangents(self, x):
        u = x[:self.n_u].reshape(-1, 2)
        T = np.einsum("ga,bai->bgi", self.dNe, self.X[self.edges] + u[self.edges])  # (b,g,2)
        L = np.linalg.norm(T, axis=-1)
        ext = L - self.L0
        if self.tension_only:
            ext = np.maximum(ext, 0.0)
        w = EDGE_WEIGHTS * self.k / self.L0
        return T, L, ext, w

    def energy(self, x, pressures) -> float:
        _, _, ext, w = self._tangents(x)
        return float(np.sum(w * 0.5 * ext**2))

    def assemble(self, x, pressures) -> Contribution:
        T, L, ext, w = self._tangents(x)
        E = float(np.sum(w * 0.5 * ext**2))
        t = T / L[..., None]
        gT = (w * ext)[..., None] * t                                      # dE/dT (b,g,2)
        active = (ext != 0) | (not self.tension_only)
        tt = t[..., :, None] * t[..., None, :]
        hT = w[..., None, None] * (active[..., None, None] * tt + (ext / L)[..., None, None] * (np.eye(2) - tt))
        nb = len(self.edges)
        g9 = np.zeros((nb, 9))
        g9[:, :6] = np.einsum("bgi,gid->bd", gT, self.Bg)
        h9 = np.zeros((nb, 9, 9))
        h9[:, :6, :6] = np.einsum("gid,bgij,gje->bde", self.Bg, hT, self.Bg)
        return Contribution(E, g9, h9)
