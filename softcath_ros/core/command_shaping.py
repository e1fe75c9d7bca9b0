"""Shaping a pressure command stream: rate limit, command watchdog, request checks.

Policy that a node applies between an allocation and the wire, kept here (no ROS) so it
is tested without DDS and shared by every node that streams pressures. Times are in
seconds of a monotonic clock, pressures in Pa.

Freshness rule (every node that commands pressures, and the regulator): a command's age counts
from when it *arrived* (or was stamped), not from when a busy node got round to it. A queued
command older than the timeout is stale and dropped, and the watchdog is fed with the arrival
time, so no backlog holds pressure past timeout + ramp (``PressureStream``).
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
    """Expires when no fresh command arrived for longer than ``timeout`` seconds (or none yet).
    Fed with each command's arrival time (module docstring), never with when it was handled."""

    def __init__(self, timeout: float):
        if not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError(f"command timeout {timeout} s must be positive and finite")
        self.timeout = float(timeout)
        self.last_feed: float | None = None

    def fresh(self, arrived: float, now: float) -> bool:
        """Whether a command that arrived at ``arrived`` may still be used at ``now``."""
        return now - arrived <= self.timeout

    def feed(self, arrived: float) -> None:
        """A command that arrived at ``arrived``: the timeout counts from there (a command handled
        out of order never moves it back)."""
        self.last_feed = arrived if self.last_feed is None else max(self.last_feed, arrived)

    def expired(self, now: float) -> bool:
        return self.last_feed is None or now - self.last_feed > self.timeout


# An unchanged output is re-sent this often (s): 10 Hz, five messages per 0.5 s command_timeout of
# the rig's watchdog (docs/rig.md), so four lost in a row still do not vent the rig.
KEEP_ALIVE_PERIOD = 0.1


class PressureStream:
    """The pressures a node streams to the regulator, on an injected clock (``clock()`` -> s).

    ``command(target, arrived)`` sets a new target unless the command is stale (dropped: False);
    ``output()`` gives what to send now: the target (zero once the watchdog expired), rate limited,
    or None when the output has not changed and the keep-alive is not due yet, so an idle stream
    costs a message per ``keep_alive`` instead of one per tick. Pressure after the last fresh
    command arrived at t: held at most until t + timeout, then ramped down at ``max_rate``.
    """

    def __init__(self, n_channels: int, max_rate: float, timeout: float, clock,
                 keep_alive: float = KEEP_ALIVE_PERIOD):
        if not (keep_alive > 0 and math.isfinite(keep_alive)):
            raise ValueError(f"keep-alive period {keep_alive} s must be positive and finite")
        self.clock = clock
        self.limiter = RateLimiter(n_channels, max_rate)
        self.watchdog = CommandWatchdog(timeout)
        self.keep_alive = float(keep_alive)
        self.target = np.zeros(n_channels)
        self.vented = True            # no command yet counts as vented
        self.dropped = 0              # stale commands dropped
        self._t_step: float | None = None
        self._t_sent = -math.inf
        self._sent: np.ndarray | None = None

    def fresh(self, arrived: float) -> bool:
        """Whether a command that arrived at ``arrived`` is still worth handling (check before an
        expensive allocation)."""
        return self.watchdog.fresh(arrived, self.clock())

    def command(self, target, arrived: float) -> bool:
        """A new target (Pa) from a command that arrived at ``arrived``; False (dropped) when stale."""
        if not self.fresh(arrived):
            self.dropped += 1
            return False
        self.watchdog.feed(arrived)
        self.target = np.asarray(target, dtype=float).copy()
        self.vented = False
        return True

    def check_watchdog(self) -> bool:
        """Vent when the watchdog expired; True when this call is the one that vented."""
        if not self.vented and self.watchdog.expired(self.clock()):
            self.vented = True
            return True
        return False

    @property
    def settled(self) -> bool:
        """Output at its target (nothing to ramp): the stream may tick at the keep-alive rate."""
        target = np.zeros_like(self.target) if self.vented else self.target
        return bool(np.array_equal(self.limiter.output, target))

    def output(self, force: bool = False) -> np.ndarray | None:
        """Pressures to send now (rate limited from the last call), or None when unchanged and
        the keep-alive is not due (``force``: send anyway)."""
        now = self.clock()
        self.check_watchdog()
        dt = 0.0 if self._t_step is None else now - self._t_step
        self._t_step = now
        out = self.limiter.step(np.zeros_like(self.target) if self.vented else self.target, dt)
        if not force and self._sent is not None and np.array_equal(out, self._sent) and \
                now - self._t_sent < self.keep_alive * (1.0 - 1e-6):
            return None
        self._t_sent, self._sent = now, out.copy()
        return out

    def sent(self, values) -> None:
        """What actually went out when it differs from ``output()`` (a last guard clamped or
        zeroed it): the limiter continues from there."""
        self.limiter.output = np.asarray(values, dtype=float).copy()
        self._sent = self.limiter.output.copy()


# A waiting pose command is superseded by a newer one only once it has waited this long (s): a
# rung that keeps up answers every command (a scheduling pause of a few ms only queues a few),
# one that does not answers the newest instead of a backlog.
SUPERSEDE_AGE = 0.01


def is_superseded(arrived: float, now: float, newer_waiting: bool, age: float = SUPERSEDE_AGE) -> bool:
    """Whether a command waiting to be answered (arrived at ``arrived``) is skipped at ``now``: it
    has waited longer than ``age`` and a newer one waits (so the newest never is)."""
    return newer_waiting and now - arrived > age


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
