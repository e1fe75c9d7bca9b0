"""Triangle mesh of the fundamental wedge of a section (all of it without symmetry), in units of
the outer radius R: the walls' pieces inside the wedge, discretised with a spacing graded by the
wall thickness, the wedge's rays between them, a hexagonal lattice inside, completed by Triangle's
quality refinement (``mesh.py`` says why Triangle), then the P2 midside nodes, those of wall edges
on their wall's line or arc. ``mesh.py`` places the wedge and fills the section with its images.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError
from .wall_pieces import ON_RAY, Arc, Piece

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


@dataclass
class Wedge:
    nodes: np.ndarray            # P2 nodes
    triangles: np.ndarray        # (e, 6)
    regions: np.ndarray          # (e,) 0 silicone, 1 fill
    walls: np.ndarray            # (b, 3) quadratic wall edges (start, mid, end)


def exact_cos_sin(degrees: float) -> tuple[float, float]:
    """cos and sin, exact at multiples of 90 degrees (a ray on an axis has an exact zero)."""
    k = degrees / 90.0
    if abs(k - round(k)) < 1e-12:
        return [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][int(round(k)) % 4]
    t = math.radians(degrees)
    return math.cos(t), math.sin(t)


def mesh_wedge(loops: list[list[Piece]], polys, h: float, wedge, filled, lattice_angle: float) -> Wedge:
    """Mesh of the fundamental wedge (all the section if None), in units of R: walls are the
    pieces of ``loops`` (outer first) inside the wedge; ``polys`` their polygons (classification)."""
    import shapely
    import triangle

    rings = [p.exterior for p in polys]
    rays = [] if wedge is None else [np.array(exact_cos_sin(a)) for a in wedge]
    wall_size = _wall_spacing(rings, h)
    pieces = _wedge_pieces(loops, rays, wedge)
    # the meshed region: the silicone and the filled holes
    meshed = shapely.difference(polys[0], shapely.union_all(
        [polys[1 + i] for i in range(len(loops) - 1) if i not in filled] or [shapely.Polygon()]))
    chains = _Chains()
    for i, (k, q) in enumerate(pieces):
        chains.add(q.point(_wall_parameters(q, wall_size(q.point(_SAMPLES), k), h)), i)
    for e in rays:
        _add_ray(chains, e, pieces, meshed, wall_size, h)
    V, S = _merge_points(np.concatenate(chains.points), np.array(chains.segments), rays, 1e-9)
    V = np.concatenate([V, _lattice(meshed, rings, h, wedge, lattice_angle)])
    tri = triangle.triangulate({"vertices": V, "segments": S[:, 1:]},
                               f"pq{MIN_ANGLE:.1f}a{AREA_BOUND * h * h:.10f}YYQ")
    P, T = tri["vertices"], tri["triangles"]
    if len(P) < len(V) or np.max(np.abs(P[:len(V)] - V)) > 0:
        raise ModelError("section mesher: Triangle moved a wall point (internal error)")
    P, T, S, region = _meshed_triangles(P, T, S, len(V), polys, filled)
    return _quadratic(P, T, S, region, pieces)


# samples of a piece's or a ray stretch's parameter at which spacings are evaluated
_SAMPLES = np.linspace(0.0, 1.0, 65)


class _Chains:
    """Points of the walls' and rays' chains and their segments (piece index, or -1 on a ray;
    start; end), as Triangle's input."""

    def __init__(self):
        self.points: list[np.ndarray] = []
        self.segments: list[tuple[int, int, int]] = []

    def add(self, pts: np.ndarray, tag: int):
        n0 = sum(len(v) for v in self.points)
        self.points.append(pts)
        self.segments.extend((tag, n0 + i, n0 + i + 1) for i in range(len(pts) - 1))


def _wall_spacing(rings, h: float):
    """``wall_size(p, k)``: spacing on outline k at points p, a fraction of the distance to the
    other outlines."""
    import shapely

    others = [shapely.union_all([rings[j] for j in range(len(rings)) if j != k]) if len(rings) > 1 else None
              for k in range(len(rings))]

    def wall_size(p: np.ndarray, k: int) -> np.ndarray:
        d = np.full(len(p), np.inf) if others[k] is None else shapely.distance(shapely.points(p), others[k])
        return h * np.clip(d / WALL_REFERENCE, MIN_SIZE_RATIO, 1.0)

    return wall_size


def _wedge_pieces(loops: list[list[Piece]], rays, wedge) -> list[tuple[int, Piece]]:
    """(outline index, piece) of every outline's pieces, split where a wedge ray crosses them,
    those inside the wedge kept."""
    pieces: list[tuple[int, Piece]] = []
    for k, o in enumerate(loops):
        for q in o:
            ts = sorted({0.0, 1.0, *(t for e in rays for t in q.ray_hits(e))})
            for t0, t1 in zip(ts[:-1], ts[1:]):
                sub = q.sub(t0, t1)
                if wedge is None or _in_wedge(sub.point(0.5)[None], wedge)[0]:
                    pieces.append((k, sub))
    return pieces


def _wall_parameters(q: Piece, size: np.ndarray, h: float) -> np.ndarray:
    """Parameters of the points on the piece ``q`` spaced by ``size`` (at ``_SAMPLES``); round
    walls at most ARC_STEP h radians per edge."""
    density = q.length / size
    if isinstance(q, Arc):
        density = np.maximum(density, abs(q.sweep) / min(ARC_STEP * h, MAX_ARC_STEP))
    return _graded(_SAMPLES, density)


def _add_ray(chains: _Chains, e: np.ndarray, pieces, meshed, wall_size, h: float) -> None:
    """The ray ``e``'s stretches in the meshed region, cut where walls end on it, spaced from the
    walls' spacing at their ends growing at GRADING per unit length up to h."""
    import shapely

    t = _SAMPLES
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
        chains.add((a + (b - a) * _graded(t, (b - a) / size))[:, None] * e[None], -1)


def _meshed_triangles(P: np.ndarray, T: np.ndarray, S: np.ndarray, n_input: int, polys, filled):
    """Triangle's output cut to the meshed region (its quality refinement also fills the empty
    holes), renumbered, corners counter-clockwise: (points, triangles, segments, regions)."""
    import shapely

    # regions by the triangles' centroids (no triangle crosses a wall: walls are mesh edges)
    c = P[T].mean(axis=1)
    region = np.where(shapely.contains_xy(polys[0], c[:, 0], c[:, 1]), 0, -1)
    for i in range(len(polys) - 1):
        region[shapely.contains_xy(polys[1 + i], c[:, 0], c[:, 1])] = 1 if i in filled else -1
    T, region = T[region >= 0], region[region >= 0]
    # only the points of kept triangles
    used = np.unique(T)
    if not np.isin(np.arange(n_input), used).all():
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
    return P, T, S, region


def _quadratic(P: np.ndarray, T: np.ndarray, S: np.ndarray, region: np.ndarray, pieces) -> Wedge:
    """The P2 wedge: one midside node per edge; on a wall, on its piece."""
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
    return Wedge(nodes, triangles, region, np.column_stack([wall[:, 1], n1 + pos, wall[:, 2]]))


def _lattice(meshed, rings, h: float, wedge, a0: float) -> np.ndarray:
    """A hexagonal lattice of spacing h inside the meshed region, LATTICE_CLEARANCE h away from
    the walls and the wedge's rays, with a row along the direction ``a0`` (degrees: the wedge's
    first ray, so it is symmetric about the rays of a wedge between mirror lines)."""
    import shapely

    m = int(math.ceil(1.0 / h)) + 2
    j, i = np.meshgrid(np.arange(-m, m + 1), np.arange(-m, m + 1), indexing="ij")
    p = np.column_stack([(i + 0.5 * j).ravel() * h, (j * math.sqrt(3) / 2).ravel() * h])
    c, s = exact_cos_sin(a0)
    p = p @ np.array([[c, -s], [s, c]]).T
    if wedge is not None:
        p = p[_in_wedge(p, wedge)]
        for a in wedge:
            e = np.array(exact_cos_sin(a))
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



__all__ = ["Wedge", "exact_cos_sin", "mesh_wedge"]
