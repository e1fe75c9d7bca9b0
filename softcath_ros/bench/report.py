"""Bench report: Markdown table and PNG plots (R_C and force vs pressure, loading/unloading,
models overlaid, before/after calibration)."""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from .analysis import Hysteresis, StepStats
from ..core.units import PA_PER_BAR

# Overlaid by default: the accurate rung through its table (the section rung's surrogate) and the fast,
# rough closed form.
DEFAULT_OVERLAY = ("surrogate", "closed_form")


def _fmt(x: float, scale: float = 1.0, digits: int = 2) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{x * scale:.{digits}f}"


def _model_cell(values: dict, quantity: str, scale: float, digits: int) -> str:
    """A model's value, with its 95% band (calibrated overlays) as +- half-width."""
    cell = _fmt(values[quantity], scale, digits)
    half = values.get(f"{quantity}_band95")
    return cell if half is None or not np.isfinite(half) else f"{cell} ± {_fmt(half, scale, digits)}"


def simulated_rig(meta: dict) -> dict | None:
    """The simulated rig's recorded parameters (sim_bench_node's /softcath/bench/rig: ``rig`` and the
    truth's ``model``), or None for a rig that did not announce them."""
    import json

    try:
        rig = json.loads(meta.get("rig", ""))
    except ValueError:
        return None
    if not (isinstance(rig, dict) and rig.get("simulated") and isinstance(rig.get("rig"), dict)):
        return None
    return {**rig["rig"], "model": rig.get("model", "unknown")}


def truth_note(rig: dict, recording) -> str:
    """Why the uncalibrated overlays miss a simulated rig: its truth is shifted (RigParams)."""
    shift, scale = float(rig.get("pressure_shift", 0.0)), float(rig.get("material_scale", 1.0))
    return (f"The simulated rig's truth is the `{rig['model']}` rung bending as at (1 − {shift:g}) × the true pressure "
            f"(its recorded `pressure_shift` {shift:g}, the published gap between model and experiment) on a "
            f"material × {scale:g}, read with the bench's friction and out-of-plane biases: the uncalibrated overlays "
            f"miss it by that much by design. `softcath calibrate {recording}` fits shift and scale and writes this "
            "report again with the calibrated overlay.")


def calibration_caveats(message: str, rig: dict | None) -> list[str]:
    """What a calibration's intervals do not hold: the model's misfit (widened, warned) and the bench's
    own biases (on a simulated rig, its recorded ones)."""
    import math

    from .calibration import MISFIT

    lines = []
    misfit = next((part for part in message.split("; ") if part.startswith(MISFIT)), None)
    if misfit:
        lines += [f"**Warning**: {misfit}. The shift and scale describe this rung only as well as it fits; "
                  "the intervals count the misfit as error.", ""]
    bias = ("The intervals hold the readings' noise" + (" and the model's misfit" if misfit else "") +
            ", not the bench's own biases (friction, out-of-plane bending, the gauge's fixed error): the fit "
            "absorbs those into shift and scale")
    if rig is not None:
        keep = 1.0 - float(rig.get("friction_underread", 0.0))
        tilt = math.cos(float(rig.get("out_of_plane_tilt", 0.0)))
        bias += (f"; this simulated rig reads the angle x{keep * tilt:.3f} and the force x{keep:.3f} and its gauge "
                 f"is off by up to {float(rig.get('gauge_error', 0.0)) / PA_PER_BAR:g} bar, so its truth (shift "
                 f"{rig.get('pressure_shift', '?')}, scale {rig.get('material_scale', '?')}) may lie outside them")
    return lines + [bias + ".", ""]


def markdown(title: str, info: dict[str, str], stats: list[StepStats], hyst: list[Hysteresis],
             plots: list[str], calibration: dict | None = None, tips: list | None = None,
             tips_skipped: dict | None = None, overlay_note: str = "", tips_model: str = "the model",
             rig: dict | None = None) -> str:
    labels = list(stats[0].model) if stats else []
    lines = [f"# {title}", ""]
    for k, v in info.items():
        lines.append(f"- **{k}**: {v}")
    lines.append("")
    lines += _step_tables(stats, labels, overlay_note)
    if hyst:
        lines += _hysteresis_section(hyst)
    if tips or tips_skipped:
        from .tip_compare import markdown_section
        lines += markdown_section(tips, tips_skipped, tips_model)
    if calibration:
        lines += _calibration_section(calibration, rig)
    if plots:
        lines += ["## Plots", ""] + ([overlay_note, ""] if overlay_note else []) \
            + [f"![{Path(p).stem}]({Path(p).name})" for p in plots] + [""]
    return "\n".join(lines)


def _step_tables(stats: list[StepStats], labels: list[str], overlay_note: str) -> list[str]:
    """Per bench, a table of its steps with each overlaid rung's answer."""
    lines = []
    noted = False
    for bench in ("angle", "force"):
        rows = [s for s in stats if s.bench == bench]
        if not rows:
            continue
        if overlay_note and not noted:
            lines += [overlay_note, ""]
            noted = True
        if bench == "angle":
            lines += ["## Angle bench: radius of curvature", "",
                      "R_C = l / theta per reading; mean ± std over trials and samples (— where the bend is "
                      "within the reading noise).", ""]
            head = ["drive", "phase", "p cmd [bar]", "p measured [bar]", "n", "theta / l [1/m]", "R_C [mm]"]
            head += [f"R_C {lb} [mm]" for lb in labels]
        else:
            lines += ["## Blocking-force bench", "", "Scale reading minus the reading at p = 0 of the same trial.", ""]
            head = ["drive", "phase", "p cmd [bar]", "p measured [bar]", "n", "force [mN]"]
            head += [f"force {lb} [mN]" for lb in labels]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for s in rows:
            p = f"{_fmt(s.pressure_magnitude, 1 / PA_PER_BAR, 3)} ± {_fmt(float(np.max(s.pressure_std)), 1 / PA_PER_BAR, 3)}"
            level = _fmt(s.level, 1 / PA_PER_BAR, 3) if s.drive.startswith("channel") else f"{s.level:g} of reach"
            cells = [s.drive, s.phase + (" (unsettled)" if s.unsettled else ""), level, p, str(s.n)]
            if bench == "angle":
                cells += [f"{_fmt(s.curvature_mean)} ± {_fmt(s.curvature_std)}",
                          f"{_fmt(s.radius_mean, 1e3, 1)} ± {_fmt(s.radius_std, 1e3, 1)}"]
                cells += [_model_cell(s.model[lb], "radius", 1e3, 1) for lb in labels]
            else:
                cells += [f"{_fmt(s.force_mean, 1e3)} ± {_fmt(s.force_std, 1e3)}"]
                cells += [_model_cell(s.model[lb], "force", 1e3, 2) for lb in labels]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def _hysteresis_section(hyst: list[Hysteresis]) -> list[str]:
    """Unloading against loading per level, with its significance."""
    thresholds = sorted({round(h.threshold, 2) for h in hyst})
    lines = []
    lines += ["## Hysteresis: unloading minus loading at equal measured pressure", "",
              "Each unloading step against the loading curve at the unloading step's measured pressure (the "
              "regulator's lag makes equal commanded levels differ in pressure): a quadratic through the three "
              "nearest loading steps. t = difference / its standard error, which holds the steps' reading noise, "
              "the noise of their mean measured pressures times the curve's slope, and the interpolation error "
              "(Welch); significant where |t| exceeds the Bonferroni threshold of its curve "
              f"(1% family-wise; here {min(thresholds):g} to {max(thresholds):g}).", "",
              "| bench | drive | level | p measured [bar] | quantity | loading | unloading | difference | t "
              "| significant |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for h in hyst:
        unit, sc = ("1/m", 1.0) if h.quantity == "curvature" else ("mN", 1e3)
        lv = f"{h.level / PA_PER_BAR:.3f} bar" if h.drive.startswith("channel") else f"{h.level:g}"
        lines.append(f"| {h.bench} | {h.drive} | {lv} | {h.pressure / PA_PER_BAR:.3f} | {h.quantity} [{unit}] | "
                     f"{h.loading * sc:.3f} | {h.unloading * sc:.3f} | {h.difference * sc:+.3f} | "
                     f"{h.t_statistic:+.2f} | {'yes' if h.significant else 'no'} |")
    n_sig = sum(h.significant for h in hyst)
    lines += ["", f"{n_sig} of {len(hyst)} levels show a significant loading/unloading difference"
              + (": hysteresis." if n_sig else ": no hysteresis beyond the scatter."), ""]
    return lines


def _calibration_section(calibration, rig: dict | None) -> list[str]:
    """The fitted calibration, its confidence and caveats."""
    c = calibration.to_dict()
    lines = []
    lines += ["## Calibration", "",
              f"Rung `{c['rung']}` fitted to `{c['recording']}` (sha256 {c['recording_sha256'][:12]}..., "
              f"{c['date']}; 95% confidence from the Jacobian), applied to every overlaid rung "
              "(bands: 95% from its covariance):", "",
              f"- pressure shift: {c['pressure_shift']:.4f} ± {c['ci95']['pressure_shift']:.4f} "
              "(model evaluated at (1 − shift) × p)",
              f"- material scale: {c['material_scale']:.4f} ± {c['ci95']['material_scale']:.4f} "
              "(all Yeoh coefficients × scale)",
              f"- parameter correlation: {calibration.correlation:.3f}",
              f"- normalised residual rms: before {c['rms_before']:.3g}, after {c['rms_after']:.3g} "
              f"({c['n_residuals']} readings)", ""]
    from .calibration import MISFIT

    lines += calibration_caveats(c["message"], rig)
    solver = "; ".join(part for part in c["message"].split("; ") if part and not part.startswith(MISFIT))
    if solver:
        lines += [f"Solver: {solver}", ""]
    return lines


def plot(stats: list[StepStats], out_dir: Path, stem: str) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    labels = list(stats[0].model) if stats else []
    styles = ["-", "--", ":", "-."]
    for bench, qty, ylabel, scale in (("angle", "radius", "R_C = l / theta [mm]", 1e3),
                                      ("angle", "curvature", "theta / l [1/m]", 1.0),
                                      ("force", "force", "blocking force [mN]", 1e3)):
        rows = [s for s in stats if s.bench == bench]
        if not rows:
            continue
        fig, ax = plt.subplots(figsize=(6.4, 4.4))
        for drive in sorted({s.drive for s in rows}):
            for phase, marker in (("loading", "o"), ("unloading", "s")):
                sel = [s for s in rows if s.drive == drive and s.phase == phase]
                if not sel:
                    continue
                x = np.array([s.pressure_magnitude for s in sel]) / PA_PER_BAR
                y = np.array([getattr(s, f"{qty}_mean") for s in sel]) * scale
                e = np.array([getattr(s, f"{qty}_std") for s in sel]) * scale
                ok = np.isfinite(y)
                ax.errorbar(x[ok], y[ok], yerr=np.nan_to_num(e[ok]), fmt=marker, capsize=3, ms=5,
                            label=f"bench {drive}, {phase}", mfc="none" if phase == "unloading" else None)
            sel = sorted([s for s in rows if s.drive == drive and s.phase == "loading"], key=lambda s: s.pressure_magnitude)
            for lb, ls in zip(labels, itertools.cycle(styles)):
                x = np.array([s.pressure_magnitude for s in sel]) / PA_PER_BAR
                y = np.array([s.model[lb][qty] for s in sel]) * scale
                ok = np.isfinite(y)
                line, = ax.plot(x[ok], y[ok], ls, label=f"model {lb}")
                if sel and f"{qty}_band95" in sel[0].model[lb]:
                    half = np.array([s.model[lb][f"{qty}_band95"] for s in sel]) * scale
                    ok &= np.isfinite(half)
                    ax.fill_between(x[ok], y[ok] - half[ok], y[ok] + half[ok], color=line.get_color(), alpha=0.2,
                                    label=f"model {lb}, 95% band")
        ax.set_xlabel("measured pressure [bar]")
        ax.set_ylabel(ylabel)
        if qty == "radius":
            ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"{stem}: {bench} bench")
        fig.tight_layout()
        path = out_dir / f"{stem}_{qty}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(str(path))
    return paths


def recording_design(path):
    """The design attached to a bench recording (attachment 'design.yaml'), or None."""
    from ..core.design import design_from_dict
    from ..core.yaml_io import decode_text, load_yaml
    from ..recording.reader import read_attachments

    data = read_attachments(path).get("design.yaml")
    source = f"{path}:design.yaml"
    return None if data is None else design_from_dict(load_yaml(decode_text(data, source), source), source=source)


def write_report(recording, design=None, rungs=DEFAULT_OVERLAY, calibration=None,
                 out_dir=None, topics: dict | None = None, cache: bool = True) -> dict:
    """Analyse ``recording`` and write report.md + PNGs. Returns paths and the statistics.

    ``calibration`` (a ``core.calibration_file.Calibration``) is applied to every rung in ``rungs``:
    each is overlaid as it is and calibrated, the calibrated one with its 95% band. ``cache``:
    whether rungs that cache may read their cache (``--no-cache``)."""
    from ..core.calibration_file import band95, build_model
    from ..core.errors import SoftcathError
    from ..core.models import run_options
    from ..recording.reader import read_metadata, recording_file
    from .analysis import (MODEL_QUANTITIES, check_rows_match_design, hysteresis, model_quantities, overlay_model,
                           rows_from_recording, summarise)

    path = recording_file(recording)
    out = Path(out_dir) if out_dir else path.parent
    design = design or recording_design(path)
    if design is None:
        raise SoftcathError(f"{path} has no design attached; pass --design")
    if calibration is not None:
        calibration.check_design(design)
    rows = rows_from_recording(path, topics)
    if not rows:
        raise SoftcathError(f"{path}: no bench readings (no 'sample' markers on the step topic)")
    check_rows_match_design(rows, design)
    out.mkdir(parents=True, exist_ok=True)   # after the checks: a refused report leaves no folder
    stats = summarise(rows)
    overlaid, built = [], {}
    for rung in rungs:
        opts = run_options(rung, cache=cache)
        built[rung] = build_model(rung, design, **opts)
        overlay_model(stats, built[rung], rung)
        overlaid.append(rung)
        if calibration is not None:
            def quantities(c, rung=rung, opts=opts):
                q = model_quantities(stats, build_model(rung, design, c, **opts))
                return np.stack([q[name] for name in MODEL_QUANTITIES])

            half = band95(calibration, quantities)
            built[f"{rung} calibrated"] = build_model(rung, design, calibration, **opts)
            overlay_model(stats, built[f"{rung} calibrated"], f"{rung} calibrated",
                          band95=dict(zip(MODEL_QUANTITIES, half)))
            overlaid.append(f"{rung} calibrated")
    hyst = hysteresis(stats)
    all_meta = read_metadata(path)
    meta = all_meta.get("softcath", {})
    result = all_meta.get("softcath_result")
    info = {"recording": str(path), "design": design.name,
            "simulated": meta.get("simulated", "unknown"),
            "protocol": meta.get("protocol", "unknown"),
            "readings": f"{len(rows)} ({sum(not r.settled for r in rows)} from unsettled steps)",
            "models overlaid": ", ".join(overlaid)}
    rig = simulated_rig(meta)
    if meta.get("simulated") == "true":
        info["note"] = "simulated rig (sim_bench_node), not hardware"
    if rig is not None:
        info["simulated rig"] = (f"seed {rig.get('seed', '?')}, truth `{rig['model']}`, pressure shift "
                                 f"{rig.get('pressure_shift', '?')}, material scale {rig.get('material_scale', '?')}, "
                                 f"hysteresis {float(rig.get('hysteresis_pressure', 0.0)) / PA_PER_BAR:g} bar "
                                 "(a rerun with this seed reproduces the noise)")
    if result is not None and result.get("complete") != "true":
        info["incomplete"] = (f"{result.get('completed_steps', '?')} of {result.get('n_steps', '?')} steps completed "
                              f"(only those are analysed): {result.get('reason', '')}")
    from .tip_compare import tips_from_recording
    tips_skipped: dict = {}
    # the first rung, calibrated if given
    tips_label = (overlaid[1] if calibration is not None else overlaid[0]) if overlaid else ""
    tips = tips_from_recording(path, built[tips_label], tips_skipped) if overlaid else []
    plots = plot(stats, out, "report")
    text = markdown(f"Bench report: {design.name}", info, stats, hyst, plots, calibration, tips, tips_skipped,
                    overlay_note=truth_note(rig, path) if rig is not None else "", tips_model=f"`{tips_label}`",
                    rig=rig)
    md = out / "report.md"
    md.write_text(text)
    return {"report": str(md), "plots": plots, "stats": stats, "hysteresis": hyst, "rows": rows, "tips": tips,
            "tips_skipped": tips_skipped}
