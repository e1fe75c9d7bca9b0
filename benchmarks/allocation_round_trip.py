"""Allocation round trip against the section rung (issue 13 target: within 0.5 degrees and 1% in R_C
over the reachable set).

The allocator on the default rung (the surrogate of the section rung) turns bend requests spread
over the reachable set (every ``--step`` degrees, at fractions of the reachable curvature in that
direction: the allocator's answer to a request far beyond it, so the pressure box's edge or, where
the body would meet its shaft first, the bend that clears it) into channel pressures; the section rung itself (fresh, from rest, on worker processes)
then says how those pressures bend the body. Reported per request: the R_C error (1/|k| against
the requested 1/|k|) and the direction error.

    .venv/bin/python benchmarks/allocation_round_trip.py [--design three_channel_5mm] [--step 30]
        [--fractions 0.3,0.6,0.9] [--workers 2] [--name allocation_round_trip]
        [--max-pressure 20000]

Writes benchmarks/results/allocation_round_trip.{json,csv,png}.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import save_figure, write_results  # noqa: E402

from softcath_ros.core.allocation import Allocator  # noqa: E402
from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402
from softcath_ros.core.models.surrogate_build import RayPool, default_workers  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", default="three_channel_5mm")
    ap.add_argument("--model", default="surrogate", help="the allocator's rung")
    ap.add_argument("--step", type=float, default=30.0, help="degrees between request directions")
    ap.add_argument("--fractions", default="0.3,0.6,0.9", help="fractions of the reachable curvature")
    ap.add_argument("--offset", type=float, default=7.0, help="first direction, degrees (off the channels' own)")
    ap.add_argument("--workers", type=int, default=default_workers())
    ap.add_argument("--name", default="allocation_round_trip", help="results stem under benchmarks/results/")
    ap.add_argument("--max-pressure", type=float, default=None, help="the allocator's limit, Pa (default: the design's)")
    args = ap.parse_args()
    from tqdm import tqdm

    design = load_design(args.design)
    model = make_model(args.model, design)
    alloc = Allocator(model) if args.max_pressure is None else Allocator(model, max_pressure=args.max_pressure)
    requests = []
    for deg in np.arange(args.offset, 360.0 + args.offset, args.step):
        phi = math.radians(deg)
        kmax = alloc.allocate(1e3 * np.array([math.cos(phi), math.sin(phi)])).max_curvature
        for f in (float(x) for x in args.fractions.split(",")):
            k = f * kmax * np.array([math.cos(phi), math.sin(phi)])
            a = alloc.allocate(k)
            requests.append((deg, f, k, a))
    rows = []
    with tqdm(total=0, desc="section at the allocated pressures", unit="cmd") as bar:
        pool = RayPool(design, "section", {}, args.workers, bar)
        try:
            for i, (_, _, _, a) in enumerate(requests):
                pool.submit(i, a.pressures[None, :])
            answers = dict(pool.results())
        finally:
            pool.close(cancel=True)
    for i, (deg, f, k, a) in enumerate(requests):
        got = answers[i]
        ks = got["values"][0, :2] if got["n_ok"] else np.full(2, np.nan)
        kr, kg = float(np.hypot(*k)), float(np.hypot(*ks))
        d = math.atan2(ks[1], ks[0]) - math.atan2(k[1], k[0])
        rows.append({"direction_deg": float(deg), "fraction_of_reach": f, "requested_curvature_per_m": kr,
                     "pressures_pa": a.pressures.round(1).tolist(), "allocation_converged": bool(a.converged),
                     "allocation_saturated": bool(a.saturated),
                     "section_converged": bool(got["n_ok"]), "section_curvature_per_m": kg,
                     "rc_rel_error": abs(kr / kg - 1.0) if kg > 0 else float("nan"),
                     "direction_error_deg": abs(math.degrees((d + math.pi) % (2 * math.pi) - math.pi))})
    rc = np.array([r["rc_rel_error"] for r in rows])
    de = np.array([r["direction_error_deg"] for r in rows])
    ok = np.isfinite(rc)
    print(f"{len(rows)} requests, section answered {ok.sum()}: R_C error max {np.nanmax(rc):.3%} "
          f"(median {np.nanmedian(rc):.3%}), direction max {np.nanmax(de):.3f} deg; target 1% and 0.5 deg")
    for fr in sorted(set(r["fraction_of_reach"] for r in rows)):
        sel = [r for r in rows if r["fraction_of_reach"] == fr]
        print(f"  at {fr:.0%} of reach: R_C max {max(r['rc_rel_error'] for r in sel):.3%}, "
              f"direction max {max(r['direction_error_deg'] for r in sel):.3f} deg")
    write_results(args.name, {"design": design.name, "allocator_model": args.model,
                              "allocator_max_pressure_pa": alloc.max_pressure,
                              "allocator_limited_by": alloc.limited_by_peak or alloc.limited_by_rung,
                                            "target_rc_rel": 0.01, "target_direction_deg": 0.5,
                                            "note": "section rung fresh from rest per command; shared machine"}, rows)
    plot(rows, args.name)


def plot(rows, name: str = "allocation_round_trip") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for fr in sorted(set(r["fraction_of_reach"] for r in rows)):
        sel = [r for r in rows if r["fraction_of_reach"] == fr]
        x = [r["direction_deg"] for r in sel]
        axes[0].plot(x, [100 * r["rc_rel_error"] for r in sel], "o-", label=f"{fr:.0%} of reach")
        axes[1].plot(x, [r["direction_error_deg"] for r in sel], "o-", label=f"{fr:.0%} of reach")
    axes[0].axhline(1.0, color="k", ls="--", lw=1, label="target 1%")
    axes[1].axhline(0.5, color="k", ls="--", lw=1, label="target 0.5 deg")
    axes[0].set_ylabel("R_C error against the section rung, %")
    axes[1].set_ylabel("direction error, degrees")
    for ax in axes:
        ax.set_xlabel("requested direction, degrees")
        ax.legend(fontsize=7)
    fig.suptitle("allocation round trip: surrogate allocator, section rung at its pressures")
    fig.tight_layout()
    save_figure(fig, name, dpi=110)


if __name__ == "__main__":
    main()
