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
distance to the nearest other outline), the interior is a hexagonal lattice completed by
Triangle's quality refinement (``wedge_mesh.py``, with its sizes). Midside nodes of wall edges
are put on their line or arc (isoparametric geometry), so a round wall is round to O(h^3).

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
from .wall_pieces import wall_pieces
from .wedge_mesh import Wedge, exact_cos_sin, mesh_wedge

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
    c, s = exact_cos_sin(degrees)
    return np.array([[c, -s], [s, c]])


def _mirror(degrees: float) -> np.ndarray:
    """Reflection in the line through the origin at ``degrees`` from +x."""
    c, s = exact_cos_sin(2 * degrees)
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
    mesh = _replicate(mesh_wedge(loops, polys, h / R, wedge, filled, free), group, outlines, R)
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
    e = np.array(exact_cos_sin(d))
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


def _replicate(w: Wedge, group: list[np.ndarray], outlines, R: float) -> SectionMesh:
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
