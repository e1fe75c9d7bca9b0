"""Is a node keeping up with its command stream? (pure bookkeeping, no ROS)

A node cannot see commands still waiting in its queue, only those it handles, so
"commands arrive faster than the rung answers" shows as the handler being busy
nearly all the time: back-to-back callbacks. ``AnswerLoad`` adds up the time spent
answering within each reporting window; a busy fraction at or above ``behind_at``
means the node is at capacity and falling behind (answers come late, and old
commands are dropped once the queue depth is reached).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LoadReport:
    commands: int                  # commands answered in the window
    window_s: float                # wall time of the window, s
    command_rate_hz: float         # commands answered per second
    mean_answer_s: float           # mean time to answer one command, s (0 when none)
    max_rate_hz: float             # 1 / mean_answer_s: the most this rung sustains (inf when none)
    busy_fraction: float           # time spent answering / window
    behind: bool                   # busy_fraction >= behind_at


class AnswerLoad:
    def __init__(self, start_s: float, behind_at: float = 0.9):
        if not 0.0 < behind_at <= 1.0:
            raise ValueError(f"behind_at = {behind_at}: must lie in (0, 1]")
        self.behind_at = behind_at
        self._start = start_s
        self._commands = 0
        self._busy = 0.0

    def record(self, answer_s: float) -> None:
        """One command answered, taking ``answer_s`` seconds of the handler's time."""
        self._commands += 1
        self._busy += answer_s

    def report(self, now_s: float) -> LoadReport:
        """Figures for the window since the last report; starts a new window."""
        window = max(now_s - self._start, 1e-9)
        n, busy = self._commands, self._busy
        mean = busy / n if n else 0.0
        busy_fraction = min(busy / window, 1.0)
        self._start, self._commands, self._busy = now_s, 0, 0.0
        return LoadReport(commands=n, window_s=window, command_rate_hz=n / window, mean_answer_s=mean,
                          max_rate_hz=(1.0 / mean) if mean > 0 else float("inf"),
                          busy_fraction=busy_fraction, behind=busy_fraction >= self.behind_at)
