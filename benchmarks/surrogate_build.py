"""Cold build time of the surrogate tables from the section rung (issue 13: 3-channel <= 30 s,
1-channel <= 5 s on a quiet 2-core machine).

Each design's table is built into an empty temporary cache (so neither the section rung's cached
batches nor a shipped table are used) and timed from the constructor's call to its return; the
table's measured error against the section rung (its held-out commands) is recorded with it.

    .venv/bin/python benchmarks/surrogate_build.py [--designs implemented_5mm,three_channel_5mm]
        [--name surrogate_build] [--label after] [--ship]

Writes benchmarks/results/<name>.{json,csv,png}; with an existing <name>.json the rows of other
labels (e.g. "before", measured at the commit before the ray builder) are kept beside the new ones.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import RESULTS, save_figure, write_results  # noqa: E402

from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402
from softcath_ros.provenance import machine_meta  # noqa: E402


def _cpu_seconds() -> float:
    import resource

    return sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--designs", default="implemented_5mm,three_channel_5mm")
    ap.add_argument("--name", default="surrogate_build")
    ap.add_argument("--label", default="after", help="what this run measures (kept apart from other labels)")
    ap.add_argument("--ship", action="store_true", help="also write each built table to the package's shipped table")
    args = ap.parse_args()
    old = RESULTS / f"{args.name}.json"
    rows = [r for r in json.loads(old.read_text())["results"] if r["label"] != args.label] if old.is_file() else []
    meta_now = machine_meta()
    for name in args.designs.split(","):
        design = load_design(name)
        with tempfile.TemporaryDirectory(prefix="softcath-build-") as cache:
            cpu0 = _cpu_seconds()
            t0 = time.perf_counter()
            # (the "before" rows were measured at commit f2dec9f, whose surrogate had no shipped tables)
            model = make_model("surrogate", design, cache=cache, progress=True, shipped=False)
            took = time.perf_counter() - t0
            cpu = _cpu_seconds() - cpu0
            if args.ship:
                model.write(model.shipped_path())
        bound = model.error_bound
        row = {"label": args.label, "design": name, "channels": design.n_channels, "build_s": took,
               "cpu_s": cpu,   # this process and its finished workers: what a quiet machine would need in all
               "source_evaluations": model.meta.get("source_evaluations"),
               "source_rays": model.meta.get("source_rays"), "workers": model.meta.get("workers"),
               "range_max_pa": model.pressure_range[1],
               "error_rc_rel_max": max(b.get("rc_rel_max", float("nan")) for k, b in bound.items()
                                       if k != "common_mode"),
               "error_direction_deg_max": max(b.get("direction_deg_max", float("nan")) for k, b in bound.items()
                                              if k != "common_mode"),
               "commit": meta_now.get("git_commit") or meta_now.get("commit"),
               "load_average_1min": __import__("os").getloadavg()[0]}
        rows.append(row)
        print(f"{args.label} {name}: built in {took:.1f} s ({cpu:.1f} CPU s), R_C error vs section max {row['error_rc_rel_max']:.3%}, "
              f"load {row['load_average_1min']:.2f}")
    keys = list(dict.fromkeys(k for r in rows for k in r))
    rows = [{k: r.get(k) for k in keys} for r in rows]     # rows of other labels may lack newer fields
    write_results(args.name, {"note": "cold builds into an empty cache; the machine is shared (load per row)"}, rows)
    plot(rows, args.name)


def plot(rows, name) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    labels = list(dict.fromkeys(r["label"] for r in rows))
    designs = list(dict.fromkeys(r["design"] for r in rows))
    w = 0.8 / max(len(labels), 1)
    for i, lab in enumerate(labels):
        xs = [j + i * w for j, d in enumerate(designs) for r in rows if r["label"] == lab and r["design"] == d]
        ys = [r["build_s"] for d in designs for r in rows if r["label"] == lab and r["design"] == d]
        ax.bar(xs, ys, width=w, label=lab)
    ax.axhline(30, color="k", ls="--", lw=1, label="3-channel target 30 s")
    ax.axhline(5, color="grey", ls=":", lw=1, label="1-channel target 5 s")
    ax.set_xticks([j + w * (len(labels) - 1) / 2 for j in range(len(designs))], designs)
    ax.set_ylabel("cold build time, s")
    ax.set_yscale("log")
    ax.set_title("surrogate table build from the section rung (shared 2-core machine)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, name, dpi=110)


if __name__ == "__main__":
    main()
