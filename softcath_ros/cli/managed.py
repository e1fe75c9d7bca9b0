"""The rig's managed (lifecycle) nodes brought to active by `softcath characterise` before the first
step: bench.bringup decides (configure, then activate, each node that offers lifecycle_msgs'
ChangeState service); here its requests go over the GetState / ChangeState services of the graph
supervisor's ReadyWatch node."""
from __future__ import annotations

import time

from ..core.errors import SoftcathError

MANAGED_DISCOVERY_S = 2.0   # a rig's lifecycle services are looked for this long (softcath's own nodes: until seen)
MANAGED_TIMEOUT_S = 60.0    # each managed node configured and active by then (configure opens a device)


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


def activate_managed(watch, say, discovery_s: float = MANAGED_DISCOVERY_S, timeout_s: float = MANAGED_TIMEOUT_S) -> list[str]:
    """Configure then activate every managed node of the rig (bench.bringup decides, here its
    requests go over the lifecycle_msgs GetState / ChangeState services); the nodes brought up.
    SoftcathError (one line) naming the node that fails a check, with the reason it put on
    /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from lifecycle_msgs.msg import Transition as TransitionMsg
    from lifecycle_msgs.srv import ChangeState, GetState

    from .. import topics
    from ..bench.bringup import AskState, Bringup, Transition

    node = watch.node
    start = time.monotonic()
    while True:   # discovery: services show up over a second or two (seconds on a loaded machine)
        watch.poll(0.1)
        names = _lifecycle_nodes(node)
        if time.monotonic() - start >= discovery_s and announced_managed(watch) <= set(names):
            break
        if time.monotonic() - start >= discovery_s + timeout_s:
            missing = sorted(announced_managed(watch) - set(names))
            raise SoftcathError(f"{', '.join(missing)} said it spins but its lifecycle services did not show up "
                                f"within {discovery_s + timeout_s:g} s")
    if not names:
        return []
    reasons: dict[str, str] = {}
    diag = node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, lambda m: reasons.update(
        {s.name.split(":")[0]: s.message for s in m.status if s.level == DiagnosticStatus.ERROR}), 50)
    clients = {n: (node.create_client(GetState, f"{n}/get_state"), node.create_client(ChangeState, f"{n}/change_state"))
               for n in names}
    ids = {"configure": TransitionMsg.TRANSITION_CONFIGURE, "activate": TransitionMsg.TRANSITION_ACTIVATE}
    pending = []   # (future, request)
    bring = Bringup(names, timeout_s)

    def send(requests):
        for r in requests:
            get, change = clients[r.node]
            if isinstance(r, AskState):
                pending.append((get.call_async(GetState.Request()), r))
            else:
                say(f"[characterise] {r.transition} {r.node}")
                pending.append((change.call_async(ChangeState.Request(transition=TransitionMsg(id=ids[r.transition]))), r))

    try:
        send(bring.start(time.monotonic()))
        while not bring.done:
            watch.poll(0.05)
            for item in [x for x in pending if x[0].done()]:
                pending.remove(item)
                future, r = item
                result = future.result()
                if isinstance(r, AskState):
                    send(bring.on_state(r.node, result.current_state.label))
                else:
                    if not result.success:
                        end = time.monotonic() + 1.0    # the node's reason arrives on /diagnostics at once
                        while r.node.rsplit("/", 1)[-1] not in reasons and time.monotonic() < end:
                            watch.poll(0.05)
                    send(bring.on_transition(r.node, r.transition, result.success,
                                             reasons.get(r.node.rsplit("/", 1)[-1], "")))
            bring.update(time.monotonic())
    finally:
        for get, change in clients.values():
            node.destroy_client(get)
            node.destroy_client(change)
        node.destroy_subscription(diag)
    if bring.failure:
        raise SoftcathError(bring.failure)
    return names
