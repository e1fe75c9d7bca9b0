"""Closed-form rung: Euler-Bernoulli beam over the transformed section.

Each channel's pressure acts on its end cap (area A_i, centroid r_i, any hole shape): an axial force
p_i A_i at an offset r_i - r_na from the neutral axis, so a moment that is constant
along the length. Equilibrium of the linear-elastic section gives
    J k = -sum_i p_i A_i (r_i - r_na)     (J: bending stiffness tensor, N m^2)
    lambda - 1 = sum_i p_i A_i / EA.
Linear in pressure, so the whole rung is a 2 x C matrix and a C-vector.
It ignores wall ballooning and hyperelasticity and so under-predicts bending
by 2-3x at 0.15-0.2 bar (docs/architecture.md); it is the cheapest rung, not the truest.
"""
from __future__ import annotations

import numpy as np

from ..design import Design
from ..section_properties import transformed_section
from .base import BendModel, BendState, RungInfo


class ClosedFormModel(BendModel):
    name = "closed_form"
    solver_version = "closed-form-1"   # bump when a change alters its answers
    info = RungInfo(summary="Euler-Bernoulli beam over the transformed section: linear in pressure",
                    models=("free_bending", "device_stiffness"), linear_gain=True)

    def __init__(self, design: Design):
        super().__init__(design)
        self.section = transformed_section(design)
        # any hole shape: each channel's end-cap area and its centroid's offset from the neutral axis
        areas = self.section.pressure_areas
        offsets = self.section.pressure_offsets                                            # (C, 2)
        moment_per_pa = (areas[:, None] * offsets).T                                       # (2, C) m^3
        self.curvature_per_pa = -np.linalg.solve(self.section.bending_stiffness, moment_per_pa)  # (2, C)
        self.stretch_per_pa = areas / self.section.axial_stiffness                          # (C,)
        # Transposed copies so a batch is one matmul without a temporary transpose.
        self._gt = np.ascontiguousarray(self.curvature_per_pa.T)

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        n = pressures.shape[0]
        return BendState(curvature=pressures @ self._gt,
                         axial_stretch=1.0 + pressures @ self.stretch_per_pa,
                         converged=np.ones(n, dtype=bool))

    def curvature_single(self, pressures: np.ndarray) -> tuple[np.ndarray, float]:
        """Fast path for one command (no BendState allocation): (k (2,), stretch)."""
        return self.curvature_per_pa @ pressures, 1.0 + float(self.stretch_per_pa @ pressures)
