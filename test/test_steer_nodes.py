"""Steering over DDS, every node its own process on a private domain (few, short runs):
docs/steering.md's step line runs (softcath steer-sim on its defaults: three_sector_5mm, the
surrogate, the design's steering range) and its closed loop beats open loop (how fast a step
settles, against the 1 s target, is benchmarks/steering.py's measure, not here, where the machine
may be busy);
killing the tracker's publisher (sim_bench_node) makes steer_node fall back to open loop and
say so on /diagnostics; the watchdog vents when the targets stop."""
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PointStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from doc_commands import doc_argv  # noqa: E402
from domains import private_domain  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.core.kinematics import tip_pose_single  # noqa: E402
from softcath_ros.graph import NodeGraph, graph_env  # noqa: E402

SOFTCATH = Path(sys.executable).parent / "softcath"


def test_steer_sim_step_line_runs_over_dds_and_beats_open_loop(tmp_path):
    """docs/steering.md's step line, as written (in a fresh folder: runs/ lands there)."""
    argv = doc_argv(("docs/steering.md",), "softcath steer-sim --trajectory step")
    domain = private_domain()
    env = {**graph_env(domain), "ROS_DOMAIN_ID": str(domain)}
    res = subprocess.run([str(SOFTCATH), *argv], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=110)
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout)
    # the step response's settling time is reported (0.89 s at load 4); how fast it settles is
    # benchmarks/steering.py's target: on a starved machine the wall-clock loop may not settle
    # within a 2 s hold, so it is not asserted here
    assert out["settling_time_s"] > 0, out   # reported for the step response (inf: a step never settled)
    # closed loop beats open loop's steady-state error (6.2 mm): 0.12 mm at load 4; a busy machine
    # costs accuracy (its accuracy target is benchmarks/steering.py's)
    assert out["comparison"]["mode"] == "open_loop"
    logs = "".join(f"\n--- {log.name}\n" + "\n".join(log.read_text().splitlines()[-20:])
                   for log in sorted((tmp_path / "runs").glob("*.log")))   # the nodes' own words, on a failure
    assert out["steady_state_error_mm"] < out["comparison"]["steady_state_error_m"] * 1e3, (out, logs)
    assert Path(out["recording"]).exists() and Path(out["plot"]).exists()
    assert Path(out["recording"]).is_relative_to(tmp_path / "runs")


class Operator:
    def __init__(self, domain):
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("steer_test_operator", context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.pressures = []
        self.loop = None
        self.node.create_subscription(Float64MultiArray, topics.PRESSURE_CMD,
                                      lambda m: self.pressures.append(list(m.data)), 50)
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diag, 50)
        self.pub = self.node.create_publisher(PointStamped, topics.TIP_TARGET, 10)

    def _on_diag(self, msg):
        for s in msg.status:
            if s.name == f"{topics.STEER_NODE}: loop":
                self.loop = {"level": s.level, "message": s.message, **{kv.key: kv.value for kv in s.values}}

    def send(self, tip):
        msg = PointStamped()
        msg.header.frame_id = topics.FRAME_ID
        msg.point.x, msg.point.y, msg.point.z = (float(v) for v in tip)
        self.pub.publish(msg)

    def spin(self, seconds, until=None, tip=None):
        end = time.monotonic() + seconds
        next_send = 0.0
        while time.monotonic() < end:
            if tip is not None and time.monotonic() >= next_send:
                self.send(tip)
                next_send = time.monotonic() + 0.02
            self.executor.spin_once(timeout_sec=0.005)
            if until is not None and until():
                return True
        return until is None

    def close(self):
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def test_tracker_loss_falls_back_and_watchdog_vents():
    domain = private_domain()
    k = 0.1 / 0.04
    tip = tip_pose_single(0.0, -k, 0.04)[0]
    with NodeGraph(domain=domain) as graph:
        rig = graph.start("sim_bench_node", {"design": "three_channel_5mm", "material_scale": 1.2,
                                             "actuator_time_constant": 0.016})
        steer = graph.start("steer_node", {"design": "three_channel_5mm", "command_timeout": 0.5,
                                           "diagnostics_period": 0.5})
        graph.wait_ready(rig, steer, timeout_s=60.0)
        op = Operator(domain)
        try:
            assert op.spin(15.0, lambda: op.loop is not None and op.loop["state"] == "closed_loop", tip=tip), op.loop
            # the tracker's publisher dies; targets keep coming meanwhile (a blocking wait for its
            # exit here would let the 0.5 s command timeout vent the controller)
            rig.send_signal(signal.SIGINT)
            t_kill = time.monotonic()
            assert op.spin(5.0, lambda: op.loop["state"] == "open_loop", tip=tip), op.loop
            assert time.monotonic() - t_kill < 1.5
            assert op.loop["level"] == DiagnosticStatus.WARN and "no valid measurement" in op.loop["message"]
            assert int(op.loop["measurements_fallbacks"]) == 1
            assert max(op.pressures[-1]) > 0                          # still steering, open loop
            # the targets stop: vent, ramped to zero
            assert op.spin(5.0, lambda: op.loop["state"] == "vented"), op.loop
            assert op.spin(3.0, lambda: op.pressures and max(op.pressures[-1]) == 0.0)
        finally:
            op.close()


def test_steer_node_defaults_to_the_surrogate_on_its_shipped_table(monkeypatch):
    """In-process: with its defaults steer_node steers three_sector_5mm, its feed-forward the surrogate
    read from the table shipped for the design (none is built at start-up), limited to the design's
    steering range (below 0.3 bar: the allocator's limit, not a new design)."""
    from softcath_ros.core.steering_range import STEERING_MAX_PRESSURE, steering_range
    from softcath_ros.nodes.steer_node import SteerNode

    def no_build(model):
        raise AssertionError("steer_node built a surrogate table at start-up")

    monkeypatch.setattr("softcath_ros.core.models.surrogate_tabulate.build_table", no_build)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    try:
        node = SteerNode(context=context)
        model = node.ctrl.allocator.model
        assert model.name == "surrogate" and model.origin == "shipped" and node.design.name == "three_sector_5mm"
        assert node.ctrl.max_pressure == steering_range(model) < STEERING_MAX_PRESSURE
        assert node.get_parameter("max_pressure").value == node.ctrl.max_pressure
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_steer_driver_builds_the_truths_rung_once_when_given_its_pressure_limit(monkeypatch, tmp_path):
    """In-process: `softcath steer-sim` passes max_pressure, so the driver builds only the truth it plays
    (one surrogate, one table read), not a second rung for a default it does not use; without the
    parameter the default is still the design's steering range on the truth's rung as shipped."""
    from rclpy.parameter import Parameter

    from softcath_ros.core.design import load_design
    from softcath_ros.core.models.surrogate import SurrogateModel
    from softcath_ros.core.steering_range import steering_model, steering_range
    from softcath_ros.nodes.steer_driver import SteerDriver

    built = []
    make = SurrogateModel.__init__

    def counted(self, *args, **kwargs):
        built.append(self)
        make(self, *args, **kwargs)

    monkeypatch.setattr(SurrogateModel, "__init__", counted)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    try:
        for given, builds in ((25000.0, 1), (None, 2)):
            built.clear()
            params = [Parameter("output", value=str(tmp_path / f"run_{builds}"))]
            params += [] if given is None else [Parameter("max_pressure", value=given)]
            node = SteerDriver(context=context, parameter_overrides=params)
            try:
                assert len(built) == builds, [m.origin for m in built]
                want = given if given is not None else steering_range(steering_model("surrogate", load_design(
                    "three_sector_5mm")))
                assert node.get_parameter("max_pressure").value == want
            finally:
                node.writer.close()
                node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
