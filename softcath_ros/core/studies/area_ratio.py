"""Area ratio: outer diameter, wall thickness and lumen diameter varied on a grid, the channel(s)
filling the remaining space; R_C against channel area / body area (docs/actuator.md's key parameter).

Layout: a 1-channel design keeps the implemented stacking along y (bottom wall with the fibre,
lumen, middle wall, channel, outer wall; variation.stacked_layout), every wall equal to the
varied thickness. A multi-channel design keeps N equal channels around a central lumen at the
largest size the walls allow (core/channel_layout.py). Grid: outer diameter x0.8/1/1.2, wall
x2/3, x1, x4/3 of the baseline's thinnest wall, lumen x2/3, 1, 4/3 (27 cases, some infeasible).

Does the ratio alone summarise them? Judged by how much R_C still differs between cases at
nearly the same ratio (within RATIO_WINDOW, relative) and by the scatter about a fit of log R_C on log ratio;
also for R_C / D, since geometric similarity predicts R_C proportional to D at a fixed ratio.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np

from ..channel_layout import max_channel_layout
from ..design import DEFAULT_MIN_WALL, Design
from ..errors import DesignError
from ..options import Option
from .context import StudyContext, StudyResult
from .plotting import pyplot, save, where
from .variation import apply_stacked, area_ratio, make_variant, min_wall_of, stacked_layout

OUTER = (0.8, 1.0, 1.2)
WALL = (2 / 3, 1.0, 4 / 3)
LUMEN = (2 / 3, 1.0, 4 / 3)
RATIO_WINDOW = 0.05   # cases whose area ratios differ by less than 5% count as 'similar ratio'


def _fill(base: Design, outer: float, wall: float, lumen: float):
    def edit(d):
        d["outer_diameter"] = outer
        if base.n_channels == 1:
            apply_stacked(d, stacked_layout(outer, lumen, wall, wall, wall))
        else:
            try:
                lay = max_channel_layout(outer, lumen, wall, base.n_channels)
            except ValueError as exc:
                raise DesignError("channels", None, f"no layout: {exc}") from None
            first = math.degrees(math.atan2(base.channels[0].center[1], base.channels[0].center[0]))
            d["channels"] = [{"diameter": lay.channel_diameter, "center": list(c)}
                             for c in lay.centers(base.n_channels, first)]
            d["lumen"] = {"diameter": lumen, "center": [0.0, 0.0]}
        if d.get("limiting_fibre") and base.n_channels == 1:
            d["limiting_fibre"]["diameter"] = min(d["limiting_fibre"]["diameter"], 0.5 * wall)
        if d.get("device"):
            d["device"]["diameter"] = min(d["device"]["diameter"], lumen)
    return edit


def variants(base: Design, min_wall: float = DEFAULT_MIN_WALL):
    if base.lumen is None:
        raise DesignError("lumen", None, "the area-ratio study varies the lumen; this design has none")
    wall0 = min_wall_of(base)
    out = []
    for fo, fw, fl in itertools.product(OUTER, WALL, LUMEN):
        outer, wall, lumen = base.outer_diameter * fo, wall0 * fw, base.lumen.diameter * fl
        label = f"D {outer * 1e3:.1f}, w {wall * 1e3:.2f}, d_l {lumen * 1e3:.2f} mm"
        v = make_variant(base, label, "outer/wall/lumen", label, _fill(base, outer, wall, lumen),
                         baseline=(fo, fw, fl) == (1.0, 1.0, 1.0), min_wall=min_wall,
                         info={"outer_diameter_mm": outer * 1e3, "wall_mm": wall * 1e3, "lumen_mm": lumen * 1e3})
        if v.feasible:
            v = replace(v, info=v.info + (("channel_diameter_mm", v.design.channels[0].diameter * 1e3),
                                          ("area_ratio", area_ratio(v.design))))
        out.append(v)
    return out


def collapse(rows: list[dict], key: str) -> dict:
    """How well ``key`` (R_C or R_C/D) is a function of the area ratio alone.

    ``r2``: of a straight-line fit of log(key) on log(ratio); ``worst_bin_spread``: the largest
    (max/min - 1) of ``key`` among cases whose ratios lie within RATIO_WINDOW (relative) of each other."""
    pts = sorted((r["area_ratio"], r[key]) for r in rows if r.get(key) is not None)
    if len(pts) < 3:
        return {"r2": None, "worst_bin_spread": None, "bin": None}
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    coef = np.polyfit(x, y, 1)
    res = y - np.polyval(coef, x)
    r2 = 1 - float(res @ res) / float(((y - y.mean()) ** 2).sum())
    worst, where = 0.0, None
    for i, (ri, _) in enumerate(pts):
        group = [v for rj, v in pts if ri <= rj <= ri * (1 + RATIO_WINDOW)]
        if len(group) >= 2:
            s = max(group) / min(group) - 1
            if s > worst:
                worst, where = s, ri
    return {"r2": r2, "slope": float(coef[0]), "worst_bin_spread": worst, "bin": where}


# options run() takes beyond the design and the context (softcath study validates flags against them)
OPTIONS = (Option("min_wall", "float", "fabrication minimum wall in m"),)


def run(design: Design, ctx: StudyContext, min_wall: float = DEFAULT_MIN_WALL) -> StudyResult:
    rows = ctx.evaluate(variants(design, min_wall), "area-ratio")
    for r in rows:
        r["rc_over_d"] = (None if r["radius_of_curvature_mm"] is None
                          else r["radius_of_curvature_mm"] / r["outer_diameter_mm"])
    ok = [r for r in rows if r["radius_of_curvature_mm"] is not None]
    c_rc, c_norm = collapse(ok, "radius_of_curvature_mm"), collapse(ok, "rc_over_d")
    findings = []
    if c_rc["r2"] is not None:
        findings.append(
            f"the area ratio is the key parameter (published): over {len(ok)} converged cases (ratios "
            f"{min(r['area_ratio'] for r in ok):.3f}..{max(r['area_ratio'] for r in ok):.3f}) a power law in the ratio "
            f"explains R^2 = {c_rc['r2']:.3f} of the variance of log R_C (slope {c_rc['slope']:.2f}); cases within "
            f"{RATIO_WINDOW:.0%} in ratio still differ by up to {c_rc['worst_bin_spread']:.0%} in R_C (near ratio "
            f"{c_rc['bin']:.3f})")
        findings.append(
            f"normalised by the outer diameter (geometric similarity: R_C scales with D at a fixed ratio), R_C/D vs "
            f"ratio: R^2 = {c_norm['r2']:.3f}, worst spread at similar ratios {c_norm['worst_bin_spread']:.0%} -> the "
            f"ratio alone {'summarises' if c_norm['worst_bin_spread'] < 0.15 else 'does not summarise'} R_C/D "
            f"(threshold 15%), and R_C itself {'is' if c_rc['worst_bin_spread'] < 0.15 else 'is not'} summarised "
            "without the size")
    bad = [r for r in rows if r["radius_of_curvature_mm"] is None]
    if bad:
        findings.append(f"{sum(not r['feasible'] for r in bad)} infeasible and "
                        f"{sum(r['feasible'] for r in bad)} not converged cases are listed in the table")

    def plot(path: str) -> None:
        plt = pyplot()
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
        for ax, key, lab in ((axes[0], "radius_of_curvature_mm", "R_C [mm]"), (axes[1], "rc_over_d", "R_C / D")):
            for i, fo in enumerate(sorted({r["outer_diameter_mm"] for r in ok})):
                sub = [r for r in ok if r["outer_diameter_mm"] == fo]
                ax.scatter([r["area_ratio"] for r in sub], [r[key] for r in sub], color=f"C{i}",
                           label=f"D = {fo:.1f} mm")
            for r in ok:
                if r["baseline"]:
                    ax.plot([r["area_ratio"]], [r[key]], "*", ms=15, color="k", label="baseline")
            ax.set_xlabel("channel area / body area")
            ax.set_ylabel(lab)
            ax.set_yscale("log")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        save(fig, path, f"area ratio, {where(design, ctx)} "
                        f"({len(rows) - len(ok)} of {len(rows)} infeasible or not converged, not shown)")

    cols = [("outer_diameter_mm", "D [mm]"), ("wall_mm", "wall [mm]"), ("lumen_mm", "lumen [mm]"),
            ("channel_diameter_mm", "channel [mm]"), ("area_ratio", "area ratio"), ("baseline", "baseline"),
            ("radius_of_curvature_mm", "R_C [mm]"), ("rc_over_d", "R_C/D"), ("status", "status")]
    return StudyResult("area-ratio", "Area ratio: channel area / body area", design.name, rows, cols, findings, plot,
                       meta={"collapse_rc": c_rc, "collapse_rc_over_d": c_norm, "min_wall_m": min_wall})
