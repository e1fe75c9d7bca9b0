"""Sensitivity: one parameter at a time over a stated range, R_C at the study pressure.

Parameters (baseline marked in every group): reinforcement pitch and thread diameter (x0.5 to
x2), thread shape (square/round), limiting-fibre diameter (x0.5 to x2), fibre placement
(bottom = the baseline's, top = mirrored across the bending plane's neutral side, none), and
the material set. The project has one published Ecoflex 00-30 set (core/materials.py);
docs/actuator.md states published sets differ by about 2x in c1, so the study spans that spread
with the set scaled by 0.5 and 2, and checks the Yeoh higher terms with its neo-Hookean part.
"""
from __future__ import annotations

from ..design import Design
from .context import StudyContext, StudyResult
from .plotting import category_panel, pyplot, save, where
from .variation import Variant, make_variant

FACTORS = (0.5, 0.75, 1.0, 1.5, 2.0)
# A parameter "matters little" when R_C varies by less than this over its range (stated threshold).
LITTLE = 0.10


def _scaled_group(base: Design, parameter: str, section: str, key: str, unit_mm: bool = True) -> list[Variant]:
    obj = getattr(base, section)
    if obj is None:
        return []
    v0 = getattr(obj, key)
    out = []
    for f in FACTORS:
        value = v0 * f

        def edit(d, value=value):
            d[section][key] = value

        out.append(make_variant(base, f"{value * 1e3:.3g} mm", parameter, value, edit, baseline=f == 1.0))
    return out


def variants(base: Design) -> list[Variant]:
    out = _scaled_group(base, "reinforcement pitch", "reinforcement", "pitch")
    out += _scaled_group(base, "thread diameter", "reinforcement", "thread_diameter")
    if base.reinforcement is not None:
        for shape in ("square", "round"):
            def edit(d, shape=shape):
                d["reinforcement"]["shape"] = shape
            out.append(make_variant(base, shape, "thread shape", shape, edit,
                                    baseline=shape == base.reinforcement.shape))
    out += _scaled_group(base, "fibre diameter", "limiting_fibre", "diameter")
    f = base.limiting_fibre
    if f is not None:
        def top(d):
            d["limiting_fibre"]["center"] = [f.center[0], -f.center[1]]

        def none(d):
            d["limiting_fibre"] = None
        out.append(make_variant(base, "bottom", "fibre placement", "bottom", lambda d: None, baseline=True))
        out.append(make_variant(base, "top", "fibre placement", "top", top))
        out.append(make_variant(base, "none", "fibre placement", "none", none))
    m = base.material
    sets = [("baseline", m, True), ("c_i x0.5", m.scaled(0.5), False), ("c_i x2", m.scaled(2.0), False),
            ("neo-Hookean (c1 only)", m.__class__(c1=m.c1, bulk_modulus=m.bulk_modulus, density=m.density), False)]
    for label, mat, is_base in sets:
        spec = {"model": "yeoh", "c1": mat.c1, "c2": mat.c2, "c3": mat.c3,
                "bulk_modulus": mat.bulk_modulus, "density": mat.density}

        def edit(d, spec=spec):
            d["material"] = spec
        out.append(make_variant(base, label if not is_base else f"design's set (c1 {m.c1 / 1e3:.3g} kPa)",
                                "material set", f"c1={mat.c1:g} Pa", edit, baseline=is_base))
    return out


def spread(rows: list[dict]) -> float | None:
    """(max - min) R_C over the converged cases of a group, relative to the group's baseline."""
    rc = [r["radius_of_curvature_mm"] for r in rows if r["radius_of_curvature_mm"] is not None]
    base = [r["radius_of_curvature_mm"] for r in rows if r["baseline"] and r["radius_of_curvature_mm"] is not None]
    if len(rc) < 2 or not base:
        return None
    return (max(rc) - min(rc)) / base[0]


# options run() takes beyond the design and the context: none
OPTIONS = ()


def run(design: Design, ctx: StudyContext) -> StudyResult:
    rows = ctx.evaluate(variants(design), "sensitivity")
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(r["parameter"], []).append(r)
    for g in groups.values():
        s = spread(g)
        for r in g:
            r["group_spread"] = s
    findings = []
    little = [p for p in ("reinforcement pitch", "thread diameter", "thread shape", "fibre diameter") if p in groups]
    for p in little:
        s = spread(groups[p])
        g = groups[p]
        lost = [r["label"] for r in g if r["radius_of_curvature_mm"] is None]
        findings.append(
            f"{p} matters little (published): " + ("no two converged cases" if s is None else
            f"R_C varies by {s:.1%} of the baseline over {g[0]['label']} .. {g[-1]['label']} -> "
            f"{'holds' if s < LITTLE else 'does not hold'} (threshold {LITTLE:.0%})")
            + (f"; not converged/infeasible: {', '.join(lost)}" if lost else ""))
    if "fibre placement" in groups:
        by = {r["label"]: r["radius_of_curvature_mm"] for r in groups["fibre placement"]}
        if by.get("none") is not None and by.get("bottom") is not None:
            findings.append(f"removing the limiting fibre bends less (published): R_C {by['bottom']:.1f} mm with "
                            f"the fibre at the bottom, {by['none']:.1f} mm without -> "
                            f"{'holds' if by['none'] > by['bottom'] else 'does not hold'}"
                            + (f"; fibre at the top: {by['top']:.1f} mm" if by.get("top") else "; fibre at the top: "
                               "did not converge"))
        else:
            findings.append(f"removing the limiting fibre: cannot judge, R_C bottom {by.get('bottom')}, none {by.get('none')}")
    if "material set" in groups:
        s = spread(groups["material set"])
        findings.append(f"material set: R_C varies by {'n/a' if s is None else f'{s:.0%}'} of the baseline over the "
                        "published 2x spread in c1 (the largest single uncertainty, docs/actuator.md)")

    def plot(path: str) -> None:
        plt = pyplot()
        names = list(groups)
        cols = 3
        nrows = (len(names) + cols - 1) // cols
        fig, axes = plt.subplots(nrows, cols, figsize=(13, 3.6 * nrows), squeeze=False)
        for ax, name in zip(axes.ravel(), names):
            category_panel(ax, groups[name], name)
        for ax in axes.ravel()[len(names):]:
            ax.axis("off")
        save(fig, path, f"sensitivity of R_C, {where(design, ctx)}")

    cols = [("parameter", "parameter"), ("label", "value"), ("baseline", "baseline"),
            ("radius_of_curvature_mm", "R_C [mm]"), ("max_principal_stretch", "max stretch"),
            ("group_spread", "group spread"), ("status", "status")]
    return StudyResult("sensitivity", "Sensitivity: one parameter at a time", design.name, rows, cols, findings, plot)
