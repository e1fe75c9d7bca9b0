"""Miniaturise: the design scaled to smaller outer diameters at constant area ratio.

Every length scales (core/studies/variation.scale_design_dict): holes, walls, fibre,
reinforcement pitch and thread, cap, length. Materials and pressure do not, so geometric
similarity predicts the same strains at the same pressure and R_C proportional to D: a smaller
actuator bends with a smaller radius at equal pressure (docs/actuator.md). The walls the scaling
implies are reported against the fabrication minimum (``min_wall``, default 0.2 mm);
diameters whose walls fall below it are listed as infeasible.
"""
from __future__ import annotations

from ..design import DEFAULT_MIN_WALL, Design
from ..options import Option
from .context import StudyContext, StudyResult
from .plotting import pyplot, save, where
from .variation import area_ratio, make_variant, min_wall_of, scale_design_dict

DIAMETERS_MM = (5.0, 4.0, 3.0, 2.0, 1.5)


def variants(base: Design, min_wall: float = DEFAULT_MIN_WALL, diameters_mm=DIAMETERS_MM):
    wall0 = min_wall_of(base)
    out = []
    for dm in diameters_mm:
        s = dm * 1e-3 / base.outer_diameter

        def edit(d, s=s):
            scale_design_dict(d, s)
            d["min_wall_thickness"] = min_wall   # the fabrication limit, not the scaled one

        out.append(make_variant(base, f"D {dm:g} mm", "outer diameter", dm * 1e-3, edit,
                                baseline=abs(s - 1.0) < 1e-9,
                                info={"outer_diameter_mm": dm, "scale": s, "implied_wall_mm": wall0 * s * 1e3,
                                      "area_ratio": area_ratio(base)}))
    return out


# options run() takes beyond the design and the context (softcath study validates flags against them)
OPTIONS = (Option("min_wall", "float", "fabrication minimum wall in m"),)


def run(design: Design, ctx: StudyContext, min_wall: float = DEFAULT_MIN_WALL) -> StudyResult:
    rows = ctx.evaluate(variants(design, min_wall), "miniaturise")
    for r in rows:
        r["rc_over_d"] = (None if r["radius_of_curvature_mm"] is None
                          else r["radius_of_curvature_mm"] / r["outer_diameter_mm"])
    ok = sorted((r for r in rows if r["radius_of_curvature_mm"] is not None), key=lambda r: -r["outer_diameter_mm"])
    findings = []
    if len(ok) >= 2:
        rc = [r["radius_of_curvature_mm"] for r in ok]
        ratio = [r["rc_over_d"] for r in ok]
        smaller_bends_more = all(b < a for a, b in zip(rc, rc[1:]))
        findings.append(
            "smaller actuators bend more at equal pressure (published): R_C "
            + ", ".join(f"{r['radius_of_curvature_mm']:.2f} mm at D {r['outer_diameter_mm']:g} mm" for r in ok)
            + f" -> {'holds' if smaller_bends_more else 'does not hold'}; R_C/D stays within "
            f"{max(ratio) / min(ratio) - 1:.2%} (similarity: R_C proportional to D)")
    for r in rows:
        if abs(r["outer_diameter_mm"] - 2.0) < 1e-9:
            findings.append(f"at 2 mm the walls become {r['implied_wall_mm']:.2f} mm (docs/actuator.md: 0.24 mm, fragile, "
                            "hard to mould)")
    bad = [f"{r['label']} ({r['status']})" for r in rows if r["radius_of_curvature_mm"] is None]
    if bad:
        findings.append("not evaluated: " + "; ".join(bad))

    def plot(path: str) -> None:
        plt = pyplot()
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
        d = [r["outer_diameter_mm"] for r in ok]
        a1.plot(d, [r["radius_of_curvature_mm"] for r in ok], "o-")
        a1.set_xlabel("outer diameter [mm]")
        a1.set_ylabel("R_C [mm]")
        a1.grid(alpha=0.3)
        a2.plot([r["outer_diameter_mm"] for r in rows], [r["implied_wall_mm"] for r in rows], "s-", color="C2",
                label="implied thinnest wall")
        a2.axhline(min_wall * 1e3, color="r", ls="--", label="fabrication minimum")
        a2.set_xlabel("outer diameter [mm]")
        a2.set_ylabel("wall [mm]")
        a2.legend(fontsize=8)
        a2.grid(alpha=0.3)
        save(fig, path, f"miniaturisation at constant area ratio {area_ratio(design):.3f}, {where(design, ctx)}")

    cols = [("outer_diameter_mm", "D [mm]"), ("scale", "scale"), ("implied_wall_mm", "implied wall [mm]"),
            ("area_ratio", "area ratio"), ("baseline", "baseline"), ("radius_of_curvature_mm", "R_C [mm]"),
            ("rc_over_d", "R_C/D"), ("status", "status")]
    return StudyResult("miniaturise", "Miniaturisation at constant area ratio", design.name, rows, cols, findings, plot,
                       meta={"min_wall_m": min_wall})
