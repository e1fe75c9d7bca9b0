"""A device in the lumen (a guidewire, a camera lead) as a beam bending with the section.

    1/2 EI_dev |k|^2     (per unit length; EI_dev / (c_ref R^4) non-dimensional)
"""
from __future__ import annotations

import numpy as np

from . import Contribution


class DeviceBending:
    def __init__(self, bending_stiffness: float, i_glob: np.ndarray):
        """``bending_stiffness``: EI / (c_ref R^4); ``i_glob``: the unknowns (lambda, kx R, ky R)."""
        self.ei = bending_stiffness
        self.dofs = np.asarray(i_glob)[None]
        self._hessian = np.diag([0.0, self.ei, self.ei])[None]

    def energy(self, x, pressures) -> float:
        _, kx, ky = x[self.dofs[0]]
        return 0.5 * self.ei * (kx**2 + ky**2)

    def assemble(self, x, pressures) -> Contribution:
        _, kx, ky = x[self.dofs[0]]
        return Contribution(self.energy(x, pressures), np.array([[0.0, self.ei * kx, self.ei * ky]]),
                            self._hessian.copy())
