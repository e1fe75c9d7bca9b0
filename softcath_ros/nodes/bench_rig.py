"""bench_node's watch on the rig (docs/rig.md): the rig's topics subscribed, their freshness, the
measured pressures, and the run's view of the rig (``RigView`` of bench/bench_run.py: what keeps it
from being ready, what went stale, who else commands the pressures). Mixed into ``BenchNode``."""
from __future__ import annotations

import json
import math
from functools import partial

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped, WrenchStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure
from std_msgs.msg import Float64, Float64MultiArray, String

from .. import topics
from ..bench.rig_contract import RigMonitor, graph_problems, with_driver_reports

LEVEL_NAMES = {1: "WARN", 2: "ERROR", 3: "STALE"}    # diagnostic_msgs/DiagnosticStatus levels


def _stamp_s(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


class RigWatch:
    """The rig's inputs and the run's view of the rig (a mixin of ``BenchNode``: it reads the node's
    design, protocol, clock and recorder)."""

    def rig_monitors(self, n: int, stale_after: float) -> None:
        """The rig's topics (docs/rig.md) for ``n`` channels, and the deprecated unstamped ones for one
        release; readings older than ``stale_after`` s are stale."""
        extra = [topics.PRESSURE_CMD] if self.by_direction else []  # allocation_node keeps publishing
        # only the readings of the benches this protocol uses are required (all are recorded)
        benches = tuple(dict.fromkeys(b.kind for b in self.protocol.benches))
        self.contract = RigMonitor(topics.rig_topics(n, benches) + extra, stale_after)
        self.legacy = RigMonitor(topics.deprecated_rig_topics(benches) + extra, stale_after)

    def watch_rig(self, n: int) -> None:
        """Subscribe to the rig's topics (``rig_monitors`` first)."""
        self.monitor: RigMonitor | None = None   # the one chosen when the rig is found
        self.channel_pressures = np.full(n, np.nan)
        self.legacy_pressures: np.ndarray | None = None
        for c in range(n):
            self.create_subscription(FluidPressure, topics.pressure_measured_topic(c),
                                     partial(self.on_channel_pressure, c), 10)
        self.create_subscription(Vector3Stamped, topics.BENCH_BEND_ANGLE,
                                 partial(self.on_stamped, topics.BENCH_BEND_ANGLE), 10)
        self.create_subscription(WrenchStamped, topics.BENCH_WRENCH, partial(self.on_stamped, topics.BENCH_WRENCH), 10)
        self.create_subscription(Float64MultiArray, topics.PRESSURE_MEASURED, self.on_legacy_pressure, 10)
        for t in (topics.BENCH_ANGLE, topics.BENCH_FORCE):
            self.create_subscription(Float64, t, partial(self.on_legacy, t), 10)
        if self.by_direction:
            self.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, self.on_allocator_command, 10)
        self.driver_reports: dict[str, str] = {}     # node -> its last /diagnostics report that is not OK
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.on_diagnostics, 10)
        self.rig_info: dict | None = None
        self.create_subscription(String, topics.BENCH_RIG, self.on_rig,
                                 QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))

    # -------------------------------------------------------------- inputs
    def clock_s(self) -> float:
        """The ROS clock the rig's stamps are compared with, s."""
        return self.get_clock().now().nanoseconds * 1e-9

    def on_channel_pressure(self, channel: int, msg):
        if math.isfinite(msg.fluid_pressure):
            self.channel_pressures[channel] = msg.fluid_pressure
            self.contract.seen(topics.pressure_measured_topic(channel), self.now(), _stamp_s(msg.header))

    def on_stamped(self, topic: str, msg):
        self.contract.seen(topic, self.now(), _stamp_s(msg.header))

    def on_legacy_pressure(self, msg):
        p = np.asarray(msg.data, dtype=float)
        if p.shape == (self.design.n_channels,) and np.all(np.isfinite(p)):
            self.legacy_pressures = p
            self.legacy.seen(topics.PRESSURE_MEASURED, self.now())

    def on_legacy(self, topic: str, msg):
        self.legacy.seen(topic, self.now())

    def on_allocator_command(self, msg):
        for m in (self.contract, self.legacy):
            m.seen(topics.PRESSURE_CMD, self.now())

    def measured(self) -> np.ndarray | None:
        """The measured pressures (Pa per channel) if every channel's reading is fresh, else None:
        a stale reading is never used as a fresh one."""
        if self.monitor is None:
            return None
        t, clock = self.now(), self.clock_s()
        if self.monitor is self.legacy:
            return self.legacy_pressures if self.legacy.alive(topics.PRESSURE_MEASURED, t) else None
        chans = [topics.pressure_measured_topic(c) for c in range(self.design.n_channels)]
        return self.channel_pressures.copy() if all(self.contract.alive(c, t, clock) for c in chans) else None

    def on_diagnostics(self, msg):
        for status in msg.status:
            level = status.level[0] if isinstance(status.level, bytes) else int(status.level)
            if level in LEVEL_NAMES:
                self.driver_reports[status.name] = f"{LEVEL_NAMES[level]} {status.message}"
            else:
                self.driver_reports.pop(status.name, None)

    def on_rig(self, msg):
        try:
            self.rig_info = json.loads(msg.data)
        except ValueError:
            self.rig_info = {"raw": msg.data}

    # -------------------------------------------------------------- the run's view of the rig (RigView)
    def problems(self) -> dict[str, str]:
        out = self.rig_problems()
        if out:
            self.monitor = None   # chosen afresh when the rig is ready again
        return out

    def stale(self, lost_after: float) -> dict[str, str]:
        return self.monitor.problems(self.now(), None if self.monitor is self.legacy else self.clock_s(), lost_after)

    def recording_error(self) -> str | None:
        return self.recorder.error

    def graph_problems(self) -> tuple[RigMonitor, dict[str, str]]:
        return graph_problems(self.contract, self.legacy, self.design.n_channels, self.count_publishers,
                              self.count_subscribers, self.by_direction)

    def rig_problems(self) -> dict[str, str]:
        """What keeps the rig from being ready, by topic (empty: ready): the graph's lacks, then each
        topic that is not alive. Chooses the monitor when the rig is ready."""
        t, clock = self.now(), self.clock_s()
        monitor, out = self.graph_problems()
        for topic in monitor.topics:
            why = None if topic in out else monitor.problem(topic, t, clock)
            if why:
                out[topic] = why
        if out and self.driver_reports:
            out = with_driver_reports(out, self.publisher_nodes, self.driver_reports)
        if not out and self.monitor is None:
            self.monitor = monitor
            if monitor is self.legacy:
                self.get_logger().warning(
                    f"the rig publishes the deprecated unstamped {', '.join(topics.DEPRECATED_RIG_TOPICS)}: "
                    "accepted for this release (freshness by arrival time only); publish the stamped "
                    "topics of docs/rig.md")
        return out

    def publisher_nodes(self, topic: str) -> list[str]:
        return [i.node_name for i in self.get_publishers_info_by_topic(topic)]

    def other_commanders(self) -> list[str]:
        """Nodes publishing /softcath/pressure_cmd that should not: besides this node (per channel)
        or besides allocation_node (by direction)."""
        allowed = topics.ALLOCATION_NODE if self.by_direction else self.get_name()
        return [f"{i.node_namespace.rstrip('/')}/{i.node_name}"
                for i in self.get_publishers_info_by_topic(topics.PRESSURE_CMD)
                if i.node_name != allowed]
