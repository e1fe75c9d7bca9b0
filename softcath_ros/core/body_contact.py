"""Where a bent body reaches itself or the shaft it sits on: a geometric check no rung models.

Every rung solves a free body: nothing stops its outer surface from passing through its own
other end, or through what holds its base (the catheter shaft, or a rig's holder), once it bends
far enough. Such a state is not a prediction of anything, so callers refuse it (stop reason
``OUTSIDE_MODEL``). The body is taken as round (radius ``radius``) around its deformed backbone;
the shaft as the body's straight continuation below the base, of the body's radius (the least
that holds it: a wider holder is reached earlier).

The test samples the surface: a ring of points on each cross-section disc (normal to the local
tangent), and asks whether any lies inside

* the shaft: behind the base's plane and within ``radius`` of its axis;
* a slice of the body far along the backbone from its own (further than half a turn of the
  body's own radius, pi r: nearer slices touch only when the bend folds, checked apart);
* or whether the bend folds: a backbone radius of curvature under ``radius`` (the inner side of
  the bend would have negative length).

A constant-curvature body (an arc of angle theta) cannot reach either before theta > pi, which
``may_reach`` uses as a cheap test for a live node's answers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

RING_POINTS = 16   # points on each cross-section's rim


@dataclass(frozen=True)
class BodyContact:
    """The first place found where the body reaches something it cannot pass through."""

    what: str            # "shaft", "itself" or "fold"
    at_m: float          # arc length along the deformed backbone of the reaching cross-section, m
    depth_m: float       # how far that point is inside (fold: radius minus the radius of curvature), m
    at_tip: bool = False   # the reaching cross-section is the tip's
    other_m: float | None = None   # itself: arc length of the earlier part it reaches, m

    def describe(self) -> str:
        where = ("the tip" if self.at_tip else f"the cross-section {self.at_m * 1e3:.1f} mm along the backbone")
        if self.what == "shaft":
            return (f"the body reaches the shaft it sits on ({where} is {self.depth_m * 1e3:.2g} mm inside "
                    "the straight continuation of the base): no rung models that contact")
        if self.what == "itself":
            return (f"the body reaches itself ({where} overlaps the cross-section {self.other_m * 1e3:.1f} mm "
                    f"along the backbone by {self.depth_m * 1e3:.2g} mm): no rung models the outer "
                    "surface's self-contact")
        return (f"the bend folds the body's inner side ({where} has a radius of curvature "
                f"{self.depth_m * 1e3:.2g} mm under the body's radius)")


def may_reach(bending_angle_rad) -> np.ndarray:
    """Whether a constant-curvature body with a straight cap may reach itself or its shaft: only
    beyond a half turn (every tangent within less than pi of the base's, so the body moves away
    from its base and from each of its own cross-sections)."""
    return np.abs(np.asarray(bending_angle_rad, dtype=float)) > math.pi


def _frames(points: np.ndarray):
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    tangent = np.gradient(points, s, axis=0, edge_order=2)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    # a normal for each tangent: Gram-Schmidt against the axis least aligned with it
    helper = np.eye(3)[np.argmin(np.abs(tangent), axis=1)]
    u = helper - (helper * tangent).sum(axis=1, keepdims=True) * tangent
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(tangent, u)
    return s, seg, tangent, u, v


def body_contact(points, radius: float) -> BodyContact | None:
    """The first contact (by arc length of the reaching cross-section, the later of a pair) of a round body of
    ``radius`` (m) around the backbone ``points`` (M, 3), m, base first, with itself or with its
    shaft; None when it reaches neither. The backbone needs points closer than ``radius`` apart
    (a slice is the length between two points)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise ValueError(f"body_contact: points of shape {pts.shape}; needs (M >= 3, 3)")
    if not radius > 0:
        raise ValueError(f"body_contact: radius {radius!r} m; needs > 0")
    s, seg, t, u, v = _frames(pts)
    if seg.max() >= radius:
        raise ValueError(f"body_contact: backbone points {seg.max() * 1e3:.2f} mm apart; needs under the "
                         f"body's radius {radius * 1e3:.2f} mm")
    found: list[BodyContact] = []
    # fold: the turning of the tangent per length (1/radius of curvature) above 1/radius
    turn = np.arccos(np.clip((t[1:] * t[:-1]).sum(axis=1), -1.0, 1.0)) / seg
    folds = np.flatnonzero(turn * radius > 1.0)
    if folds.size:
        i = int(folds[0])
        found.append(BodyContact("fold", float(s[i]), float(radius - 1.0 / turn[i])))
    angles = np.linspace(0.0, 2.0 * math.pi, RING_POINTS, endpoint=False)
    ring = (pts[:, None, :] + radius * (np.cos(angles)[None, :, None] * u[:, None, :]
                                        + np.sin(angles)[None, :, None] * v[:, None, :]))   # (M, R, 3)
    rim = np.concatenate([ring, pts[:, None, :]], axis=1)   # the centre too (a deep overlap)
    # the shaft: behind the base's plane, within radius of its axis
    rel = rim - pts[0]
    along = rel @ t[0]
    off = np.linalg.norm(rel - along[..., None] * t[0], axis=-1)
    inside = (along < -1e-12 * radius) & (off < radius * (1 - 1e-9))
    if inside.any():
        i = int(np.flatnonzero(inside.any(axis=1))[0])
        found.append(BodyContact("shaft", float(s[i]), float(radius - off[i][inside[i]].min()), i == len(s) - 1))
    # itself: a rim point of slice i inside slice j, from half way back to point j - 1 to half way on to point j + 1 (the ends: to the face)
    back = 0.5 * np.concatenate([[0.0], seg])
    ahead = 0.5 * np.concatenate([seg, [0.0]])
    # (i, j) pairs to test: far apart along the backbone, near enough in space for a rim point of
    # slice i (within radius of its centre) to lie in slice j (within radius and a spacing of its)
    gap = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
    far = (np.abs(s[:, None] - s[None, :]) > math.pi * radius) & (gap < 2.0 * radius + seg.max())
    ii, jj = np.nonzero(far)
    if ii.size:
        rel = rim[ii] - pts[jj][:, None, :]                             # (P, R+1, 3)
        a = np.einsum("prk,pk->pr", rel, t[jj])
        radial = np.linalg.norm(rel - a[..., None] * t[jj][:, None, :], axis=-1)
        hit = (a >= -back[jj][:, None]) & (a <= ahead[jj][:, None]) & (radial < radius * (1 - 1e-9))
        if hit.any():
            # the pair whose later cross-section is nearest the base: the first part to come round
            p = np.flatnonzero(hit.any(axis=1))
            later = np.maximum(ii[p], jj[p])
            first = p[np.argmin(later)]
            a_i, b_j = int(max(ii[first], jj[first])), int(min(ii[first], jj[first]))
            found.append(BodyContact("itself", float(s[a_i]), float(radius - radial[first][hit[first]].min()),
                                     a_i == len(s) - 1, float(s[b_j])))
    return min(found, key=lambda c: c.at_m) if found else None
