"""`softcath predict`: bending for channel pressures, from any rung."""
from __future__ import annotations

import math
import sys

import numpy as np

from ..core import json_output
from ..core.design import load_design
from ..core.errors import SoftcathError
from .common import PA_PER_BAR, add_option_argument, parse_model_options, parse_pressures, positive_float


def register(sub) -> None:
    from ..core.models import available_models

    p = sub.add_parser("predict", help="predict bending for channel pressures")
    p.add_argument("--design", required=True, help="design YAML file, or the name of a shipped design")
    p.add_argument("--model", default="closed_form", help=f"model rung: {', '.join(available_models())}")
    p.add_argument("--pressure", required=True, nargs="+",
                   help="one command per value; comma list per channel for multi-channel designs")
    p.add_argument("--unit", choices=("bar", "Pa"), default="Pa", help="unit of --pressure (default Pa)")
    p.add_argument("--length", type=positive_float, default=None, help="actuated length in m (default: the design's)")
    p.add_argument("--scene", default=None, help="scene YAML file or shipped scene name (for --model auto)")
    add_option_argument(p)
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..core.models import make_model
    from ..core.prediction import format_mm, predict

    design = load_design(args.design)
    pressures = parse_pressures(args.pressure, design.n_channels, args.unit)
    if np.any(pressures < 0):
        raise SoftcathError("pressures are gauge pressures and must not be negative")
    over = pressures.max() > design.max_pressure
    if args.model == "auto":
        parse_model_options("auto", args.option)   # refuses options for auto
        from ..core.scene import load_scene

        if args.scene is None:
            raise SoftcathError("--model auto needs --scene FILE (what the model must handle)")
        model = make_model("auto", design, scene=load_scene(args.scene))
        print(model.selection.reason, file=sys.stderr)
    else:
        model = make_model(args.model, design, **parse_model_options(args.model, args.option))
    results = predict(model, pressures, args.length)
    if args.json:
        json_output.dump({"model": model.name, "design": design.name,
                   "length_m": args.length if args.length is not None else model.design.length,
                   "results": [r.to_json() for r in results]}, sys.stdout, indent=2)
        print()
    else:
        print(f"model {model.name}, design {design.name}, length "
              f"{(args.length or model.design.length) * 1e3:.1f} mm")
        print(f"{'pressure [bar]':>18} {'1/|k| [mm]':>10} {'angle [deg]':>12} {'tip x,y,z [mm]':>28}")
        for r in results:
            ps = ",".join(f"{v / PA_PER_BAR:.3f}" for v in r.pressures_pa)
            if not r.converged:
                print(f"{ps:>18}  did not converge: {r.reason}")
                continue
            tip = ",".join(f"{v * 1e3:.2f}" for v in r.tip_position_m)
            force = "" if r.contact_force_n is None else f"   contact force {r.contact_force_n * 1e3:.2f} mN"
            print(f"{ps:>18} {format_mm(r.radius_of_curvature_m):>10} "
                  f"{math.degrees(r.bending_angle_rad):12.2f} {tip:>28}{force}")
    if over:
        print(f"warning: some pressures exceed the design's max_pressure {design.max_pressure:g} Pa",
              file=sys.stderr)
    return 0
