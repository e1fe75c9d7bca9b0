"""fe3d: the condensed tangent's smallest eigenvalues along a pressure ramp (core/fe3d/stability.py),
to tell a bifurcation or limit point (lam -> 0 at the stop) from a numerical failure (lam clearly > 0).

    .venv/bin/python benchmarks/fe3d_stability.py --length 0.02 --order 1 --from 0.15bar --name fe3d_stability_20mm_p1
    .venv/bin/python benchmarks/fe3d_stability.py --length 0.02 --order 0 --from 0.15bar --name fe3d_stability_20mm_p0
    .venv/bin/python benchmarks/fe3d_stability.py --resume fe3d_stability_20mm_p1 --amplitude 1e-2 --name ...

Per accepted step: R_C = L/theta, the lumen wall's smallest hoop stretch and det F, the outer
surface's smallest principal surface stretch (where, the other one there), its smallest hoop and
axial stretches and det F (core/fe3d/measure.py surface_stretch), the smallest gap, wall time; from
``--from`` on also the k eigenvalues nearest zero over 2 c1, where the first mode is largest
(element, nearest surface), its share within 0.5 mm of the lumen wall, its load share (~1 limit
point, ~0 bifurcation), its extent (the elements holding 90 % of its M: count, reference r, angle
and z ranges) and the outer surface's smallest principal stretch within that angular range.
Writes benchmarks/results/<name>.{json,csv,png} (eigenvalue vs pressure) and keeps the last two
accepted states and the first mode in $SOFTCATH_CACHE/<name>.npz. ``--k 0``: no eigenvalues (the
wall's stretches along the ramp only). ``--census``: from ``--from`` on also the contact pairs of a
fresh search at every accepted step (LumenContact.pair_census: the wall area of the pairs in the
barrier's range and of those whose partner lies more than 2 d_hat behind the primary, through the
silicone, ignored by the energy; where they are and their mean gap), the diagnosis of the pairs'
stall in docs/models/fe3d.md ("Where it fails"):

    .venv/bin/python benchmarks/fe3d_stability.py --length 0.01 --mesh-size coarse --contact-distance 0.02 \
        --order 0 --k 0 --census --from 0.20bar --to 0.30bar --name fe3d_contact_pairs_10mm

``--resume NAME``: continue NAME's ramp from its last converged state plus ``--amplitude`` x the
lumen wall's thickness (0.6 mm) times its first mode scaled to a largest displacement of 1
(an imperfection), or with ``--shifted`` (NewtonSettings(shifted_tangent=True)) and no imperfection.
Ctrl-C stops the ramp and writes what converged.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import fe3d_solver_log, pressure_option, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.fe3d.measure import lumen_wall_stretch, measure, outer_surface_stretch  # noqa: E402
from softcath_ros.core.fe3d.mesh import MeshSettings  # noqa: E402
from softcath_ros.core.fe3d.ramp import default_step_control, run_ramp  # noqa: E402
from softcath_ros.core.fe3d.newton_settings import NewtonSettings  # noqa: E402
from softcath_ros.core.fe3d.solver import Fe3dProblem  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402

COARSE = MeshSettings(section_h=1.0e-3, wall_h=0.7e-3, layer_h=4.5e-3, cap_layers=1)   # test/test_fe3d.py's
WALL_THICKNESS = 0.6e-3   # m: the implemented design's lumen wall, to the outside and to the channel


def _cache(name: str) -> Path:
    root = Path(os.environ.get("SOFTCATH_CACHE", "/tmp/softcath_cache"))
    root.mkdir(parents=True, exist_ok=True)
    return root / f"{name}.npz"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", default="implemented_5mm")
    ap.add_argument("--length", type=float, default=0.02, help="m")
    ap.add_argument("--order", type=int, default=1, help="element pressure's order (0: P2/P0, 1: P2/P1)")
    ap.add_argument("--interior-order", type=int, default=None,
                    help="order of the displacement's element-interior bubbles (condensed; default: none beyond P2)")
    ap.add_argument("--mesh-size", default="1.0", help="scale of the default mesh, or 'coarse' (the tests')")
    ap.add_argument("--lumen-h", type=float, default=None, help="edge length on the lumen wall, m, after --mesh-size "
                    "(default: the mesh's wall_h)")
    ap.add_argument("--contact-distance", type=float, default=0.01, help="d_hat / lumen diameter")
    ap.add_argument("--from", dest="start", type=pressure_option("--from"), default=0.15 * PA_PER_BAR,
                    help="eigenvalues from this pressure on, with its unit (default 0.15bar)")
    ap.add_argument("--to", type=pressure_option("--to"), default=0.35 * PA_PER_BAR, help="with its unit (default 0.35bar)")
    ap.add_argument("--step", type=pressure_option("--step"), default=0.025 * PA_PER_BAR,
                    help="checkpoint spacing, with its unit (default 0.025bar)")
    ap.add_argument("--initial-step", type=pressure_option("--initial-step"), default=None,
                    help="with its unit (default: the ramp's, 0.01bar)")
    ap.add_argument("--k", type=int, default=3, help="eigenvalues per state (0: none)")
    ap.add_argument("--census", action="store_true", help="the contact pairs' census from --from on (see above)")
    ap.add_argument("--resume", default=None, help="continue this run's last converged state (see above)")
    ap.add_argument("--amplitude", type=float, default=0.0, help="imperfection / wall thickness (with --resume)")
    ap.add_argument("--shifted", action="store_true", help="NewtonSettings(shifted_tangent=True)")
    ap.add_argument("--max-searches", type=int, default=None, help="contact pair searches per solve (default: LumenContact's)")
    ap.add_argument("--settle-force", type=float, default=None,
                    help="pairs settled below this fraction of the pressure load (default: LumenContact's)")
    ap.add_argument("--debug", action="store_true", help="the solver's per-iteration log on stderr")
    ap.add_argument("--name", required=True)
    args = ap.parse_args(argv)

    design = load_design(args.design).with_length(args.length)
    mesh = COARSE if args.mesh_size == "coarse" else MeshSettings().scaled(float(args.mesh_size))
    if args.lumen_h is not None:
        mesh = dataclasses.replace(mesh, lumen_h=args.lumen_h)
    try:
        pb = Fe3dProblem(design, mesh, NewtonSettings(threads=1, shifted_tangent=args.shifted), None,
                         contact_distance=args.contact_distance, pressure_order=args.order,
                         interior_order=args.interior_order)
    except ValueError as exc:   # the problem's own check of its options, as one line
        ap.error(str(exc))
    if args.debug:
        fe3d_solver_log()
    if pb.contact is not None:
        if args.max_searches is not None:
            pb.contact.max_searches = args.max_searches
        if args.settle_force is not None:
            pb.contact.settle_force = args.settle_force
    start = None
    meta = {"design": args.design, "length_m": args.length, "pressure_order": args.order,
            "interior_order": args.interior_order,
            "mesh_size": args.mesh_size, "lumen_h_m": args.lumen_h, "contact_distance": args.contact_distance, "ndof": pb.fes.ndof,
            "threads": 1, "shifted_tangent": args.shifted, "k": args.k, "census": args.census,
            "max_searches": pb.contact and pb.contact.max_searches, "settle_force": pb.contact and pb.contact.settle_force,
            "command": "benchmarks/fe3d_stability.py " + " ".join(sys.argv[1:] if argv is None else argv)}
    if args.resume:
        try:
            saved = np.load(_cache(args.resume))
            mode = saved["mode"] / saved["mode_peak"]
        except (OSError, KeyError, ValueError) as exc:
            ap.error(f"--resume {args.resume}: no saved state in {_cache(args.resume)} ({exc})")
        if saved["state"].shape != (pb.fes.ndof,):
            ap.error(f"--resume {args.resume}: its state has {saved['state'].size} unknowns, this problem {pb.fes.ndof}: "
                     "give the same --length, --order, --interior-order, --mesh-size and --lumen-h as that run")
        state = saved["state"] + args.amplitude * WALL_THICKNESS * mode
        start = (float(saved["load"]), state)
        meta.update(resumed_from=args.resume, resumed_load_bar=float(saved["load"]) / PA_PER_BAR,
                    imperfection_m=args.amplitude * WALL_THICKNESS, amplitude_of_wall=args.amplitude)
        print(f"resume at {start[0] / PA_PER_BAR:.4f} bar, imperfection {args.amplitude * WALL_THICKNESS * 1e6:.2f} um",
              flush=True)
    print("ndof", pb.fes.ndof, flush=True)
    rows: list[dict] = []
    kept: list[tuple[float, np.ndarray]] = []
    t0 = time.perf_counter()
    shown = [0.0]   # run_ramp reports increments from 0

    def record():
        load = shown[0]
        m = measure(pb)
        w = lumen_wall_stretch(pb)
        o = outer_surface_stretch(pb, samples=True)
        th = m["bending_angle_rad"]
        at = o["min_principal_at_m"] * 1e3
        row = {"pressure_bar": load / PA_PER_BAR, "R_C_mm": args.length / th * 1e3 if th > 0 else float("inf"),
               "lumen_min_gap_um": m.get("lumen_min_gap_m", float("nan")) * 1e6,
               "min_hoop_stretch": w["min_hoop_stretch"], "min_det_f_wall": w["min_det_f"],
               "min_principal_stretch": w["min_principal_stretch"], "other_principal_there": w["other_principal_there"],
               "normal_stretch_there": w["normal_stretch_there"],
               **{f"min_principal_at_{k}_mm": float(v) * 1e3 for k, v in zip("xyz", w["min_principal_at_m"])},
               "outer_min_principal_stretch": o["min_principal_stretch"],
               "outer_other_principal_there": o["other_principal_there"],
               "outer_min_principal_at_x_mm": at[0], "outer_min_principal_at_y_mm": at[1],
               "outer_min_principal_at_z_mm": at[2],
               "outer_min_principal_at_deg": float(np.degrees(np.arctan2(at[1], at[0]))),
               "outer_min_hoop_stretch": o["min_hoop_stretch"], "outer_axial_stretch_there": o["axial_stretch_there"],
               "outer_min_axial_stretch": float(o["axial_stretch"].min()), "outer_min_det_f": o["min_det_f"]}
        state = pb.get_state()
        if args.census and pb.contact is not None and load >= args.start - 1e-6:
            for kind, v in pb.contact.pair_census().items():
                row[f"{kind}_area_mm2"] = v["area_m2"] * 1e6
                for k in ("x", "y", "z", "gap"):   # absent when no pair of the kind
                    if k in v:
                        row[f"{kind}_{k}_{'um' if k == 'gap' else 'mm'}"] = v[k] * (1e6 if k == "gap" else 1e3)
        if args.k > 0 and load >= args.start - 1e-6:
            ts = time.perf_counter()
            s = pb.stability(args.k)
            pb.set_state(state)
            for j, lam in enumerate(s.eigenvalues):
                row[f"lambda{j + 1}_over_mu"] = float(lam)
            e = s.extent
            # the outer surface's samples in the first mode's angular range (where 90 % of its M is)
            ang = np.degrees(np.arctan2(o["points_m"][:, 1], o["points_m"][:, 0]))
            inside = (ang >= e["angle_deg"][0]) & (ang <= e["angle_deg"][1])
            lam_there = o["principal_stretches"][inside, 0] if inside.any() else np.array([np.nan])
            row.update(mode_where=s.where, mode_x_mm=s.at_m[0] * 1e3, mode_y_mm=s.at_m[1] * 1e3,
                       mode_z_mm=s.at_m[2] * 1e3, mode_lumen_share=s.lumen_share, mode_load_share=s.load_share,
                       mode_elements_90=e["elements"], mode_r_min_mm=e["r_m"][0] * 1e3, mode_r_max_mm=e["r_m"][1] * 1e3,
                       mode_deg_min=e["angle_deg"][0], mode_deg_max=e["angle_deg"][1],
                       mode_z_min_mm=e["z_m"][0] * 1e3, mode_z_max_mm=e["z_m"][1] * 1e3,
                       outer_min_principal_in_mode=float(np.min(lam_there)),
                       stability_s=time.perf_counter() - ts)
            np.savez(_cache(args.name), state=state, load=load, mode=s.modes[0], mode_peak=s.max_displacement_m[0],
                     previous_state=kept[-1][1] if kept else state,
                     previous_load=kept[-1][0] if kept else load)
        row["wall_time_s"] = time.perf_counter() - t0
        rows.append(row)
        kept[:] = (kept + [(load, state)])[-2:]
        print(" ".join(f"{k}={v:.5g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)

    class Progress:
        def update(self, n):
            shown[0] += n

        def set_postfix_str(self, s):
            record()

    cps = np.round(np.arange(args.step, args.to + 1e-4, args.step) / PA_PER_BAR, 6) * PA_PER_BAR
    control = default_step_control() if args.initial_step is None else \
        default_step_control(step=args.initial_step)
    r = run_ramp(pb, [1.0], cps, control, progress=Progress(), start=start)
    meta.update(converged=r.converged, message=r.message, stop_reason=r.stop_reason, steps=r.steps,
                cuts=r.cuts, newton_iterations=r.iterations, total_s=time.perf_counter() - t0,
                min_gap_every_step_um=min(g for _, g in r.min_gap_m) * 1e6 if r.min_gap_m else None,
                last_converged_bar=(shown[0] or (start[0] if start else 0.0)) / PA_PER_BAR)
    print(r.converged, r.message, f"{meta['total_s']:.0f} s", flush=True)
    if rows:
        keys = list(dict.fromkeys(k for row in rows for k in row))
        rows = [{k: row.get(k, "") for k in keys} for row in rows]
        write_results(args.name, meta, rows)
        plot(rows, args, meta)
    return 0 if r.converged else 1


def plot(rows, args, meta):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    have = [r for r in rows if r.get("lambda1_over_mu", "") != ""]
    if not have:
        return
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    p = [r["pressure_bar"] for r in have]
    for j in range(args.k):
        ax.plot(p, [r[f"lambda{j + 1}_over_mu"] for r in have], "o-", ms=3, label=f"lambda{j + 1} / 2c1")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("pressure (bar)")
    ax.set_ylabel("eigenvalue of K v = lam M v over 2 c1 (M: H1 seminorm)")
    ax.set_title(f"fe3d {args.length * 1e3:.0f} mm, P2/P{args.order}: "
                 f"last converged {meta['last_converged_bar']:.4f} bar", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, args.name)


if __name__ == "__main__":
    sys.exit(main())
