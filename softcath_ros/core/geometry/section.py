"""The cross-section as outlines: the body circle, holes with roles, the limiting fibre; its
validation and its walls.

``Section`` is what every rung reads: ``outer`` (the body's ``Outline``), ``holes`` (each a
``SectionHole``: design field name, role ``channel`` | ``lumen``, exact ``outline``, shapely
``polygon``, the ``shape`` as written), ``fibre`` (a ``Circle`` or None). Walls are true minimum
distances: exact where one side is a circle (the body, a circular hole, the fibre), otherwise
bracketed between polygons outside and inside the outlines (``bracketed_gap``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import DesignError
from .outline import Outline

# Width (m) within which a wall between two non-circular outlines is bracketed (``bracketed_gap``).
WALL_CHORD_TOLERANCE = 1.0e-7
# A wall this much (m) under the minimum still passes: a wall drawn at the minimum (positions typed
# to the micrometre) is accepted, and a refused wall never reads as the minimum at the micrometre
# the message shows. Far below what moulding holds.
WALL_TOLERANCE = 0.5e-6


@dataclass(frozen=True)
class Circle:
    center: tuple[float, float]
    radius: float
    kind = "circle"

    def spec(self) -> dict:
        return {"diameter": 2.0 * self.radius, "center": list(self.center)}


@dataclass(frozen=True, eq=False)
class SectionHole:
    """A hole in the section: ``name`` is its design field (``channels[0]``, ``lumen``)."""

    name: str
    role: str            # "channel" | "lumen"
    outline: Outline
    shape: object       # Circle | Sector | PolygonShape | FileShape: the exact primitive as written

    @property
    def polygon(self):
        """Shapely polygon of the outline (chords within ``outline.CHORD_TOLERANCE``)."""
        return self.outline.shapely

    @property
    def area(self) -> float:
        return math.pi * self.shape.radius**2 if self.is_circle else self.outline.area

    @property
    def centroid(self) -> np.ndarray:
        return np.asarray(self.shape.center, dtype=float) if self.is_circle else self.outline.centroid

    @property
    def is_circle(self) -> bool:
        return isinstance(self.shape, Circle)

    def position_field(self, towards_axis: bool = False) -> tuple[str, object]:
        """The field (and its value) a refusal about where this hole lies names."""
        s = self.shape
        if isinstance(s, Circle):
            return f"{self.name}.center", list(s.center)
        if s.kind == "sector":
            return (f"{self.name}.inner_radius", s.inner_radius) if towards_axis else \
                (f"{self.name}.outer_radius", s.outer_radius)
        if s.kind == "polygon":
            return f"{self.name}.points", [list(p) for p in s.points]
        return f"{self.name}.path", s.path


@dataclass(frozen=True)
class Wall:
    """Silicone between two boundaries: ``between`` names them (a hole's field or ``outer``)."""

    thickness: float                      # m
    between: tuple[str, str]
    points: tuple[tuple[float, float], tuple[float, float]] | None   # the nearest points (m), if located


@dataclass(frozen=True, eq=False)
class Section:
    outer_radius: float
    holes: tuple[SectionHole, ...]
    fibre: Circle | None = None

    @cached_property
    def outer(self) -> Outline:
        return Outline.circle((0.0, 0.0), self.outer_radius)

    @property
    def channels(self) -> tuple[SectionHole, ...]:
        return tuple(h for h in self.holes if h.role == "channel")

    @property
    def lumen(self) -> SectionHole | None:
        return next((h for h in self.holes if h.role == "lumen"), None)

    @property
    def body_area(self) -> float:
        return math.pi * self.outer_radius**2

    @property
    def silicone_area(self) -> float:
        return self.body_area - sum(h.area for h in self.holes)

    @property
    def area_ratio(self) -> float:
        """Total channel area over the body's cross-section area."""
        return sum(h.area for h in self.channels) / self.body_area

    def silicone(self, tolerance: float | None = None):
        """Shapely polygon of the silicone: the body with the holes cut out."""
        from shapely.geometry import Polygon

        if tolerance is None:
            return Polygon(self.outer.shapely.exterior, [h.polygon.exterior for h in self.holes])
        return Polygon(self.outer.polygon(tolerance).exterior, [h.outline.polygon(tolerance).exterior for h in self.holes])

    # ------------------------------------------------------------------ walls
    def outer_wall(self, hole: SectionHole, locate: bool = True) -> Wall:
        """The wall between a hole and the body's surface (``locate``: with its end points)."""
        far = hole.outline.farthest_from_origin()
        pts = None
        if locate:
            ring = hole.outline.polygon_points()
            p = ring[int(np.argmax(np.hypot(ring[:, 0], ring[:, 1])))]
            pts = (tuple(p), tuple(p * self.outer_radius / max(float(np.hypot(*p)), 1e-300)))
        return Wall(self.outer_radius - far, (hole.name, "outer"), pts)

    def wall_between(self, a: SectionHole, b: SectionHole, locate: bool = True, decide_at: float | None = None) -> Wall:
        """The wall between two holes; negative thickness (-1) when they overlap. ``decide_at``: a
        thickness the answer must be on the right side of (see ``bracketed_gap``)."""
        pts = None
        if locate:
            from shapely import shortest_line

            line = shortest_line(a.polygon, b.polygon)
            pts = tuple(tuple(c) for c in line.coords)
        if a.is_circle and b.is_circle:
            gap = math.dist(a.shape.center, b.shape.center) - a.shape.radius - b.shape.radius
        elif a.is_circle or b.is_circle:
            c, other = (a, b) if a.is_circle else (b, a)
            gap = other.outline.distance_to_point(c.shape.center) - c.shape.radius
            if other.outline.contains(c.shape.center):   # the circle's centre inside the shape: overlapping
                gap = -1.0
        else:
            gap = bracketed_gap(a.outline, b.outline, decide_at)
        return Wall(gap, (a.name, b.name), pts)

    def walls(self) -> list[Wall]:
        out = [self.outer_wall(h) for h in self.holes]
        for i, a in enumerate(self.holes):
            out += [self.wall_between(a, b) for b in self.holes[i + 1:]]
        return out

    def thinnest_wall(self) -> Wall:
        return min(self.walls(), key=lambda w: w.thickness)

    def largest_inscribed_diameter(self, hole: SectionHole) -> float:
        """Diameter of the largest circle inside a hole (what a device in the lumen can be)."""
        if hole.is_circle:
            return 2.0 * hole.shape.radius
        from shapely import maximum_inscribed_circle

        # on a polygon within 1 nm of the arcs, the centre found to 1 nm: the diameter to within ~4 nm
        line = maximum_inscribed_circle(hole.outline.polygon(1e-9), tolerance=1e-9)
        return 2.0 * line.length


def bracketed_gap(a: Outline, b: Outline, decide_at: float | None = None) -> float:
    """The true minimum distance between two outlines (-1 when they overlap), bracketed: polygons
    containing the outlines give a lower bound, polygons inside them an upper bound. The chords are
    refined until the bracket is within ``WALL_CHORD_TOLERANCE`` and wholly on one side of
    ``decide_at`` (the acceptance threshold), or narrower than 1 nm: a wall is accepted or refused
    exactly, and one at the threshold to within 1 nm is accepted."""
    tol = WALL_CHORD_TOLERANCE / 4   # each bound within 2 tol of the truth
    while True:
        inner_a, inner_b = a.polygon(tol, "inside"), b.polygon(tol, "inside")
        if inner_a.intersects(inner_b):
            return -1.0
        upper = inner_a.distance(inner_b)
        outer_a, outer_b = a.polygon(tol, "outside"), b.polygon(tol, "outside")
        lower = 0.0 if outer_a.intersects(outer_b) else outer_a.distance(outer_b)
        straddles = decide_at is not None and lower < decide_at <= upper
        if (not straddles and upper - lower <= WALL_CHORD_TOLERANCE) or upper - lower <= 1e-9 or tol < 1e-11:
            return upper if straddles else 0.5 * (lower + upper)
        tol *= 0.1


def check_section(section: Section, min_wall: float) -> None:
    """Holes inside the body and apart, every wall >= ``min_wall`` (true minimum distance,
    ``WALL_TOLERANCE`` allowed), the fibre inside silicone; refusals name the field. (Outlines are
    checked simple as they are built, ``shapes.shape_outline``.)"""
    for h in section.holes:
        wall = section.outer_wall(h, locate=False)
        field, value = h.position_field()
        if wall.thickness < 0:
            what = f"hole of diameter {2 * h.shape.radius:g}" if h.is_circle else f"the {h.shape.kind}"
            raise DesignError(field, value, f"{what} reaches outside the body (outer diameter {2 * section.outer_radius:g})")
        if wall.thickness < min_wall - WALL_TOLERANCE:
            raise DesignError(field, value, f"outer wall {wall.thickness * 1e3:.3f} mm is thinner than the minimum "
                                            f"{min_wall * 1e3:.3f} mm")
    for i, a in enumerate(section.holes):
        for b in section.holes[i + 1:]:
            wall = section.wall_between(a, b, locate=False, decide_at=min_wall - WALL_TOLERANCE)
            # name the later hole, or the shaped one of a circle and a shape (its fields place the wall)
            named, other = (a, b) if b.is_circle and not a.is_circle else (b, a)
            towards_axis = float(np.hypot(*other.centroid)) < float(np.hypot(*named.centroid))
            field, value = named.position_field(towards_axis)
            if wall.thickness < 0:
                raise DesignError(field, value, f"overlaps {other.name}")
            if wall.thickness < min_wall - WALL_TOLERANCE:
                raise DesignError(field, value, f"wall to {other.name} is {wall.thickness * 1e3:.3f} mm, thinner than "
                                                f"the minimum {min_wall * 1e3:.3f} mm")
    f = section.fibre
    if f is not None:
        if math.hypot(*f.center) + f.radius > section.outer_radius:
            raise DesignError("limiting_fibre.center", list(f.center), "fibre is not inside the silicone body")
        for h in section.holes:
            if h.is_circle:
                cuts = math.dist(f.center, h.shape.center) < f.radius + h.shape.radius
            else:
                cuts = h.outline.contains(f.center) or h.outline.distance_to_point(f.center) < f.radius
            if cuts:
                raise DesignError("limiting_fibre.center", list(f.center), f"fibre is not inside silicone: it cuts {h.name}")
