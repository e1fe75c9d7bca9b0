"""The ladder chart's numbers and the shipped envelope, through `softcath envelope` (the cases,
settings and references are described in softcath_ros/core/ladder.py).

Writes benchmarks/results/ladder_chart.{csv,json} and, when every case is run, the shipped
softcath_ros/config/ladder_envelope.yaml that model selection reads; a subset of the cases writes
benchmarks/results/ladder_chart_partial.* and leaves the envelope as it was. Draw with `softcath chart`.

    .venv/bin/python benchmarks/ladder_chart.py [--no-fe3d] [--refresh [RUNG ...]] [--cases NAME ...]
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
        sys.exit(softcath(["envelope", "--out", str(out), "--results", str(stem), *argv]))
