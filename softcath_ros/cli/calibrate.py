"""`softcath calibrate RECORDING`: fit pressure shift and material scale, write the calibration file."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from ..core import json_output
from .common import add_model_argument


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="fit a model to a bench recording and write a calibration file")
    p.add_argument("file", nargs="*", help="the bench recording (.mcap or its bag directory); several: the newest "
                                           "(default: the newest under runs/)")
    p.add_argument("--design", default=None, help="design to calibrate (default: the one attached to the recording)")
    add_model_argument(p, "rung to fit")
    p.add_argument("--output", default=None,
                   help="calibration file (default: <design>.calibration.yaml beside the recording)")
    p.add_argument("--no-cache", action="store_true", help="rungs that cache do not read their cache")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench.analysis import rows_from_recording
    from ..bench.calibration import MISFIT, calibrate
    from ..bench.report import recording_design, write_report
    from ..core.calibration_file import from_fit
    from ..core.design import load_design
    from ..core.errors import SoftcathError
    from ..recording.reader import recording_file
    from .report import pick_recording

    path = recording_file(pick_recording(args.file, "calibrate"))
    design = load_design(args.design) if args.design else recording_design(path)
    if design is None:
        raise SoftcathError(f"{path} has no design attached; pass --design")
    out = Path(args.output) if args.output else path.parent / f"{design.name}.calibration.yaml"
    out.parent.mkdir(parents=True, exist_ok=True)   # an output that cannot be written fails before the fit
    if out.is_dir():
        raise SoftcathError(f"--output {out}: a folder; name the calibration file")
    result = calibrate(rows_from_recording(path), design, args.model)
    if not all(math.isfinite(v) for row in result.covariance for v in row):
        raise SoftcathError(f"{path}: shift and scale are not identifiable from this recording ({result.message})")
    calibration = from_fit(result, design, path)
    calibration.save(out)
    rep = write_report(path, design, [args.model], calibration, out_dir=path.parent, cache=not args.no_cache)
    if args.json:
        json_output.dump({**calibration.to_dict(), "correlation": calibration.correlation, "calibration_file": str(out),
                   "report": rep["report"]}, sys.stdout, indent=2)
        print()
    else:
        ci = calibration.ci95
        print(f"rung {result.rung}: pressure shift {result.pressure_shift:.4f} ± {ci['pressure_shift']:.4f}, "
              f"material scale {result.material_scale:.4f} ± {ci['material_scale']:.4f} (95%), "
              f"correlation {calibration.correlation:.2f}")
        print(f"normalised residual rms {result.rms_before:.3g} -> {result.rms_after:.3g}"
              + ("" if result.success else f" (solver: {result.message})"))
        misfit = next((part for part in result.message.split("; ") if part.startswith(MISFIT)), None)
        if misfit:
            print(f"warning: {misfit}")
        print(f"calibration: {out}  (use it with --calibration {out})")
        print(f"report (before/after): {rep['report']}")
    return 0
