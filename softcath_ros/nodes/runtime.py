"""Executors and the main loop every softcath node shares.

``run_node`` builds the node, spins it on the executor it names and ends with exit
code 0 on SIGINT/SIGTERM (rclpy's signal handlers shut the context down; we catch
the resulting exceptions so no traceback is printed). A node that cannot start
(bad design file, unknown model, bad parameter, a parameter it does not declare, a params file
with no section for it) logs one line and exits with 2.

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
import time
from contextlib import contextmanager
from typing import Callable

from ..core.errors import SoftcathError, shown

EXECUTORS = ("events", "single", "multi")
_started_argv: list[str] = []     # the command line run_node started this process's node with


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


INT64 = (-2**63, 2**63 - 1)


def ros_arguments(argv: list[str]) -> list[str]:
    """The ROS arguments in ``argv``: everything between ``--ros-args`` and ``--`` (or the end)."""
    out, inside = [], False
    for a in argv:
        if a == "--ros-args":
            inside = True
        elif a == "--" and inside:
            inside = False
        elif inside:
            out.append(a)
    return out


def params_files(argv: list[str]) -> list[str]:
    """The ``--params-file PATH`` arguments among the ROS arguments of ``argv``."""
    ros = ros_arguments(argv)
    return [ros[i + 1] if i + 1 < len(ros) else "" for i, a in enumerate(ros) if a == "--params-file"]


_start_interruptible = [False]
_sigint_seen = [False]


def _on_sigint(signum, frame) -> None:
    _sigint_seen[0] = True
    if _start_interruptible[0]:
        _start_interruptible[0] = False
        raise KeyboardInterrupt


@contextmanager
def interruptible_start():
    """Long start-up work (a rung building its table) that SIGINT stops at once, also a SIGINT that
    came just before it: run_node ends the process cleanly (exit 0, one line) instead of letting
    the build finish first."""
    if _sigint_seen[0]:
        raise KeyboardInterrupt
    _start_interruptible[0] = True
    try:
        yield
    finally:
        _start_interruptible[0] = False


def started_params_files() -> list[str]:
    """The ``--params-file`` paths of the command line ``run_node`` started with ([] in-process)."""
    return params_files(_started_argv)


def check_parameter_rules(argv: list[str]) -> None:
    """Check ``-p NAME:=VALUE`` rules before rcl does (its refusal is a multi-line error): the
    ``:=`` is there and VALUE is YAML (as rcl reads it)."""
    from ..core.yaml_io import load_yaml

    ros = ros_arguments(argv)
    for i, a in enumerate(ros):
        if a not in ("-p", "--param"):
            continue
        rule = ros[i + 1] if i + 1 < len(ros) else ""
        name, sep, value = rule.partition(":=")
        if not sep or not name:
            raise SoftcathError(f"-p {shown(rule)}: expected NAME:=VALUE")
        load_yaml(value, f"-p {name}")


def check_params_file(path: str) -> None:
    """Check a node parameter file before rcl reads it, so every fault is one line (rcl's own
    messages come as a multi-line RCLError traceback): it exists, is bounded YAML with unique keys
    (core.yaml_io), maps node names (optionally nested in namespaces, or ``/**``) to
    ``ros__parameters`` mappings, and every value is a bool, integer (int64), finite-or-not float,
    string or a list of one of those."""
    from ..core.yaml_io import load_yaml_file

    if not path:
        raise SoftcathError("--params-file needs a file name")
    data = load_yaml_file(path, f"params file {path}")
    if not isinstance(data, dict) or not data:
        raise SoftcathError(f"params file {path}: must map node names to {{ros__parameters: {{...}}}}")

    def node_entry(value, where: str) -> None:
        if not where or where.endswith("/"):
            raise SoftcathError(f"params file {path}: an empty node name ('{where}')")
        if not isinstance(value, dict):
            raise SoftcathError(f"params file {path}: '{where}' must be a mapping with ros__parameters")
        if "ros__parameters" not in value:
            for key, inner in value.items():       # a namespace level: /ns: {node: {ros__parameters}}
                if not isinstance(inner, dict):
                    raise SoftcathError(f"params file {path}: '{where}' has no ros__parameters (found '{key}' "
                                        "instead); the form is NODE_NAME: {ros__parameters: {name: value}}")
                node_entry(inner, f"{where}/{key}")
            return
        for key in value:
            if key != "ros__parameters":
                raise SoftcathError(f"params file {path}: '{where}.{key}' beside ros__parameters; "
                                    "parameters go under ros__parameters")
        parameters(value["ros__parameters"], f"{where}.ros__parameters")

    def parameters(value, where: str) -> None:
        if not isinstance(value, dict):
            raise SoftcathError(f"params file {path}: '{where}' must be a mapping of parameter: value")
        for name, v in value.items():
            at = f"{where}.{name}"
            if name is None or str(name) == "":
                raise SoftcathError(f"params file {path}: '{where}' has a parameter without a name")
            if isinstance(v, dict):              # nested names: a.b: value
                if not v:
                    raise SoftcathError(f"params file {path}: '{at}' is an empty mapping, not a value")
                parameters(v, at)
                continue
            if isinstance(v, list) and not v:
                raise SoftcathError(f"params file {path}: '{at}' is an empty list (rcl cannot type it)")
            items = v if isinstance(v, list) else [v]
            for item in items:
                if item is None or not isinstance(item, (bool, int, float, str)):
                    raise SoftcathError(f"params file {path}: '{at}' = {shown(item)}: a parameter is a bool, number, "
                                        "string or a list of one kind")
                if isinstance(item, int) and not isinstance(item, bool) and not INT64[0] <= item <= INT64[1]:
                    raise SoftcathError(f"params file {path}: '{at}' = {shown(item)}: integer beyond 64 bits")
            if isinstance(v, list) and len({type(i) for i in v}) > 1:
                raise SoftcathError(f"params file {path}: '{at}' = {shown(v)}: a list parameter holds one kind of value")

    for key, value in data.items():
        node_entry(value, str(key))


def _rcl_reason(exc: Exception) -> str:
    """rcl's error text without its source locations (``, at /project/src/...``)."""
    text = " ".join(str(exc).split())
    return text.split(", at /")[0]


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

    from ..graph import READY_MARK, default_to_localhost_discovery
    from .parameters import refuse_unknown_parameters

    # rclpy's SIGINT handler shuts the context down, which ends the spin, and then chains to the
    # handler it found: Python's, which would raise KeyboardInterrupt at whatever line runs next
    # (an except clause, the bench recording's finalisation) and print a traceback. A no-op
    # Python handler, installed before rclpy.init so rclpy still chains to it, leaves the
    # shutdown to the context alone, as for SIGTERM. Inside ``interruptible_start`` (a table
    # being built at start-up) it raises KeyboardInterrupt, so the build stops at once.
    signal.signal(signal.SIGINT, _on_sigint)
    default_to_localhost_discovery()
    try:
        argv = sys.argv if args is None else list(args)
        _started_argv[:] = argv
        check_parameter_rules(argv)
        for path in params_files(argv):
            check_params_file(path)
        rclpy.init(args=args)
    except SoftcathError as exc:
        print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
        return 2
    except _rclpy.RCLError as exc:      # e.g. a -p value rcl cannot parse
        print(f"[ERROR] cannot start: invalid ROS arguments: {_rcl_reason(exc)}", file=sys.stderr)
        return 2
    node = None
    name = ""
    code = 0
    try:
        try:
            node = factory()
        except startup_errors as exc:
            print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:      # SIGINT inside interruptible_start
            print("[INFO] stopped during start-up (SIGINT)", file=sys.stderr)
            return 0
        try:    # each node refuses these itself before acting on its parameters; this covers every node
            refuse_unknown_parameters(node)
        except SoftcathError as exc:
            print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
            node.destroy_node()
            node = None
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
