"""`softcath predict`: bending for channel pressures, from any rung.

Exit codes (as `softcath sweep`): 0 all converged, 1 some command did not converge (the output
still lists every command), 2 bad input (pressures above the design's max_pressure included).
With ``--calibration`` the rung is calibrated and each result carries a 95% band.
"""
from __future__ import annotations

import math
import sys

import numpy as np

from ..core import json_output
from ..core.design import load_design
from ..core.errors import SoftcathError
from .common import (PA_PER_BAR, add_model_argument, add_option_argument, add_unit_argument, check_pressure_limits,
                     checked_length, parse_model_options, parse_pressures, positive_float)


def register(sub) -> None:
    p = sub.add_parser("predict", help="predict bending for channel pressures")
    p.add_argument("--design", required=True, help="design YAML file, or the name of a shipped design")
    add_model_argument(p, "model rung")
    p.add_argument("--pressure", required=True, nargs="+",
                   help="one pressure per command (0.15bar, 15kPa, 15000Pa, or a bare number with --unit); "
                        "a comma list per channel for multi-channel designs")
    add_unit_argument(p, "--pressure")
    p.add_argument("--length", type=positive_float, default=None,
                   help="actuated length in m (default: the design's); rungs that solve the whole body (rod, fe3d) "
                        "solve one of this length")
    p.add_argument("--scene", default=None, help="scene YAML file or shipped scene name (for --model auto)")
    p.add_argument("--calibration", default=None, help="calibration file from `softcath calibrate` to apply")
    p.add_argument("--no-cache", action="store_true", help="rungs that cache do not read their cache")
    add_option_argument(p)
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..core.calibration_file import build_model, load_calibration
    from ..core.models import run_options
    from ..core.prediction import format_mm, predict

    design = load_design(args.design)
    length = None if args.length is None else checked_length(design, args.length)   # None: the model's own
    pressures = parse_pressures(args.pressure, design.n_channels, args.unit)
    check_pressure_limits(pressures, design)
    calibration = load_calibration(args.calibration) if args.calibration else None
    if args.model == "auto":
        parse_model_options("auto", args.option)   # refuses options for auto
        from ..core.scene import load_scene

        if args.scene is None:
            raise SoftcathError("--model auto needs --scene FILE (what the model must handle)")
        options = {"scene": load_scene(args.scene)}
        scene_length = options["scene"].design.length
        if length is not None and not math.isclose(length, scene_length, rel_tol=1e-9):
            raise SoftcathError(f"--length {length:g} with --model auto: scene '{options['scene'].name}' sets the "
                                f"length ({scene_length:g} m) the rung was chosen for; give a scene of that length")
    else:
        options = {**run_options(args.model, cache=not args.no_cache), **parse_model_options(args.model, args.option)}
    model = build_model(args.model, design, calibration, **options)
    if args.model == "auto":
        print(model.selection.reason, file=sys.stderr)
    results = predict(model, pressures, length)
    if calibration is not None:
        add_bands(results, args.model, design, calibration, pressures, length, options)
    length = model.design.length if length is None else length   # auto's is the scene's
    if args.json:
        doc = {"model": model.name, "design": design.name, "length_m": length,
               "results": [r.to_json() for r in results]}
        if calibration is not None:
            doc["calibration"] = {"file": args.calibration, **{k: calibration.to_dict()[k] for k in (
                "rung", "design_hash", "pressure_shift", "material_scale", "covariance", "recording", "date")}}
        json_output.dump(doc, sys.stdout, indent=2)
        print()
    else:
        print(f"model {model.name}, design {design.name}, length {length * 1e3:.1f} mm")
        print(f"{'pressure [bar]':>18} {'R_C=l/theta [mm]':>17} {'1/|k| [mm]':>11} {'angle [deg]':>12} "
              f"{'tip x,y,z [mm]':>28}")
        for r in results:
            ps = ",".join(f"{v / PA_PER_BAR:.3f}" for v in r.pressures_pa)
            if not r.converged:
                print(f"{ps:>18}  no answer: {r.reason}")
                continue
            tip = ",".join(f"{v * 1e3:.2f}" for v in r.tip_position_m)
            rc = format_mm(r.radius_of_curvature_m)
            if r.band95 is not None and r.band95.get("radius_of_curvature_m") is not None:
                rc += f" ± {r.band95['radius_of_curvature_m'] * 1e3:.2f}"
            force = "" if r.contact_force_n is None else f"   contact force {r.contact_force_n * 1e3:.2f} mN"
            print(f"{ps:>18} {rc:>17} {format_mm(r.centreline_radius_m):>11} "
                  f"{math.degrees(r.bending_angle_rad):12.2f} {tip:>28}{force}")
    return 0 if all(r.converged for r in results) else 1


BAND_FIELDS = ("radius_of_curvature_m", "centreline_radius_m", "bending_angle_rad")


def add_bands(results, name, design, calibration, pressures, length, options) -> None:
    """Each converged result's 95% band (half-widths) of R_C, 1/|k|, angle and tip position from the
    calibration's covariance (core/calibration_file.band95: the rung rebuilt at +-1 sigma)."""
    from ..core.calibration_file import band95, build_model
    from ..core.prediction import predict

    def quantities(c):
        rows = predict(build_model(name, design, c, **options), pressures, length)
        return np.array([[np.nan if not r.converged or getattr(r, f) is None else getattr(r, f) for f in BAND_FIELDS]
                         + (list(r.tip_position_m) if r.converged else [np.nan] * 3) for r in rows], dtype=float)

    half = band95(calibration, quantities)
    for r, h in zip(results, half):
        if r.converged:
            r.band95 = {**{f: (None if not math.isfinite(v) else float(v)) for f, v in zip(BAND_FIELDS, h[:3])},
                        "tip_position_m": [None if not math.isfinite(v) else float(v) for v in h[3:]]}
