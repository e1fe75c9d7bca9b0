"""`softcath characterise`: the main job. Brings up sim_bench_node, model_node (so the
predicted /softcath/tip_pose and /softcath/backbone are recorded), allocation_node for
protocols by bending direction, and bench_node, as separate processes on a private ROS
domain; runs the default characterisation (0 -> 0.35 -> 0 bar, three trials, angle and
blocking-force benches), then writes the report and prints where both are.
Ctrl-C stops the run cleanly: bench_node finalises the recording first.

``--rig manual``: no ROS graph; the operator sets each step's pressure and types the
reading at the terminal (bench/manual.py); same recording layout, same report.

allocation_node runs only for protocols by direction (bench_node sends /softcath/bend_cmd,
allocation_node publishes /softcath/pressure_cmd). A per-channel protocol publishes
/softcath/pressure_cmd itself and must be its only publisher: allocation_node publishes
there too (at least while it ramps down after its watchdog), so the two would fight.
"""
from __future__ import annotations

import json
import os
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

from ..core.errors import SoftcathError
from ..graph import NodeGraph, stop_process


def register(sub) -> None:
    p = sub.add_parser("characterise", help="run the bench characterisation on the simulated rig "
                       "(nodes as separate processes) or by hand (--rig manual) and write recording + report")
    p.add_argument("--rig", choices=("sim", "manual"), default="sim",
                   help="sim: the simulated rig (default); manual: the operator types each reading "
                   "at the terminal (no ROS graph; bench/manual.py)")
    p.add_argument("--protocol", default="default", help="shipped protocol name or a path")
    p.add_argument("--design", default=None, help="design (default: the protocol's)")
    p.add_argument("--sim-model", default="closed_form", help="rung that plays the rig's truth")
    p.add_argument("--model", nargs="+", default=["closed_form"], help="rung(s) overlaid in the report")
    p.add_argument("--output-dir", default="runs", help="where the recording directory goes (default runs/)")
    p.add_argument("--timeout", type=float, default=170.0, help="give up after this many seconds")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench.protocol import load_protocol
    from ..bench.report import write_report
    from ..core.design import load_design

    if args.rig == "manual":
        return run_manual(args)
    protocol = load_protocol(args.protocol)
    design = load_design(args.design or protocol.design or "implemented_5mm")
    out_dir = Path(args.output_dir).resolve()
    name = f"bench_{protocol.name}_{datetime.now().strftime('%Y%m%d_%H%M%S')}"
    design_arg = design.source or design.name
    helpers = [("sim_bench_node", {"design": design_arg, "model": args.sim_model}),
               ("model_node", {"design": design_arg, "model": args.model[0]})]
    if protocol.drive == "direction":
        helpers.append(("allocation_node", {"design": design_arg, "model": args.model[0]}))
    logs = out_dir / f"{name}_logs"
    logs.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    say = (lambda *a: None) if args.json else (lambda *a: print(*a, flush=True))
    # A private domain unless told: another graph on ours could publish on our topics.
    explicit = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if explicit and not (explicit.isdigit() and int(explicit) <= 232):
        raise SoftcathError(f"ROS_DOMAIN_ID={explicit!r}: must be an integer 0..232 (or unset for a private domain)")
    with NodeGraph(domain=int(explicit) if explicit else None, probe_s=0.0 if explicit else 1.0) as graph:
        bench = None
        timed_out: list[bool] = []
        try:
            for node, params in helpers:
                log = open(logs / f"{node}.log", "w")
                graph.start(node, params, stdout=log)
                log.close()
                say(f"[characterise] started {node} (log {logs / (node + '.log')})")
            bench = graph.start("bench_node", {"protocol": args.protocol, "design": design_arg,
                                               "model": args.model[0], "output_dir": out_dir, "name": name})
            watchdog = threading.Timer(args.timeout, lambda: (timed_out.append(True), stop_process(bench, 15.0)))
            watchdog.daemon = True
            watchdog.start()
            say(f"[characterise] bench_node running protocol '{protocol.name}' on ROS_DOMAIN_ID={graph.domain}")
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
                stop_process(bench, 15.0)
            raise
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
