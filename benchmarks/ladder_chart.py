"""The ladder chart's numbers and the shipped envelope, through `softcath envelope` (the cases,
settings and references are described in softcath_ros/core/ladder.py).

Writes benchmarks/results/ladder_chart.{csv,json} and, when every case is run, the shipped
config/ladder_envelope.yaml that model selection reads; a subset of the cases writes
benchmarks/results/ladder_chart_partial.* and leaves the envelope as it was; then draws the charts
(`softcath chart`: ladder_chart.png, _lengths.png, _directions.png beside the CSV).

Every rung's results per case are cached (core/cache.py, kind ``ladder``, keyed by the rung's solver
version): with the same SOFTCATH_CACHE a re-run only redraws, and after a rung's solver version
changes (fe3d with contact) only that rung is measured again.

    .venv/bin/python benchmarks/ladder_chart.py [--no-fe3d] [--fe3d-three-channel] [--refresh [RUNG ...]] [--cases NAME ...]
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import RESULTS  # noqa: E402

from softcath_ros.cli import main as softcath  # noqa: E402
from softcath_ros.resources import envelope_path  # noqa: E402

if __name__ == "__main__":
    argv = sys.argv[1:]
    partial = "--cases" in argv
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "ladder_envelope.yaml" if partial else envelope_path()
        stem = RESULTS / ("ladder_chart_partial" if partial else "ladder_chart")
        code = softcath(["envelope", "--out", str(out), "--results", str(stem), *argv])
        if code == 0 and "-h" not in argv and "--help" not in argv:   # and the charts (softcath chart)
            code = softcath(["chart", "--csv", str(stem.with_suffix(".csv"))])
        sys.exit(code)
