"""The rig contract's checks (docs/rig.md), without ROS: bench_node feeds them its clock and the
arrivals of the rig's topics.

- ``RigMonitor``: per topic, when the last message arrived and the stamp it carried. A topic is
  *alive* when a message arrived within ``stale_after`` s and its stamp (where it has one) lies
  within ``stale_after`` s of the receiver's clock; otherwise ``problems`` names it with the
  reason. bench_node uses only readings that are alive, before the first step and during the run.
- ``graph_problems`` / ``wait_for_rig``: what the ROS graph lacks for a run (a rig topic with no
  publisher, nothing listening to the command); bench_node's configure waits a bounded time for it
  to be empty and fails with ``NoRig`` (exit code 3) naming each missing topic;
  ``with_driver_reports`` adds what the topic's driver reports on /diagnostics when it is not OK.
- ``FollowCheck``: before the first step, the pressure source must follow a small test command:
  a baseline at zero command, then the test pressures; it passes once every commanded channel
  has risen by ``fraction`` of its test pressure above the baseline, fails after ``timeout`` s.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .. import topics as T
from ..errors import SoftcathError
from .bench_run import EXIT_NO_RIG


class NoRig(SoftcathError):
    """The rig's topics are not on the graph: exit code 3 (docs/rig.md)."""
    exit_code = EXIT_NO_RIG


def graph_problems(contract: "RigMonitor", legacy: "RigMonitor", n_channels: int, publishers: Callable[[str], int],
                   subscribers: Callable[[str], int], by_direction: bool) -> tuple["RigMonitor", dict[str, str]]:
    """The monitor whose topics the rig publishes (``contract``'s, or ``legacy``'s deprecated ones when
    nothing publishes the contract's) and what the graph lacks for it, by topic: each of its topics with
    no publisher, nothing subscribing the pressure command (the rig's pressure source) or, by direction,
    the bend command (allocation_node)."""
    stamped = any(publishers(t) for t in T.rig_topics(n_channels))
    monitor = legacy if publishers(T.PRESSURE_MEASURED) > 0 and not stamped else contract
    out = {t: "no publisher" for t in monitor.topics if publishers(t) == 0}
    if subscribers(T.PRESSURE_CMD) == 0:
        out[T.PRESSURE_CMD] = "nothing subscribes (the rig's pressure source)"
    if by_direction and subscribers(T.BEND_CMD) == 0:
        out[T.BEND_CMD] = "nothing subscribes (allocation_node)"
    return monitor, out


def wait_for_rig(problems: Callable[[], dict[str, str]], timeout_s: float, clock: Callable[[], float],
                 sleep: Callable[[float], None], period_s: float = 0.1) -> None:
    """Until ``problems()`` is empty; ``NoRig`` naming each problem if it is not within ``timeout_s``
    (``clock``, ``sleep`` injected)."""
    end = clock() + timeout_s
    while True:
        found = problems()
        if not found:
            return
        if clock() >= end:
            raise NoRig(f"no rig after {timeout_s:g} s: " + "; ".join(f"{t}: {why}" for t, why in found.items()))
        sleep(period_s)


def with_driver_reports(problems: dict[str, str], publishers_of: Callable[[str], list[str]],
                        reports: dict[str, str]) -> dict[str, str]:
    """``problems`` with the /diagnostics report of each problem topic's publisher that is not OK
    (``reports``: node name -> "ERROR <message>"): a driver in error says there why its topic is
    silent, and the "no rig" line should say it too."""
    out = {}
    for topic, why in problems.items():
        said = [f"{node} reports {reports[node]}" for node in publishers_of(topic) if node in reports]
        out[topic] = why + (f" ({'; '.join(said)})" if said else "")
    return out


class RigMonitor:
    def __init__(self, topics: list[str], stale_after: float):
        if not (stale_after > 0 and math.isfinite(stale_after)):
            raise ValueError(f"stale_after {stale_after!r} s must be positive and finite")
        self.stale_after = float(stale_after)
        self.topics = list(topics)
        self._arrival: dict[str, float | None] = {t: None for t in self.topics}
        self._stamp: dict[str, float | None] = {t: None for t in self.topics}
        self.counts: dict[str, int] = {t: 0 for t in self.topics}

    def seen(self, topic: str, arrival_s: float, stamp_s: float | None = None) -> None:
        """A message on ``topic`` arrived at ``arrival_s`` (monotonic s) carrying ``stamp_s``
        (its header stamp in the rig's clock, s; None for an unstamped topic)."""
        self._arrival[topic] = arrival_s
        self._stamp[topic] = stamp_s
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def problem(self, topic: str, now_s: float, clock_s: float | None = None,
                limit: float | None = None) -> str | None:
        """Why ``topic`` is not alive at ``now_s`` (monotonic) / ``clock_s`` (the stamps' clock), or
        None; ``limit`` (s) replaces ``stale_after`` (e.g. the longer silence that ends a run)."""
        limit = self.stale_after if limit is None else limit
        arrival = self._arrival.get(topic)
        if arrival is None:
            return "no message yet"
        age = now_s - arrival
        if age > limit:
            return f"no message for {age:.2f} s (allowed {limit:g} s)"
        stamp = self._stamp.get(topic)
        if stamp is not None and clock_s is not None:
            skew = clock_s - stamp
            if stamp == 0.0:
                return "header stamp is zero (the rig must stamp each reading with the time it was taken)"
            if abs(skew) > limit:
                return (f"stamp {skew:+.2f} s off this clock (allowed {limit:g} s): a stale reading "
                        "or unsynchronised clocks")
        return None

    def problems(self, now_s: float, clock_s: float | None = None, limit: float | None = None) -> dict[str, str]:
        """Every topic that is not alive, with the reason."""
        out = {}
        for t in self.topics:
            why = self.problem(t, now_s, clock_s, limit)
            if why is not None:
                out[t] = why
        return out

    def alive(self, topic: str, now_s: float, clock_s: float | None = None) -> bool:
        return self.problem(topic, now_s, clock_s) is None


class FollowCheck:
    """Baseline at zero command for ``baseline_s``, then ``test_pressures`` (Pa per channel) until
    each commanded channel rose by ``fraction`` of its test value, or ``timeout`` s passed."""

    def __init__(self, test_pressures, timeout: float = 3.0, fraction: float = 0.5, baseline_s: float = 0.3):
        self.test_pressures = np.asarray(test_pressures, dtype=float)
        if not np.any(self.test_pressures > 0):
            raise ValueError("the follow test needs a positive test pressure on some channel")
        self.timeout, self.fraction, self.baseline_s = float(timeout), float(fraction), float(baseline_s)
        self.state = "idle"   # idle -> baseline -> rising -> passed | failed
        self.message = ""
        self._t0 = 0.0
        self._samples: list[np.ndarray] = []
        self.baseline: np.ndarray | None = None
        self.rise = np.zeros_like(self.test_pressures)

    @property
    def commanding(self) -> bool:
        """True while the test pressures are to be commanded (else zero)."""
        return self.state == "rising"

    @property
    def done(self) -> bool:
        return self.state in ("passed", "failed")

    def start(self, t: float) -> None:
        self.state, self._t0, self._samples = "baseline", t, []

    def update(self, t: float, measured) -> str:
        """Advance with the latest fresh measurement (Pa per channel, or None); returns the state."""
        if self.state == "baseline":
            if measured is not None:
                self._samples.append(np.asarray(measured, dtype=float))
            if t - self._t0 >= self.baseline_s and self._samples:
                self.baseline = np.mean(self._samples, axis=0)
                self.state, self._t0 = "rising", t
        elif self.state == "rising":
            driven = self.test_pressures > 0
            if measured is not None:
                self.rise = np.asarray(measured, dtype=float) - self.baseline
                if np.all(self.rise[driven] >= self.fraction * self.test_pressures[driven]):
                    self.state = "passed"
                    return self.state
            if t - self._t0 >= self.timeout:
                self.state = "failed"
                chans = ", ".join(f"channel {c}: commanded {self.test_pressures[c]:.0f} Pa, rose {self.rise[c]:.0f} Pa"
                                  for c in np.flatnonzero(driven))
                self.message = (f"the pressure source did not follow a test command within {self.timeout:g} s "
                                f"({chans}; needed {self.fraction:.0%} of the command)")
        return self.state


def follow_test_command(steps, level: float):
    """The follow test's command from a protocol's steps: the first step that commands a pressure,
    scaled so its largest channel gets ``level`` Pa (never more than that step asks for).
    Returns (pressures Pa per channel, bend 1/m or None)."""
    for s in steps:
        p = np.asarray(s.pressures, dtype=float)
        top = float(np.max(p))
        if top > 0:
            scale = min(1.0, level / top)
            bend = None if s.bend is None else (s.bend[0] * scale, s.bend[1] * scale)
            return p * scale, bend
    raise ValueError("the protocol commands no pressure: nothing to test the rig with")
