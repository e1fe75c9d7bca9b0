"""Blocking force from a rung's free curvature (until a rod rung with contact exists).

The blocking-force bench holds the tip of a cantilevered actuator on a scale. With a
linear beam (Euler-Bernoulli, small deflection), the pressure acts as an end moment
M that would bend the free actuator with curvature kappa = M / EI; a transverse tip
force F that brings the tip deflection back to zero satisfies
    M l^2 / (2 EI) = F l^3 / (3 EI)   =>   F = 3 M / (2 l) = 3 EI kappa / (2 l).
EI is the transformed section's bending stiffness about the bending direction, and
kappa the rung's own (possibly nonlinear) free curvature, so M = EI kappa is the
equivalent end moment of that rung. This ignores large deflection and the change of
stiffness under pressure; a rod rung with contact should replace it.
"""
from __future__ import annotations

import numpy as np

from ..core.section_properties import transformed_section


class BlockingForce:
    """F(p) = 3 EI(n) |k(p)| / (2 l) for one model (``model.evaluate``) and sample length l (m)."""

    def __init__(self, model):
        self.model = model
        self.stiffness = transformed_section(model.design).bending_stiffness  # (2, 2) N m^2

    def from_curvature(self, curvature: np.ndarray, length: float) -> np.ndarray:
        k = np.atleast_2d(np.asarray(curvature, dtype=float))
        mag = np.hypot(k[:, 0], k[:, 1])
        n = np.divide(k, mag[:, None], out=np.zeros_like(k), where=mag[:, None] > 0)
        ei = np.einsum("ni,ij,nj->n", n, self.stiffness, n)
        out = 1.5 * ei * mag / float(length)
        return out if np.ndim(curvature) > 1 else out[0]

    def __call__(self, pressures, length: float) -> np.ndarray:
        state = self.model.evaluate(pressures)
        return self.from_curvature(state.curvature, length)
