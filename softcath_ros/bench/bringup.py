"""Driving a rig's managed (lifecycle) nodes, as pure state machines on an injected clock.

``Bringup`` (to active): for each node ask its state; unconfigured -> configure; inactive ->
activate; active: done. ``Teardown`` (to finalized): active -> deactivate; inactive or
unconfigured -> shutdown; finalized, or the node's process ended (``on_ended``: bench_node ends
itself once deactivated): done. A transition that fails, a state the goal cannot be reached from
or no answer within ``timeout_s`` ends it with a one-line ``failure`` naming the node. The adapter
(cli/managed.py) performs the returned ``AskState`` / ``Transition`` requests over the
lifecycle_msgs GetState / ChangeState services and feeds the answers back (``on_state``,
``on_transition``).
"""
from __future__ import annotations

from dataclasses import dataclass

UP = {"unconfigured": "configure", "inactive": "activate"}
DOWN = {"active": "deactivate", "inactive": "shutdown", "unconfigured": "shutdown"}


@dataclass(frozen=True)
class AskState:
    node: str


@dataclass(frozen=True)
class Transition:
    node: str
    transition: str     # "configure" | "activate" | "deactivate" | "shutdown"


class Bringup:
    goal, steps, verb = "active", UP, "activated"

    def __init__(self, nodes: list[str], timeout_s: float = 30.0):
        self.nodes, self.timeout_s = list(nodes), timeout_s
        self.reached: set[str] = set()
        self.failure: str | None = None
        self.t0: float | None = None

    @property
    def active(self) -> set[str]:
        return self.reached

    @property
    def done(self) -> bool:
        return self.failure is not None or self.reached >= set(self.nodes)

    def start(self, now: float) -> list:
        self.t0 = now
        return [AskState(n) for n in self.nodes]

    def _fail(self, message: str) -> list:
        if self.failure is None:
            self.failure = message
        return []

    def on_state(self, node: str, state: str) -> list:
        if self.done:
            return []
        if state == self.goal:
            self.reached.add(node)
            return []
        if state in self.steps:
            return [Transition(node, self.steps[state])]
        return self._fail(f"{node} is {state}: it cannot be {self.verb} (restart it)")

    def on_transition(self, node: str, transition: str, ok: bool, why: str = "") -> list:
        if self.done:
            return []
        if not ok:
            return self._fail(f"{node} failed to {transition}" + (f": {why}" if why else ""))
        return [AskState(node)]

    def on_ended(self, node: str) -> list:
        """The node's process ended: nothing more to ask it."""
        if self.goal == "finalized":
            self.reached.add(node)
            return []
        return self._fail(f"{node} ended before it was {self.verb}")

    def update(self, now: float) -> list:
        if not self.done and now - self.t0 >= self.timeout_s:
            waiting = [n for n in self.nodes if n not in self.reached]
            self._fail(f"{', '.join(waiting)} not {self.goal} after {self.timeout_s:g} s (no answer to its "
                       "lifecycle services)")
        return []


class Teardown(Bringup):
    goal, steps, verb = "finalized", DOWN, "shut down"
