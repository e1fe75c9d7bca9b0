"""What acts on the actuator besides its pressures (softcath_base frame, SI): the loads a scene
names and the rod rung models, and their planar form in the rod's bending plane (core/rod/statics.py)."""
from __future__ import annotations

from dataclasses import dataclass

REST_TIP = "rest_tip"   # contact point: the tip of the straight, unpressurised body


@dataclass(frozen=True)
class TipPlaneContact:
    """A rigid plane the tip presses on (frictionless: the tip may slide and rotate on it).

    ``normal``: unit normal pointing from the surface to the side the actuator is on;
    ``point``: a point on the surface (m), or ``REST_TIP`` (the scale touches the tip at p = 0)."""

    normal: tuple[float, float, float]
    point: tuple[float, float, float] | str = REST_TIP


@dataclass(frozen=True)
class Loads:
    tip_force: tuple[float, float, float] | None = None   # N, dead load at the tip
    gravity: tuple[float, float, float] | None = None     # m/s^2, acceleration of gravity
    contact: TipPlaneContact | None = None

    @property
    def any(self) -> bool:
        return self.tip_force is not None or self.gravity is not None or self.contact is not None


@dataclass(frozen=True)
class PlaneContact:
    """A plane the tip may touch: ``normal`` (a, b) unit, pointing to the side the tip stays on;
    ``point`` (a, b) on the plane (m)."""

    normal: tuple[float, float]
    point: tuple[float, float]


@dataclass(frozen=True)
class PlanarLoads:
    tip_force: tuple[float, float] = (0.0, 0.0)          # N, (a, b)
    weight_per_length: tuple[float, float] = (0.0, 0.0)  # N per m of reference length, (a, b)
    contact: PlaneContact | None = None
