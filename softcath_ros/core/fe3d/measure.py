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
    """The displacement at reference points (N, 3), m. A point in no element (netgen's "Meshpoint
    not in mesh") is a ModelError naming it, never netgen's traceback."""
    from ..errors import ModelError

    mesh = problem.mesh
    try:
        vals = problem.u(mesh(pts[:, 0], pts[:, 1], pts[:, 2]))
    except Exception as exc:   # netgen raises its own NgException (a RuntimeError subclass or not)
        outside = [p for p in pts if not _in_mesh(mesh, p)]
        where = outside[0] if outside else pts[0]
        raise ModelError(f"fe3d: cannot read the displacement at x = {where[0] * 1e3:.3f}, y = {where[1] * 1e3:.3f}, "
                         f"z = {where[2] * 1e3:.3f} mm: {' '.join(str(exc).split())}") from None
    return np.asarray(vals).reshape(len(pts), 3)


def _in_mesh(mesh, p) -> bool:
    try:
        return mesh(float(p[0]), float(p[1]), float(p[2])).nr >= 0
    except Exception:
        return False


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


def bending_with_mid(rot: np.ndarray, rot_mid: np.ndarray, mid: np.ndarray) -> tuple[float, np.ndarray]:
    """Bending angle theta (beyond a full turn too) and direction u from the tip's rotation and the
    section's at mid-length (its rotation ``rot_mid`` and axis point ``mid``). The mid-length angle,
    about half the tip's and read by ``bending_from_tip`` (reliable below about 1.8 pi, where the
    mid section stands well off the axis), gives the bending axis a and an estimate 2 theta_mid;
    the tip's rotation angle signed by whether its axis is a or -a, psi in [-pi, pi], fixes
    theta = psi + 2 pi k, k the turn nearest that estimate; u is the tip's. So theta is exact while
    the halves bend within pi of each other, also near a full turn, where the tip is back near the
    axis and its position cannot tell theta from 2 pi - theta."""
    from scipy.spatial.transform import Rotation

    theta_mid, u_mid = bending_from_tip(rot_mid, mid)
    rotvec = Rotation.from_matrix(rot).as_rotvec()
    phi = float(np.linalg.norm(rotvec))           # in [0, pi]
    if phi < 1e-12:
        return 2.0 * math.pi * round(theta_mid / math.pi), u_mid
    n = rotvec / phi
    along = 1.0 if n @ np.array([-u_mid[1], u_mid[0], 0.0]) >= 0.0 else -1.0   # the tip's axis is a or -a
    u = along * np.array([n[1], -n[0]])
    psi = along * phi
    theta = psi + 2.0 * math.pi * round((2.0 * theta_mid - psi) / (2.0 * math.pi))
    return max(theta, 0.0), u / np.hypot(*u)


def _section_pose(problem, z: float) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (rigid fit of the section's solid points at reference height z: the channels' too
    within the tip cap, where silicone closes them) and position of the body axis there, in the
    design's frame."""
    sec = problem.prism.section
    ref = np.column_stack([sec.points, np.full(len(sec.points), z)])
    in_cap = z >= problem.design.length - problem.design.cap_thickness
    solid = np.zeros(len(sec.points), dtype=bool)
    for tri, reg in zip(sec.triangles, sec.region):
        if reg in ("silicone", "fibre") or (in_cap and reg.startswith("channel")):
            solid[tri] = True
    ref = ref[solid]
    cur = ref + _evaluate(problem, ref)
    if problem.half:
        off = np.abs(ref[:, 0]) > 1e-12
        ref, cur = _mirror(ref, off), _mirror(cur, off)
    rot = best_fit_rotation(ref, cur)
    axis = np.array([0.0, 0.0, z])
    if _axis_in_solid(problem):
        point = axis + _evaluate(problem, axis[None, :])[0]
    else:   # the axis runs through an empty lumen (e.g. a central one): carry it with the section's fit
        point = cur.mean(axis=0) + rot @ (axis - ref.mean(axis=0))
    turn = problem.rotation   # a half model about a mirror plane turned to x = 0
    if turn:   # back to the design's frame
        c, s = math.cos(-turn), math.sin(-turn)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        point, rot = rz @ point, rz @ rot @ rz.T
    return rot, point


# the body axis counts as in material when every empty hole's wall is at least this fraction of
# the outer radius from it: a wall through (or at) the axis leaves the axis point on no element
AXIS_CLEARANCE = 1e-3


def _axis_in_solid(problem) -> bool:
    """Whether the body axis is inside material (not in an empty hole nor on its wall), at the tip
    and at mid-length. A lumen with a device or a fill is solid; a channel is empty below the cap.
    Else the axis point is carried with the section's rigid fit."""
    d = problem.design
    holes = list(d.channels)
    if d.lumen is not None and d.device is None and not getattr(problem, "has_fill", False):
        holes.append(d.lumen)
    clearance = AXIS_CLEARANCE * d.outer_radius
    for h in holes:
        if getattr(h, "kind", "circle") == "circle":
            if math.hypot(*h.center) < h.radius + clearance:
                return False
        elif h.outline.contains((0.0, 0.0)) or h.outline.distance_to_point((0.0, 0.0)) < clearance:
            return False
    return True


def measure(problem) -> dict:
    """Bending angle (rad), bending direction (unit (2,)), arc length (m), tip position (m),
    channel volumes (m^3) and mid-channel areas (m^2) of the current state."""
    design = problem.design
    length = design.length
    rot, tip = _section_pose(problem, length)
    theta, direction = bending_with_mid(rot, *_section_pose(problem, 0.5 * length))
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


def deformed_backbone(problem, spacing: float) -> np.ndarray:
    """The deformed body axis (M, 3), m, in the design's frame, at reference heights at most
    ``spacing`` (m) apart from the base to the tip (each a section's rigid fit, as the tip's)."""
    length = problem.design.length
    heights = np.linspace(0.0, length, max(3, math.ceil(length / spacing) + 1))
    return np.array([_section_pose(problem, float(z))[1] for z in heights])


def channel_area(problem, i: int) -> float:
    """Area of channel i's deformed section at mid-length of its open part (Newell's formula).
    In the half model a channel the plane cuts is closed by its mirror image; one not meshed
    (at x < 0) has its mirror partner's area."""
    prism = problem.prism
    sec = prism.section
    source, factor = prism.channel_shares[i]
    if source != i:
        return channel_area(problem, source)
    z_mid = prism.z_levels[prism.n_layers_channel // 2]
    loop = _wall_loop(sec, f"channel{i}")   # counter-clockwise; a cut channel's from x = 0 to x = 0
    ref = np.column_stack([sec.points[loop], np.full(len(loop), z_mid)])
    cur = ref + _evaluate(problem, ref)
    if factor == 2.0:
        back = cur[::-1].copy()
        back[:, 0] *= -1.0
        cur = np.vstack([cur, back])
    nxt = np.roll(cur, -1, axis=0)
    return float(0.5 * np.linalg.norm(np.cross(cur, nxt).sum(axis=0)))


def _edge_owners(sec) -> dict[tuple[int, int], list[int]]:
    """Each section edge (i, j), i < j, with the triangles it bounds."""
    owners: dict[tuple[int, int], list[int]] = {}
    for t, tri in enumerate(sec.triangles):
        for j in range(3):
            a, b = int(tri[j]), int(tri[(j + 1) % 3])
            owners.setdefault((min(a, b), max(a, b)), []).append(t)
    return owners


def _wall_loop(sec, region: str) -> np.ndarray:
    """The section's points on the wall of hole ``region`` (the edges between its triangles and
    the silicone's), chained in order counter-clockwise about the hole: a closed wall from any
    point, one the half model's plane cuts from its end on x = 0 to its other end."""
    owners = _edge_owners(sec)
    nxt = {}
    for (a, b), ts in owners.items():
        inside = [t for t in ts if sec.region[t] == region]
        if len(inside) != 1 or len(ts) != 2:
            continue
        tri = [int(v) for v in sec.triangles[inside[0]]]
        k = tri.index(a)
        # the hole's triangle is left of a -> b where it runs a -> b counter-clockwise: so does the hole
        start, end = (a, b) if tri[(k + 1) % 3] == b else (b, a)
        nxt[start] = end
    if not nxt:
        return np.zeros(0, dtype=int)
    ends = set(nxt.values())
    first = next((p for p in nxt if p not in ends), next(iter(nxt)))   # an open wall starts at its end
    loop = [first]
    while loop[-1] in nxt and nxt[loop[-1]] != first and len(loop) <= len(nxt):
        loop.append(nxt[loop[-1]])
    return np.array(loop, dtype=int)


def _curve_nodes(problem, surface: str) -> tuple[np.ndarray, np.ndarray]:
    """The section's mesh points on a closed section curve (m), in order around its centre (the
    half model's half curve, x >= 0), and that centre. ``surface``: "lumen" (the section edges
    between the lumen's triangles and the silicone's) or "outer" (the edges of one triangle only,
    off the symmetry plane x = 0)."""
    sec = problem.prism.section
    lumen = problem.design.lumen
    if surface == "lumen" and getattr(lumen, "kind", "circle") != "circle":
        # a shaped lumen need not be star-shaped about its centroid: its wall chained edge to edge
        return sec.points[_wall_loop(sec, "lumen")], np.asarray(lumen.center, dtype=float)
    owners = _edge_owners(sec)
    on_plane = np.abs(sec.points[:, 0]) < 1e-12
    if surface == "lumen":
        centre = np.asarray(problem.design.lumen.center, dtype=float)
        edges = [e for e, ts in owners.items() if len(ts) == 2
                 and (sec.region[ts[0]] == "lumen") != (sec.region[ts[1]] == "lumen")]
    elif surface == "outer":
        centre = np.zeros(2)
        edges = [e for e, ts in owners.items() if len(ts) == 1 and not (on_plane[e[0]] and on_plane[e[1]])]
    else:
        raise ValueError(f"surface: 'lumen' or 'outer', not {surface!r}")
    pts = sec.points[np.unique(np.array(edges, dtype=int))]
    return pts[np.argsort(np.arctan2(pts[:, 1] - centre[1], pts[:, 0] - centre[0]))], centre


def _surface_levels(problem) -> np.ndarray:
    """z (m) at which a surface is sampled: every mesh level above the base (which does not move)
    and the middle of every layer (the P2 field is curved along z too)."""
    z = problem.prism.z_levels
    return np.sort(np.concatenate([z[1:], 0.5 * (z[:-1] + z[1:])]))


def lumen_wall_nodes(problem):
    """The section's mesh points on the lumen wall (m), in order around the lumen (the half model's
    half wall), and the z levels (m) at which the wall is sampled (``_surface_levels``)."""
    return _curve_nodes(problem, "lumen")[0], _surface_levels(problem)


def surface_stretch(problem, surface: str, per_edge: int = 4, samples: bool = False) -> dict:
    """A closed section curve's surface stretches along the body (``surface``: "lumen" wall or
    "outer" surface, see ``_curve_nodes``) at the current state, sampled at ``per_edge`` points per
    curve edge of the section on every mesh level and mid-layer, a hair inside the silicone: the
    hoop stretch |F t| (t the curve edge's reference direction in the section), the axial one
    |F e_z| and the surface's principal stretches (of the 2x2 surface Cauchy-Green tensor on t, e_z).
    A neo-Hookean surface under plane-strain compression creases at a surface stretch of about 0.65
    (Hong, Zhao & Suo 2009), wrinkles (Biot) at 0.54. Returns the smallest hoop and principal
    stretches with where (reference x, y, z in m), the surface's normal stretch there (det F over
    the product of the principal ones) and the smallest det F on the surface; with ``samples`` also
    every sample's reference point (m), hoop, axial and principal stretches and det F."""
    pts2, c = _curve_nodes(problem, surface)
    levels = _surface_levels(problem)
    nxt = pts2[1:] if problem.half else np.roll(pts2, -1, axis=0)
    start = pts2[:-1] if problem.half else pts2
    t = (np.arange(per_edge) + 0.5) / per_edge   # inside each edge: the surface is a chord there
    xy = (start[:, None, :] * (1 - t)[None, :, None] + nxt[:, None, :] * t[None, :, None]).reshape(-1, 2)
    chord = np.repeat((nxt - start) / np.linalg.norm(nxt - start, axis=1)[:, None], per_edge, axis=0)
    tangent = np.column_stack([chord, np.zeros(len(chord))])
    inward = 1e-3 if surface == "lumen" else -1e-3   # the silicone: outside the lumen, inside the outer surface
    xy = c + (xy - c) * (1.0 + inward)
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
    out = {"min_hoop_stretch": float(hoop[i]), "min_hoop_at_m": pts[i],
           "axial_stretch_there": float(np.sqrt(c22[i])),
           "min_principal_stretch": float(lam_min[k]), "other_principal_there": float(lam_max[k]),
           "normal_stretch_there": float(det[k] / (lam_min[k] * lam_max[k])), "min_principal_at_m": pts[k],
           "min_det_f": float(det.min()), "min_det_f_at_m": pts[int(np.argmin(det))]}
    if samples:
        out.update(points_m=pts, hoop_stretch=hoop, axial_stretch=np.sqrt(c22),
                   principal_stretches=np.column_stack([lam_min, lam_max]), det_f=det)
    return out


def lumen_wall_stretch(problem, per_edge: int = 4) -> dict:
    """The lumen wall's surface stretches (``surface_stretch``): the creasing diagnostic of the lumen."""
    return surface_stretch(problem, "lumen", per_edge)


def outer_surface_stretch(problem, per_edge: int = 4, samples: bool = False) -> dict:
    """The outer surface's stretches (``surface_stretch``), under the hoop reinforcement."""
    return surface_stretch(problem, "outer", per_edge, samples)
