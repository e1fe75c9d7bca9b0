"""The steering loop's range and feed-forward: the pressure limit a steered design is held to
(``steering_range``: a tip kept in the hemisphere in front of its base) and the allocator the
controller inverts the model with (``steering_allocator``)."""
from __future__ import annotations

import math

from .allocation import Allocator
from .errors import SoftcathError

# The top of every design's steering range: above it one channel of three_channel_5mm balloons towards
# lumen contact on the section rung (it bends 61 degrees at 0.3 bar, over 9 rad at 0.5 bar).
STEERING_MAX_PRESSURE = 3.0e4   # Pa
# A steered tip stays in the hemisphere in front of its base: one channel alone at the steering limit
# turns the tip at most this far from the base's axis (a softer body gets a lower limit, not a wrap).
STEERING_MAX_BEND_DEG = 90.0


class SteeringError(SoftcathError):
    """A steering request or setting the controller cannot use."""


def steering_design(design, max_pressure: float):
    """``design`` with its pressure limit lowered to ``max_pressure`` (Pa; never raised)."""
    from dataclasses import replace

    if not max_pressure > 0:
        raise SteeringError(f"max_pressure {max_pressure} Pa must be positive")
    return replace(design, max_pressure=min(float(max_pressure), float(design.max_pressure)))


def steering_model(rung: str, design):
    """``rung`` on ``design`` as shipped: a surrogate reads the table shipped for it (a lowered limit
    would be another design, whose table would be built at start-up)."""
    from .calibration_file import build_model

    return build_model(rung, design)


def steering_range(model) -> float:
    """The default steering limit (Pa) on ``model`` (a rung on its design as shipped): the lowest of
    STEERING_MAX_PRESSURE (0.3 bar), the design's max_pressure, and the pressure at which any channel
    alone turns the tip STEERING_MAX_BEND_DEG (90 degrees) from the base's axis, so a steered tip stays
    in the hemisphere in front of its base (channel_limits.bend_limit, on the rung the controller
    inverts). three_channel_5mm keeps 0.3 bar (61 degrees there); three_sector_5mm, about ten times
    as soft, stops where its 40 mm body would otherwise wrap back towards its shaft."""
    from .channel_limits import bend_limit

    top = min(STEERING_MAX_PRESSURE, float(model.design.max_pressure))
    reached = bend_limit(model, min(top, float(model.pressure_range[1])), math.radians(STEERING_MAX_BEND_DEG))
    return top if reached is None else reached[0]


def steering_allocator(rung, design, max_pressure: float | None = None) -> Allocator:
    """The feed-forward: ``rung`` (a name, built by ``steering_model``, or that model) on ``design``,
    its inverse limited to ``max_pressure`` (Pa, never above the design's; None: ``steering_range``)."""
    model = steering_model(rung, design) if isinstance(rung, str) else rung
    limit = steering_range(model) if max_pressure is None else steering_design(design, max_pressure).max_pressure
    return Allocator(model, max_pressure=limit)


__all__ = ["STEERING_MAX_BEND_DEG", "STEERING_MAX_PRESSURE", "SteeringError", "steering_allocator", "steering_design",
           "steering_model", "steering_range"]
