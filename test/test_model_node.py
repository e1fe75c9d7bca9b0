"""model_node in its own process over DDS: poses, bad inputs, diagnostics, clean shutdown.

Each test runs the node with ``sys.executable -m softcath_ros.nodes.model_node`` on its
own private ROS_DOMAIN_ID (test/domains.py) on loopback, and talks to it
from this process through the reusable sweep client (softcath_ros.tools.pressure_sweep).
"""
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from domains import private_domain, private_env, tied
from softcath_ros import topics
from softcath_ros.core.design import load_design
from softcath_ros.core.kinematics import backbone_poses
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import predict
from softcath_ros.graph import graph_env
from softcath_ros.resources import find

REPO = Path(__file__).resolve().parents[1]

rclpy = pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")

DESIGN = load_design("implemented_5mm")
MODEL = make_model("closed_form", DESIGN)


def expected_tip(pressure_pa: float):
    r = predict(MODEL, np.array([[pressure_pa]]))[0]
    return np.array(r.tip_position_m), np.array(r.tip_orientation_xyzw)


class Running:
    """A model_node process plus a client in this process on the same private domain."""

    def __init__(self, *ros_args: str, env_extra: dict | None = None):
        """The node on the closed form unless ``ros_args`` name a model or a params file (its mechanics are checked
        against the rung that answers every pressure; the default rung: test_model_node_surrogate.py)."""
        if not any(a.startswith("model:=") or a == "--params-file" for a in ros_args):
            ros_args = ("-p", "model:=closed_form", *ros_args)
        self.domain = private_domain()
        env = {**graph_env(self.domain), **(env_extra or {})}
        self.proc = subprocess.Popen(tied([sys.executable, "-m", "softcath_ros.nodes.model_node", "--ros-args", *ros_args]),
                                     env=env, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        from diagnostic_msgs.msg import DiagnosticArray

        from softcath_ros.tools.pressure_sweep import SweepClient

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        self.client = SweepClient(node_name="test_model_node_client", timeout_s=10.0, context=self.context)
        self.diagnostics = []
        self.client.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.diagnostics.append, 10)
        self.client.wait_for_model_node(timeout_s=60.0)
        self.sync()

    def sync(self, timeout_s: float = 60.0) -> None:
        """Wait until the node's publishers have matched every subscription this client has made so
        far. The client seeing the node's publishers is not enough: each side pairs endpoints when it
        reads the other's discovery announcements, and a reliable volatile publisher never delivers
        what it published before it matched a reader (under load the node's side can lag by seconds;
        its first answer was then lost). A participant's subscriptions are announced in order and read
        in order, so a /diagnostics report arriving on a subscription made now proves the earlier ones
        are matched too."""
        from diagnostic_msgs.msg import DiagnosticArray

        got = []
        sub = self.client.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, got.append, 10)
        try:
            if not self.client.spin_until(lambda: got, timeout_s):
                raise TimeoutError(f"no /diagnostics from model_node within {timeout_s:g} s")
        finally:
            self.client.node.destroy_subscription(sub)

    def counters(self, timeout_s: float = 20.0, **wanted) -> dict:
        """The first /diagnostics report whose counters include ``wanted`` (waits for it)."""
        found = {}

        def match():
            for arr in self.diagnostics:
                for st in arr.status:
                    kv = {v.key: v.value for v in st.values}
                    if st.name.startswith(topics.MODEL_NODE) and all(kv.get(k) == str(w) for k, w in wanted.items()):
                        found.update(kv, _level=st.level)
                        return True
            return False

        self.client.spin_until(match, timeout_s)
        return found

    def stop(self, sig=signal.SIGINT, timeout_s: float = 30.0):
        """Signal the node; (exit code, stderr)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            _, err = self.proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
            return "hung", err
        return self.proc.returncode, err

    def close(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()
        self.client.close()
        rclpy.try_shutdown(context=self.context)


# start_node: the fixture in conftest.py (shared with test_live_view.py).


@pytest.mark.parametrize("preparation", ["serialized", "reuse"])
def test_poses_arrive_match_core_and_backbone_ends_at_tip(start_node, preparation):
    node = start_node("-p", "backbone_points:=7", "-p", "design:=implemented_5mm",
                      "-p", f"message_preparation:={preparation}")
    before = time.time_ns()
    pt = node.client.send([30000.0])
    after = time.time_ns()
    assert pt is not None, "no pose for a valid command"
    pos, quat = expected_tip(30000.0)
    np.testing.assert_allclose(pt.tip_position_m, pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pt.tip_orientation_xyzw, quat, rtol=0, atol=1e-12)
    # Stamped with the time the node received the command: between our send and our receipt.
    assert before <= pt.stamp_ns <= after
    assert node.client._tips[-1].header.frame_id == topics.FRAME_ID
    bb_msg = node.client._backbones[-1]
    assert bb_msg.header.frame_id == topics.FRAME_ID
    assert bb_msg.header.stamp == node.client._tips[-1].header.stamp
    backbone = np.array(pt.backbone_m)
    assert backbone.shape == (7, 3)
    k, stretch = MODEL.curvature_single(np.array([30000.0]))
    arc = DESIGN.length - DESIGN.cap_thickness     # the channelled part bends; the tip cap stays straight
    np.testing.assert_allclose(backbone, backbone_poses(k, arc * stretch, 7, DESIGN.cap_thickness)[0], atol=1e-12)
    np.testing.assert_allclose(backbone[0], [0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(backbone[-1], pt.tip_position_m, rtol=0, atol=0)
    # Bending towards -y for the channel at +y, and a unit quaternion.
    assert pos[1] < 0
    assert abs(np.linalg.norm(pt.tip_orientation_xyzw) - 1) < 1e-12
    code, err = node.stop(signal.SIGTERM)
    assert code == 0 and "Traceback" not in err, err


def test_bad_inputs_rejected_counted_reported_and_node_survives(start_node):
    # The safety limit is the design's: an override on the command line must not raise it.
    node = start_node("-p", "max_pressure:=1000000.0", "-p", "out_of_range:=reject")
    bad = [[float("nan")], [float("inf")], [10000.0, 10000.0], [-1.0], [DESIGN.max_pressure * 1.01], [1.0e6]]
    for cmd in bad:
        assert node.client.send(cmd, timeout_s=0.3) is None, f"a pose was published for bad command {cmd}"
    assert node.client.n_received == 0
    diag = node.counters(rejected=len(bad))
    assert diag, f"no /diagnostics report with rejected={len(bad)}; got {node.diagnostics[-1:] }"
    assert diag["accepted"] == "0" and diag["clamped"] == "0"
    assert "max_pressure" in diag["last_reason"]
    assert diag["max_pressure_pa"] == f"{DESIGN.max_pressure:g}"
    assert node.proc.poll() is None, "node died on bad input"
    # Still answers a good command correctly afterwards.
    pt = node.client.send([20000.0])
    assert pt is not None
    np.testing.assert_allclose(pt.tip_position_m, expected_tip(20000.0)[0], atol=1e-12)
    assert node.counters(accepted=1, rejected=len(bad))
    code, err = node.stop(signal.SIGINT)
    assert code == 0 and "Traceback" not in err, err
    assert "rejected" in err  # the (throttled) warning was logged


def test_clamp_policy_clamps_out_of_range_but_rejects_non_finite(start_node):
    node = start_node("-p", "out_of_range:=clamp")
    high = node.client.send([DESIGN.max_pressure * 3])
    assert high is not None
    np.testing.assert_allclose(high.tip_position_m, expected_tip(DESIGN.max_pressure)[0], atol=1e-12)
    low = node.client.send([-5000.0])
    assert low is not None
    np.testing.assert_allclose(low.tip_position_m, [0, 0, DESIGN.length], atol=1e-15)
    assert node.client.send([float("nan")], timeout_s=0.3) is None
    diag = node.counters(clamped=2, rejected=1)
    assert diag and diag["accepted"] == "2" and diag["out_of_range"] == "clamp"
    assert all(np.isfinite(v) for v in high.tip_position_m + low.tip_position_m)


def test_params_file_is_loaded(start_node):
    node = start_node("--params-file", str(find("params", "model_node")), "-p", "backbone_points:=5")
    pt = node.client.send([10000.0])
    assert pt is not None and len(pt.backbone_m) == 5
    code, err = node.stop(signal.SIGINT)
    assert code == 0 and "Traceback" not in err, err
    assert "design implemented_5mm" in err  # start-up line from the params file's design


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_ends_node_cleanly(start_node, sig):
    node = start_node()
    assert node.client.send([5000.0]) is not None
    code, err = node.stop(sig)
    assert code == 0, f"exit code {code} on {sig.name}: {err}"
    assert "Traceback" not in err


def test_a_rung_building_its_law_at_start_says_so_shows_progress_and_stops_on_sigint(tmp_path):
    """The rod on an empty cache tabulates its section law for minutes before the node is ready: the
    start says what it builds and how long, shows a progress bar, and SIGINT stops it at once (exit
    0, one line) instead of after the build (before: silent, and a SIGINT waited 6 min)."""
    import os
    import select

    env = private_env(SOFTCATH_CACHE=str(tmp_path / "cache"))
    proc = subprocess.Popen([sys.executable, "-m", "softcath_ros.nodes.model_node", "--ros-args", "-p", "model:=rod"],
                            env=env, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err = b""
    try:
        end = time.monotonic() + 120.0
        while b"section M(kappa, p)" not in err and time.monotonic() < end and proc.poll() is None:
            if select.select([proc.stderr], [], [], 0.5)[0]:
                err += os.read(proc.stderr.fileno(), 65536)
        text = err.decode(errors="replace")
        assert "model rod: loading; if neither shipped nor cached it builds its moment-curvature law" in text, text
        assert "minutes" in text and "section M(kappa, p)" in text, text
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=30)    # the build takes minutes: stopping within 30 s is the SIGINT
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    text = (err + rest).decode(errors="replace")
    assert proc.returncode == 0 and "stopped during start-up (SIGINT)" in text and "Traceback" not in text, text
    assert "ready" not in text


def test_bad_configuration_exits_with_one_line_error():
    env = private_env()
    proc = subprocess.run([sys.executable, "-m", "softcath_ros.nodes.model_node", "--ros-args",
                           "-p", "model:=no_such_rung"], env=env, capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2
    assert "no_such_rung" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("frame_id", ["softcath_base", "", "ab", "abc"])
@pytest.mark.parametrize("n", [1, 2, 7, 20])
def test_preallocated_cdr_buffers_deserialise_to_the_same_messages(frame_id, n):
    from geometry_msgs.msg import Pose, PoseArray, PoseStamped
    from rclpy.serialization import deserialize_message, serialize_message

    from softcath_ros.nodes.cdr import PoseArrayBuffer, PoseStampedBuffer

    values = np.random.default_rng(n).normal(size=(n, 7))
    stamp_ns = 1_795_359_200_123_456_789

    def fill(pose, row):
        p, q = pose.position, pose.orientation
        p.x, p.y, p.z, q.x, q.y, q.z, q.w = row

    buf = PoseArrayBuffer(frame_id, n)
    buf.poses[:] = values
    buf.set_stamp(stamp_ns)
    msg = PoseArray(poses=[Pose() for _ in range(n)])
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    for pose, row in zip(msg.poses, values.tolist()):
        fill(pose, row)
    assert deserialize_message(buf.to_bytes(), PoseArray) == msg
    assert len(buf.to_bytes()) == len(serialize_message(msg))  # padding bytes differ, so compare content + size

    tip = PoseStampedBuffer(frame_id)
    tip.poses[0] = values[-1]
    tip.set_stamp(stamp_ns)
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    fill(msg.pose, values[-1].tolist())
    assert deserialize_message(tip.to_bytes(), PoseStamped) == msg
    assert len(tip.to_bytes()) == len(serialize_message(msg))


def test_non_converged_or_non_finite_model_result_publishes_nothing_and_is_counted():
    """In-process (no DDS traffic needed): a rung that fails must not reach the topics."""
    from std_msgs.msg import Float64MultiArray

    from softcath_ros.core.models.base import BendModel, BendState
    from softcath_ros.nodes.model_node import ModelNode

    class FailingRung(BendModel):
        name = "failing"

        def __init__(self, design, result):
            super().__init__(design)
            self.result = result

        def _evaluate_batch(self, pressures):
            n = len(pressures)
            if self.result == "diverged":
                return BendState(np.zeros((n, 2)), np.ones(n), np.zeros(n, bool), message="Newton diverged at step 3")
            return BendState(np.full((n, 2), np.nan), np.ones(n), np.ones(n, bool))

    class Recorder:
        def __init__(self):
            self.sent = []

        def publish(self, msg):
            self.sent.append(msg)

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    node = ModelNode(context=context)
    try:
        for result, reason in (("diverged", "Newton diverged"), ("nan", "non-finite")):
            node.model, node._fast = FailingRung(DESIGN, result), None
            node._tip_pub, node._backbone_pub = Recorder(), Recorder()
            before = node.counters.model_failed
            node._on_command(Float64MultiArray(data=[10000.0]))
            assert node._tip_pub.sent == [] and node._backbone_pub.sent == []
            assert node.counters.model_failed == before + 1
            assert reason in node.counters.last_reason
        assert node.counters.accepted == 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_answer_load_reports_a_rung_too_slow_for_its_commands():
    """In-process: a rung slower than the command stream turns /diagnostics' answer-load status to WARN."""
    import time

    from diagnostic_msgs.msg import DiagnosticStatus
    from std_msgs.msg import Float64MultiArray

    from softcath_ros.core.models.base import BendModel, BendState
    from softcath_ros.nodes.model_node import ModelNode

    class SlowRung(BendModel):
        name = "slow"

        def _evaluate_batch(self, pressures):
            time.sleep(0.02)            # 20 ms per command: sustains about 50 commands/s
            n = len(pressures)
            return BendState(np.tile([0.0, -10.0], (n, 1)), np.ones(n), np.ones(n, bool))

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    node = ModelNode(context=context)
    try:
        cmd = Float64MultiArray(data=[10000.0])
        node._diagnostics._load_status()                 # start a fresh window
        for _ in range(500):                             # closed form, 1 ms apart: keeping up
            node._on_command(cmd)
            time.sleep(0.001)
        ok = node._diagnostics._load_status()
        assert ok.level == DiagnosticStatus.OK and "keeping up" in ok.message
        node.model, node._fast = SlowRung(DESIGN), None
        for i in range(25):                              # back to back, as a queue of waiting commands
            node._on_command(Float64MultiArray(data=[9000.0 + i]))   # each new: an unchanged one is not solved again
        slow = node._diagnostics._load_status()
        values = {kv.key: kv.value for kv in slow.values}
        assert slow.level == DiagnosticStatus.WARN and "falling behind" in slow.message, slow.message
        # at least the rung's 20 ms; a loaded machine only adds to it
        assert values["behind"] == "true" and float(values["mean_answer_ms"]) >= 20.0
        assert node.counters.accepted == 525
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_readme_nodes_over_topics_run_as_written():
    """README's "Nodes over topics": model_node started as written, then the pressure_sweep line as
    written answers every command of its sweep (the tool waits until the node answers its first
    command, so none is lost to DDS matching) and prints R_C = l / theta for each."""
    import shlex

    readme = (REPO / "README.md").read_text().splitlines()
    node_line = next(line for line in readme if line.startswith(".venv/bin/model_node --ros-args -p design:="))
    sweep_line = next(line for line in readme if line.startswith(".venv/bin/python -m softcath_ros.tools.pressure_sweep"))
    bindir = Path(sys.executable).parent

    def argv(line):
        words = shlex.split(line, comments=True)
        return [str(bindir / words[0].removeprefix(".venv/bin/")), *words[1:]]

    domain = private_domain()
    node = subprocess.Popen(argv(node_line), env=graph_env(domain), cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        sweep = subprocess.run(argv(sweep_line), env=graph_env(domain), cwd=REPO, capture_output=True, text=True,
                               timeout=110)
        assert sweep.returncode == 0, sweep.stderr[-2000:]
        rows = [line for line in sweep.stdout.splitlines()[1:] if line.strip()]
        assert len(rows) >= 2 and not [r for r in rows if "no pose" in r], sweep.stdout
        assert float(rows[-1].split()[0]) == pytest.approx(0.25)       # the last command, bar
        assert 0 < float(rows[-1].split()[1]) < 100.0                   # R_C [mm] of a bent body
    finally:
        node.send_signal(signal.SIGINT)
        try:
            node.wait(timeout=30)
        except subprocess.TimeoutExpired:
            node.kill()
