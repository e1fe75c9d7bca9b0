"""fe3d lumen contact: what the contact pairs do while the lumen closes (the diagnosis of the
stall in docs/models/fe3d.md, "Where it fails").

Ramps a body (default: the coarse 10 mm body of test/test_fe3d.py) with lumen contact and,
at every accepted step from ``--from`` bar on, searches the pairs afresh and reports
(LumenContact.pair_census) the wall area of the pairs in the barrier's range and of those
whose partner lies more than 2 d_hat behind the primary (through the silicone, ignored by the
energy), with where they are, and the wall's smallest gap; and at every accepted step the lumen
wall's smallest surface stretches (core/fe3d/measure.py ``lumen_wall_stretch``: hoop and principal,
with where), the creasing diagnostic (a neo-Hookean surface creases at about 0.65).

    .venv/bin/python benchmarks/fe3d_contact_pairs.py --to 0.30 --name fe3d_contact_pairs_10mm
    .venv/bin/python benchmarks/fe3d_contact_pairs.py --length 0.02 --mesh-size 1.0 --contact-distance 0.01 \
        --step 0.025 --to 0.35 --no-census --name fe3d_wall_stretch_20mm   # fe3d_sweep.py's path
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.fe3d.measure import lumen_wall_stretch  # noqa: E402
from softcath_ros.core.fe3d.mesh import MeshSettings  # noqa: E402
from softcath_ros.core.fe3d.ramp import run_ramp  # noqa: E402
from softcath_ros.core.models.fe3d import Fe3dModel  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402

COARSE = MeshSettings(section_h=1.0e-3, wall_h=0.7e-3, layer_h=4.5e-3, cap_layers=1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, default=0.010, help="m")
    ap.add_argument("--to", type=float, default=0.30, help="bar")
    ap.add_argument("--from", dest="start", type=float, default=0.20, help="bar: census from here on")
    ap.add_argument("--mesh-size", type=float, default=None, help="the default mesh scaled (default: the test's coarse mesh)")
    ap.add_argument("--lumen-h", type=float, default=None, help="edge length on the lumen wall, m (default: wall_h)")
    ap.add_argument("--contact-distance", type=float, default=0.02, help="of the lumen diameter")
    ap.add_argument("--step", type=float, default=None,
                    help="checkpoint spacing, bar (fe3d_sweep.py's ramp path; default: one checkpoint at --to)")
    ap.add_argument("--no-census", action="store_true", help="the wall's stretches only, no pair census")
    ap.add_argument("--name", default="fe3d_contact_pairs_10mm")
    args = ap.parse_args(argv)
    design = load_design("implemented_5mm").with_length(args.length)
    mesh = COARSE if args.mesh_size is None else MeshSettings().scaled(args.mesh_size)
    if args.lumen_h is not None:
        mesh = dataclasses.replace(mesh, lumen_h=args.lumen_h)
    model = Fe3dModel(design, mesh=mesh, cache=False, threads=1, contact_distance=args.contact_distance)
    pb = model.problem
    rows = []
    t0 = time.perf_counter()

    class Census:   # run_ramp calls this after every accepted step, with the problem at that state
        shown = 0.0

        def update(self, n):
            self.shown += n

        def set_postfix_str(self, s):
            p = self.shown / PA_PER_BAR
            row = {"pressure_bar": p, "newton": s, "time_s": time.perf_counter() - t0,
                   "min_gap_um": pb.last_min_gap * 1e6 if hasattr(pb, "last_min_gap") else None}
            ws = lumen_wall_stretch(pb)
            row["min_hoop_stretch"] = ws["min_hoop_stretch"]
            row["min_principal_stretch"] = ws["min_principal_stretch"]
            row["other_principal_stretch"] = ws["other_principal_there"]
            row["normal_stretch"] = ws["normal_stretch_there"]
            row["wall_min_det_f"] = ws["min_det_f"]
            for k, v in zip("xyz", ws["min_principal_at_m"]):
                row[f"stretch_{k}_mm"] = float(v) * 1e3
            if p >= args.start - 1e-9 and not args.no_census:
                for kind, v in pb.contact.pair_census().items():
                    row[f"{kind}_area_mm2"] = v["area_m2"] * 1e6
                    for k in ("x", "y", "z", "gap"):   # None when no pair of the kind
                        row[f"{kind}_{k}_{'um' if k == 'gap' else 'mm'}"] = \
                            v[k] * (1e6 if k == "gap" else 1e3) if k in v else None
            rows.append(row)
            print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)

    if args.step:
        checkpoints = np.round(np.arange(args.step, args.to + 1e-9, args.step), 6) * PA_PER_BAR
    else:
        checkpoints = [args.to * PA_PER_BAR]
    ramp = run_ramp(pb, [1.0], checkpoints, progress=Census())
    keys = list(dict.fromkeys(k for r in rows for k in r))   # every column, rows before --from lack the census
    rows = [{k: r.get(k) for k in keys} for r in rows]
    meta = {"length_m": args.length, "mesh": "test coarse" if args.mesh_size is None else args.mesh_size,
            "lumen_h": args.lumen_h,
            "checkpoint_step_bar": args.step, "ndof": pb.fes.ndof, "d_hat_m": pb.contact.d_hat, "threads": 1, "converged": ramp.converged,
            "message": ramp.message, "stop_reason": ramp.stop_reason, "steps": ramp.steps, "cuts": ramp.cuts,
            "min_gap_every_step_um": min(g for _, g in ramp.min_gap_m) * 1e6 if ramp.min_gap_m else None,
            "total_s": time.perf_counter() - t0, "solver_version": model.solver_version,
            "note": "wall clock on a 2-core machine shared with other jobs (load average in meta)"}
    path = write_results(args.name, meta, rows)
    print(f"{args.name}: converged={ramp.converged} {ramp.message} ({meta['total_s']:.0f} s); wrote {path}.json/.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
