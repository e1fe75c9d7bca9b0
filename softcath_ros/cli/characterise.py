"""`softcath characterise`: the main job. Runs a protocol on a rig and writes the recording and
the report.

Rigs (``--rig``, the table ``RIGS``; a new rig is one more entry with its own ``run``):
- ``sim`` (default): starts sim_bench_node, model_node (so the predicted /softcath/tip_pose and
  /softcath/backbone are recorded), allocation_node for protocols by bending direction, and
  bench_node, as separate processes on a private ROS domain.
- ``ros``: whatever publishes the rig contract (docs/rig.md) on the user's ROS_DOMAIN_ID (a real
  rig, or sim_bench_node started by hand): the same graph without sim_bench_node; bench_node
  waits ``--wait-timeout`` s for it and names each missing topic.

``--rig manual``: no ROS graph; the operator sets each step's pressure and types the
reading at the terminal (bench/manual.py); same recording layout, same report.

allocation_node runs only for protocols by direction (bench_node sends /softcath/bend_cmd,
allocation_node publishes /softcath/pressure_cmd). A per-channel protocol publishes
/softcath/pressure_cmd itself and must be its only publisher.

Faults (docs/rig.md "Exit codes"): bench_node's own failures pass through with its exit code and
reason (3 no rig, 4 another commander, 5 rig lost mid-run, 6 disk full); after a failure mid-run
the report is still written on the completed steps. A child that dies while the bench runs gets
the bench stopped within 2 s (exit 5). What is waited for, when a child is stopped and the one
retry of a hung bench_node are decided by bench/supervisor.py (a state machine on the clock);
readiness is what each node says on /softcath/ready (graph.ReadyWatch), not its log. SIGINT and SIGTERM stop bench_node first (it finalises the
recording), then every other child; exit 130 (SIGINT) or 143 (SIGTERM).
"""
from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Callable

from ..core.errors import SoftcathError
from ..graph import NodeGraph
from .common import bounded_float, check_rung_names
from .report import add_overlay_arguments

EXIT_CHILD_DIED = 5       # as bench_node's "rig lost"
EXIT_DISK_FULL = 6        # as bench_node's "recording failed"
# A child that dies: bench_node gets this long to notice by itself (a rig's topics go stale after
# its lost_after, 1 s, then 0.3 s of venting), then is stopped. model_node is no part of the rig:
# bench_node would never notice, so it is stopped at once.
CHILD_GRACE_S = {"model_node": 0.0}
# Every helper (rig, model_node, allocation_node) is waited for before bench_node starts, so the
# recording has the model's predictions from the first step (a loaded machine can take many seconds
# to import); one not spinning by then is said, and the run goes on (bench_node checks the rig itself).
HELPER_READY_S = 60.0
BENCH_READY_S = 60.0   # bench_node not spinning by then: started once more
RIG_CHILD_GRACE_S = 1.5


class Stopped(Exception):
    """SIGTERM (or SIGINT) arrived: stop the graph, finalise, exit 128 + signum."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@dataclass(frozen=True)
class RigChoice:
    help: str
    run: Callable  # (args, protocol, design) -> exit code


def register(sub) -> None:
    p = sub.add_parser("characterise", help="run a bench protocol on a rig (simulated by default) "
                       "and write recording + report")
    p.add_argument("--rig", default="sim", choices=sorted(RIGS),
                   help="; ".join(f"{k}: {v.help}" for k, v in sorted(RIGS.items())) + " (default sim)")
    p.add_argument("--protocol", default="default", help="shipped protocol name or a path")
    p.add_argument("--design", default=None, help="design (default: the protocol's)")
    p.add_argument("--sim-model", default="surrogate", help="rung that plays the rig's truth (default: the section "
                   "rung's table)")
    add_overlay_arguments(p, "; the first also drives the nodes")
    p.add_argument("--output-dir", default="runs", help="where the recording directory goes (default runs/)")
    p.add_argument("--timeout", type=bounded_float(1.0, 7 * 86400.0), default=170.0,
                   help="give up after this many seconds (at most a week)")
    p.add_argument("--wait-timeout", type=bounded_float(0.1, 3600.0), default=20.0,
                   help="seconds bench_node waits for the rig's topics (default 20)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench.protocol import design_steps, load_protocol
    from ..core.design import load_design

    check_rung_names([*args.model, *([args.sim_model] if args.rig == "sim" else [])])
    main_thread = threading.current_thread() is threading.main_thread()  # signals go to the main thread only
    if main_thread:
        restore_interrupt()
    if args.rig == "manual":
        return run_manual(args)
    protocol = load_protocol(args.protocol)
    design = load_design(args.design or protocol.design or "implemented_5mm")
    design_steps(protocol, design, args.model[0])   # a step beyond the design (or its reach): refused now
    previous = signal.signal(signal.SIGTERM, _raise_stopped) if main_thread else None
    try:
        return RIGS[args.rig].run(args, protocol, design)
    except Stopped as exc:
        return 128 + exc.signum
    except KeyboardInterrupt:
        return 128 + signal.SIGINT
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def restore_interrupt() -> None:
    """Ctrl-C (SIGINT) stops the run and finalises its recording, also when this process was started
    with SIGINT ignored or blocked (a shell script's background job, a parent that ignores it):
    both are inherited through exec, and Python keeps an inherited SIG_IGN."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def _raise_stopped(signum, frame):
    raise Stopped(signum)


def _run_sim(args, protocol, design) -> int:
    return run_graph(args, protocol, design, rig_nodes=[("sim_bench_node", {"model": args.sim_model})],
                     private=True)


def _run_ros(args, protocol, design) -> int:
    return run_graph(args, protocol, design, rig_nodes=[], private=False)


RIGS: dict[str, RigChoice] = {
    "sim": RigChoice("the simulated rig (sim_bench_node) on a private ROS domain", _run_sim),
    "ros": RigChoice("whatever publishes the rig contract (docs/rig.md) on $ROS_DOMAIN_ID", _run_ros),
    # No ROS graph: run() hands it to run_manual before the graph's signal handling.
    "manual": RigChoice("the operator types each reading at the terminal (no ROS graph; bench/manual.py)",
                        lambda args, protocol, design: run_manual(args)),
}


def _domain(private: bool) -> int | None:
    explicit = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if explicit and not (explicit.isdigit() and int(explicit) <= 232):
        raise SoftcathError(f"ROS_DOMAIN_ID={explicit!r}: must be an integer 0..232"
                            + (" (or unset for a private domain)" if private else ""))
    if explicit:
        return int(explicit)
    return None if private else 0  # a ROS rig lives on the user's domain (ROS's default 0)


class _Log:
    """A child's log file; a full disk stops the logging (said once), not the run."""

    def __init__(self, path: Path, say):
        self.path, self.say, self.failed = path, say, False
        try:
            self.f = open(path, "w")
        except OSError as exc:
            self.f = None
            self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        if not self.failed:
            self.failed = True
            what = "disk full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else f"cannot write ({exc.strerror})"
            self.say(f"[characterise] {what}: log {self.path} stops here")

    def write(self, text: str) -> None:
        if self.f is not None and not self.failed:
            try:
                self.f.write(text)
                self.f.flush()
            except OSError as exc:
                self._fail(exc)

    def close(self) -> None:
        if self.f is not None:
            try:
                self.f.close()
            except OSError as exc:
                self._fail(exc)


class _BenchOutput:
    """bench_node's piped output, read without blocking: lines to its log, the terminal and ``lines``."""

    def __init__(self, proc: subprocess.Popen, log: _Log, say, lines: list[str]):
        self.proc, self.log, self.say, self.lines = proc, log, say, lines
        self.fd = proc.stdout.fileno()
        self.partial = b""
        self.closed = False

    def read(self, timeout_s: float) -> None:
        """What arrived within ``timeout_s`` (until the end once the process ended)."""
        import select

        while not self.closed:
            if not select.select([self.fd], [], [], timeout_s)[0]:
                return
            chunk = os.read(self.fd, 65536)
            if not chunk:
                self.closed = True
                chunk = b"\n" if self.partial else b""
            *complete, self.partial = (self.partial + chunk).split(b"\n")
            for raw in complete:
                line = raw.decode(errors="replace")
                self.log.write(line + "\n")
                self.lines.append(line.rstrip())
                if "[softcath_bench]" in line or line.startswith("recording:"):
                    self.say("  " + line.rstrip().split("]: ")[-1])
            if self.proc.poll() is None:
                return   # a live process: what was there is read; the supervision goes on

    def drain(self) -> None:
        self.read(None)


def _plan(args, protocol, design, rig_nodes):
    """Where the run goes (output folder, recording name, logs folder) and the helpers it starts."""
    out_dir = Path(args.output_dir).resolve()
    name = f"bench_{protocol.name}_{datetime.now().strftime('%Y%m%d_%H%M%S')}"
    design_arg = design.source or design.name
    helpers = [(node, {"design": design_arg, **params}) for node, params in rig_nodes]
    helpers.append(("model_node", {"design": design_arg, "model": args.model[0]}))
    if protocol.drive == "direction":
        helpers.append(("allocation_node", {"design": design_arg, "model": args.model[0]}))
    # Not beside the recording: `softcath report runs/bench_default_*/` must match recordings only.
    logs = out_dir / "logs" / name
    try:
        logs.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SoftcathError(f"cannot create {logs}: {exc.strerror or exc}") from None
    return out_dir, name, design_arg, helpers, logs


def _rig_readings(protocol, design) -> list[list[str]]:
    """The rig topics this protocol's run reads (as bench_node's configure checks them): the contract's,
    or the deprecated unstamped ones."""
    from .. import topics

    benches = tuple(dict.fromkeys(b.kind for b in protocol.benches))
    return [topics.rig_topics(design.n_channels, benches), topics.deprecated_rig_topics(benches)]


def run_graph(args, protocol, design, rig_nodes: list[tuple[str, dict]], private: bool) -> int:
    """The ROS path shared by the rigs: helpers + bench_node on one domain, supervised by
    bench.supervisor.GraphSupervisor (readiness said over ROS: graph.ReadyWatch); the report at the
    end (also on the completed steps of a failed run)."""
    from ..bench.supervisor import (BringUpBench, Fail, GraphState, GraphSupervisor, KillBench, Say, StartBench,
                                    StopBench)
    from ..graph import ReadyWatch
    from .managed import activate_rig, bring_up_bench, stop_bench

    out_dir, name, design_arg, helpers, logs = _plan(args, protocol, design, rig_nodes)
    t0 = time.monotonic()
    say = (lambda *a: None) if args.json else (lambda *a: print(*a, flush=True))
    domain = _domain(private)
    lines: list[str] = []
    stopped: list[int] = []
    sup = GraphSupervisor([node for node, _ in helpers], args.timeout, HELPER_READY_S, BENCH_READY_S,
                          CHILD_GRACE_S, RIG_CHILD_GRACE_S)
    with NodeGraph(domain=domain, probe_s=1.0 if domain is None else 0.0) as graph:
        if not private:  # a ROS rig may sit on another machine: an explicit discovery range wins
            graph.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        bench = output = None
        children: dict[str, subprocess.Popen] = {}
        watch = ReadyWatch(graph.domain)
        blog = _Log(logs / "bench_node.log", say)
        try:
            children.update(_start_helpers(graph, helpers, logs, say))
            while sup.state is not GraphState.DONE:
                if output is not None:
                    output.read(0.05)
                watch.poll(0.05)
                ready = {n for n, p in children.items() if p.pid in watch.ready}
                exited = {n: p.returncode for n, p in children.items() if p.poll() is not None}
                if bench is not None and bench.poll() is not None:
                    output.drain()
                for cmd in sup.update(time.monotonic(), ready, exited, (out_dir / name).exists()):
                    if isinstance(cmd, StartBench) and cmd.attempt == 1:   # the rig's managed nodes: active
                        activate_rig(watch, say, _rig_readings(protocol, design), args.wait_timeout)
                    if isinstance(cmd, StartBench):
                        lines.clear()
                        bench = children["bench_node"] = graph.start(
                            "bench_node", {"protocol": args.protocol, "design": design_arg, "model": args.model[0],
                                           "output_dir": out_dir, "name": name, "wait_timeout": args.wait_timeout,
                                           "autostart": False})
                        output = _BenchOutput(bench, blog, say, lines)
                    elif isinstance(cmd, BringUpBench):
                        bring_up_bench(watch, bench, args.wait_timeout, say)
                        say(f"[characterise] bench_node running protocol '{protocol.name}' on the {args.rig} rig, "
                            f"ROS_DOMAIN_ID={graph.domain}")
                    elif isinstance(cmd, StopBench):
                        stop_bench(watch, bench, cmd.lifecycle, say)
                    elif isinstance(cmd, KillBench):
                        bench.kill()
                    elif isinstance(cmd, Say):
                        say(f"[characterise] {cmd.text}")
                    elif isinstance(cmd, Fail):
                        raise SoftcathError(f"{cmd.node} ended (exit {cmd.code}) before it was ready; its log: "
                                            f"{logs / (cmd.node + '.log')}")
        except (Stopped, KeyboardInterrupt) as exc:
            stopped.append(exc.signum if isinstance(exc, Stopped) else int(signal.SIGINT))
            if threading.current_thread() is threading.main_thread():
                signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second signal must not cut the finalisation
            if bench is not None:
                stop_bench(watch, bench, sup.brought_up == sup.attempt, say, wait_s=15.0)
                output.drain()
        finally:
            blog.close()
            watch.close()
        # leaving the graph stops every other child (SIGINT, then SIGKILL after a grace)
    died = list(sup.died)
    summary = _summary(lines)
    if stopped:
        sig = signal.Signals(stopped[0]).name
        where = f"; recording {summary['recording']} (finalised, incomplete)" if summary else ""
        print(f"softcath characterise: stopped by {sig}: every child stopped{where}", file=sys.stderr)
        return 128 + stopped[0]
    if sup.timed_out:
        raise SoftcathError(f"characterisation took longer than {args.timeout:g} s; stopped "
                            f"(recording finalised; logs in {logs})")
    return _outcome(args, design, bench.returncode, summary, died, lines, t0, logs, out_dir / name, say)


def _start_helpers(graph, helpers, logs: Path, say) -> dict[str, subprocess.Popen]:
    """The rig, model_node, allocation_node, each logging to its file under ``logs``."""
    children = {}
    for node, params in helpers:
        log = _Log(logs / f"{node}.log", say)
        children[node] = graph.start(node, params, stdout=log.f or subprocess.DEVNULL)
        log.close()
        say(f"[characterise] started {node} (log {logs / (node + '.log')})")
    return children


def _outcome(args, design, code: int, summary: dict | None, died: list[str], lines: list[str], t0: float,
             logs: Path, run_dir: Path, say) -> int:
    """The report and exit code from how bench_node ended (its summary line, its exit code) and the
    children that died; a failed run still reports its completed steps."""
    if code == 0 and summary and not died:
        try:
            return _done(args, summary, design, t0, logs)
        except SoftcathError as exc:
            if "disk full" in str(exc):
                print(f"softcath characterise: error: {exc}", file=sys.stderr)
                return EXIT_DISK_FULL
            raise
    if code < 0 and not summary:  # bench_node itself killed: the rig vents by itself (docs/rig.md)
        died.append(f"bench_node killed by {signal.Signals(-code).name}")
        bags = sorted(run_dir.glob("*.mcap"))
        reason = "the recording was not finalised" + (f": softcath recover {bags[0]}" if bags else "")
    elif summary and summary.get("error"):
        reason = summary["error"]
    elif summary:
        reason = "bench_node stopped (recording finalised, incomplete)"
    else:
        reason = f"bench_node exited with {code}; logs in {logs}\n" + "\n".join(lines[-8:])
    if died:
        reason = f"{', '.join(died)} during the run; {reason}"
        code = code if code in (3, 4, 5, 6) else EXIT_CHILD_DIED
    if summary and summary.get("completed_steps") and code != EXIT_DISK_FULL:  # a torn file needs recover first
        try:
            _done(args, summary, design, t0, logs, incomplete=True)
        except SoftcathError as exc:
            say(f"[characterise] no report on the completed steps: {exc}")
    print(f"softcath characterise: error: {reason}", file=sys.stderr)
    return code if code in (3, 4, 5, 6) else 2


def _summary(lines: list[str]) -> dict | None:
    found = [x for x in lines if x.startswith("summary: ")]
    return json.loads(found[-1][len("summary: "):]) if found else None


def _done(args, summary: dict, design, t0: float, logs: Path, incomplete: bool = False) -> int:
    from ..bench.report import write_report

    try:
        report = write_report(summary["recording"], design, args.model, cache=not args.no_cache)
    except OSError as exc:
        full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
        raise SoftcathError(f"{'disk full' if full else 'cannot write'} writing the report beside "
                            f"{summary['recording']} ({exc.strerror or exc})") from None
    elapsed = time.monotonic() - t0
    if args.json:
        json.dump({"recording": summary["recording"], "report": report["report"], "plots": report["plots"],
                   "messages": summary["messages"], "dropped": summary["dropped"], "elapsed_s": elapsed,
                   "complete": summary.get("complete", True), "completed_steps": summary.get("completed_steps"),
                   "logs": str(logs)}, sys.stdout, indent=2)
        print()
    else:
        state = (f"stopped after {summary.get('completed_steps')} of {summary.get('n_steps')} steps" if incomplete
                 else f"done in {elapsed:.0f} s")
        print(f"[characterise] {state}: {summary['messages']} messages recorded, {summary['dropped']} dropped")
        print(f"recording: {summary['recording']}")
        print(f"report:    {report['report']}" + (" (completed steps only)" if incomplete else ""))
        for p in report["plots"]:
            print(f"plot:      {p}")
    return 0


def run_manual(args) -> int:
    """--rig manual: readings typed at the terminal (bench.manual), then the same report."""
    from ..bench.manual import run_manual_bench
    from ..bench.report import write_report

    terminal = sys.stderr if args.json else sys.stdout  # --json keeps stdout for the answer
    run = run_manual_bench(args.protocol, args.design, args.model[0], Path(args.output_dir).resolve(),
                           say=lambda s: print(s, file=terminal, flush=True),
                           prompt=lambda s: print(s, end="", file=terminal, flush=True))
    report = write_report(run["recording"], run["design"], args.model) if run["readings"] else None
    out = {k: run[k] for k in ("recording", "outcome", "n_steps", "readings", "skipped", "refused")}
    out.update(report=report and report["report"], plots=report["plots"] if report else [])
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    else:
        print(f"[characterise] manual bench {run['outcome']}: {run['readings']} readings, {run['skipped']} "
              f"skipped, {run['refused']} entries refused, of {run['n_steps']} steps")
        print(f"recording: {run['recording']}")
        print(f"report:    {out['report'] or '(no readings: none written)'}")
    return 0 if run["outcome"] == "complete" else 1
