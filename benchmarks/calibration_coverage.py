"""Do the calibration's stated 95% intervals hold the truth about 95% of the time?

The quick protocol on the simulated rig (core only, a fake clock: no DDS) whose truth is the closed
form on a 30% stiffer silicone at the published shift 0.25, with the rig's gauge and reading noise
and no bench bias (friction, tilt, fixed gauge error: the fit absorbs those), once per seed; each
run is calibrated (bench/calibration.py) and its intervals checked against the truth.
``--hysteresis`` (Pa) gives the rig a play the model does not have: the model misfits the readings
beyond their noise, and the intervals must say so (widened by the levels' lack of fit).

    .venv/bin/python benchmarks/calibration_coverage.py [--seeds 24] [--protocol quick] [--hysteresis 0.03bar]

Writes benchmarks/results/calibration_coverage.{json,csv} (with --hysteresis:
calibration_coverage_misfit.*).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness import pressure_option, write_results

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))
from bench_sim_helpers import run_offline  # noqa: E402  (the offline runner the tests use)

from softcath_ros.bench.analysis import rows_from_events  # noqa: E402
from softcath_ros.bench.calibration import MISFIT, calibrate  # noqa: E402
from softcath_ros.bench.protocol import load_protocol  # noqa: E402
from softcath_ros.bench.sim_rig import RigParams, SimulatedRig  # noqa: E402
from softcath_ros.core.calibration_file import scaled_design  # noqa: E402
from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402

TRUE_SHIFT, TRUE_SCALE = 0.25, 1.3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=24)
    ap.add_argument("--protocol", default="quick")
    ap.add_argument("--hysteresis", type=pressure_option("--hysteresis"), default=0.0,
                    help="the rig's play, with its unit (a misfit the model lacks)")
    args = ap.parse_args()
    design = load_design("implemented_5mm")
    truth = make_model("closed_form", scaled_design(design, TRUE_SCALE))
    protocol = load_protocol(args.protocol)
    rows = []
    for seed in range(args.seeds):
        params = RigParams(pressure_shift=TRUE_SHIFT, friction_underread=0.0, out_of_plane_tilt=0.0,
                           gauge_error=0.0, hysteresis_pressure=args.hysteresis, seed=seed)
        events, streams = run_offline(protocol, SimulatedRig(truth, params))
        r = calibrate(rows_from_events(events, streams), design, "closed_form")
        rows.append({"seed": seed, "readings": r.n_residuals, "pressure_shift": r.pressure_shift,
                     "shift_ci95": r.ci95["pressure_shift"], "material_scale": r.material_scale,
                     "scale_ci95": r.ci95["material_scale"], "correlation": r.correlation, "rms_after": r.rms_after,
                     "misfit_warned": MISFIT in r.message,
                     "shift_covered": abs(r.pressure_shift - TRUE_SHIFT) <= r.ci95["pressure_shift"],
                     "scale_covered": abs(r.material_scale - TRUE_SCALE) <= r.ci95["material_scale"]})
        print(rows[-1], flush=True)
    n = len(rows)
    covered = {k: sum(r[k] for r in rows) for k in ("shift_covered", "scale_covered", "misfit_warned")}
    print(f"{n} runs: shift covered {covered['shift_covered']}, scale covered {covered['scale_covered']}, "
          f"misfit warned {covered['misfit_warned']}")
    meta = {"protocol": args.protocol, "truth": {"pressure_shift": TRUE_SHIFT, "material_scale": TRUE_SCALE,
                                                 "rung": "closed_form", "hysteresis_pressure": args.hysteresis},
            "runs": n, **covered, "note": "core only (no DDS); shared 2-core machine"}
    print(write_results("calibration_coverage_misfit" if args.hysteresis else "calibration_coverage", meta, rows))


if __name__ == "__main__":
    main()
