"""Symmetry of a section found from its outlines (never assumed from a channel count).

``symmetry(section)`` returns the mirror lines through the body axis and the largest n-fold
rotation that map the section onto itself: every hole onto a hole of the same role (the
permutation says which), the fibre onto itself. Two outlines match when their polygons lie within
``tolerance`` of each other (Hausdorff distance), so a shape drawn with other vertices still counts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .outline import Outline
from .section import Section

MAX_ORDER = 12


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


def _same_moments(a: Outline, b: Outline, tol: float) -> bool:
    """Cheap exact test first: equal area, centroid and centroidal second moments."""
    ia, ib = a.integrals, b.integrals
    if np.hypot(*(ia.centroid - ib.centroid)) > tol:
        return False
    scale = max(ia.area, ib.area)
    if abs(ia.area - ib.area) > 1e-6 * scale:
        return False
    ja, jb = ia.centroidal_second, ib.centroidal_second
    return bool(np.abs(ja - jb).max() <= 1e-6 * max(np.abs(ja).max(), np.abs(jb).max()))


def _matches(section: Section, transform, tol: float):
    """The hole permutation under ``transform`` (Outline -> Outline), or None if it fails."""
    perm = []
    for hole in section.holes:
        moved = transform(hole.outline)
        found = None
        for j, other in enumerate(section.holes):
            if other.role != hole.role or j in perm or not _same_moments(moved, other.outline, tol):
                continue
            # the outlines themselves, coarsely (chords within 10 tol): the moments could agree by chance
            if moved.polygon(10 * tol).hausdorff_distance(other.outline.polygon(10 * tol)) <= 21 * tol:
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
    """Mirror lines and rotation order of ``section`` (``tolerance`` m, default 1e-5 of the radius)."""
    tol = 1e-5 * section.outer_radius if tolerance is None else tolerance
    mirrors = []
    for a in _candidate_mirror_angles(section):
        if any(min(abs(a - m.angle), math.pi - abs(a - m.angle)) < 1e-4 for m in mirrors):
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
