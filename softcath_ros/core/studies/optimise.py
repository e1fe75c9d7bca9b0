"""Optimise: maximise bending at the study pressure over the channels' shapes.

The channels are fans (annular sectors about the body axis, core/geometry ``sector``) with filleted
corners: the shape that fills the room a round hole cannot (docs/actuator.md "Optimised designs").
The lumen keeps its diameter (it carries the device, the camera lead).

1-DOF: one fan facing the baseline's channel, the lumen below it at the bottom wall (the design's
minimum, holding the fibre in its middle as the implemented design). Variables: outer wall, the
fan's depth (outer minus inner radius: a D-shape when its inner arc nears the axis), span, fillet.
Multi-channel (2-DOF): N equal fans at 360/N degrees round the central lumen, N in COUNTS. Variables:
outer wall, lumen wall (the fans' radii), span, fillet as a fraction of half the fan's radial depth
(1: round ends, a stadium). The span is free down to narrow slots: a fan's ends stretch most (they
round up under pressure, and the wall between neighbours bends into the empty fan), so the stretch
limit is met by narrower, rounder fans, not by thicker walls (fans spanning their whole third with
walls of 0.5-1.3 mm all stretched past 2.0 at 0.14 bar); the wall between fans is the design
validation's, at least the minimum.

Constraints: every wall at least the design's own ``min_wall_thickness``, measured as the true minimum
distance between the outlines by the design validation (a variant that breaks it is infeasible); the
rung converges at the study pressure; the largest principal stretch in the silicone at that pressure
(section rung) at most ``max_stretch``: the strain margin that keeps the thin walls from being driven
towards rupture. Default 2.0 (100% strain), a stated choice well below Ecoflex 00-30's elongation at
break, chosen for repeated cycling; the implemented design reaches 1.43 at 0.14 bar.

Search: a coarse grid solved in parallel (cached), then scipy's COBYLA from the best feasible grid
point (variables in mm and degrees, derivative free: remeshing makes R_C slightly noisy in the
geometry). The best feasible design seen is the optimum; it is written as a design file with
R_C-vs-pressure curves against the baseline (and the implemented design).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import yaml

from ..design import Design, load_design
from ..errors import DesignError, SoftcathError
from ..models import rung_class
from ..models.base import BendModel
from ..units import PA_PER_BAR
from ..options import Option
from .context import StudyContext, StudyResult
from .plotting import pyplot, save, where
from .runner import run_cases
from .variation import area_ratio, channel_wall_of, make_variant, min_wall_of, tidy

# 3 is the fewest fans that steer in every direction, and what the allocation and the surrogate's
# pair tables serve; 4 or more on request (--counts)
COUNTS = (3,)
DEFAULT_MAX_STRETCH = 2.0
CURVE_BAR = tuple(round(0.025 * i, 3) for i in range(1, 11))   # 0.025 .. 0.25 bar
MAX_ITER = 30


@dataclass(frozen=True)
class Variable:
    """One shape variable: name, unit (mm scaled with D / 5 mm, or deg), bounds, its coarse grid."""

    name: str
    unit: str
    lower: float
    upper: float
    grid: tuple[float, ...]


def fan(inner: float, outer: float, direction: float, span: float, fillet: float) -> dict:
    return {"shape": "sector", "inner_radius": tidy(inner), "outer_radius": tidy(outer),
            "direction": round(direction % 360.0, 9), "span": round(span, 9), "fillet": tidy(fillet)}


def family_variables(base: Design, count: int) -> tuple[Variable, ...]:
    """The shape variables of a family (lengths in mm at the baseline's size)."""
    scale = base.outer_diameter / 5e-3
    w = base.min_wall_thickness * 1e3
    if count == 1:
        return (Variable("outer wall", "mm", w, w + 0.5 * scale, (w, w + 0.1 * scale)),
                Variable("depth", "mm", 0.5 * scale, 2.0 * scale, (1.5 * scale, 1.7 * scale)),
                Variable("span", "deg", 90.0, 220.0, (170.0, 190.0)),
                Variable("fillet", "mm", 0.05 * scale, 0.6 * scale, (0.2 * scale, 0.35 * scale)))
    third = 360.0 / count
    return (Variable("outer wall", "mm", w, w + 0.5 * scale, (w, w + 0.1 * scale)),
            Variable("lumen wall", "mm", w, w + 0.5 * scale, (w,)),
            Variable("span", "deg", 0.25 * third, third - 10.0, tuple(round(f * third, 1) for f in (0.4, 0.5, 0.6, 0.7))),
            Variable("fillet", "of half depth", 0.3, 0.95, (0.6, 0.95)))


def layout_fan(base: Design, x: tuple[float, ...]):
    """1-DOF: one fan facing the baseline's channel (outer wall, depth, span, fillet in mm / deg)."""
    t_o, depth, span, fillet = x[0] * 1e-3, x[1] * 1e-3, x[2], x[3] * 1e-3
    big_r, r_l, t_b = base.outer_radius, base.lumen.radius, base.min_wall_thickness
    c = base.channels[0].center
    facing = math.degrees(math.atan2(c[1], c[0])) if math.hypot(*c) > 0 else 90.0
    u = np.array([math.cos(math.radians(facing)), math.sin(math.radians(facing))])

    def edit(d):
        outer = big_r - t_o
        if outer - depth <= 0:
            raise DesignError("channels[0].inner_radius", tidy(outer - depth), "the fan's depth reaches the body axis")
        d["channels"] = [fan(outer - depth, outer, facing, span, fillet)]
        lumen_at = -(big_r - t_b - r_l) * u
        d["lumen"] = {"diameter": base.lumen.diameter, "center": [tidy(v) for v in lumen_at]}
        if d.get("limiting_fibre") is not None:
            d["limiting_fibre"]["center"] = [tidy(v) for v in -(big_r - 0.5 * t_b) * u]
    return edit


def layout_ring(base: Design, count: int, x: tuple[float, ...]):
    """N fans round the central lumen (outer wall, lumen wall in mm, span in deg, fillet as a fraction
    of half the radial depth)."""
    t_o, t_l, span, fillet_part = x[0] * 1e-3, x[1] * 1e-3, x[2], x[3]
    big_r, r_l = base.outer_radius, base.lumen.radius
    c = base.channels[0].center
    first = math.degrees(math.atan2(c[1], c[0])) if base.n_channels > 1 and math.hypot(*c) > 0 else 90.0

    def edit(d):
        inner, outer = r_l + t_l, big_r - t_o
        if outer <= inner:
            raise DesignError("channels", None, "no room for the fans between the lumen and outer walls")
        fillet = fillet_part * 0.5 * (outer - inner)
        d["channels"] = [fan(inner, outer, first + 360.0 * i / count, span, fillet) for i in range(count)]
        d["lumen"] = {"diameter": base.lumen.diameter, "center": [0.0, 0.0]}
    return edit


class Search:
    """Evaluations of one layout family (memoised by its variables), feasibility and history."""

    def __init__(self, base: Design, ctx: StudyContext, count: int, max_stretch: float, max_iter: int = MAX_ITER):
        self.base, self.ctx, self.count, self.max_stretch = base, ctx, count, max_stretch
        self.variables = family_variables(base, count)
        self.max_iter = max_iter
        self.history: dict[tuple, dict] = {}

    def variant(self, x):
        edit = layout_fan(self.base, x) if self.count == 1 else layout_ring(self.base, self.count, x)
        return make_variant(self.base, self.label(x), "shape", x, edit)

    def label(self, x) -> str:
        return ", ".join(f"{v.name} {t:.1f} {v.unit}" if v.unit == "deg" else f"{v.name} {t:.3f} {v.unit}"
                         for v, t in zip(self.variables, x))

    def evaluate(self, many: list[tuple], stage: str, parallel: bool) -> list[dict]:
        keys = [tuple(round(float(t), 6) for t in x) for x in many]
        new = [k for k in dict.fromkeys(keys) if k not in self.history]
        variants = [self.variant(k) for k in new]
        feasible = [v for v in variants if v.feasible]
        specs = [self.ctx.spec(v.design) for v in feasible]
        if parallel:
            results = self.ctx.solve(specs, f"optimise {self.count} ch, {stage}")
        else:   # one candidate at a time (COBYLA): in this process, or on the given executor
            results = run_cases(specs, executor=self.ctx.executor, workers=1, cache=self.ctx.cache,
                                progress=False, stats=self.ctx.stats)
        it = iter(results)
        for k, v in zip(new, variants):
            row = {"count": self.count, "stage": stage, "label": v.label,
                   **{f"x_{i}": t for i, t in enumerate(k)}}
            if not v.feasible:
                row.update(feasible=False, radius_of_curvature_mm=None, max_principal_stretch=None,
                           status=f"infeasible: {v.reason}", design=None)
            else:
                r = next(it)["results"][0]
                rc, st = r["radius_of_curvature_m"], r["max_principal_stretch"]
                ok = r["converged"] and rc is not None and st is not None and st <= self.max_stretch
                status = ("ok" if ok else f"did not converge: {r['message']}" if not r["converged"]
                          else f"max stretch {st:.3f} > {self.max_stretch}")
                row.update(feasible=ok, radius_of_curvature_mm=None if rc is None else rc * 1e3,
                           max_principal_stretch=st, status=status, design=v.design,
                           channel_area_mm2=v.design.channels[0].area * 1e6,
                           area_ratio=area_ratio(v.design), thinnest_wall_mm=min_wall_of(v.design) * 1e3)
            self.history[k] = row
        return [self.history[k] for k in keys]

    def best(self) -> dict | None:
        ok = [r for r in self.history.values() if r["feasible"]]
        return min(ok, key=lambda r: r["radius_of_curvature_mm"]) if ok else None

    def run(self) -> dict | None:
        grid = list(itertools.product(*(v.grid for v in self.variables)))
        self.evaluate(grid, "grid", parallel=True)
        start = self.best()
        if start is None or self.max_iter <= 0:
            return start
        from scipy.optimize import minimize

        lo = np.array([v.lower for v in self.variables])
        hi = np.array([v.upper for v in self.variables])
        # COBYLA steps in units of each variable's range / 10: degrees and millimetres alike
        span = (hi - lo) / 10.0

        def solve(u):
            return self.evaluate([tuple(lo + np.asarray(u) * span)], "cobyla", parallel=False)[0]

        def objective(u):   # curvature in 1/mm, negated; 0 (straight) where nothing converged or feasible
            r = solve(u)
            rc = r["radius_of_curvature_mm"]
            return -1.0 / rc if rc and r["status"] != "infeasible" else 0.0

        def stretch_margin(u):
            if np.any(np.asarray(u) < -1e-9) or np.any(np.asarray(u) > 10.0 + 1e-9):
                return -1.0
            r = solve(u)
            st = r["max_principal_stretch"]
            return self.max_stretch - st if st is not None else -1.0

        u0 = (np.array([start[f"x_{i}"] for i in range(len(self.variables))]) - lo) / span
        cons = [{"type": "ineq", "fun": lambda u, i=i: u[i]} for i in range(len(lo))]
        cons += [{"type": "ineq", "fun": lambda u, i=i: 10.0 - u[i]} for i in range(len(lo))]
        cons.append({"type": "ineq", "fun": stretch_margin})
        minimize(objective, u0, method="COBYLA", constraints=cons,
                 options={"rhobeg": 0.5, "tol": 0.02, "maxiter": self.max_iter})
        return self.best()


def design_file_text(design: Design, description: str) -> str:
    data = design.to_dict()
    data["description"] = description
    return "# Written by `softcath study optimise` (core/studies/optimise.py). SI units: metres, pascals.\n" + \
        yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110)


# options run() takes beyond the design and the context (softcath study validates flags against them)
OPTIONS = (Option("max_stretch", "float", "largest principal stretch allowed in the silicone"),
           Option("counts", "object", "channel counts to optimise over"),
           Option("max_iter", "int", "COBYLA steps after the grid (0: the grid's best)"))


def run(design: Design, ctx: StudyContext, max_stretch: float = DEFAULT_MAX_STRETCH,
        counts: tuple[int, ...] = COUNTS, max_iter: int = MAX_ITER) -> StudyResult:
    """The channels' shapes that bend ``design`` most at the study's pressure within ``max_stretch``,
    per channel count (one for a 1-DOF design, ``counts`` else): a table against the baseline, the
    optimum's design file, and R_C against pressure for the optimum, the baseline and the implemented design."""
    if design.lumen is None:
        raise DesignError("lumen", None, "the optimiser keeps the lumen (it carries the device); this design has none")
    if rung_class(ctx.rung).max_principal_stretch is BendModel.max_principal_stretch:
        raise SoftcathError(f"rung {ctx.rung} reports no principal stretch, which the optimiser's stretch limit "
                            "needs: use --model section")
    kind = "1dof" if design.n_channels == 1 else "2dof"
    searches = [Search(design, ctx, 1, max_stretch, max_iter)] if kind == "1dof" else \
        [Search(design, ctx, n, max_stretch, max_iter) for n in counts]
    bests = [(s, s.run()) for s in searches]
    found = [(s, b) for s, b in bests if b is not None]
    stem = f"optimised_{kind}_{design.outer_diameter * 1e3:g}mm"
    p_bar = ctx.pressure / PA_PER_BAR
    rows = _rows(design, ctx, bests, stem)
    findings, extra = [], {}
    optimum = opt_design = None
    if found:
        opt_design, optimum = _optimum(design, ctx, bests, found, rows, stem, max_stretch, findings, extra)
    else:
        findings.append("no candidate met the constraints; no design file written")
    curve_designs = [design] + ([opt_design] if optimum else [])
    if design.name != "implemented_5mm":
        try:
            curve_designs.append(load_design("implemented_5mm"))
        except DesignError:
            pass
    curves = _curves(design, ctx, curve_designs, stem, findings, extra)
    history = [{k: v for k, v in r.items() if k != "design"} for s in searches for r in s.history.values()]
    plot = partial(_plot, curve_designs=curve_designs, curves=curves, searches=searches, p_bar=p_bar,
                   max_stretch=max_stretch, title=f"optimise {kind} from {where(design, ctx)}")
    cols = [("design", "design"), ("count", "channels"), ("label", "shape"), ("channel_area_mm2", "channel [mm^2]"),
            ("area_ratio", "area ratio"), ("thinnest_wall_mm", "thinnest wall [mm]"),
            ("radius_of_curvature_mm", f"R_C at {p_bar:g} bar [mm]"), ("max_principal_stretch", "max stretch"),
            ("status", "status")]
    return StudyResult("optimise", f"Optimised {kind.upper()} design", design.name, rows, cols, findings, plot,
                       extra_files=extra, meta={"max_stretch": max_stretch, "history": history, "curves": curves,
                                                "design_file": f"{stem}.yaml" if optimum else None})


def _rows(design: Design, ctx: StudyContext, bests, stem: str) -> list[dict]:
    """The table: the baseline at the same pressure, then each count's best candidate."""
    base_case = ctx.solve([ctx.spec(design)], "optimise baseline")[0]["results"][0]
    rows = [{"design": design.name, "count": design.n_channels, "label": "baseline",
             "channel_area_mm2": design.channels[0].area * 1e6, "area_ratio": area_ratio(design),
             "thinnest_wall_mm": min_wall_of(design) * 1e3,
             "radius_of_curvature_mm": None if base_case["radius_of_curvature_m"] is None
             else base_case["radius_of_curvature_m"] * 1e3,
             "max_principal_stretch": base_case["max_principal_stretch"],
             "status": "ok" if base_case["converged"] else f"did not converge: {base_case['message']}"}]
    for s, b in bests:
        rows.append({"design": f"{stem} candidate", "count": s.count, "label": b["label"] if b else "-",
                     "channel_area_mm2": b and b["channel_area_mm2"], "area_ratio": b and b["area_ratio"],
                     "thinnest_wall_mm": b and b["thinnest_wall_mm"],
                     "radius_of_curvature_mm": b and b["radius_of_curvature_mm"],
                     "max_principal_stretch": b and b["max_principal_stretch"],
                     "status": f"best of {len(s.history)} evaluated" if b else "no feasible design"})
    return rows


def _optimum(design: Design, ctx: StudyContext, bests, found, rows, stem: str, max_stretch: float, findings, extra):
    """(the optimum's design, its evaluation): the best of ``found``, named ``stem`` in ``rows``, its
    design file in ``extra`` and what it says about the published optimum in ``findings``."""
    p_bar = ctx.pressure / PA_PER_BAR
    s_opt, optimum = min(found, key=lambda sb: sb[1]["radius_of_curvature_mm"])
    opt_design = replace(optimum["design"], name=stem)
    rows[1 + bests.index((s_opt, optimum))]["design"] = stem
    extra[f"{stem}.yaml"] = design_file_text(
        opt_design, f"maximum bending at {p_bar:g} bar from {design.name}: {s_opt.count} channel(s), walls >= "
                    f"{design.min_wall_thickness * 1e3:g} mm, max principal stretch <= {max_stretch:g} "
                    f"(softcath study optimise, rung {ctx.rung})")
    base_rc = rows[0]["radius_of_curvature_mm"]
    findings.append(
        f"optimum ({s_opt.count} fan(s)): {optimum['label']}, channel {optimum['channel_area_mm2']:.3f} mm^2, "
        f"area ratio {optimum['area_ratio']:.3f} (baseline {rows[0]['area_ratio']:.3f}); R_C at {p_bar:g} bar "
        f"{optimum['radius_of_curvature_mm']:.2f} mm vs baseline "
        + (f"{base_rc:.2f} mm ({base_rc / optimum['radius_of_curvature_mm']:.2f}x the curvature)" if base_rc else
           "(baseline did not converge)")
        + f"; max principal stretch {optimum['max_principal_stretch']:.2f} (limit {max_stretch:g})")
    walls_at_min = abs(optimum["thinnest_wall_mm"] - design.min_wall_thickness * 1e3) < 0.02
    findings.append(
        ("published: the optimised 1-DOF design has one channel of maximal area with walls at a fabricable minimum"
         if s_opt.count == 1 else "published: the 2-DOF design has three channels at 120 degrees, each as large "
         "as the minimum walls allow") + " -> " + _walls_verdict(opt_design, s_opt.count, walls_at_min))
    if base_rc and abs(base_rc / optimum["radius_of_curvature_mm"] - 1) < 0.005:
        findings.append(f"{design.name} is already this family's optimum: the design file written repeats its "
                        "geometry under the new name")
    if len(found) > 1:
        findings.append("count: " + ", ".join(f"{s.count} channels R_C {b['radius_of_curvature_mm']:.2f} mm"
                                              for s, b in found)
                        + " (3 is the fewest that bend in every direction)")
    return opt_design, optimum


def _walls_verdict(opt_design: Design, count: int, walls_at_min: bool) -> str:
    """Whether the optimum's channels are as large as the minimum walls allow; fans round the lumen
    are not when their span leaves more silicone between them than the minimum (the stretch binds there)."""
    if not walls_at_min:
        return "the optimum keeps every wall above the minimum (the strain or convergence limit binds)"
    shape = opt_design.channels[0].shape
    if count > 1 and shape.kind == "sector":
        between = channel_wall_of(opt_design)   # the validation's true minimum distance, fillets and all
        if between > opt_design.min_wall_thickness + 2e-5:
            return (f"its outer and lumen walls sit on the minimum, but its fans span {shape.span:.1f} of "
                    f"{360.0 / count:g} deg, {between * 1e3:.2f} mm of silicone between them at the thinnest "
                    "(the stretch limit binds): does not hold")
    return "the optimum's thinnest wall sits on the minimum: holds"


def _curves(design: Design, ctx: StudyContext, curve_designs: list, stem: str, findings, extra) -> list[dict]:
    """R_C against pressure for ``curve_designs``: rows, their CSV in
    ``extra`` and where a rung stopped converging in ``findings``."""
    levels = [b * PA_PER_BAR for b in CURVE_BAR]
    curve_results = ctx.solve([ctx.spec(d, levels) for d in curve_designs], "optimise curves")
    curves = []
    for d, res in zip(curve_designs, curve_results):
        for p, r in zip(CURVE_BAR, res["results"]):
            rc = r["radius_of_curvature_m"]
            curves.append({"design": d.name, "pressure_bar": p, "converged": r["converged"],
                           "radius_of_curvature_mm": None if rc is None else rc * 1e3,
                           "max_principal_stretch": r["max_principal_stretch"], "message": r["message"]})
    lines = ["design,pressure_bar,converged,radius_of_curvature_mm,max_principal_stretch,message"]
    lines += [f"{c['design']},{c['pressure_bar']},{c['converged']},{c['radius_of_curvature_mm'] or ''},"
              f"{c['max_principal_stretch'] or ''},\"{c['message']}\"" for c in curves]
    extra[f"{stem}_curves.csv"] = "\n".join(lines) + "\n"
    for d in curve_designs:
        stop = [c["pressure_bar"] for c in curves if c["design"] == d.name and not c["converged"]]
        if stop:
            findings.append(f"{d.name}: the rung did not converge from {min(stop):g} bar on the curve (listed in the "
                            "curves CSV)")
    return curves


def _plot(path: str, curve_designs, curves, searches, p_bar: float, max_stretch: float, title: str) -> None:
    """R_C against pressure, the candidates, and the sections of the baseline and the optimum."""
    plt = pyplot()
    from matplotlib.patches import Circle, Polygon

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    for i, d in enumerate(curve_designs):
        pts = [(c["pressure_bar"], c["radius_of_curvature_mm"]) for c in curves
               if c["design"] == d.name and c["converged"]]
        if pts:
            axes[0].plot(*zip(*pts), "o-", color=f"C{i}", label=d.name)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("pressure [bar]")
    axes[0].set_ylabel("R_C [mm]")
    axes[0].set_title("R_C against pressure (missing points: did not converge)", fontsize=9)
    axes[0].legend(fontsize=8)
    axes[0].grid(alpha=0.3)
    for j, s in enumerate(searches):
        ev = [r for r in s.history.values() if r["radius_of_curvature_mm"] is not None]
        axes[1].scatter([r["area_ratio"] for r in ev], [r["radius_of_curvature_mm"] for r in ev],
                        c=["C2" if r["feasible"] else "C3" for r in ev], marker="os^"[j % 3], s=18,
                        label=f"{s.count} channel(s)")
    axes[1].set_xlabel("channel area / body area")
    axes[1].set_ylabel(f"R_C at {p_bar:g} bar [mm]")
    axes[1].set_title(f"candidates (green feasible, red: stretch > {max_stretch:g})", fontsize=9)
    axes[1].legend(fontsize=8)
    axes[1].grid(alpha=0.3)
    ax = axes[2]
    for d, style in zip(curve_designs[:2], ("--", "-")):
        ax.add_patch(Circle((0, 0), d.outer_radius * 1e3, fill=False, ls=style))
        for h in d.section.holes:   # the real outlines
            ax.add_patch(Polygon(np.asarray(h.polygon.exterior.coords) * 1e3, closed=True, fill=False, ls=style,
                                 color="C0" if h.role == "channel" else "C1"))
    ax.set_xlim(-3, 3)
    ax.set_ylim(-3, 3)
    ax.set_aspect("equal")
    ax.set_title("sections: baseline dashed, optimum solid (mm)", fontsize=9)
    save(fig, path, title)
