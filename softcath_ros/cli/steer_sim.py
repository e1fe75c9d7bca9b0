"""`softcath steer-sim`: closed-loop steering on the simulated rig, over DDS.

Starts sim_bench_node (the rig: truth with the 25% pressure shift and material scale 1.2,
a 10 Hz actuator, a tip tracker with noise, latency and drops), steer_node (the controller)
and steer_driver (targets, recording, scoring) as separate processes on a private ROS
domain; prints tip error RMS, steady-state error and settling time; writes the MCAP
recording and a plot of the target, the DDS run's tip path and, for comparison, the other
loop's path from the core simulation (bench/steering_sim.py, same scenario, no DDS).
"""
from __future__ import annotations

import json
import os
import sys
import time
from datetime import datetime
from pathlib import Path

from ..core.allocation import lowered_max_pressure
from ..core.errors import SoftcathError
from .common import add_unit_argument, check_rung_names, parse_pressure

MAX_DURATION_S = 3600.0   # of targets: the run, its recording and its plot are held to this


def register(sub) -> None:
    p = sub.add_parser("steer-sim", help="closed-loop steering on the simulated rig (nodes over DDS): "
                       "tip errors, recording, plot")
    p.add_argument("--design", default="three_sector_5mm", help="design name or file")
    p.add_argument("--trajectory", choices=("step", "circle"), default="step")
    p.add_argument("--duration", type=float, default=6.0, help="seconds of targets (default 6)")
    p.add_argument("--open-loop", action="store_true", help="run the controller open loop (feed-forward only)")
    p.add_argument("--mode", choices=("integral", "adaptive"), default="adaptive", help="feedback (closed loop)")
    p.add_argument("--model", default="surrogate", help="rung of the controller and of the rig's truth (default "
                   "surrogate: the section rung's shipped table)")
    p.add_argument("--max-pressure", default=None, metavar="P",
                   help="pressure limit, e.g. 0.25bar (at most the design's; default the design's steering "
                   "range: 0.3 bar, lower where one channel would turn the tip past 90 degrees)")
    add_unit_argument(p, "--max-pressure")
    p.add_argument("--latency", type=float, default=0.05, help="tracker latency, s")
    p.add_argument("--drop", type=float, default=0.2, help="fraction of tracker samples lost")
    p.add_argument("--output-dir", default="runs", help="where the recording goes (default runs/)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def _plot(series: dict, other, out: Path, title: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))
    ax.plot(series["target"][:, 0] * 1e3, series["target"][:, 1] * 1e3, "k--", lw=1, label="target")
    ax.plot(series["tip"][:, 0] * 1e3, series["tip"][:, 1] * 1e3, lw=1.2, label=series["label"])
    ax.plot(other["tip"][:, 0] * 1e3, other["tip"][:, 1] * 1e3, lw=1, alpha=0.8, label=other["label"])
    ax.set_xlabel("tip x, mm")
    ax.set_ylabel("tip y, mm")
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return str(out)


def run(args) -> int:
    import numpy as np

    from ..bench.steering_sim import SteeringScenario, run_metrics, simulate, steering_rig_params
    from ..bench.sim_rig import TrackerParams
    from ..core.steering import SteeringParams
    from ..core.steering_range import steering_model, steering_range
    from ..graph import NodeGraph, stop_process

    if not (0 < args.duration <= MAX_DURATION_S):
        raise SoftcathError(f"--duration {args.duration} s must be positive and at most {MAX_DURATION_S:g} s")
    if not 0 <= args.drop < 1 or not 0 <= args.latency < 10:
        raise SoftcathError("--drop must lie in [0, 1) and --latency in [0, 10) s")
    from ..core.design import load_design

    design = load_design(args.design)   # a wrong name or file is one line here, not a node that fails to start
    check_rung_names([args.model])
    max_pressure = (steering_range(steering_model(args.model, design)) if args.max_pressure is None
                    else lowered_max_pressure(parse_pressure(args.max_pressure, "--max-pressure", args.unit), design))
    rig = steering_rig_params()
    mode = "open_loop" if args.open_loop else args.mode
    name = f"steer_{args.trajectory}_{mode}_{datetime.now().strftime('%Y%m%d_%H%M%S')}"
    out_dir = Path(args.output_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    bag = out_dir / name
    say = (lambda *a: None) if args.json else (lambda *a: print(*a, flush=True))
    rig_params = {"design": args.design, "model": args.model, "pressure_shift": rig.pressure_shift,
                  "material_scale": rig.material_scale, "actuator_time_constant": rig.actuator_time_constant,
                  "tracker_latency": float(args.latency), "tracker_drop_fraction": float(args.drop)}
    steer_params = {"design": args.design, "model": args.model, "mode": mode, "max_pressure": float(max_pressure)}
    driver_params = {"design": args.design, "truth": args.model, "pressure_shift": rig.pressure_shift,
                     "material_scale": rig.material_scale, "max_pressure": float(max_pressure),
                     "trajectory": args.trajectory, "duration": float(args.duration), "output": str(bag)}
    explicit = os.environ.get("ROS_DOMAIN_ID", "").strip()
    t0 = time.monotonic()
    with NodeGraph(domain=int(explicit) if explicit.isdigit() else None) as graph:
        logs, procs = {}, []
        for node, params in (("sim_bench_node", rig_params), ("steer_node", steer_params)):
            logs[node] = out_dir / f"{name}_{node}.log"
            with open(logs[node], "w") as log:
                procs.append(graph.start(node, params, stdout=log))
        try:
            graph.wait_ready(*procs, timeout_s=120.0)
        except SoftcathError as exc:
            raise SoftcathError(f"{exc} (logs {', '.join(str(p) for p in logs.values())})") from None
        say(f"[steer-sim] rig and controller up on ROS_DOMAIN_ID={graph.domain}; driving {args.trajectory} "
            f"for {args.duration:g} s ({mode})")
        driver = graph.start("steer_driver", driver_params)
        try:
            text = driver.communicate(timeout=args.duration + 120.0)[0]
        except BaseException:
            stop_process(driver, 10.0)
            raise
    lines = [x for x in text.splitlines() if x.startswith("summary: ")]
    if driver.returncode != 0 or not lines:
        raise SoftcathError(f"steer_driver failed (exit {driver.returncode}): {text.strip().splitlines()[-3:]}")
    summary = json.loads(lines[-1][len("summary: "):])
    data = np.load(summary["series"])
    # The other loop, from the core simulation of the same scenario, for the plot.
    other_mode = "adaptive" if args.open_loop else "open_loop"
    scenario = SteeringScenario(design=args.design, model=args.model, truth=args.model, max_pressure=max_pressure,
                                rig=rig, tracker=TrackerParams(latency=args.latency, drop_fraction=args.drop),
                                controller=SteeringParams(mode=other_mode if not args.open_loop else args.mode))
    other = simulate(scenario, args.trajectory, args.duration)
    plot = _plot({"target": data["target"], "tip": data["tip"], "label": f"{mode} (DDS run)"},
                 {"tip": other.tip, "label": f"{scenario.controller.mode} (core simulation)"},
                 bag / "tip_paths.png", f"{args.design}, {args.trajectory}, model {args.model}, "
                 f"latency {args.latency * 1e3:g} ms, {args.drop:.0%} dropped")
    m = summary["metrics"]
    result = {"mode": mode, "trajectory": args.trajectory, "duration_s": args.duration, "model": args.model,
              "tip_error_rms_mm": m["tip_error_rms_m"] * 1e3, "steady_state_error_mm": m["steady_state_error_m"] * 1e3,
              "settling_time_s": m["settling_time_s"], "recording": summary["recording"], "plot": plot,
              "series": summary["series"], "comparison": {"mode": scenario.controller.mode, "source": "core simulation",
                                                          **{k: v for k, v in run_metrics(other, args.duration).items()
                                                             if k in ("tip_error_rms_m", "steady_state_error_m",
                                                                      "settling_time_s")}},
              "elapsed_s": time.monotonic() - t0}
    _print_result(result, args.json)
    return 0


def _print_result(result: dict, as_json: bool) -> None:
    """The run's result as JSON, or in three lines."""
    if as_json:
        json.dump(result, sys.stdout, indent=2)
        print()
    else:
        settle = result["settling_time_s"]
        print(f"[steer-sim] {result['mode']}: tip error RMS {result['tip_error_rms_mm']:.3f} mm, steady state "
              f"{result['steady_state_error_mm']:.3f} mm" + ("" if settle is None else f", settling {settle:.2f} s"))
        print(f"recording: {result['recording']}")
        print(f"plot:      {result['plot']}")
