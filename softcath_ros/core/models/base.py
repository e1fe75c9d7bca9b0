"""The interface every rung of the model ladder implements.

A model maps channel pressures (Pa, gauge) to a bend state: the curvature vector
k = (kx, ky) in 1/m and the axial stretch of the backbone. Convention: the
backbone bends *towards* the direction k/|k| in the xy-plane of ``softcath_base``
with curvature |k| (so a channel at +y, which lengthens the +y side, gives k
pointing to -y).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..design import Design
from ..errors import ModelError


@dataclass
class BendState:
    """Result of a model evaluation. Batched: leading axis N, or no axis for one command."""

    curvature: np.ndarray       # (..., 2) 1/m
    axial_stretch: np.ndarray   # (...) dimensionless, 1 = unstretched
    converged: np.ndarray       # (...) bool
    message: str = ""           # why a solve did not converge (empty when all did)
    extras: dict = field(default_factory=dict)  # rung-specific outputs (channel area, iterations, ...)


class BendModel:
    """Base class: subclasses set ``name`` and implement ``_evaluate_batch``."""

    name = "abstract"

    def __init__(self, design: Design):
        self.design = design

    @property
    def n_channels(self) -> int:
        return self.design.n_channels

    @property
    def pressure_range(self) -> tuple[float, float]:
        """Pa: the channel pressures this rung answers. The design's limit unless the rung knows a
        narrower range up front (a table refuses outside the range it was built on)."""
        return 0.0, float(self.design.max_pressure)

    def evaluate(self, pressures) -> BendState:
        """Bend state for one pressure vector (shape (C,)) or a batch (shape (N, C)), Pa."""
        p = np.asarray(pressures, dtype=float)
        single = p.ndim == 1
        batch = p[None, :] if single else p
        if batch.ndim != 2 or batch.shape[1] != self.n_channels:
            raise ModelError(f"model '{self.name}' for design '{self.design.name}' expects "
                             f"{self.n_channels} channel pressure(s) per command, got shape {p.shape}")
        state = self._evaluate_batch(batch)
        if single:
            state.curvature = state.curvature[0]
            state.axial_stretch = state.axial_stretch[0]
            state.converged = state.converged[0]
        return state

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:  # pragma: no cover - abstract
        raise NotImplementedError


def lumen_fill_fraction(value, rung: str) -> float | None:
    """A rung's ``lumen_fill`` option checked: None (empty lumen) or the fill's shear modulus as a
    fraction in (0, 1) of the silicone's. ``rung`` prefixes the error ("model 'section'", "fe3d")."""
    if value is None:
        return None
    if isinstance(value, bool) or not 0.0 < float(value) < 1.0:
        raise ModelError(f"{rung}: lumen_fill = {value!r} must be a fraction of the silicone's shear modulus "
                         "in (0, 1), or None for an empty lumen")
    return float(value)
