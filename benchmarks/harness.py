"""What every benchmark shares: timing over repeats (median and spread), the machine and load the
numbers come from (softcath_ros.provenance: CPU, cores, Python, package versions, git commit, load
average when the script started and when it wrote), and writing results
(benchmarks/results/<name>.{json,csv}) and charts (<name>.png).

Timing: medians over many repeats, because these machines are shared and noisy. Node graphs
are started on a private DDS domain by softcath_ros.graph.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import signal
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from softcath_ros.core.errors import SoftcathError
from softcath_ros.core.units import parse_pressure
from softcath_ros.provenance import machine_meta

RESULTS = Path(__file__).resolve().parent / "results"
LOAD_AT_START = os.getloadavg()   # when the benchmark script imported the harness


def pressure_option(option: str) -> Callable[[str], float]:
    """An argparse ``type`` for a pressure option: Pa from text with its unit (``0.35bar``,
    ``35kPa``), by the tools' one rule (core/units.py); a bare non-zero number is refused."""
    def parse(text: str) -> float:
        try:
            return parse_pressure(text, option)
        except SoftcathError as exc:
            raise argparse.ArgumentTypeError(str(exc).replace(" (or give --unit Pa|kPa|bar)", "")) from None
    return parse


def time_loops(fn: Callable[[], object], repeats: int, calls: int) -> list[float]:
    """Seconds per call of ``fn`` for each of ``repeats`` timed loops of ``calls`` calls."""
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        out.append((time.perf_counter() - t0) / calls)
    return out


def median_time(fn: Callable[[], object], repeats: int, calls: int = 1) -> float:
    """Median over ``repeats`` loops of the seconds per call of ``fn``."""
    return float(np.median(time_loops(fn, repeats, calls)))


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
    """Median and spread (interquartile range, 99th percentile, minimum, maximum) of per-call
    times (seconds), and their count."""
    t = np.asarray(seconds, dtype=float)
    q1, q3 = np.percentile(t, [25, 75])
    return {"median_s": float(np.median(t)), "iqr_s": float(q3 - q1), "p99_s": float(np.percentile(t, 99)),
            "min_s": float(t.min()), "max_s": float(t.max()), "n": int(t.size)}


def write_results(name: str, meta: dict, rows: list[dict]) -> Path:
    """JSON (machine metadata + ``meta``, whose keys win, + rows) and CSV (rows) under
    benchmarks/results/; returns the stem path."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{name}.json").write_text(json.dumps(
        {"meta": {**machine_meta(LOAD_AT_START), **meta}, "results": rows}, indent=2))
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


def fe3d_solver_log() -> None:
    """The fe3d solver's per-iteration log on stderr, each line stamped with ms since start (--debug)."""
    import logging

    logging.basicConfig(level=logging.WARNING, format="%(relativeCreated)9.0f ms %(message)s")
    logging.getLogger("softcath_ros.core.fe3d.newton").setLevel(logging.DEBUG)


def _interrupt(signum, frame):
    raise KeyboardInterrupt(signal.Signals(signum).name)


def stop_on_signals() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt, which a long run catches to keep what it measured:
    also when SIGINT came ignored (a job started with ``&`` from a script) or the run is killed politely."""
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)


@contextmanager
def signals_held():
    """SIGINT and SIGTERM ignored inside (the results being written whole), restored after."""
    saved = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
