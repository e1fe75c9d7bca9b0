"""The actuator's body as a triangle mesh for the live 3D view (no ROS: model_node publishes it).

A tube of the outer diameter swept along the backbone poses (z of each pose is the tangent):
``sides`` vertices per ring, two triangles per quad between neighbouring rings, no end caps.
Each ring vertex belongs to the channel whose centre it faces (within the angular sector
0.6 of the way to the next channel; for one channel +-60 degrees), else to the bare silicone.
Channel surface is coloured by its pressure as a fraction of max_pressure (blue at 0, red at
the limit), the silicone a light grey. The triangle list (3 vertices per triangle, with a colour
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


class BodyMesh:
    """Fixed topology for ``n_points`` backbone poses; ``update`` gives vertices and colours."""

    def __init__(self, design, n_points: int, sides: int = 12):
        if n_points < 2 or sides < 3:
            raise ValueError("a tube needs at least 2 rings of 3 vertices")
        self.n_points, self.sides = int(n_points), int(sides)
        self.radius = design.outer_radius
        self.max_pressure = design.max_pressure
        a = np.linspace(0.0, 2.0 * math.pi, self.sides, endpoint=False)
        self._ring = self.radius * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)  # (S, 3)
        # Which channel each ring vertex shows (-1: silicone).
        centres = np.array([math.atan2(c.center[1], c.center[0]) for c in design.channels])
        half = 0.6 * math.pi / len(centres) if len(centres) > 1 else math.radians(60.0)
        d = np.abs((a[None, :] - centres[:, None] + math.pi) % (2.0 * math.pi) - math.pi)   # (C, S)
        self.owner = np.where(d.min(axis=0) <= half + 1e-9, d.argmin(axis=0), -1)
        owner = self.owner
        # Triangles between ring j and j+1 (vertex index = ring * S + side).
        j, s = np.meshgrid(np.arange(self.n_points - 1), np.arange(self.sides), indexing="ij")
        v00 = j * self.sides + s
        v01 = j * self.sides + (s + 1) % self.sides
        v10 = v00 + self.sides
        v11 = v01 + self.sides
        tris = np.stack([np.stack([v00, v10, v11], -1), np.stack([v00, v11, v01], -1)], axis=2)
        self.triangles = tris.reshape(-1, 3)               # (T, 3), outward-facing winding
        self._flat = self.triangles.reshape(-1)
        self._vertex_owner = np.tile(owner, self.n_points)[self._flat]   # per triangle-list vertex

    @property
    def n_vertices(self) -> int:
        """Vertices in the triangle list (3 per triangle)."""
        return self._flat.size

    def vertices(self, positions: np.ndarray, quats: np.ndarray) -> np.ndarray:
        """Ring vertices (n_points * sides, 3), m, in the backbone's frame."""
        ring = rotate(quats[:, None, :], np.broadcast_to(self._ring, (len(positions), self.sides, 3)))
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

