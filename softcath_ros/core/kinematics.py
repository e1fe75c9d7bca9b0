"""Constant-curvature kinematics in ``softcath_base`` (z along the unbent axis).

A backbone of arc length s with curvature vector k = (kx, ky) (bends towards k/|k|)
is an arc of angle theta = |k| s. Written without dividing by |k| or normalising k:

    position    = ( k s^2 f2(theta),  s f1(theta) )     f1 = sin(t)/t, f2 = (1 - cos t)/t^2
    orientation = rotation about (-ky, kx, 0)/|k| by theta
                = quaternion ( s (-ky, kx, 0) g(theta),  cos(theta/2) )  g = sin(t/2)/t

f1, f2, g are entire functions evaluated through np.sinc, so every formula is exact
and smooth through k = 0 and never flips direction for tiny curvature.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _sinc(t):
    """sin(t)/t, exact at 0."""
    return np.sinc(np.asarray(t) / np.pi)


def arc_poses(curvature, arc_length):
    """Positions (..., 3) and unit quaternions (..., 4, xyzw) at arc length(s) ``arc_length``.

    ``curvature`` has shape (..., 2); ``arc_length`` broadcasts against its leading shape.
    """
    k = np.asarray(curvature, dtype=float)
    s = np.asarray(arc_length, dtype=float)
    kx, ky = k[..., 0], k[..., 1]
    kappa = np.hypot(kx, ky)
    theta = kappa * s
    f1 = _sinc(theta)
    half = 0.5 * theta
    f2 = 0.5 * _sinc(half) ** 2        # (1 - cos t)/t^2 = sin^2(t/2) / (2 (t/2)^2)
    g = 0.5 * _sinc(half)              # sin(t/2)/t
    s2f2 = s * s * f2
    shape = np.broadcast(kx, s).shape
    position = np.empty(shape + (3,))
    position[..., 0] = kx * s2f2
    position[..., 1] = ky * s2f2
    position[..., 2] = s * f1
    quat = np.empty(shape + (4,))
    sg = s * g
    quat[..., 0] = -ky * sg
    quat[..., 1] = kx * sg
    quat[..., 2] = 0.0
    quat[..., 3] = np.cos(half)
    return position, quat


def tip_pose(curvature, length):
    """Tip position (m) and quaternion (x, y, z, w) of a backbone of arc length ``length``."""
    return arc_poses(curvature, length)


def backbone_poses(curvature, length, n_points: int):
    """Poses at ``n_points`` equally spaced arc lengths from base (0) to tip (``length``).

    For a single curvature (2,) returns (n_points, 3) and (n_points, 4); for a batch
    (N, 2) with lengths (N,), (N, n_points, 3) and (N, n_points, 4).
    """
    if n_points < 2:
        raise ValueError(f"n_points = {n_points}: a backbone needs at least base and tip (2)")
    k = np.asarray(curvature, dtype=float)
    fractions = np.linspace(0.0, 1.0, n_points)
    s = np.asarray(length, dtype=float)[..., None] * fractions
    return arc_poses(k[..., None, :], s)


def bending_angle(curvature, length):
    """Bending angle theta = |k| s, rad."""
    k = np.asarray(curvature, dtype=float)
    return np.hypot(k[..., 0], k[..., 1]) * np.asarray(length, dtype=float)


@dataclass(frozen=True)
class TipInverse:
    curvature: np.ndarray   # (..., 2) 1/m: the arc through the target, tangent to z at the base
    arc_length: np.ndarray  # (...) m: that arc's length
    reachable: np.ndarray   # (...) bool: arc length within tolerance of the backbone length


def curvature_for_tip(tip, length, rtol: float = 1e-3) -> TipInverse:
    """Inverse kinematics: the constant-curvature arc that ends at ``tip`` (m).

    Through a point there is exactly one circular arc tangent to z at the origin:
    k = 2 (x, y) / |tip|^2 and angle theta = 2 atan2(rho, z). That arc's length must
    equal ``length`` (within ``rtol``) for the point to be reachable; otherwise the
    result says ``reachable = False`` and gives the arc length the point would need.
    """
    p = np.asarray(tip, dtype=float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    r2 = x * x + y * y + z * z
    rho = np.hypot(x, y)
    safe_r2 = np.where(r2 > 0, r2, 1.0)
    k = np.stack([2.0 * x / safe_r2, 2.0 * y / safe_r2], axis=-1)
    theta = 2.0 * np.arctan2(rho, z)
    # arc = theta / |k| = theta r2 / (2 rho) -> z as rho -> 0 (for z > 0).
    with np.errstate(divide="ignore", invalid="ignore"):
        arc = np.where(rho > 1e-12 * np.sqrt(safe_r2), theta * r2 / (2.0 * np.where(rho > 0, rho, 1.0)),
                       np.where(z > 0, z, np.inf))
    arc = np.where(r2 > 0, arc, np.inf)
    reachable = np.isfinite(arc) & (np.abs(arc - length) <= rtol * np.asarray(length))
    return TipInverse(curvature=np.where(r2[..., None] > 0, k, 0.0), arc_length=arc, reachable=reachable)


def _sinc_scalar(t: float) -> float:
    # Taylor below 1e-4: the error term t^4/120 is below double precision there.
    return 1.0 - t * t / 6.0 if abs(t) < 1e-4 else math.sin(t) / t


def tip_pose_single(kx: float, ky: float, arc_length: float):
    """``tip_pose`` for one backbone with plain floats: ((x, y, z), (qx, qy, qz, qw)).

    Same formulas without numpy's per-call overhead (about 10x faster for one pose),
    for nodes that answer one command at a time.
    """
    s = arc_length
    theta = math.hypot(kx, ky) * s
    half = 0.5 * theta
    sinc_half = _sinc_scalar(half)
    s2f2 = s * s * 0.5 * sinc_half * sinc_half
    sg = s * 0.5 * sinc_half
    return ((kx * s2f2, ky * s2f2, s * _sinc_scalar(theta)),
            (-ky * sg, kx * sg, 0.0, math.cos(half)))


def planar_backbone_poses(points, n_points: int):
    """Poses at ``n_points`` equally spaced (by arc length) along a solved planar backbone.

    ``points`` (M, 3) m, from the base (0, 0, 0) along z, bending in a vertical plane (the rod
    under loads, whose shape is no single arc). Orientation: the rotation that takes z to the
    local tangent about the axis normal to that plane, as for an arc (module docstring).
    """
    pts = np.asarray(points, dtype=float)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.linspace(0.0, s[-1], n_points)
    pos = np.column_stack([np.interp(at, s, pts[:, j]) for j in range(3)])
    tangent = np.gradient(pts, s, axis=0, edge_order=2)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    lateral = tangent[:, :2]
    # the bending plane's in-plane direction e (unit, xy): where the backbone leans most
    lean = pts[np.argmax(np.hypot(pts[:, 0], pts[:, 1])), :2]
    norm = np.hypot(*lean)
    e = lean / norm if norm > 0 else np.array([0.0, -1.0])
    phi = np.interp(at, s, np.arctan2(lateral @ e, tangent[:, 2]))
    quats = np.column_stack([-e[1] * np.sin(phi / 2), e[0] * np.sin(phi / 2), np.zeros_like(phi), np.cos(phi / 2)])
    return pos, quats
