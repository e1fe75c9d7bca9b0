"""The ladder chart's numbers and the shipped envelope, through `softcath envelope` (the cases,
settings and references are described in softcath_ros/core/ladder.py).

Writes benchmarks/results/ladder_chart.{csv,json} and, when every case is run (or kept: ``--keep``),
the shipped config/ladder_envelope.yaml that model selection reads; a subset of the cases without
``--keep`` writes benchmarks/results/ladder_chart_partial.* and leaves the envelope as it was; then
draws the charts (`softcath chart`: ladder_chart.png, _lengths.png, _directions.png beside the CSV).

The fan design's cases (three_sector_5mm) were added by measuring them only, without section D/40
(1.5-2 s a command on the circle designs, minutes a case on the fan design's finer mesh), and keeping
the other cases' committed rows (their fe3d took hours; meta ``kept`` names their commit):

    .venv/bin/python benchmarks/ladder_chart.py --cases "sector one channel" "sector pair equal" \
        "sector one channel 20mm" "sector pair equal 20mm" --settings closed_form \
        "surrogate (of section D/20)" "section D/12" "section D/20" "fe3d mesh 1.4, 1.2 mm layers" \
        --keep benchmarks/results/ladder_chart.json

Their fe3d is not solved: at 20 mm it is the committed sweeps fe3d_sector_ch0_20mm (to 0.125 bar) and
fe3d_sector_pair_20mm (to 0.05 bar) at the ladder's pressures (fe3d-10 at the rung's defaults, half
body; no tip recorded, so no tip error against them); above those and at 40 mm the reference is
section D/20. The rod models one channel only.

Every rung's results per case are cached (core/cache.py, kind ``ladder``, keyed by the rung's solver
version): with the same SOFTCATH_CACHE a re-run only redraws, and after a rung's solver version
changes (fe3d with contact) only that rung is measured again.

    .venv/bin/python benchmarks/ladder_chart.py [--no-fe3d] [--fe3d-three-channel] [--refresh [RUNG ...]] \
        [--cases NAME ...] [--keep RESULTS.json]
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
    partial = "--cases" in argv and "--keep" not in argv
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "ladder_envelope.yaml" if partial else envelope_path()
        stem = RESULTS / ("ladder_chart_partial" if partial else "ladder_chart")
        code = softcath(["envelope", "--out", str(out), "--results", str(stem), *argv])
        if code == 0 and "-h" not in argv and "--help" not in argv:   # and the charts (softcath chart)
            code = softcath(["chart", "--csv", str(stem.with_suffix(".csv"))])
        sys.exit(code)
