"""Device stiffness: R_C against the bending stiffness EI of a device in the lumen.

EI from 0 to 8 N mm^2 (1 N mm^2 = 1e-6 N m^2; docs/actuator.md writes "1 N mm^2 (1e-9 N m^2)",
a unit slip: 1 mm^2 = 1e-6 m^2). Device diameter 0.8 x the lumen's (the rung uses only EI).
A constant pressure moment M against the sum of the bending stiffnesses gives
R_C = (EI_act + EI_dev) / M: linear in EI_dev, intercept EI_act / M, slope 1 / M. The study
fits that line, reports its intercept, the actuator's own EI it implies (intercept / slope),
and the device stiffness at which R_C has grown by NOTICEABLE over the bare actuator.
"""
from __future__ import annotations

import numpy as np

from ..design import Design
from ..errors import DesignError
from ..section_properties import transformed_section
from .context import StudyContext, StudyResult
from .plotting import pyplot, save, where
from .variation import make_variant

EI_N_MM2 = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
NOTICEABLE = 0.05   # "non-negligible": R_C changed by 5%


def variants(base: Design):
    if base.lumen is None:
        raise DesignError("lumen", None, "a device needs a lumen; this design has none")
    out = []
    for ei in EI_N_MM2:
        def edit(d, ei=ei):
            d["device"] = {"diameter": 0.8 * base.lumen.diameter, "bending_stiffness": ei * 1e-6}
        out.append(make_variant(base, f"{ei:g} N mm^2", "device EI", ei * 1e-6, edit, baseline=ei == 0.0,
                                info={"device_ei_n_mm2": ei}))
    return out


def linear_fit(ei: np.ndarray, rc: np.ndarray) -> dict:
    slope, intercept = np.polyfit(ei, rc, 1)
    pred = intercept + slope * ei
    return {"intercept": float(intercept), "slope": float(slope),
            "r2": 1 - float(((rc - pred) ** 2).sum() / ((rc - rc.mean()) ** 2).sum()),
            "max_rel_residual": float(np.max(np.abs(rc - pred) / rc))}


# options run() takes beyond the design and the context: none
OPTIONS = ()


def run(design: Design, ctx: StudyContext) -> StudyResult:
    rows = ctx.evaluate(variants(design), "device-stiffness")
    ok = [r for r in rows if r["radius_of_curvature_mm"] is not None]
    findings, fit = [], None
    if len(ok) >= 3:
        ei = np.array([r["device_ei_n_mm2"] for r in ok])          # N mm^2
        rc = np.array([r["radius_of_curvature_mm"] for r in ok])    # mm
        fit = linear_fit(ei, rc)
        for r in rows:
            r["fit_rc_mm"] = fit["intercept"] + fit["slope"] * r["device_ei_n_mm2"]
        ei_act = fit["intercept"] / fit["slope"]                    # N mm^2
        ei_noticeable = NOTICEABLE * fit["intercept"] / fit["slope"]
        closed = transformed_section(design).bending_stiffness
        monotonic = all(b > a for a, b in zip(rc, rc[1:]))
        findings.append(
            f"R_C grows about linearly with device stiffness (published): R_C = {fit['intercept']:.2f} mm + "
            f"{fit['slope']:.3f} mm per N mm^2 x EI, R^2 = {fit['r2']:.5f}, largest deviation from the line "
            f"{fit['max_rel_residual']:.2%}; monotonic: {'yes' if monotonic else 'no'} -> "
            f"{'holds' if fit['r2'] > 0.99 and monotonic else 'does not hold'}")
        findings.append(f"intercept {fit['intercept']:.2f} mm (bare actuator, solved: "
                        f"{ok[0]['radius_of_curvature_mm']:.2f} mm); implied actuator stiffness intercept/slope = "
                        f"{ei_act:.2f} N mm^2 = {ei_act * 1e-6:.2e} N m^2 (closed-form section, small strain: "
                        f"{closed[0, 0] * 1e6:.2f} / {closed[1, 1] * 1e6:.2f} N mm^2 about x / y)")
        findings.append(f"the device becomes non-negligible (R_C +{NOTICEABLE:.0%}) from EI = {ei_noticeable:.2f} N mm^2 "
                        f"= {ei_noticeable * 1e-6:.2e} N m^2; docs/actuator.md says 'about 1 N mm^2 (1e-9 N m^2)': 1 N mm^2 "
                        "is 1e-6 N m^2 (the 1e-9 is a unit slip)")
    bad = [r["label"] for r in rows if r["radius_of_curvature_mm"] is None]
    if bad:
        findings.append(f"not converged / infeasible: {', '.join(bad)}")

    def plot(path: str) -> None:
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        ax.plot([r["device_ei_n_mm2"] for r in ok], [r["radius_of_curvature_mm"] for r in ok], "o", label="solved")
        if fit is not None:
            x = np.linspace(0, max(EI_N_MM2), 50)
            ax.plot(x, fit["intercept"] + fit["slope"] * x, "-", label=f"fit, R^2 = {fit['r2']:.4f}")
            ax.axvline(NOTICEABLE * fit["intercept"] / fit["slope"], color="grey", ls=":",
                       label=f"R_C +{NOTICEABLE:.0%}")
            ax.axvline(1.0, color="C3", ls="--", lw=0.8, label="docs/actuator.md: ~1 N mm^2")
        ax.set_xlabel("device bending stiffness EI [N mm^2] (1 N mm^2 = 1e-6 N m^2)")
        ax.set_ylabel("R_C [mm]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        save(fig, path, f"device stiffness, {where(design, ctx)}")

    cols = [("device_ei_n_mm2", "device EI [N mm^2]"), ("baseline", "baseline"), ("radius_of_curvature_mm", "R_C [mm]"),
            ("fit_rc_mm", "linear fit [mm]"), ("status", "status")]
    return StudyResult("device-stiffness", "Device stiffness in the lumen", design.name, rows, cols, findings, plot,
                       meta={"fit_mm_per_n_mm2": fit, "noticeable": NOTICEABLE})
