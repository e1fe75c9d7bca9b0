"""Channel shift: channel 0 moved along its radial line towards and away from the outer wall.

The channel keeps its diameter; steps of D/50 (0.1 mm on the 5 mm body) from 5 steps
inwards to 5 steps outwards. Variants are validated against the study's fabrication
minimum wall (``min_wall``, default 0.2 mm, core/design.py's moulding limit) rather than the
design's own minimum, and each row says whether the design's own minimum still holds; steps
past the fabrication limit are reported as infeasible.
"""
from __future__ import annotations

import math
from dataclasses import replace

from ..design import DEFAULT_MIN_WALL, Design
from ..options import Option
from .context import StudyContext, StudyResult
from .plotting import pyplot, save, where
from .variation import make_variant, min_wall_of

STEPS = 5


def variants(base: Design, min_wall: float = DEFAULT_MIN_WALL):
    ch = base.channels[0]
    dist = math.hypot(*ch.center)
    direction = (0.0, 1.0) if dist == 0 else (ch.center[0] / dist, ch.center[1] / dist)
    step = base.outer_diameter / 50.0
    out = []
    for i in range(-STEPS, STEPS + 1):
        shift = i * step
        centre = [ch.center[0] + shift * direction[0], ch.center[1] + shift * direction[1]]

        def edit(d, centre=centre):
            d["channels"][0]["center"] = centre

        outer_wall = base.outer_radius - math.hypot(*centre) - ch.radius
        v = make_variant(base, f"{shift * 1e3:+.2f} mm", "shift towards outer wall", shift, edit, baseline=i == 0,
                         min_wall=min_wall, info={"outer_wall_mm": outer_wall * 1e3,
                                                  "channel_offset_mm": math.hypot(*centre) * 1e3})
        if v.feasible:
            thinnest = min_wall_of(v.design)
            v = replace(v, info=v.info + (("thinnest_wall_mm", thinnest * 1e3),
                                          ("meets_design_min_wall", thinnest >= base.min_wall_thickness - 1e-12)))
        out.append(v)
    return out


# Steps that change R_C by less than this count as flat, not as a reversal of the trend.
FLAT = 0.005


def monotonic_decreasing(values: list[float], flat: float = FLAT) -> bool:
    """Every step outwards lowers R_C or leaves it within ``flat`` (relative)."""
    return all(b < a * (1 + flat) for a, b in zip(values, values[1:]))


# options run() takes beyond the design and the context (softcath study validates flags against them)
OPTIONS = (Option("min_wall", "float", "fabrication minimum wall in m"),)


def run(design: Design, ctx: StudyContext, min_wall: float = DEFAULT_MIN_WALL) -> StudyResult:
    rows = ctx.evaluate(variants(design, min_wall), "channel-shift")
    ok = [r for r in rows if r["radius_of_curvature_mm"] is not None]
    findings = []
    if len(ok) >= 2:
        rc = [r["radius_of_curvature_mm"] for r in ok]
        base = next((r for r in ok if r["baseline"]), None)
        findings.append(
            "shifting the channel towards the outer wall bends more (published): R_C goes from "
            f"{ok[0]['radius_of_curvature_mm']:.1f} mm (outer wall {ok[0]['outer_wall_mm']:.2f} mm) to "
            f"{ok[-1]['radius_of_curvature_mm']:.1f} mm (outer wall {ok[-1]['outer_wall_mm']:.2f} mm)"
            + (f", baseline {base['radius_of_curvature_mm']:.1f} mm" if base else "")
            + f" ({rc[-1] / rc[0] - 1:+.1%}); every outward step bends more or stays within {FLAT:.1%}: "
            f"{'yes' if monotonic_decreasing(rc) else 'no'} -> "
            f"{'holds' if rc[-1] < rc[0] and monotonic_decreasing(rc) else 'does not hold'}")
        if all(r["max_principal_stretch"] is not None for r in (ok[0], ok[-1])) and base:
            findings.append(
                "the published cost is a more fragile outer wall: the largest principal stretch in the section is "
                f"{ok[0]['max_principal_stretch']:.2f} innermost (thinnest wall {ok[0].get('thinnest_wall_mm', 0):.2f} mm), "
                f"{base['max_principal_stretch']:.2f} at the baseline and {ok[-1]['max_principal_stretch']:.2f} outermost "
                f"(outer wall {ok[-1]['outer_wall_mm']:.2f} mm): it sits in whichever wall is thinnest")
    bad = [r["label"] for r in rows if r["radius_of_curvature_mm"] is None]
    if bad:
        findings.append(f"not evaluated or not converged: {', '.join(bad)} (see status)")

    def plot(path: str) -> None:
        plt = pyplot()
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
        x = [r["outer_wall_mm"] for r in ok]
        a1.plot(x, [r["radius_of_curvature_mm"] for r in ok], "o-")
        for r in ok:
            if r["baseline"]:
                a1.plot([r["outer_wall_mm"]], [r["radius_of_curvature_mm"]], "*", ms=14, color="C1", label="baseline")
        a1.axvline(design.min_wall_thickness * 1e3, color="grey", ls=":", label="design's min wall")
        for r in rows:
            if r["radius_of_curvature_mm"] is None:
                a1.axvline(r["outer_wall_mm"], color="r", ls="--", lw=0.8)
        a1.set_xlabel("outer wall thickness [mm] (channel moves outwards to the left)")
        a1.set_ylabel("R_C [mm]")
        a1.invert_xaxis()
        a1.legend(fontsize=8)
        a1.grid(alpha=0.3)
        a2.plot(x, [r["max_principal_stretch"] for r in ok], "s-", color="C2")
        a2.set_xlabel("outer wall thickness [mm]")
        a2.set_ylabel("max principal stretch")
        a2.invert_xaxis()
        a2.grid(alpha=0.3)
        save(fig, path, f"channel shift, {where(design, ctx)} (red dashes: infeasible / not converged)")

    cols = [("label", "shift"), ("outer_wall_mm", "outer wall [mm]"), ("thinnest_wall_mm", "thinnest wall [mm]"),
            ("meets_design_min_wall", "meets design min"), ("baseline", "baseline"),
            ("radius_of_curvature_mm", "R_C [mm]"), ("max_principal_stretch", "max stretch"), ("status", "status")]
    return StudyResult("channel-shift", "Channel shift towards the outer wall", design.name, rows, cols, findings,
                       plot, meta={"min_wall_m": min_wall, "step_m": design.outer_diameter / 50.0})

