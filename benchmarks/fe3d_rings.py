"""Discrete rings against the homogenised hoop membrane in the 3D rung, on the same axial mesh.

The reference FE models the reinforcement as rings of square 0.15 mm thread every 0.8 mm;
fe3d uses a hoop membrane of the same average stiffness (E A / pitch) by default. Resolving
every ring needs layers of the thread's width, so this runs shorter bodies than 40 mm and
compares, at the same axial resolution, membrane (layers of ``--layer``) and rings (one layer
per band, gaps split to ``--layer``):

    .venv/bin/python benchmarks/fe3d_rings.py                       # 8 mm, coarse section
    .venv/bin/python benchmarks/fe3d_rings.py --length 0.016 --to 0.20bar --name fe3d_rings_16mm

Writes benchmarks/results/<name>.{json,csv,png}; results are cached (the project cache, kind fe3d).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import pressure_option, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.fe3d.mesh import MeshSettings  # noqa: E402
from softcath_ros.experimental.fe3d_variants import Fe3dVariantModel  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--length", type=float, default=0.008, help="m")
    ap.add_argument("--to", type=pressure_option("--to"), default=0.15 * PA_PER_BAR, help="top pressure with its unit (default 0.15bar)")
    ap.add_argument("--step", type=pressure_option("--step"), default=0.05 * PA_PER_BAR, help="between reported pressures, with its unit (default 0.05bar)")
    ap.add_argument("--mesh-size", type=float, default=1.4, help="scale of the default section mesh")
    ap.add_argument("--layer", type=float, default=0.4e-3, help="largest layer height, m")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--name", default="fe3d_rings_8mm")
    args = ap.parse_args(argv)

    design = load_design("implemented_5mm").with_length(args.length)
    pressures = np.round(np.arange(args.step, args.to + 1e-4, args.step) / PA_PER_BAR, 6)   # bar
    mesh = dataclasses.replace(MeshSettings().scaled(args.mesh_size), layer_h=args.layer)
    out = {}
    for model_name in ("membrane", "rings"):
        model = Fe3dVariantModel(design, mesh=mesh, reinforcement=model_name, progress=True, threads=args.threads)
        t0 = time.perf_counter()
        state = model.evaluate(pressures[:, None] * PA_PER_BAR)
        out[model_name] = (state, model.problem.fes.ndof, time.perf_counter() - t0)
        print(f"{model_name}: {out[model_name][1]} DOF, {out[model_name][2]:.0f} s {state.message}", flush=True)
    rows = []
    for i, p in enumerate(pressures):
        rc = {k: (float(v[0].radius_l_over_theta[i]) if v[0].converged[i] else None) for k, v in out.items()}
        rows.append({"pressure_bar": float(p),
                     "membrane_radius_mm": rc["membrane"] * 1e3 if rc["membrane"] else None,
                     "rings_radius_mm": rc["rings"] * 1e3 if rc["rings"] else None,
                     "rings_vs_membrane": (rc["rings"] / rc["membrane"] - 1.0) if all(rc.values()) else None})
    meta = {"length_m": args.length, "mesh_size": args.mesh_size, "layer_h_m": args.layer,
            "ndof": {k: v[1] for k, v in out.items()}, "wall_s": {k: v[2] for k, v in out.items()},
            "messages": {k: v[0].message for k, v in out.items()},
            "note": "rings: hoop stiffness E A / thread width on the bands under the threads; membrane: E A / pitch "
                    "everywhere; same axial layers"}
    write_results(args.name, meta, rows)
    for r in rows:
        print(r)
    print(plot(args.name, rows, args.length))
    return 0


def plot(name: str, rows: list[dict], length: float) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for key, label in (("membrane_radius_mm", "hoop membrane (E A / pitch)"), ("rings_radius_mm", "discrete rings")):
        pts = [(r["pressure_bar"], r[key]) for r in rows if r[key]]
        if pts:
            ax.plot(*zip(*pts), "o-", label=label)
    ax.set_yscale("log")
    ax.set_xlabel("pressure [bar]")
    ax.set_ylabel("R_C = L / theta [mm]")
    ax.set_title(f"fe3d, {length * 1e3:.0f} mm body: rings vs membrane", fontsize=9)
    ax.legend()
    fig.tight_layout()
    return save_figure(fig, name)


if __name__ == "__main__":
    sys.exit(main())
