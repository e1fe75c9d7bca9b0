"""Design studies: the published parameter studies, reproduced on any design, and
design optimisation. Each study builds validated design variants (variation.py), solves them
as cached cases fanned out over an executor (cases.py, runner.py) and returns rows, findings
and a chart (context.StudyResult) that output.py writes as CSV, PNG and Markdown."""
from __future__ import annotations

import importlib

# study name (CLI) -> module in this package with run(design, ctx, **options)
STUDIES: dict[str, str] = {
    "sensitivity": "sensitivity",
    "channel-shift": "channel_shift",
    "area-ratio": "area_ratio",
    "device-stiffness": "device_stiffness",
    "miniaturise": "miniaturise",
    "optimise": "optimise",
}


def study_module(name: str):
    from ..errors import SoftcathError

    if name not in STUDIES:
        raise SoftcathError(f"unknown study '{name}'; available: {', '.join(STUDIES)}")
    return importlib.import_module(f"{__name__}.{STUDIES[name]}")
