"""`softcath sweep`: a pressure range through any rung, to CSV + JSON + a PNG of R_C and angle.

One channel ramps (``--channel``, default 0), the others stay at zero. The whole range goes
to the model as one batch so continuation rungs (section, fe3d) ramp once and show their
progress. Points that did not converge are written with ``converged = false`` and no
numbers. Exit codes (as `softcath predict`): 0 all converged, 1 some point did not (files and
JSON still written), 2 bad input (a pressure above the design's max_pressure included).
``radius_of_curvature_m`` is R_C = l / theta; ``centreline_radius_m`` is 1/|k|.
"""
from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import numpy as np

from ..core import json_output
from ..core.errors import SoftcathError
from .common import (PA_PER_BAR, add_model_argument, add_option_argument, add_unit_argument, bounded_int,
                     check_pressure_limits, checked_length, parse_model_options, parse_pressure, positive_float)

MAX_STEPS = 10_000   # a sweep's rows are held in memory and plotted


def register(sub) -> None:
    p = sub.add_parser("sweep", help="pressure sweep through a model: CSV, JSON and a plot")
    p.add_argument("--design", required=True, help="design YAML file, or the name of a shipped design")
    add_model_argument(p, "model rung")
    p.add_argument("--from", dest="p_from", default="0", help="first pressure, e.g. 0.05bar (default 0)")
    p.add_argument("--to", dest="p_to", required=True, help="last pressure, e.g. 0.25bar or 25kPa")
    p.add_argument("--steps", type=bounded_int(2, MAX_STEPS), default=11,
                   help=f"number of pressures, ends included, 2-{MAX_STEPS} (default 11)")
    add_unit_argument(p, "--from/--to")
    p.add_argument("--channel", type=bounded_int(0, 63), default=0, help="which channel ramps (0-based; default 0)")
    p.add_argument("--length", type=positive_float, default=None,
                   help="actuated length in m (default: the design's); rungs that solve the whole body (rod, fe3d) "
                        "solve one of this length")
    p.add_argument("--out", default=None, help="output prefix: writes PREFIX.csv, PREFIX.json, PREFIX.png "
                                               "(default: sweep_<design>_<model>)")
    p.add_argument("--no-cache", action="store_true", help="recompute even if cached (rungs that cache)")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG")
    p.add_argument("--calibration", default=None, help="calibration file from `softcath calibrate` to apply")
    add_option_argument(p)
    p.add_argument("--json", action="store_true", help="print the JSON to stdout as well")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..core.design import load_design
    from ..core.calibration_file import build_model, load_calibration
    from ..core.models import RUNGS, make_model, run_options
    from ..core.prediction import predict

    design = load_design(args.design)
    length = checked_length(design, args.length)
    if args.steps < 2:
        raise SoftcathError(f"--steps {args.steps}: need at least 2")
    if not 0 <= args.channel < design.n_channels:
        raise SoftcathError(f"--channel {args.channel}: design '{design.name}' has channels 0..{design.n_channels - 1}")
    lo, hi = parse_pressure(args.p_from, "--from", args.unit), parse_pressure(args.p_to, "--to", args.unit)
    if lo < 0 or hi <= lo:
        raise SoftcathError(f"--from {args.p_from} --to {args.p_to}: need 0 <= from < to")
    if args.model not in RUNGS:
        make_model(args.model, design)  # raises the 'unknown model' error listing the rungs
    levels = np.linspace(lo, hi, args.steps)
    pressures = np.zeros((args.steps, design.n_channels))
    pressures[:, args.channel] = levels
    check_pressure_limits(pressures, design)
    calibration = load_calibration(args.calibration) if args.calibration else None
    options = {**run_options(args.model, progress=True, cache=not args.no_cache),
               **parse_model_options(args.model, args.option)}
    model = build_model(args.model, design, calibration, **options)
    results = predict(model, pressures, length)
    rows = []
    for p, r in zip(levels, results):
        ok = r.converged
        rows.append({
            "pressure_pa": float(p), "pressure_bar": float(p / PA_PER_BAR), "converged": ok,
            "bending_angle_deg": math.degrees(r.bending_angle_rad) if ok else None,
            "radius_of_curvature_m": r.radius_of_curvature_m if ok else None,
            "centreline_radius_m": r.centreline_radius_m if ok else None,
            "curvature_x_per_m": r.curvature_per_m[0] if ok else None,
            "curvature_y_per_m": r.curvature_per_m[1] if ok else None,
            "axial_stretch": r.axial_stretch if ok else None,
            "tip_x_m": r.tip_position_m[0] if ok else None, "tip_y_m": r.tip_position_m[1] if ok else None,
            "tip_z_m": r.tip_position_m[2] if ok else None,
            "reason": "" if ok else r.reason})
    prefix = Path(args.out or f"sweep_{design.name}_{args.model}")
    prefix.parent.mkdir(parents=True, exist_ok=True)
    doc = {"model": model.name, "design": design.name, "length_m": length, "channel": args.channel,
           "results": rows}
    Path(f"{prefix}.json").write_text(json_output.dumps(doc, indent=2))
    with open(f"{prefix}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written = [f"{prefix}.csv", f"{prefix}.json"]
    if not args.no_plot:
        written.append(plot_sweep(rows, f"{prefix}.png", f"{design.name}, {model.name}, "
                                  f"L = {length * 1e3:.0f} mm, channel {args.channel}"))
    if args.json:
        json_output.dump(doc, sys.stdout, indent=2)
        print()
    else:
        print(f"{'p [bar]':>8} {'angle [deg]':>12} {'L/theta [mm]':>13}")
        for r in rows:
            if r["converged"]:
                rc = r["radius_of_curvature_m"]
                print(f"{r['pressure_bar']:8.4f} {r['bending_angle_deg']:12.2f} "
                      f"{'inf' if rc is None else f'{rc * 1e3:.2f}':>13}")
            else:
                print(f"{r['pressure_bar']:8.4f}  no answer: {r['reason']}")
        for path in written:
            print(f"wrote {path}")
    return 0 if all(r["converged"] for r in rows) else 1


def plot_sweep(rows: list[dict], path: str, title: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r["converged"]]
    p = [r["pressure_bar"] for r in ok]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot(p, [r["bending_angle_deg"] for r in ok], "o-")
    ax1.set_xlabel("pressure [bar]")
    ax1.set_ylabel("bending angle [deg]")
    rc = [(r["pressure_bar"], r["radius_of_curvature_m"] * 1e3) for r in ok if r["radius_of_curvature_m"]]
    if rc:
        ax2.plot(*zip(*rc), "o-")
    ax2.set_xlabel("pressure [bar]")
    ax2.set_ylabel("R_C = l / theta [mm]")
    ax2.set_yscale("log")
    failed = [r["pressure_bar"] for r in rows if not r["converged"]]
    if failed:
        for ax in (ax1, ax2):
            ax.axvline(min(failed), color="r", ls="--", label=f"no convergence from {min(failed):.3f} bar")
        ax1.legend()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
