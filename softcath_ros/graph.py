"""Start a graph of softcath nodes on a private DDS domain, and stop it cleanly.

Used by `softcath characterise`, the node benchmarks and the tests, so that parallel runs on one
machine never see each other's topics:

- ``lease_domain()`` holds an exclusive lock (``fcntl.flock``) on one ROS_DOMAIN_ID in a range for
  as long as the lease lives; every process that uses this module gets a different domain. With
  ``probe_s`` it also listens on the domain and skips it when a foreign participant shows up
  (a graph started by other means).
- ``NodeGraph`` starts node executables with parameters on the leased domain (loopback only,
  ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST unless set otherwise), and stops them: SIGINT, then
  SIGKILL after a grace.
- Readiness is said over ROS, never in log lines: the shared node runtime publishes, once a node
  spins, its name and process id on the latched /softcath/ready (``topics.READY``); ``ReadyWatch``
  listens there and ``wait_ready`` waits for given processes.

No rclpy import at module level: only the probe and ``ReadyWatch`` need it.
"""
from __future__ import annotations

import fcntl
import importlib.util
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .core.errors import SoftcathError

DOMAIN_RANGE = (100, 230)   # ROS_DOMAIN_IDs leased here; 0-99 stay free for users' own graphs
LOCK_DIR = Path(tempfile.gettempdir()) / "softcath_ros_domains"


class DomainLease:
    """One ROS_DOMAIN_ID held exclusively by this process until ``release()`` (or exit)."""

    def __init__(self, domain: int, lock_file=None):
        self.domain = domain
        self._lock = lock_file

    def release(self) -> None:
        if self._lock is not None:
            fcntl.flock(self._lock, fcntl.LOCK_UN)
            self._lock.close()
            self._lock = None

    def __enter__(self) -> "DomainLease":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _foreign_participants(domain: int, listen_s: float) -> list[str]:
    """Node names another graph has on ``domain`` (loopback), seen within ``listen_s`` seconds (the
    first seen ends the wait: a free domain costs the whole window, a busy one only its discovery)."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = rclpy.create_node("softcath_domain_probe", context=context)
        end = time.monotonic() + listen_s
        while True:
            names = [n for n in node.get_node_names() if n != "softcath_domain_probe"]
            if names or time.monotonic() >= end:
                break
            time.sleep(0.05)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return names


def last_leased(domain: int) -> float:
    """When ``domain`` was last leased (or tried) by any process: its lock file's time; 0 if never."""
    try:
        return (LOCK_DIR / f"{domain}.lock").stat().st_mtime
    except OSError:
        return 0.0


def lease_domain(domain_range: tuple[int, int] = DOMAIN_RANGE, probe_s: float = 0.0) -> DomainLease:
    """A domain no other process using this module holds (and, with ``probe_s`` > 0, where no
    foreign node answers within that time). SoftcathError when every domain is taken."""
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    lo, hi = domain_range
    # Least recently leased first (a lease opens its lock file for writing): Fast DDS keeps a domain's
    # shared-memory ports for a moment, and a participant made soon after on the same domain can read
    # what a stopped graph's nodes sent there. Ties in random order.
    domains = sorted(range(lo, hi + 1), key=lambda d: (last_leased(d), random.random()))
    for domain in domains:
        f = open(LOCK_DIR / f"{domain}.lock", "w")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        if probe_s > 0 and _foreign_participants(domain, probe_s):
            fcntl.flock(f, fcntl.LOCK_UN)
            f.close()
            continue
        return DomainLease(domain, f)
    raise SoftcathError(f"no free ROS_DOMAIN_ID in {lo}..{hi}: every one is leased or in use")


DISCOVERY_RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"


def default_to_localhost_discovery(environ=None) -> str:
    """Keep DDS discovery on this machine unless the user asked otherwise: set
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST when it is unset or empty (an explicit value, e.g.
    SUBNET to reach a rig on the network, wins). Every softcath executable calls this before
    rclpy starts (docs/nodes.md, "Network"). Returns the range in effect."""
    environ = os.environ if environ is None else environ
    if not environ.get(DISCOVERY_RANGE_VAR, "").strip():
        environ[DISCOVERY_RANGE_VAR] = "LOCALHOST"
    return environ[DISCOVERY_RANGE_VAR]


def graph_env(domain: int, base: dict | None = None) -> dict:
    """The environment of a node on ``domain``: loopback discovery unless set, unbuffered output."""
    env = dict(os.environ if base is None else base)
    env.update(ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
    default_to_localhost_discovery(env)
    return env


def node_command(name: str) -> list[str]:
    """The node's console script next to this Python, else ``python -m softcath_ros.nodes.NAME``."""
    if importlib.util.find_spec(f"softcath_ros.nodes.{name}") is None:
        raise SoftcathError(f"no node '{name}' in softcath_ros.nodes")
    script = Path(sys.executable).parent / name
    return [str(script)] if script.exists() else [sys.executable, "-m", f"softcath_ros.nodes.{name}"]


def ros_args(params: dict | None = None, extra: list[str] | tuple = ()) -> list[str]:
    """``--ros-args -p name:=value ...`` for ``params`` plus any further ROS arguments."""
    out = ["--ros-args"]
    for k, v in (params or {}).items():
        out += ["-p", f"{k}:={v}"]
    return out + list(extra)


def stop_process(proc: subprocess.Popen, grace_s: float = 10.0, sig=signal.SIGINT) -> int:
    """Signal ``proc`` (SIGINT: a node finalises and exits), kill it after ``grace_s``; its exit code."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def wait_output(proc: subprocess.Popen, mark: str, timeout_s: float = 60.0) -> str:
    """Read ``proc``'s piped output until a line holds ``mark`` (a step of its work, e.g. a bench's
    "starting protocol"; readiness is ``wait_ready``'s); returns the text read so far (it is no
    longer in the pipe). SoftcathError, with that text's tail, when the process ends first or
    ``timeout_s`` passes."""
    import selectors

    fd = proc.stdout.fileno()
    text = b""
    with selectors.DefaultSelector() as sel:
        sel.register(fd, selectors.EVENT_READ)
        end = time.monotonic() + timeout_s
        while mark.encode() not in text:
            left = end - time.monotonic()
            if left <= 0 or not sel.select(timeout=left):
                raise SoftcathError(f"no {mark!r} after {timeout_s:g} s: {text.decode(errors='replace')[-500:]}")
            chunk = os.read(fd, 65536)
            if not chunk:  # the process closed its output: it ended
                proc.wait()
                raise SoftcathError(f"exited with {proc.returncode} before {mark!r}: "
                                    f"{text.decode(errors='replace')[-500:]}")
            text += chunk
    return text.decode(errors="replace")


READY_BACKLOG = 256   # READY samples a ReadyWatch keeps between two polls (more than any graph's nodes)


class ReadyWatch:
    """The nodes on ``domain`` that said they spin (``topics.READY``), by process id: a small rclpy
    node of its own context. ``poll(timeout_s)`` takes what arrived; ``close()`` ends it."""

    def __init__(self, domain: int):
        import json

        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from std_msgs.msg import String

        from . import topics

        default_to_localhost_discovery()
        self.ready: dict[int, dict] = {}
        self.context = rclpy.Context()
        # the caller's signal handling stays its own (characterise finalises the bench on SIGTERM)
        rclpy.init(context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("softcath_ready_watch", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

        def on_ready(msg):
            try:
                info = json.loads(msg.data)
                self.ready[int(info["pid"])] = info
            except (ValueError, KeyError, TypeError):
                pass

        # every node's one latched sample is kept until taken: with a depth of 1 a sample arriving
        # before the previous one was taken replaced it, and that node never counted as ready
        qos = QoSProfile(depth=READY_BACKLOG, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(String, topics.READY, on_ready, qos)

    def poll(self, timeout_s: float) -> None:
        self.executor.spin_once(timeout_sec=timeout_s)

    def close(self) -> None:
        import rclpy

        if self.context is not None:
            context, self.context = self.context, None
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
            rclpy.try_shutdown(context=context)


def _tail(proc: subprocess.Popen) -> str:
    """What an ended process wrote on its piped output (its last 500 characters)."""
    if proc.stdout is None:
        return ""
    try:
        return (proc.stdout.read() or "")[-500:]
    except (OSError, ValueError):
        return ""


def wait_ready(procs, domain: int | None = None, timeout_s: float = 60.0, watch: ReadyWatch | None = None) -> None:
    """Until every process of ``procs`` (one or a list) announced on ``domain`` that its node spins.
    SoftcathError naming the first that ended before it (with its output's tail) or, after
    ``timeout_s``, those still not ready. ``watch``: a ReadyWatch to reuse (else one for this call)."""
    procs = list(procs) if isinstance(procs, (list, tuple)) else [procs]
    own = watch is None
    watch = ReadyWatch(domain) if own else watch
    try:
        end = time.monotonic() + timeout_s
        while True:
            waiting = [p for p in procs if p.pid not in watch.ready]
            if not waiting:
                return
            for p in waiting:
                if p.poll() is not None:
                    raise SoftcathError(f"{Path(str(p.args[0])).name if p.args else 'node'} exited with "
                                        f"{p.returncode} before it was ready: {_tail(p)}")
            if time.monotonic() > end:
                raise SoftcathError(f"not ready after {timeout_s:g} s: process(es) "
                                    f"{', '.join(str(p.pid) for p in waiting)}")
            watch.poll(0.1)
    finally:
        if own:
            watch.close()


class NodeGraph:
    """Nodes as separate processes on one private domain; a context manager that stops them all.

    ``domain``: an explicit ROS_DOMAIN_ID (not leased), or None to lease one (``probe_s`` as in
    ``lease_domain``)."""

    def __init__(self, domain: int | None = None, probe_s: float = 0.0, env: dict | None = None):
        self.lease = None if domain is not None else lease_domain(probe_s=probe_s)
        self.domain = domain if domain is not None else self.lease.domain
        self.env = graph_env(self.domain, env)
        self.processes: list[tuple[str, subprocess.Popen]] = []
        self._watch: ReadyWatch | None = None

    @property
    def watch(self) -> ReadyWatch:
        """The graph's ReadyWatch (made on first use, ended with the graph)."""
        if self._watch is None:
            self._watch = ReadyWatch(self.domain)
        return self._watch

    def start(self, node: str, params: dict | None = None, extra_ros_args=(), stdout=subprocess.PIPE,
              stderr=subprocess.STDOUT, **popen) -> subprocess.Popen:
        """Start executable ``node`` (e.g. "model_node") with ``params``; output piped unless told."""
        cmd = node_command(node) + ros_args(params, extra_ros_args)
        proc = subprocess.Popen(cmd, env=self.env, stdout=stdout, stderr=stderr, text=True, **popen)
        self.processes.append((node, proc))
        return proc

    def wait_ready(self, *procs: subprocess.Popen, timeout_s: float = 60.0) -> None:
        """``wait_ready`` for every one of ``procs`` within ``timeout_s`` in all."""
        wait_ready(list(procs), timeout_s=timeout_s, watch=self.watch)

    def stop(self, grace_s: float = 10.0) -> dict[str, int]:
        """Stop every node still running (SIGINT, then kill after ``grace_s``); exit codes by node."""
        codes = {}
        for name, proc in reversed(self.processes):
            codes[name] = stop_process(proc, grace_s)
        return codes

    def __enter__(self) -> "NodeGraph":
        return self

    def __exit__(self, *exc) -> None:
        try:
            if self._watch is not None:
                self._watch.close()
            self.stop()
            for _, proc in self.processes:
                for stream in (proc.stdout, proc.stderr):
                    if stream is not None:
                        stream.close()
        finally:
            if self.lease is not None:
                self.lease.release()


__all__ = ["DOMAIN_RANGE", "DomainLease", "NodeGraph", "ReadyWatch", "graph_env", "last_leased", "lease_domain",
           "node_command", "ros_args", "stop_process", "wait_output", "wait_ready"]
