"""Symmetry of a section found from its outlines (never assumed from a channel count).

``symmetry(section)`` returns the mirror lines through the body axis and the largest n-fold
rotation that map the section onto itself: every hole onto a hole of the same role (the
permutation says which), the fibre onto itself. Two outlines match when their polygons lie within
``tolerance`` of each other (Hausdorff distance; default 2 um), so a shape drawn with other vertices,
or positions typed to the micrometre, still count.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .outline import Outline
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


def _alike(a: Outline, b: Outline) -> bool:
    """Cheap first test: about the same area and place (the outlines decide, ``_matches``)."""
    ia, ib = a.integrals, b.integrals
    size = math.sqrt(max(ia.area, ib.area))
    return abs(ia.area - ib.area) <= 0.05 * max(ia.area, ib.area) and \
        float(np.hypot(*(ia.centroid - ib.centroid))) <= 0.05 * size


def _matches(section: Section, transform, tol: float):
    """The hole permutation under ``transform`` (Outline -> Outline), or None if it fails."""
    perm = []
    for hole in section.holes:
        moved = transform(hole.outline)
        found = None
        for j, other in enumerate(section.holes):
            if other.role != hole.role or j in perm or not _alike(moved, other.outline):
                continue
            # the outlines themselves: within tol of each other (their polygons' chords within tol / 4)
            if moved.polygon(tol / 4).hausdorff_distance(other.outline.polygon(tol / 4)) <= 1.5 * tol:
                found = j
                break
        if found is None:
            return None
        perm.append(found)
    f = section.fibre
    if f is not None:
        moved = transform(Outline.circle(f.center, f.radius)).centroid
        if np.hypot(*(moved - np.asarray(f.center))) > tol:
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
    typed to the micrometre keeps its symmetry."""
    tol = min(SYMMETRY_TOLERANCE, 1e-3 * section.outer_radius) if tolerance is None else tolerance
    same_line = max(1e-4, 10.0 * tol / section.outer_radius)   # rad: one mirror line found twice
    mirrors = []
    for a in _candidate_mirror_angles(section):
        if any(min(abs(a - m.angle), math.pi - abs(a - m.angle)) < same_line for m in mirrors):
            continue   # the same line found from another part
        perm = _matches(section, lambda o, a=a: o.mirrored(a), tol)
        if perm is not None:
            mirrors.append(Mirror(a, perm))
    order, rperm = 1, tuple(range(len(section.holes)))
    for n in range(MAX_ORDER, 1, -1):
        perm = _matches(section, lambda o, n=n: o.rotated(2 * math.pi / n), tol)
        if perm is not None:
            order, rperm = n, perm
            break
    return Symmetry(tuple(mirrors), order, rperm)
