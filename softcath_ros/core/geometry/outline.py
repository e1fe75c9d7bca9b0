"""Closed outlines made of straight edges and circular arcs, kept exact.

An outline is a loop of vertices, each with the bulge of the edge that leaves it (the DXF
convention: bulge = tan(sweep / 4); 0 is a straight edge, > 0 an arc turning counter-clockwise,
< 0 clockwise; a full circle is two vertices with bulge 1). This is the exact primitive a mesher
or CAD kernel can rebuild curved edges from; ``polygon(tolerance)`` is a polygonal
approximation whose vertices lie on the true edges and whose chords stray from the arcs by at
most ``tolerance`` (m). Areas, first and second moments are exact integrals over the lines and
arcs (Green's theorem: polygon terms plus a closed form per circular segment), so a circle's
section properties are those of the circle, not of a polygon.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

# Largest distance (m) between an arc and the chords that approximate it in ``polygon()``.
CHORD_TOLERANCE = 1.0e-7


@dataclass(frozen=True)
class Arc:
    """A circular edge: from ``start`` to ``end`` about ``center``, sweeping ``sweep`` rad
    (positive counter-clockwise)."""

    start: tuple[float, float]
    end: tuple[float, float]
    center: tuple[float, float]
    radius: float
    sweep: float

    @property
    def start_angle(self) -> float:
        return math.atan2(self.start[1] - self.center[1], self.start[0] - self.center[0])

    def contains_angle(self, angle: float) -> bool:
        """Whether the direction ``angle`` (rad, from the centre) lies on the arc."""
        rel = (angle - self.start_angle) % (2 * math.pi)
        if self.sweep < 0:
            rel = (2 * math.pi - rel) % (2 * math.pi)
        return rel <= abs(self.sweep) + 1e-12


@dataclass(frozen=True)
class Line:
    start: tuple[float, float]
    end: tuple[float, float]


@dataclass(frozen=True)
class SectionIntegrals:
    """Integrals over an area about the origin: A, (int x, int y), [[int xx, int xy], [int xy, int yy]]."""

    area: float
    first: np.ndarray      # (2,) m^3
    second: np.ndarray     # (2, 2) m^4

    @property
    def centroid(self) -> np.ndarray:
        return self.first / self.area

    @property
    def centroidal_second(self) -> np.ndarray:
        """Second moments about the centroid, J_ab = int (r - c)_a (r - c)_b dA (m^4)."""
        c = self.centroid
        return self.second - self.area * np.outer(c, c)


def arc_of(p0, p1, bulge: float) -> Arc:
    """The arc an edge of the given bulge draws from ``p0`` to ``p1``."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    chord = p1 - p0
    length = float(np.hypot(*chord))
    sweep = 4.0 * math.atan(bulge)
    alpha = 0.5 * abs(sweep)
    radius = length / (2.0 * math.sin(alpha))
    left = np.array([-chord[1], chord[0]]) / length
    centre = 0.5 * (p0 + p1) + math.copysign(1.0, bulge) * radius * math.cos(alpha) * left
    return Arc(tuple(p0), tuple(p1), tuple(centre), radius, sweep)


def rotation_matrix(angle: float) -> np.ndarray:
    """The turn by ``angle`` (rad, counter-clockwise) about the origin."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def mirror_matrix(angle: float) -> np.ndarray:
    """The reflection in the line through the origin at ``angle`` (rad from +x)."""
    c, s = math.cos(2 * angle), math.sin(2 * angle)
    return np.array([[c, s], [s, -c]])


_GAUSS_U, _GAUSS_W = np.polynomial.legendre.leggauss(24)
# Below this half-angle (rad) a segment is integrated over its chord (sector minus triangle would
# lose digits to cancellation on a flat arc of a large circle).
_FLAT_ARC = 0.5
# An arc whose sagitta is below this (m) is a straight edge.
FLAT_SAGITTA = 1e-12


def _segment_integrals(arc: Arc) -> tuple[float, np.ndarray, np.ndarray]:
    """Signed integrals over the circular segment between an arc and its chord (the part an arc
    adds to, or for a clockwise arc takes from, the polygon of the vertices)."""
    r, alpha = arc.radius, 0.5 * abs(arc.sweep)
    p0, p1 = np.asarray(arc.start), np.asarray(arc.end)
    mid_angle = arc.start_angle + 0.5 * arc.sweep
    if alpha < _FLAT_ARC:
        # chord frame: origin at the chord's midpoint, u along the chord, v towards the arc;
        # height of the arc over the chord h(u) = (L^2/4 - u^2) / (sqrt(r^2 - u^2) + r cos(alpha))
        half = 0.5 * float(np.hypot(*(p1 - p0)))
        u = half * _GAUSS_U
        w = half * _GAUSS_W
        h = (half * half - u * u) / (r * np.sqrt(1.0 - (u / r) ** 2) + r * math.cos(alpha))
        area = float(w @ h)
        s_loc = np.array([w @ (u * h), w @ (h * h) / 2.0])
        m_loc = np.array([[w @ (u * u * h), w @ (u * h * h) / 2.0], [w @ (u * h * h) / 2.0, w @ (h**3) / 3.0]])
        e_u = (p1 - p0) / (2.0 * half)
        e_v = np.array([math.cos(mid_angle), math.sin(mid_angle)])
        rot = np.column_stack([e_u, e_v])
        origin = 0.5 * (p0 + p1)
    else:
        # circle frame: origin at the centre, x towards the arc's midpoint; sector minus triangle
        s, c = math.sin(alpha), math.cos(alpha)
        area = alpha * r * r - r * r * s * c
        s_loc = np.array([2.0 / 3.0 * r**3 * s - 2.0 / 3.0 * r**3 * s * c * c, 0.0])
        ixx = r**4 / 4.0 * (alpha + s * c) - r**4 * s * c**3 / 2.0
        iyy = r**4 / 4.0 * (alpha - s * c) - r**4 * s**3 * c / 6.0
        m_loc = np.diag([ixx, iyy])
        rot = np.array([[math.cos(mid_angle), -math.sin(mid_angle)], [math.sin(mid_angle), math.cos(mid_angle)]])
        origin = np.asarray(arc.center)
    s_rot = rot @ s_loc
    second = rot @ m_loc @ rot.T + np.outer(origin, s_rot) + np.outer(s_rot, origin) + area * np.outer(origin, origin)
    sign = math.copysign(1.0, arc.sweep)
    return sign * area, sign * (area * origin + s_rot), sign * second


class Outline:
    """A closed outline (m): ``vertices`` (N, 2) and ``bulges`` (N,), oriented counter-clockwise."""

    def __init__(self, vertices, bulges=None):
        v = np.asarray(vertices, dtype=float).reshape(-1, 2)
        b = np.zeros(len(v)) if bulges is None else np.asarray(bulges, dtype=float).reshape(-1)
        if len(b) != len(v):
            raise ValueError("one bulge per vertex")
        chords = np.hypot(*(np.roll(v, -1, axis=0) - v).T)
        b = np.where(np.abs(b) * 0.5 * chords < FLAT_SAGITTA, 0.0, b)   # an arc flatter than a picometre is a line
        if len(v) < 2 or (len(v) == 2 and not np.any(b != 0)):
            raise ValueError("an outline needs at least three vertices, or two with an arc between them")
        self.vertices, self.bulges = v, b
        integrals = self._integrals()
        if integrals.area < 0:        # keep every outline counter-clockwise (the integrals change sign)
            self.vertices, self.bulges = v[::-1].copy(), -np.roll(b[::-1], -1)
            del self._edges   # the edges of the other orientation
            integrals = SectionIntegrals(-integrals.area, -integrals.first, -integrals.second)
        self.integrals = integrals
        self.vertices.setflags(write=False)
        self.bulges.setflags(write=False)

    # ---------------------------------------------------------------- construction
    @classmethod
    def circle(cls, center, radius: float) -> "Outline":
        cx, cy = center
        return cls([(cx + radius, cy), (cx - radius, cy)], [1.0, 1.0])

    def transformed(self, matrix, offset=(0.0, 0.0)) -> "Outline":
        """The outline under x -> M x + t (a mirror reverses the arcs' turning)."""
        m = np.asarray(matrix, float)
        flip = np.linalg.det(m) < 0
        return Outline(self.vertices @ m.T + np.asarray(offset, float), -self.bulges if flip else self.bulges)

    def rotated(self, angle: float) -> "Outline":
        return self.transformed(rotation_matrix(angle))

    def mirrored(self, angle: float) -> "Outline":
        """Mirrored about the line through the origin at ``angle`` (rad from +x)."""
        return self.transformed(mirror_matrix(angle))

    # ---------------------------------------------------------------- edges
    def edges(self) -> list[Line | Arc]:
        """The exact edges in order: ``Line`` or ``Arc`` (a new list of the kept edges)."""
        return list(self._edges)

    @cached_property
    def _edges(self) -> tuple[Line | Arc, ...]:
        out = []
        n = len(self.vertices)
        for i in range(n):
            p0, p1, b = self.vertices[i], self.vertices[(i + 1) % n], self.bulges[i]
            out.append(Line(tuple(p0), tuple(p1)) if b == 0 else arc_of(p0, p1, b))
        return tuple(out)

    @property
    def is_circle(self) -> bool:
        return len(self.vertices) == 2 and bool(np.all(np.abs(self.bulges - self.bulges[0]) < 1e-12)) \
            and abs(abs(self.bulges[0]) - 1.0) < 1e-12

    def polygon_points(self, tolerance: float = CHORD_TOLERANCE, side: str = "on") -> np.ndarray:
        """Vertices of a polygonal approximation (M, 2), counter-clockwise, not repeated at the end,
        within ``tolerance`` (m) of every arc. ``side``: ``on`` (vertices on the arcs, chords
        between), ``outside`` (a polygon containing the outline: tangent lines round arcs that bulge
        out, chords of arcs that bulge in) or ``inside`` (a polygon inside the outline)."""
        if side not in ("on", "outside", "inside"):
            raise ValueError(f"side must be 'on', 'outside' or 'inside', not {side!r}")
        pts = []
        for e in self._edges:
            pts.append(e.start)
            if isinstance(e, Line):
                continue
            step = 2.0 * math.acos(max(-1.0, 1.0 - tolerance / e.radius)) if tolerance < e.radius else math.pi
            sagitta = e.radius * (1.0 - math.cos(0.5 * e.sweep))
            n = 1 if sagitta <= tolerance else max(1, math.ceil(abs(e.sweep) / step - 1e-9))
            tangents = side != "on" and (side == "outside") == (e.sweep > 0)
            if not tangents:
                t = e.start_angle + e.sweep * np.arange(1, n) / n
                radius = e.radius
            else:   # the corners of tangent lines, each piece at most a quarter turn
                n = max(n, math.ceil(abs(e.sweep) / (0.5 * math.pi) - 1e-9))
                t = e.start_angle + e.sweep * (np.arange(n) + 0.5) / n
                radius = e.radius / math.cos(0.5 * e.sweep / n)
            pts.extend(zip(e.center[0] + radius * np.cos(t), e.center[1] + radius * np.sin(t)))
        return np.asarray(pts, dtype=float)

    def polygon(self, tolerance: float = CHORD_TOLERANCE, side: str = "on"):
        """The shapely polygon of ``polygon_points(tolerance, side)``."""
        from shapely.geometry import Polygon

        return Polygon(self.polygon_points(tolerance, side))

    @cached_property
    def shapely(self):
        """``polygon()`` at the default chord tolerance (cached)."""
        return self.polygon()

    # ---------------------------------------------------------------- integrals
    def _integrals(self) -> SectionIntegrals:
        """Exact area, first and second moments about the origin of the enclosed area (signed by
        the orientation; ``integrals`` holds them for the counter-clockwise outline)."""
        v = self.vertices
        x0, y0 = v[:, 0], v[:, 1]
        x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
        cross = x0 * y1 - x1 * y0
        area = 0.5 * cross.sum()
        first = np.array([((x0 + x1) * cross).sum(), ((y0 + y1) * cross).sum()]) / 6.0
        ixx = ((x0 * x0 + x0 * x1 + x1 * x1) * cross).sum() / 12.0
        iyy = ((y0 * y0 + y0 * y1 + y1 * y1) * cross).sum() / 12.0
        ixy = ((x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) * cross).sum() / 24.0
        second = np.array([[ixx, ixy], [ixy, iyy]])
        for e in self._edges:
            if isinstance(e, Arc):
                a, s, m = _segment_integrals(e)
                area, first, second = area + a, first + s, second + m
        return SectionIntegrals(float(area), first, second)

    @property
    def area(self) -> float:
        return self.integrals.area

    @property
    def centroid(self) -> np.ndarray:
        return self.integrals.centroid

    # ---------------------------------------------------------------- distances
    def distance_to_point(self, p) -> float:
        """Exact shortest distance from ``p`` to the outline's edges (not signed)."""
        p = np.asarray(p, float)
        best = math.inf
        for e in self._edges:
            a, b = np.asarray(e.start), np.asarray(e.end)
            if isinstance(e, Line):
                d = b - a
                t = 0.0 if not d.any() else min(1.0, max(0.0, float((p - a) @ d / (d @ d))))
                best = min(best, float(np.hypot(*(a + t * d - p))))
            else:
                q = p - np.asarray(e.center)
                rho = float(np.hypot(*q))
                if rho > 0 and e.contains_angle(math.atan2(q[1], q[0])):
                    best = min(best, abs(rho - e.radius))
                else:
                    best = min(best, float(np.hypot(*(a - p))), float(np.hypot(*(b - p))))
        return best

    def farthest_from_origin(self) -> float:
        """Exact largest distance of the outline from the origin (the body axis)."""
        far = float(np.max(np.hypot(self.vertices[:, 0], self.vertices[:, 1])))
        for e in self._edges:
            if isinstance(e, Arc):
                c = np.asarray(e.center)
                rho = float(np.hypot(*c))
                if rho == 0 or e.contains_angle(math.atan2(c[1], c[0])):
                    far = max(far, rho + e.radius)
        return far

    def contains(self, p) -> bool:
        """Whether ``p`` lies inside the exact outline (within a picometre of it counts as on it, not
        inside): decided on a polygon whose chords stray from the arcs by less than ``p``'s distance."""
        from shapely.geometry import Point

        d = self.distance_to_point(p)
        if d < 1e-12:
            return False
        poly = self.shapely if d > 2.0 * CHORD_TOLERANCE else self.polygon(0.5 * d)
        return bool(poly.contains(Point(*p)))

    def __repr__(self) -> str:
        return f"Outline({len(self.vertices)} vertices, {int(np.count_nonzero(self.bulges))} arcs)"
