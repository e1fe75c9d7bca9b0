"""The walls of a section as exact pieces for the mesher (section_fe/mesh.py): lines and circular
arcs in units of the outer radius, each able to give its points, project onto itself, be cut at a
parameter and say where a ray from the body axis (a symmetry wedge's edge) crosses it."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# x R: a wall point this near a wedge ray is on it (the ray's angle is rounded to 1e-6 deg, so a
# corner on a mirror line can be ~1e-8 R off it); a ray crossing a piece this near its end is its end
ON_RAY = 1e-7


@dataclass(frozen=True)
class Arc:
    """A circular arc: centre, radius, start angle and signed sweep (rad, > 0 counter-clockwise)."""
    center: tuple[float, float]
    radius: float
    start: float
    sweep: float

    @property
    def length(self) -> float:
        return self.radius * abs(self.sweep)

    def point(self, t) -> np.ndarray:
        a = self.start + self.sweep * np.asarray(t, float)
        return np.stack([self.center[0] + self.radius * np.cos(a), self.center[1] + self.radius * np.sin(a)], -1)

    def project(self, p: np.ndarray) -> np.ndarray:
        v = p - np.asarray(self.center)
        return np.asarray(self.center) + self.radius * v / np.linalg.norm(v, axis=-1, keepdims=True)

    def sub(self, t0: float, t1: float) -> "Arc":
        return Arc(self.center, self.radius, self.start + self.sweep * t0, self.sweep * (t1 - t0))

    def scaled(self, f: float) -> "Arc":
        return Arc((self.center[0] * f, self.center[1] * f), self.radius * f, self.start, self.sweep)

    def ray_hits(self, e: np.ndarray) -> list[float]:
        """Parameters t in (0, 1) where the ray {r e, r > 0} crosses the arc."""
        c = np.asarray(self.center)
        ec, cc = float(e @ c), float(c @ c)
        disc = ec * ec - cc + self.radius ** 2
        if disc <= 0:
            return []
        out = []
        for r in (ec - math.sqrt(disc), ec + math.sqrt(disc)):
            if r < -1e-12:          # the origin is on the ray (a wall through the axis is cut there)
                continue
            q = r * e - c
            a = (math.atan2(q[1], q[0]) - self.start) * np.sign(self.sweep) % (2 * math.pi)
            t = a / abs(self.sweep)
            if ON_RAY < t * self.length and ON_RAY < (1 - t) * self.length:
                out.append(t)
        return out


@dataclass(frozen=True)
class Line:
    """A straight segment from a to b."""
    a: tuple[float, float]
    b: tuple[float, float]

    @property
    def length(self) -> float:
        return math.dist(self.a, self.b)

    def point(self, t) -> np.ndarray:
        t = np.asarray(t, float)[..., None]
        return (1 - t) * np.asarray(self.a) + t * np.asarray(self.b)

    def project(self, p: np.ndarray) -> np.ndarray:
        a, d = np.asarray(self.a), np.asarray(self.b) - np.asarray(self.a)
        return a + (((p - a) @ d) / (d @ d))[..., None] * d

    def sub(self, t0: float, t1: float) -> "Line":
        return Line(tuple(self.point(t0).tolist()), tuple(self.point(t1).tolist()))

    def scaled(self, f: float) -> "Line":
        return Line((self.a[0] * f, self.a[1] * f), (self.b[0] * f, self.b[1] * f))

    def ray_hits(self, e: np.ndarray) -> list[float]:
        a, d = np.asarray(self.a), np.asarray(self.b) - np.asarray(self.a)
        den = d[0] * e[1] - d[1] * e[0]
        if abs(den) < 1e-15 * max(1.0, float(d @ d)):
            return []
        t = (a[1] * e[0] - a[0] * e[1]) / den
        r = float((a + t * d) @ e)
        inside = ON_RAY < t * self.length and ON_RAY < (1 - t) * self.length
        return [float(t)] if inside and r > -1e-12 else []


Piece = Arc | Line


def wall_pieces(outline, scale: float, start: float) -> list[Piece]:
    """The outline's exact edges (``geometry.Outline.edges``) as pieces, lengths times ``scale``;
    a circle as one arc from the direction ``start`` (degrees: it turns with the design)."""
    from ..geometry import Line as OutlineLine

    if outline.is_circle:
        e = outline.edges()[0]
        return [Arc(tuple(e.center), e.radius, math.radians(start), 2 * math.pi).scaled(scale)]
    out: list[Piece] = []
    for e in outline.edges():
        if isinstance(e, OutlineLine):
            out.append(Line(tuple(e.start), tuple(e.end)).scaled(scale))
        else:
            out.append(Arc(tuple(e.center), e.radius, e.start_angle, e.sweep).scaled(scale))
    return out
