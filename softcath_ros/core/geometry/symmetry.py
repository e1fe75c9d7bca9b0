"""Symmetry of a section found from its outlines (never assumed from a channel count).

``symmetry(section)`` returns the mirror lines through the body axis and the largest n-fold
rotation that map the section onto itself: every hole onto a hole of the same role (the
permutation says which), the fibre onto itself. Two outlines match when their polygons lie within
``tolerance`` of each other (Hausdorff distance; default 2 um), so a shape drawn with other vertices,
or positions typed to the micrometre, still count. A candidate mirror or turn moves each hole's
centroid and polygon points (no new outline); the answer is kept in memory per section content.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .outline import Outline, mirror_matrix, rotation_matrix
from .section import Section

MAX_ORDER = 12
# m: outlines this close after a mirror or turn are the same (positions typed to the micrometre are
# each within 0.7 um of where they were meant: two of them within 1.4 um)
SYMMETRY_TOLERANCE = 2e-6


@dataclass(frozen=True)
class Mirror:
    angle: float                      # rad in [0, pi): the mirror line's direction from +x
    permutation: tuple[int, ...]      # hole i lands on hole permutation[i]

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the mirror plane (in the section)."""
        return np.array([-math.sin(self.angle), math.cos(self.angle)])


@dataclass(frozen=True)
class Symmetry:
    mirrors: tuple[Mirror, ...]
    rotation_order: int                       # 1: none; n: the section maps onto itself turned by 360/n deg
    rotation_permutation: tuple[int, ...]     # hole i lands on this hole under one turn of 360/n deg

    def has_mirror(self, angle: float, tol: float = 1e-9) -> Mirror | None:
        """The mirror along ``angle`` (rad) if the section has it."""
        for m in self.mirrors:
            d = (angle - m.angle) % math.pi
            if min(d, math.pi - d) <= tol:
                return m
        return None


class _Placed:
    """A hole as the search reads it, computed once per section: role, area,
    centroid and the points of its polygon (chords within ``tol / 4``). An isometry keeps the area
    and moves the centroid and the points, so a candidate is tested without building a new outline."""

    def __init__(self, role: str, outline: Outline, tol: float):
        self.role = role
        self.area = outline.integrals.area
        self.centroid = outline.integrals.centroid
        self.points = outline.polygon_points(tol / 4)
        self._polygon = None

    @property
    def polygon(self):
        if self._polygon is None:
            import shapely

            self._polygon = shapely.polygons(self.points)
        return self._polygon


def _alike(area: float, centroid: np.ndarray, other: _Placed) -> bool:
    """Cheap first test: about the same area and place (the outlines decide, ``_matches``)."""
    size = math.sqrt(max(area, other.area))
    return abs(area - other.area) <= 0.05 * max(area, other.area) and \
        float(np.hypot(*(centroid - other.centroid))) <= 0.05 * size


def _matches(holes: list[_Placed], fibre_center, matrix: np.ndarray, tol: float):
    """The hole permutation under x -> ``matrix`` x (a mirror or turn about the body axis), or None
    if it fails."""
    import shapely

    perm = []
    for hole in holes:
        centroid = matrix @ hole.centroid
        moved = None
        found = None
        for j, other in enumerate(holes):
            if other.role != hole.role or j in perm or not _alike(hole.area, centroid, other):
                continue
            # the outlines themselves: within tol of each other (their polygons' chords within tol / 4)
            if moved is None:
                moved = shapely.polygons(hole.points @ matrix.T)
            if moved.hausdorff_distance(other.polygon) <= 1.5 * tol:
                found = j
                break
        if found is None:
            return None
        perm.append(found)
    if fibre_center is not None and np.hypot(*(matrix @ fibre_center - fibre_center)) > tol:
        return None
    return tuple(perm)


def _candidate_mirror_angles(section: Section) -> list[float]:
    points = [h.centroid for h in section.holes] + ([np.asarray(section.fibre.center)] if section.fibre else [])
    angles = []
    small = 1e-9 * section.outer_radius
    dirs = [math.atan2(p[1], p[0]) for p in points if np.hypot(*p) > small]
    angles += dirs
    angles += [0.5 * (a + b) for i, a in enumerate(dirs) for b in dirs[i + 1:]]
    for h in section.holes:   # a hole on the axis: its principal axes
        if np.hypot(*h.centroid) <= small:
            j = h.outline.integrals.centroidal_second
            w, v = np.linalg.eigh(j)
            if w[1] - w[0] > 1e-9 * abs(w[1]):   # a circle on the axis has no axes of its own
                angles += [math.atan2(v[1, k], v[0, k]) for k in range(2)]
    if not angles:
        angles = [0.0]
    angles += [a + math.pi / 2 for a in angles]
    return _distinct(angles, 1e-9)


def _distinct(angles, gap: float) -> list[float]:
    """Mirror-line angles folded into [0, pi), those within ``gap`` rad of another dropped."""
    out = []
    for a in sorted(a % math.pi for a in angles):
        if not out or min(abs(a - out[-1]), math.pi - abs(a - out[-1])) > gap:
            out.append(a)
    if len(out) > 1 and math.pi - out[-1] + out[0] <= gap:
        out.pop()
    return out


def symmetry(section: Section, tolerance: float | None = None) -> Symmetry:
    """Mirror lines and rotation order of ``section``: outlines that land within ``tolerance`` (m;
    default ``SYMMETRY_TOLERANCE``, at most 1e-3 of the radius) of each other match, so a design
    typed to the micrometre keeps its symmetry. Found once per section content (kept in memory)."""
    tol = min(SYMMETRY_TOLERANCE, 1e-3 * section.outer_radius) if tolerance is None else tolerance
    return _symmetry_of(_SectionKey(section, tol))


class _SectionKey:
    """What the symmetry depends on, hashable: the radius, each hole's role, exact outline
    (vertices and bulges) and centroid, the fibre and the tolerance; carries the section to search."""

    def __init__(self, section: Section, tol: float):
        self.section, self.tol = section, tol
        f = section.fibre
        self.key = (float(section.outer_radius), float(tol),
                    tuple((h.role, h.outline.vertices.tobytes(), h.outline.bulges.tobytes(),
                           np.asarray(h.centroid, dtype=float).tobytes()) for h in section.holes),
                    None if f is None else (float(f.center[0]), float(f.center[1]), float(f.radius)))

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other) -> bool:
        return isinstance(other, _SectionKey) and self.key == other.key


@lru_cache(maxsize=128)
def _symmetry_of(key: _SectionKey) -> Symmetry:
    section, tol = key.section, key.tol
    holes = [_Placed(h.role, h.outline, tol) for h in section.holes]
    fibre = None if section.fibre is None else np.asarray(section.fibre.center, dtype=float)
    same_line = max(1e-4, 10.0 * tol / section.outer_radius)   # rad: one mirror line found twice
    mirrors = []
    for a in _candidate_mirror_angles(section):
        if any(min(abs(a - m.angle), math.pi - abs(a - m.angle)) < same_line for m in mirrors):
            continue   # the same line found from another part
        perm = _matches(holes, fibre, mirror_matrix(a), tol)
        if perm is not None:
            mirrors.append(Mirror(a, perm))
    order, rperm = 1, tuple(range(len(section.holes)))
    for n in range(MAX_ORDER, 1, -1):
        perm = _matches(holes, fibre, rotation_matrix(2 * math.pi / n), tol)
        if perm is not None:
            order, rperm = n, perm
            break
    return Symmetry(tuple(mirrors), order, rperm)
