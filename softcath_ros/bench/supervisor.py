"""`softcath characterise`'s supervision of its node graph as a pure state machine on an injected clock.

helpers (the rig, model_node, allocation_node: each waited for until it says it spins, at most
``helper_ready_s``) -> bench (bench_node, started unconfigured, is brought up through its lifecycle
once it spins, then runs the protocol) -> done (bench_node ended). ``update(now,
ready, exited, bench_has_output)`` takes what the adapter observed (node names that said they spin,
exit codes of the ended ones, whether bench_node made its recording's folder) and returns commands:
``StartBench``, ``BringUpBench`` (configure: it checks the rig, then activate), ``StopBench``
(deactivate then shutdown once it was brought up, else SIGINT; ``KillBench`` follows when it
outlives its grace), ``Say``, ``Fail``. No rclpy, no threads, no sleeping (test/test_graph_supervisor.py drives it).

What it decides:
- the watchdog: bench_node still running ``timeout_s`` after its start is stopped (``timed_out``);
- a bench_node hung before it spins (a DDS start-up hang seen under load: it has not said it spins nor
  made its recording's folder after ``bench_ready_s``) is stopped and started once more;
- a helper that ends while bench_node runs: bench_node gets the helper's grace (``child_grace``) to
  notice by itself (a rig's topics go stale), then it is stopped; ``died`` says who and how.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

BENCH = "bench_node"
STOP_GRACE_S = 15.0         # a bench_node stopped by the watchdog or a death finalises its recording
STALLED_STOP_GRACE_S = 5.0  # a hung one has nothing to finalise


class GraphState(Enum):
    HELPERS = "helpers"
    BENCH = "bench"
    DONE = "done"


@dataclass(frozen=True)
class StartBench:
    attempt: int


@dataclass(frozen=True)
class BringUpBench:
    """bench_node spins: configure it (it checks the rig) and activate it (it runs)."""


@dataclass(frozen=True)
class StopBench:
    """Stop bench_node (it vents and finalises its recording): by its lifecycle (deactivate, then
    shutdown) when it was brought up, else SIGINT."""
    lifecycle: bool = False


@dataclass(frozen=True)
class KillBench:
    """bench_node outlived its grace after StopBench."""


@dataclass(frozen=True)
class Say:
    text: str


@dataclass(frozen=True)
class Fail:
    """A helper ended before it was ready: the run cannot go on."""
    node: str
    code: int


@dataclass
class GraphSupervisor:
    helpers: list[str]
    timeout_s: float
    helper_ready_s: float = 60.0
    bench_ready_s: float = 60.0
    child_grace: dict[str, float] = field(default_factory=dict)
    default_grace_s: float = 1.5

    def __post_init__(self):
        self.state = GraphState.HELPERS
        self.t0: float | None = None
        self.attempt = 0
        self.brought_up = 0                  # the attempt whose bench_node was brought up
        self.t_bench = 0.0
        self.timed_out = self.stalled = False
        self.died: list[str] = []
        self.stop_at: float | None = None    # a helper died: stop bench_node at this time
        self.kill_at: float | None = None    # bench_node was stopped: kill it at this time

    def _start_bench(self, now: float) -> list:
        self.state, self.t_bench = GraphState.BENCH, now
        self.attempt += 1
        self.stalled, self.kill_at = False, None
        return [StartBench(self.attempt)]

    def _stop(self, now: float, grace_s: float) -> list:
        if self.kill_at is not None:
            return []
        self.kill_at = now + grace_s
        return [StopBench(lifecycle=self.brought_up == self.attempt)]

    def update(self, now: float, ready: set[str], exited: dict[str, int], bench_has_output: bool = False) -> list:
        if self.t0 is None:
            self.t0 = now
        if self.state is GraphState.HELPERS:
            return self._helpers(now, ready, exited)
        if self.state is GraphState.BENCH:
            return self._bench(now, ready, exited, bench_has_output)
        return []

    def _helpers(self, now: float, ready: set[str], exited: dict[str, int]) -> list:
        waiting = [h for h in self.helpers if h not in ready]
        for h in waiting:
            if h in exited:
                self.state = GraphState.DONE
                return [Fail(h, exited[h])]
        if waiting and now - self.t0 < self.helper_ready_s:
            return []
        says = [Say(f"{h} is not spinning after {self.helper_ready_s:g} s; starting bench_node anyway: the "
                    "recording may lack its output") for h in waiting]
        return says + self._start_bench(now)

    def _bench(self, now: float, ready: set[str], exited: dict[str, int], bench_has_output: bool) -> list:
        if BENCH in exited:
            if self.stalled and self.attempt == 1 and not self.timed_out and not self.died:
                return [Say(f"bench_node was not spinning after {self.bench_ready_s:g} s (a DDS start-up hang); "
                            "stopped and started again")] + self._start_bench(now)
            self.state = GraphState.DONE
            return []
        if self.kill_at is not None:
            return [KillBench()] if now >= self.kill_at else []
        if BENCH in ready and self.brought_up < self.attempt:
            self.brought_up = self.attempt
            return [BringUpBench()]
        if now - self.t_bench >= self.timeout_s:
            self.timed_out = True
            return self._stop(now, STOP_GRACE_S)
        if (self.attempt == 1 and BENCH not in ready and not bench_has_output
                and now - self.t_bench >= self.bench_ready_s):
            self.stalled = True
            return self._stop(now, STALLED_STOP_GRACE_S)
        if not self.died:
            for h in self.helpers:
                if h in exited:
                    self.died.append(f"{h} exited ({exited[h]})")
                    self.stop_at = now + self.child_grace.get(h, self.default_grace_s)
                    break
        if self.stop_at is not None and now >= self.stop_at:
            return self._stop(now, STOP_GRACE_S)
        return []
