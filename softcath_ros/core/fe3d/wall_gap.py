"""The lumen wall's geometric gap check in the 3D problem (LumenContact.min_gap): the wall sampled
along each mesh level's section, the deformed section rings in their own planes, and the smallest
distance between two points of a ring that are not neighbours along it (negative where it crosses
itself). Independent of the contact's pairs: it sees walls that pass through each other anywhere."""
from __future__ import annotations

import math

import numpy as np

# wall points per mesh edge of the lumen wall in the geometric gap check: its chords cut the
# curved wall, most at a shoulder folded tight; at the 20 mm default mesh's 0.2397 bar state
# 4 per edge read a crossing of 6.5 um, 8 / 16 / 32 read 5.2 / 0.85 / 0.82 um (0.1 s per check at 16)
SAMPLES = 16


class WallSampling:
    """Reference points of the lumen wall for the geometric gap check: ``ring`` (n, 2), SAMPLES
    points per wall edge of the section in order around the lumen (the half model's half wall,
    mirrored later), ``levels`` the mesh levels' z (m), and per level three rings stacked in
    ``ref`` (m): at the level and a quarter layer above and below it (the deformed axis there). The
    points are located in the mesh once (``located``): locating them cost ten times evaluating
    the displacement there."""

    def __init__(self, ring: np.ndarray, levels: np.ndarray, length: float):
        self.ring, self.levels = ring, np.asarray(levels, dtype=float)
        dz = 0.25 * (self.levels[1] - self.levels[0]) if len(self.levels) > 1 else 1e-4
        zs = np.column_stack([self.levels, np.minimum(self.levels + dz, length), np.maximum(self.levels - dz, 0.0)])
        n = len(ring)
        self.ref = np.column_stack([np.tile(ring, (zs.size, 1)), np.repeat(zs.ravel(), n)])
        self.located = None

    def deformed(self, problem) -> np.ndarray:
        """(levels, 3, n, 3): the deformed points (m) of the rings at, above and below each level."""
        if self.located is None:
            self.located = problem.mesh(self.ref[:, 0], self.ref[:, 1], self.ref[:, 2])
        cur = self.ref + np.asarray(problem.u(self.located)).reshape(len(self.ref), 3)
        return cur.reshape(len(self.levels), 3, len(self.ring), 3)


def wall_sampling(problem) -> WallSampling:
    """The lumen wall's WallSampling for ``problem``."""
    from .measure import lumen_wall_nodes

    pts, levels = lumen_wall_nodes(problem)
    closed = not problem.half
    nxt = np.roll(pts, -1, axis=0) if closed else pts[1:]
    start = pts if closed else pts[:-1]
    t = np.arange(SAMPLES) / SAMPLES
    ring = (start[:, None, :] * (1 - t)[None, :, None] + nxt[:, None, :] * t[None, :, None]).reshape(-1, 2)
    if not closed:
        ring = np.vstack([ring, pts[-1:]])
    return WallSampling(ring, levels, problem.design.length)


def _closed_ring(problem, cur: np.ndarray) -> np.ndarray:
    """A deformed ring (n, 3) closed by its mirror image on the half model."""
    if problem.half:
        back = cur[::-1].copy()
        back[:, 0] *= -1.0
        cur = np.vstack([cur, back[1:-1]])
    return cur


def section_rings(problem, sampling: WallSampling) -> list:
    """Each deformed section ring of the lumen wall (closed by its mirror image on the half model) in
    the plane normal to the deformed axis there, about its centroid: (m, 2) in-plane coordinates, m,
    per mesh level. The body's bending moves them only through the section's own deformation."""
    out = []
    for rings in sampling.deformed(problem):
        cur, above, below = (_closed_ring(problem, r) for r in rings)
        centre = cur.mean(axis=0)
        # the deformed section's plane: normal to the body's deformed axis there (a best-fit
        # plane would tilt out of a closed slit, whose points are nearly on one curve)
        axis = (above - below).mean(axis=0)
        axis /= np.linalg.norm(axis)
        e1 = np.array([1.0, 0.0, 0.0]) - axis[0] * axis
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        out.append((cur - centre) @ np.column_stack([e1, e2]))
    return out


def min_wall_gap(problem, sampling: WallSampling) -> float:
    """See LumenContact.min_gap. Each section ring (``section_rings``) is tested for crossings with
    the section rung's polygon test."""
    return min((polygon_gap(P, 2 * SAMPLES) for P in section_rings(problem, sampling)), default=math.inf)


def polygon_gap(P: np.ndarray, skip: int) -> float:
    """A closed polygon's (P: (m, 2), segment k from vertex k to k + 1) smallest distance from a
    vertex to a segment at least ``skip`` segments away along it, or, when two segments at least 2
    apart properly cross, minus the largest crossing depth (per crossing pair the smallest distance
    of an end point of one to the other). Exact, as the all-pairs test, but only pairs of segments
    near each other are tested (a k-d tree on the segments' midpoints): a segment within r of a
    point has its midpoint within r + half the longest segment."""
    from scipy.spatial import cKDTree

    from ..section_fe.terms.contact import point_segment_distance, segments_cross

    m = len(P)
    nxt = np.roll(P, -1, axis=0)
    half = 0.5 * float(np.max(np.linalg.norm(nxt - P, axis=1)))
    tree = cKDTree(0.5 * (P + nxt))
    # crossings: segments whose midpoints lie within the two half lengths of each other
    pairs = tree.query_pairs(2.0 * half * (1.0 + 1e-9) + 1e-300, output_type="ndarray")
    if len(pairs):
        i, k = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
        apart = (k - i >= 2) & (k - i <= m - 2)
        i, k = i[apart], k[apart]
        crossing = segments_cross(P, i, k)
        if np.any(crossing):
            i, k = i[crossing], k[crossing]
            a, b, c, e = P[i], P[(i + 1) % m], P[k], P[(k + 1) % m]
            depth = np.min(np.stack([point_segment_distance(a, c, e), point_segment_distance(b, c, e),
                                     point_segment_distance(c, a, b), point_segment_distance(e, a, b)]), axis=0)
            return -max(float(np.max(depth)), 1e-15)
    # distances: grow the radius r until some allowed pair lies within it (then none beyond can be nearer)
    vertices = cKDTree(P)
    span = float(np.max(np.ptp(P, axis=0))) if m else 0.0
    r = max(4.0 * half, span / 16.0)
    while True:
        near = vertices.sparse_distance_matrix(tree, r + half, output_type="ndarray")
        vi, sj = near["i"].astype(np.intp), near["j"].astype(np.intp)
        off = (sj - vi) % m
        keep = (off >= skip) & (off <= m - skip - 1)
        d = point_segment_distance(P[vi[keep]], P[sj[keep]], P[(sj[keep] + 1) % m]) if keep.any() else np.empty(0)
        if len(d) and float(np.min(d)) <= r:
            return float(np.min(d))
        if r > 2.0 * span + 4.0 * half:
            return float(np.min(d)) if len(d) else math.inf
        r *= 2.0
