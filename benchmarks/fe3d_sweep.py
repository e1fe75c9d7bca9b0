"""fe3d benchmark and validation runs: pressure sweeps through the 3D rung, timed, with peak memory.

    .venv/bin/python benchmarks/fe3d_sweep.py                      # 0 -> 0.20 bar, 40 mm, the rung's defaults
    .venv/bin/python benchmarks/fe3d_sweep.py --length 0.02 --to 0.35bar --name fe3d_20mm
    .venv/bin/python benchmarks/fe3d_sweep.py --mesh-size 1.2 --name fe3d_mesh_1.2   # finer in the section
    .venv/bin/python benchmarks/fe3d_sweep.py --fixed-steps 0.01bar --name fe3d_fixed_steps
    .venv/bin/python benchmarks/fe3d_sweep.py --length 0.02 --to 0.35bar --contact-distance 0.03 --name fe3d_contact_0.03
    .venv/bin/python benchmarks/fe3d_sweep.py --length 0.02 --to 0.35bar --no-section --name fe3d_timing_20mm   # the timed case only
    .venv/bin/python benchmarks/fe3d_sweep.py --design docs/examples/sectors.yaml --channel 0 --to 0.35bar \
        --name fe3d_sweep_sectors_ch0   # one channel of a multi-channel design: the half body on its mirror plane
    .venv/bin/python benchmarks/fe3d_sweep.py --design three_sector_5mm --channel 1 2 \
        --length 0.02 --to 0.35bar --threads 1 --name fe3d_sector_pair_20mm   # an equal pair (docs/validation.md)
    .venv/bin/python benchmarks/fe3d_sweep.py --length 0.02 --to 0.35bar --order 0 --interior-order none \
        --contact-distance 0.01 --mesh-size 1.0 --layer-h scaled --name fe3d_p2p0   # the former default (fe3d-7)

Flags left out take the rung's defaults (core/models/fe3d.py: mesh 1.4, 1.2 mm layers, P2 + bubbles / P1,
barrier 0.02 D since 2026-12-04; result files before that date record their element and mesh in meta).

Writes benchmarks/results/<name>.{json,csv}: per checkpoint pressure, bending angle,
R_C = L/theta (and the section rung's at the same pressure with its relative difference:
section vs 3D), curvature, stretch, channel volume/area, Newton iterations, wall time; the
meta block holds the total time, peak RSS, DOF count, convergence and the failure message.
Ctrl-C (or SIGTERM) stops the sweep and writes what converged (meta "interrupted"). Times are wall
clock (total_s) and the process's CPU time (cpu_s) on a shared machine.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import (fe3d_solver_log, pressure_option, save_figure, signals_held, stop_on_signals,  # noqa: E402
                     write_results)

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.fe3d.ramp import default_step_control  # noqa: E402
from softcath_ros.core.fe3d.newton_settings import NewtonSettings  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402
from softcath_ros.core.errors import DesignError, ModelError  # noqa: E402
from softcath_ros.core.models.fe3d import (DEFAULT_CONTACT_DISTANCE, DEFAULT_CONTACT_INTORDER,  # noqa: E402
                                            DEFAULT_INTERIOR_ORDER, DEFAULT_LAYER_H, DEFAULT_MESH_SIZE, DEFAULT_PRESSURE_ORDER, Fe3dModel,
                                            mesh_settings)
from softcath_ros.core.prediction import angle_per_length  # noqa: E402
from softcath_ros.core.units import PA_PER_BAR  # noqa: E402

PUBLISHED_40MM = {15000.0: 31.13e-3, 20000.0: 16.86e-3}   # docs/actuator.md: R_C of the published FE


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", default="implemented_5mm")
    ap.add_argument("--length", type=float, default=0.040, help="m")
    ap.add_argument("--to", type=pressure_option("--to"), default=0.20 * PA_PER_BAR, help="with its unit (default 0.20bar)")
    ap.add_argument("--step", type=pressure_option("--step"), default=0.025 * PA_PER_BAR,
                    help="checkpoint spacing, with its unit (default 0.025bar)")
    ap.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE,
                    help=f"scale of the base mesh in the section (smaller = finer; default {DEFAULT_MESH_SIZE})")
    ap.add_argument("--fixed-steps", type=pressure_option("--fixed-steps"), default=None,
                    help="step control off: plain load steps of this size (with its unit), no cutting, no predictor")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--contact-distance", default=None,
                    help="lumen contact's barrier distance as a fraction of the lumen diameter "
                         f"(default: the rung's, {DEFAULT_CONTACT_DISTANCE}); 'none' switches contact off")
    ap.add_argument("--energy-tol", type=float, default=None,
                    help="Newton's |du.r| tolerance relative to c1 x volume (default: the solver's, 1e-9)")
    ap.add_argument("--lumen-h", type=float, default=None,
                    help="edge length on the lumen wall, m, after --mesh-size (default: wall_h)")
    ap.add_argument("--curvature-safety", type=float, default=None,
                    help="netgen's curvature safety in the section (default: 2 for circles, 0.5 with a shaped hole)")
    ap.add_argument("--layer-h", default=None,
                    help=f"prism height along the body, m (default {DEFAULT_LAYER_H}); 'scaled': the base mesh's "
                         "scaled by --mesh-size")
    ap.add_argument("--order", type=int, default=DEFAULT_PRESSURE_ORDER,
                    help=f"element pressure's order (0: P2/P0; 1: P2/P1; default {DEFAULT_PRESSURE_ORDER})")
    ap.add_argument("--contact-intorder", type=int, default=DEFAULT_CONTACT_INTORDER,
                    help=f"quadrature order of the lumen contact on the wall (default {DEFAULT_CONTACT_INTORDER})")
    ap.add_argument("--interior-order", default=str(DEFAULT_INTERIOR_ORDER),
                    help=f"condensed interior bubbles of this order added to P2 (default {DEFAULT_INTERIOR_ORDER}; "
                         "'none': plain P2)")
    ap.add_argument("--debug", action="store_true", help="the solver's per-iteration log on stderr")
    ap.add_argument("--stall", default=None,
                    help="NewtonSettings.stall_iterations: fail a solve whose |du.r| has not fallen tenfold in N iterations "
                         f"(default: the model's, {NewtonSettings.stall_iterations}; 'none': never)")
    ap.add_argument("--max-step", type=pressure_option("--max-step"), default=None,
                    help="StepControl.max_step, with its unit (the adaptive ramp's largest step; default 0.025bar)")
    ap.add_argument("--no-retry", action="store_true",
                    help="StepControl.retry_from_last = False: a failed predicted step is cut at once")
    ap.add_argument("--no-section", action="store_true", help="skip the section rung's comparison columns")
    ap.add_argument("--channel", type=int, nargs="+", default=[0],
                    help="the channel(s) pressurised, two or more at equal pressure (a multi-channel design: the "
                         "half body on the direction's mirror plane when it has one)")
    ap.add_argument("--name", default="fe3d_sweep")
    ap.add_argument("--plot-only", action="store_true", help="only redraw the PNG from the committed JSON")
    args = ap.parse_args(argv)
    if args.plot_only:
        print(plot(args.name))
        return 0

    design = load_design(args.design).with_length(args.length)
    checkpoints = np.round(np.arange(0.0, args.to + 1e-4, args.step) / PA_PER_BAR, 6) * PA_PER_BAR
    if not all(0 <= c < design.n_channels for c in args.channel) or len(set(args.channel)) < len(args.channel):
        ap.error(f"--channel {' '.join(map(str, args.channel))}: {design.name} has channels "
                 f"0..{design.n_channels - 1}, each once")
    commands = np.zeros((len(checkpoints), design.n_channels))
    commands[:, args.channel] = checkpoints[:, None]
    control = None
    if args.fixed_steps is not None:
        control = dataclasses.replace(default_step_control(adaptive=False), initial_step=args.fixed_steps)
    if args.no_retry:
        control = dataclasses.replace(control or default_step_control(), retry_from_last=False)
    if args.max_step is not None:
        if not 0 < args.max_step <= args.to:
            ap.error(f"--max-step {args.max_step / PA_PER_BAR:g} bar: must be positive and at most --to ({args.to / PA_PER_BAR:g} bar)")
        control = dataclasses.replace(control or default_step_control(), max_step=args.max_step)
    stall = {}
    if args.stall is not None:
        try:
            stall = {"stall_iterations": None if args.stall.lower() == "none" else int(args.stall)}
        except ValueError:
            ap.error(f"--stall {args.stall}: a number of iterations or 'none'")
        if stall["stall_iterations"] is not None and stall["stall_iterations"] < 1:
            ap.error(f"--stall {args.stall}: must be at least 1 iteration")
    contact = {} if args.contact_distance is None else {
        "contact_distance": None if args.contact_distance.lower() == "none" else float(args.contact_distance)}
    try:
        layer_h = (DEFAULT_LAYER_H if args.layer_h is None else None if args.layer_h.lower() == "scaled"
                   else float(args.layer_h))
        interior = None if args.interior_order.lower() == "none" else int(args.interior_order)
    except ValueError:
        ap.error(f"--layer-h {args.layer_h} / --interior-order {args.interior_order}: a number, 'scaled' / 'none'")
    if args.lumen_h is not None and not (math.isfinite(args.lumen_h) and args.lumen_h > 0):
        ap.error(f"--lumen-h {args.lumen_h}: must be a positive length (m)")
    try:   # the rung's own mesh; an explicit lumen edge holds as given (m), after the scaling
        mesh = mesh_settings(args.mesh_size, layer_h, design.outer_diameter)
    except ModelError as exc:
        ap.error(str(exc))
    if args.lumen_h is not None:
        mesh = dataclasses.replace(mesh, lumen_h=args.lumen_h)
    if args.curvature_safety is not None:
        if not (math.isfinite(args.curvature_safety) and 0.1 <= args.curvature_safety <= 10):
            ap.error(f"--curvature-safety {args.curvature_safety}: a number in [0.1, 10]")
        mesh = dataclasses.replace(mesh, curvature_safety=args.curvature_safety)
    newton = NewtonSettings(threads=args.threads, **stall,
                            **({} if args.energy_tol is None else {"energy_tol": args.energy_tol}))
    if args.debug:
        fe3d_solver_log()
    try:
        model = Fe3dModel(design, mesh=mesh, newton=newton, step_control=control, cache=False, progress=True,
                          tangent_predictor=args.fixed_steps is None, threads=args.threads,
                          pressure_order=args.order, interior_order=interior,
                          contact_intorder=args.contact_intorder,
                          **({"half": True} if design.n_channels > 1 else {}), **contact)
    except ModelError as exc:   # a bad option, as one line
        ap.error(str(exc))
    stop_on_signals()   # Ctrl-C or kill: the ramp stops and what converged is written below
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        problem = model.problem_for(commands[-1] / commands[-1].max())
    except KeyboardInterrupt:
        print(f"{args.name}: interrupted while meshing, nothing measured", file=sys.stderr)
        return 130
    ndof = problem.fes.ndof
    t_setup = time.perf_counter() - t0
    state, ramp = model.sweep(commands)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    # the section rung at the same pressures, as the same R_C = L / theta (its arc over the channelled
    # part, the tip cap straight: angle_per_length): the section-vs-3D comparison (after the fe3d timing
    # and memory were read)
    section_rc, section_refused = [None] * len(checkpoints), None
    if not args.no_section:
        try:
            section_model = make_model("section", design)
            section = section_model.evaluate(commands)
            section_rc = [1.0 / float(a) if ok and a > 0 else None
                          for a, ok in zip(angle_per_length(section, section_model), section.converged)]
        except (ModelError, DesignError) as exc:   # a design the section rung does not take yet
            section_refused = str(exc)
        except KeyboardInterrupt:
            section_refused = "interrupted"
    gaps = {pt.load: pt.measured.get("lumen_min_gap_m") for pt in (ramp.points if ramp else [])}
    rows = []
    for i, p in enumerate(checkpoints):
        ok = bool(state.converged[i])
        diag = state.diagnostics
        rc = float(state.radius_l_over_theta[i]) if ok else None
        volume, area = (float(diag.channel_volume[i, args.channel[0]]),   # NaN at p = 0
                        float(diag.channel_area[i, args.channel[0]]))
        pub = PUBLISHED_40MM.get(float(p)) if abs(args.length - 0.040) < 1e-9 else None
        rows.append({
            "pressure_bar": float(p) / PA_PER_BAR, "converged": ok,
            "bending_angle_deg": float(np.degrees(state.tip.angle[i])) if ok else None,
            "radius_l_over_theta_mm": (rc * 1e3 if rc is not None and np.isfinite(rc) else None),
            "published_radius_mm": pub * 1e3 if pub else None,
            "error_vs_published": ((rc - pub) / pub if (pub and rc) else None),
            "section_radius_l_over_theta_mm": section_rc[i] * 1e3 if section_rc[i] else None,
            "section_vs_fe3d": ((section_rc[i] - rc) / rc if (section_rc[i] and rc and np.isfinite(rc)) else None),
            "section_bending_angle_deg": math.degrees(args.length / section_rc[i]) if section_rc[i] else None,
            "curvature_y_per_m": float(state.curvature[i, 1]) if ok else None,
            "curvature_per_m": float(np.hypot(*state.curvature[i])) if ok else None,
            "axial_stretch": float(state.axial_stretch[i]) if ok else None,
            "channel_volume_mm3": volume * 1e9 if ok and math.isfinite(volume) else None,
            "channel_area_mm2": area * 1e6 if ok and math.isfinite(area) else None,
            "newton_iterations": int(diag.newton_iterations[i]) if ok else None,
            "lumen_min_gap_um": (gaps[float(p)] * 1e6 if ok and gaps.get(float(p)) is not None else None),
            "time_s": float(diag.time_s[i]) if ok else None})
    meta = {"design": design.name, "channel": args.channel if len(args.channel) > 1 else args.channel[0], "section_refused": section_refused,
            "command": " ".join(["benchmarks/fe3d_sweep.py", *(sys.argv[1:] if argv is None else argv)]),
            "length_m": args.length, "mesh": dataclasses.asdict(model.mesh_settings),
            "mesh_size": args.mesh_size, "ndof": ndof, "half_model": problem.half,
            "step_control": "fixed" if args.fixed_steps else "adaptive",
            "step_settings": dataclasses.asdict(model.step_control), "threads": args.threads,
            "setup_s": t_setup, "total_s": total, "cpu_s": cpu, "peak_rss_mb": peak_mb,
            "interrupted": bool(ramp.interrupted) if ramp else False,
            "converged": bool(ramp.converged) if ramp else True, "message": ramp.message if ramp else "",
            "stop_reason": ramp.stop_reason if ramp else "",
            "contact_distance": model.contact_distance, "lumen_h": args.lumen_h, "layer_h": layer_h,
            "pressure_order": model.pressure_order, "interior_order": model.interior_order,
            "contact_intorder": model.contact_intorder,
            "newton": dataclasses.asdict(model.newton_settings),
            "min_gap_every_step_um": ([min(g for _, g in ramp.min_gap_m) * 1e6] if ramp and ramp.min_gap_m else None),
            "steps": ramp.steps if ramp else 0, "cuts": ramp.cuts if ramp else 0,
            "newton_iterations_total": ramp.iterations if ramp else 0,
            "factorisations": problem.factorizations,
            "pair_searches": problem.contact.searches if problem.contact else None,
            "pair_searches_skipped": problem.contact.skipped if problem.contact else None,
            "note": "wall clock on a 2-core machine shared with other jobs (load average in meta)"}
    with signals_held():   # the files written whole
        path = write_results(args.name, meta, rows)
    print(f"{args.name}: {total:.1f} s, peak {peak_mb:.0f} MB, {ndof} DOF, converged={meta['converged']} "
          f"{meta['message']}")
    for r in rows:
        print(r)
    print(f"wrote {path}.json/.csv, {plot(args.name)}")
    return 0


def plot(name: str) -> str:
    """R_C = L/theta and bending angle against pressure, published FE points overlaid."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness import RESULTS

    doc = json.loads((RESULTS / f"{name}.json").read_text())
    rows = [r for r in doc["results"] if r["converged"] and r["radius_l_over_theta_mm"]]
    meta = doc["meta"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot([r["pressure_bar"] for r in rows], [r["radius_l_over_theta_mm"] for r in rows], "o-", label="fe3d")
    pub = [(r["pressure_bar"], r["published_radius_mm"]) for r in doc["results"] if r.get("published_radius_mm")]
    if pub:
        ax1.plot(*zip(*pub), "rs", label="published FE")
    ax1.set_yscale("log")
    ax1.set_xlabel("pressure [bar]")
    ax1.set_ylabel("R_C = L / theta [mm]")
    ax1.legend()
    ax2.plot([r["pressure_bar"] for r in rows], [r["bending_angle_deg"] for r in rows], "o-")
    ax2.set_xlabel("pressure [bar]")
    ax2.set_ylabel("bending angle [deg]")
    status = "converged" if meta["converged"] else meta["message"][:70]
    fig.suptitle(f"{name}: L = {meta['length_m'] * 1e3:.0f} mm, {meta['ndof']} DOF, {meta['total_s']:.0f} s "
                 f"(load avg {meta.get('load_average', meta.get('load_average_before'))[0]:.1f}); {status}", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, name)


if __name__ == "__main__":
    sys.exit(main())
