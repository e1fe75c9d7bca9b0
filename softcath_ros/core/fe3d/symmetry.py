"""Mirror symmetry of a design's section (holes, fibre and channel pressures): whether a half model
about x = 0 may be used, a mirror plane to turn the section onto, and how each channel's volume
follows from the half model's."""
from __future__ import annotations

import math

import numpy as np

from ..design import Design
from .holes import is_circle


def can_use_half_model(design: Design) -> bool:
    """Mirror symmetry about the y-z plane with every hole and the fibre on it (centroid at x = 0)."""
    return all(abs(centre[0]) < 1e-12 for _, centre, _, _ in _features(design)) and \
        mirror_partners(design, math.pi / 2) is not None


def _features(design: Design, direction=None) -> list[tuple[str, tuple[float, float], object, float]]:
    """(kind, centre, shape, pressure per unit) of every hole and the fibre: what a mirror must map
    onto its like. ``shape``: a circle's radius (m), else the hole's outline."""
    d = [0.0] * design.n_channels if direction is None else [float(v) for v in direction]
    holes = [("channel", c, p) for c, p in zip(design.channels, d)]
    if design.lumen is not None:
        holes.append(("lumen", design.lumen, 0.0))
    out = [(kind, h.center, h.radius if is_circle(h) else h.outline, p) for kind, h, p in holes]
    if design.limiting_fibre is not None:
        f = design.limiting_fibre
        out.append(("fibre", f.center, 0.5 * f.diameter, 0.0))
    return out


def _same_shape(a, b, angle: float, scale: float) -> bool:
    """Whether shape ``a`` mirrored about the plane at ``angle`` is shape ``b`` (radii within
    ``scale`` m; outlines: equal area and centroidal second moments, and within ``scale`` of
    each other)."""
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, float) and isinstance(b, float) and abs(a - b) <= scale
    image = a.mirrored(angle)
    ia, ib = image.integrals, b.integrals
    ja, jb = ia.centroidal_second, ib.centroidal_second
    if abs(ia.area - ib.area) > 1e-6 * ib.area or np.abs(ja - jb).max() > 1e-6 * np.abs(jb).max():
        return False
    tol = max(scale, 1e-7)
    return image.polygon(tol).hausdorff_distance(b.polygon(tol)) <= 3 * tol


def _reflect(point, angle: float) -> np.ndarray:
    """``point`` mirrored about the plane through the body axis along (cos angle, sin angle)."""
    e = np.array([math.cos(angle), math.sin(angle)])
    p = np.asarray(point, dtype=float)
    return 2.0 * (p @ e) * e - p


def mirror_partners(design: Design, angle: float, direction=None, tol: float = 1e-9) -> list[int] | None:
    """For the mirror plane through the axis along ``angle`` (rad from +x): the channel each
    channel maps onto (itself when the plane cuts it), or None when the section (holes, fibre
    and, if given, the channel pressures per unit ``direction``) is not symmetric about it."""
    feats = _features(design, direction)
    scale = tol * design.outer_radius
    partner = []
    for kind, centre, shape, p in feats:
        image = _reflect(centre, angle)
        match = [j for j, (k2, c2, s2, p2) in enumerate(feats)
                 if k2 == kind and np.hypot(*(image - c2)) <= scale
                 and abs(p2 - p) <= tol * max(1.0, abs(p)) and _same_shape(shape, s2, angle, scale)]
        if not match:
            return None
        partner.append(match[0])
    return partner[:design.n_channels]


def mirror_plane(design: Design, direction=None) -> float | None:
    """The angle (rad from +x) of a plane through the body axis about which the section and the
    channel pressures ``direction`` are mirror symmetric (the y-z plane, pi/2, when it is one), or
    None. Candidates: the planes through each off-axis feature's centre and the bisectors between
    pairs of them (a mirror maps a feature onto itself, then the plane runs through its centre,
    or onto another at the same distance from the axis)."""
    centres = [np.asarray(c) for _, c, _, _ in _features(design, direction)]
    off_axis = [c for c in centres if np.hypot(*c) > 1e-9 * design.outer_radius]
    candidates = [math.pi / 2]
    candidates += [math.atan2(c[1], c[0]) for c in off_axis]
    bisectors = [0.5 * (math.atan2(a[1], a[0]) + math.atan2(b[1], b[0])) for i, a in enumerate(off_axis)
                 for b in off_axis[i + 1:]]
    candidates += bisectors + [b + math.pi / 2 for b in bisectors]
    for angle in candidates:
        if mirror_partners(design, angle, direction) is not None:
            return angle
    return None


def rotated_section(design: Design, angle: float) -> Design:
    """The design with its section rotated by ``angle`` (rad, counter-clockwise) about the body
    axis: every hole and the fibre moved (a shaped hole's outline turned with its centroid, its
    shape as written kept); the body (a circle, hoop reinforcement) is unchanged."""
    from dataclasses import replace

    c, s = math.cos(angle), math.sin(angle)

    def turn(p):   # a centre that lands on a plane through the axis lands there exactly
        q = (c * p[0] - s * p[1], s * p[0] + c * p[1])
        return tuple(0.0 if abs(v) < 1e-12 * design.outer_radius else v for v in q)

    def moved(h):
        if is_circle(h):
            return replace(h, center=turn(h.center))
        return replace(h, center=turn(h.center), outline=h.outline.rotated(angle))

    return replace(design, channels=tuple(moved(h) for h in design.channels),
                   lumen=None if design.lumen is None else moved(design.lumen),
                   limiting_fibre=None if design.limiting_fibre is None else
                   replace(design.limiting_fibre, center=turn(design.limiting_fibre.center)))


def partners_about_yz(design: Design) -> list[int]:
    """``mirror_partners`` about x = 0, which a half model's section must have."""
    partners = mirror_partners(design, math.pi / 2)
    if partners is None:
        raise ValueError(f"{design.name}: the section is not mirror symmetric about x = 0")
    return partners


def channel_shares(design: Design, half: bool) -> list[tuple[int, float]]:
    """How each channel's whole volume follows from the model's: V_i = factor * v_source, with v
    the volume enclosed by the channel's walls in the model. Full model: (i, 1). Half model about
    x = 0: a channel the plane cuts (i, 2); one inside x > 0 (i, 1); one at x < 0, not meshed,
    its mirror partner's volume (partner, 1)."""
    if not half:
        return [(i, 1.0) for i in range(design.n_channels)]
    partners = partners_about_yz(design)
    out = []
    for i, ch in enumerate(design.channels):
        x = ch.center[0]
        out.append((i, 2.0) if abs(x) <= 1e-9 * design.outer_radius else (i, 1.0) if x > 0 else (partners[i], 1.0))
    return out
