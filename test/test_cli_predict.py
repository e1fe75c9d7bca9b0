"""`softcath predict` as users and scripts call it (a real subprocess, the installed console script)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model


def softcath(*args):
    return subprocess.run([sys.executable, "-m", "softcath_ros.cli", *args], capture_output=True, text=True,
                          timeout=60)


def test_predict_json_matches_model():
    r = softcath("predict", "--design", "implemented_5mm", "--model", "closed_form", "--pressure", "0", "0.2", "--unit", "bar",
                 "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["model"] == "closed_form" and out["design"] == "implemented_5mm"
    straight, bent = out["results"]
    assert straight["radius_of_curvature_m"] is None and straight["tip_position_m"] == [0.0, 0.0, 0.04]
    k = make_model("closed_form", load_design("implemented_5mm")).evaluate([2e4]).curvature
    assert bent["pressures_pa"] == [20000.0]
    assert bent["curvature_per_m"] == pytest.approx(k.tolist())
    stretch = make_model("closed_form", load_design("implemented_5mm")).evaluate([2e4]).axial_stretch
    # R_C = l / theta (theta = |k| (l - cap) stretch: the tip cap stays straight); 1/|k| under its own name
    assert bent["radius_of_curvature_m"] == pytest.approx(0.04 / (abs(k[1]) * stretch * 0.039))
    assert bent["radius_of_curvature_m"] == pytest.approx(0.04 / bent["bending_angle_rad"])
    assert bent["centreline_radius_m"] == pytest.approx(1 / abs(k[1]))
    assert bent["converged"] is True and len(bent["tip_orientation_xyzw"]) == 4
    assert bent["tip_position_m"][1] < 0   # bends towards -y, away from the channel


def test_predict_length_override_and_table():
    r = softcath("predict", "--design", "implemented_5mm", "--model", "closed_form", "--pressure", "20000Pa", "--length", "0.02")
    assert r.returncode == 0, r.stderr
    # 1/|k| does not depend on the length; R_C = l / theta does, through the straight 1 mm cap
    state = make_model("closed_form", load_design("implemented_5mm")).evaluate([2e4])
    k, stretch = float(np.ravel(state.curvature)[1]), float(np.ravel(state.axial_stretch)[0])
    assert "length 20.0 mm" in r.stdout and f"{1e3 / abs(k):.2f}" in r.stdout
    assert f"{1e3 * 0.02 / (abs(k) * stretch * 0.019):.2f}" in r.stdout


@pytest.mark.parametrize("args,fragment", [
    (["--design", "nope", "--pressure", "1Pa"], "no such file or shipped design"),
    (["--design", "implemented_5mm", "--pressure", "1,2", "--unit", "Pa"], "2 value(s) for a design with 1 channel"),
    (["--design", "implemented_5mm", "--pressure", "abc"], "not a pressure"),
    (["--design", "implemented_5mm", "--pressure", "-1", "--unit", "kPa"], "must not be negative"),
    (["--design", "implemented_5mm", "--pressure", "1Pa", "--model", "bogus"], "unknown model 'bogus'"),
    (["--design", "implemented_5mm", "--pressure", "1Pa", "--length", "-2"], "must be positive"),
])
def test_bad_input_is_one_line_error(args, fragment):
    r = softcath("predict", *args)
    assert r.returncode != 0
    assert fragment in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_every_subcommand_has_help(capsys):
    """In this process: one start-up for all (the other tests here run the CLI as a process)."""
    from softcath_ros.cli import SUBCOMMANDS, command_names, main

    names = command_names()
    assert len(names) == len(SUBCOMMANDS) and "import" in names
    for name in names:
        assert main([name, "--help"]) == 0, name
        out = capsys.readouterr().out
        assert out.startswith(f"usage: softcath {name}"), (name, out[:200])


def test_predict_reports_the_rods_own_tip_and_contact_force():
    """A rung that solves its backbone under loads (the rod at the blocking bench) reports its own
    tip (held on the scale, y = 0), not a constant-curvature arc, and the contact force."""
    from softcath_ros.core.models import make_model
    from softcath_ros.core.prediction import predict
    from softcath_ros.core.scene import load_scene

    from test_rod import COARSE, GRID   # the rod tests' coarse section law: what is tested is the rung's tip

    bench = load_scene("blocking_force_bench")
    rod = make_model("rod", bench.design, loads=bench.loads, grid=GRID, cache=False, **COARSE)
    (r,) = predict(rod, np.array([[10000.0]]))
    assert r.converged and abs(r.tip_position_m[1]) < 1e-9 and r.contact_force_n > 0.005
    assert "contact_force_n" in r.to_json()
    # what model_node publishes: the solved backbone, its last pose on the scale
    from softcath_ros.core.prediction import arc_and_cap, state_backbone

    positions, quats = state_backbone(rod.evaluate(np.array([10000.0])), *arc_and_cap(rod, bench.design.length), 20)
    # held at the tip, the body bows away from the scale (y > 0) between base and tip
    assert positions.shape == (20, 3) and abs(positions[-1, 1]) < 1e-9 and positions[:, 1].max() > 1e-5
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0)
    free = predict(make_model("closed_form", bench.design), np.array([[10000.0]]))[0]
    assert free.tip_position_m[1] < -1e-4 and "contact_force_n" not in free.to_json()


def test_models_lists_what_each_rung_declares():
    r = softcath("models", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert set(doc) == {"closed_form", "section", "fe3d", "surrogate", "rod"}
    assert doc["closed_form"]["linear_gain"] and doc["rod"]["solves_backbone"]
    assert doc["rod"]["depends_on_length"] and doc["fe3d"]["depends_on_length"] and not doc["section"]["depends_on_length"]
    assert "contact" in doc["rod"]["models"] and "contact" not in doc["section"]["models"]
    assert doc["section"]["options"]["mesh_size"]["kind"] == "float"


def test_rung_options_are_checked_against_the_declaration():
    from softcath_ros.cli.common import parse_model_options
    from softcath_ros.core.errors import SoftcathError

    assert parse_model_options("section", ["mesh_size=0.0004", "adaptive=false", "max_newton=12"]) == \
        {"mesh_size": 0.0004, "adaptive": False, "max_newton": 12}
    with pytest.raises(SoftcathError, match="has no such option; its options: none"):
        parse_model_options("closed_form", ["mesh_size=1"])
    with pytest.raises(SoftcathError, match="expected a float"):
        parse_model_options("section", ["mesh_size=fine"])
    with pytest.raises(SoftcathError, match="cannot give"):
        parse_model_options("fe3d", ["mesh=x"])
    r = softcath("predict", "--design", "implemented_5mm", "--model", "closed_form", "--pressure", "10000Pa", "--option",
                 "tol=1")
    assert r.returncode == 2 and "model 'closed_form' has no such option" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_commands_default_to_the_accurate_rung():
    """predict, sweep, allocate and calibrate run the section rung's shipped table unless told;
    the closed form stays available by name."""
    from softcath_ros.cli import build_parser

    parser = build_parser()
    for argv in (["predict", "--design", "d", "--pressure", "1Pa"], ["sweep", "--design", "d", "--to", "1Pa"],
                 ["allocate", "--design", "d", "--curvature", "1,0"], ["calibrate"]):
        assert parser.parse_args(argv).model == "surrogate", argv
    r = softcath("predict", "--design", "implemented_5mm", "--pressure", "0.2", "--unit", "bar", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    state = make_model("surrogate", load_design("implemented_5mm"), build=False).evaluate([2e4])
    assert doc["model"] == "surrogate"
    assert doc["results"][0]["curvature_per_m"] == pytest.approx(list(np.ravel(state.curvature)), rel=1e-9)


@pytest.mark.parametrize("loads", [{}, {"tip_force": [0.0, 2e-3, 0.0]}, {"gravity": [0.0, -9.81, 0.0]},
                                   {"contact": "rest_tip"}])
def test_predict_at_another_length_reports_the_rod_solved_at_that_length(loads):
    """--length on the rod: tip pose, angle, R_C = l/theta and 1/|k| are those of the rod of that
    length (solved, under the same loads; the scale at that length's rest tip), not an arc of the
    design's rod laid out at the new length."""
    from softcath_ros.core.prediction import predict
    from softcath_ros.core.rod.loads import TipPlaneContact

    if loads.get("contact") == "rest_tip":
        loads = {"contact": TipPlaneContact(normal=(0.0, 1.0, 0.0))}
    design = load_design("implemented_5mm")
    rod = make_model("rod", design, source="closed_form", **loads)
    for length in (0.017, 0.04, 0.06):
        (r,) = predict(rod, np.array([[20000.0]]), length)
        solved = make_model("rod", design.with_length(length), source="closed_form", **loads).solve(20000.0)
        theta = solved.theta[-1]
        assert r.converged and r.bending_angle_rad == pytest.approx(theta, rel=1e-9)
        e = rod.direction
        tip = [solved.positions[-1, 1] * e[0], solved.positions[-1, 1] * e[1], solved.positions[-1, 0]]
        np.testing.assert_allclose(r.tip_position_m, tip, rtol=0, atol=1e-12)
        assert r.radius_of_curvature_m == pytest.approx(length / abs(theta), rel=1e-9)
        assert r.centreline_radius_m == pytest.approx(solved.arc_length / abs(theta), rel=1e-9)
        # the stretch of the channelled part (the rigid tip cap excluded)
        assert r.axial_stretch == pytest.approx(solved.arc_length / (length - design.cap_thickness), rel=1e-9)
        if "contact" in loads:   # held on the scale at the rest tip of this length
            assert abs(r.tip_position_m[1]) < 1e-9 and r.tip_position_m[2] < length and r.contact_force_n > 0
        elif loads:              # under a load no single arc has the rod's tip
            arc = predict(make_model("closed_form", design), np.array([[20000.0]]), length)[0]
            assert np.linalg.norm(np.subtract(arc.tip_position_m, r.tip_position_m)) > 1e-5


def test_length_on_rungs_that_solve_a_body_of_the_designs_length(monkeypatch):
    """A rung answering per section (closed form) lays its arc out at any length; one that solves a body
    of the design's length (fe3d, a surrogate tabulating it) is built again for the other length with
    the options it was made with; built directly, without them, it refuses in one line."""
    from softcath_ros.core.errors import ModelError
    from softcath_ros.core.models import RUNGS, rung_info
    from softcath_ros.core.prediction import predict

    design = load_design("implemented_5mm")
    cf = make_model("closed_form", design)
    assert cf.at_length(0.02) is cf
    (a,) = predict(cf, np.array([[20000.0]]), 0.02)
    (b,) = predict(make_model("closed_form", design.with_length(0.02)), np.array([[20000.0]]))
    np.testing.assert_allclose(a.tip_position_m, b.tip_position_m, atol=1e-15)

    monkeypatch.setitem(RUNGS, "whole_body", "test_cli_predict:WholeBody")
    body = make_model("whole_body", design, tip_gain=2.0)
    assert body.at_length(0.04) is body
    short = body.at_length(0.02)
    assert short.design.length == 0.02 and short.tip_gain == 2.0 and body.design.length == 0.04
    (r,) = predict(body, np.array([[20000.0]]), 0.02)
    assert r.tip_position_m == pytest.approx(predict(short, np.array([[20000.0]]))[0].tip_position_m, abs=1e-15)
    with pytest.raises(ModelError, match="solves a body of design 'implemented_5mm''s length") as exc:
        predict(WholeBody(design), np.array([[20000.0]]), 0.02)
    assert "\n" not in str(exc.value)
    assert rung_info("fe3d").depends_on_length and rung_info("rod").depends_on_length
    assert not rung_info("section").depends_on_length and not rung_info("closed_form").depends_on_length


def _whole_body_class():
    from softcath_ros.core.models.base import RungInfo
    from softcath_ros.core.models.closed_form import ClosedFormModel

    class WholeBody(ClosedFormModel):
        """Stand-in for a rung solving a body of the design's length (fe3d without NGSolve)."""

        name = "whole_body"
        info = RungInfo(summary="stand-in", depends_on_length=True)

        def __init__(self, design, tip_gain: float = 1.0):
            super().__init__(design)
            self.tip_gain = tip_gain

    return WholeBody


WholeBody = _whole_body_class()
