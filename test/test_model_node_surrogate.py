"""model_node with the surrogate rung and with `model: auto` from a scene, over DDS: the pose for
one command is the core's prediction with the same rung. Reuses test_model_node's process harness
(its ROS_DOMAIN_ID range)."""
import signal

import numpy as np
import pytest

from softcath_ros.core.models import make_model
from softcath_ros.core.model_selection import select_model
from softcath_ros.core.prediction import predict
from softcath_ros.core.scene import load_scene

pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")
from test_model_node import DESIGN, Running  # noqa: E402


@pytest.mark.parametrize("params,rung", [(["-p", "model:=surrogate"], "surrogate"),
                                         (["-p", "model:=auto", "-p", "scene:=free_bending_live"], None)])
def test_model_node_with_surrogate_and_auto_matches_core(params, rung):
    rung = rung or select_model(load_scene("free_bending_live")).rung
    model = make_model(rung, DESIGN)     # builds the surrogate's table into the cache first if needed
    node = Running("-p", "design:=implemented_5mm", *params)
    try:
        pt = node.client.send([15000.0])
        assert pt is not None, "no pose for a valid command"
        r = predict(model, np.array([[15000.0]]))[0]
        np.testing.assert_allclose(pt.tip_position_m, r.tip_position_m, rtol=0, atol=1e-12)
        assert node.counters(model=model.name)
        code, err = node.stop(signal.SIGTERM)
        assert code == 0 and "Traceback" not in err, err
    finally:
        node.close()


def test_default_model_node_runs_the_shipped_section_table_and_refuses_common_pressure():
    """The shipped params file's model: the surrogate of the section rung, from the table shipped with
    the package (nothing built at start-up; the test cache is empty); a 3-channel command with all
    channels pressurised beyond the measured common-mode limit gets no pose and its reason on
    /diagnostics."""
    from softcath_ros.core.design import load_design
    from softcath_ros.resources import find

    node = Running("--params-file", str(find("params", "model_node")), "-p", "design:=three_channel_5mm")
    try:
        design = load_design("three_channel_5mm")
        model = make_model("surrogate", design, build=False)
        pt = node.client.send([12000.0, 5000.0, 0.0])
        assert pt is not None, "no pose for a valid command"
        r = predict(model, np.array([[12000.0, 5000.0, 0.0]]))[0]
        np.testing.assert_allclose(pt.tip_position_m, r.tip_position_m, rtol=0, atol=1e-12)
        assert node.client.send([12000.0, 15000.0, 6000.0], timeout_s=0.5) is None
        diag = node.counters(model="surrogate", model_failed=1)
        assert "common to all three channels" in diag["last_reason"]
        code, err = node.stop(signal.SIGTERM)
        assert code == 0 and "Traceback" not in err, err
        assert "shipped table" in err and "building" not in err
    finally:
        node.close()


def test_model_node_publishes_no_pose_for_a_body_bent_through_its_shaft():
    """The 40 mm design at 0.27 bar would turn about 350 deg, the tip through the shaft below the
    base (core/body_contact.py): no pose, the reason on /diagnostics; a pose again at 0.15 bar."""
    from softcath_ros.resources import find

    node = Running("--params-file", str(find("params", "model_node")), "-p", "design:=implemented_5mm")
    try:
        assert node.client.send([27000.0], timeout_s=0.5) is None
        diag = node.counters(model="surrogate", model_failed=1)
        assert "shaft" in diag["last_reason"] and "27000" in diag["last_reason"]
        assert node.client.send([15000.0]) is not None, "no pose for a valid command after a refused one"
        code, err = node.stop(signal.SIGTERM)
        assert code == 0 and "Traceback" not in err, err
    finally:
        node.close()
