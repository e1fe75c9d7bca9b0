"""What the 3D solution says about the bending: a constant-curvature arc fitted to the tip.

* Bending angle and direction: the rigid rotation that best maps the tip face's reference
  points onto their deformed positions (Kabsch); theta is the angle between the rotated
  and the original axis, the bending direction is where the rotated axis leans.
* Arc length: the constant-curvature arc with that angle that best reaches the deformed
  body axis at the tip (least squares); axial stretch = arc length / L.
* Channel volume (the enclosed fluid) and the area of the channel's deformed section
  half way along the open channel.
"""
from __future__ import annotations

import math

import numpy as np


def best_fit_rotation(ref: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Rotation R minimising sum |R (ref - mean) - (cur - mean)|^2."""
    a = ref - ref.mean(axis=0)
    b = cur - cur.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    return (u @ np.diag([1.0, 1.0, d]) @ vt).T


def _evaluate(problem, pts: np.ndarray) -> np.ndarray:
    mesh = problem.mesh
    vals = problem.u(mesh(pts[:, 0], pts[:, 1], pts[:, 2]))
    return np.asarray(vals).reshape(len(pts), 3)


def _mirror(pts: np.ndarray, off_plane: np.ndarray) -> np.ndarray:
    """The half model's points and the mirror images about x = 0 of those ``off_plane``; a point
    on the plane once (as in the full body: twice would weigh it double in the tip's fit)."""
    m = pts[off_plane].copy()
    m[:, 0] *= -1.0
    return np.vstack([pts, m])


def bending_from_tip(rot: np.ndarray, tip: np.ndarray) -> tuple[float, np.ndarray]:
    """Bending angle theta in [0, 2 pi) and bending direction u from the tip's rotation and position.

    A constant-curvature bend towards u by theta rotates the tip about (-uy, ux, 0) by theta.
    The rotation alone cannot tell (u, theta) from (-u, 2 pi - theta), so beyond a half
    circle we use the tip position, whose sideways part always points along u.
    """
    from scipy.spatial.transform import Rotation

    rotvec = Rotation.from_matrix(rot).as_rotvec()
    phi = float(np.linalg.norm(rotvec))           # in [0, pi]
    lateral = np.asarray(tip[:2], dtype=float)
    if phi < 1e-12:
        lean = np.hypot(*lateral)
        return phi, (lateral / lean if lean > 0 else np.array([0.0, -1.0]))
    n = rotvec / phi
    u = np.array([n[1], -n[0]])
    u /= np.hypot(*u)
    if lateral @ u < 0.0:                          # bent past a half circle
        return 2.0 * math.pi - phi, -u
    return phi, u


def _axis_in_solid(problem) -> bool:
    """Whether the body axis at the tip is in material (not in an empty lumen). Channels are
    closed by the cap there; a lumen with a device or a fill is solid."""
    lumen = problem.design.lumen
    if lumen is None or problem.design.device is not None or getattr(problem, "has_fill", False):
        return True
    return math.hypot(*lumen.center) > lumen.radius


def measure(problem) -> dict:
    """Bending angle (rad), bending direction (unit (2,)), arc length (m), tip position (m),
    channel volumes (m^3) and mid-channel areas (m^2) of the current state."""
    design = problem.design
    prism = problem.prism
    sec = prism.section
    length = design.length
    # --- tip rotation (section vertices at z = L)
    tip_ref = np.column_stack([sec.points, np.full(len(sec.points), length)])
    solid = np.zeros(len(sec.points), dtype=bool)
    for tri, reg in zip(sec.triangles, sec.region):
        if reg in ("silicone", "fibre") or reg.startswith("channel"):
            solid[tri] = True
    tip_ref = tip_ref[solid]
    tip_cur = tip_ref + _evaluate(problem, tip_ref)
    if problem.half:
        off = np.abs(tip_ref[:, 0]) > 1e-12
        tip_ref, tip_cur = _mirror(tip_ref, off), _mirror(tip_cur, off)
    rot = best_fit_rotation(tip_ref, tip_cur)
    axis_tip = np.array([0.0, 0.0, length])
    if _axis_in_solid(problem):
        tip = axis_tip + _evaluate(problem, axis_tip[None, :])[0]
    else:   # the axis runs through an empty lumen (e.g. a central one): carry it with the tip face's fit
        tip = tip_cur.mean(axis=0) + rot @ (axis_tip - tip_ref.mean(axis=0))
    turn = problem.rotation   # a half model about a mirror plane turned to x = 0
    if turn:   # back to the design's frame
        c, s = math.cos(-turn), math.sin(-turn)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        tip, rot = rz @ tip, rz @ rot @ rz.T
    theta, direction = bending_from_tip(rot, tip)
    # --- arc length through the deformed tip of the body axis
    if theta > 1e-9:
        g = np.array([direction[0] * (1 - math.cos(theta)) / theta,
                      direction[1] * (1 - math.cos(theta)) / theta, math.sin(theta) / theta])
    else:
        g = np.array([0.0, 0.0, 1.0])
    arc = float(tip @ g / (g @ g))
    # --- channels
    volumes = problem.channel_volumes()
    areas = [channel_area(problem, i) for i in range(design.n_channels)]
    out = {"bending_angle_rad": theta, "bending_direction": direction, "arc_length_m": arc,
           "tip_position_m": tip, "tip_rotation": rot, "channel_volume_m3": volumes,
           "channel_area_m2": np.array(areas)}
    if getattr(problem, "contact", None) is not None:
        known = getattr(problem, "last_min_gap_state", None)
        same = known is not None and np.array_equal(known, problem.get_state())
        out["lumen_min_gap_m"] = problem.last_min_gap if same else problem.contact.min_gap()
    return out


def channel_area(problem, i: int) -> float:
    """Area of channel i's deformed section at mid-length of its open part (Newell's formula).
    In the half model a channel the plane cuts is closed by its mirror image; one not meshed
    (at x < 0) has its mirror partner's area."""
    prism = problem.prism
    sec = prism.section
    source, factor = prism.channel_shares[i]
    if source != i:
        return channel_area(problem, source)
    hole = problem.design.channels[i]
    z_mid = prism.z_levels[prism.n_layers_channel // 2]
    on = np.abs(np.hypot(sec.points[:, 0] - hole.center[0], sec.points[:, 1] - hole.center[1])
                - hole.radius) < 0.1 * hole.radius
    pts2 = sec.points[on]
    ang = np.arctan2(pts2[:, 1] - hole.center[1], pts2[:, 0] - hole.center[0])
    order = np.argsort(ang)  # counter-clockwise; a cut channel (x >= 0) runs -90 -> +90 deg
    ref = np.column_stack([pts2[order], np.full(len(order), z_mid)])
    cur = ref + _evaluate(problem, ref)
    if factor == 2.0:
        back = cur[::-1].copy()
        back[:, 0] *= -1.0
        cur = np.vstack([cur, back])
    nxt = np.roll(cur, -1, axis=0)
    return float(0.5 * np.linalg.norm(np.cross(cur, nxt).sum(axis=0)))


def lumen_wall_nodes(problem):
    """The section's mesh points on the lumen wall (m), in order around the lumen (the half model's
    half wall), and the z levels (m) at which the wall is sampled: every mesh level above the base
    (which does not move) and the middle of every layer (the P2 field is curved along z too)."""
    lumen = problem.design.lumen
    sec = problem.prism.section
    c = np.asarray(lumen.center, dtype=float)
    on = np.abs(np.hypot(sec.points[:, 0] - c[0], sec.points[:, 1] - c[1]) - lumen.radius) < 0.1 * lumen.radius
    pts = sec.points[on]
    pts = pts[np.argsort(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]))]
    z = problem.prism.z_levels
    return pts, np.sort(np.concatenate([z[1:], 0.5 * (z[:-1] + z[1:])]))


def lumen_wall_stretch(problem, per_edge: int = 4) -> dict:
    """The lumen wall's surface stretches at the current state, sampled at ``per_edge`` points per
    wall edge of the section on every mesh level and mid-layer (a hair inside the silicone):
    the hoop stretch |F t| (t the wall edge's reference direction in the section), the axial one |F e_z| and
    the surface's principal stretches (of the 2x2 surface Cauchy-Green tensor on t, e_z). A
    neo-Hookean surface under plane-strain compression creases at a surface stretch of about 0.65
    (Hong, Zhao & Suo 2009), wrinkles (Biot) at 0.54. Returns the smallest hoop and principal
    stretches with where (reference x, y, z in m), the wall's normal stretch there (det F over the
    product of the principal ones) and the smallest det F at the wall."""
    c = np.asarray(problem.design.lumen.center, dtype=float)
    pts2, levels = lumen_wall_nodes(problem)
    nxt = pts2[1:] if problem.half else np.roll(pts2, -1, axis=0)
    start = pts2[:-1] if problem.half else pts2
    t = (np.arange(per_edge) + 0.5) / per_edge   # inside each edge: the wall is a chord there
    xy = (start[:, None, :] * (1 - t)[None, :, None] + nxt[:, None, :] * t[None, :, None]).reshape(-1, 2)
    chord = np.repeat((nxt - start) / np.linalg.norm(nxt - start, axis=1)[:, None], per_edge, axis=0)
    tangent = np.column_stack([chord, np.zeros(len(chord))])
    xy = c + (xy - c) * (1.0 + 1e-3)   # a hair inside the silicone (the lumen is not meshed)
    levels = np.clip(levels, 1e-9, problem.design.length - 1e-9)   # inside the mesh
    import ngsolve as ng

    grad = ng.Grad(problem.u)
    pts = np.vstack([np.column_stack([xy, np.full(len(xy), zk)]) for zk in levels])
    tan = np.tile(tangent, (len(levels), 1))
    g = np.asarray(grad(problem.mesh(pts[:, 0], pts[:, 1], pts[:, 2]))).reshape(len(pts), 3, 3)
    F = np.eye(3)[None] + g
    ft = np.einsum("nij,nj->ni", F, tan)
    fz = F[:, :, 2]
    c11, c22, c12 = (ft * ft).sum(1), (fz * fz).sum(1), (ft * fz).sum(1)
    mean, dev = 0.5 * (c11 + c22), np.sqrt(0.25 * (c11 - c22) ** 2 + c12 ** 2)
    lam_min, lam_max = np.sqrt(np.maximum(mean - dev, 0.0)), np.sqrt(mean + dev)
    hoop = np.sqrt(c11)
    det = np.linalg.det(F)
    i, k = int(np.argmin(hoop)), int(np.argmin(lam_min))
    return {"min_hoop_stretch": float(hoop[i]), "min_hoop_at_m": pts[i],
            "axial_stretch_there": float(np.sqrt(c22[i])),
            "min_principal_stretch": float(lam_min[k]), "other_principal_there": float(lam_max[k]),
            "normal_stretch_there": float(det[k] / (lam_min[k] * lam_max[k])), "min_principal_at_m": pts[k],
            "min_det_f": float(det.min()), "min_det_f_at_m": pts[int(np.argmin(det))]}
