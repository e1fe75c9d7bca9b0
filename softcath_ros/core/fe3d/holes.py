"""The holes of a design's section as the 3D model reads them: a circle, or a shape with an outline."""
from __future__ import annotations

import math


def is_circle(hole) -> bool:
    """A circular hole (``design.Hole``); any other is a ``ShapedHole`` with an outline."""
    return getattr(hole, "kind", "circle") == "circle"


def hole_size(hole) -> float:
    """A hole's radius (m): a circle's own, else that of the circle of equal area (for mesh sizes
    and scales of distance)."""
    return hole.radius if is_circle(hole) else math.sqrt(hole.area / math.pi)
