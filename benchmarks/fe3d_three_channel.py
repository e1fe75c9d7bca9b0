"""fe3d on the 3-channel design (three_channel_5mm, 40 mm): one direction's pressure sweep, timed,
with a profile of where the time goes, on the full body or on the half body about the direction's
mirror plane (``half=True``: core/fe3d/mesh.py ``mirror_plane``).

    .venv/bin/python benchmarks/fe3d_three_channel.py --to 0.1bar --full --name fe3d_3ch_profile_full
    .venv/bin/python benchmarks/fe3d_three_channel.py --to 0.1bar --full --mirror-mesh --name fe3d_3ch_full_mirror
    .venv/bin/python benchmarks/fe3d_three_channel.py --to 0.1bar --name fe3d_3ch_profile_half
    .venv/bin/python benchmarks/fe3d_three_channel.py --to 0.35bar --name fe3d_three_channel_default    # the timed sweep
    .venv/bin/python benchmarks/fe3d_three_channel.py --to 0.35bar --direction pair --name fe3d_three_channel_pair
    .venv/bin/python benchmarks/fe3d_three_channel.py --to 0.35bar --max-step 0.05bar --name fe3d_three_channel_step0.05
    .venv/bin/python benchmarks/fe3d_three_channel.py --compare fe3d_3ch_profile_full fe3d_3ch_profile_half

Writes benchmarks/results/<name>.{json,csv,png}: per checkpoint R_C = L / theta, bending angle and
direction, tip position, lumen's smallest gap, Newton iterations, wall time; the meta block holds
the DOF count, total time, steps, cuts, Newton iterations and the profile: seconds spent in
assembling the tangent, factorising it, the residual, the contact pair search (``Update``), the
geometric crossing check of the lumen wall, the det F check, the tangent predictor and the
measurement. Ctrl-C stops the sweep and writes what converged. Wall clock on a shared machine
(load average in meta); one fe3d job at a time.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import RESULTS, pressure_option, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.fe3d.ramp import default_step_control  # noqa: E402
from softcath_ros.core.models.fe3d import DEFAULT_MESH_SIZE  # noqa: E402
from softcath_ros.experimental.fe3d_variants import Fe3dVariantModel  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402

DIRECTIONS = {"one": (1.0, 0.0, 0.0), "pair": (1.0, 1.0, 0.0), "pair21": (1.0, 0.5, 0.0)}


class Profile:
    """Wall time and calls per instrumented method (wrapped on the class, restored afterwards)."""

    def __init__(self):
        self.seconds = defaultdict(float)
        self.calls = defaultdict(int)

    @contextlib.contextmanager
    def wrap(self, targets):
        saved = []
        for label, owner, attr in targets:
            fn = getattr(owner, attr)
            saved.append((owner, attr, fn))
            setattr(owner, attr, self._timed(label, fn))
        try:
            yield self
        finally:
            for owner, attr, fn in saved:
                setattr(owner, attr, fn)

    def _timed(self, label, fn):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[label] += time.perf_counter() - t0
                self.calls[label] += 1
        return timed

    def table(self) -> dict:
        return {k: {"s": round(self.seconds[k], 3), "calls": self.calls[k]} for k in sorted(self.seconds)}


def profile_targets(problem):
    """(label, owner, attribute) of what one ramp spends its time in. The factorisation is split
    into assembly and Cholesky by wrapping the problem's BilinearForm and matrix calls."""
    from softcath_ros.core.fe3d import contact, measure, solver

    targets = [("newton (total)", solver.Fe3dProblem, "newton"),
               ("factorise: assemble + Cholesky", solver.Fe3dProblem, "_factorize"),
               ("det F check", solver.Fe3dProblem, "min_jacobian_ok"),
               ("tangent predictor", solver.Fe3dProblem, "tangent"),
               ("measure", measure, "measure"),
               ("material range check", solver.Fe3dProblem, "max_isochoric_i1")]
    if problem.contact is not None:
        targets += [("contact search (Update)", contact.LumenContact, "update"),
                    ("wall crossing check", contact.LumenContact, "min_gap"),
                    ("contact settle check", solver.Fe3dProblem, "_contact_pairs_settled")]
    return targets


def run(args) -> int:
    design = load_design("three_channel_5mm").with_length(args.length)
    direction = DIRECTIONS[args.direction]
    checkpoints = np.round(np.arange(args.step, args.to + 1e-4, args.step) / PA_PER_BAR, 6) * PA_PER_BAR
    contact = {} if args.contact_distance is None else {
        "contact_distance": None if args.contact_distance.lower() == "none" else float(args.contact_distance)}
    control = default_step_control()
    if args.max_step is not None:
        control = dataclasses.replace(control, max_step=args.max_step)
    model = Fe3dVariantModel(design, mesh_size=args.mesh_size, half=not args.full, cache=False, progress=True,
                      threads=args.threads, mirror_mesh=args.full and args.mirror_mesh, step_control=control,
                      **contact)
    prof = Profile()
    t0 = time.perf_counter()
    problem = model.problem_for(np.asarray(direction))
    t_setup = time.perf_counter() - t0
    # ramp.py and fe3d.py import measure by name: wrap it where it is called
    from softcath_ros.core.fe3d import ramp as ramp_module

    targets = profile_targets(problem) + [("measure", ramp_module, "measure")]
    targets = [t for t in targets if not (t[0] == "measure" and t[1].__name__.endswith("fe3d.measure"))]
    with prof.wrap(targets):
        state, ramp = model.sweep(np.outer(checkpoints, direction))
    total = time.perf_counter() - t0
    gaps = {pt.load: pt.measured.get("lumen_min_gap_m") for pt in (ramp.points if ramp else [])}
    rows = []
    for i, p in enumerate(checkpoints):
        ok = bool(state.converged[i])
        k = state.curvature[i]
        rows.append({
            "pressure_bar": float(p) / PA_PER_BAR, "converged": ok,
            "radius_l_over_theta_mm": float(state.radius_l_over_theta[i]) * 1e3 if ok else None,
            "bending_angle_deg": float(np.degrees(state.tip.angle[i])) if ok else None,
            "bending_direction_deg": float(np.degrees(math.atan2(k[1], k[0]))) if ok else None,
            "tip_x_mm": float(state.tip.position[i, 0]) * 1e3 if ok else None,
            "tip_y_mm": float(state.tip.position[i, 1]) * 1e3 if ok else None,
            "tip_z_mm": float(state.tip.position[i, 2]) * 1e3 if ok else None,
            "channel_volume_mm3": [float(v) * 1e9 for v in state.diagnostics.channel_volume[i]] if ok else None,
            "lumen_min_gap_um": (gaps[float(p)] * 1e6 if ok and gaps.get(float(p)) is not None else None),
            "newton_iterations": int(state.diagnostics.newton_iterations[i]) if ok else None,
            "time_s": float(state.diagnostics.time_s[i]) if ok else None})
    meta = {"design": design.name, "length_m": args.length, "direction": list(direction),
            "mesh_size": args.mesh_size, "mesh": dataclasses.asdict(model.mesh_settings),
            "pressure_order": model.pressure_order, "interior_order": model.interior_order,
            "ndof": problem.fes.ndof, "half_model": problem.half, "mirror_mesh": model.mirror_mesh,
            "mirror_rotation_deg": math.degrees(getattr(problem, "rotation", 0.0)),
            "threads": args.threads, "contact_distance": model.contact_distance,
            "step_settings": dataclasses.asdict(model.step_control),
            "setup_s": t_setup, "total_s": total, "ramp_wall_s": ramp.wall_time if ramp else None,
            "converged": bool(ramp.converged) if ramp else True, "message": ramp.message if ramp else "",
            "stop_reason": ramp.stop_reason if ramp else "",
            "steps": ramp.steps if ramp else 0, "cuts": ramp.cuts if ramp else 0,
            "newton_iterations_total": ramp.iterations if ramp else 0,
            "profile_s": prof.table(),
            "command": "python benchmarks/fe3d_three_channel.py " + " ".join(sys.argv[1:]),
            "note": "wall clock on a 2-core machine shared with other jobs (load average in meta)"}
    path = write_results(args.name, meta, rows)
    print(f"{args.name}: {total:.1f} s, {problem.fes.ndof} DOF, half={problem.half}, converged={meta['converged']} "
          f"{meta['message']}")
    print(json.dumps(meta["profile_s"], indent=1))
    for r in rows:
        print(r)
    print(f"wrote {path}.json/.csv, {plot(args.name)}")
    return 0


def compare(full: str, half: str) -> None:
    """Relative differences half vs full in R_C and tip angle per common converged pressure."""
    a = json.loads((RESULTS / f"{full}.json").read_text())["results"]
    b = {r["pressure_bar"]: r for r in json.loads((RESULTS / f"{half}.json").read_text())["results"]}
    for r in a:
        h = b.get(r["pressure_bar"])
        if r["converged"] and h and h["converged"]:
            print(f"{r['pressure_bar']:.3f} bar: R_C {r['radius_l_over_theta_mm']:.4f} / "
                  f"{h['radius_l_over_theta_mm']:.4f} mm ({h['radius_l_over_theta_mm'] / r['radius_l_over_theta_mm'] - 1:+.3%}), "
                  f"angle {r['bending_angle_deg']:.4f} / {h['bending_angle_deg']:.4f} deg "
                  f"({h['bending_angle_deg'] / r['bending_angle_deg'] - 1:+.3%})")


def plot(name: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    doc = json.loads((RESULTS / f"{name}.json").read_text())
    meta = doc["meta"]
    rows = [r for r in doc["results"] if r["converged"]]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot([r["pressure_bar"] for r in rows], [r["radius_l_over_theta_mm"] for r in rows], "o-")
    ax1.set_yscale("log")
    ax1.set_xlabel("pressure [bar]")
    ax1.set_ylabel("R_C = L / theta [mm]")
    ax2.plot([r["pressure_bar"] for r in rows], [r["time_s"] for r in rows], "o-")
    ax2.set_xlabel("pressure [bar]")
    ax2.set_ylabel("ramp wall time [s]")
    status = "converged" if meta["converged"] else meta["message"][:70]
    fig.suptitle(f"{name}: 3 channels, direction {meta['direction']}, {'half' if meta['half_model'] else 'full'} "
                 f"model, {meta['ndof']} DOF, {meta['total_s']:.0f} s (load {meta['load_average_before'][0]:.1f}); {status}",
                 fontsize=8)
    fig.tight_layout()
    return save_figure(fig, name)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--direction", choices=sorted(DIRECTIONS), default="one")
    ap.add_argument("--length", type=float, default=0.040, help="m")
    ap.add_argument("--to", type=pressure_option("--to"), default=0.35 * PA_PER_BAR, help="with its unit (default 0.35bar)")
    ap.add_argument("--step", type=pressure_option("--step"), default=0.05 * PA_PER_BAR,
                    help="checkpoint spacing, with its unit (default 0.05bar)")
    ap.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE, help="scale of the base mesh in the section (the rung's default)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--max-step", type=pressure_option("--max-step"), default=None,
                    help="largest load step, with its unit (default: the rung's)")
    ap.add_argument("--full", action="store_true", help="the full body (default: the half body when the "
                                                         "direction lies on a mirror plane)")
    ap.add_argument("--mirror-mesh", action="store_true", help="with --full: the full body meshed as the half "
                                                                "section and its mirror image")
    ap.add_argument("--contact-distance", default=None, help="fraction of the lumen diameter; 'none': off")
    ap.add_argument("--name", default="fe3d_three_channel")
    ap.add_argument("--compare", nargs=2, metavar=("FULL", "HALF"), help="print half vs full of two results")
    ap.add_argument("--plot-only", action="store_true")
    args = ap.parse_args(argv)
    if args.compare:
        compare(*args.compare)
        return 0
    if args.plot_only:
        print(plot(args.name))
        return 0
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
