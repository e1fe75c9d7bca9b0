"""`softcath allocate`: channel pressures for a desired bend, from any rung.

Exit codes: 0 allocated (possibly saturated: see ``saturated``), 1 the direction is
unreachable for the design or the model's inverse did not converge (the JSON still
says so), 2 bad input.
"""
from __future__ import annotations

import math
import sys

from ..core import json_output
from ..core.design import load_design
from ..core.errors import SoftcathError
from ..core.prediction import arc_and_cap
from .common import PA_PER_BAR, add_model_argument, add_unit_argument, bounded_int, finite_float, parse_pressure

MAX_DIRECTIONS = 3600   # 0.1 deg apart; each direction is one bisection on the model


def register(sub) -> None:
    p = sub.add_parser("allocate", help="channel pressures for a desired bend (curvature, angle or tip point)")
    p.add_argument("--design", required=True, help="design YAML file, or the name of a shipped design")
    add_model_argument(p, "model rung")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--curvature", metavar="KX,KY", help="curvature vector in softcath_base, 1/m")
    target.add_argument("--direction", type=finite_float, metavar="DEG",
                        help="bending direction, degrees from +x towards +y (use with --angle)")
    target.add_argument("--tip", metavar="X,Y,Z", help="desired tip position in softcath_base, m")
    p.add_argument("--angle", type=finite_float, metavar="DEG", help="bending angle, degrees (with --direction)")
    p.add_argument("--max-pressure", default=None, metavar="P",
                   help="lower the design's max_pressure, e.g. 0.2bar, to stay where a rung converges")
    add_unit_argument(p, "--max-pressure")
    p.add_argument("--reachable-set", type=bounded_int(0, MAX_DIRECTIONS), default=0, metavar="N",
                   help=f"also report the maximum curvature on N equally spaced directions (N <= {MAX_DIRECTIONS})")
    p.add_argument("--calibration", default=None, help="calibration file from `softcath calibrate` to apply")
    p.add_argument("--no-cache", action="store_true", help="rungs that cache do not read their cache")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def _floats(text: str, n: int, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise SoftcathError(f"{option} {text!r}: not a comma list of numbers") from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise SoftcathError(f"{option} {text!r}: needs {n} finite comma-separated numbers")
    return values


def run(args) -> int:
    from ..core.allocation import Allocator
    from ..core.calibration_file import build_model, load_calibration
    from ..core.models import run_options

    if (args.direction is None) != (args.angle is None):
        raise SoftcathError("--direction and --angle go together")
    design = load_design(args.design)
    calibration = load_calibration(args.calibration) if args.calibration else None
    model = build_model(args.model, design, calibration, **run_options(args.model, cache=not args.no_cache))
    max_pressure = None if args.max_pressure is None else parse_pressure(args.max_pressure, "--max-pressure", args.unit)
    allocator = Allocator(model, max_pressure=max_pressure)
    if args.curvature is not None:
        k = _floats(args.curvature, 2, "--curvature")
        result = allocator.allocate(k)
        direction = math.atan2(k[1], k[0])
    elif args.tip is not None:
        tip = _floats(args.tip, 3, "--tip")
        result = allocator.allocate_tip(tip)
        direction = math.atan2(tip[1], tip[0])
    else:
        if not (math.isfinite(args.direction) and math.isfinite(args.angle)):
            raise SoftcathError("--direction and --angle must be finite")
        direction = math.radians(args.direction)
        result = allocator.allocate_bend(direction, math.radians(args.angle))
    if not math.isfinite(result.max_curvature) and result.reachable:
        result.max_curvature = allocator.max_curvature(direction)
    arc_length = arc_and_cap(model, design.length)[0]   # the bent arc's reference length
    out = {"model": allocator.model.name, "design": design.name, "max_pressure_pa": allocator.max_pressure,
           **result.to_json(),
           "max_bending_angle_rad": result.max_curvature * arc_length * result.axial_stretch}
    if args.reachable_set > 0:
        rs = allocator.reachable_set(args.reachable_set)
        out["reachable_set"] = {"directions_deg": [math.degrees(d) for d in rs.directions],
                                "max_curvature_per_m": rs.max_curvature.tolist(),
                                "channel_directions_deg": [math.degrees(d) if math.isfinite(d) else None
                                                           for d in rs.channel_directions],
                                "channel_max_curvature_per_m": rs.channel_max_curvature.tolist()}
    if args.json:
        json_output.dump(out, sys.stdout, indent=2)
        print()
    else:
        _print_human(out, arc_length)
    if not result.reachable or not result.converged:
        print(f"softcath allocate: {result.message}", file=sys.stderr)
        return 1
    return 0


def _print_human(out: dict, arc_length: float) -> None:
    """``arc_length``: the reference length of the bent arc (m, the channelled part)."""
    print(f"model {out['model']}, design {out['design']}")
    print("pressures [bar]: " + ", ".join(f"{p / PA_PER_BAR:.4f}" for p in out["pressures_pa"]))
    kx, ky = out["achieved_curvature_per_m"]
    kappa = math.hypot(kx, ky)
    print(f"achieved curvature [1/m]: ({kx:.4f}, {ky:.4f}), direction {math.degrees(math.atan2(ky, kx)):.2f} deg, "
          f"angle {math.degrees(kappa * arc_length * out['axial_stretch']):.2f} deg")
    print(f"max curvature in this direction [1/m]: {out['max_curvature_per_m']:.4f}"
          + ("  (SATURATED: request beyond reach)" if out["saturated"] else ""))
    if "tip_error_m" in out:
        print(f"tip error [mm]: {out['tip_error_m'] * 1e3:.3f}" + ("" if out["tip_reachable"] else "  (not reached)"))
    if "reachable_set" in out:
        rs = out["reachable_set"]
        for d, k in zip(rs["directions_deg"], rs["max_curvature_per_m"]):
            print(f"  direction {d:7.2f} deg: max curvature {k:.4f} 1/m")
