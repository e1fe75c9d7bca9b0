"""Executors and the main loop every softcath node shares.

``run_node`` builds the node, spins it on the executor it names and ends with exit
code 0 on SIGINT/SIGTERM (rclpy's signal handlers shut the context down; we catch
the resulting exceptions so no traceback is printed). A node that cannot start
(bad design file, unknown model, bad parameter) logs one line and exits with 2.

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

import os
import signal
import sys
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


def set_realtime_priority(priority: int) -> str:
    """Put every thread of this process (DDS threads included) on SCHED_FIFO ``priority`` (1-99).

    Returns "" on success, else why not (no CAP_SYS_NICE / rtprio limit). Latency under a
    loaded machine is mostly waiting for a core; a real-time class removes that wait.
    Threads started later inherit the class from the thread that starts them.
    """
    import os

    try:
        for tid in os.listdir("/proc/self/task"):
            os.sched_setscheduler(int(tid), os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"cannot use SCHED_FIFO priority {priority}: {exc}"
    return ""


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


def run_node(factory: Callable, args=None, startup_errors: tuple = ()) -> int:
    """Create the node with ``factory()``, spin it on ``node.executor_name``; return the exit code.

    ``startup_errors``: exception types that mean "cannot start with this configuration";
    they are logged as one line and give exit code 2. A node that ends by itself has a
    ``finished`` property (spinning stops when it is true) and a ``finish()`` method, called on
    the way out whether it finished or was interrupted, that returns the exit code. Once the node
    spins it logs ``graph.READY_MARK`` (what ``graph.wait_ready`` waits for).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    from ..graph import READY_MARK

    # rclpy's SIGINT handler shuts the context down, which ends the spin, and then chains to the
    # handler it found: Python's, which would raise KeyboardInterrupt at whatever line runs next
    # (an except clause, the bench recording's finalisation) and print a traceback. A no-op
    # Python handler, installed before rclpy.init so rclpy still chains to it, leaves the
    # shutdown to the context alone, as for SIGTERM.
    signal.signal(signal.SIGINT, lambda signum, frame: None)
    rclpy.init(args=args)
    node = None
    name = ""
    code = 0
    try:
        try:
            node = factory()
        except startup_errors as exc:
            print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
            return 2
        name = getattr(node, "executor_name", "events")
        executor = make_executor(name)
        executor.add_node(node)
        priority = getattr(node, "realtime_priority", 0)
        if priority:
            problem = set_realtime_priority(priority)
            if problem:
                node.get_logger().warning(problem + "; running with normal scheduling")
        node.get_logger().info(f"{READY_MARK} on the {name} executor")
        ends = hasattr(type(node), "finished")
        spin(executor, name, (lambda: node.finished) if ends else None)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        # A signal can shut the context down between the loop's ok() check and the
        # executor's next wait; rcl then reports an invalid context. That is the requested
        # shutdown, not a fault: only re-raise while the context is still up.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            if hasattr(node, "finish"):
                code = node.finish()
            node.destroy_node()
        rclpy.try_shutdown()
    if name == "events":
        # rclpy 9.1's EventsExecutor can abort the process when it is destroyed ("Destroying
        # callback manager with callbacks remaining", exit -6), about once in 20 when a signal
        # comes right after start-up. Everything is finalised and shut down above, so end the
        # process here, before the executor's destructor runs.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code
