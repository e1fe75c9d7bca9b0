"""Hole shapes as written in a design file, each turned into an exact ``Outline``.

``circle`` {diameter, center}; ``sector`` {inner_radius, outer_radius, direction, span, fillet}
(an annular sector about the body axis, angles in degrees, direction counter-clockwise from +x);
``polygon`` {points, fillet} (points [x, y] or [x, y, bulge] in m); ``file`` {path, units,
layer | id} (a closed outline from a DXF layer or an SVG element, read by ``cad``). Fillets are
exact tangent arcs (not a buffered approximation), so they stay arcs for a mesher. Every refusal
is a ``DesignError`` naming the field and the value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..checks import finite_number
from ..errors import DesignError
from .outline import Outline

SHAPES = ("circle", "sector", "polygon", "file")
_KEYS = {"circle": {"shape", "diameter", "center"},
         "sector": {"shape", "inner_radius", "outer_radius", "direction", "span", "fillet"},
         "polygon": {"shape", "points", "fillet"},
         "file": {"shape", "path", "units", "layer", "id"}}
MAX_POINTS = 10_000
MIN_EDGE = 1e-9   # m: points closer than this are one point
MAX_REACH = 0.1   # m: no hole of a catheter-scale section reaches further from the axis (plausibility.PLAUSIBLE_SIZE)
# m: an outline must be simple on polygons this close to its arcs (and at the default chord tolerance)
SIMPLE_CHECK_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Sector:
    inner_radius: float
    outer_radius: float
    direction: float    # deg
    span: float         # deg
    fillet: float = 0.0
    kind = "sector"

    def spec(self) -> dict:
        return {"shape": "sector", "inner_radius": self.inner_radius, "outer_radius": self.outer_radius,
                "direction": self.direction, "span": self.span, "fillet": self.fillet}


@dataclass(frozen=True)
class PolygonShape:
    points: tuple[tuple[float, ...], ...]
    fillet: float = 0.0
    kind = "polygon"

    def spec(self) -> dict:
        return {"shape": "polygon", "points": [list(p) for p in self.points], "fillet": self.fillet}


@dataclass(frozen=True)
class FileShape:
    """An outline read from CAD; ``spec()`` gives it back as the polygon read (self-contained,
    e.g. inside a recording), so the content hash follows the geometry, not the file name."""

    path: str
    units: str
    layer: str | None
    element_id: str | None
    points: tuple[tuple[float, float, float], ...]   # the outline as read: [x, y, bulge] in m
    kind = "file"

    def spec(self) -> dict:
        return {"shape": "polygon", "points": [list(p) for p in self.points], "fillet": 0.0}


def number_field(value, field_name) -> float:
    """A design field's finite number, else refused naming the field."""
    v = finite_number(value)
    if v is None:
        raise DesignError(field_name, value, "must be a finite number")
    return v


def nonnegative_field(value, field_name) -> float:
    v = number_field(value, field_name)
    if v < 0:
        raise DesignError(field_name, v, "must not be negative")
    return v


def shape_kind(spec, field_name: str) -> str:
    """The ``shape`` a hole mapping names (``circle`` when it names none)."""
    if not isinstance(spec, dict):
        raise DesignError(field_name, spec, "must be a mapping (a circle {diameter, center} or {shape: ...})")
    kind = spec.get("shape", "circle")
    if kind not in SHAPES:
        raise DesignError(f"{field_name}.shape", kind, f"unknown shape; known: {list(SHAPES)}")
    for key in spec:
        if key not in _KEYS[kind]:
            raise DesignError(f"{field_name}.{key}", spec[key], f"unknown key for a {kind}; allowed: {sorted(_KEYS[kind])}")
    return kind


def required_field(spec, key, field_name):
    """``spec[key]``, else refused as ``field_name.key`` missing."""
    if key not in spec:
        raise DesignError(f"{field_name}.{key}", None, "missing required field")
    return spec[key]


def parse_sector(spec: dict, field_name: str) -> Sector:
    ri = nonnegative_field(required_field(spec, "inner_radius", field_name), f"{field_name}.inner_radius")
    ro = number_field(required_field(spec, "outer_radius", field_name), f"{field_name}.outer_radius")
    if ro <= ri:
        raise DesignError(f"{field_name}.outer_radius", ro, f"must be larger than inner_radius {ri:g}")
    direction = number_field(required_field(spec, "direction", field_name), f"{field_name}.direction")
    span = number_field(required_field(spec, "span", field_name), f"{field_name}.span")
    if not 0 < span < 360:
        raise DesignError(f"{field_name}.span", span, "must lie in (0, 360) degrees")
    fillet = nonnegative_field(spec.get("fillet", 0.0), f"{field_name}.fillet")
    return Sector(ri, ro, direction, span, fillet)


def parse_points(value, field_name: str) -> tuple[tuple[float, ...], ...]:
    if not isinstance(value, list) or not 2 <= len(value) <= MAX_POINTS:
        raise DesignError(field_name, value, f"must be a list of 2 to {MAX_POINTS} points [x, y] (m)")
    out = []
    for i, p in enumerate(value):
        if not isinstance(p, (list, tuple)) or len(p) not in (2, 3):
            raise DesignError(f"{field_name}[{i}]", p, "must be [x, y] (m) or [x, y, bulge]")
        out.append(tuple(number_field(c, f"{field_name}[{i}][{k}]") for k, c in enumerate(p)))
    return tuple(out)


def parse_polygon(spec: dict, field_name: str) -> PolygonShape:
    points = parse_points(required_field(spec, "points", field_name), f"{field_name}.points")
    fillet = nonnegative_field(spec.get("fillet", 0.0), f"{field_name}.fillet")
    return PolygonShape(points, fillet)


def parse_file(spec: dict, field_name: str, base_dir: Path | None) -> FileShape:
    from .cad import read_outline

    raw = required_field(spec, "path", field_name)
    if not isinstance(raw, str) or not raw:
        raise DesignError(f"{field_name}.path", raw, "must be a file path (DXF or SVG)")
    path = Path(raw)
    if not path.is_absolute():
        path = (base_dir or Path.cwd()) / path
    units = spec.get("units", "mm")
    if units not in ("mm", "m"):
        raise DesignError(f"{field_name}.units", units, "must be 'mm' or 'm'")
    layer, element_id = spec.get("layer"), spec.get("id")
    points = read_outline(path, units, layer, element_id, field_name)
    return FileShape(str(path), units, layer, element_id, points)


def parse_shape(spec: dict, field_name: str, base_dir: Path | None = None):
    """The shape of a non-circular hole mapping (``shape_kind`` already checked the keys)."""
    kind = spec["shape"]
    if kind == "sector":
        return parse_sector(spec, field_name)
    if kind == "polygon":
        return parse_polygon(spec, field_name)
    return parse_file(spec, field_name, base_dir)


# ------------------------------------------------------------------------------ outlines

def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def _arc_bulge(start, end, centre, ccw: bool) -> float:
    """Bulge of the arc about ``centre`` from ``start`` to ``end`` turning as told."""
    a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    a1 = math.atan2(end[1] - centre[1], end[0] - centre[0])
    sweep = (a1 - a0) % (2 * math.pi) if ccw else -((a0 - a1) % (2 * math.pi))
    return math.tan(sweep / 4.0)


def sector_outline(s: Sector, field_name: str = "sector") -> Outline:
    ri, ro, f = s.inner_radius, s.outer_radius, (s.fillet if s.fillet >= MIN_EDGE else 0.0)
    a0 = math.radians(s.direction - 0.5 * s.span)
    a1 = math.radians(s.direction + 0.5 * s.span)
    span = a1 - a0
    if ri * span < MIN_EDGE:   # an inner arc under 1 nm: a pie slice, its tip on the axis a polygon corner
        ri = 0.0
        pts = [(0.0, 0.0, 0.0), (*(ro * _unit(a0)), math.tan(span / 4)), (*(ro * _unit(a1)), 0.0)]
        if f == 0:
            return Outline([p[:2] for p in pts], [p[2] for p in pts])
        # fillet the two outer corners exactly, then the tip as a polygon corner
    if f == 0:
        v = [ri * _unit(a0), ro * _unit(a0), ro * _unit(a1), ri * _unit(a1)]
        return Outline(v, [0.0, math.tan(span / 4), 0.0, -math.tan(span / 4)])
    if f >= 0.5 * (ro - ri):
        raise DesignError(f"{field_name}.fillet", f, f"must be less than half the radial depth {ro - ri:g} m")
    beta_o = math.asin(f / (ro - f))
    if span - 2 * beta_o <= 0:
        raise DesignError(f"{field_name}.fillet", f, "too large for the sector's span at its outer arc")
    verts, bulges = [], []
    # outer corner at a0: fillet from the radial line to the outer arc
    c = (ro - f) * _unit(a0 + beta_o)
    t_line, t_arc = (ro - f) * math.cos(beta_o) * _unit(a0), ro * _unit(a0 + beta_o)
    verts += [t_line, t_arc]
    bulges += [_arc_bulge(t_line, t_arc, c, True), math.tan((span - 2 * beta_o) / 4)]
    c = (ro - f) * _unit(a1 - beta_o)
    t_arc, t_line = ro * _unit(a1 - beta_o), (ro - f) * math.cos(beta_o) * _unit(a1)
    verts += [t_arc, t_line]
    bulges += [_arc_bulge(t_arc, t_line, c, True), 0.0]
    if ri == 0.0:
        inner = _fillet_corners([(0.0, 0.0)], f, field_name, neighbours=(verts[-1], verts[0]))
        verts += [p for p, _ in inner]
        bulges += [b for _, b in inner]
    else:
        beta_i = math.asin(f / (ri + f))
        if span - 2 * beta_i <= 0:
            raise DesignError(f"{field_name}.fillet", f, "too large for the sector's span at its inner arc")
        if (ro - f) * math.cos(beta_o) <= (ri + f) * math.cos(beta_i):
            raise DesignError(f"{field_name}.fillet", f, "too large for the sector's radial edges")
        c = (ri + f) * _unit(a1 - beta_i)
        t_line, t_arc = (ri + f) * math.cos(beta_i) * _unit(a1), ri * _unit(a1 - beta_i)
        verts += [t_line, t_arc]
        bulges += [_arc_bulge(t_line, t_arc, c, True), -math.tan((span - 2 * beta_i) / 4)]
        c = (ri + f) * _unit(a0 + beta_i)
        t_arc, t_line = ri * _unit(a0 + beta_i), (ri + f) * math.cos(beta_i) * _unit(a0)
        verts += [t_arc, t_line]
        bulges += [_arc_bulge(t_arc, t_line, c, True), 0.0]
    return Outline(verts, bulges)


def _fillet_corners(points, f, field_name, neighbours=None):
    """Exact tangent-arc fillets of radius ``f`` at polygon corners (straight edges on both sides).

    ``points``: the corner vertices, counter-clockwise; returns [(vertex, bulge of the edge
    leaving it)] with each corner replaced by its two tangent points and the arc between them.
    ``neighbours`` (prev, next) gives the far ends of the two edges for a single corner."""
    pts = [np.asarray(p[:2], float) for p in points]
    n = len(pts)
    out, tangents = [], []
    for i in range(n):
        v = pts[i]
        prev = np.asarray(neighbours[0], float) if neighbours else pts[i - 1]
        nxt = np.asarray(neighbours[1], float) if neighbours else pts[(i + 1) % n]
        d1, d2 = prev - v, nxt - v
        l1, l2 = float(np.hypot(*d1)), float(np.hypot(*d2))
        d1, d2 = d1 / l1, d2 / l2
        theta = math.acos(max(-1.0, min(1.0, float(d1 @ d2))))   # interior angle between the edges
        a_, b_ = v - prev, nxt - v
        turn = float(a_[0] * b_[1] - a_[1] * b_[0])
        if abs(math.pi - theta) < 1e-9 or f == 0:
            tangents.append((0.0, l1, l2))
            out.append([(v, 0.0)])
            continue
        if theta < 1e-6:
            raise DesignError(f"{field_name}.fillet", f, "a corner is too sharp to fillet")
        t = f / math.tan(0.5 * theta)
        tangents.append((t, l1, l2))
        sweep = math.pi - theta
        bulge = math.tan(sweep / 4) * (1.0 if turn > 0 else -1.0)
        out.append([(v + t * d1, bulge), (v + t * d2, 0.0)])
    if neighbours is None:
        for i in range(n):   # the two fillets on one edge must fit on it
            t_here, _, l_next = tangents[i]
            t_next = tangents[(i + 1) % n][0]
            if t_here + t_next > l_next * (1 + 1e-12):
                raise DesignError(f"{field_name}.fillet", f, f"too large for the edge after point {i}")
    else:
        t, l1, l2 = tangents[0]
        if t > min(l1, l2):
            raise DesignError(f"{field_name}.fillet", f, "too large for the sector's tip")
    return [p for corner in out for p in corner]


def polygon_outline(s: PolygonShape, field_name: str = "polygon", points_field: str | None = None) -> Outline:
    """The outline of a polygon (its points' bulges kept, its corners filleted); refusals name
    ``points_field`` (default ``field_name.points``)."""
    points_field = points_field or f"{field_name}.points"
    pts = np.array([p[:2] for p in s.points], float)
    bulges = np.array([p[2] if len(p) == 3 else 0.0 for p in s.points], float)
    if np.any(np.abs(bulges) >= 1e6):
        raise DesignError(points_field, "bulge", "a bulge must be below 1e6 in size")
    steps = np.hypot(*(np.roll(pts, -1, axis=0) - pts).T)
    if np.any(steps < MIN_EDGE):
        i = int(np.flatnonzero(steps < MIN_EDGE)[0])
        raise DesignError(f"{points_field}[{i}]", list(s.points[i]), "repeats the next point (within 1 nm; an outline "
                                                                       "is closed by itself)")
    if s.fillet < MIN_EDGE:   # a fillet under 1 nm is none
        return _checked(lambda: Outline(pts, bulges), points_field)
    if np.any(bulges != 0):
        raise DesignError(f"{field_name}.fillet", s.fillet, "fillets apply to straight-edged polygons only")
    ccw = Outline(pts)   # oriented counter-clockwise
    filleted = _fillet_corners(ccw.vertices, s.fillet, field_name)
    return _checked(lambda: Outline([p for p, _ in filleted], [b for _, b in filleted]), points_field)


def _checked(build, points_field):
    try:
        return build()
    except (ValueError, ZeroDivisionError) as exc:
        raise DesignError(points_field, "outline", str(exc)) from None


def shape_outline(shape, field_name: str) -> Outline:
    """The exact outline of a non-circular hole, refused unless one simple loop with area."""
    if isinstance(shape, Sector):
        outline, field, value = sector_outline(shape, field_name), f"{field_name}.outer_radius", shape.outer_radius
    elif isinstance(shape, PolygonShape):
        outline, field, value = polygon_outline(shape, field_name), f"{field_name}.points", [list(p) for p in shape.points]
    else:
        outline = polygon_outline(PolygonShape(shape.points), field_name, f"{field_name}.path")
        field, value = f"{field_name}.path", shape.path
    import shapely

    chords = np.hypot(*(np.roll(outline.vertices, -1, axis=0) - outline.vertices).T)
    if chords.min() < MIN_EDGE:
        raise DesignError(field, value, "an edge of the outline is shorter than 1 nm")
    reach = outline.farthest_from_origin()
    if reach > MAX_REACH:   # before any polygon of it is made: a slip of units, not a catheter
        hint = "; drawn in mm? (units: mm)" if isinstance(shape, FileShape) and shape.units == "m" else \
            ": design files are in metres"
        raise DesignError(field, value, f"the outline reaches {reach:.3g} m from the body axis, implausible{hint}")
    poly = outline.shapely
    for p in (poly, outline.polygon(SIMPLE_CHECK_TOLERANCE)):   # at the default chords and within 1 nm of the arcs
        if not p.is_valid:
            raise DesignError(field, value, f"the outline is not simple ({shapely.is_valid_reason(p)})")
    if not outline.area > 0 or not poly.area > 0:
        raise DesignError(field, value, "the outline encloses no area")
    return outline
