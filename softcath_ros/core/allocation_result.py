"""What an allocation returns: the pressures of one request and what they achieve, and the reachable set."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Allocation:
    """One allocation. Pressures in Pa, curvatures in 1/m, angles in rad."""

    pressures: np.ndarray               # (C,) Pa, each in [0, max_pressure]
    requested_curvature: np.ndarray     # (2,) 1/m, as asked (before saturation)
    achieved_curvature: np.ndarray      # (2,) 1/m, the model's forward curvature at ``pressures``
    axial_stretch: float                # the model's axial stretch at ``pressures``
    max_curvature: float                # 1/m, reachable-set radius in the requested direction
    saturated: bool                     # the request lay beyond the reachable set
    reachable: bool                     # False: no channel combination bends this way
    active_channels: tuple[int, ...]    # channels with non-zero pressure (0, 1 or 2 of them)
    converged: bool = True              # the model's inverse converged (always for linear rungs)
    message: str = ""                   # why not reachable / not converged, or what was clipped
    iterations: int = 0                 # model evaluations batches used by the inverse
    extras: dict = field(default_factory=dict)  # mode-specific (tip error, requested angle, ...)

    @property
    def bending_angle(self) -> float:
        """Achieved bending angle, rad (needs the backbone length: see ``extras``)."""
        return float(self.extras.get("achieved_angle_rad", float("nan")))

    def to_json(self) -> dict:
        d = {"pressures_pa": [float(v) for v in self.pressures],
             "saturated": bool(self.saturated),
             "reachable": bool(self.reachable),
             "converged": bool(self.converged),
             "requested_curvature_per_m": [float(v) for v in self.requested_curvature],
             "achieved_curvature_per_m": [float(v) for v in self.achieved_curvature],
             "axial_stretch": float(self.axial_stretch),
             "max_curvature_per_m": float(self.max_curvature),
             "active_channels": list(self.active_channels),
             "iterations": int(self.iterations),
             "message": self.message}
        d.update({k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.extras.items()})
        return d


@dataclass(frozen=True)
class ReachableSet:
    directions: np.ndarray      # (N,) rad, direction of the curvature vector (atan2(ky, kx))
    max_curvature: np.ndarray   # (N,) 1/m, 0 where the direction is unreachable
    channel_directions: np.ndarray  # (C,) rad, each channel's own bending direction (nan: none)
    channel_max_curvature: np.ndarray  # (C,) 1/m, each channel alone at max_pressure
