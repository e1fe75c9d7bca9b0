"""`softcath design check|show DESIGN`: validate a design's cross-section and print its numbers,
or draw it (holes, fibre, device, the thinnest wall marked).

``check`` prints each hole's area and centroid, each channel's offset from the neutral axis (the
pressure force's lever arm in the closed form), the area ratio, the thinnest wall and the symmetry
found from the outlines. A design that does not load is refused in one line (exit 2).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core import json_output


def register(sub) -> None:
    p = sub.add_parser("design", help="check or draw a design's cross-section (areas, walls, symmetry)")
    dsub = p.add_subparsers(dest="design_command", required=True, parser_class=type(p))
    c = dsub.add_parser("check", help="validate a design and print its areas, centroid offsets and thinnest wall")
    c.add_argument("design", help="design file, or the name of a shipped design")
    c.add_argument("--json", action="store_true", help="machine-readable output")
    c.set_defaults(func=run_check)
    s = dsub.add_parser("show", help="draw the cross-section to a PNG")
    s.add_argument("design", help="design file, or the name of a shipped design")
    s.add_argument("--out", default=None, help="PNG to write (default: <design name>_section.png here)")
    s.set_defaults(func=run_show)


def summary(design) -> dict:
    """The numbers `design check` prints (SI units)."""
    from ..core.geometry import symmetry
    from ..core.section_properties import transformed_section

    section = design.section
    ts = transformed_section(design)
    holes = []
    for h in section.holes:
        row = {"hole": h.name, "shape": h.shape.kind, "area_m2": h.area, "centroid_m": list(h.centroid)}
        if h.role == "channel":
            row["offset_from_neutral_axis_m"] = list(h.centroid - ts.neutral_axis)
        holes.append(row)
    wall = section.thinnest_wall()
    sym = symmetry(section)
    return {"design": design.name, "source": design.source, "valid": True,
            "outer_diameter_m": design.outer_diameter, "body_area_m2": section.body_area,
            "silicone_area_m2": section.silicone_area, "area_ratio": section.area_ratio,
            "neutral_axis_m": list(ts.neutral_axis), "holes": holes,
            "thinnest_wall": {"thickness_m": wall.thickness, "between": list(wall.between),
                              "points_m": [list(p) for p in wall.points]},
            "min_wall_thickness_m": design.min_wall_thickness,
            "symmetry": {"rotation_order": sym.rotation_order,
                         "mirror_angles_deg": [math.degrees(m.angle) for m in sym.mirrors]}}


def run_check(args) -> int:
    from ..core.design import load_design

    doc = summary(load_design(args.design))
    if args.json:
        print(json_output.dumps(doc, indent=2))
        return 0
    mm = 1e3

    def xy(v) -> str:   # mm, no "-0.0000"
        return ", ".join(f"{round(c * mm, 4) + 0.0:+.4f}" for c in v)

    print(f"design {doc['design']}: valid ({doc['source']})")
    print(f"body: outer diameter {doc['outer_diameter_m'] * mm:.3f} mm, area {doc['body_area_m2'] * 1e6:.4f} mm^2, "
          f"silicone {doc['silicone_area_m2'] * 1e6:.4f} mm^2")
    na = doc["neutral_axis_m"]
    print(f"neutral axis (modulus-weighted centroid): x, y {xy(na)} mm")
    print(f"{'hole':<12} {'shape':<8} {'area mm^2':>10} {'centroid x, y mm':>20} {'offset x, y mm':>20}")
    for h in doc["holes"]:
        c = h["centroid_m"]
        off = h.get("offset_from_neutral_axis_m")
        off_text = "-" if off is None else xy(off)
        print(f"{h['hole']:<12} {h['shape']:<8} {h['area_m2'] * 1e6:>10.4f} {xy(c):>20} {off_text:>20}")
    print(f"area ratio (channels / body): {doc['area_ratio']:.4f}")
    w = doc["thinnest_wall"]
    print(f"thinnest wall: {w['thickness_m'] * mm:.4f} mm between {w['between'][0]} and {w['between'][1]} "
          f"(minimum {doc['min_wall_thickness_m'] * mm:.4f} mm)")
    s = doc["symmetry"]
    mirrors = ", ".join(f"{a:.1f}" for a in s["mirror_angles_deg"]) or "none"
    turns = "no rotation" if s["rotation_order"] == 1 else f"{s['rotation_order']}-fold rotation"
    print(f"symmetry: {turns}; mirror lines at {mirrors} deg")
    return 0


def draw_section(design, out: Path) -> Path:
    """The cross-section to ``out`` (PNG): silicone grey, channels blue, lumen orange, fibre black,
    device dashed, thinnest wall red, neutral axis a cross, mirror lines dotted; axes in mm."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle as CirclePatch
    from matplotlib.patches import Polygon as PolygonPatch

    from ..core.section_properties import transformed_section

    section = design.section
    mm = 1e3
    fig = Figure(figsize=(4.6, 4.6), dpi=90)
    ax = fig.add_subplot()
    ax.add_patch(PolygonPatch(section.outer.polygon_points(1e-6) * mm, facecolor="0.85", edgecolor="0.3"))
    for h in section.holes:
        colour = "C0" if h.role == "channel" else "C1"
        ax.add_patch(PolygonPatch(h.outline.polygon_points(1e-6) * mm, facecolor="white", edgecolor=colour, lw=1.5))
        cx, cy = h.centroid * mm
        ax.annotate(h.name.replace("channels", "ch"), (cx, cy), ha="center", va="center", fontsize=7, color=colour)
    if section.fibre is not None:
        ax.add_patch(CirclePatch(np.asarray(section.fibre.center) * mm, section.fibre.radius * mm, color="k"))
    if design.device is not None and section.lumen is not None:
        centre = _device_centre(section.lumen)
        ax.add_patch(CirclePatch(centre * mm, 0.5 * design.device.diameter * mm, fill=False, ls="--", color="C2",
                                 label=f"device {design.device.diameter * mm:.2f} mm"))
    from ..core.geometry import symmetry

    r_out = section.outer_radius * mm
    for i, m in enumerate(symmetry(section).mirrors):   # mirror lines found from the outlines
        dx, dy = r_out * np.cos(m.angle), r_out * np.sin(m.angle)
        ax.plot([-dx, dx], [-dy, dy], ls=":", color="0.45", lw=0.8, label="mirror lines" if i == 0 else None)
    na = transformed_section(design).neutral_axis * mm
    ax.plot(*na, "x", color="C3", ms=6, label="neutral axis")
    wall = section.thinnest_wall()
    (x0, y0), (x1, y1) = wall.points
    ax.plot([x0 * mm, x1 * mm], [y0 * mm, y1 * mm], color="red", lw=2.5,
            label=f"thinnest wall {wall.thickness * mm:.3f} mm")
    r = section.outer_radius * mm * 1.05
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"{design.name}: channel area ratio {section.area_ratio:.3f}", fontsize=9)
    ax.legend(loc="lower right", fontsize=7, framealpha=0.8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, metadata={"Software": None})
    return out


def _device_centre(lumen) -> np.ndarray:
    """Where a device sits in the lumen: a circle's centre, else the centre of the largest circle inside."""
    if lumen.is_circle:
        return np.asarray(lumen.shape.center, dtype=float)
    from shapely import maximum_inscribed_circle

    return np.asarray(maximum_inscribed_circle(lumen.polygon).coords[0])


def run_show(args) -> int:
    from ..core.design import load_design

    design = load_design(args.design)
    out = Path(args.out or f"{design.name}_section.png")
    if out.suffix.lower() != ".png":
        from ..core.errors import SoftcathError

        raise SoftcathError(f"--out {out}: must end in .png")
    print(f"wrote {draw_section(design, out)}")
    return 0
