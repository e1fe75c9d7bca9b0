"""Where and how fe3d fails on a short body: the deformed cross-section at the last converged state.

Ramps the 3D rung until it stops (20 mm, 0 -> 0.35 bar by default), then draws the deformed
section (mirrored half model) at the layer nearest the element the failure message names,
beside the undeformed one, coloured by det F. Answers "is it the lumen collapsing?" with a
picture rather than a guess.

    .venv/bin/python benchmarks/fe3d_failure_picture.py [--length 0.02] [--to 0.35bar] [--mesh-size 1.0]
                                                       [--lumen-fill 0.01] [--name fe3d_failure_20mm]

Writes benchmarks/results/<name>.{png,json,csv}.
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import pressure_option, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.fe3d.measure import best_fit_rotation  # noqa: E402
from softcath_ros.core.models.fe3d import DEFAULT_MESH_SIZE, Fe3dModel  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--length", type=float, default=0.020, help="m")
    ap.add_argument("--to", type=pressure_option("--to"), default=0.35 * PA_PER_BAR, help="top pressure with its unit (default 0.35bar)")
    ap.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE, help="scale of the base mesh in the section (the rung's default)")
    ap.add_argument("--lumen-fill", type=float, default=None)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--name", default="fe3d_failure_20mm")
    args = ap.parse_args(argv)

    design = load_design("implemented_5mm").with_length(args.length)
    model = Fe3dModel(design, mesh_size=args.mesh_size, cache=False, progress=True, threads=args.threads,
                      lumen_fill=args.lumen_fill)
    t0 = time.perf_counter()
    state, ramp = model.sweep(np.array([[args.to]]))
    elapsed = time.perf_counter() - t0
    problem = model.problem   # holds the last converged state (a failed step restores it)
    last = ramp.points[-1].load if ramp.points else 0.0
    match = re.search(r"last converged p = ([0-9.]+) bar", ramp.message or "")
    reached = float(match.group(1)) if match else args.to / PA_PER_BAR
    where = re.search(r"z = ([0-9.]+) mm", ramp.message or "")
    z_fail = float(where.group(1)) * 1e-3 if where else 0.5 * args.length
    z_levels = problem.prism.z_levels
    z = float(z_levels[np.argmin(np.abs(z_levels - z_fail))])

    sec = problem.prism.section
    pts3 = np.column_stack([sec.points, np.full(len(sec.points), z)])
    # Sample a hair inside a solid triangle next to each point (boundary points can fall outside
    # the mesh by round-off) and a hair below the layer boundary (above it for the base).
    solid_tri = [t for t, r in zip(sec.triangles, sec.region) if r in ("silicone", "fibre")]
    inward = np.zeros_like(sec.points)
    for tri in solid_tri:
        inward[tri] = sec.points[tri].mean(axis=0) - sec.points[tri]
    probe = pts3.copy()
    probe[:, :2] += 1e-3 * inward
    probe[:, 2] += -1e-9 if z > 0 else 1e-9
    used = np.any(inward != 0.0, axis=1)
    u = np.zeros_like(pts3)
    jac = np.ones(len(pts3))
    u[used] = np.asarray(problem.u(problem.mesh(*probe[used].T))).reshape(-1, 3)
    jac[used] = np.asarray(problem.J(problem.mesh(*probe[used].T))).ravel()
    deformed = pts3 + u
    # The layer's section in its own (rotated) frame: undo the best-fit rigid rotation of the
    # whole section (the half model mirrored first, so the fit has no spurious twist).
    flip = np.array([-1.0, 1.0, 1.0])
    ref_all = np.vstack([pts3, pts3 * flip]) if problem.half else pts3
    def_all = np.vstack([deformed, deformed * flip]) if problem.half else deformed
    rot = best_fit_rotation(ref_all, def_all)
    local = (deformed - def_all.mean(axis=0)) @ rot + ref_all.mean(axis=0)
    rows = [{"x_mm": float(p[0] * 1e3), "y_mm": float(p[1] * 1e3), "ux_mm": float(d[0] * 1e3),
             "uy_mm": float(d[1] * 1e3), "uz_mm": float(d[2] * 1e3), "det_F": float(j)}
            for p, d, j in zip(sec.points, u, jac)]
    meta = {"length_m": args.length, "target_bar": args.to / PA_PER_BAR, "reached_bar": reached, "last_checkpoint_pa": last,
            "lumen_fill": args.lumen_fill, "mesh_size": args.mesh_size, "layer_h": model.mesh_settings.layer_h,
            "pressure_order": model.pressure_order, "interior_order": model.interior_order, "section_z_m": z,
            "message": ramp.message, "wall_s": elapsed, "ndof": problem.fes.ndof}
    write_results(args.name, meta, rows)
    print(ramp.message or f"reached {args.to / PA_PER_BAR} bar")
    print(draw(args.name, sec, local, jac, z, reached, ramp.message))
    return 0


def draw(name, sec, deformed, jac, z, reached, message) -> str:
    """Undeformed and deformed section (the deformed one in its own rotated frame)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    tri = sec.triangles
    solid = np.array([r in ("silicone", "fibre") for r in sec.region])
    for ax, xy, title in ((axes[0], sec.points, "undeformed"),
                          (axes[1], deformed[:, :2],
                           f"deformed at {reached:.4f} bar (last converged)")):
        for sign in (1.0, -1.0):   # the half model, mirrored
            t = Triangulation(sign * xy[:, 0] * 1e3, xy[:, 1] * 1e3, tri[solid])
            pc = ax.tripcolor(t, jac if title != "undeformed" else np.ones_like(jac), shading="gouraud",
                              cmap="viridis", vmin=0.0, vmax=1.2)
            ax.triplot(t, lw=0.2, color="k")
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
    fig.colorbar(pc, ax=axes, label="det F", shrink=0.8)
    fig.suptitle(f"fe3d section at z = {z * 1e3:.1f} mm: {message[:110]}", fontsize=7)
    return save_figure(fig, name, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
