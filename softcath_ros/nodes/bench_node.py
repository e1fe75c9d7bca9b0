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

It waits (up to ``wait_timeout`` s) for a rig: a publisher of /softcath/pressure_measured
and a subscriber of /softcath/pressure_cmd (by direction also allocation_node: a
subscriber of /softcath/bend_cmd that publishes /softcath/pressure_cmd). If that rig is
sim_bench_node (its node is in the graph or it announced itself on /softcath/bench/rig),
the recording is marked simulated. At the end it prints ``recording: PATH`` and a
one-line summary.

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
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, String

from .. import topics
from ..bench.protocol import ProtocolRunner, expand_steps, load_protocol
from ..core.checks import NAME_RULE, is_file_name
from ..core.design import load_design
from ..core.errors import SoftcathError
from ..recording import BagWriter
from .parameters import declare
from .recorder import TopicRecorder
from .runtime import EXECUTORS, run_node

DEFAULT_TOPICS = topics.RECORDED


class BenchNode(Node):
    def __init__(self, **node_options):
        super().__init__(topics.BENCH_NODE, **node_options)
        p = partial(declare, self)
        protocol_name = p("protocol", "default", "protocol file or shipped protocol name")
        design_name = p("design", "", "design file or shipped design name (default: the protocol's)")
        model_name = p("model", "closed_form", "model rung the allocator uses for a protocol by direction")
        output_dir = p("output_dir", "runs", "folder the recording is written under")
        run_name = p("name", "", "recording name (default: bench_<protocol>_<date>_<time>)")
        record_topics = p("record_topics", list(DEFAULT_TOPICS), "topics recorded to MCAP")
        rate_hz = p("rate_hz", 50.0, "protocol and command rate, Hz", minimum=1.0, maximum=1000.0)
        flush_period = p("flush_period", 1.0, "seconds between recording flushes", minimum=0.01, maximum=60.0)
        self.wait_timeout = p("wait_timeout", 20.0, "seconds to wait for a rig before giving up",
                              minimum=0.1, maximum=3600.0)
        self.start_delay = p("start_delay", 1.0, "seconds between finding the rig and the first step",
                             minimum=0.0, maximum=60.0)
        min_free_mb = p("min_free_mb", 64, "stop recording below this much free disk, MiB", minimum=0)
        self.executor_name = p("executor", "events", f"executor: {' | '.join(EXECUTORS)}", choices=EXECUTORS)
        self.protocol = load_protocol(protocol_name)
        design_name = design_name or self.protocol.design
        if not design_name:
            raise SoftcathError("no design: set the 'design' parameter or 'design' in the protocol")
        self.design = load_design(design_name)
        allocator = None
        if self.protocol.drive == "direction":
            from ..core.allocation import Allocator
            from ..core.models import make_model
            allocator = Allocator(make_model(model_name, self.design))
        self.steps = expand_steps(self.protocol, self.design.n_channels, self.design.max_pressure, allocator)
        stamp = datetime.now().strftime("%Y%m%d_%H%M%S")
        if run_name and not is_file_name(run_name):   # it names the recording folder under output_dir
            raise SoftcathError(f"parameter name = {run_name!r}: {NAME_RULE}")
        name = run_name or f"bench_{self.protocol.name}_{stamp}"
        self.writer = BagWriter(Path(output_dir) / name, flush_period_s=flush_period,
                                min_free_bytes=min_free_mb << 20, background=True,
                                custom_data={"protocol": self.protocol.name, "design": self.design.name})
        self.runner = ProtocolRunner(self.protocol, self.steps)
        reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.by_direction = self.protocol.drive == "direction"
        if self.by_direction:
            self.pub_bend = self.create_publisher(Vector3Stamped, topics.BEND_CMD, reliable)
        else:
            self.pub_cmd = self.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, reliable)
        self.pub_step = self.create_publisher(String, topics.BENCH_STEP, reliable)
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.measured = None
        self.rig_info: dict | None = None
        self.create_subscription(Float64MultiArray, topics.PRESSURE_MEASURED, self.on_measured, 10)
        self.create_subscription(String, topics.BENCH_RIG, self.on_rig,
                                 QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.recorder = TopicRecorder(self, self.writer, list(record_topics),
                                      message_info=self.executor_name != "events")
        self.state = "waiting"
        self.t0 = time.monotonic()
        self.t_ready: float | None = None
        self.t_end: float | None = None
        self.result = 0
        self.error: str | None = None
        self.create_timer(1.0 / rate_hz, self.tick)
        self.create_timer(1.0, self.diagnostics)
        self.get_logger().info(f"protocol {self.protocol.name}: {len(self.steps)} steps on design "
                               f"{self.design.name}; recording to {self.writer.path}")

    # -------------------------------------------------------------- inputs
    def on_measured(self, msg):
        p = np.asarray(msg.data, dtype=float)
        if p.shape == (self.design.n_channels,) and np.all(np.isfinite(p)):
            self.measured = p

    def on_rig(self, msg):
        try:
            self.rig_info = json.loads(msg.data)
        except ValueError:
            self.rig_info = {"raw": msg.data}

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
                self.writer.flush()

    def rig_ready(self) -> bool:
        rig = (self.count_publishers(topics.PRESSURE_MEASURED) > 0
               and self.count_subscribers(topics.PRESSURE_CMD) > 0 and self.measured is not None)
        if self.by_direction:  # allocation_node: listens to bend_cmd, publishes pressure_cmd
            return rig and self.count_subscribers(topics.BEND_CMD) > 0 and \
                self.count_publishers(topics.PRESSURE_CMD) > 0
        return rig

    def other_commanders(self) -> list[str]:
        """Nodes publishing /softcath/pressure_cmd that should not: besides this node (per channel)
        or besides allocation_node (by direction)."""
        allowed = topics.ALLOCATION_NODE if self.by_direction else self.get_name()
        return [f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                for i in self.get_publishers_info_by_topic(topics.PRESSURE_CMD)
                if i.node_name != allowed]

    def fail(self, message: str, code: int) -> None:
        self.get_logger().error(message)
        self.error = message
        self.result = code
        self.state = "done"

    def publish_command(self, pressures, bend) -> None:
        if self.by_direction:
            msg = Vector3Stamped()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = topics.FRAME_ID
            msg.vector.x, msg.vector.y = float(bend[0]), float(bend[1])
            self.pub_bend.publish(msg)
        else:
            self.pub_cmd.publish(Float64MultiArray(data=[float(x) for x in pressures]))

    def tick(self):
        t = self.now()
        if self.state == "waiting":
            if self.rig_ready():
                if self.t_ready is None:
                    self.t_ready = t  # let late discovery (subscriptions, recorder) settle
                elif t - self.t_ready >= self.start_delay:
                    self.begin(t)
            elif t > self.wait_timeout:
                self.fail(f"no rig: nothing publishes {topics.PRESSURE_MEASURED} or listens to "
                          f"{topics.PRESSURE_CMD} (start sim_bench_node or the hardware driver)"
                          + ("; a protocol by direction also needs allocation_node" if self.by_direction
                             else ""), 3)
            return
        if self.state == "running":
            self.publish_events(self.runner.update(t, self.measured))
            self.publish_command(self.runner.command, self.runner.bend_command)
            if self.runner.done:
                self.state = "finishing"
                self.t_end = t
        elif self.state == "finishing":
            self.publish_command(np.zeros(self.design.n_channels), (0.0, 0.0))
            if t - self.t_end > 0.5:  # the last readings and markers reach the recorder
                self.state = "done"

    def begin(self, t: float):
        others = self.other_commanders()
        if others:
            return self.fail(f"{', '.join(others)} also publish(es) /softcath/pressure_cmd: " + (
                "a protocol by direction needs allocation_node as its only publisher" if self.by_direction
                else "a per-channel protocol must be its only publisher (stop allocation_node, or run a "
                "protocol by direction through it)"), 4)
        simulated = topics.SIM_BENCH_NODE in self.get_node_names() or bool(self.rig_info and self.rig_info.get("simulated"))
        self.simulated = simulated
        self.writer.custom_data["simulated"] = str(simulated).lower()
        meta = {"simulated": str(simulated).lower(), "protocol": self.protocol.name,
                "design": self.design.name, "design_hash": self.design.content_hash(),
                "n_steps": str(len(self.steps)), "started": datetime.now().isoformat(timespec="seconds"),
                "rig": json.dumps(self.rig_info) if self.rig_info else "unknown"}
        self.writer.add_metadata("softcath", meta)
        self.writer.add_attachment("protocol.yaml", "application/yaml", self.protocol.to_yaml().encode())
        import yaml
        self.writer.add_attachment("design.yaml", "application/yaml",
                                   yaml.safe_dump(self.design.to_dict(), sort_keys=False).encode())
        self.state = "running"
        self.get_logger().info(f"rig found ({'simulated' if simulated else 'hardware'}); starting protocol")
        self.publish_events(self.runner.start(t))

    def diagnostics(self):
        others = self.other_commanders() if self.state == "running" else []
        if others:
            self.fail(f"{', '.join(others)} started publishing /softcath/pressure_cmd during the protocol: "
                      "stopped (the commands would fight)", 4)
        r = self.recorder
        level = DiagnosticStatus.OK if r.dropped == 0 and r.error is None else DiagnosticStatus.WARN
        step = self.runner.step
        st = DiagnosticStatus(level=level, name=topics.BENCH_NODE, message=f"{self.state}"
                              + (f", step {step.index + 1}/{len(self.steps)}" if step else ""),
                              values=[KeyValue(key="recording", value=str(self.writer.path)),
                                      KeyValue(key="messages", value=str(self.writer.message_count)),
                                      KeyValue(key="dropped", value=str(r.dropped)),
                                      KeyValue(key="pending_topics", value=",".join(r.pending))])
        msg = DiagnosticArray(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def finalise(self) -> dict:
        self.writer.close()
        return {"recording": str(self.writer.path), "messages": self.writer.message_count,
                "dropped": self.recorder.dropped,
                "lost_in_middleware": self.recorder.lost if self.recorder.counts_middleware_loss else None,
                "write_failures": self.recorder.write_failures,
                "per_topic": {k: v.message_count for k, v in self.writer.topics.items()},
                "not_seen": list(self.recorder.pending), "state": self.state, "error": self.error,
                "unsettled_steps": [k for k, ok in enumerate(self.runner.settled_flags) if not ok]}

    # -------------------------------------------------------------- the shared runtime's hooks
    @property
    def finished(self) -> bool:
        """The protocol ended (done or failed): the runtime stops spinning."""
        return self.state == "done"

    def finish(self) -> int:
        """Finalise the recording (also when interrupted), print where it is; the exit code."""
        summary = self.finalise()
        if self.state != "done":
            summary["state"] = "interrupted"
        print(f"recording: {summary['recording']}", flush=True)
        print("summary: " + json.dumps(summary), flush=True)
        return 130 if summary["state"] == "interrupted" else self.result


def main(args=None) -> int:
    return run_node(BenchNode, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
