"""Writing a study: NAME.csv (rows), NAME.png (chart), NAME.md (table, findings, rung and its
error from the ladder chart), NAME.json (all of it, machine-readable)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

from .. import json_output
from ..errors import ModelError
from ..units import PA_PER_BAR
from .context import StudyContext, StudyResult


def _at_pressure(entry: dict, pressure: float | None, own: str | None = None):
    """The entry's R_C error at the measured pressure nearest ``pressure`` and the reference there (None
    if not recorded); the error None where that reference is ``own`` (the rung's own setting: nothing
    measured)."""
    table = entry.get("error_rc_rel_by_pressure_pa") or []
    if pressure is None or not table:
        return None
    p, err = min(table, key=lambda pe: abs(pe[0] - pressure))
    ref = dict(entry.get("reference_by_pressure_pa") or []).get(p)
    return p, None if ref == own else err, ref


def rung_accuracy(rung: str, design_name: str, options: dict, pressure: float | None = None,
                  length: float | None = None) -> dict:
    """The rung's measured R_C error from the shipped ladder envelope (model_selection.load_envelope).

    Errors are measured on shipped designs only; a study's variants inherit the baseline's
    figure as an indication, which the report says."""
    from ..model_selection import load_envelope

    try:
        env = load_envelope()
    except ModelError as exc:
        return {"rung": rung, "error_rc_rel_max": None, "note": str(exc)}
    entry = env["rungs"].get(rung)
    if entry is None:
        return {"rung": rung, "error_rc_rel_max": None, "note": f"rung '{rung}' is not in the ladder chart"}
    designs = entry.get("designs") or {}
    measured_on = design_name if design_name in designs else next(iter(designs), None)
    if measured_on is None:
        return {"rung": rung, "error_rc_rel_max": None, "note": "no design measured"}
    m = designs[measured_on]
    lo, hi = m["valid_pressure_pa"]
    ref = m.get("reference") or env.get("reference")
    ref = " + ".join(ref) if isinstance(ref, list) else ref
    if ref == entry.get("setting"):   # the rung's own setting is the reference there (no fe3d on that design)
        note = (f"the ladder's reference itself on {measured_on} over {lo / PA_PER_BAR:g}..{hi / PA_PER_BAR:g} bar "
                f"(ladder chart setting '{ref}': fe3d was not run there), so its error is not measured")
    else:
        note = (f"max relative R_C error {m['error_rc_rel_max']:.1%} against {ref} on {measured_on} "
                f"over {lo / PA_PER_BAR:g}..{hi / PA_PER_BAR:g} bar (ladder chart setting '{entry.get('setting')}')")
    out = {}
    own = entry.get("setting")
    at = _at_pressure(m, pressure, own)
    if at is not None and ref != own and at[1] is None:   # e.g. a design fe3d reached only at low pressure
        out["error_rc_rel_at_pressure"] = None
        note += f"; at {at[0] / PA_PER_BAR:g} bar not measured ('{own}' is the reference there)"
    elif at is not None and ref != own:
        out["error_rc_rel_at_pressure"] = at[1]
        other = at[2] and set(at[2].split(" / ")) != set(ref.split(" + "))   # a reference of its own there
        note += f"; at {at[0] / PA_PER_BAR:g} bar {at[1]:.1%}" + (f" (against {at[2]})" if other else "")
        by_length = m.get("by_length") or {}
        key = next((k for k in by_length if length is not None and abs(float(k) - length) < 1e-9), None)
        at_l = _at_pressure(by_length[key], pressure, own) if key is not None else None
        if at_l is not None:
            out["error_rc_rel_at_pressure_and_length"] = at_l[1]
            note += (f" over all measured lengths, {'not measured' if at_l[1] is None else f'{at_l[1]:.1%}'} "
                     f"at the design's {length * 1e3:g} mm")
    if options:
        note += f"; this study ran it with options {options}"
    if measured_on != design_name:
        note += f"; '{design_name}' itself is not in the chart"
    note += "; varied designs are not in the chart, so this is an indication for them"
    return {"rung": rung, "setting": entry.get("setting"), "measured_on": measured_on,
            "error_rc_rel_max": m["error_rc_rel_max"], "reference": ref, **out, "note": note}


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        return f"{v:.4g}"
    return str(v).replace("|", "/")


MAX_CELL = 40   # longer cells (a refusal's reason) go to a note under the table: rows stay terminal-wide


def _cell(text: str, notes: list[str]) -> str:
    """The table cell for ``text``: itself, or its head before ':' and a numbered note holding it all."""
    if len(text) <= MAX_CELL:
        return text
    notes.append(text)
    head = text.split(":", 1)[0] if ":" in text[:MAX_CELL] else ""
    return f"{head} (note {len(notes)})".strip()


def markdown(result: StudyResult, ctx: StudyContext, accuracy: dict, files: dict) -> str:
    lines = [f"# {result.title} ({result.design})", "",
             f"- rung: `{ctx.rung}`; {accuracy['note']}",
             f"- pressure: {ctx.pressure / PA_PER_BAR:g} bar on channel {ctx.channel}, R_C = l / theta",
             f"- cases: {len(result.rows)} rows; {sum(1 for r in result.rows if not r.get('feasible', True))} infeasible, "
             f"{sum(1 for r in result.rows if r.get('feasible', True) and not r.get('converged', True))} did not converge "
             "(listed, never dropped)",
             f"- files: {', '.join(Path(p).name for p in files.values())}", "", "## Findings", ""]
    lines += [f"- {f}" for f in result.findings]
    lines += ["", "## Table", "", "| " + " | ".join(h for _, h in result.columns) + " |",
              "| " + " | ".join("---" for _ in result.columns) + " |"]
    notes: list[str] = []
    for r in result.rows:
        lines.append("| " + " | ".join(_cell(_fmt(r.get(k)), notes) for k, _ in result.columns) + " |")
    if notes:
        lines += ["", "Notes:", ""] + [f"{i}. {n}" for i, n in enumerate(notes, 1)]
    lines += ["", f"![{result.name}]({Path(files['png']).name})", ""]
    return "\n".join(lines)


def write_study(result: StudyResult, ctx: StudyContext, out_dir: str | Path, stem: str | None = None,
                length: float | None = None) -> dict:
    """Write the four files; returns {"csv": path, "png": ..., "md": ..., "json": ...}. ``length``
    (m, the baseline design's) picks the ladder chart's error at that length where it has one."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or f"{result.name}_{result.design}"
    files = {k: str(out / f"{stem}.{k}") for k in ("csv", "png", "md", "json")}
    keys = list(dict.fromkeys(k for r in result.rows for k in r))
    with open(files["csv"], "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in result.rows:
            w.writerow({k: json_output.dumps(v) if isinstance(v, (list, dict)) else v for k, v in r.items()})
    result.plot(files["png"])
    accuracy = rung_accuracy(ctx.rung, result.design, ctx.options, ctx.pressure, length)
    for name, text in result.extra_files.items():
        files[name] = str(out / name)
        Path(files[name]).write_text(text)
    Path(files["md"]).write_text(markdown(result, ctx, accuracy, files))
    doc = {"study": result.name, "design": result.design, "rung": ctx.rung, "rung_options": ctx.options,
           "pressure_pa": ctx.pressure, "channel": ctx.channel, "rung_accuracy": accuracy,
           "findings": result.findings, "meta": result.meta, "rows": result.rows}
    Path(files["json"]).write_text(json_output.dumps(doc, indent=2, default=str))
    return files
