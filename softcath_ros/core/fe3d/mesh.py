"""Prism mesh of the actuator: the cross-section meshed in 2D (netgen), extruded along z.

The section is a netgen OCC face built from the design's outlines (core/geometry: circles,
sectors, polygons, CAD outlines; lines and circular arcs as OCC edges), meshed in 2D and
extruded into prisms. The body is a straight extrusion, so prisms fit it far better than
tetrahedra (an OCC solid extruded and meshed in 3D): the section can be fine where the walls
are thin while layers along z stay long, and the circle designs keep their mesh and answers.
Layers are split at z = L - cap so the channels end in a silicone cap.

Regions of the 2D section: ``silicone``, ``fibre`` (strain-limiting thread), ``channel{i}``,
``lumen``. In 3D the channel regions become silicone above L - cap (the cap), the lumen
becomes the ``device`` region when the design has a device, the ``fill`` region when a
soft lumen fill is asked for (a contact proxy, see solver.py), else stays empty.
Boundaries: ``base`` (z = 0, fixed), ``tip``, ``outer`` (reinforcement), ``sym`` (x = 0
when the half model is used), ``channel{i}`` (walls and the cap's inner face, normals
pointing into the silicone's outside, i.e. into the channel), ``lumen``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..design import Design
from ..errors import ModelError
from .holes import hole_size, is_circle
from .symmetry import can_use_half_model, channel_shares, partners_about_yz


@dataclass(frozen=True)
class MeshSettings:
    """Mesh size parameters, metres. ``section_h`` is the target edge length on the section,
    ``wall_h`` the edge length on hole boundaries, ``layer_h`` the prism height along z."""

    section_h: float = 0.7e-3
    wall_h: float = 0.45e-3
    layer_h: float = 4.0e-3
    cap_layers: int = 2
    lumen_h: float | None = None    # edge length on an empty lumen's wall (None: wall_h); the
                                    # contact at its folding shoulders needs it finer
    curvature_safety: float | None = None   # netgen's elements per radius on a curved edge (None: auto)

    def scaled(self, factor: float) -> "MeshSettings":
        return MeshSettings(self.section_h * factor, self.wall_h * factor, self.layer_h * factor,
                            max(1, round(self.cap_layers / factor)),
                            None if self.lumen_h is None else self.lumen_h * factor, self.curvature_safety)


# netgen's curvature safety: 2 (its own default) where every hole is a circle, the mesh those designs were
# validated on; 0.5 with a shaped hole, whose 0.1 mm fillets 2 fills with 50 um elements graded into the
# walls (three_sector_5mm, 10 mm: 1.5x the DOF, 2.1x the CPU time; R_C 1.0 % apart at 0.05 bar)
CIRCLE_CURVATURE_SAFETY = 2.0
SHAPED_CURVATURE_SAFETY = 0.5


def curvature_safety(design: Design, settings: MeshSettings) -> float:
    """The curvature safety a section is meshed with (``MeshSettings.curvature_safety``, or by its holes)."""
    if settings.curvature_safety is not None:
        return float(settings.curvature_safety)
    holes = [*design.channels, *([design.lumen] if design.lumen is not None else [])]
    return CIRCLE_CURVATURE_SAFETY if all(is_circle(h) for h in holes) else SHAPED_CURVATURE_SAFETY


@dataclass
class SectionMesh:
    points: np.ndarray      # (P, 2) m
    triangles: np.ndarray   # (T, 3) point indices, counter-clockwise
    region: list[str]       # region name per triangle


def _outline_face(outline):
    """The netgen OCC face inside an outline (core/geometry ``Outline``: lines and circular arcs)."""
    from netgen.occ import ArcOfCircle, Face, Pnt, Segment, Wire

    edges = []
    for e in outline.edges():
        p0, p1 = Pnt(e.start[0], e.start[1], 0.0), Pnt(e.end[0], e.end[1], 0.0)
        if hasattr(e, "sweep"):   # an arc: through its middle point
            a = e.start_angle + 0.5 * e.sweep
            mid = Pnt(e.center[0] + e.radius * math.cos(a), e.center[1] + e.radius * math.sin(a), 0.0)
            edges.append(ArcOfCircle(p0, mid, p1))
        else:
            edges.append(Segment(p0, p1))
    return Face(Wire(edges))


def _hole_face(hole):
    """A hole's OCC face: netgen's own circle for a circle (the mesh the circle designs always had)."""
    from netgen.occ import Circle, Pnt

    return Circle(Pnt(*hole.center), hole.radius).Face() if is_circle(hole) else _outline_face(hole.outline)


def _shaped_edge_h(edge, edge_h: float) -> float:
    """A shaped hole's edge length: an arc gets at least two segments, so that its middle point can be
    moved to give the exact area (``_snap_arc``) however coarse the curvature safety."""
    chord = math.dist(tuple(edge.start)[:2], tuple(edge.end)[:2])
    return min(edge_h, 0.5 * edge.mass) if edge.mass > chord * (1.0 + 1e-6) else edge_h


def mesh_section(design: Design, settings: MeshSettings, half: bool) -> SectionMesh:
    """Triangulate the section with netgen's OCC kernel (imported lazily)."""
    from netgen.occ import Circle, Glue, OCCGeometry, Pnt, Rectangle

    big_r = design.outer_radius
    disk = Circle(Pnt(0, 0), big_r).Face()
    if half:
        disk = disk * Rectangle(2 * big_r, 4 * big_r).Face().Move((0, -2 * big_r, 0))
    parts = []
    body = disk
    kept = {"fibre": None, "lumen": design.lumen, **{f"channel{i}": c for i, c in enumerate(design.channels)}}
    holes = [(f"channel{i}", c.center, hole_size(c), _hole_face(c)) for i, c in enumerate(design.channels)
             if not half or c.center[0] > -1e-9 * big_r]   # the half model keeps x >= 0
    if design.lumen is not None:
        holes.append(("lumen", design.lumen.center, hole_size(design.lumen), _hole_face(design.lumen)))
    if design.limiting_fibre is not None:
        f = design.limiting_fibre
        holes.append(("fibre", f.center, 0.5 * f.diameter, Circle(Pnt(*f.center), 0.5 * f.diameter).Face()))
    for name, centre, radius, face in holes:
        body = body - face
        piece = face * disk if half else face
        piece.name = name
        # A thin fibre needs a few elements across it.
        piece.maxh = min(settings.wall_h, radius / 1.5) if name == "fibre" else settings.section_h
        edge_h = min(settings.wall_h, radius / 1.5)
        if name == "lumen" and settings.lumen_h is not None and design.device is None:
            edge_h = min(edge_h, settings.lumen_h)
        for e in piece.edges:
            e.maxh = edge_h if name == "fibre" or is_circle(kept[name]) else _shaped_edge_h(e, edge_h)
        parts.append(piece)
    body.name = "silicone"
    body.maxh = settings.section_h
    for e in body.edges:
        e.maxh = min(e.maxh, settings.wall_h) if hasattr(e, "maxh") else settings.wall_h
    try:
        geo = OCCGeometry(Glue([body] + parts), dim=2)
        ngmesh = geo.GenerateMesh(maxh=settings.section_h, curvaturesafety=curvature_safety(design, settings))
    except Exception as exc:   # netgen's NgException: one line, never its traceback
        raise ModelError(f"fe3d: netgen could not mesh {design.name}'s section: {' '.join(str(exc).split())}") from None
    pts = np.array([[p[0], p[1]] for p in ngmesh.Points()])
    names = [ngmesh.GetMaterial(i + 1) for i in range(len(parts) + 1)]
    tris, region = [], []
    for el in ngmesh.Elements2D():
        v = [int(x.nr) - 1 if hasattr(x, "nr") else int(x) - 1 for x in el.vertices]
        a, b, c = pts[v[0]], pts[v[1]], pts[v[2]]
        if (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) < 0:
            v = [v[0], v[2], v[1]]
        tris.append(v)
        region.append(names[el.index - 1])
    section = SectionMesh(points=pts, triangles=np.array(tris, dtype=int), region=region)
    circles = [(c, r) for name, c, r, _ in holes if name == "fibre" or is_circle(kept[name])]
    _snap_circles(section, design, circles, half)
    for name, _, _, _ in holes:
        if name != "fibre" and not is_circle(kept[name]):
            for arc in kept[name].outline.edges():
                if hasattr(arc, "sweep"):
                    _snap_arc(section.points, arc)
    return section


def _snap_circles(section: SectionMesh, design: Design, holes, half: bool) -> None:
    """Move the vertices of each polygonal circle (the body and ``holes``: (centre, radius)) outward
    so the polygon encloses the circle's exact area: straight-sided elements would otherwise shrink
    the channel by ~1/n^2, which is a systematic error in the pressure's moment. (The arcs of
    shaped outlines are not snapped: their chords lose that ~1/n^2 of the arcs' segments.)"""
    pts = section.points
    circles = [(design.outer_radius, (0.0, 0.0))] + [(r, c) for c, r in holes]
    for radius, centre in circles:
        d = np.hypot(pts[:, 0] - centre[0], pts[:, 1] - centre[1])
        on = np.abs(d - radius) < 1e-6 * max(radius, 1e-4)
        idx = np.nonzero(on)[0]
        if len(idx) < 3:
            continue
        ang = np.sort(np.arctan2(pts[idx, 1] - centre[1], pts[idx, 0] - centre[0]))
        gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * math.pi]))
        if half and abs(centre[0]) < 1e-12:
            gaps = gaps[gaps < math.pi - 1e-9]  # the cut along x = 0 is not an arc segment
        polygon = 0.5 * np.sum(np.sin(gaps))   # area of the inscribed polygon / r^2
        exact = 0.5 * np.sum(gaps)
        pts[idx] = np.asarray(centre) + (pts[idx] - np.asarray(centre)) * math.sqrt(exact / polygon)


def _snap_arc(pts: np.ndarray, arc) -> None:
    """A shaped outline's arc (core/geometry ``Arc``) as ``_snap_circles`` does a circle: the mesh
    points inside the arc move radially by one factor so that the polyline through them (its ends
    held) encloses the arc's exact sector area about its centre."""
    c = np.asarray(arc.center, dtype=float)
    rel = pts - c
    on = np.nonzero(np.abs(np.hypot(rel[:, 0], rel[:, 1]) - arc.radius) < 1e-6 * max(arc.radius, 1e-4))[0]
    ang = np.arctan2(rel[on, 1], rel[on, 0])
    along = ((ang - arc.start_angle) * math.copysign(1.0, arc.sweep)) % (2 * math.pi)
    along = np.where(along > 2 * math.pi - 1e-9, 0.0, along)   # the start itself, rounded below it
    keep = along <= abs(arc.sweep) + 1e-9
    idx, along = on[keep], along[keep]
    if len(idx) < 3:
        return
    order = np.argsort(along)
    idx, gaps = idx[order], np.diff(along[order])
    ends = math.sin(gaps[0]) + math.sin(gaps[-1])      # fan triangles with one moved point
    middle = float(np.sum(np.sin(gaps[1:-1])))          # with two
    exact = float(np.sum(gaps))
    f = exact / ends if middle == 0.0 else (-ends + math.sqrt(ends * ends + 4.0 * middle * exact)) / (2.0 * middle)
    pts[idx[1:-1]] = c + (pts[idx[1:-1]] - c) * f


def mirrored_section(half: SectionMesh, design: Design) -> SectionMesh:
    """The full section as the half section (x >= 0) and its mirror image: a full mesh with
    x = 0 as a mirror plane, so a full model and the half model share their discretisation
    (a channel's image carries its mirror partner's name)."""
    partners = partners_about_yz(design)
    pts = half.points
    on_plane = np.abs(pts[:, 0]) < 1e-12
    image = np.arange(len(pts))
    off = np.nonzero(~on_plane)[0]
    image[off] = len(pts) + np.arange(len(off))
    mirrored = pts[off] * np.array([-1.0, 1.0])
    tris = image[half.triangles][:, [0, 2, 1]]   # a mirror reverses the orientation
    names = [f"channel{partners[int(r[7:])]}" if r.startswith("channel") else r for r in half.region]
    return SectionMesh(points=np.vstack([pts, mirrored]), triangles=np.vstack([half.triangles, tris]),
                       region=list(half.region) + names)


@dataclass
class PrismMesh:
    ngmesh: object            # netgen.meshing.Mesh
    z_levels: np.ndarray      # (K+1,) m
    section: SectionMesh
    half: bool
    n_layers_channel: int     # layers below the cap
    channel_shares: list      # (source channel, factor) per channel: see channel_shares()


def z_levels(design: Design, settings: MeshSettings) -> tuple[np.ndarray, int]:
    l_open = design.length - design.cap_thickness
    n_open = max(2, math.ceil(l_open / settings.layer_h - 1e-9))
    n_cap = max(1, settings.cap_layers)
    z = np.concatenate([np.linspace(0.0, l_open, n_open + 1),
                        np.linspace(l_open, design.length, n_cap + 1)[1:]])
    return z, n_open


def ring_bands(design: Design) -> list[tuple[float, float]]:
    """(z0, z1) of each discrete reinforcement ring on the outer surface: threads of width
    ``thread_diameter`` centred at (j + 1/2) pitch along the whole body, cap included."""
    r = design.reinforcement
    n = int(math.floor(design.length / r.pitch + 1e-9))
    half = 0.5 * r.thread_diameter
    return [((j + 0.5) * r.pitch - half, (j + 0.5) * r.pitch + half) for j in range(n)]


def z_levels_with_rings(design: Design, settings: MeshSettings) -> tuple[np.ndarray, int]:
    """Layer boundaries that resolve every ring band (one layer across a band, the gaps split to
    at most ``layer_h``), plus the cap's start: many more layers than the membrane needs."""
    l_open = design.length - design.cap_thickness
    cuts = {0.0, l_open, design.length}
    for z0, z1 in ring_bands(design):
        cuts.update((z0, z1))
    cuts = np.array(sorted(c for c in cuts if 0.0 <= c <= design.length))
    z = [cuts[0]]
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b - a < 1e-9:
            continue
        k = max(1, math.ceil((b - a) / settings.layer_h - 1e-9))
        z.extend(np.linspace(a, b, k + 1)[1:])
    z = np.array(z)
    return z, int(np.argmin(np.abs(z - l_open)))


def build_mesh(design: Design, settings: MeshSettings, half: bool | str | None = None,
               lumen_fill: bool = False, rings: bool = False) -> PrismMesh:
    """The 3D prism mesh (netgen Mesh with named regions and boundaries). ``half``: the half
    body x >= 0 (True), the full body (False), the full body meshed as the half section and its
    mirror image ("mirror"), None: half when the design allows. ``lumen_fill``:
    mesh the (empty) lumen as a ``fill`` region. ``rings``: resolve the reinforcement's
    discrete rings along z; the outer faces under a ring are the boundary ``ring``."""
    import netgen.meshing as nm

    if half is None:
        half = can_use_half_model(design)
    if half == "mirror":
        sec, half = mirrored_section(mesh_section(design, settings, True), design), False
    else:
        sec = mesh_section(design, settings, bool(half))
    rings = rings and design.reinforcement is not None
    z, n_open = z_levels_with_rings(design, settings) if rings else z_levels(design, settings)
    z_mid = 0.5 * (z[:-1] + z[1:])
    under_ring = np.zeros(len(z_mid), dtype=bool)
    for z0, z1 in (ring_bands(design) if rings else []):
        under_ring |= (z_mid > z0) & (z_mid < z1)
    n_pts, n_lev = len(sec.points), len(z)
    m = nm.Mesh(dim=3)
    pnums = []
    for zk in z:
        for x, y in sec.points:
            pnums.append(m.Add(nm.MeshPoint(nm.Pnt(float(x), float(y), float(zk)))))

    def pid(i, k):
        return pnums[k * n_pts + i]

    has_device = design.device is not None
    fill = lumen_fill and not has_device and design.lumen is not None
    domains = ["silicone", "fibre"] + (["device"] if has_device else []) + (["fill"] if fill else [])
    dom_index = {name: i + 1 for i, name in enumerate(domains)}
    for name, idx in dom_index.items():
        m.SetMaterial(idx, name)

    def solid_region(reg: str, layer: int) -> str | None:
        """Which 3D domain a section triangle becomes in a layer (None: empty)."""
        if reg in ("silicone", "fibre"):
            return reg
        if reg.startswith("channel"):
            return "silicone" if layer >= n_open else None
        if reg == "lumen":
            return "device" if has_device else ("fill" if fill else None)
        return None

    n_tri = len(sec.triangles)
    layer_domain = [[solid_region(sec.region[t], k) for t in range(n_tri)] for k in range(n_lev - 1)]
    for k in range(n_lev - 1):
        for t, (a, b, c) in enumerate(sec.triangles):
            dom = layer_domain[k][t]
            if dom is None:
                continue
            m.Add(nm.Element3D(dom_index[dom], [pid(a, k), pid(b, k), pid(c, k),
                                                  pid(a, k + 1), pid(b, k + 1), pid(c, k + 1)]))

    _add_faces(m, sec, layer_domain, pid, n_open, under_ring, half, design.outer_radius)
    return PrismMesh(ngmesh=m, z_levels=z, section=sec, half=half, n_layers_channel=n_open,
                     channel_shares=channel_shares(design, half))


def _add_faces(m, sec: SectionMesh, layer_domain, pid, n_open: int, under_ring, half: bool, outer_r: float) -> None:
    """The boundary faces of the prism mesh ``m``: quads on the section's free and hole edges per
    layer (``outer``/``ring``, ``sym``, ``channel{i}``, ``lumen``), triangles on the base, the tip and
    the channels' cap faces. ``layer_domain[k][t]``: the 3D domain of section triangle t in layer k
    (None: empty); ``pid(i, k)``: the mesh point of section point i on level k."""
    import netgen.meshing as nm

    n_lev = len(layer_domain) + 1
    bc_names: list[str] = []

    def bc(name: str) -> int:
        if name not in bc_names:
            bc_names.append(name)
            m.Add(nm.FaceDescriptor(surfnr=len(bc_names), domin=1, domout=0, bc=len(bc_names)))
            m.SetBCName(len(bc_names) - 1, name)
        return bc_names.index(name) + 1

    # Section edges: which triangles touch each edge (to find region interfaces).
    edge_tris: dict[tuple[int, int], list[int]] = {}
    for t, tri in enumerate(sec.triangles):
        for j in range(3):
            a, b = int(tri[j]), int(tri[(j + 1) % 3])
            edge_tris.setdefault((min(a, b), max(a, b)), []).append(t)
    pts = sec.points
    for k in range(n_lev - 1):
        for (a, b), ts in edge_tris.items():
            doms = [layer_domain[k][t] for t in ts]
            solid = [t for t, d in zip(ts, doms) if d is not None]
            if len(solid) != 1:
                continue  # interior edge of the solid, or an edge in empty space
            t_in = solid[0]
            other = [t for t in ts if t != t_in]
            if other:  # interface to an empty region: a hole wall
                reg = sec.region[other[0]]
                name = reg  # channel{i} or lumen
            else:
                mid = 0.5 * (pts[a] + pts[b])
                if half and abs(pts[a][0]) < 1e-12 and abs(pts[b][0]) < 1e-12:
                    name = "sym"
                elif abs(math.hypot(*mid) - outer_r) < 0.05 * outer_r:
                    name = "ring" if under_ring[k] else "outer"
                else:  # a half hole cut by the symmetry plane has no other free edges
                    name = "sym"
            # Quad a_k b_k b_k+1 a_k+1 oriented with its normal pointing out of the solid.
            tri = sec.triangles[t_in]
            centroid = pts[tri].mean(axis=0)
            edge = pts[b] - pts[a]
            normal = np.array([edge[1], -edge[0]])   # (b-a) x e_z
            if np.dot(normal, 0.5 * (pts[a] + pts[b]) - centroid) < 0:
                a, b = b, a
            m.Add(nm.Element2D(bc(name), [pid(a, k), pid(b, k), pid(b, k + 1), pid(a, k + 1)]))
    # Flat faces: base, tip and the channel caps' inner faces (z = L - cap).
    for t, (a, b, c) in enumerate(sec.triangles):
        d0 = layer_domain[0][t]
        if d0 is not None:  # base: outward normal -z, so clockwise seen from +z
            m.Add(nm.Element2D(bc("base"), [pid(a, 0), pid(c, 0), pid(b, 0)]))
        if layer_domain[-1][t] is not None:
            kt = n_lev - 1
            m.Add(nm.Element2D(bc("tip"), [pid(a, kt), pid(b, kt), pid(c, kt)]))
        reg = sec.region[t]
        if reg.startswith("channel"):
            # The cap's inner face, seen from the channel below: normal -z out of the cap.
            m.Add(nm.Element2D(bc(reg), [pid(a, n_open), pid(c, n_open), pid(b, n_open)]))
