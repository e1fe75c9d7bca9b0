"""What every benchmark shares: timing over repeats, the machine and load the numbers come from,
and writing results (benchmarks/results/<name>.{json,csv}) and charts (<name>.png).

Timing: medians (and the 99th percentile) over many repeats, because these machines are shared
and noisy; the load average before and after is part of every result's metadata. Node graphs
are started on a private DDS domain by softcath_ros.graph.
"""
from __future__ import annotations

import csv
import json
import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


def _git_commit() -> str:
    try:
        out = subprocess.run(["git", "-C", str(RESULTS.parent), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_meta() -> dict:
    """What the numbers depend on: interpreter, numpy, CPU, load at the time, code version, date."""
    return {"python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine(),
            "cpu": _cpu_model(), "cpu_count": os.cpu_count(), "load_average": os.getloadavg(),
            "git_commit": _git_commit(), "date": time.strftime("%Y-%m-%d %H:%M:%S")}


def time_loops(fn: Callable[[], object], repeats: int, calls: int) -> list[float]:
    """Seconds per call of ``fn`` for each of ``repeats`` timed loops of ``calls`` calls."""
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        out.append((time.perf_counter() - t0) / calls)
    return out


def time_each(fn: Callable[[object], object], inputs: Iterable) -> np.ndarray:
    """Seconds of each call ``fn(x)`` over ``inputs`` (one clock pair per call)."""
    clock = time.perf_counter_ns
    out = []
    for x in inputs:
        t0 = clock()
        fn(x)
        out.append((clock() - t0) * 1e-9)
    return np.asarray(out)


def summary(seconds) -> dict:
    """Median, 99th percentile, minimum and count of per-call times (seconds)."""
    t = np.asarray(seconds, dtype=float)
    return {"median_s": float(np.median(t)), "p99_s": float(np.percentile(t, 99)), "min_s": float(t.min()),
            "n": int(t.size)}


def write_results(name: str, meta: dict, rows: list[dict]) -> Path:
    """JSON (meta + rows) and CSV (rows) under benchmarks/results/; returns the stem path."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{name}.json").write_text(json.dumps({"meta": {**meta, **machine_meta()}, "results": rows},
                                                     indent=2))
    with open(RESULTS / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return RESULTS / name


def save_figure(fig, name: str, dpi: int = 100) -> str:
    """The chart as benchmarks/results/<name>.png (the figure is closed); returns the path."""
    import matplotlib.pyplot as plt

    out = RESULTS / f"{name}.png"
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return str(out)
