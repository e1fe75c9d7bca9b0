"""`softcath characterise`: the main job. Brings up sim_bench_node, model_node (so the
predicted /softcath/tip_pose and /softcath/backbone are recorded), allocation_node for
protocols by bending direction, and bench_node, as separate processes on a private ROS
domain; runs the default characterisation (0 -> 0.35 -> 0 bar, three trials, angle and
blocking-force benches), then writes the report and prints where both are.
Ctrl-C stops the run cleanly: bench_node finalises the recording first.

allocation_node runs only for protocols by direction (bench_node sends /softcath/bend_cmd,
allocation_node publishes /softcath/pressure_cmd). A per-channel protocol publishes
/softcath/pressure_cmd itself and must be its only publisher: allocation_node publishes
there too (at least while it ramps down after its watchdog), so the two would fight.
"""
from __future__ import annotations

import importlib.util
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

from ..core.errors import SoftcathError


def register(sub) -> None:
    p = sub.add_parser("characterise", help="run the bench characterisation on the simulated rig "
                       "(nodes as separate processes) and write recording + report")
    p.add_argument("--protocol", default="default", help="shipped protocol name or a path")
    p.add_argument("--design", default=None, help="design (default: the protocol's)")
    p.add_argument("--sim-model", default="closed_form", help="rung that plays the rig's truth")
    p.add_argument("--model", nargs="+", default=["closed_form"], help="rung(s) overlaid in the report")
    p.add_argument("--output-dir", default="runs", help="where the recording directory goes (default runs/)")
    p.add_argument("--timeout", type=float, default=170.0, help="give up after this many seconds")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def _command(name: str) -> list[str] | None:
    """The node's console script next to this Python, else ``python -m``; None if not installed."""
    script = Path(sys.executable).parent / name
    if importlib.util.find_spec(f"softcath_ros.nodes.{name}") is None:
        return None
    return [str(script)] if script.exists() else [sys.executable, "-m", f"softcath_ros.nodes.{name}"]


def _free_domain(listen_s: float = 1.0, tries: int = 5) -> int:
    """A ROS domain in 120..230 where no other participant shows up within ``listen_s``: another
    graph on the same domain (a test, another run) could publish on our topics and spoil the data."""
    import rclpy

    for _ in range(tries):
        domain = random.randint(120, 230)
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            node = rclpy.create_node("softcath_characterise_probe", context=context)
            time.sleep(listen_s)
            busy = [n for n in node.get_node_names() if n != "softcath_characterise_probe"]
            node.destroy_node()
        finally:
            rclpy.shutdown(context=context)
        if not busy:
            return domain
    return domain  # all busy (unlikely): bench_node still refuses foreign pressure_cmd publishers


def _stop(proc: subprocess.Popen, timeout: float = 5.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run(args) -> int:
    from ..bench.protocol import load_protocol
    from ..bench.report import write_report
    from ..core.design import load_design

    protocol = load_protocol(args.protocol)
    design = load_design(args.design or protocol.design or "implemented_5mm")
    out_dir = Path(args.output_dir).resolve()
    name = f"bench_{protocol.name}_{datetime.now().strftime('%Y%m%d_%H%M%S')}"
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if "ROS_DOMAIN_ID" not in env:  # a private domain unless told
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = env["ROS_AUTOMATIC_DISCOVERY_RANGE"]
        env["ROS_DOMAIN_ID"] = str(_free_domain())
    env["PYTHONUNBUFFERED"] = "1"
    design_arg = design.source or design.name
    helpers = [("sim_bench_node", ["-p", f"design:={design_arg}", "-p", f"model:={args.sim_model}"]),
               ("model_node", ["-p", f"design:={design_arg}", "-p", f"model:={args.model[0]}"])]
    if protocol.drive == "direction":
        helpers.append(("allocation_node", ["-p", f"design:={design_arg}", "-p", f"model:={args.model[0]}"]))
    procs: list[tuple[str, subprocess.Popen]] = []
    logs = out_dir / f"{name}_logs"
    logs.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    say = (lambda *a: None) if args.json else (lambda *a: print(*a, flush=True))
    bench = None
    timed_out: list[bool] = []
    try:
        for node, extra in helpers:
            cmd = _command(node)
            if cmd is None:
                say(f"[characterise] {node} not installed; running without it")
                continue
            log = open(logs / f"{node}.log", "w")
            procs.append((node, subprocess.Popen(cmd + ["--ros-args", *extra], env=env, stdout=log,
                                                 stderr=subprocess.STDOUT)))
            say(f"[characterise] started {node} (log {logs / (node + '.log')})")
        bench_cmd = _command("bench_node")
        if bench_cmd is None:
            raise SoftcathError("bench_node is not installed")
        bench = subprocess.Popen(bench_cmd + ["--ros-args", "-p", f"protocol:={args.protocol}",
                                              "-p", f"design:={design_arg}", "-p", f"model:={args.model[0]}",
                                              "-p", f"output_dir:={out_dir}",
                                              "-p", f"name:={name}"],
                                 env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        watchdog = threading.Timer(args.timeout, lambda: (timed_out.append(True), _stop(bench, 15.0)))
        watchdog.daemon = True
        watchdog.start()
        say(f"[characterise] bench_node running protocol '{protocol.name}' on ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}")
        lines = []
        with open(logs / "bench_node.log", "w") as blog:
            for line in bench.stdout:
                blog.write(line)
                lines.append(line.rstrip())
                if "[softcath_bench]" in line or line.startswith("recording:"):
                    say("  " + line.rstrip().split("]: ")[-1])
        bench.wait()
        watchdog.cancel()
        if timed_out:
            raise SoftcathError(f"characterisation took longer than {args.timeout:g} s; stopped "
                                f"(recording finalised; logs in {logs})")
    except KeyboardInterrupt:
        if bench is not None:
            _stop(bench, timeout=15.0)
        raise
    finally:
        for _, p in procs:
            _stop(p)
    summary_lines = [x for x in lines if x.startswith("summary: ")]
    if bench.returncode != 0 or not summary_lines:
        tail = "\n".join(lines[-8:])
        raise SoftcathError(f"bench_node failed (exit {bench.returncode}); logs in {logs}\n{tail}")
    summary = json.loads(summary_lines[-1][len("summary: "):])
    report = write_report(summary["recording"], design, args.model)
    elapsed = time.monotonic() - t0
    if args.json:
        json.dump({"recording": summary["recording"], "report": report["report"], "plots": report["plots"],
                   "messages": summary["messages"], "dropped": summary["dropped"], "elapsed_s": elapsed,
                   "logs": str(logs)}, sys.stdout, indent=2)
        print()
    else:
        print(f"[characterise] done in {elapsed:.0f} s: {summary['messages']} messages recorded, "
              f"{summary['dropped']} dropped")
        print(f"recording: {summary['recording']}")
        print(f"report:    {report['report']}")
        for p in report["plots"]:
            print(f"plot:      {p}")
    return 0
