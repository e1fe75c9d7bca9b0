"""The actuator's body as a triangle mesh for the live 3D view (no ROS: model_node publishes it).

A tube of the outer diameter swept along the backbone poses (z of each pose is the tangent):
``sides`` vertices per ring, two triangles per quad between neighbouring rings, no end caps.
Each outer ring vertex belongs to the channel lying under it: within the angle the channel's real
outline spans as seen from the body axis (the nearest vertex at least), else to the bare silicone.
Inside it, every hole's real outline (core/geometry: circle, sector, polygon, CAD) is swept the
same way with ``sides`` vertices spaced evenly along it: the channels' walls, and the lumen's.
Channel surfaces are coloured by their pressure as a fraction of max_pressure (blue at 0, red at
the limit), the silicone and the lumen a light grey. The triangle list (3 vertices per triangle, with a colour
each) is what a visualization_msgs/Marker TRIANGLE_LIST carries.
"""
from __future__ import annotations

import math

import numpy as np

SILICONE_RGBA = (0.82, 0.82, 0.80, 0.9)
LOW_RGBA = np.array([0.15, 0.35, 0.95, 1.0])    # channel at 0 Pa
HIGH_RGBA = np.array([0.95, 0.15, 0.10, 1.0])   # channel at max_pressure


def rotate(quats: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Rotate ``vectors`` (..., 3) by unit quaternions (..., 4, xyzw)."""
    q = quats[..., :3]
    w = quats[..., 3:4]
    t = 2.0 * np.cross(q, vectors)
    return vectors + w * t + np.cross(q, t)


def outline_ring(outline, n: int) -> np.ndarray:
    """``n`` points (n, 2), m, evenly spaced along a hole's outline, counter-clockwise."""
    ring = np.asarray(outline.polygon(outline_tolerance(outline)).exterior.coords)[:-1]
    closed = np.vstack([ring, ring[:1]])
    run = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    at = np.linspace(0.0, run[-1], n, endpoint=False)
    return np.column_stack([np.interp(at, run, closed[:, 0]), np.interp(at, run, closed[:, 1])])


def outline_tolerance(outline) -> float:
    """Chord tolerance for drawing: 1e-3 of the outline's size (m)."""
    return 1e-3 * math.sqrt(outline.area)


def outer_owner(angles: np.ndarray, channels) -> np.ndarray:
    """For each outer vertex angle (rad), the channel under it: the one whose outline spans that
    angle as seen from the axis (each channel owns its nearest vertex at least), else -1."""
    owner = np.full(len(angles), -1)
    for i, h in enumerate(channels):
        pts = outline_ring(h.outline, 256)
        mid = math.atan2(h.centroid[1], h.centroid[0])
        rel = (np.arctan2(pts[:, 1], pts[:, 0]) - mid + math.pi) % (2 * math.pi) - math.pi
        d = (angles - mid + math.pi) % (2 * math.pi) - math.pi
        if h.polygon.contains(_origin()):   # a channel round the axis lies under every vertex
            inside = np.ones(len(angles), bool)
        else:
            inside = (d >= rel.min() - 1e-9) & (d <= rel.max() + 1e-9)
        inside[np.argmin(np.abs(d))] = True
        owner[inside & (owner == -1)] = i
    return owner


def _origin():
    from shapely.geometry import Point

    return Point(0.0, 0.0)


class BodyMesh:
    """Fixed topology for ``n_points`` backbone poses; ``update`` gives vertices and colours."""

    def __init__(self, design, n_points: int, sides: int = 12):
        if n_points < 2 or sides < 3:
            raise ValueError("a tube needs at least 2 rings of 3 vertices")
        self.n_points, self.sides = int(n_points), int(sides)
        self.radius = design.outer_radius
        self.max_pressure = design.max_pressure
        a = np.linspace(0.0, 2.0 * math.pi, self.sides, endpoint=False)
        outer = self.radius * np.stack([np.cos(a), np.sin(a)], axis=-1)
        section = design.section
        holes = list(section.channels) + ([section.lumen] if section.lumen is not None else [])
        # the rings: the outer surface, then each hole's outline (vertices evenly along it)
        rings = [outer] + [outline_ring(h.outline, self.sides) for h in holes]
        self._ring = np.concatenate([np.column_stack([r, np.zeros(len(r))]) for r in rings])   # (R * S, 3)
        self.owner = outer_owner(a, section.channels)   # which channel each outer vertex shows (-1: silicone)
        ring_owner = np.concatenate([self.owner] + [np.full(self.sides, i if h.role == "channel" else -1)
                                                    for i, h in enumerate(holes)])
        # Triangles between point j and j+1 of each ring (vertex index = point * R * S + ring * S + side).
        per_point = len(rings) * self.sides
        j, r, s = np.meshgrid(np.arange(self.n_points - 1), np.arange(len(rings)), np.arange(self.sides), indexing="ij")
        v00 = j * per_point + r * self.sides + s
        v01 = j * per_point + r * self.sides + (s + 1) % self.sides
        v10 = v00 + per_point
        v11 = v01 + per_point
        tris = np.stack([np.stack([v00, v10, v11], -1), np.stack([v00, v11, v01], -1)], axis=3)
        self.triangles = tris.reshape(-1, 3)               # (T, 3), the outer surface facing outwards
        self._flat = self.triangles.reshape(-1)
        self._vertex_owner = np.tile(ring_owner, self.n_points)[self._flat]   # per triangle-list vertex
        self._per_point = per_point

    @property
    def n_vertices(self) -> int:
        """Vertices in the triangle list (3 per triangle)."""
        return self._flat.size

    def vertices(self, positions: np.ndarray, quats: np.ndarray) -> np.ndarray:
        """Ring vertices (n_points * rings * sides, 3), m, in the backbone's frame: per backbone point
        the outer ring first, then the holes' (channels in command order, then the lumen)."""
        ring = rotate(quats[:, None, :], np.broadcast_to(self._ring, (len(positions), self._per_point, 3)))
        return (positions[:, None, :] + ring).reshape(-1, 3)

    def channel_colours(self, pressures) -> np.ndarray:
        """RGBA per channel (C, 4) from the pressures, Pa (clipped to [0, max_pressure])."""
        f = np.clip(np.asarray(pressures, dtype=float) / self.max_pressure, 0.0, 1.0)[:, None]
        return (1.0 - f) * LOW_RGBA + f * HIGH_RGBA

    def triangle_list(self, positions, quats, pressures, out_points=None, out_colours=None):
        """(points (3T, 3), colours (3T, 4)) of the body; written into ``out_*`` when given."""
        v = self.vertices(np.asarray(positions, dtype=float), np.asarray(quats, dtype=float))
        points = np.take(v, self._flat, axis=0, out=out_points)
        palette = np.vstack([self.channel_colours(pressures), SILICONE_RGBA])   # owner -1 -> last row
        colours = np.take(palette, self._vertex_owner, axis=0, out=out_colours)
        return points, colours

