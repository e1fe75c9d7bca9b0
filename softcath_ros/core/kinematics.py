"""Constant-curvature kinematics in ``softcath_base`` (z along the unbent axis).

A backbone of arc length s with curvature vector k = (kx, ky) (bends towards k/|k|)
is an arc of angle theta = |k| s. Written without dividing by |k| or normalising k:

    position    = ( k s^2 f2(theta),  s f1(theta) )     f1 = sin(t)/t, f2 = (1 - cos t)/t^2
    orientation = rotation about (-ky, kx, 0)/|k| by theta
                = quaternion ( s (-ky, kx, 0) g(theta),  cos(theta/2) )  g = sin(t/2)/t

f1, f2, g are entire functions evaluated through np.sinc, so every formula is exact
and smooth through k = 0 and never flips direction for tiny curvature.

The body: the channelled part bends as that arc; the tip cap beyond the channel's end (``cap``,
m; the design's ``cap_thickness``) carries no moment when the tip is free, so it stays straight
and unstretched along the arc's end tangent t = (k s f1(theta), cos theta). Every tip and backbone
function takes the arc length of the channelled part and the cap's length.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

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


def arc_tangent(curvature, arc_length):
    """Unit tangent (..., 3) at arc length ``arc_length`` of the arc of curvature ``curvature``."""
    k = np.asarray(curvature, dtype=float)
    s = np.asarray(arc_length, dtype=float)
    theta = np.hypot(k[..., 0], k[..., 1]) * s
    ksf = s * _sinc(theta)
    return np.stack(np.broadcast_arrays(k[..., 0] * ksf, k[..., 1] * ksf, np.cos(theta)), axis=-1)


def tip_pose(curvature, arc_length, cap=0.0):
    """Tip position (m) and quaternion (x, y, z, w) of a body whose channelled part is an arc of
    length ``arc_length`` (m, deformed) followed by a straight cap of ``cap`` (m)."""
    pos, quat = arc_poses(curvature, arc_length)
    if np.any(np.asarray(cap) != 0):
        pos = pos + np.asarray(cap, dtype=float)[..., None] * arc_tangent(curvature, arc_length)
    return pos, quat


def backbone_poses(curvature, arc_length, n_points: int, cap=0.0):
    """Poses at ``n_points`` equally spaced arc lengths from base (0) to tip (``arc_length`` + ``cap``).

    For a single curvature (2,) returns (n_points, 3) and (n_points, 4); for a batch
    (N, 2) with lengths (N,), (N, n_points, 3) and (N, n_points, 4).
    """
    if n_points < 2:
        raise ValueError(f"n_points = {n_points}: a backbone needs at least base and tip (2)")
    if np.shape(curvature) == (2,) and np.ndim(arc_length) == 0 and np.ndim(cap) == 0:
        return _single_backbone(float(curvature[0]), float(curvature[1]), float(arc_length), float(cap), n_points)
    k = np.asarray(curvature, dtype=float)[..., None, :]
    arc = np.asarray(arc_length, dtype=float)[..., None]
    fractions = np.linspace(0.0, 1.0, n_points)
    s = (arc + np.asarray(cap, dtype=float)[..., None]) * fractions
    on_arc = np.minimum(s, arc)
    pos, quat = arc_poses(k, on_arc)
    beyond = s - on_arc
    if np.any(beyond > 0):
        pos = pos + beyond[..., None] * arc_tangent(k, on_arc)
    return pos, quat


@lru_cache(maxsize=8)
def _fractions(n_points: int) -> np.ndarray:
    out = np.linspace(0.0, 1.0, n_points)
    out.flags.writeable = False
    return out


def _sinc_of(t: np.ndarray) -> np.ndarray:
    """sin(t)/t of a 1-D array, 1 at 0."""
    return np.divide(np.sin(t), t, out=np.ones_like(t), where=t != 0.0)


def _single_backbone(kx: float, ky: float, arc: float, cap: float, n_points: int):
    """``backbone_poses`` for one curvature (the node's hot path: the same formulas on 1-D arrays,
    without the batch path's broadcasting; equal to it to round-off)."""
    s = (arc + cap) * _fractions(n_points)
    on_arc = np.minimum(s, arc)
    half = (0.5 * math.hypot(kx, ky)) * on_arc
    g = 0.5 * on_arc * _sinc_of(half)                  # s sin(t/2)/t
    position = np.empty((n_points, 3))
    s2f2 = 2.0 * g * g                                  # s^2 (1 - cos t)/t^2
    position[:, 0] = kx * s2f2
    position[:, 1] = ky * s2f2
    position[:, 2] = on_arc * _sinc_of(2.0 * half)
    quat = np.zeros((n_points, 4))
    quat[:, 0] = -ky * g
    quat[:, 1] = kx * g
    quat[:, 3] = np.cos(half)
    if cap > 0.0:
        theta = math.hypot(kx, ky) * arc
        ksf = arc * (math.sin(theta) / theta if theta != 0.0 else 1.0)
        beyond = s - on_arc
        position += beyond[:, None] * np.array([kx * ksf, ky * ksf, math.cos(theta)])
    return position, quat


def bending_angle(curvature, length):
    """Bending angle theta = |k| s, rad."""
    k = np.asarray(curvature, dtype=float)
    return np.hypot(k[..., 0], k[..., 1]) * np.asarray(length, dtype=float)


def radius_l_over_theta(length: float, angle: float) -> float:
    """R_C = l / theta (m) of a sample of ``length`` (m) bent through ``angle`` (rad); inf when straight.
    The one place R_C is formed: predictions, model_node's R_C topic and the sweep tool call it."""
    theta = abs(float(angle))
    return math.inf if theta < 1e-12 or not math.isfinite(theta) else float(length) / theta


def backbone_bend_angle(quats) -> float:
    """The bending angle (rad) of a backbone given as poses from base to tip (``quats`` (n, 4), xyzw, z
    the tangent): the tangent's turning integrated along it (the angles between neighbouring poses'
    tangents, summed). It keeps counting past 180 degrees, where the tip orientation's rotation angle
    (2 acos |w|) folds back; each step between neighbouring poses must stay under 180 degrees."""
    q = np.asarray(quats, dtype=float)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    t = np.column_stack([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])  # R(q) e_z
    a, b = t[:-1], t[1:]
    return float(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b)).sum())


@dataclass(frozen=True)
class TipInverse:
    curvature: np.ndarray   # (..., 2) 1/m: the arc through the target, tangent to z at the base
    arc_length: np.ndarray  # (...) m: that arc's length
    reachable: np.ndarray   # (...) bool: arc length within tolerance of the backbone length


def _arc_through(p):
    """(curvature (..., 2), arc length (...)) of the arc tangent to z at the origin ending at p."""
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
    return np.where(r2[..., None] > 0, k, 0.0), arc


def curvature_for_tip(tip, length=None, rtol: float = 1e-3, cap=0.0) -> TipInverse:
    """Inverse kinematics: the constant-curvature arc whose end, continued by a straight ``cap``
    (m) along its end tangent, is ``tip`` (m).

    Through a point there is exactly one circular arc tangent to z at the origin:
    k = 2 (x, y) / |tip|^2 and angle theta = 2 atan2(rho, z). With a cap the arc ends at
    tip - cap t(theta), found by fixed-point iteration (a contraction: the cap is short against
    the arc). That arc's length must equal ``length`` (within ``rtol``) for the point to be
    reachable; otherwise the result says ``reachable = False`` and gives the arc length the point
    would need (arc length inf: no arc from the base ends there). Without ``length``, reachable
    says only that an arc ends there.

    One tip (shape (3,), scalar cap and length) runs on plain floats, tens of times faster than the
    array form, for a controller that inverts every target and sample; the answers are the same.
    """
    p = np.asarray(tip, dtype=float)
    if p.shape == (3,) and np.ndim(cap) == 0 and np.ndim(length) == 0:
        kx, ky, arc = _one_tip_inverse(float(p[0]), float(p[1]), float(p[2]), float(cap))
        reachable = math.isfinite(arc) and (length is None or abs(arc - length) <= rtol * length)
        return TipInverse(curvature=np.array([kx, ky]), arc_length=np.float64(arc), reachable=np.bool_(reachable))
    cap = np.asarray(cap, dtype=float)
    k, arc = _arc_through(p)
    if np.any(cap != 0):
        for _ in range(100):
            ok = np.isfinite(arc)
            t = arc_tangent(k, np.where(ok, arc, 0.0))
            k_new, arc_new = _arc_through(p - cap[..., None] * t)
            k_new = np.where(ok[..., None], k_new, k)
            arc_new = np.where(ok, arc_new, arc)
            with np.errstate(invalid="ignore"):
                done = np.all(~ok | ((np.abs(arc_new - arc) <= 1e-14 * np.abs(arc))
                                     & np.all(np.abs(k_new - k) <= 1e-14 * np.abs(k) + 1e-300, axis=-1)))
            k, arc = k_new, arc_new
            if done:
                break
    reachable = np.isfinite(arc)
    if length is not None:
        reachable &= np.abs(arc - length) <= rtol * np.asarray(length)
    return TipInverse(curvature=k, arc_length=arc, reachable=reachable)


def _one_tip_inverse(x: float, y: float, z: float, cap: float = 0.0) -> tuple[float, float, float]:
    """``curvature_for_tip``'s arc for one tip on plain floats: (kx, ky, arc length) of the arc that,
    continued by a straight ``cap`` (m) along its end tangent, ends at (x, y, z) (m); arc length inf
    where no arc from the base ends there. ``_arc_through`` and the array iteration, per float."""

    def arc_through(px, py, pz):
        r2 = px * px + py * py + pz * pz
        if r2 <= 0:
            return 0.0, 0.0, math.inf
        rho = math.hypot(px, py)
        if rho > 1e-12 * math.sqrt(r2):
            arc = 2.0 * math.atan2(rho, pz) * r2 / (2.0 * rho)
        else:
            arc = pz if pz > 0 else math.inf
        return 2.0 * px / r2, 2.0 * py / r2, arc

    kx, ky, arc = arc_through(x, y, z)
    if cap != 0:
        for _ in range(100):
            if not math.isfinite(arc):
                break
            theta = math.hypot(kx, ky) * arc
            ksf = arc * _sinc_scalar(theta)   # the end tangent: (kx ksf, ky ksf, cos theta)
            nkx, nky, narc = arc_through(x - cap * kx * ksf, y - cap * ky * ksf, z - cap * math.cos(theta))
            done = (abs(narc - arc) <= 1e-14 * abs(arc) and abs(nkx - kx) <= 1e-14 * abs(kx) + 1e-300
                    and abs(nky - ky) <= 1e-14 * abs(ky) + 1e-300)
            kx, ky, arc = nkx, nky, narc
            if done:
                break
    return kx, ky, arc


def _sinc_scalar(t: float) -> float:
    # Taylor below 1e-4: the error term t^4/120 is below double precision there.
    return 1.0 - t * t / 6.0 if abs(t) < 1e-4 else math.sin(t) / t


def tip_pose_single(kx: float, ky: float, arc_length: float, cap: float = 0.0):
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
    ksf = cap * s * _sinc_scalar(theta)   # the cap along the end tangent
    return ((kx * (s2f2 + ksf), ky * (s2f2 + ksf), s * _sinc_scalar(theta) + cap * math.cos(theta)),
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
