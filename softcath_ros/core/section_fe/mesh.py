"""Quadratic (P2) triangle mesh of the actuator cross-section: the body outline minus its holes.

The mesher is Shewchuk's Triangle (the ``triangle`` package on PyPI), kept rather than our own:
a constrained Delaunay mesher with a minimum-angle guarantee, a few hundred kB of compiled C with
numpy as its only dependency and wheels for every platform, so the section rung needs neither
gmsh (its wheels carry a GUI toolkit's shared libraries) nor netgen (the ``fe`` extra); meshpy
wraps the same Triangle together with TetGen, which this rung does not use. Triangle keeps every
wall segment given to it as an edge of the mesh (switch ``YY``: no points added on walls), so
wall nodes are ours and sit on the true outline. (Triangle is free for research and non-commercial
use; a commercial product needs its author's permission.)

Input: the design's ``geometry.Section`` (the body circle, holes as exact outlines of lines and
arcs, roles, the fibre). Walls are discretised with a spacing graded by the wall thickness (the
distance to the nearest other outline, below), the interior is a hexagonal lattice completed
by Triangle's quality refinement. Midside nodes of wall edges are put on their line or arc
(isoparametric geometry), so a round wall is round to O(h^3).

Symmetry: the mirror lines and n-fold rotation that map the section onto itself (holes onto
holes of the same role, the fibre onto itself) come from ``geometry.symmetry``; a fundamental
wedge is meshed and its images fill the section, so the mesh has the design's symmetry exactly
(to round-off) and a symmetric design answers symmetrically. The wedge, the lattice and the
circles' first points are placed by the geometry (a mirror line, the holes' first moment of
area), so the same design turned about the axis gets the turned mesh.

Holes listed in ``filled`` are meshed too, as a second region (``regions`` 1, the silicone 0)
sharing the hole's wall nodes. Each wall is returned as a closed chain of quadratic edges,
counter-clockwise, tagged by the outline it lies on (``outer_edges``, ``hole_edges[i]``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ModelError
from .wall_pieces import ON_RAY, Arc, Piece, wall_pieces

# Sizes are proportional to h (so a finer h refines every part alike): a wall thinner than
# WALL_REFERENCE (outer radii) gets a spacing smaller than h in proportion (not below
# MIN_SIZE_RATIO h); a round wall turns at most ARC_STEP h / R radians per edge (22.5 deg at the
# default D/20), and never more than MAX_ARC_STEP (16 edges round a circle); the interior is a
# hexagonal lattice of spacing h (points LATTICE_CLEARANCE h from walls and symmetry lines)
# completed by Triangle's quality refinement
# (angles >= MIN_ANGLE, areas <= AREA_BOUND h^2); along a symmetry line the spacing grows from
# the walls at GRADING per unit length.
WALL_REFERENCE = 0.3          # outer radii: 0.75 mm on a 5 mm body
MIN_SIZE_RATIO = 0.25
ARC_STEP = math.radians(22.5) * 10
MAX_ARC_STEP = math.radians(22.5)
LATTICE_CLEARANCE = 0.7
MIN_ANGLE = 30.0
AREA_BOUND = math.sqrt(3) / 2
GRADING = 0.4
POLYGON_TOLERANCE = 1e-5     # x R: chords of the polygons that classify points (not the walls)
AREA_TOLERANCE = 1e-3        # relative: the mesh's area against the outlines' exact one
# ---------------------------------------------------------------------------- the mesh

@dataclass
class SectionMesh:
    nodes: np.ndarray            # (n, 2) m, reference positions (corner and midside nodes)
    triangles: np.ndarray        # (e, 6) node ids: 3 corners counter-clockwise, then midsides 01, 12, 20
    outer_edges: np.ndarray      # (b, 3) quadratic edges of the outer wall: (start, mid, end), counter-clockwise
    hole_edges: list[np.ndarray] = field(default_factory=list)  # per hole, (b, 3) counter-clockwise about the hole
    h: float = 0.0
    symmetric: bool = False      # exactly mirror-symmetric about x = 0
    rotations: int = 1           # n: also invariant under turns by 360/n degrees about the origin
    regions: np.ndarray | None = None  # (e,) 0 silicone, 1 a filled hole's interior; None: all silicone
    filled: tuple[int, ...] = ()       # indices (into the holes) of the holes meshed as the fill region
    mirror_lines: tuple[float, ...] = ()   # degrees from +x of the mirror lines of the mesh

    @property
    def silicone(self) -> np.ndarray:
        """(e,) True for silicone elements."""
        return np.ones(len(self.triangles), bool) if self.regions is None else self.regions == 0

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    def area(self, region: int | None = 0) -> float:
        """Area of the curved (P2) elements of a region (0 silicone, 1 fill, None all)."""
        from .quadrature import TRIANGLE_POINTS, TRIANGLE_WEIGHTS
        from .shape import p2_triangle

        _, dN = p2_triangle(TRIANGLE_POINTS[:, 0], TRIANGLE_POINTS[:, 1])
        sel = np.ones(len(self.triangles), bool) if region is None else (
            self.silicone if region == 0 else ~self.silicone)
        xe = self.nodes[self.triangles[sel]]                       # (e, 6, 2)
        J = np.einsum("qak,eai->eqik", dN, xe)
        return float(np.sum(np.linalg.det(J) @ TRIANGLE_WEIGHTS))


def _rotation(degrees: float) -> np.ndarray:
    c, s = _exact_cos_sin(degrees)
    return np.array([[c, -s], [s, c]])


def _exact_cos_sin(degrees: float) -> tuple[float, float]:
    """cos and sin, exact at multiples of 90 degrees (a ray on an axis has an exact zero)."""
    k = degrees / 90.0
    if abs(k - round(k)) < 1e-12:
        return [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][int(round(k)) % 4]
    t = math.radians(degrees)
    return math.cos(t), math.sin(t)


def _mirror(degrees: float) -> np.ndarray:
    """Reflection in the line through the origin at ``degrees`` from +x."""
    c, s = _exact_cos_sin(2 * degrees)
    return np.array([[c, s], [s, -c]])


# ---------------------------------------------------------------------------- the mesher

def mesh_section(section, h: float, filled: tuple[int, ...] = (), symmetry=None) -> SectionMesh:
    """P2 mesh of the silicone of ``section`` (``geometry.Section``) with target edge length ``h``
    (m) away from thin walls; the holes whose indices are in ``filled`` are meshed as well, as
    region 1 (``SectionMesh.regions``). ``symmetry``: a ``geometry.Symmetry`` to mesh with (None:
    ``geometry.symmetry(section)``; ``geometry.Symmetry((), 1, ...)`` for none)."""
    import shapely   # here, not at import: nodes that only read a table skip it

    from .. import geometry

    R = section.outer_radius
    if not (h > 0) or h > R:
        raise ModelError(f"section mesh size h = {h} m must lie in (0, outer radius {R} m]")
    filled = tuple(sorted(set(int(i) for i in filled)))
    if any(not 0 <= i < len(section.holes) for i in filled):
        raise ModelError(f"section mesher: filled holes {filled} must index the {len(section.holes)} holes")
    sym = geometry.symmetry(section) if symmetry is None else symmetry
    outlines = [section.outer] + [hole.outline for hole in section.holes]
    # mesh in units of R (Triangle's switches take plain decimals)
    start, width = _wedge(section, sym)
    mirror = start if sym.mirrors else None
    wedge = None if start is None else (start, start + width)
    # without symmetry the interior lattice and the circles' first points are placed by the holes'
    # first moment of area (they turn with the design)
    free = math.degrees(math.atan2(*_first_moment(section)[::-1])) if start is None else start
    loops = [wall_pieces(o, 1.0 / R, free) for o in outlines]
    polys = [shapely.transform(o.polygon(POLYGON_TOLERANCE * R), lambda c: c / R) for o in outlines]
    group = _group(sym.rotation_order, mirror)
    mesh = _replicate(_mesh_wedge(loops, polys, h / R, wedge, filled, free), group, outlines, R)
    mesh.nodes *= R
    mesh.h = h
    mesh.rotations = sym.rotation_order
    if mirror is not None:
        n = sym.rotation_order
        mesh.mirror_lines = tuple(sorted(round((mirror + 180.0 * k / n) % 180.0, 7) for k in range(n)))
        mesh.symmetric = 90.0 in mesh.mirror_lines
    if filled:
        mesh.filled = filled
    else:
        mesh.regions = None
    _check_area(mesh, section, filled)
    return mesh


def _first_moment(section) -> np.ndarray:
    return sum((hole.area * hole.centroid for hole in section.holes), np.zeros(2))


def _moment_direction(section, d: float) -> float:
    """The holes' first moment of area along the direction ``d`` (degrees)."""
    e = np.array(_exact_cos_sin(d))
    return float(sum(hole.area * (hole.centroid @ e) for hole in section.holes))


def _wedge(section, sym) -> tuple[float | None, float | None]:
    """(start of the fundamental wedge in degrees, its width; (None, None): the whole section).
    The start is a ray of a mirror line (or any ray for rotations alone) picked by the geometry
    (the largest first moment of the holes' area along it), so it turns with the design."""
    n = sym.rotation_order
    if sym.mirrors:
        # to a millionth of a degree: a line found at 89.999999999 deg (centres written to 10 digits)
        # is the y axis, whose points then have x = 0 exactly (the symmetric gauge pins them)
        rays = sorted({round(math.degrees(m.angle) % 180.0 + k, 6) % 360.0 for m in sym.mirrors for k in (0.0, 180.0)})
        width = 180.0 / n
    elif n > 1:
        rays = sorted({round(math.degrees(math.atan2(c[1], c[0])), 6) % 360.0
                       for c in (hole.centroid for hole in section.holes) if np.hypot(*c) > 1e-9 * section.outer_radius}
                      or {90.0})
        width = 360.0 / n
    else:
        return None, None
    moments = [_moment_direction(section, r) for r in rays]
    tie = 1e-9 * section.outer_radius * sum(hole.area for hole in section.holes)
    return next(r for r, m in zip(rays, moments) if m >= max(moments) - tie), width


def _group(n: int, mirror: float | None) -> list[np.ndarray]:
    """The symmetry group's maps, identity first: turns by 360/n degrees, and with a mirror
    line (degrees) the mirrors too."""
    turns = [_rotation(360.0 * k / n) for k in range(n)]
    return turns if mirror is None else turns + [t @ _mirror(mirror) for t in turns]


@dataclass
class _Wedge:
    nodes: np.ndarray            # P2 nodes
    triangles: np.ndarray        # (e, 6)
    regions: np.ndarray          # (e,) 0 silicone, 1 fill
    walls: np.ndarray            # (b, 3) quadratic wall edges (start, mid, end)


def _mesh_wedge(loops: list[list[Piece]], polys, h: float, wedge, filled, lattice_angle: float) -> _Wedge:
    """Mesh of the fundamental wedge (all the section if None), in units of R: walls are the
    pieces of ``loops`` (outer first) inside the wedge; ``polys`` their polygons (classification)."""
    import shapely
    import triangle

    rings = [p.exterior for p in polys]
    others = [shapely.union_all([rings[j] for j in range(len(loops)) if j != k]) if len(loops) > 1 else None
              for k in range(len(loops))]
    rays = [] if wedge is None else [np.array(_exact_cos_sin(a)) for a in wedge]

    def wall_size(p: np.ndarray, k: int) -> np.ndarray:
        """Spacing on outline k at points p: a fraction of the distance to the other outlines."""
        d = np.full(len(p), np.inf) if others[k] is None else shapely.distance(shapely.points(p), others[k])
        return h * np.clip(d / WALL_REFERENCE, MIN_SIZE_RATIO, 1.0)

    # pieces of every outline, split where a wedge ray crosses them, those inside the wedge kept
    pieces: list[tuple[int, Piece]] = []
    for k, o in enumerate(loops):
        for q in o:
            ts = sorted({0.0, 1.0, *(t for e in rays for t in q.ray_hits(e))})
            for t0, t1 in zip(ts[:-1], ts[1:]):
                sub = q.sub(t0, t1)
                if wedge is None or _in_wedge(sub.point(0.5)[None], wedge)[0]:
                    pieces.append((k, sub))
    verts: list[np.ndarray] = []
    segs: list[tuple[int, int, int]] = []        # (piece index, or -1 on a ray; start; end)

    def add_chain(pts: np.ndarray, tag: int):
        n0 = sum(len(v) for v in verts)
        verts.append(pts)
        segs.extend((tag, n0 + i, n0 + i + 1) for i in range(len(pts) - 1))

    t = np.linspace(0.0, 1.0, 65)
    for i, (k, q) in enumerate(pieces):
        density = q.length / wall_size(q.point(t), k)
        if isinstance(q, Arc):    # round walls: at most ARC_STEP h radians per edge
            density = np.maximum(density, abs(q.sweep) / min(ARC_STEP * h, MAX_ARC_STEP))
        add_chain(q.point(_graded(t, density)), i)
    # the rays' stretches in the meshed region (silicone, filled holes), cut where walls end on them
    meshed = shapely.difference(polys[0], shapely.union_all(
        [polys[1 + i] for i in range(len(loops) - 1) if i not in filled] or [shapely.Polygon()]))
    for e in rays:
        cuts = {0.0: None}
        for k, q in pieces:
            for end in (q.point(0.0), q.point(1.0)):
                if abs(_cross(end, e)) < ON_RAY and end @ e > ON_RAY:
                    cuts[float(end @ e)] = k
        radii = sorted(cuts)
        for a, b in zip(radii[:-1], radii[1:]):
            if b - a < 1e-9 or not meshed.contains(shapely.Point(*((a + b) / 2 * e))):
                continue
            r = a + (b - a) * t
            size = np.full_like(r, h)
            for end, k in ((a, cuts[a]), (b, cuts[b])):
                if k is not None:
                    size = np.minimum(size, wall_size((end * e)[None], k)[0] + GRADING * np.abs(r - end))
            add_chain((a + (b - a) * _graded(t, (b - a) / size))[:, None] * e[None], -1)
    V, S = _merge_points(np.concatenate(verts), np.array(segs), rays, 1e-9)
    V = np.concatenate([V, _lattice(meshed, rings, h, wedge, lattice_angle)])
    tri = triangle.triangulate({"vertices": V, "segments": S[:, 1:]},
                               f"pq{MIN_ANGLE:.1f}a{AREA_BOUND * h * h:.10f}YYQ")
    P, T = tri["vertices"], tri["triangles"]
    if len(P) < len(V) or np.max(np.abs(P[:len(V)] - V)) > 0:
        raise ModelError("section mesher: Triangle moved a wall point (internal error)")
    # regions by the triangles' centroids (no triangle crosses a wall: walls are mesh edges)
    c = P[T].mean(axis=1)
    region = np.where(shapely.contains_xy(polys[0], c[:, 0], c[:, 1]), 0, -1)
    for i in range(len(loops) - 1):
        region[shapely.contains_xy(polys[1 + i], c[:, 0], c[:, 1])] = 1 if i in filled else -1
    T, region = T[region >= 0], region[region >= 0]
    # only the points of kept triangles (Triangle's quality refinement also fills the holes)
    used = np.unique(T)
    if not np.isin(np.arange(len(V)), used).all():
        wall_ids = S[S[:, 0] >= 0][:, 1:]
        if not np.isin(wall_ids, used).all():
            raise ModelError("section mesher: a wall point is in no element (internal error)")
    new = np.full(len(P), -1)
    new[used] = np.arange(len(used))
    P, T = P[used], new[T]
    S = np.column_stack([S[:, 0], new[S[:, 1]], new[S[:, 2]]])
    p = P[T]
    area2 = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
             - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    T[area2 < 0] = T[area2 < 0][:, [0, 2, 1]]            # counter-clockwise corners
    # P2: one midside node per edge; on a wall, on its piece
    edges = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    uniq, inverse = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True)
    mids = 0.5 * (P[uniq[:, 0]] + P[uniq[:, 1]])
    n1 = len(P)
    code = uniq[:, 0] * (n1 + 1) + uniq[:, 1]
    wall = S[S[:, 0] >= 0]
    ws = np.sort(wall[:, 1:], axis=1)
    wcode = ws[:, 0] * (n1 + 1) + ws[:, 1]
    pos = np.minimum(np.searchsorted(code, wcode), len(code) - 1)
    if np.any(code[pos] != wcode):
        raise ModelError("section mesher: a wall segment is not an edge of the mesh (internal error)")
    for i in np.unique(wall[:, 0]):
        sel = wall[:, 0] == i
        mids[pos[sel]] = pieces[i][1].project(mids[pos[sel]])
    nodes = np.concatenate([P, mids])
    triangles = np.concatenate([T, n1 + inverse.ravel().reshape(3, -1).T], axis=1)
    return _Wedge(nodes, triangles, region, np.column_stack([wall[:, 1], n1 + pos, wall[:, 2]]))


def _lattice(meshed, rings, h: float, wedge, a0: float) -> np.ndarray:
    """A hexagonal lattice of spacing h inside the meshed region, LATTICE_CLEARANCE h away from
    the walls and the wedge's rays, with a row along the direction ``a0`` (degrees: the wedge's
    first ray, so it is symmetric about the rays of a wedge between mirror lines)."""
    import shapely

    m = int(math.ceil(1.0 / h)) + 2
    j, i = np.meshgrid(np.arange(-m, m + 1), np.arange(-m, m + 1), indexing="ij")
    p = np.column_stack([(i + 0.5 * j).ravel() * h, (j * math.sqrt(3) / 2).ravel() * h])
    c, s = _exact_cos_sin(a0)
    p = p @ np.array([[c, -s], [s, c]]).T
    if wedge is not None:
        p = p[_in_wedge(p, wedge)]
        for a in wedge:
            e = np.array(_exact_cos_sin(a))
            p = p[np.abs(p[:, 0] * e[1] - p[:, 1] * e[0]) > LATTICE_CLEARANCE * h]
    p = p[shapely.contains_xy(meshed, p[:, 0], p[:, 1])]
    d = shapely.distance(shapely.points(p), shapely.union_all(rings))
    return p[d > LATTICE_CLEARANCE * h]


def _cross(p, e) -> float:
    return float(p[0] * e[1] - p[1] * e[0])


def _graded(t: np.ndarray, density: np.ndarray) -> np.ndarray:
    """Parameters of points along [0, 1] spaced by a size field: ``density`` = length / size at
    the samples ``t``; at least one interval."""
    w = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(t))])
    n = max(1, int(round(w[-1])))
    return np.interp(np.linspace(0.0, w[-1], n + 1), w, t)


def _in_wedge(p: np.ndarray, wedge) -> np.ndarray:
    """Points strictly inside the wedge between the rays at angles wedge[0] and wedge[1]."""
    a = (np.degrees(np.arctan2(p[:, 1], p[:, 0])) - wedge[0]) % 360.0
    return (a > 1e-9) & (a < (wedge[1] - wedge[0]) - 1e-9)


def _merge_points(V: np.ndarray, S: np.ndarray, rays, tol: float):
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree

    # a point on a ray is put exactly on it (a ray on an axis then has exact zeros), before the
    # merge: a wall's corner and the ray's cut there are then one point
    for e in rays:
        on = np.abs(V[:, 0] * e[1] - V[:, 1] * e[0]) < ON_RAY
        V[on] = (V[on] @ e)[:, None] * e[None]
    pairs = np.array(sorted(cKDTree(V).query_pairs(tol)), dtype=np.int64).reshape(-1, 2)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(V), len(V)))
    _, label = connected_components(g, directed=False)
    first = {}
    keep = []
    for i, lab in enumerate(label):
        if lab not in first:
            first[lab] = len(keep)
            keep.append(i)
    new = np.array([first[lab] for lab in label])
    S = S.copy()
    S[:, 1], S[:, 2] = new[S[:, 1]], new[S[:, 2]]
    S = S[S[:, 1] != S[:, 2]]
    return V[keep], S


def _replicate(w: _Wedge, group: list[np.ndarray], outlines, R: float) -> SectionMesh:
    """The wedge's images under the group, coincident nodes merged, walls chained per outline."""
    from scipy.spatial import cKDTree

    nn = len(w.nodes)
    nodes = np.concatenate([w.nodes @ m.T for m in group])
    tris, walls = [], []
    for k, m in enumerate(group):
        t = w.triangles + k * nn
        if np.linalg.det(m) < 0:
            t = t[:, [0, 2, 1, 5, 4, 3]]
        tris.append(t)
        walls.append(w.walls + k * nn)
    tri = np.concatenate(tris)
    wall = np.concatenate(walls)
    regions = np.tile(w.regions, len(group))
    # merge: the first copy of a node (the identity's) wins
    pairs = np.array(sorted(cKDTree(nodes).query_pairs(1e-9)), dtype=np.int64).reshape(-1, 2)
    rep = np.arange(len(nodes))
    for a, b in pairs:                                   # a < b
        ra = rep[a]
        while rep[ra] != ra:
            ra = rep[ra]
        rb = rep[b]
        while rep[rb] != rb:
            rb = rep[rb]
        if ra != rb:
            rep[max(ra, rb)] = min(ra, rb)
    for i in range(len(rep)):
        r = i
        while rep[r] != r:
            r = rep[r]
        rep[i] = r
    used = np.unique(rep)
    new = np.full(len(nodes), -1)
    new[used] = np.arange(len(used))
    idx = new[rep]
    nodes, tri, wall = nodes[used], idx[tri], idx[wall]
    # drop duplicated triangles (a wedge of the whole section maps onto itself: none expected)
    tri_key = np.sort(tri[:, :3], axis=1)
    _, first = np.unique(tri_key, axis=0, return_index=True)
    first = np.sort(first)
    tri, regions = tri[first], regions[first]
    _, wfirst = np.unique(np.sort(wall[:, [0, 2]], axis=1), axis=0, return_index=True)
    wall = wall[np.sort(wfirst)]
    chains = _chain_walls(wall, nodes)
    # each chain is the wall of the outline it lies on
    owner = []
    for ch in chains:
        p = nodes[ch[len(ch) // 2, 0]]
        owner.append(int(np.argmin([o.distance_to_point(p * R) for o in outlines])))
    if sorted(owner) != list(range(len(outlines))):
        raise ModelError(f"section mesher: found walls of outlines {sorted(owner)} instead of one each "
                         f"(0..{len(outlines) - 1}); try another mesh size")
    by_owner = dict(zip(owner, chains))
    return SectionMesh(nodes=nodes, triangles=tri, outer_edges=by_owner[0],
                       hole_edges=[by_owner[i] for i in range(1, len(outlines))], regions=regions)


def _chain_walls(wall: np.ndarray, nodes: np.ndarray) -> list[np.ndarray]:
    """Closed chains of the quadratic wall edges, each counter-clockwise."""
    nxt: dict[int, list[int]] = {}
    for i, (a, _, b) in enumerate(wall):
        nxt.setdefault(int(a), []).append(i)
        nxt.setdefault(int(b), []).append(i)
    if any(len(v) != 2 for v in nxt.values()):
        raise ModelError("section mesher: a wall is not a closed chain (outlines touch?)")
    done = np.zeros(len(wall), bool)
    chains = []
    for s in range(len(wall)):
        if done[s]:
            continue
        chain = []
        i, start = s, int(wall[s, 0])
        a = start
        while True:
            done[i] = True
            e = wall[i] if wall[i, 0] == a else wall[i, ::-1]
            chain.append(e)
            a = int(e[2])
            if a == start:
                break
            i = next(j for j in nxt[a] if not done[j])
        ch = np.array(chain)
        p = nodes[ch[:, :2].ravel()]
        signed = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        chains.append(ch if signed > 0 else ch[::-1, ::-1])
    return chains


def _check_area(mesh: SectionMesh, section, filled) -> None:
    """The curved mesh's area equals the outlines' exact area (a lost or doubled element, or a
    wall off its outline, shows here)."""
    for name, got, expected in (
            ("silicone", mesh.area(0), section.silicone_area),
            ("fill", mesh.area(1) if filled else 0.0, sum(section.holes[i].area for i in filled))):
        if abs(got - expected) > AREA_TOLERANCE * expected:
            raise ModelError(f"section mesher: {name} area {got:.6e} m^2 differs from the outlines' "
                             f"{expected:.6e} m^2; try another mesh size")
