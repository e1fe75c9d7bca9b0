"""Closed outlines from CAD files: a DXF layer (ezdxf) or an SVG element (svgelements).

Returns [(x, y, bulge)] in metres. DXF lines, arcs, circles and (LW)polylines stay exact (a
polyline's bulges are kept); SVG lines and circular arcs stay exact, Bezier curves and
elliptical arcs become chords within ``CHORD_TOLERANCE``. SVG's y axis points down: it is
flipped so the section reads as drawn. SVG coordinates are user units (the viewBox's, whatever
the page size), each a mm or a m as the design's ``units`` says. Every refusal is one ``DesignError`` line.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..errors import DesignError
from .outline import CHORD_TOLERANCE

MAX_CAD_BYTES = 16 * 2**20
_JOIN = 1e-9   # relative to the drawing's size: endpoints this close are the same point


def read_outline(path: Path, units: str, layer, element_id, field_name: str):
    scale = 1e-3 if units == "mm" else 1.0
    if not path.is_file():
        raise DesignError(f"{field_name}.path", str(path), "no such file")
    if path.stat().st_size > MAX_CAD_BYTES:
        raise DesignError(f"{field_name}.path", str(path), f"larger than {MAX_CAD_BYTES >> 20} MiB")
    suffix = path.suffix.lower()
    if suffix == ".dxf":
        if layer is None or element_id is not None:
            raise DesignError(f"{field_name}.layer", layer, "a DXF outline is named by its layer (and no id)")
        read = lambda: _dxf_loop(path, str(layer), field_name)   # noqa: E731
    elif suffix == ".svg":
        if element_id is None or layer is not None:
            raise DesignError(f"{field_name}.id", element_id, "an SVG outline is named by its element id (and no layer)")
        read = lambda: _svg_loop(path, str(element_id), field_name, scale)   # noqa: E731
    else:
        raise DesignError(f"{field_name}.path", str(path), "must be a .dxf or .svg file")
    try:
        loop = read()
    except DesignError:
        raise
    except Exception as exc:   # the CAD readers raise many kinds on a malformed file: one line, not a traceback
        raise DesignError(f"{field_name}.path", str(path), f"not a readable {suffix[1:].upper()} outline "
                                                           f"({type(exc).__name__})") from None
    if not all(math.isfinite(v) for p in loop for v in p):
        raise DesignError(f"{field_name}.path", str(path), "the outline has a coordinate that is not a finite number")
    return tuple((float(x) * scale, float(y) * scale, float(b)) for x, y, b in loop)


# ------------------------------------------------------------------------------ DXF

def _dxf_loop(path: Path, layer: str, field_name: str):
    import ezdxf

    try:
        doc = ezdxf.readfile(str(path))
    except (OSError, ezdxf.DXFError, UnicodeDecodeError, ValueError) as exc:
        raise DesignError(f"{field_name}.path", str(path), f"not a readable DXF file ({type(exc).__name__})") from None
    entities = [e for e in doc.modelspace() if e.dxf.layer == layer]
    if not entities:
        layers = sorted({e.dxf.layer for e in doc.modelspace()})
        raise DesignError(f"{field_name}.layer", layer, f"no entities on this layer; layers with entities: {layers[:20]}")
    kinds = {e.dxftype() for e in entities}
    if kinds <= {"LWPOLYLINE", "POLYLINE", "CIRCLE"} and len(entities) == 1:
        e = entities[0]
        if e.dxftype() == "CIRCLE":
            (cx, cy, _), r = e.dxf.center, e.dxf.radius
            return [(cx + r, cy, 1.0), (cx - r, cy, 1.0)]
        if e.dxftype() == "LWPOLYLINE":
            pts = [(x, y, b) for x, y, _, _, b in e.get_points("xyseb")]
            closed = e.closed
        else:
            pts = [(v.dxf.location[0], v.dxf.location[1], v.dxf.get("bulge", 0.0)) for v in e.vertices]
            closed = e.is_closed
        if not closed:
            if len(pts) > 2 and math.dist(pts[0][:2], pts[-1][:2]) <= _JOIN * _size(pts):
                pts = pts[:-1]   # closed by repeating its first point
            else:
                raise DesignError(f"{field_name}.layer", layer, "the outline on this layer is open (a polyline not closed)")
        return pts
    if not kinds <= {"LINE", "ARC"}:
        raise DesignError(f"{field_name}.layer", layer, f"expected one closed polyline or circle, or lines and arcs "
                                                        f"joined end to end; found {sorted(kinds)}")
    edges = []
    for e in entities:
        if e.dxftype() == "LINE":
            edges.append(((e.dxf.start[0], e.dxf.start[1]), (e.dxf.end[0], e.dxf.end[1]), 0.0))
        else:
            c, r = e.dxf.center, e.dxf.radius
            a0, a1 = math.radians(e.dxf.start_angle), math.radians(e.dxf.end_angle)
            sweep = (a1 - a0) % (2 * math.pi) or 2 * math.pi
            edges.append(((c[0] + r * math.cos(a0), c[1] + r * math.sin(a0)),
                          (c[0] + r * math.cos(a1), c[1] + r * math.sin(a1)), math.tan(sweep / 4)))
    return _chain(edges, f"{field_name}.layer", layer)


def _size(pts) -> float:
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    return max(max(xs) - min(xs), max(ys) - min(ys), 1e-300)


def _chain(edges, field_name, value):
    """Edges (start, end, bulge) joined end to end into one closed loop, else refused."""
    tol = _JOIN * _size([p for s, e, _ in edges for p in (s, e)]) * 1e3
    loop = [edges.pop(0)]
    while edges:
        end = loop[-1][1]
        for k, (s, e, b) in enumerate(edges):
            if math.dist(s, end) <= tol:
                loop.append(edges.pop(k))
                break
            if math.dist(e, end) <= tol:
                edges.pop(k)
                loop.append((e, s, -b))
                break
        else:
            raise DesignError(field_name, value, f"the outline is open or not one loop: no edge starts at "
                                                 f"({end[0]:g}, {end[1]:g})")
    if math.dist(loop[-1][1], loop[0][0]) > tol:
        raise DesignError(field_name, value, "the outline is open: its last edge does not return to its first")
    return [(s[0], s[1], b) for s, _, b in loop]


# ------------------------------------------------------------------------------ SVG

def _svg_loop(path: Path, element_id: str, field_name: str, scale: float):
    import svgelements as se

    try:
        svg = se.SVG.parse(str(path))
    except Exception as exc:   # svgelements raises many kinds on a malformed file
        raise DesignError(f"{field_name}.path", str(path), f"not a readable SVG file ({type(exc).__name__})") from None
    element = svg.get_element_by_id(element_id)
    if element is None or not isinstance(element, se.Shape):
        raise DesignError(f"{field_name}.id", element_id, "no shape with this id in the SVG file")
    path_ = se.Path(element)
    if svg.viewbox is not None:   # back to user units (the viewBox's): ``units`` says what one is
        path_ *= ~se.Matrix(svg.viewbox_transform)
    path_.reify()
    tol = CHORD_TOLERANCE / scale   # in the file's units
    loops, loop = [], []
    closed = False
    for seg in path_:
        if isinstance(seg, se.Move):
            if loop:
                loops.append((loop, closed))
            loop, closed = [], False
            continue
        if isinstance(seg, se.Close):
            if seg.start is not None and seg.end is not None and seg.start != seg.end:
                loop.append(((seg.start.x, -seg.start.y), (seg.end.x, -seg.end.y), 0.0))
            closed = True
            continue
        start, end = (seg.start.x, -seg.start.y), (seg.end.x, -seg.end.y)
        if isinstance(seg, se.Line):
            if start != end:
                loop.append((start, end, 0.0))
        elif isinstance(seg, se.Arc) and abs(seg.rx - seg.ry) <= 1e-12 * max(seg.rx, 1e-300):
            loop.append((start, end, -math.tan(seg.sweep / 4)))   # y flipped: the turning reverses
        else:
            n = max(2, math.ceil(seg.length() / max(math.sqrt(8 * tol * max(seg.length(), tol)), 1e-300)))
            pts = [seg.point(t / n) for t in range(n + 1)]
            loop += [((a.x, -a.y), (b.x, -b.y), 0.0) for a, b in zip(pts, pts[1:]) if a != b]
    if loop:
        loops.append((loop, closed))
    if len(loops) != 1:
        raise DesignError(f"{field_name}.id", element_id, f"expected one closed outline; the element has {len(loops)}")
    edges, closed = loops[0]
    if not edges:
        raise DesignError(f"{field_name}.id", element_id, "the element draws nothing")
    if not closed and math.dist(edges[-1][1], edges[0][0]) > 1e-9 * _size([p for s, e, _ in edges for p in (s, e)]):
        raise DesignError(f"{field_name}.id", element_id, "the outline is open (a path not closed)")
    return [(s[0], s[1], b) for s, _, b in edges]
