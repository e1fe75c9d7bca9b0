"""How long `softcath calibrate` takes on the quick protocol, with the surrogate (the default rung):
the material scale read as a pressure scale on the design's own table (now) against a table built
for every scale the fit tries (before), and whether the two fits agree.

The recording: the quick protocol on the simulated rig (core only, a fake clock: no DDS) whose truth
is the surrogate on a design with every modulus x 1.3 at the published shift 0.25, reading and gauge
noise, no bench bias. Timed: the fit (bench/calibration.py) both ways, the rebuild with an empty
cache (each scale's table is built, as a first calibration would); and the whole command
(`softcath calibrate`, fit + calibration file + report) the new way, wall clock.

    .venv/bin/python benchmarks/calibration_speed.py [--no-rebuild]

Writes benchmarks/results/calibration_speed.{json,csv}.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from harness import write_results

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))
from bench_sim_helpers import run_offline, write_recording  # noqa: E402

from softcath_ros.bench.analysis import rows_from_events  # noqa: E402
from softcath_ros.bench.calibration import calibrate  # noqa: E402
from softcath_ros.bench.protocol import load_protocol  # noqa: E402
from softcath_ros.bench.sim_rig import RigParams, SimulatedRig, truth_model  # noqa: E402
from softcath_ros.core.design import load_design  # noqa: E402

TRUE_SHIFT, TRUE_SCALE = 0.25, 1.3


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-rebuild", action="store_true", help="skip the (minutes long) fit that rebuilds tables")
    args = ap.parse_args(argv)
    design = load_design("implemented_5mm")
    params = RigParams(pressure_shift=TRUE_SHIFT, material_scale=TRUE_SCALE, friction_underread=0.0,
                       out_of_plane_tilt=0.0, gauge_error=0.0, seed=5)
    events, streams = run_offline(load_protocol("quick"), SimulatedRig(truth_model("surrogate", design, params), params))
    rows_in = rows_from_events(events, streams)
    load_before = os.getloadavg()
    rows, fits = [], {}
    for method, rebuild in (("scaled pressures, one table", False), ("a table per scale (before)", True)):
        if rebuild and args.no_rebuild:
            continue
        with tempfile.TemporaryDirectory() as cache:
            env = os.environ.get("SOFTCATH_CACHE")
            if rebuild:
                os.environ["SOFTCATH_CACHE"] = cache      # every scale's table is built, not found
            t0 = time.perf_counter()
            fit = calibrate(rows_in, design, "surrogate", rebuild=rebuild)
            seconds = time.perf_counter() - t0
            if env is None:
                os.environ.pop("SOFTCATH_CACHE", None)
            else:
                os.environ["SOFTCATH_CACHE"] = env
        fits[method] = fit
        rows.append({"method": method, "what": "fit", "seconds": seconds, "pressure_shift": fit.pressure_shift,
                     "material_scale": fit.material_scale, "ci95_shift": fit.ci95["pressure_shift"],
                     "ci95_scale": fit.ci95["material_scale"], "rms_after": fit.rms_after})
        print(f"{method}: fit {seconds:.2f} s: shift {fit.pressure_shift:.5f} ± {fit.ci95['pressure_shift']:.4f}, "
              f"scale {fit.material_scale:.5f} ± {fit.ci95['material_scale']:.4f}")
    with tempfile.TemporaryDirectory() as tmp:
        path = write_recording(Path(tmp) / "quick", events, streams, yaml.safe_dump(design.to_dict()))
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "softcath_ros.cli", "calibrate", str(path)],
                             capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        if out.returncode != 0:
            raise SystemExit(out.stderr)
    rows.append({"method": "scaled pressures, one table", "what": "softcath calibrate (fit, file, report)",
                 "seconds": seconds})
    print(f"softcath calibrate on the recording: {seconds:.2f} s wall")
    meta = {"design": design.name, "protocol": "quick", "rung": "surrogate", "truth_shift": TRUE_SHIFT,
            "truth_scale": TRUE_SCALE, "load_average_before": load_before, "load_average_after": os.getloadavg()}
    if len(fits) == 2:
        a, b = fits.values()
        meta["difference_shift"] = a.pressure_shift - b.pressure_shift
        meta["difference_scale"] = a.material_scale - b.material_scale
    write_results("calibration_speed", meta, rows)


if __name__ == "__main__":
    main()
