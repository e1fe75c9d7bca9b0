"""tracker_node over DDS on a folder of rendered frames (known truth): the rig contract's
/softcath/bench/bend_angle and /softcath/tip_measured, stamped when the frame was read; a frame it
cannot measure publishes nothing and is counted on /diagnostics; the lifecycle transitions
(configure checks the input, activate streams, deactivate stops); bad inputs are one line."""
import math
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy")
cv2 = pytest.importorskip("cv2", reason="the tracker needs the vision extra (opencv-python-headless)")
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped, Vector3Stamped  # noqa: E402
from lifecycle_msgs.msg import Transition  # noqa: E402

from lifecycle_listener import LifecycleListener  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.bench.tracker_render import SceneLook, render  # noqa: E402
from softcath_ros.core.design import load_design  # noqa: E402
from softcath_ros.core.kinematics import tip_pose_single  # noqa: E402
from softcath_ros.graph import NodeGraph  # noqa: E402

DESIGN = load_design("implemented_5mm")
ANGLES = [0, 60, 120, 180]
LOOK = SceneLook(base_px=(500.0, 560.0))
PARAMS = {"mm_per_px": LOOK.mm_per_px, "base_px": "500,560", "toward_px": "500,100",
          "length": DESIGN.length, "cap_mm": DESIGN.cap_thickness * 1e3, "rate_hz": 20.0, "loop": True,
          "bending_direction_deg": -90.0}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("frames")
    truths = {}
    for i, deg in enumerate(ANGLES):
        frame, truth = render(math.radians(deg), DESIGN.length, DESIGN.outer_diameter, DESIGN.cap_thickness,
                              SceneLook(**{**LOOK.__dict__, "seed": i}))
        cv2.imwrite(str(root / f"f{i}.png"), frame)
        truths[deg] = truth
    blank = render(0.0, DESIGN.length, DESIGN.outer_diameter, DESIGN.cap_thickness, LOOK)[0]
    blank[:] = 230                          # the sample is out of view in this one
    cv2.imwrite(str(root / f"f{len(ANGLES)}.png"), blank)
    return root, truths


class Listener(LifecycleListener):
    def __init__(self, domain):
        super().__init__(domain, topics.TRACKER_NODE, {topics.BENCH_BEND_ANGLE: Vector3Stamped,
                                                       topics.TIP_MEASURED: PoseStamped})
        self.angles, self.tips = self.got[topics.BENCH_BEND_ANGLE], self.got[topics.TIP_MEASURED]


def stamp_s(header):
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def test_tracker_node_publishes_the_rig_contract_from_a_folder(folder):
    root, truths = folder
    with NodeGraph() as graph:
        proc = graph.start("tracker_node", {**PARAMS, "input": str(root)})
        graph.wait_ready(proc)
        listener = Listener(graph.domain)
        try:
            got = listener.spin(60.0, until=lambda: len(listener.angles) >= 12 and listener.status is not None
                                and int(listener.status["frames_not_measured"]) >= 2)
            assert got, (len(listener.angles), listener.status)
            now = time.time()
            for a in listener.angles:
                deg = math.degrees(a.vector.x)
                nearest = min(truths, key=lambda d: abs(d - deg))
                assert abs(deg - nearest) < 1.0 and a.header.frame_id == topics.FRAME_ID
                assert a.vector.y == a.vector.z == 0.0
                assert 0 < now - stamp_s(a.header) < 60          # stamped on this clock when read
            assert {min(truths, key=lambda d: abs(d - math.degrees(a.vector.x))) for a in listener.angles} == set(ANGLES)
            by_stamp = {(a.header.stamp.sec, a.header.stamp.nanosec): a.vector.x for a in listener.angles}
            paired = 0
            for t in listener.tips:
                theta = by_stamp.get((t.header.stamp.sec, t.header.stamp.nanosec))
                if theta is None:
                    continue
                paired += 1
                truth = truths[min(truths, key=lambda d: abs(d - math.degrees(theta)))]
                # implemented_5mm bends to -y: the pose is the model's own (core/kinematics) for that bend
                arc = DESIGN.length - DESIGN.cap_thickness
                model_tip, model_quat = tip_pose_single(0.0, -theta / arc, arc, DESIGN.cap_thickness)
                assert math.dist([t.pose.position.x, t.pose.position.y, t.pose.position.z], model_tip) < 0.3e-3
                assert -t.pose.position.y * 1e3 == pytest.approx(truth["tip_mm"][0], abs=0.3)
                o = t.pose.orientation
                assert [o.x, o.y, o.z, o.w] == pytest.approx(list(model_quat), abs=1e-9)
            assert paired >= 8
            # the blank frame: nothing published for it, counted with its reason
            assert "no body at the base" in listener.status["last_reason"]
            assert listener.status["state"] == "active"
        finally:
            listener.close()
        assert graph.stop()["tracker_node"] == 0


def test_lifecycle_configure_activate_deactivate(folder, tmp_path):
    root, _ = folder
    with NodeGraph() as graph:
        proc = graph.start("tracker_node", {**PARAMS, "input": str(tmp_path / "not_yet"), "autostart": False})
        graph.wait_ready(proc)
        listener = Listener(graph.domain)
        try:
            assert listener.state() == "unconfigured"
            assert not listener.transition(Transition.TRANSITION_CONFIGURE)     # the input is missing
            assert listener.state() == "unconfigured"
            assert listener.spin(10.0, until=lambda: listener.status and listener.status["level"] == DiagnosticStatus.ERROR)
            assert "configure failed" in listener.status["message"] and "no such file" in listener.status["message"]
            (tmp_path / "not_yet").symlink_to(root)                           # now it is there
            assert listener.transition(Transition.TRANSITION_CONFIGURE)
            assert listener.state() == "inactive"
            assert not listener.spin(1.5, until=lambda: listener.angles)       # configured: not streaming
            assert listener.transition(Transition.TRANSITION_ACTIVATE)
            assert listener.spin(30.0, until=lambda: len(listener.angles) >= 3)
            assert listener.transition(Transition.TRANSITION_DEACTIVATE)
            deactivated = time.time()
            listener.spin(2.0)
            assert all(stamp_s(a.header) <= deactivated for a in listener.angles)   # nothing read after it
            assert listener.state() == "inactive"
        finally:
            listener.close()
        assert graph.stop()["tracker_node"] == 0
        text = proc.stdout.read()
    assert "Traceback" not in text and "configure: " in text     # the refused configure, said in one line


@pytest.mark.parametrize("params, words", [
    ({"input": "/nonexistent/frames"}, "no such file, folder or camera"),
    ({"base_px": "500;560"}, "base_px '500;560': expected X,Y"),
    ({"mm_per_px": 0.0}, "give the scale: mm_per_px or aruco_mm"),
    ({"lenght": 0.04}, "'lenght' (did you mean 'length'?)"),
    ({"rate_hz": 0.0}, "rate_hz"),
    ({"mm_per_px": 0.0, "aruco_mm": 10.0, "base_px": None, "toward_px": None, "clamp_marker": 0}, "no ArUco marker"),
])
def test_bad_inputs_end_the_node_in_one_line(folder, params, words):
    root, _ = folder
    args = [f"{k}:={v}" for k, v in {**PARAMS, "input": str(root), **params}.items() if v is not None]
    cmd = [sys.executable, "-m", "softcath_ros.nodes.tracker_node", "--ros-args"]
    for a in args:
        cmd += ["-p", a]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in proc.stderr, proc.stderr


def test_the_documented_node_line_runs_as_written(tmp_path):
    from softcath_ros.bench.tracker_render import write_demo_frames
    from test_tracker import tracker_doc_lines

    write_demo_frames(tmp_path / "frames")
    (line,) = tracker_doc_lines("tracker_node")
    with NodeGraph() as graph:
        proc = graph.start("tracker_node", extra_ros_args=line[2:], cwd=tmp_path)
        graph.wait_ready(proc)
        listener = Listener(graph.domain)
        try:
            assert listener.spin(30.0, until=lambda: len(listener.angles) >= 5 and len(listener.tips) >= 5)
        finally:
            listener.close()
        assert graph.stop()["tracker_node"] == 0
