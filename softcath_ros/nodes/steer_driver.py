"""steer_driver (softcath_steer_driver): drives and scores one steering run (`softcath steer-sim`).

Waits until the simulated rig's true tip (/softcath/bench/tip_true) arrives, then publishes the
trajectory's first target until the controller answers it (the first non-zero
/softcath/pressure_cmd: on a loaded machine the controller may match the target topic late, and
targets it never got must not count against it). From that moment it publishes the trajectory's
targets on /softcath/tip_target at ``target_rate`` for ``duration`` s, records the
steering topics (topics.STEERING_RECORDED) to an MCAP bag, and scores the true tip against the
target (bench/steering_sim.metrics). Each true tip is scored at its stamp (when the rig took it),
not when this node got to it: on a loaded machine callbacks run late, and a tip read late must
not count against a later target. After the last target it waits for the tips stamped up to the
end of the run (at most DRAIN_TIMEOUT_S). Ends by itself and prints ``summary: {json}`` with the
metrics, the recording and the time series file (``<recording>/series.npz``).

The targets lie on the true workspace: they are built from the same truth the rig plays
(``truth_model``, pressure_shift, material_scale, max_pressure), as the core simulation does.
"""
from __future__ import annotations

import json
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.node import Node
from rclpy.time import Time
from std_msgs.msg import Float64MultiArray

from .. import topics
from ..bench.sim_rig import RigParams, truth_model
from ..bench.steering_sim import TRAJECTORIES, metrics, targets_for
from ..core.design import load_design
from ..core.errors import SoftcathError
from ..core.steering_range import steering_design, steering_model, steering_range
from ..recording import BagWriter
from .parameters import declare, refuse_unknown_parameters
from .qos import stream_qos
from .recorder import TopicRecorder
from .runtime import run_node

# s: after the last target, how long to wait for the rig's tips stamped up to the run's end
DRAIN_TIMEOUT_S = 5.0


class SteerDriver(Node):
    executor_name = "single"

    def __init__(self, **kwargs):
        super().__init__(topics.STEER_DRIVER, **kwargs)
        p = partial(declare, self)
        design = load_design(p("design", "three_sector_5mm", "design file or shipped design name"))
        truth = p("truth", "surrogate", "rung the simulated rig plays (for targets on its workspace)")
        shift = p("pressure_shift", 0.25, "the rig's pressure shift", minimum=0.0, maximum=0.99)
        scale = p("material_scale", 1.2, "the rig's material scale", minimum=0.05, maximum=20.0)
        max_pressure = p("max_pressure", lambda: steering_range(steering_model(truth, design)),
                         "the controller's pressure limit, Pa (default the design's steering range on the truth's rung)",
                         minimum=1.0)
        self.kind = p("trajectory", "step", f"one of {TRAJECTORIES}", choices=TRAJECTORIES)
        self.duration = p("duration", 6.0, "seconds of targets", minimum=0.1, maximum=3600.0)
        rate = p("target_rate", 100.0, "tip_target rate, Hz", minimum=1.0, maximum=1000.0)
        self.wait_timeout = p("wait_timeout", 60.0, "seconds to wait for the rig and the controller", minimum=0.1)
        out = p("output", "runs/steer", "recording directory (MCAP bag)")
        refuse_unknown_parameters(self)    # before a recording is opened on a typo's default
        rig = RigParams(pressure_shift=shift, material_scale=scale)
        truth_rung = truth_model(truth, design, rig)     # the design as shipped (a surrogate: its shipped table)
        design = steering_design(design, max_pressure)
        self.path = targets_for(self.kind, self.duration, truth_rung, (1.0 - shift) * design.max_pressure)
        self.writer = BagWriter(Path(out), background=True, custom_data={"design": design.name,
                                                                        "trajectory": self.kind})
        self.recorder = TopicRecorder(self, self.writer, list(topics.STEERING_RECORDED), message_info=True)
        qos = stream_qos(100)
        self.pub = self.create_publisher(PointStamped, topics.TIP_TARGET, qos)
        self.create_subscription(PoseStamped, topics.TIP_TRUE, self._on_true, 100)
        self.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, self._on_command, qos)
        self.t0_ns: int | None = None     # ROS time (ns) of the controller's first answer: t = 0
        self.t_drain = 0.0
        self.t_wait = time.monotonic()
        self.state = "waiting"
        self.samples: list[tuple] = []
        self.create_timer(1.0 / rate, self._tick)

    def _on_true(self, msg: PoseStamped) -> None:
        if self.state == "waiting" and self.count_subscribers(topics.TIP_TARGET) > 0:
            self.state = "priming"
            self.get_logger().info("rig and controller found: sending the first target until the controller answers")
        if self.state not in ("running", "draining"):
            return
        t = (Time.from_msg(msg.header.stamp).nanoseconds - self.t0_ns) * 1e-9
        if t < 0.0:
            return               # taken before the run started
        if t > self.duration:
            if self.state == "draining":
                self.state = "done"
            return
        q = msg.pose.position
        self.samples.append((t, *self.path(t), q.x, q.y, q.z))

    def _on_command(self, msg: Float64MultiArray) -> None:
        # Every trajectory starts away from the straight tip, so the controller's first answer to
        # the first target is a non-zero pressure.
        if self.state == "priming" and any(v > 0.0 for v in msg.data):
            self.state, self.t0_ns = "running", self.get_clock().now().nanoseconds
            self.get_logger().info(f"controller answered: {self.kind} for {self.duration:g} s")

    def _tick(self) -> None:
        now = time.monotonic()
        if self.state in ("waiting", "priming") and now - self.t_wait > self.wait_timeout:
            self.get_logger().error(f"no rig/controller answering within {self.wait_timeout:g} s "
                                    f"(stopped while {self.state})")
            self.state = "failed"
            return
        if self.state == "draining" and now - self.t_drain > DRAIN_TIMEOUT_S:
            self.get_logger().warning(f"no tip stamped after the run's end within {DRAIN_TIMEOUT_S:g} s: "
                                      "scoring the tips received")
            self.state = "done"
        if self.state == "priming":
            t = 0.0
        elif self.state == "running":
            t = (self.get_clock().now().nanoseconds - self.t0_ns) * 1e-9
            if t > self.duration:
                self.state, self.t_drain = "draining", now
                return
        else:
            return
        msg = PointStamped()
        msg.header.frame_id = topics.FRAME_ID
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in self.path(t))
        self.pub.publish(msg)

    @property
    def finished(self) -> bool:
        return self.state in ("done", "failed")

    def finish(self) -> int:
        self.writer.close()
        summary = {"recording": str(self.writer.path), "messages": self.writer.message_count,
                   "state": self.state if self.state in ("done", "failed") else "interrupted"}
        if self.samples:
            a = np.array(self.samples)
            series = Path(self.writer.bag_dir) / "series.npz"
            np.savez(series, t=a[:, 0], target=a[:, 1:4], tip=a[:, 4:7])
            summary["series"] = str(series)
            summary["metrics"] = metrics(a[:, 0], a[:, 1:4], a[:, 4:7], self.kind, self.duration,
                                         self.path.switch_times)
        print("summary: " + json.dumps(summary), flush=True)
        return 0 if summary["state"] == "done" else (130 if summary["state"] == "interrupted" else 3)


def main(args=None) -> int:
    return run_node(SteerDriver, args, startup_errors=(SoftcathError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
