"""`softcath calibrate FILE.mcap --design D`: fit pressure shift and material scale, write a calibrated design."""
from __future__ import annotations

import sys
from pathlib import Path

import yaml

from ..core import json_output


def register(sub) -> None:
    from ..core.models import available_models

    p = sub.add_parser("calibrate", help="fit a model to a bench recording and write a calibrated design")
    p.add_argument("file", help="the bench recording (.mcap or its bag directory)")
    p.add_argument("--design", default=None, help="design to calibrate (default: the one attached to the recording)")
    p.add_argument("--model", default="closed_form", help=f"rung to fit: {', '.join(available_models())}")
    p.add_argument("--output", default=None,
                   help="calibrated design file (default: <design>_calibrated.yaml beside the recording)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench.analysis import rows_from_recording
    from ..bench.calibration import calibrate, calibrated_design_dict
    from ..bench.report import recording_design, write_report
    from ..core.design import load_design
    from ..core.errors import SoftcathError
    from ..recording.reader import recording_file

    path = recording_file(args.file)
    design = load_design(args.design) if args.design else recording_design(path)
    if design is None:
        raise SoftcathError(f"{path} has no design attached; pass --design")
    result = calibrate(rows_from_recording(path), design, args.model)
    out = Path(args.output) if args.output else path.parent / f"{design.name}_calibrated.yaml"
    out.write_text(yaml.safe_dump(calibrated_design_dict(design, result, path.name), sort_keys=False))
    sidecar = out.with_suffix(".calibration.yaml")
    cal = {**result.to_json(), "recording": str(path), "design": design.name, "calibrated_design": str(out)}
    sidecar.write_text(yaml.safe_dump(cal, sort_keys=False))
    rep = write_report(path, design, [args.model], cal, out_dir=path.parent)
    if args.json:
        json_output.dump({**cal, "report": rep["report"]}, sys.stdout, indent=2)
        print()
    else:
        print(f"rung {result.rung}: pressure shift {result.pressure_shift:.4f} ± {result.ci95['pressure_shift']:.4f}, "
              f"material scale {result.material_scale:.4f} ± {result.ci95['material_scale']:.4f} (95%), "
              f"correlation {result.correlation:.2f}")
        print(f"normalised residual rms {result.rms_before:.3g} -> {result.rms_after:.3g}"
              + ("" if result.success else f" (solver: {result.message})"))
        print(f"calibrated design: {out}")
        print(f"calibration:       {sidecar}")
        print(f"report (before/after): {rep['report']}")
    return 0
