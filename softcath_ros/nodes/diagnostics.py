"""Counting checked inputs and reporting them on /diagnostics (diagnostic_msgs/DiagnosticArray).

A node keeps one ``InputCounters`` per input stream, bumps it per message (cheap:
plain ints) and lets a ``DiagnosticsReporter`` timer publish the totals periodically.
Level: OK while everything since the last report was accepted, WARN when something
was clamped, rejected, failed in the model or superseded by a newer command before it was
answered since then.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from .. import topics


class ThrottledLog:
    """A node's warnings and errors about bad inputs, at most one per ``period`` seconds per
    ``site`` (a name of the call site), checked before rclpy is called: rclpy's own
    ``throttle_duration_sec`` looks up the caller's source file first (0.2-0.3 ms a call), which a
    stream of refused commands at 1 kHz would pay on every one."""

    def __init__(self, logger, period: float, clock=time.monotonic):
        self._logger, self._period, self._clock = logger, float(period), clock
        self._last: dict[str, float] = {}

    def _due(self, site: str) -> bool:
        now = self._clock()
        if now - self._last.get(site, -math.inf) < self._period:
            return False
        self._last[site] = now
        return True

    def warning(self, site: str, text: str) -> None:
        if self._due(site):
            self._logger.warning(text)

    def error(self, site: str, text: str) -> None:
        if self._due(site):
            self._logger.error(text)


def diagnostic_status(level, name: str, message: str, values, hardware_id: str = ""):
    """A DiagnosticStatus; ``values``: (key, text) pairs or a mapping of them."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    items = values.items() if isinstance(values, dict) else values
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=str(v)) for k, v in items])


def publish_statuses(node, publisher, *statuses) -> None:
    """One DiagnosticArray of ``statuses``, stamped with the node's clock now."""
    from diagnostic_msgs.msg import DiagnosticArray

    msg = DiagnosticArray(status=list(statuses))
    msg.header.stamp = node.get_clock().now().to_msg()
    publisher.publish(msg)


@dataclass
class InputCounters:
    accepted: int = 0        # commands that produced a published result (clamped ones included)
    rejected: int = 0        # bad input: nothing published
    clamped: int = 0         # out of range, clamped into the limits and then used
    model_failed: int = 0    # valid input, but the model did not converge / gave non-finite numbers
    superseded: int = 0      # replaced by a newer command before it was answered (the newest is answered)
    last_reason: str = ""    # why the most recent command was rejected, clamped or failed
    extra: dict = field(default_factory=dict)  # fixed key/values shown with the counters

    def problems(self) -> int:
        return self.rejected + self.clamped + self.model_failed + self.superseded

    def key_values(self) -> list[tuple[str, str]]:
        kv = [("accepted", str(self.accepted)), ("rejected", str(self.rejected)),
              ("clamped", str(self.clamped)), ("model_failed", str(self.model_failed)),
              ("superseded", str(self.superseded)),
              ("last_reason", self.last_reason)]
        return kv + [(k, str(v)) for k, v in self.extra.items()]


class DiagnosticsReporter:
    """Publishes ``counters`` on /diagnostics every ``period`` seconds from ``node``'s timer."""

    def __init__(self, node, counters: InputCounters, status_name: str, hardware_id: str,
                 period: float = 1.0, topic: str = topics.DIAGNOSTICS, answer_load=None):
        """``answer_load`` (core.answer_load.AnswerLoad), when given, adds a second status
        saying whether the node keeps up with its commands (WARN when it falls behind)."""
        from diagnostic_msgs.msg import DiagnosticArray

        self._node = node
        self._counters = counters
        self._name = status_name
        self._hardware_id = hardware_id
        self._pub = node.create_publisher(DiagnosticArray, topic, 10)
        self._problems_at_last_report = 0
        self._answer_load = answer_load
        self._timer = node.create_timer(period, self.publish)

    def publish(self) -> None:
        from diagnostic_msgs.msg import DiagnosticStatus

        c = self._counters
        new_problems = c.problems() - self._problems_at_last_report
        self._problems_at_last_report = c.problems()
        if new_problems:
            level, message = (DiagnosticStatus.WARN, f"{new_problems} command(s) rejected, clamped, failed or "
                              f"superseded: {c.last_reason}")
        else:
            level, message = DiagnosticStatus.OK, "all commands since the last report accepted"
        status = diagnostic_status(level, self._name, message, c.key_values(), self._hardware_id)
        extra = [self._load_status()] if self._answer_load is not None else []
        publish_statuses(self._node, self._pub, status, *extra)

    def _load_status(self):
        import time

        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        r = self._answer_load.report(time.monotonic())
        if r.behind:
            level = DiagnosticStatus.WARN
            message = (f"falling behind: busy {r.busy_fraction:.0%} of the time answering "
                       f"{r.command_rate_hz:.0f} commands/s; this rung sustains about {r.max_rate_hz:.0f}/s")
        else:
            level, message = DiagnosticStatus.OK, f"keeping up: busy {r.busy_fraction:.0%} of the time"
        values = {"commands_per_s": f"{r.command_rate_hz:.1f}", "mean_answer_ms": f"{r.mean_answer_s * 1e3:.3f}",
                  # no answer in the window: no rate measured (never 'inf' on the wire)
                  "max_rate_hz": f"{r.max_rate_hz:.1f}" if math.isfinite(r.max_rate_hz) else "n/a", "busy_fraction": f"{r.busy_fraction:.3f}",
                  "behind": str(r.behind).lower()}
        return DiagnosticStatus(level=level, name=f"{self._name} (answer load)", message=message,
                                hardware_id=self._hardware_id,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])
