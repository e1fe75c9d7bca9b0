"""model_node under a command flood faster than its rung: /diagnostics keeps coming while the rung
solves, superseded commands are counted, and the answer is for the newest command, not a backlog;
a command is superseded only when stale (waited over the stated age behind a newer one)."""
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")
pytestmark = pytest.mark.ros

from domains import private_domain  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.core.models.base import BendModel, BendState  # noqa: E402
from softcath_ros.core.prediction import state_backbone  # noqa: E402

SOLVE_S = 0.05      # the slow rung: 50 ms per command, about 20 answers/s


class SlowRung(BendModel):
    name = "slow"

    def _evaluate_batch(self, pressures):
        time.sleep(SOLVE_S)
        p = np.asarray(pressures, float)[:, 0]
        return BendState(np.stack([np.zeros_like(p), -p * 1e-3], axis=1), np.ones(len(p)), np.ones(len(p), bool))


def test_flood_on_a_slow_rung_answers_the_newest_command_and_diagnostics_keep_coming(monkeypatch):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import Float64MultiArray

    from softcath_ros.nodes import model_node

    monkeypatch.setattr(model_node, "build_model", lambda name, design, calibration=None, **kw: SlowRung(design))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    node = model_node.ModelNode(context=context, parameter_overrides=[
        Parameter("model", value="section"), Parameter("diagnostics_period", value=0.1),
        Parameter("executor", value="single")])
    probe = rclpy.create_node("flood_probe", context=context)
    assert node._solver is not None, "a 50 ms rung must answer on the solve thread"
    diagnostics, tips = [], []
    probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS,
                              lambda m: diagnostics.append((time.monotonic(), m)), 100)
    probe.create_subscription(PoseStamped, topics.TIP_POSE, lambda m: tips.append(m), 1000)
    pub = probe.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, 1000)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(probe)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 10.0
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        n, t0 = 400, time.monotonic()
        for i in range(n):                       # 400 commands in about 1 s: 20 times what the rung answers
            pub.publish(Float64MultiArray(data=[100.0 * (i + 1)]))
            time.sleep(0.0025)
        flood_end = time.monotonic()
        last_pressure = 100.0 * n
        # the newest command is answered soon after the flood, not after a backlog of 400 x 50 ms
        while time.monotonic() < flood_end + 3.0:
            if node.counters.accepted and not node._pending and tips:
                break
            time.sleep(0.05)
        time.sleep(3 * SOLVE_S)
        took = time.monotonic() - t0
        c = node.counters
        assert c.accepted + c.superseded + c.rejected == n, vars(c)
        assert c.superseded >= n // 2 and c.accepted < n // 2, vars(c)
        positions, _ = state_backbone(SlowRung(node.design).evaluate([last_pressure]), node.arc_length, node.cap,
                                      node.n_points)
        assert tips and tips[-1].pose.position.y == pytest.approx(positions[-1][1], rel=1e-9), \
            "the last answer must be for the newest command"
        assert took < 5.0
        # /diagnostics never went silent during the flood (period 0.1 s; allow a loaded machine 5x)
        during = [t for t, _ in diagnostics if t0 <= t <= flood_end]
        gaps = np.diff([t0] + during + [flood_end])
        assert len(during) >= 3 and gaps.max() < 0.5, gaps
        values = {kv.key: kv.value for _, m in diagnostics[-3:] for s in m.status for kv in s.values}
        assert int(values["superseded"]) > 0
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown(context=context)


def _inline_node(model="closed_form"):
    from rclpy.parameter import Parameter

    from softcath_ros.nodes.model_node import ModelNode

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    node = ModelNode(context=context, parameter_overrides=[Parameter("model", value=model),
                                                           Parameter("display_rate", value=0.0)])
    return context, node


def test_waiting_commands_are_all_answered_unless_stale():
    """Commands found waiting after an answer (a scheduling pause queued them): each is answered
    while it has waited no longer than the stated age; older ones with a newer one behind them are
    superseded, and the newest always is answered. A fake clock, so no wall-clock window."""
    from std_msgs.msg import Float64MultiArray

    context, node = _inline_node()
    assert node._solver is None
    answered = []
    node._publish_serialized = lambda stamp_ns, positions, quats: answered.append(positions[-1].copy())
    try:
        now = 100.0
        node._clock_s = lambda: now
        age = node.supersede_age
        cmds = [Float64MultiArray(data=[1000.0 * (i + 1)]) for i in range(4)]
        node._answer_waiting([(m, now - 0.5 * age) for m in cmds])           # all fresh: all answered
        assert len(answered) == 4 and node.counters.superseded == 0 and node.counters.accepted == 4
        node._answer_waiting([(cmds[0], now - 3 * age), (cmds[1], now - 2 * age), (cmds[2], now - 0.5 * age),
                              (cmds[3], now - 3 * age)])                      # the newest is answered however old
        assert node.counters.superseded == 2 and node.counters.accepted == 6
        np.testing.assert_array_equal(answered[4:], answered[2:4])           # commands 2 and 3 were answered
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_an_unchanged_command_costs_no_model_call():
    """The last answer is kept: the same pressures again are answered (newly stamped) without a
    model call."""
    from std_msgs.msg import Float64MultiArray

    context, node = _inline_node()
    calls, stamps = [], []
    fast = node._fast
    node._fast = lambda p: (calls.append(1), fast(p))[1]
    node._publish_serialized = lambda stamp_ns, positions, quats: stamps.append(stamp_ns)
    try:
        for _ in range(5):
            node._on_command(Float64MultiArray(data=[2000.0]))
        node._on_command(Float64MultiArray(data=[3000.0]))
        assert len(calls) == 2 and len(stamps) == 6 and node.counters.accepted == 6
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_flood_on_the_closed_form_answers_the_newest_and_counts_the_rest():
    """The inline path (closed form, events executor): what reached the node is answered or
    superseded (when stale), and the last answer is for the last command."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.experimental import EventsExecutor
    from std_msgs.msg import Float64MultiArray

    from rclpy.parameter import Parameter

    from softcath_ros.nodes.model_node import ModelNode

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    node = ModelNode(context=context, parameter_overrides=[Parameter("model", value="closed_form")])
    probe = rclpy.create_node("flood_probe", context=context)
    assert node._solver is None, "the closed form answers in the callback"
    tips = []
    probe.create_subscription(PoseStamped, topics.TIP_POSE, tips.append, 1000)
    pub = probe.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, 1000)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    executor.add_node(probe)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 10.0
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        n = 5000
        for i in range(n):
            pub.publish(Float64MultiArray(data=[5.0 * (i + 1)]))   # up to 25 kPa, within the limit
        from softcath_ros.core.kinematics import backbone_poses

        curvature, stretch = node._fast([5.0 * n])
        positions, _ = backbone_poses(curvature, node.arc_length * stretch, node.n_points, node.cap)

        def answered_last():
            return bool(tips) and tips[-1].pose.position.y == pytest.approx(positions[-1][1], rel=1e-9)

        deadline = time.monotonic() + 60.0        # an event (the last command's pose), not a time window
        while time.monotonic() < deadline and not answered_last():
            time.sleep(0.05)
        c = node.counters
        assert c.rejected == 0 and c.accepted + c.superseded <= n, vars(c)
        assert answered_last(), "the last answer must be for the last command"
    finally:
        stop.set()
        spinner.join(timeout=5.0)
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
        rclpy.try_shutdown(context=context)
