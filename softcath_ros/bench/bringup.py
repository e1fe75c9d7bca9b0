"""Bringing a rig's managed (lifecycle) nodes to active, as a pure state machine on an injected clock.

For each node: ask its state; unconfigured -> configure; inactive -> activate; active: done. A
transition that fails, a state that cannot become active (finalized) or no answer within
``timeout_s`` ends the bring-up with a one-line ``failure`` naming the node. The adapter
(characterise) performs the returned ``AskState`` / ``Transition`` requests over the lifecycle_msgs
GetState / ChangeState services and feeds the answers back (``on_state``, ``on_transition``).
"""
from __future__ import annotations

from dataclasses import dataclass

NEXT = {"unconfigured": "configure", "inactive": "activate"}


@dataclass(frozen=True)
class AskState:
    node: str


@dataclass(frozen=True)
class Transition:
    node: str
    transition: str     # "configure" | "activate"


class Bringup:
    def __init__(self, nodes: list[str], timeout_s: float = 30.0):
        self.nodes, self.timeout_s = list(nodes), timeout_s
        self.active: set[str] = set()
        self.failure: str | None = None
        self.t0: float | None = None

    @property
    def done(self) -> bool:
        return self.failure is not None or self.active >= set(self.nodes)

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
        if state == "active":
            self.active.add(node)
            return []
        if state in NEXT:
            return [Transition(node, NEXT[state])]
        return self._fail(f"{node} is {state}: it cannot be activated (restart it)")

    def on_transition(self, node: str, transition: str, ok: bool, why: str = "") -> list:
        if self.done:
            return []
        if not ok:
            return self._fail(f"{node} failed to {transition}" + (f": {why}" if why else ""))
        return [AskState(node)]

    def update(self, now: float) -> list:
        if not self.done and now - self.t0 >= self.timeout_s:
            waiting = [n for n in self.nodes if n not in self.active]
            self._fail(f"{', '.join(waiting)} not active after {self.timeout_s:g} s (no answer to its lifecycle "
                       "services)")
        return []
