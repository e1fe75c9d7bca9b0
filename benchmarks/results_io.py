"""Writing a benchmark's results: benchmarks/results/<name>.{json,csv} with the machine it ran on."""
from __future__ import annotations

import csv
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


def machine_meta() -> dict:
    """What the numbers depend on: interpreter, numpy, CPU count, load at the time, date."""
    return {"python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine(),
            "cpu_count": os.cpu_count(), "load_average": os.getloadavg(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}


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
