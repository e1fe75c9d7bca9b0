"""The run of a bench protocol as a pure state machine on an injected clock (bench_node adapts it).

waiting (for the rig) -> checking (the pressure source follows a test command) -> running (the
protocol) -> finishing (zero command, so the last readings are recorded) -> done. ``tick(now, rig)``
advances it with what the adapter observed (``rig``: a ``RigView``) and returns the actions the
adapter performs, in order: ``Begin`` (write the recording's metadata, then call ``begin`` or
``fail``), ``Command``, ``Vent``, ``VentDirectly``, ``Markers``, ``Say``. No rclpy, no threads, no
sleeping: tests drive it with a fake clock (test/test_bench_run.py).

Exit codes (docs/rig.md): 3 no rig or it failed the checks before the first step, 4 another node
commands the pressures, 5 the rig stopped answering mid-run, 6 the recording failed.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np

EXIT_NO_RIG, EXIT_FIGHT, EXIT_RIG_LOST, EXIT_RECORDING = 3, 4, 5, 6
VENT_S = 0.5        # zero command this long at the end, so the last readings are recorded
ABORT_VENT_S = 0.3  # after an abort: the rig is gone or failing; stop within 2 s of its death


class RunState(Enum):
    WAITING = "waiting"
    CHECKING = "checking"
    RUNNING = "running"
    FINISHING = "finishing"
    DONE = "done"


class RigView(Protocol):
    """What the adapter observes of the rig, asked for only when the run needs it."""

    def problems(self) -> dict[str, str]:
        """What keeps the rig from being ready, by topic (empty: ready)."""

    def stale(self, lost_after: float) -> dict[str, str]:
        """Rig topics stale for ``lost_after`` s, by topic."""

    def measured(self):
        """Fresh measured pressures (Pa per channel) or None."""

    def recording_error(self) -> str | None:
        ...

    def other_commanders(self) -> list[str]:
        """Nodes that publish the pressure command besides the allowed one."""


@dataclass(frozen=True)
class Begin:
    """The rig is ready: check for other commanders, write the metadata, then ``begin``/``fail``."""


@dataclass(frozen=True)
class Command:
    pressures: np.ndarray
    bend: tuple[float, float] | None


@dataclass(frozen=True)
class Vent:
    """Zero command (and on the direct vent publisher, if one was opened)."""


@dataclass(frozen=True)
class VentDirectly:
    """Open a publisher of the pressure command of one's own (allocation_node may be dead)."""


@dataclass(frozen=True)
class Markers:
    events: list


@dataclass(frozen=True)
class Say:
    level: str      # "info" | "warning" | "error"
    text: str


class BenchRun:
    def __init__(self, runner, follow, follow_bend, n_channels: int, by_direction: bool,
                 wait_timeout: float, start_delay: float, lost_after: float):
        self.runner, self.follow, self.follow_bend = runner, follow, follow_bend
        self.n_channels, self.by_direction = n_channels, by_direction
        self.wait_timeout, self.start_delay, self.lost_after = wait_timeout, start_delay, lost_after
        self.state = RunState.WAITING
        self.t_ready: float | None = None
        self.t_last_tick = 0.0
        self.t_end: float | None = None
        self.vent_s = VENT_S
        self.completed_steps = 0
        self.result = 0
        self.error: str | None = None
        self.stop_reason = ""
        self.vents_directly = False

    @property
    def n_steps(self) -> int:
        return len(self.runner.steps)

    @property
    def done(self) -> bool:
        return self.state is RunState.DONE

    @property
    def commanding(self) -> bool:
        """Commands were or are being sent (another commander then means a fight)."""
        return self.state in (RunState.CHECKING, RunState.RUNNING)

    # -------------------------------------------------------------- transitions
    def begin(self, now: float) -> list:
        """The adapter wrote the recording's metadata: test that the pressure source follows."""
        self.state = RunState.CHECKING
        self.follow.start(now)
        return []

    def fail(self, message: str, code: int) -> list:
        """Stop before anything was commanded: no venting needed."""
        self.error = self.stop_reason = message
        self.result = code
        self.state = RunState.DONE
        return [Say("error", message)]

    def abort(self, now: float, message: str, code: int) -> list:
        """Stop after commands were sent: the abort marker, then zero command for ABORT_VENT_S."""
        if self.error is not None:
            return []
        self.error = self.stop_reason = message
        self.result = code
        step = self.runner.step
        out = [Say("error", message), Markers([{
            "event": "protocol_abort", "t": now, "reason": message, "completed_steps": self.completed_steps,
            "step": step.index if step else None}])]
        if self.by_direction and not self.vents_directly:
            self.vents_directly = True
            out.append(VentDirectly())
        self.state = RunState.FINISHING
        self.t_end = now
        self.vent_s = ABORT_VENT_S
        return out

    def _markers(self, events: list) -> list:
        self.completed_steps += sum(ev["event"] == "step_end" for ev in events)
        return [Markers(events)] if events else []

    def _zero(self) -> np.ndarray:
        return np.zeros(self.n_channels)

    def tick(self, now: float, rig: RigView) -> list:
        # A tick long after the previous one: the process was not scheduled, and the readings that
        # arrived meanwhile are still queued behind this tick. Judge freshness at the next tick.
        starved, self.t_last_tick = now - self.t_last_tick > 0.25 * self.lost_after, now
        if self.state is RunState.WAITING:
            return self._wait(now, rig)
        if self.commanding:
            error = rig.recording_error()
            if error is not None:
                return self.abort(now, f"recording failed: {error}", EXIT_RECORDING)
            stale = {} if starved else rig.stale(self.lost_after)
            if stale:
                what = "; ".join(f"{k}: {v}" for k, v in stale.items())
                if self.state is RunState.CHECKING:
                    return self.abort(now, f"rig not ready for the first step: {what}", EXIT_NO_RIG)
                return self.abort(now, f"the rig stopped answering at step {self.runner.step.index + 1}/"
                                  f"{self.n_steps} ({what}): stopped and vented; {self.completed_steps} "
                                  "steps completed", EXIT_RIG_LOST)
        if self.state is RunState.CHECKING:
            return self._check(now, rig)
        if self.state is RunState.RUNNING:
            out = self._markers(self.runner.update(now, rig.measured()))
            out.append(Command(self.runner.command, self.runner.bend_command))
            if self.runner.done:
                self.state, self.t_end = RunState.FINISHING, now
            return out
        if self.state is RunState.FINISHING:
            if now - self.t_end > self.vent_s:  # the last readings and markers reach the recorder
                self.state = RunState.DONE
            return [Vent()]
        return []

    def _wait(self, now: float, rig: RigView) -> list:
        problems = rig.problems()
        if not problems:
            if self.t_ready is None:
                self.t_ready = now  # let late discovery (subscriptions, recorder) settle
            elif now - self.t_ready >= self.start_delay:
                return [Begin()]
            return []
        self.t_ready = None
        if now > self.wait_timeout:
            return self.fail(f"no rig after {self.wait_timeout:g} s: " + "; ".join(
                f"{k}: {v}" for k, v in problems.items()) + " (start sim_bench_node or the rig's driver; "
                "docs/rig.md)", EXIT_NO_RIG)
        return []

    def _check(self, now: float, rig: RigView) -> list:
        state = self.follow.update(now, rig.measured())
        if state == "passed":
            self.state = RunState.RUNNING
            return [Say("info", f"the pressure source followed the test command ({self.follow.rise.max():.0f} Pa "
                                "rise); starting protocol")] + self._markers(self.runner.start(now))
        if state == "failed":
            others = rig.other_commanders()
            if others:  # the likely reason the source did not follow
                return self.abort(now, f"{', '.join(others)} also publish(es) /softcath/pressure_cmd: "
                                  f"{self.follow.message}", EXIT_FIGHT)
            return self.abort(now, self.follow.message, EXIT_NO_RIG)
        on = self.follow.commanding
        return [Command(self.follow.test_pressures if on else self._zero(),
                        self.follow_bend if on and self.follow_bend else (0.0, 0.0))]
