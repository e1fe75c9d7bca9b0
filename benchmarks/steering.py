"""Closed-loop steering against open loop (issue 16 targets).

Core-only simulation (bench/steering_sim.py, no DDS) of the 40 mm three_sector_5mm design
(the steering default; ``--design`` for another),
controller and rig truth on the section-rung surrogate (the table shipped for the design, the
controller's inverse limited to the design's steering range, core/steering_range.steering_range, or
``--max-pressure``), the rig 25% pressure-shifted with material scale 1.2,
a 10 Hz actuator behind the 80 ms regulator, a 100 Hz tip tracker with 0.1 mm noise, 20% of the
samples dropped, latency 50 ms and 150 ms; trajectories: three steps, and a 0.2 Hz circle.
Modes: open_loop, integral, adaptive. The controller's CPU is the time spent in its calls per
simulated second (100 Hz measurements, 200 Hz output). Plus one DDS run (`softcath steer-sim`,
separate processes, its defaults: the same surrogate).

    .venv/bin/python benchmarks/steering.py [--quick] [--design three_channel_5mm] [--max-pressure 10000]
        [--name steering]

Writes benchmarks/results/<name>.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from harness import save_figure, write_results  # benchmarks/ is the script's directory
from softcath_ros.bench.sim_rig import TrackerParams  # noqa: E402
from softcath_ros.bench.steering_sim import SteeringScenario, build, run_metrics, simulate  # noqa: E402
from softcath_ros.core.steering import SteeringParams  # noqa: E402

RUNG = "surrogate"
DURATION = {"step": 6.0, "circle": 10.0}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="50 ms latency only, no DDS run")
    ap.add_argument("--design", default=SteeringScenario.design, help="design name or file (the core runs)")
    ap.add_argument("--max-pressure", type=float, default=None,
                    help="the steering range, Pa (default the design's: core/steering_range.steering_range)")
    ap.add_argument("--name", default="steering", help="results stem under benchmarks/results/")
    args = ap.parse_args()
    built = build(SteeringScenario(design=args.design, model=RUNG, truth=RUNG, max_pressure=args.max_pressure))
    rows, runs = [], {}
    latencies = (0.05,) if args.quick else (0.05, 0.15)
    for kind in ("step", "circle"):
        for mode in ("open_loop", "integral", "adaptive"):
            for latency in latencies:
                if mode == "open_loop" and latency != latencies[0]:
                    continue   # the open loop never uses the measurement
                scenario = SteeringScenario(design=args.design, model=RUNG, truth=RUNG, max_pressure=args.max_pressure,
                                            controller=SteeringParams(mode=mode),
                                            tracker=TrackerParams(latency=latency, drop_fraction=0.2))
                t0 = time.perf_counter()
                run = simulate(scenario, kind, DURATION[kind], built)
                m = run_metrics(run, DURATION[kind])
                runs[(kind, mode, latency)] = run
                rows.append({"source": "core", "trajectory": kind, "mode": mode, "model": RUNG, "truth": RUNG,
                             "latency_ms": latency * 1e3, "dropped": 0.2, "duration_s": DURATION[kind],
                             "tip_error_rms_mm": m["tip_error_rms_m"] * 1e3,
                             "steady_state_error_mm": m["steady_state_error_m"] * 1e3,
                             "settling_time_s": m["settling_time_s"],
                             **{f"{part}_error_{stat}_mm": (m[f"{part}_error_{stat}_m"] * 1e3 if kind == "circle"
                                                            else None)
                                for part, stat in (("radial", "rms"), ("tangential", "rms"), ("tangential", "mean"),
                                                   ("axial", "rms"))},
                             "controller_core_fraction": m["controller_core_fraction"],
                             "final_gain": m["final_gain"], "wall_s": time.perf_counter() - t0})
                print(json.dumps(rows[-1]), flush=True)
    if not args.quick:
        rows.append(dds_run(args.design, args.max_pressure))
        print(json.dumps(rows[-1]), flush=True)
    write_results(args.name, {"design": built[2].name, "steering_range_pa": built[2].max_pressure,
                              "allocator_max_pressure_pa": built[0].max_pressure,
                              "quick": args.quick, "rig": "pressure_shift 0.25, material_scale 1.2, "
                              "regulator 80 ms, actuator 16 ms (10 Hz)", "tracker": "100 Hz, 0.1 mm noise",
                              "note": "machine shared with other jobs; CPU fractions are upper bounds"}, rows)
    chart(runs, latencies[0], args.name)
    return 0


def dds_run(design: str, max_pressure: float | None) -> dict:
    exe = Path(sys.executable).parent / "softcath"
    with tempfile.TemporaryDirectory() as out:
        env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
        t0 = time.perf_counter()
        argv = [str(exe), "steer-sim", "--design", design, "--trajectory", "step", "--duration", "6", "--json",
                "--output-dir", out] + ([] if max_pressure is None else ["--max-pressure", f"{max_pressure!r}Pa"])
        res = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=300)
        if res.returncode != 0:
            raise SystemExit(f"steer-sim failed: {res.stderr[-1000:]}")
        r = json.loads(res.stdout)
    return {"source": "dds (steer-sim)", "trajectory": "step", "mode": r["mode"], "model": r["model"],
            "truth": r["model"], "latency_ms": 50.0, "dropped": 0.2, "duration_s": 6.0,
            "tip_error_rms_mm": r["tip_error_rms_mm"], "steady_state_error_mm": r["steady_state_error_mm"],
            "settling_time_s": r["settling_time_s"], "controller_core_fraction": None,
            "final_gain": None, "wall_s": time.perf_counter() - t0}


def chart(runs: dict, latency: float, name: str = "steering") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for mode, style in (("open_loop", "C1"), ("integral", "C2"), ("adaptive", "C0")):
        r = runs[("step", mode, latency)]
        axes[0].plot(r.t, np.linalg.norm(r.tip - r.target, axis=1) * 1e3, style, lw=1, label=mode)
        c = runs[("circle", mode, latency)]
        axes[1].plot(c.t, np.linalg.norm(c.tip - c.target, axis=1) * 1e3, style, lw=1, label=mode)
        late = c.t >= 5.0
        axes[2].plot(c.tip[late, 0] * 1e3, c.tip[late, 1] * 1e3, style, lw=1, label=mode)
    c = runs[("circle", "open_loop", latency)]
    axes[2].plot(c.target[:, 0] * 1e3, c.target[:, 1] * 1e3, "k--", lw=1, label="target")
    axes[0].set(title=f"steps: tip error ({latency * 1e3:g} ms latency, 20% dropped)", xlabel="t, s",
                ylabel="mm", yscale="log")
    axes[1].set(title="0.2 Hz circle: tip error", xlabel="t, s", ylabel="mm", yscale="log")
    axes[2].set(title="circle, second half: tip paths", xlabel="x, mm", ylabel="y, mm", aspect="equal")
    for ax in axes:
        ax.legend(fontsize=8)
    axes[0].axhline(0.5, color="grey", lw=0.5)
    axes[0].axhline(0.3, color="grey", lw=0.5, ls=":")
    axes[1].axhline(0.3, color="grey", lw=0.5, ls=":")
    fig.tight_layout()
    save_figure(fig, name)


if __name__ == "__main__":
    sys.exit(main())
