"""The ladder's rows summarised: a report per case and setting, and the measured envelope per rung
and design that ``model: auto`` reads (core/model_selection.py); the rows come from core/ladder.py."""
from __future__ import annotations

import os
import time
from pathlib import Path

from .ladder import DEFAULT_SETTING, TOLERANCES, tolerance_key
from .models import rung_info
from .units import PA_PER_BAR


def report(rows: list[dict], say=print) -> None:
    def worst(vals):
        vals = [v for v in vals if v is not None]
        return max(vals) if vals else float("nan")

    for case in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == case]
        refs = {}
        for r in rs:
            refs.setdefault(r["reference"] or "none", []).append(f"{r['pressure_pa'] / PA_PER_BAR:g}")
        say(f"{case} (reference: " + "; ".join(f"{k} at {', '.join(dict.fromkeys(v))} bar" for k, v in refs.items())
            + "):")
        for label in dict.fromkeys(r["setting"] for r in rs):
            s = [r for r in rs if r["setting"] == label]
            say(f"  {label:28s} {s[0]['s_per_eval'] * 1e6:14.2f} us/eval  R_C error max "
                  f"{worst(r['rc_rel_error'] for r in s):8.2%}  tip {worst(r['tip_error_mm'] for r in s):6.2f} mm  "
                  f"direction {worst(r['direction_error_deg'] for r in s):6.2f} deg  "
                  f"stops {s[0]['boundary_pa'] / PA_PER_BAR:.4f} bar ({s[0]['stop_reason'] or 'reached max_pressure'})"
                  f"  within 5 % to {s[0][tolerance_key(0.05)] / PA_PER_BAR:.2f} bar")


def _envelope(rs: list[dict]) -> dict | None:
    """One rung's measured envelope over rows of one setting (one or more cases)."""
    if not rs:
        return None
    inside = [r for r in rs if r["pressure_pa"] <= r["boundary_pa"]]

    def err(r, key):
        # a point's reference has no error against itself: taken as 0, so a scene asking for more
        # accuracy than any rung has gets the reference
        return 0.0 if r["setting"] == r["reference"] else r[key]

    def worst(key, rows=inside):
        vals = [err(r, key) for r in rows if err(r, key) is not None]
        return max(vals) if vals else None

    pressures = sorted({float(r["pressure_pa"]) for r in inside})
    return {
        "error_rc_rel_max": worst("rc_rel_error"),
        "error_tip_mm_max": worst("tip_error_mm"),
        "error_direction_deg_max": worst("direction_error_deg"),
        "reference": sorted({r["reference"] for r in inside if r["reference"]}),
        "cost_s_per_eval": max(float(r["s_per_eval"]) for r in rs),
        "valid_pressure_pa": [0.0, min(float(r["boundary_pa"]) for r in rs)],
        # a rung that models contact: the range with the tip on the bench's scale (blocked), which
        # selection uses for a scene with contact
        **({"valid_pressure_pa_with_contact": [0.0, min(float(r["contact_boundary_pa"]) for r in rs)]}
           if all(r.get("contact_boundary_pa") not in (None, "") for r in rs) else {}),
        "stop_reasons": sorted({r["stop_reason"] for r in rs if r.get("stop_reason")}),
        # per tolerance the lowest over the cases of the last pressure within it (see run_case)
        "accurate_to_pa": {f"{tol:g}": min(float(r[tolerance_key(tol)]) for r in rs) for tol in TOLERANCES
                           if all(tolerance_key(tol) in r for r in rs)},
        "measured_pressures_pa": pressures,
        # per measured pressure the worst R_C error over the cases there: selection judges a scene by
        # the pressures it needs, not by errors near the rung's limit it never reaches
        "error_rc_rel_by_pressure_pa": [[p, worst("rc_rel_error", [r for r in inside if r["pressure_pa"] == p])]
                                        for p in pressures],
        # and against what: fe3d where it converged, else the section rung with contact
        "reference_by_pressure_pa": [[p, " / ".join(sorted({r["reference"] for r in inside
                                                            if r["pressure_pa"] == p and r["reference"]}))]
                                     for p in pressures],
        "cases": list(dict.fromkeys(r["case"] for r in rs))}


def envelope_document(rows: list[dict], measured: str) -> dict:
    """Per rung (its default setting) and design: the worst over that design's cases, and per
    measured length its own envelope (``by_length``, keyed by the length in m) for selection."""
    rungs = {}
    for rung, label in DEFAULT_SETTING.items():
        rs = [r for r in rows if r["setting"] == label]
        if not rs:
            continue
        designs = {}
        for design in dict.fromkeys(r["design"] for r in rs):
            d_rows = [r for r in rs if r["design"] == design]
            entry = _envelope(d_rows)
            lengths = list(dict.fromkeys(r["length_m"] for r in d_rows))
            if len(lengths) > 1:
                entry["by_length"] = {f"{L:g}": _envelope([r for r in d_rows if r["length_m"] == L])
                                      for L in lengths}
            designs[design] = entry
        rungs[rung] = {"setting": label, "capabilities": list(rung_info(rung).models),
                       "designs": designs}
    refs = sorted({r["reference"] for r in rows if r["reference"]})   # a point with no reference names none
    return {"reference": " / ".join(refs), "measured": measured,
           "loadavg": list(os.getloadavg()),
           "note": "written by `softcath envelope`; read by core/model_selection.py (model: auto). "
                   "Errors are relative errors in R_C = l / theta (and tip mm, direction degrees) against each "
                   "point's reference (fe3d where it converged, else the section rung with lumen contact at its "
                   "default mesh) over the measured pressures inside each rung's valid range; per design the worst "
                   "over its cases, per length (by_length) that length's cases. accurate_to_pa: per R_C tolerance "
                   "the last measured pressure up to which the error stays within it (a point where the rung is "
                   "its own reference does not count). Costs are seconds per evaluation on a shared 2-core machine.",
           "rungs": rungs}


def write_envelope(rows: list[dict], path: Path) -> None:
    """The envelope of ``rows`` as YAML at ``path`` (atomically: model selection may be reading it)."""
    import yaml

    doc = envelope_document(rows, time.strftime("%Y-%m-%d %H:%M:%S"))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(yaml.safe_dump(doc, sort_keys=False))
    os.replace(tmp, path)


__all__ = ["envelope_document", "report", "write_envelope"]
