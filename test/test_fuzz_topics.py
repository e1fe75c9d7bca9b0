"""A bounded flood of hostile messages on every input topic of model_node, allocation_node and
sim_bench_node (in-process, one executor): no callback raises, nothing non-finite is published, no published
pressure leaves [0, max_pressure], and /diagnostics keeps reporting."""
import json
import math
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")
pytestmark = pytest.mark.ros

from domains import private_domain  # noqa: E402
from softcath_ros import topics  # noqa: E402

N_MESSAGES = 1000          # per input topic kind, sent as fast as the publisher goes
EDGES = [math.nan, math.inf, -math.inf, 1e308, -1e308, -1.0, 0.0, 1e-300, 5e4, 5e4 * (1 + 1e-12), 1e9, 3.0]


def _hostile(rng: np.random.Generator, size: int) -> list[float]:
    """``size`` values, each an edge value or a random one of random magnitude."""
    out = []
    for _ in range(size):
        if rng.random() < 0.5:
            out.append(float(rng.choice(EDGES)))
        else:
            out.append(float(rng.normal() * 10.0 ** rng.integers(-3, 7)))
    return out


def _finite(values) -> bool:
    return all(math.isfinite(v) for v in values)


def test_hostile_flood_on_every_input_topic(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PointStamped, PoseArray, PoseStamped, Vector3Stamped, WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import FluidPressure
    from std_msgs.msg import Float64MultiArray, String

    from softcath_ros.nodes.allocation_node import AllocationNode
    from softcath_ros.nodes.model_node import ModelNode
    from softcath_ros.nodes.sim_bench_node import SimBenchNode

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    model = ModelNode(context=context, parameter_overrides=[Parameter("diagnostics_period", value=0.2)])
    # The allocator publishes on pressure_cmd too: the model node answers those as well.
    alloc = AllocationNode(context=context, parameter_overrides=[Parameter("diagnostics_period", value=0.2),
                                                                 Parameter("command_timeout", value=0.2)])
    from_allocator = []            # what the allocator itself publishes (the probe publishes on pressure_cmd too)
    publish = alloc.pub.publish
    alloc.pub.publish = lambda msg: (from_allocator.append(list(msg.data)), publish(msg))
    rig = SimBenchNode(context=context)
    # the deprecated unstamped readings are off by default (legacy_topics)
    assert all(rig.count_publishers(t) == 0 for t in topics.DEPRECATED_RIG_TOPICS)
    probe = rclpy.create_node("hostile_probe", context=context)
    outputs = {"tip": [], "backbone": [], "pressure": [], "diagnostics": [], "measured": [], "angle": [],
               "force": []}
    for c in range(len(rig.pub_pc)):   # the rig contract's stamped readings (docs/rig.md)
        probe.create_subscription(FluidPressure, topics.pressure_measured_topic(c), outputs["measured"].append, 1000)
    probe.create_subscription(Vector3Stamped, topics.BENCH_BEND_ANGLE, outputs["angle"].append, 1000)
    probe.create_subscription(WrenchStamped, topics.BENCH_WRENCH, outputs["force"].append, 1000)
    pub_s = probe.create_publisher(String, topics.BENCH_STEP, 100)
    probe.create_subscription(PoseStamped, topics.TIP_POSE, outputs["tip"].append, 1000)
    probe.create_subscription(PoseArray, topics.BACKBONE, outputs["backbone"].append, 1000)
    probe.create_subscription(Float64MultiArray, topics.PRESSURE_CMD, outputs["pressure"].append, 1000)
    probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, outputs["diagnostics"].append, 100)
    pub_p = probe.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, 1000)
    pub_k = probe.create_publisher(Vector3Stamped, topics.BEND_CMD, 1000)
    pub_t = probe.create_publisher(PointStamped, topics.TIP_TARGET, 1000)

    executor = SingleThreadedExecutor(context=context)
    for n in (model, alloc, rig, probe):
        executor.add_node(n)
    failures = []

    def spin():
        try:
            while context.ok():
                executor.spin_once(timeout_sec=0.05)
        except Exception as exc:  # noqa: BLE001 - a callback that raised: the test fails on it
            if context.ok():
                failures.append(repr(exc))

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    rng = np.random.default_rng(14)
    try:
        deadline = time.monotonic() + 10.0
        while pub_k.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        t0 = time.monotonic()
        for i in range(N_MESSAGES):
            size = int(rng.choice([0, 1, 1, 1, 2, 3, 1000]))
            pub_p.publish(Float64MultiArray(data=_hostile(rng, size)))
            k = Vector3Stamped()
            k.header.frame_id = str(rng.choice([topics.FRAME_ID, topics.FRAME_ID, "", "world", "x" * 300]))
            k.vector.x, k.vector.y, k.vector.z = _hostile(rng, 3)
            pub_k.publish(k)
            if i % 10 == 0:
                length = _hostile(rng, 1)[0]
                pub_s.publish(String(data=str(rng.choice([
                    f'{{"event": "step_start", "bench": "angle", "sample_length_m": {json.dumps(length)}}}',
                    '[1, 2]', '"step_start"', '{"event": "step_start"}', "not json", '{"event": "step_start", '
                    '"bench": "laser", "sample_length_m": 0.02}', '{"event": "step_start", "bench": "force", '
                    '"sample_length_m": null}']))))
            if i % 3 == 0:
                t = PointStamped()
                t.header.frame_id = topics.FRAME_ID
                t.point.x, t.point.y, t.point.z = _hostile(rng, 3)
                pub_t.publish(t)
        # After the flood the model node still answers a valid command and refuses a bad one. (Under
        # load it answers only the newest command of a burst, which may have been one it refuses.)
        good = Float64MultiArray(data=[0.1 * model.max_pressure] * model.n_channels)
        bad = Float64MultiArray(data=[math.nan] * model.n_channels)
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and not (model.counters.accepted > 0 and model.counters.rejected > 0):
            pub_p.publish(good)
            time.sleep(0.1)
            pub_p.publish(bad)
            time.sleep(0.1)
        time.sleep(1.0)                      # the last answers and a diagnostics report or two
        took = time.monotonic() - t0
        assert not failures, failures
        assert spinner.is_alive() and took < 60.0
        limit = alloc.max_pressure
        assert from_allocator and alloc.counters.accepted > 0 and alloc.counters.rejected > 0
        assert all(len(p) == alloc.design.n_channels and _finite(p) and all(0 <= v <= limit for v in p)
                   for p in from_allocator)
        assert model.counters.accepted > 0 and model.counters.rejected > 0
        for tip in outputs["tip"]:
            p, q = tip.pose.position, tip.pose.orientation
            assert _finite([p.x, p.y, p.z, q.x, q.y, q.z, q.w])
        for bb in outputs["backbone"]:
            assert _finite([v for pose in bb.poses for v in (pose.position.x, pose.position.y, pose.position.z)])
        assert outputs["measured"] and outputs["angle"] and outputs["force"]
        rig_limit = rig.rig.max_pressure
        for m in outputs["measured"]:
            assert _finite([m.fluid_pressure]) and -1e4 <= m.fluid_pressure <= rig_limit + 1e4   # + gauge error
        assert _finite([m.vector.x for m in outputs["angle"]] + [m.wrench.force.z for m in outputs["force"]])
        assert len(outputs["diagnostics"]) >= 2
        for msg in outputs["diagnostics"]:
            for s in msg.status:
                for kv in s.values:
                    assert kv.value.lower() not in ("nan", "inf", "-inf"), (s.name, kv.key, kv.value)
    finally:
        executor.shutdown()
        for n in (model, alloc, rig, probe):
            n.destroy_node()
        rclpy.try_shutdown(context=context)


def test_allocator_output_never_exceeds_its_limit_under_hostile_requests():
    """The allocator node's publishing path, called directly (no DDS losses to account for): every
    published command is finite and within [0, max_pressure] whatever the requests were."""
    from geometry_msgs.msg import PointStamped, Vector3Stamped
    from rclpy.parameter import Parameter

    from softcath_ros.nodes.allocation_node import AllocationNode

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    node = AllocationNode(context=context, parameter_overrides=[Parameter("max_pressure", value=30000.0)])
    sent = []

    class Recorder:
        def publish(self, msg):
            sent.append(list(msg.data))

    node.pub = Recorder()
    rng = np.random.default_rng(7)
    try:
        for i in range(2000):
            if i % 2:
                k = Vector3Stamped()
                k.header.frame_id = topics.FRAME_ID
                k.vector.x, k.vector.y, k.vector.z = _hostile(rng, 3)
                node._on_bend(k)
            else:
                t = PointStamped()
                t.header.frame_id = topics.FRAME_ID
                t.point.x, t.point.y, t.point.z = _hostile(rng, 3)
                node._on_tip(t)
            node._tick()
        assert sent and node.counters.rejected > 0 and node.counters.accepted > 0
        assert all(len(p) == node.design.n_channels and _finite(p) and all(0 <= v <= 30000.0 for v in p) for p in sent)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
