"""The main loop every softcath node shares.

``run_node`` builds the node, spins it on the executor it names and ends with exit
code 0 on SIGINT/SIGTERM (rclpy's signal handlers shut the context down; we catch
the resulting exceptions so no traceback is printed). A node that cannot start
(bad design file, unknown model, bad parameter, a parameter it does not declare, a params file
with no section for it) logs one line and exits with 2. Executors: nodes/executors.py; the
command line's checks: nodes/command_line.py; real-time scheduling: nodes/realtime.py.
"""
from __future__ import annotations

import os
import signal
import sys
from contextlib import contextmanager
from typing import Callable

from ..core.errors import SoftcathError
from .command_line import check_parameter_rules, check_params_file, params_files, record_started_argv
from .executors import make_executor, spin
from .realtime import set_realtime_priority

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


def pause(node, seconds: float) -> None:
    """Sleep inside a callback or at start-up (a bounded wait, e.g. bench_node's rig check); SIGINT or
    SIGTERM (rclpy shut the node's context down) ends it at once with KeyboardInterrupt."""
    import time

    import rclpy

    if not rclpy.ok(context=node.context):
        raise KeyboardInterrupt
    time.sleep(seconds)


def _rcl_reason(exc: Exception) -> str:
    """rcl's error text without its source locations (``, at /project/src/...``)."""
    text = " ".join(str(exc).split())
    return text.split(", at /")[0]


def announce_ready(node, executor_name: str) -> None:
    """Say on the latched ``topics.READY`` that ``node`` spins: its name, process id, executor and
    whether it is managed (lifecycle: characterise then waits until it sees its services)."""
    import json

    from rclpy.lifecycle import LifecycleNode
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from .. import topics

    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.ready_publisher = node.create_publisher(String, topics.READY, qos)
    node.ready_publisher.publish(String(data=json.dumps(
        {"node": node.get_fully_qualified_name(), "pid": os.getpid(), "executor": executor_name,
         "managed": isinstance(node, LifecycleNode)})))


def run_node(factory: Callable, args=None, startup_errors: tuple = ()) -> int:
    """Create the node with ``factory()``, spin it on ``node.executor_name``; return the exit code.

    ``startup_errors``: exception types that mean "cannot start with this configuration"; logged
    as one line, exit code 2 (or the error's ``exit_code``: bench_node's NoRig, 3). A node that ends by itself has a
    ``finished`` property (spinning stops when it is true) and a ``finish()`` method, called on
    the way out whether it finished or was interrupted, that returns the exit code. Once the node
    spins it says so on the latched ``topics.READY`` (what ``graph.wait_ready`` waits for).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    # rcl's own error type is exposed only through rclpy's implementation module (no public alias)
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    if _init_ros(args, _rclpy.RCLError):
        return 2
    node = None
    name = ""
    code = 0
    try:
        node, refused = _create(factory, startup_errors)
        if node is None:
            return refused
        name = getattr(node, "executor_name", "events")
        _spin_node(node, name)
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


def _init_ros(args, rcl_error) -> bool:
    """Initialise rclpy with ``args`` after softcath's checks of the command line and its params
    files; True when it cannot start (said in one line)."""
    import rclpy

    from ..graph import default_to_localhost_discovery

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
        record_started_argv(argv)
        check_parameter_rules(argv)
        for path in params_files(argv):
            check_params_file(path)
        rclpy.init(args=args)
    except SoftcathError as exc:
        print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
        return True
    except rcl_error as exc:      # e.g. a -p value rcl cannot parse
        print(f"[ERROR] cannot start: invalid ROS arguments: {_rcl_reason(exc)}", file=sys.stderr)
        return True
    return False


def _create(factory: Callable, startup_errors: tuple):
    """(the node, None), or (None, the exit code) when it cannot start: a startup error or unknown
    parameters (2, or the error's ``exit_code``; said in one line), or SIGINT during start-up (0)."""
    from .parameters import refuse_unknown_parameters

    try:
        node = factory()
    except startup_errors as exc:
        print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
        return None, getattr(exc, "exit_code", 2)
    except KeyboardInterrupt:      # SIGINT inside interruptible_start
        print("[INFO] stopped during start-up (SIGINT)", file=sys.stderr)
        return None, 0
    try:    # each node refuses these itself before acting on its parameters; this covers every node
        refuse_unknown_parameters(node)
    except SoftcathError as exc:
        print(f"[ERROR] cannot start: {exc}", file=sys.stderr)
        node.destroy_node()
        return None, 2
    return node, None


def _spin_node(node, name: str) -> None:
    """Spin ``node`` on the executor ``name`` (with its real-time priority, if it asks for one) until
    it finishes or the context shuts down; says it is ready once it spins."""
    executor = make_executor(name)
    executor.add_node(node)
    priority = getattr(node, "realtime_priority", 0)
    if priority:
        problem = set_realtime_priority(priority)
        if problem:
            node.get_logger().warning(problem + "; running with normal scheduling")
    announce_ready(node, name)
    node.get_logger().info(f"spinning on the {name} executor")
    ends = hasattr(type(node), "finished")
    spin(executor, name, (lambda: node.finished) if ends else None)
