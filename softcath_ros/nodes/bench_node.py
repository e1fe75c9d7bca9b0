"""bench_node (node ``softcath_bench``): runs a test protocol and records everything to MCAP.

The protocol engine (bench.protocol.ProtocolRunner) decides; this node publishes its
commands and its markers (JSON) on /softcath/bench/step, feeds it the measured pressures,
and records the listed topics with a TopicRecorder into a rosbag2-style bag directory
under ``output_dir``. Chunks are flushed every second and at each step end; SIGINT/SIGTERM
vent nothing it does not own but always finalise the file.

Commands: a per-channel protocol publishes /softcath/pressure_cmd itself and must be its
only publisher (another one, e.g. allocation_node, would fight the staircase: the run
stops with an error, exit code 4). A protocol by bending direction publishes the requested
curvature on /softcath/bend_cmd and allocation_node, then the only publisher allowed,
turns it into /softcath/pressure_cmd.

The rig contract (docs/rig.md): configure waits up to ``wait_timeout`` s until every rig topic the
protocol uses (/softcath/pressure_measured/ch<i>; /softcath/bench/bend_angle for an angle bench,
/softcath/bench/wrench for a force bench) has a publisher and something listens to
/softcath/pressure_cmd (by direction allocation_node too), else it fails naming each missing topic
(exit 3 at start-up, nothing recorded). The run then waits (as long) until each is alive with fresh
stamps (by direction allocation_node's /softcath/pressure_cmd keeps coming; a timeout names each
topic, exit 3) and the pressure source follows a small test command (exit 3 if not). A rig on
the deprecated unstamped topics is accepted with a warning. During the run a reading
older than ``stale_after`` s is never used; when any rig topic (or allocation_node's command)
has been stale for ``lost_after`` s the run stops: the "protocol_abort" marker, zero command for
0.3 s, the recording finalised and marked incomplete, exit 5. A failing recording (disk full) stops it likewise,
exit 6. If the rig is sim_bench_node (its node is in the graph or it announced itself on
/softcath/bench/rig), the recording is marked simulated. At the end it prints
``recording: PATH`` and a one-line summary.

The run's logic (waiting, follow test, steps, venting, aborts) is bench/bench_run.py's state machine;
this node adapts it (its observations in, its actions out; the rig's inputs and the run's view of
the rig in nodes/bench_rig.py). A managed (lifecycle) node: configure loads the protocol, checks
the rig and opens the recording, activate runs, deactivate stops (abort marker, zero command, exit
130); ``autostart`` (default true) does both at start-up, else `softcath characterise` (or any
lifecycle manager) drives them.

The node spins on the EventsExecutor and writes in a background thread by default
(``executor`` parameter; see nodes/recorder.py and benchmarks/recorder_throughput.py).
"""
from __future__ import annotations

import json
import sys
import time
from datetime import datetime
from functools import partial
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Vector3Stamped
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, String

from .. import topics
from ..bench.protocol import ProtocolRunner, design_steps, load_protocol
from ..bench.bench_run import (EXIT_FIGHT, EXIT_RECORDING, Begin, BenchRun, Command, Markers,
                               Say, Vent, VentDirectly)
from ..bench.rig_contract import FollowCheck, follow_test_command, wait_for_rig
from ..core.checks import NAME_RULE, is_file_name
from ..core.design import load_design
from ..core.errors import SoftcathError
from ..recording import BagWriter, RecordingError, check_destination
from .bench_rig import RigWatch
from .diagnostics import diagnostic_status, publish_statuses
from .parameters import declare, refuse_unknown_parameters
from .recorder import TopicRecorder
from .executors import EXECUTORS
from .runtime import pause, run_node

DEFAULT_TOPICS = topics.RECORDED

# Exit codes (docs/rig.md): 0 done, 2 cannot start, 3 no rig or it failed the checks before the
# first step, 4 another node commands the pressures, 5 the rig stopped answering mid-run,
# 6 the recording failed (disk full), 130 interrupted (SIGINT/SIGTERM).
# (bench/bench_run.py decides them).
EXIT_INTERRUPTED = 130


class BenchNode(RigWatch, LifecycleNode):
    def __init__(self, **node_options):
        super().__init__(topics.BENCH_NODE, **node_options)
        p = partial(declare, self)
        self.settings = dict(  # what configure uses
            protocol_name=p("protocol", "default", "protocol file or shipped protocol name"),
            design_name=p("design", "", "design file or shipped design name (default: the protocol's)"),
            model_name=p("model", "surrogate", "model rung the allocator uses for a protocol by direction "
                         "(as allocation_node)"),
            output_dir=p("output_dir", "runs", "folder the recording is written under"),
            run_name=p("name", "", "recording name (default: bench_<protocol>_<date>_<time>)"),
            record_topics=p("record_topics", list(DEFAULT_TOPICS), "topics recorded to MCAP"),
            rate_hz=p("rate_hz", 50.0, "protocol and command rate, Hz", minimum=1.0, maximum=1000.0),
            flush_period=p("flush_period", 1.0, "seconds between recording flushes", minimum=0.01, maximum=60.0))
        self.wait_timeout = p("wait_timeout", 20.0, "seconds to wait for a rig before giving up",
                              minimum=0.1, maximum=3600.0)
        self.start_delay = p("start_delay", 1.0, "seconds between finding the rig and the first step",
                             minimum=0.0, maximum=60.0)
        self.settings["min_free_mb"] = p("min_free_mb", 64, "stop recording below this much free disk, MiB", minimum=0)
        self.stale_after = stale_after = p("stale_after", 0.5, "a rig reading older than this (s) is stale: "
                                           "never used, its rig topic is not ready", minimum=0.05, maximum=60.0)
        self.lost_after = p("lost_after", 1.0, "a rig topic stale this long (s) mid-run: the run stops "
                            "(at least stale_after)", minimum=0.05, maximum=60.0)
        if self.lost_after < stale_after:
            raise SoftcathError(f"parameter lost_after = {self.lost_after:g}: must be at least stale_after "
                                f"= {stale_after:g}")
        self.follow_pressure = p("follow_test_pressure", 5000.0, "Pa, largest channel of the test command "
                                 "the pressure source must follow before the first step", minimum=100.0)
        self.follow_timeout = p("follow_timeout", 3.0, "s the pressure source gets to follow the test command",
                                minimum=0.1, maximum=120.0)
        self.executor_name = p("executor", "events", f"executor: {' | '.join(EXECUTORS)}", choices=EXECUTORS)
        autostart = p("autostart", True, "configure and activate at start (false: a lifecycle manager drives it: configure "
                      "loads the protocol, checks the rig, opens the recording; activate runs; deactivate vents, stops)")
        refuse_unknown_parameters(self)    # before a recording is opened on a typo's default
        self.run: BenchRun | None = None
        self.timer = None
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.configure_error: SoftcathError | None = None
        self._autostart = autostart
        if autostart:
            self.trigger_configure()
            if self.run is None:
                raise self.configure_error   # its exit code: 3 for no rig (NoRig), else 2
            self.trigger_activate()

    # -------------------------------------------------------------- lifecycle
    def on_configure(self, state) -> TransitionCallbackReturn:
        """Load the protocol and design, open the recording, subscribe to the rig's topics."""
        try:
            self.configure_run(**self.settings)
        except (SoftcathError, ValueError) as exc:
            self.configure_error = exc if isinstance(exc, SoftcathError) else SoftcathError(str(exc))
            if not self._autostart:   # (at start-up the one line is the exit's)
                self.get_logger().error(f"configure: {exc}")
                publish_statuses(self, self.pub_diag, diagnostic_status(
                    DiagnosticStatus.ERROR, topics.BENCH_NODE, f"configure failed: {exc}", []))
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        """Run: wait for the rig, test the pressure source, the protocol's steps."""
        self.t0 = time.monotonic()
        self.timer = self.create_timer(1.0 / self.settings["rate_hz"], self.tick)
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        """Stop: after a command, the abort marker and zero command (the tick vents until done); before
        one, done at once. The recording is finalised on the way out."""
        if not self.run.done:
            message = "interrupted (lifecycle deactivate): stopped" + (" and vented" if self.run.commanding else "")
            if self.run.commanding:
                self.perform(self.run.abort(self.now(), message, EXIT_INTERRUPTED))
            else:
                self.perform(self.run.fail(message, EXIT_INTERRUPTED))
        return super().on_deactivate(state)

    def configure_run(self, protocol_name, design_name, model_name, output_dir, run_name, record_topics, rate_hz,
                      flush_period, min_free_mb) -> None:
        stale_after = self.stale_after
        self.protocol = load_protocol(protocol_name)
        design_name = design_name or self.protocol.design
        if not design_name:
            raise SoftcathError("no design: set the 'design' parameter or 'design' in the protocol")
        self.design = load_design(design_name)
        self.steps = design_steps(self.protocol, self.design, model_name)
        self.by_direction = self.protocol.drive == "direction"
        if run_name and not is_file_name(run_name):   # it names the recording folder under output_dir
            raise SoftcathError(f"parameter name = {run_name!r}: {NAME_RULE}")
        test_pressures, self.follow_bend = follow_test_command(self.steps, self.follow_pressure)
        name = run_name or f"bench_{self.protocol.name}_{datetime.now().strftime('%Y%m%d_%H%M%S')}"
        check_destination(Path(output_dir) / name)     # a bad output_dir is bad input (2), not "no rig"
        n = self.design.n_channels
        self.rig_monitors(n, stale_after)
        # the check: the rig's topics on the graph within wait_timeout (before a recording is opened)
        wait_for_rig(lambda: self.graph_problems()[1], self.wait_timeout, time.monotonic, partial(pause, self))
        self.writer = BagWriter(Path(output_dir) / name, flush_period_s=flush_period,
                                min_free_bytes=min_free_mb << 20, background=True,
                                custom_data={"protocol": self.protocol.name, "design": self.design.name,
                                             "stale_after_s": f"{stale_after:g}"})
        self.runner = ProtocolRunner(self.protocol, self.steps)
        reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        if self.by_direction:
            self.pub_bend = self.create_publisher(Vector3Stamped, topics.BEND_CMD, reliable)
        else:
            self.pub_cmd = self.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, reliable)
        self.pub_step = self.create_publisher(String, topics.BENCH_STEP, reliable)
        self.watch_rig(n)
        self.pub_vent = None
        self.recorder = TopicRecorder(self, self.writer, list(dict.fromkeys(list(record_topics) + topics.rig_topics(n))),
                                      message_info=self.executor_name != "events")
        self.run = BenchRun(self.runner, FollowCheck(test_pressures, timeout=self.follow_timeout), self.follow_bend,
                            n, self.by_direction, self.wait_timeout, self.start_delay, self.lost_after)
        self.t0 = time.monotonic()
        self.create_timer(1.0, self.diagnostics)
        self.get_logger().info(f"protocol {self.protocol.name}: {len(self.steps)} steps on design "
                               f"{self.design.name}; recording to {self.writer.path}")

    # -------------------------------------------------------------- protocol
    def now(self) -> float:
        return time.monotonic() - self.t0

    def publish_events(self, events):
        for ev in events:
            self.pub_step.publish(String(data=json.dumps(ev)))
            if ev["event"] == "step_start" and ev["step"] == 0 or (
                    ev["event"] == "step_start" and self.steps[ev["step"] - 1].trial != ev["trial"]):
                self.get_logger().info(f"step {ev['step'] + 1}/{len(self.steps)}: {ev['bench']} bench, "
                                       f"{ev['sample_name']}, {ev['drive']}, trial {ev['trial'] + 1}")
            if ev["event"] == "step_end":
                try:
                    self.writer.flush()
                except RecordingError as exc:
                    self.recorder.error = str(exc)

    def perform(self, actions) -> None:
        """Carry out what the run decided (bench.bench_run)."""
        for a in actions:
            if isinstance(a, Command):
                self.publish_command(a.pressures, a.bend)
            elif isinstance(a, Vent):
                self.vent()
            elif isinstance(a, Markers):
                self.publish_events(a.events)
            elif isinstance(a, Say):   # (rclpy fixes a call site's severity: one call per level)
                if a.level == "error":
                    self.get_logger().error(a.text)
                elif a.level == "warning":
                    self.get_logger().warning(a.text)
                else:
                    self.get_logger().info(a.text)
            elif isinstance(a, VentDirectly):
                # allocation_node may be the one that died: vent the rig directly too.
                self.pub_vent = self.create_publisher(Float64MultiArray, topics.PRESSURE_CMD,
                                                      QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
            elif isinstance(a, Begin):
                self.begin(self.now())

    def publish_command(self, pressures, bend) -> None:
        if self.by_direction:
            msg = Vector3Stamped()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = topics.FRAME_ID
            msg.vector.x, msg.vector.y = float(bend[0]), float(bend[1])
            self.pub_bend.publish(msg)
        else:
            self.pub_cmd.publish(Float64MultiArray(data=[float(x) for x in pressures]))

    def vent(self) -> None:
        zeros = np.zeros(self.design.n_channels)
        self.publish_command(zeros, (0.0, 0.0))
        if self.pub_vent is not None:
            self.pub_vent.publish(Float64MultiArray(data=[0.0] * len(zeros)))

    def tick(self):
        self.perform(self.run.tick(self.now(), self))

    def begin(self, t: float):
        others = self.other_commanders()
        if others:
            return self.perform(self.run.fail(f"{', '.join(others)} also publish(es) /softcath/pressure_cmd: " + (
                "a protocol by direction needs allocation_node as its only publisher" if self.by_direction
                else "a per-channel protocol must be its only publisher (stop allocation_node, or run a "
                "protocol by direction through it)"), EXIT_FIGHT))
        simulated = topics.SIM_BENCH_NODE in self.get_node_names() or bool(self.rig_info and self.rig_info.get("simulated"))
        self.simulated = simulated
        self.writer.custom_data["simulated"] = str(simulated).lower()
        meta = {"simulated": str(simulated).lower(), "protocol": self.protocol.name,
                "design": self.design.name, "design_hash": self.design.content_hash(),
                "n_steps": str(len(self.steps)), "started": datetime.now().isoformat(timespec="seconds"),
                "rig": json.dumps(self.rig_info) if self.rig_info else "unknown",
                "stale_after_s": self.writer.custom_data["stale_after_s"],
                "rig_topics": "deprecated unstamped" if self.monitor is self.legacy else "stamped"}
        import yaml
        try:
            self.writer.add_metadata("softcath", meta)
            self.writer.add_attachment("protocol.yaml", "application/yaml", self.protocol.to_yaml().encode())
            self.writer.add_attachment("design.yaml", "application/yaml",
                                       yaml.safe_dump(self.design.to_dict(), sort_keys=False).encode())
        except RecordingError as exc:
            return self.perform(self.run.fail(f"recording failed: {exc}", EXIT_RECORDING))
        self.perform(self.run.begin(t))
        self.get_logger().info(f"rig found ({'simulated' if simulated else 'hardware'}); testing that the "
                               "pressure source follows a small command")

    def diagnostics(self):
        others = self.other_commanders() if self.run.commanding else []
        if others:
            self.perform(self.run.abort(self.now(), f"{', '.join(others)} started publishing /softcath/pressure_cmd during the protocol: "
                       "stopped (the commands would fight)", EXIT_FIGHT))
        r = self.recorder
        level = DiagnosticStatus.OK if r.dropped == 0 and r.error is None else DiagnosticStatus.WARN
        step = self.runner.step
        message = f"{self.state}" + (f", step {step.index + 1}/{len(self.steps)}" if step else "")
        publish_statuses(self, self.pub_diag, diagnostic_status(level, topics.BENCH_NODE, message, [
            ("recording", self.writer.path), ("messages", self.writer.message_count), ("dropped", r.dropped),
            ("pending_topics", ",".join(r.pending))]))

    def finalise(self, interrupted: bool = False) -> dict:
        """Mark the recording complete or not (metadata record and rosbag2 custom_data), close it.
        A failing disk is said in one line; the chunks written so far stay recoverable."""
        run = self.run
        complete = run.done and run.error is None and self.runner.done and not interrupted
        reason = "" if complete else (run.stop_reason or ("interrupted (SIGINT/SIGTERM)" if interrupted else
                                                           "stopped before the protocol ended"))
        result = {"complete": str(complete).lower(), "completed_steps": str(run.completed_steps),
                  "n_steps": str(len(self.steps)), "reason": reason}
        self.writer.custom_data.update(complete=result["complete"], completed_steps=result["completed_steps"])
        try:
            self.writer.add_metadata("softcath_result", result)
            self.writer.close()
        except (RecordingError, OSError) as exc:
            msg = str(exc) if isinstance(exc, RecordingError) else f"closing {self.writer.path} failed: {exc}"
            run.error = run.error or f"recording failed: {msg}"
            run.result = run.result or EXIT_RECORDING
            self.writer.abandon()
        return {"recording": str(self.writer.path), "messages": self.writer.message_count,
                "dropped": self.recorder.dropped,
                "lost_in_middleware": self.recorder.lost if self.recorder.counts_middleware_loss else None,
                "write_failures": self.recorder.write_failures,
                "per_topic": {k: v.message_count for k, v in self.writer.topics.items()},
                "not_seen": list(self.recorder.pending), "state": self.state, "error": run.error,
                "complete": complete, "completed_steps": run.completed_steps, "n_steps": len(self.steps),
                "unsettled_steps": [k for k, ok in enumerate(self.runner.settled_flags) if not ok]}

    @property
    def state(self) -> str:
        return self.run.state.value

    # -------------------------------------------------------------- the shared runtime's hooks
    @property
    def finished(self) -> bool:
        """The protocol ended (done or failed): the runtime stops spinning."""
        return self.run is not None and self.run.done

    def finish(self) -> int:
        """Finalise the recording (also when interrupted), print where it is; the exit code."""
        if self.run is None:   # never configured: no recording
            return 0
        # A signal during the venting after an abort keeps the abort's reason and code.
        interrupted = not self.run.done and self.run.error is None
        summary = self.finalise(interrupted)
        if interrupted:
            summary["state"] = "interrupted"
        print(f"recording: {summary['recording']}", flush=True)
        print("summary: " + json.dumps(summary), flush=True)
        if summary["error"]:
            print(f"[ERROR] {summary['error']}", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED if interrupted else self.run.result


def main(args=None) -> int:
    return run_node(BenchNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
