"""Helpers shared by the `softcath` subcommands."""
from __future__ import annotations

import math

import numpy as np

from ..core.errors import SoftcathError
from ..core.units import PA_PER_BAR


def parse_pressures(values: list[str], n_channels: int, unit: str) -> np.ndarray:
    """Each value is one command: a number, or a comma list with one value per channel."""
    scale = PA_PER_BAR if unit == "bar" else 1.0
    rows = []
    for v in values:
        try:
            row = [float(x) for x in v.split(",")]
        except ValueError:
            raise SoftcathError(f"--pressure {v!r}: not a number or comma list of numbers") from None
        if len(row) != n_channels:
            raise SoftcathError(f"--pressure {v!r}: {len(row)} value(s) for a design with {n_channels} channel(s)")
        if not all(math.isfinite(x) for x in row):
            raise SoftcathError(f"--pressure {v!r}: values must be finite")
        rows.append(row)
    return np.asarray(rows) * scale
