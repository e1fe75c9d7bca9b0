"""The executors a node can spin on, the spin loop, and taking every waiting message at once.

Executors (``benchmarks/node_latency.py`` compares them):
- ``events``: rclpy.experimental.EventsExecutor, C++ event queue, lowest overhead.
  Its ``spin()`` in rclpy 9.1 (PyPI wheels) never dispatches a callback here, so we
  drive it with ``spin_once(timeout)``, which works and wakes on shutdown.
  It does not pass MessageInfo to subscription callbacks.
- ``single``: rclpy's SingleThreadedExecutor (Python wait-set loop).
- ``multi``: rclpy's MultiThreadedExecutor (thread pool; callbacks in one mutually
  exclusive group unless the node says otherwise).
"""
from __future__ import annotations

import time
from typing import Callable

EXECUTORS = ("events", "single", "multi")


def make_executor(name: str):
    """The executor called ``name`` (one of ``EXECUTORS``)."""
    if name == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    if name == "single":
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor()
    if name == "multi":
        from rclpy.executors import MultiThreadedExecutor

        return MultiThreadedExecutor()
    raise ValueError(f"executor {name!r} is not one of {EXECUTORS}")


def take_waiting(subscription) -> list[tuple[object, float]]:
    """Every message waiting in ``subscription``, oldest first, each with when it arrived in
    time.monotonic seconds (the middleware's reception stamp; now where it gives none). The
    executor then finds nothing to take for their events and skips them."""
    # rclpy has no public call that drains a subscription's queue; Subscription.handle.take_message
    # is what its executors call for each message, so it is used here the same way.
    taken = []
    with subscription.handle:
        while True:
            got = subscription.handle.take_message(subscription.msg_type, subscription.raw)
            if got is None:
                break
            taken.append(got)
    now, wall_ns = time.monotonic(), time.time_ns()
    out = []
    for msg, info in taken:
        received = int((info or {}).get("received_timestamp", 0) or 0)
        out.append((msg, now - max(wall_ns - received, 0) * 1e-9 if received > 0 else now))
    return out


def spin(executor, name: str, finished: Callable[[], bool] | None = None) -> None:
    """Run callbacks until the context shuts down (SIGINT/SIGTERM or rclpy.shutdown()) or, for a
    node that ends by itself (a bench run), until ``finished()``."""
    if name == "events" or finished is not None:
        context = executor.context
        done = finished or (lambda: False)
        while context.ok() and not done():
            executor.spin_once(timeout_sec=0.05 if finished is not None else 0.5)
    else:
        executor.spin()
