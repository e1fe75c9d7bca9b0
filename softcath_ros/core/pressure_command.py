"""Checking commanded channel pressures before any model sees them.

The nodes call this; the policy lives here so the CLI, allocator and nodes agree.
Outcomes: accepted as is, clamped into [0, max_pressure], or rejected. Non-finite
values and a wrong channel count are always rejected: there is no safe guess.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

POLICIES = ("reject", "clamp")


@dataclass(frozen=True)
class CommandCheck:
    pressures: np.ndarray | None  # (C,) Pa to use, or None when rejected
    status: str                    # "ok" | "clamped" | "rejected"
    reason: str = ""               # what was wrong, for logs and diagnostics


def check_pressure_command(values, n_channels: int, max_pressure: float,
                           out_of_range: str = "reject") -> CommandCheck:
    """Validate one command; ``out_of_range`` is the policy for finite values outside [0, max]."""
    if out_of_range not in POLICIES:
        raise ValueError(f"out_of_range policy {out_of_range!r} is not one of {POLICIES}")
    p = np.asarray(values, dtype=float).ravel()
    if p.size != n_channels:
        return CommandCheck(None, "rejected", f"wrong number of channels: got {p.size}, expected {n_channels}")
    if not np.all(np.isfinite(p)):
        return CommandCheck(None, "rejected", f"non-finite pressure in {p.tolist()}")
    low, high = float(p.min()), float(p.max())
    if low >= 0.0 and high <= max_pressure:
        return CommandCheck(p, "ok")
    what = (f"pressure {low:.6g} Pa is negative" if low < 0.0
            else f"pressure {high:.6g} Pa exceeds max_pressure {max_pressure:.6g} Pa")
    if out_of_range == "reject":
        return CommandCheck(None, "rejected", what)
    return CommandCheck(np.clip(p, 0.0, max_pressure), "clamped", what)

