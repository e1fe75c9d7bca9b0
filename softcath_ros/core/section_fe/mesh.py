"""Quadratic (P2) triangle mesh of the actuator cross-section: a disk with circular holes.

A small self-contained mesher (numpy + scipy's Delaunay), so the section rung needs no
meshing library: nodes on every circle at spacing ``h``, a hexagonal lattice inside,
a few rounds of Laplacian smoothing, Delaunay, and the triangles whose centroid lies
in a hole or outside the disk dropped. Midside nodes of edges on a circle are put on
the circle (isoparametric geometry), so holes are round to O(h^3).

Holes listed in ``filled`` are meshed too, as a second region (``regions`` 1, the silicone
0) that conforms to the hole's circle: its wall nodes are shared by both regions.

The P1 triangulation is checked: each region's area must equal the area of its boundary
polygons exactly, which holds only if every boundary chord is an edge of the mesh.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ModelError


@dataclass(frozen=True)
class Circle:
    center: tuple[float, float]
    radius: float


@dataclass
class SectionMesh:
    nodes: np.ndarray            # (n, 2) m, reference positions (corner and midside nodes)
    triangles: np.ndarray        # (e, 6) node ids: 3 corners counter-clockwise, then midsides 01, 12, 20
    outer_edges: np.ndarray      # (b, 3) quadratic edges on the outer circle: (start, mid, end)
    hole_edges: list[np.ndarray] = field(default_factory=list)  # per hole, (b, 3) counter-clockwise about the hole
    h: float = 0.0
    symmetric: bool = False      # exactly mirror-symmetric about x = 0
    rotations: int = 1           # 3: also exactly invariant under turns by 120 degrees about the origin
    regions: np.ndarray | None = None  # (e,) 0 silicone, 1 a filled hole's interior; None: all silicone
    filled: tuple[int, ...] = ()       # indices (into the holes) of the holes meshed as the fill region

    @property
    def silicone(self) -> np.ndarray:
        """(e,) True for silicone elements."""
        return np.ones(len(self.triangles), bool) if self.regions is None else self.regions == 0

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)


def _circle_points(c: Circle, h: float, min_points: int = 16, count: int | None = None) -> np.ndarray:
    """Counter-clockwise points on the circle, spacing about ``h``, or exactly ``count`` of them."""
    n = count if count is not None else max(min_points, int(math.ceil(2 * math.pi * c.radius / h)))
    t = 2 * math.pi * np.arange(n) / n
    return np.column_stack([c.center[0] + c.radius * np.cos(t), c.center[1] + c.radius * np.sin(t)])


def _signed_distance(p: np.ndarray, outer: Circle, holes: list[Circle]) -> np.ndarray:
    """Distance to the boundary, positive inside the silicone."""
    d = outer.radius - np.hypot(p[:, 0] - outer.center[0], p[:, 1] - outer.center[1])
    for c in holes:
        d = np.minimum(d, np.hypot(p[:, 0] - c.center[0], p[:, 1] - c.center[1]) - c.radius)
    return d


def _region(p: np.ndarray, outer: Circle, holes: list[Circle], filled: tuple[int, ...]) -> np.ndarray:
    """Per point: 0 in the silicone, 1 inside a filled hole, -1 outside the meshed domain."""
    out = np.where(_signed_distance(p, outer, holes) > 0, 0, -1)
    for i in filled:
        c = holes[i]
        out[np.hypot(p[:, 0] - c.center[0], p[:, 1] - c.center[1]) < c.radius] = 1
    return out


def _wall_distance(p: np.ndarray, outer: Circle, holes: list[Circle]) -> np.ndarray:
    """Unsigned distance to the nearest circle (outer boundary or a hole's wall)."""
    d = np.abs(outer.radius - np.hypot(p[:, 0] - outer.center[0], p[:, 1] - outer.center[1]))
    for c in holes:
        d = np.minimum(d, np.abs(np.hypot(p[:, 0] - c.center[0], p[:, 1] - c.center[1]) - c.radius))
    return d


def _mirror_partner(c: Circle, holes: list[Circle], tol: float) -> int | None:
    """Index of the hole that is ``c`` mirrored in x = 0 (itself if centred on the axis)."""
    for i, o in enumerate(holes):
        if (abs(o.center[0] + c.center[0]) < tol and abs(o.center[1] - c.center[1]) < tol
                and abs(o.radius - c.radius) < tol):
            return i
    return None


def _axis_circle_points(c: Circle, h: float) -> np.ndarray:
    """Counter-clockwise points on a circle centred on x = 0, exactly mirror-symmetric."""
    n = 4 * max(4, int(math.ceil(2 * math.pi * c.radius / h / 4)))
    # exactly n (a multiple of 4): recomputing n from the spacing can round up to n + 1
    pts = _circle_points(Circle((0.0, c.center[1]), c.radius), h, count=n)
    k = np.arange(n // 4 + 1, 3 * n // 4)
    pts[k, 0] = -pts[n // 2 - k, 0]
    pts[k, 1] = pts[n // 2 - k, 1]
    pts[[n // 4, 3 * n // 4], 0] = 0.0
    return pts


def _rotation(degrees: float) -> np.ndarray:
    t = math.radians(degrees)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


_MIRROR = np.diag([-1.0, 1.0])
# the maps of the mirror-symmetric mesh (about x = 0) and of the 3-fold one (D3: turns by 120
# degrees and the mirror), identity first
MIRROR_GROUP = [np.eye(2), _MIRROR]
THREE_FOLD_GROUP = [_rotation(a) @ m for m in (np.eye(2), _MIRROR) for a in (0.0, 120.0, 240.0)]


def _in_domain(p: np.ndarray, group: list[np.ndarray]) -> np.ndarray:
    """Points in the group's fundamental domain: x > 0 (mirror), or angles in [90, 150) degrees (D3)."""
    if len(group) == 2:
        return p[:, 0] > 0
    # closed (a triangle symmetric about a mirror line has its centroid on it): images are deduplicated
    a = np.degrees(np.arctan2(p[:, 1], p[:, 0])) % 360.0
    return (a >= 90.0 - 1e-9) & (a <= 150.0 + 1e-9)


def _is_image(c: Circle, holes: list[Circle], m: np.ndarray, tol: float) -> int | None:
    """Index of the hole that is ``c`` mapped by ``m`` (an orthogonal map about the origin)."""
    q = m @ np.asarray(c.center)
    for i, o in enumerate(holes):
        if np.hypot(*(np.asarray(o.center) - q)) < tol and abs(o.radius - c.radius) < tol:
            return i
    return None


def _three_fold(outer: Circle, holes: list[Circle], tol: float) -> bool:
    """The geometry is invariant under D3 about the origin, and every hole is centred there or on
    a mirror line of D3 (so its points can be made symmetric): the 3-fold mesher applies."""
    if np.hypot(*outer.center) > tol or not holes:
        return False
    for c in holes:
        if any(_is_image(c, holes, m, tol) is None for m in THREE_FOLD_GROUP):
            return False
        on_axis = [abs((_rotation(-a) @ np.asarray(c.center))[0]) < tol for a in (0.0, 120.0, 240.0)]
        if not any(on_axis):
            return False
    return True


def _d3_circle_points(c: Circle, h: float) -> np.ndarray:
    """Counter-clockwise points on a circle centred on the origin, invariant under D3: a multiple
    of 6, starting at 90 degrees (on every mirror line)."""
    n = 6 * max(3, int(math.ceil(2 * math.pi * c.radius / h / 6)))
    t = math.pi / 2 + 2 * math.pi * np.arange(n) / n
    return np.column_stack([c.radius * np.cos(t), c.radius * np.sin(t)])


def _three_fold_boundary(outer: Circle, holes: list[Circle], h: float, tol: float) -> list[np.ndarray]:
    """Circle points of the outer boundary and the holes, invariant under D3 as a set: a hole on
    the y axis mirror-symmetric, its images the turned copies of its points."""
    boundary = [_d3_circle_points(outer, h)]
    for c in holes:
        if np.hypot(*c.center) < tol:
            boundary.append(_d3_circle_points(Circle((0.0, 0.0), c.radius), h))
            continue
        for a in (0.0, 120.0, 240.0):
            base = _rotation(-a) @ np.asarray(c.center)
            if abs(base[0]) < tol:       # c is the hole on the y axis at base, turned by a
                q = _axis_circle_points(Circle((0.0, float(base[1])), c.radius), h)
                boundary.append(q @ _rotation(a).T)
                break
    return boundary


def _ray_points(outer: Circle, holes: list[Circle], h: float, degrees: float) -> list[tuple]:
    """Points at spacing about h on the ray from the origin at ``degrees``, inside the silicone
    (the ends of each stretch are the circle points where the ray crosses a circle)."""
    e = np.array([math.cos(math.radians(degrees)), math.sin(math.radians(degrees))])
    cuts = [0.0]
    for c in [outer] + list(holes):
        ec, cc = float(e @ np.asarray(c.center)), float(np.dot(c.center, c.center))
        disc = ec * ec - cc + c.radius ** 2
        if disc > 0:
            cuts += [r for r in (ec - math.sqrt(disc), ec + math.sqrt(disc)) if 0 < r <= outer.radius]
    cuts = sorted(set(cuts))
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        if _region(((a + b) / 2 * e)[None], outer, holes, ())[0] != 0:
            continue
        m = max(1, int(round((b - a) / h)))
        out += [tuple((a + (b - a) * t / m) * e) for t in range(1, m)]
    return out


def _group_maps(points: np.ndarray, group: list[np.ndarray], tol: float) -> list[np.ndarray]:
    """For each map g of the group, the index of g(p) for every point p (the set must be invariant)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    maps = []
    for m in group:
        d, idx = tree.query(points @ m.T)
        if np.max(d) > tol:
            raise ModelError("section mesher: the symmetric point set is not symmetric (internal error)")
        maps.append(idx)
    return maps


def _unique(points: np.ndarray, tol: float) -> np.ndarray:
    from scipy.spatial import cKDTree

    drop = {j for i, j in cKDTree(points).query_pairs(tol)}
    return points[[i for i in range(len(points)) if i not in drop]]


def mesh_section(outer: Circle, holes: list[Circle], h: float, smoothing_rounds: int = 8,
                 filled: tuple[int, ...] = ()) -> SectionMesh:
    """P2 mesh of ``outer`` minus ``holes`` with target edge length ``h`` (m); the holes whose
    indices are in ``filled`` are meshed as well, as region 1 (``SectionMesh.regions``).

    A geometry symmetric about x = 0 gets an exactly mirror-symmetric mesh, so a symmetric
    design under symmetric load gives an exactly symmetric answer (no sideways bending)."""
    if h <= 0 or h > outer.radius:
        raise ModelError(f"section mesh size h = {h} m must lie in (0, outer radius {outer.radius} m]")
    filled = tuple(sorted(set(int(i) for i in filled)))
    if any(not 0 <= i < len(holes) for i in filled):
        raise ModelError(f"section mesher: filled holes {filled} must index the {len(holes)} holes")
    tol = 1e-9 * outer.radius
    partners = [_mirror_partner(c, holes, tol) for c in holes]
    symmetric = abs(outer.center[0]) < tol and all(p is not None for p in partners)
    three_fold = not filled and _three_fold(outer, holes, tol)
    group = THREE_FOLD_GROUP if three_fold else MIRROR_GROUP if symmetric else None
    if three_fold:
        # the circles' points and points on the mirror lines (the rays at 90 and 150 degrees and
        # their images), then the lattice, all invariant under D3
        boundary = _three_fold_boundary(outer, holes, h, tol)
        rays = np.array(_ray_points(outer, holes, h, 90.0) + _ray_points(outer, holes, h, 150.0)).reshape(-1, 2)
        rays = _unique(np.concatenate([rays @ m.T for m in group]), tol)
        boundary_pts = boundary + [rays]
    elif symmetric:
        boundary = [_axis_circle_points(outer, h)]
        for i, c in enumerate(holes):
            j = partners[i]
            if j == i:
                boundary.append(_axis_circle_points(c, h))
            elif c.center[0] > 0:
                boundary.append(_circle_points(c, h))
            else:  # the mirror image of the partner's points, reversed to stay counter-clockwise
                q = _circle_points(holes[j], h)
                q[:, 0] = -q[:, 0]
                boundary.append(np.concatenate([q[:1], q[:0:-1]]))
        # points on the symmetry axis inside the silicone and the filled holes (the ends of
        # each stretch are circle points)
        cuts = sorted([(c.center[1] - c.radius, c.center[1] + c.radius) for c in holes if abs(c.center[0]) < tol])
        edges = [outer.center[1] - outer.radius] + [v for cut in cuts for v in cut] + [outer.center[1] + outer.radius]
        stretches = list(zip(edges[0::2], edges[1::2]))
        stretches += [(holes[i].center[1] - holes[i].radius, holes[i].center[1] + holes[i].radius)
                      for i in filled if abs(holes[i].center[0]) < tol]
        axis = []
        for a, b in stretches:
            m = max(1, int(round((b - a) / h)))
            axis += [(0.0, a + (b - a) * t / m) for t in range(1, m)]
        boundary_pts = boundary + [np.array(axis).reshape(-1, 2)]
    else:
        boundary = [_circle_points(outer, h)] + [_circle_points(c, h) for c in holes]
        boundary_pts = boundary
    # fixed while smoothing: the circle points (and the mirror mesh's axis points); the 3-fold
    # mesh's mirror-line points move, kept on their lines by the symmetrisation
    n_boundary = sum(len(b) for b in (boundary if three_fold else boundary_pts))
    # Hexagonal lattice, kept away from the boundary so boundary chords stay Delaunay edges
    # (with a row through the centre for the 3-fold mesh: the lattice is then invariant under D3).
    dy = h * math.sqrt(3) / 2
    ys = np.arange(-outer.radius, outer.radius + dy, dy)
    if three_fold:
        ys = dy * np.arange(-int(outer.radius / dy) - 1, int(outer.radius / dy) + 2)
    pts = []
    for j, y in enumerate(ys):
        odd = (j % 2) if not three_fold else int(round(y / dy)) % 2
        half = np.arange(0.0, outer.radius + h, h) + (0.5 * h if odd else 0.0)
        xs = np.concatenate([-half[::-1], half[1:] if half[0] == 0 else half])
        pts.append(np.column_stack([xs + outer.center[0], np.full_like(xs, y + outer.center[1])]))
    interior = np.concatenate(pts)
    def lattice_keep(p):
        return (_region(p, outer, holes, filled) >= 0) & (_wall_distance(p, outer, holes) > 0.7 * h)

    keep = lattice_keep(interior)
    if three_fold:
        # decided for a point and its images together, and away from the mirror lines (their
        # points are placed on them)
        for m in group:
            q = interior @ m.T
            keep &= lattice_keep(q) & (np.abs(q[:, 0]) > 0.7 * h)
    elif symmetric:
        # decided for a point and its mirror image together: round-off in a centre given as
        # 1e-19 instead of 0 must not keep one and drop the other
        keep &= lattice_keep(interior * np.array([-1.0, 1.0])) & (np.abs(interior[:, 0]) > 0.7 * h)
    interior = interior[keep]
    if three_fold:      # the lattice's images of a kept point, exactly (not up to round-off)
        base = interior[_in_domain(interior, group) | (np.hypot(*interior.T) < tol)]
        interior = _unique(np.concatenate([base @ m.T for m in group]), tol)
    points = np.concatenate(boundary_pts + [interior])
    maps = _group_maps(points, group, tol) if group is not None else None

    region0 = _region(points, outer, holes, filled)
    for _ in range(smoothing_rounds + 1):
        tri = _triangulate(points, outer, holes, maps, group, filled)
        if _ == smoothing_rounds:
            break
        # Laplacian smoothing of interior nodes (boundary fixed), kept inside the domain.
        acc = np.zeros_like(points)
        cnt = np.zeros(len(points))
        for a, b in ((0, 1), (1, 2), (2, 0)):
            np.add.at(acc, tri[:, a], points[tri[:, b]])
            np.add.at(acc, tri[:, b], points[tri[:, a]])
            np.add.at(cnt, tri[:, a], 1)
            np.add.at(cnt, tri[:, b], 1)
        new = points.copy()
        movable = np.arange(len(points)) >= n_boundary
        movable &= cnt > 0
        new[movable] = acc[movable] / cnt[movable, None]
        if maps is not None:  # keep the points exactly symmetric: the mean over the group
            new = sum(new[idx] @ m for idx, m in zip(maps, group)) / len(group)
        # a node stays in its own region (silicone or fill), away from every wall
        ok = (_region(new, outer, holes, filled) == region0) & (_wall_distance(new, outer, holes) > 0.5 * h)
        if maps is not None:
            for idx in maps:
                ok &= ok[idx]
        points = np.where((movable & ok)[:, None], new, points)
    regions = _region(points[tri].mean(axis=1), outer, holes, filled)
    _check_conforming(points, tri, boundary, regions, filled)
    mesh = _to_p2(points, tri, boundary, [outer] + list(holes), h)
    mesh.symmetric = symmetric
    mesh.rotations = 3 if three_fold else 1
    if filled:
        mesh.regions = regions
        mesh.filled = filled
    return mesh


def _triangulate(points: np.ndarray, outer: Circle, holes: list[Circle], maps=None, group=None,
                 filled: tuple[int, ...] = ()) -> np.ndarray:
    from scipy.spatial import Delaunay   # here, not at import: nodes that only read a table skip scipy.spatial

    tri = Delaunay(points).simplices
    centroids = points[tri].mean(axis=1)
    tri = tri[_region(centroids, outer, holes, filled) >= 0]
    if maps is not None:
        # the fundamental domain's triangles and their images (Delaunay may pick either diagonal of
        # the lattice's cocircular quadrilaterals, so the full triangulation need not be symmetric)
        base = tri[_in_domain(points[tri].mean(axis=1), group)]
        tri = np.concatenate([idx[base] for idx in maps])
        if len(group) > 2:
            tri = tri[np.unique(np.sort(tri, axis=1), axis=0, return_index=True)[1]]
    # Counter-clockwise corners.
    p = points[tri]
    area2 = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])
    tri[area2 < 0] = tri[area2 < 0][:, [0, 2, 1]]
    return tri


def _polygon_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _check_conforming(points, tri, boundary, regions, filled) -> None:
    p = points[tri]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    holes = [_polygon_area(b) for b in boundary[1:]]   # boundary: outer, holes in order (+ axis points)
    for name, got, expected in (
            ("silicone", area[regions == 0].sum(), _polygon_area(boundary[0]) - sum(holes)),
            ("fill", area[regions == 1].sum(), sum(holes[i] for i in filled))):
        if abs(got - expected) > 1e-9 * max(expected, _polygon_area(boundary[0])):
            raise ModelError(f"section mesher produced a non-conforming mesh ({name} area {got:.6e} vs "
                             f"{expected:.6e} m^2); try another mesh size")


def _to_p2(points, tri, boundary, circles, h) -> SectionMesh:
    # Unique edges -> midside nodes.
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    key = np.sort(edges, axis=1)
    uniq, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    n_p1 = len(points)
    mids = 0.5 * (points[uniq[:, 0]] + points[uniq[:, 1]])
    # Boundary nodes: the first len(boundary[0]) belong to circle 0, and so on.
    offsets = np.cumsum([0] + [len(b) for b in boundary])
    owner = np.full(n_p1, -1)
    for i in range(len(boundary)):
        owner[offsets[i]:offsets[i + 1]] = i
    on_circle = (owner[uniq[:, 0]] >= 0) & (owner[uniq[:, 0]] == owner[uniq[:, 1]])
    # An edge joining two nodes of one circle is a boundary chord only if they are neighbours on it.
    for i, c in enumerate(circles):
        sel = on_circle & (owner[uniq[:, 0]] == i)
        n_i = offsets[i + 1] - offsets[i]
        a, b = uniq[sel, 0] - offsets[i], uniq[sel, 1] - offsets[i]
        neighbours = (np.abs(a - b) == 1) | (np.abs(a - b) == n_i - 1)
        idx = np.flatnonzero(sel)
        on_circle[idx[~neighbours]] = False
        idx = idx[neighbours]
        v = mids[idx] - np.asarray(c.center)
        mids[idx] = np.asarray(c.center) + c.radius * v / np.linalg.norm(v, axis=1)[:, None]
    nodes = np.concatenate([points, mids])
    mid_ids = n_p1 + inverse.reshape(3, -1).T  # (e, 3) for edges 01, 12, 20
    triangles = np.concatenate([tri, mid_ids], axis=1)

    def circle_edges(i: int, ccw_about_center: bool) -> np.ndarray:
        n_i = offsets[i + 1] - offsets[i]
        start = offsets[i] + np.arange(n_i)
        end = offsets[i] + (np.arange(n_i) + 1) % n_i
        k = np.sort(np.column_stack([start, end]), axis=1)
        pos = np.searchsorted(uniq[:, 0] * (n_p1 + 1) + uniq[:, 1], k[:, 0] * (n_p1 + 1) + k[:, 1])
        mid = n_p1 + pos
        e = np.column_stack([start, mid, end])  # boundary points are generated counter-clockwise
        return e if ccw_about_center else e[:, ::-1]

    outer_edges = circle_edges(0, True)
    hole_edges = [circle_edges(i, True) for i in range(1, len(circles))]
    return SectionMesh(nodes=nodes, triangles=triangles, outer_edges=outer_edges, hole_edges=hole_edges, h=h)
