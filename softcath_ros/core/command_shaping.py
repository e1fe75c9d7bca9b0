"""Shaping a pressure command stream: rate limit, command watchdog, request checks.

Policy that a node applies between an allocation and the wire, kept here (no ROS) so it
is tested without DDS and shared by every node that streams pressures. Times are in
seconds of a monotonic clock, pressures in Pa.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class RateLimiter:
    """Moves each channel's output towards its target by at most ``max_rate`` (Pa/s) x dt."""

    def __init__(self, n_channels: int, max_rate: float):
        if not (max_rate > 0 and math.isfinite(max_rate)):
            raise ValueError(f"max pressure rate {max_rate} Pa/s must be positive and finite")
        self.max_rate = float(max_rate)
        self.output = np.zeros(n_channels)

    def step(self, target: np.ndarray, dt: float) -> np.ndarray:
        limit = self.max_rate * max(dt, 0.0)
        self.output = self.output + np.clip(np.asarray(target, dtype=float) - self.output, -limit, limit)
        return self.output


class CommandWatchdog:
    """Expires when no command was fed for longer than ``timeout`` seconds (or none yet)."""

    def __init__(self, timeout: float):
        if not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError(f"command timeout {timeout} s must be positive and finite")
        self.timeout = float(timeout)
        self.last_feed: float | None = None

    def feed(self, now: float) -> None:
        self.last_feed = now

    def expired(self, now: float) -> bool:
        return self.last_feed is None or now - self.last_feed > self.timeout


@dataclass(frozen=True)
class RequestCheck:
    ok: bool
    reason: str = ""


def check_frame(frame_id: str, expected: str) -> RequestCheck:
    if frame_id != expected:
        return RequestCheck(False, f"frame '{frame_id}' is not the expected '{expected}'")
    return RequestCheck(True)


def check_vector(values, max_norm: float, what: str, unit: str) -> RequestCheck:
    """Finite and not absurdly large (``max_norm``): larger values are a fault, not a request to saturate."""
    v = [float(x) for x in values]
    if not all(math.isfinite(x) for x in v):
        return RequestCheck(False, f"{what} {v} {unit} is not finite")
    norm = math.sqrt(sum(x * x for x in v))
    if norm > max_norm:
        return RequestCheck(False, f"{what} {v} {unit}: magnitude {norm:.6g} exceeds the sanity limit {max_norm:.6g}")
    return RequestCheck(True)
