"""The ladder chart's numbers: every rung on the same cases against the reference rung.

Cases: the 1-channel design (implemented_5mm, 40 mm) at 0.05..0.25 bar. Reference: fe3d at its
default mesh (mesh_size 1.0) if NGSolve is installed and converges there, else the section rung's
finest mesh (D/40), and the output says which. Each rung/setting records, per pressure, the
relative error in R_C = 1/|k| and the tip position error (mm), and its time per evaluation
(single commands for the table rungs; a cold sweep divided by its commands for the solvers).
A ramp from 0 to max_pressure locates each rung's failure boundary (the last pressure it reached).

Results are cached per rung (.cache/ladder/, keyed by the design's content hash, rung, settings
and cases), so re-running only redraws. Writes benchmarks/results/ladder_chart.{csv,json} and
config/ladder_envelope.yaml (what model selection reads); draw with `softcath chart`.

    .venv/bin/python benchmarks/ladder_chart.py [--no-fe3d] [--refresh]
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_io import RESULTS, machine_meta, write_results  # noqa: E402

from softcath_ros.core.cache import cache_dir, key_of  # noqa: E402
from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.errors import ModelError  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402
from softcath_ros.core.prediction import predict  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ENVELOPE = ROOT / "config" / "ladder_envelope.yaml"
DESIGN = "implemented_5mm"
PRESSURES = np.array([5000.0, 10000.0, 15000.0, 20000.0, 25000.0])   # Pa
# What each rung models (scene features, core/scene.py). The surrogate inherits its source's.
CAPABILITIES = {"closed_form": ["free_bending", "device_stiffness"],
                "section": ["free_bending", "device_stiffness"],
                "surrogate": ["free_bending", "device_stiffness"],
                "fe3d": ["free_bending", "device_stiffness"]}
# (label, rung, options, is a solver: timed as a cold sweep)
SETTINGS = [
    ("closed_form", "closed_form", {}, False),
    ("surrogate (of section D/20)", "surrogate", {}, False),
    ("section D/12", "section", {"mesh_size": 0.005 / 12}, True),
    ("section D/20", "section", {}, True),
    ("section D/40", "section", {"mesh_size": 0.005 / 40}, True),
    ("fe3d mesh 1.0", "fe3d", {"mesh_size": 1.0}, True),
]


def run_rung(design, rung: str, options: dict, solver: bool, refresh: bool) -> dict:
    """Predictions at the case pressures, time per evaluation and failure boundary (cached)."""
    path = cache_dir("ladder") / f"{rung}_{key_of(design.content_hash(), rung, options, PRESSURES.tolist())}.json"
    if path.is_file() and not refresh:
        return json.loads(path.read_text())
    opts = dict(options)
    if solver and rung != "fe3d":
        opts["cache"] = False   # cold: the time is the solver's
    model = make_model(rung, design, **opts)
    t0 = time.perf_counter()
    preds = predict(model, PRESSURES[:, None])
    sweep = time.perf_counter() - t0
    if rung == "fe3d":
        # minutes per sweep: its own cache is kept, and the cost is the ramp's recorded wall time
        times = [t for t in model.evaluate(PRESSURES[:, None]).extras["time_s"] if t is not None]
        total = max(times) if times == sorted(times) else sum(times)
        per_eval = (total or sweep) / len(PRESSURES)
    elif solver:
        per_eval = sweep / len(PRESSURES)
    else:
        p1 = PRESSURES[2:3]
        times = []
        for _ in range(7):
            t = time.perf_counter()
            for _ in range(2000):
                model.evaluate(p1)
            times.append((time.perf_counter() - t) / 2000)
        per_eval = statistics.median(times)
    # failure boundary: a ramp to max_pressure (fe3d: the case ramp only, it is too slow to go further)
    if rung == "fe3d":
        ok = [p.converged for p in preds]
        boundary = float(PRESSURES[np.argmin(ok) - 1]) if not all(ok) else float(PRESSURES[-1])
        beyond = not all(ok)
    elif rung == "surrogate":
        boundary, beyond = model.pressure_range[1], True
    else:
        ramp = np.linspace(0.0, design.max_pressure, 41)[:, None]
        st = make_model(rung, design, **opts).evaluate(ramp)
        n_ok = int(np.argmin(st.converged)) if not st.converged.all() else len(ramp)
        boundary, beyond = float(ramp[n_ok - 1, 0]), n_ok < len(ramp)
    out = {"rung": rung, "options": options, "s_per_eval": per_eval, "boundary_pa": boundary,
           "fails_beyond": beyond, "predictions": [p.to_json() for p in preds]}
    path.write_text(json.dumps(out))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--no-fe3d", action="store_true", help="reference = section D/40 (no NGSolve run)")
    ap.add_argument("--refresh", action="store_true", help="recompute cached rung results")
    args = ap.parse_args()
    design = load_design(DESIGN)
    results = {}
    for label, rung, options, solver in SETTINGS:
        if rung == "fe3d" and args.no_fe3d:
            continue
        print(f"running {label} ...", flush=True)
        try:
            results[label] = run_rung(design, rung, options, solver, args.refresh)
        except ModelError as exc:
            print(f"  {label}: not available ({exc})")
    for label, res in results.items():
        # A rung may flag an impossible state converged (fe3d past ~180 degrees of bend returned
        # k = 0 with a negative axial stretch): such points count as failures, said so.
        for p in res["predictions"]:
            if p["converged"] and not (p["axial_stretch"] or 0) > 0:
                p["converged"] = False
                p["reason"] = f"reported converged with axial stretch {p['axial_stretch']}: not physical"
                print(f"  {label}: {p['pressures_pa'][0]:.0f} Pa {p['reason']}")
        ok = [p["converged"] for p in res["predictions"]]
        if not all(ok):
            first = ok.index(False)
            res["boundary_pa"] = min(res["boundary_pa"], PRESSURES[first - 1] if first else 0.0)
            res["fails_beyond"] = True
    ref_label = "fe3d mesh 1.0"
    if ref_label not in results or sum(p["converged"] for p in results[ref_label]["predictions"]) < 3:
        ref_label = "section D/40"
    ref = results[ref_label]["predictions"]
    print(f"reference: {ref_label}")
    rows = []
    for label, res in results.items():
        for p, r in zip(res["predictions"], ref):
            row = {"setting": label, "rung": res["rung"], "pressure_pa": p["pressures_pa"][0],
                   "s_per_eval": res["s_per_eval"], "converged": p["converged"],
                   "reference": ref_label, "boundary_pa": res["boundary_pa"], "fails_beyond": res["fails_beyond"],
                   "rc_m": p["radius_of_curvature_m"], "rc_rel_error": None, "tip_error_mm": None}
            if p["converged"] and r["converged"]:
                row["rc_rel_error"] = abs(p["radius_of_curvature_m"] / r["radius_of_curvature_m"] - 1.0)
                row["tip_error_mm"] = 1e3 * float(np.linalg.norm(np.subtract(p["tip_position_m"],
                                                                            r["tip_position_m"])))
            rows.append(row)
    write_results("ladder_chart", {"design": DESIGN, "length_m": design.length, "reference": ref_label,
                                   "pressures_pa": PRESSURES.tolist()}, rows)
    write_envelope(rows, ref_label, design)
    for label in results:
        rs = [r for r in rows if r["setting"] == label]
        errs = [r["rc_rel_error"] for r in rs if r["rc_rel_error"] is not None]
        print(f"{label:28s} {rs[0]['s_per_eval'] * 1e6:12.2f} us/eval  R_C error max "
              f"{max(errs) if errs else float('nan'):.2%}  boundary {rs[0]['boundary_pa']:.0f} Pa")
    print(f"wrote {RESULTS}/ladder_chart.{{csv,json}} and {ENVELOPE}; draw with: softcath chart")


def write_envelope(rows: list[dict], ref_label: str, design) -> None:
    """Per rung, its default setting's envelope (the cheapest setting per rung is what a scene runs)."""
    import yaml

    default = {"closed_form": "closed_form", "surrogate": "surrogate (of section D/20)",
               "section": "section D/20", "fe3d": "fe3d mesh 1.0"}
    rungs = {}
    for rung, label in default.items():
        rs = [r for r in rows if r["setting"] == label]
        if not rs:
            continue
        inside = [r for r in rs if r["pressure_pa"] <= rs[0]["boundary_pa"]]
        errs = [r["rc_rel_error"] for r in inside if r["rc_rel_error"] is not None]
        tips = [r["tip_error_mm"] for r in inside if r["tip_error_mm"] is not None]
        is_ref = label == ref_label
        rungs[rung] = {
            "setting": label,
            "capabilities": CAPABILITIES[rung],
            "designs": {design.name: {
                # the reference has no error against itself: its envelope is the reference's own (unmeasured
                # here, taken as 0), so a scene asking for more accuracy than any rung has gets the reference
                "error_rc_rel_max": 0.0 if is_ref else (max(errs) if errs else None),
                "error_tip_mm_max": 0.0 if is_ref else (max(tips) if tips else None),
                "cost_s_per_eval": float(rs[0]["s_per_eval"]),
                "valid_pressure_pa": [0.0, float(rs[0]["boundary_pa"])],
                "measured_pressures_pa": [float(r["pressure_pa"]) for r in inside]}}}
    doc = {"reference": ref_label, "measured": machine_meta()["date"],
           "note": "written by benchmarks/ladder_chart.py; read by core/model_selection.py (model: auto). "
                   "Errors are relative R_C errors against the reference over the measured pressures inside "
                   "each rung's valid range; costs are seconds per evaluation on a shared 2-core machine.",
           "rungs": rungs}
    ENVELOPE.write_text(yaml.safe_dump(doc, sort_keys=False))


if __name__ == "__main__":
    main()
