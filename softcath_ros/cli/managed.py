"""The managed (lifecycle) nodes of a run, driven by `softcath characterise`: the rig's nodes brought
to active before bench_node starts, then bench_node itself (configure checks the rig, activate runs
the protocol) and, to stop it early, deactivate (it vents) then shutdown. bench.bringup decides;
here its requests go over the GetState / ChangeState services of the graph supervisor's ReadyWatch
node."""
from __future__ import annotations

import signal
import subprocess
import time
from typing import Callable

from .. import topics
from ..core.errors import SoftcathError
from ..graph import stop_process

BENCH_NODE = "/" + topics.BENCH_NODE   # bench_node's lifecycle services live under its name
MANAGED_DISCOVERY_S = 2.0   # a rig's lifecycle services are looked for this long (softcath's own nodes: until seen)
MANAGED_TIMEOUT_S = 60.0    # each managed node configured and active by then (configure opens a device)
TEARDOWN_TIMEOUT_S = 5.0    # deactivate + shutdown answered by then, else the caller falls back to a signal


def _lifecycle_nodes(node) -> list[str]:
    """The managed nodes on the graph: those offering lifecycle_msgs' ChangeState service."""
    suffix = "/change_state"
    return sorted(name[:-len(suffix)] for name, types in node.get_service_names_and_types()
                  if name.endswith(suffix) and "lifecycle_msgs/srv/ChangeState" in types)


def announced_managed(watch) -> set[str]:
    """The managed nodes that said they spin on the watch's domain (nodes/runtime.announce_ready):
    their services are waited for however long discovery takes (a third-party node is found only
    within the discovery window)."""
    return {info["node"] for info in watch.ready.values() if info.get("managed") and isinstance(info.get("node"), str)}


def _discover(watch, names: list[str] | None, exclude: tuple, discovery_s: float, timeout_s: float) -> list[str]:
    """``names`` once all offer their services, or every managed node seen within ``discovery_s`` but
    those in ``exclude`` (and at least those that said they spin); SoftcathError after
    ``discovery_s + timeout_s`` naming the ones whose services did not show up."""
    start = time.monotonic()
    while True:   # discovery: services show up over a second or two (seconds on a loaded machine)
        watch.poll(0.1)
        found = set(_lifecycle_nodes(watch.node))
        wanted = set(names) if names is not None else announced_managed(watch) - set(exclude)
        elapsed = time.monotonic() - start
        if wanted <= found and (names is not None or elapsed >= discovery_s):
            return list(names) if names is not None else sorted(found - set(exclude))
        if elapsed >= discovery_s + timeout_s:
            raise SoftcathError(f"{', '.join(sorted(wanted - found))} said it spins but its lifecycle services "
                                f"did not show up within {discovery_s + timeout_s:g} s")


def activate_managed(watch, say, discovery_s: float = MANAGED_DISCOVERY_S, timeout_s: float = MANAGED_TIMEOUT_S,
                     names: list[str] | None = None, exclude: tuple = (),
                     ended: Callable[[str], bool] = lambda n: False) -> list[str]:
    """Configure then activate ``names`` (default: every managed node on the graph but ``exclude``;
    ``ended(name)``: its process is gone); the nodes brought up. SoftcathError (one line) naming the node that fails a check, with the
    reason it put on /diagnostics."""
    from ..bench.bringup import Bringup

    names = _discover(watch, names, exclude, discovery_s, timeout_s)
    if names:
        failure = _drive(watch, say, Bringup(names, timeout_s), ended)
        if failure:
            raise SoftcathError(failure)
    return names


def activate_rig(watch, say, readings: list[list[str]], wait_timeout: float,
                 discovery_s: float = MANAGED_DISCOVERY_S) -> list[str]:
    """The rig's managed nodes (all but bench_node) brought to active, looked for again until one of
    ``readings`` (lists of topics: the contract's, the deprecated ones) has a publisher on every topic
    or ``wait_timeout`` s pass: an unconfigured node publishes nothing, and on a loaded machine its
    services can show up after the first discovery window. bench_node's configure then names what is
    still missing. The nodes brought up."""
    brought: list[str] = []
    end = time.monotonic() + wait_timeout
    while True:
        brought += activate_managed(watch, say, discovery_s=discovery_s, exclude=(BENCH_NODE, *brought))
        if any(all(watch.node.count_publishers(t) for t in topics_) for topics_ in readings) \
                or time.monotonic() >= end:
            return brought


def shutdown_managed(watch, say, names: list[str], ended: Callable[[str], bool],
                     timeout_s: float = TEARDOWN_TIMEOUT_S) -> str | None:
    """Deactivate then shut down ``names`` (``ended(name)``: its process is gone, nothing to ask);
    the one-line failure (no answer, a refused transition) or None."""
    from ..bench.bringup import Teardown

    return _drive(watch, say, Teardown(names, timeout_s), ended)


def bring_up_bench(watch, bench: subprocess.Popen, wait_timeout: float, say) -> None:
    """bench_node, started unconfigured: configure (it checks the rig, up to ``wait_timeout``), then
    activate (it runs). A failed check is one of the checks before the first step: exit 3 (docs/rig.md)."""
    from ..bench.rig_contract import NoRig

    try:
        activate_managed(watch, say, names=[BENCH_NODE], timeout_s=MANAGED_TIMEOUT_S + wait_timeout,
                         ended=lambda n: bench.poll() is not None)
    except SoftcathError as exc:
        raise NoRig(str(exc)) from None


def stop_bench(watch, bench: subprocess.Popen, lifecycle: bool, say, wait_s: float | None = None) -> None:
    """bench_node stops early (it vents, marks the recording incomplete, exits): deactivate then shutdown
    when it was brought up, SIGINT when it was not or its lifecycle services do not answer. ``wait_s``:
    wait that long for it to end (it finalises its recording), then SIGINT and a kill after 5 s."""
    if lifecycle and bench.poll() is None:
        failure = shutdown_managed(watch, say, [BENCH_NODE], ended=lambda n: bench.poll() is not None)
        if failure is not None:
            say(f"[characterise] {failure}; stopping bench_node by SIGINT")
            lifecycle = False
    if not lifecycle and bench.poll() is None:
        bench.send_signal(signal.SIGINT)
    if wait_s is not None:
        try:
            bench.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            stop_process(bench, 5.0)


def _drive(watch, say, machine, ended: Callable[[str], bool]) -> str | None:
    """Perform ``machine``'s (bench.bringup) requests until it is done; its failure or None."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from lifecycle_msgs.msg import Transition as TransitionMsg
    from lifecycle_msgs.srv import ChangeState, GetState

    from ..bench.bringup import AskState

    node = watch.node
    reasons: dict[str, str] = {}
    diag = node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, lambda m: reasons.update(
        {s.name.split(":")[0]: s.message for s in m.status if s.level == DiagnosticStatus.ERROR}), 50)
    clients = {n: (node.create_client(GetState, f"{n}/get_state"), node.create_client(ChangeState, f"{n}/change_state"))
               for n in machine.nodes}
    ids = {"configure": TransitionMsg.TRANSITION_CONFIGURE, "activate": TransitionMsg.TRANSITION_ACTIVATE,
           "deactivate": TransitionMsg.TRANSITION_DEACTIVATE,
           "shutdown": TransitionMsg.TRANSITION_INACTIVE_SHUTDOWN}
    shutdown_from = {"unconfigured": TransitionMsg.TRANSITION_UNCONFIGURED_SHUTDOWN}
    pending = []   # (future, request)
    states: dict[str, str] = {}

    def send(requests):
        for r in requests:
            get, change = clients[r.node]
            if isinstance(r, AskState):
                pending.append((get.call_async(GetState.Request()), r))
            else:
                say(f"[characterise] {r.transition} {r.node}")
                tid = shutdown_from.get(states.get(r.node), ids[r.transition]) if r.transition == "shutdown" \
                    else ids[r.transition]
                pending.append((change.call_async(ChangeState.Request(transition=TransitionMsg(id=tid))), r))

    def reason_of(n: str) -> str:
        return reasons.get(n.rsplit("/", 1)[-1], "")

    try:
        send(machine.start(time.monotonic()))
        while not machine.done:
            watch.poll(0.05)
            for n in machine.nodes:
                if n not in machine.reached and ended(n):
                    machine.on_ended(n)
            for item in [x for x in pending if x[0].done()]:
                pending.remove(item)
                future, r = item
                result = future.result()
                if isinstance(r, AskState):
                    states[r.node] = result.current_state.label
                    send(machine.on_state(r.node, result.current_state.label))
                else:
                    if not result.success:
                        end = time.monotonic() + 1.0    # the node's reason arrives on /diagnostics at once
                        while not reason_of(r.node) and time.monotonic() < end:
                            watch.poll(0.05)
                    send(machine.on_transition(r.node, r.transition, result.success, reason_of(r.node)))
            machine.update(time.monotonic())
    finally:
        for get, change in clients.values():
            node.destroy_client(get)
            node.destroy_client(change)
        node.destroy_subscription(diag)
    return machine.failure
