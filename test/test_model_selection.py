"""Scenes and `model: auto`: validation that names field and value, and the selection rule
(cheapest rung that models the scene, is valid over its pressures, meets accuracy and rate)."""
import re
import subprocess
import sys

import pytest

from softcath_ros.core.errors import ModelError
from softcath_ros.core.model_selection import load_envelope, select_model
from softcath_ros.core.models import make_model
from softcath_ros.core.scene import SceneError, load_scene, scene_from_dict
from softcath_ros.resources import find, shipped_names

ENV = {"reference": "fe3d mesh 1.4, 1.2 mm layers", "rungs": {
    "closed_form": {"capabilities": ["free_bending", "device_stiffness"], "designs": {"implemented_5mm": {
        "error_rc_rel_max": 0.60, "cost_s_per_eval": 5e-6, "valid_pressure_pa": [0, 50000]}}},
    "surrogate": {"capabilities": ["free_bending", "device_stiffness"], "designs": {"implemented_5mm": {
        "error_rc_rel_max": 0.04, "cost_s_per_eval": 2e-5, "valid_pressure_pa": [0, 27500]}}},
    "section": {"capabilities": ["free_bending", "device_stiffness"], "designs": {"implemented_5mm": {
        "error_rc_rel_max": 0.03, "cost_s_per_eval": 0.05, "valid_pressure_pa": [0, 27500]}}},
    "fe3d": {"capabilities": ["free_bending", "device_stiffness"], "designs": {"implemented_5mm": {
        "error_rc_rel_max": 0.0, "cost_s_per_eval": 30.0, "valid_pressure_pa": [0, 25000]}}},
}}


def scene(**over):
    raw = {"name": "t", "design": "implemented_5mm", "pressure_range": [0.0, 20000.0],
           "required_accuracy": 0.05, "required_rate": 1000.0}
    raw.update(over)
    return scene_from_dict(raw)


def test_shipped_scenes_load():
    names = shipped_names("scene")
    assert {"free_bending_live", "device_in_lumen", "blocking_force_bench", "design_study_accurate"} <= set(names)
    assert load_scene("device_in_lumen").features == ("free_bending", "device_stiffness")
    assert "contact" in load_scene("blocking_force_bench").features


@pytest.mark.parametrize("over,field", [
    ({"pressure_range": [0, 9e5]}, "pressure_range"),
    ({"required_rate": -1}, "required_rate"),
    ({"gravity": "yes"}, "gravity"),
    ({"device": {"diameter": 0.01, "bending_stiffness": 1e-6}}, "device.diameter"),
    ({"loads": {"tip_force": [0, 1]}}, "loads.tip_force"),
    ({"loads": {"contact": {"plane_z": 0.017}}}, "loads.contact"),
    ({"loads": {"contact": {"kind": "wall", "normal": [0, 1, 0]}}}, "loads.contact.kind"),
    ({"loads": {"contact": {"normal": [0, 0, 0]}}}, "loads.contact.normal"),
    ({"loads": {"contact": {"normal": [0, 1, 0], "point": "tip"}}}, "loads.contact.point"),
    ({"gravity": True}, "gravity"),
    ({"colour": "red"}, "colour"),
])
def test_scene_errors_name_field_and_value(over, field):
    with pytest.raises(SceneError) as e:
        scene(**over)
    assert e.value.field == field and f"'{field}'" in str(e.value)


def test_picks_cheapest_rung_meeting_accuracy_and_rate():
    sel = select_model(scene(), ENV)
    assert sel.rung == "surrogate"          # closed form is cheaper but 60% off
    assert "surrogate" in sel.reason and "closed_form" in sel.rejected
    assert "exceeds the required" in sel.rejected["closed_form"]
    # looser accuracy: the closed form qualifies and is cheapest
    assert select_model(scene(required_accuracy=0.8), ENV).rung == "closed_form"
    # tighter accuracy at a slow rate: only the reference, with its pressure range
    assert select_model(scene(required_accuracy=0.01, required_rate=0.01), ENV).rung == "fe3d"


def test_refuses_when_nothing_qualifies():
    with pytest.raises(ModelError, match="no rung qualifies.*does not model contact"):
        select_model(scene(loads={"contact": {"kind": "tip_plane", "normal": [0, 1, 0], "point": "rest_tip"}}), ENV)
    with pytest.raises(ModelError, match="cannot keep up"):
        select_model(scene(required_accuracy=0.035), ENV)       # section is accurate enough but too slow
    with pytest.raises(ModelError, match="valid over 0..27500 Pa only"):
        select_model(scene(pressure_range=[0, 40000]), ENV)


def test_committed_envelope_drives_the_shipped_scenes():
    env = load_envelope()
    assert env["rungs"] and all("capabilities" in r for r in env["rungs"].values())
    live = select_model(load_scene("free_bending_live"), env)
    cost = env["rungs"][live.rung]["designs"]["implemented_5mm"]["cost_s_per_eval"]
    assert cost <= 1e-3
    if "rod" not in env["rungs"]:   # until the ladder chart measures the rod rung
        with pytest.raises(ModelError, match="contact"):
            select_model(load_scene("blocking_force_bench"), env)
    model = make_model("auto", load_scene("free_bending_live").design, scene=load_scene("free_bending_live"))
    assert model.name == live.rung and model.selection.rung == live.rung


def test_blocking_scene_contact_schema():
    s = load_scene("blocking_force_bench")
    assert s.design.length == 0.017 and s.contact.point == "rest_tip"
    assert s.contact.normal == (0.0, 1.0, 0.0) and s.gravity == (0.0, -9.81, 0.0)
    assert s.features == ("free_bending", "contact", "gravity")


ROD = {"capabilities": ["free_bending", "device_stiffness", "tip_load", "contact", "gravity"],
       "designs": {"implemented_5mm": {"error_rc_rel_max": 0.04, "cost_s_per_eval": 3e-3,
                                       "valid_pressure_pa": [0, 35000]}}}


def test_picks_rod_for_the_blocking_bench_once_measured(monkeypatch):
    env = {"reference": ENV["reference"], "rungs": {**ENV["rungs"], "rod": ROD}}
    bench = load_scene("blocking_force_bench")
    sel = select_model(bench, env)
    assert sel.rung == "rod" and "contact" in sel.reason
    assert "does not model contact" in sel.rejected["surrogate"]
    # the scene's loads reach the rung (a stand-in for the rod, which would build its law)
    seen = {}

    class Probe:
        def __init__(self, design, **options):
            seen.update(options, design=design)

    import softcath_ros.core.models as models
    monkeypatch.setattr(models, "RUNGS", {**models.RUNGS, "rod": f"{__name__}:_Probe"})
    globals()["_Probe"] = Probe
    make_model("auto", bench.design, scene=bench, envelope=env)
    assert seen["loads"] == bench.loads and seen["design"].length == 0.017
    # free bending alone still goes to the cheaper rungs
    assert select_model(scene(), env).rung == "surrogate"


def test_predict_cli_auto_says_what_it_picked(tmp_path):
    """The shipped blocking scene (to 0.35 bar) goes to the rod (the only rung with contact); the
    same scene to 0.4 bar, beyond the rod's measured range, is refused with every rung's reason."""
    import yaml


    if "rod" in load_envelope()["rungs"]:
        assert select_model(load_scene("blocking_force_bench"), load_envelope()).rung == "rod"
    raw = yaml.safe_load(find("scene", "blocking_force_bench").read_text())
    assert raw["pressure_range"] == [0.0, 35000.0]      # the bench's range, held by the hinged rod
    raw["pressure_range"] = [0.0, 40000.0]
    (tmp_path / "bench_035.yaml").write_text(yaml.safe_dump(raw))
    r = subprocess.run([sys.executable, "-m", "softcath_ros.cli", "predict", "--design", "implemented_5mm",
                        "--model", "auto", "--scene", str(tmp_path / "bench_035.yaml"), "--pressure", "0.1",
                        "--unit", "bar"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no rung qualifies" in r.stderr and "contact" in r.stderr
    assert re.search(r"rod: valid over 0..\d+ Pa only", r.stderr) or "rod" not in load_envelope()["rungs"]


def test_selection_uses_the_envelope_measured_at_the_scenes_length():
    """by_length entries (benchmarks/ladder_chart.py measures 40, 20 and 17 mm) decide for a scene at
    that length; another length falls back to the design's worst case, and the reason says which."""
    sur = ENV["rungs"]["surrogate"]["designs"]["implemented_5mm"]
    by_length = {"0.04": {**sur, "error_rc_rel_max": 0.03},
                 "0.017": {**sur, "error_rc_rel_max": 0.09, "valid_pressure_pa": [0, 25000]}}
    env = {**ENV, "rungs": {**ENV["rungs"], "surrogate": {**ENV["rungs"]["surrogate"], "designs": {
        "implemented_5mm": {**sur, "error_rc_rel_max": 0.09, "by_length": by_length}}}}}
    at_40 = select_model(scene(), env)
    assert at_40.rung == "surrogate" and "scene's length 40 mm" in at_40.reason
    short = select_model(scene(length=0.017, required_accuracy=0.1), env)
    assert short.rung == "surrogate" and "scene's length 17 mm" in short.reason
    slow = select_model(scene(length=0.017, required_rate=10.0), env)  # 17 mm: the surrogate's 9% > 5%
    assert slow.rung == "section" and "9.00% exceeds" in slow.rejected["surrogate"]
    with pytest.raises(ModelError, match="valid over 0..25000 Pa only"):
        select_model(scene(length=0.017, required_accuracy=0.1, pressure_range=[0, 26000]), env)
    other = select_model(scene(length=0.03, required_accuracy=0.1), env)
    assert other.rung == "surrogate" and "not at 30 mm" in other.reason


def test_scene_length_applies_to_its_design():
    assert scene(length=0.017).design.length == 0.017
    assert load_scene("blocking_force_bench").design.length == 0.017
    with pytest.raises(SceneError, match="'length'"):
        scene(length=-1.0)


def test_selection_judges_the_error_over_the_scenes_pressures():
    """An error measured near the rung's limit (11% at 0.25 bar) does not disqualify it for a scene
    that stops at 0.2 bar; a scene between measured pressures is judged up to the next one above."""
    sur = {**ENV["rungs"]["surrogate"]["designs"]["implemented_5mm"], "error_rc_rel_max": 0.11,
           "error_rc_rel_by_pressure_pa": [[10000.0, 0.038], [20000.0, 0.006], [25000.0, 0.11]]}
    env = {**ENV, "rungs": {**ENV["rungs"], "surrogate": {**ENV["rungs"]["surrogate"],
                                                           "designs": {"implemented_5mm": sur}}}}
    assert select_model(scene(pressure_range=[0.0, 20000.0]), env).rung == "surrogate"
    with pytest.raises(ModelError, match="surrogate: measured R_C error 11.00% exceeds"):
        select_model(scene(pressure_range=[0.0, 22000.0]), env)       # brackets 0.25 bar: 11% > 5%


def test_a_scene_to_040_bar_picks_a_rung_whose_envelope_covers_it_and_045_bar_is_refused():
    """The envelope is measured over 0-0.5 bar with lumen contact, and a rung's range ends where its
    answers end: the 3-channel design (40 mm) bends through its shaft only past 0.4375 bar, so a scene
    to 0.40 bar on it gets a rung whose measured range and measured pressures reach 0.40 bar; to
    0.45 bar, on it or on the 40 mm implemented_5mm body (its shaft from about 0.26 bar), every rung
    that answers free bending is refused by its range."""
    from softcath_ros.core.model_selection import measured_envelope

    env = load_envelope()
    high = scene(design="three_channel_5mm", pressure_range=[0.0, 40000.0], required_accuracy=0.15,
                 required_rate=100.0)
    sel = select_model(high, env)
    measured = measured_envelope(env["rungs"][sel.rung], high)
    assert measured["valid_pressure_pa"][1] >= 40000.0
    assert max(measured["measured_pressures_pa"]) >= 40000.0
    assert [p for p, e in measured["error_rc_rel_by_pressure_pa"] if p == 40000.0 and e is not None]
    for design in ("three_channel_5mm", "implemented_5mm"):
        too_high = scene(design=design, pressure_range=[0.0, 45000.0], required_accuracy=0.15, required_rate=100.0)
        with pytest.raises(ModelError, match="no rung qualifies") as refused:
            select_model(too_high, env)
        short = [n for n, r in env["rungs"].items()
                 if measured_envelope(r, too_high) and measured_envelope(r, too_high)["valid_pressure_pa"][1] < 45000.0]
        assert {"fe3d", "section", "surrogate"} <= set(short), (design, short)
        assert len(re.findall(r"valid over 0..\d+ Pa only", str(refused.value))) >= len(short), design


@pytest.mark.slow
def test_envelope_command_writes_what_selection_reads(tmp_path, monkeypatch):
    """`softcath envelope` on one case and three settings (closed form, section D/12 and the section rung's
    default D/20, the reference without fe3d):
    the file has the shipped envelope's layout and drives selection by measured error and cost."""
    from softcath_ros.cli import main as softcath

    monkeypatch.setenv("SOFTCATH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "envelope.yaml"
    code = softcath(["envelope", "--out", str(out), "--results", str(tmp_path / "rows"), "--no-fe3d",
                     "--cases", "1ch 40mm", "--settings", "closed_form", "section D/12", "section D/20"])
    assert code == 0 and (tmp_path / "rows.csv").is_file()
    meta = __import__("json").loads((tmp_path / "rows.json").read_text())["meta"]
    assert meta["load_average_before"] and meta["load_average_after"] and "numpy" in meta["packages"]
    env = load_envelope(out)
    shipped = load_envelope()
    assert set(env) == set(shipped)
    section = env["rungs"]["section"]["designs"]["implemented_5mm"]
    assert set(section) <= set(shipped["rungs"]["section"]["designs"]["implemented_5mm"])
    closed = env["rungs"]["closed_form"]["designs"]["implemented_5mm"]
    assert closed["error_rc_rel_max"] > 1.0 > 0.05 > section["error_rc_rel_max"]
    assert closed["cost_s_per_eval"] < section["cost_s_per_eval"]
    # a rate every measured cost meets, also on a loaded machine: the choice here is by accuracy and cost order
    assert select_model(scene(required_accuracy=0.05, required_rate=0.01), env).rung == "section"
    assert select_model(scene(required_accuracy=5.0, required_rate=0.01), env).rung == "closed_form"


def test_envelope_command_refuses_unknown_cases_in_one_line(capsys):
    from softcath_ros.cli import main as softcath

    assert softcath(["envelope", "--cases", "2ch 10mm"]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown" in err and "1ch 40mm" in err and len(err.splitlines()) == 1


def test_a_node_refuses_an_offline_rung_and_the_envelope_agrees_with_each_declaration():
    """RungInfo.live is the decision; the measured envelope backs it: every live rung answers a command
    within seconds on each measured design (well under one on the circle designs; the section rung on
    the fan design 5.3 s a command of a cold ladder sweep, most of it in the commands past where its
    body's answers end), the offline one (fe3d) takes 25 s or more."""
    from softcath_ros.core.model_selection import require_live_rung
    from softcath_ros.core.models import available_models, rung_info

    envelope = load_envelope()
    for name in available_models():
        costs = [d["cost_s_per_eval"] for d in envelope["rungs"].get(name, {}).get("designs", {}).values()]
        assert costs, name
        circles = [d["cost_s_per_eval"] for n, d in envelope["rungs"].get(name, {}).get("designs", {}).items()
                   if n != "three_sector_5mm"]
        if rung_info(name).live:
            assert max(circles) < 1.0 and max(costs) < 10.0, (name, costs)
            require_live_rung(name, "implemented_5mm", envelope)
        else:
            assert min(costs) > 20.0, (name, costs)
    assert not rung_info("fe3d").live
    require_live_rung("auto", "implemented_5mm", envelope)       # a chooser, not a rung
    fe3d_cost = envelope["rungs"]["fe3d"]["designs"]["implemented_5mm"]["cost_s_per_eval"]
    with pytest.raises(ModelError, match=rf"fe3d is no live rung: one command takes about {fe3d_cost:.0f} s for "
                                         r"design implemented_5mm .*model:=surrogate"):
        require_live_rung("fe3d", "implemented_5mm", envelope)
    with pytest.raises(ModelError, match="takes a minute or more"):   # a design the envelope did not measure
        require_live_rung("fe3d", "my_design", envelope)


def test_the_fan_design_is_judged_at_its_length_against_fe3d_where_the_committed_sweeps_went():
    """The shipped envelope knows three_sector_5mm (one fan, an equal pair; 40 mm against the section
    rung, 20 mm against the committed fe3d sweeps to 0.125 / 0.05 bar, else the section rung). At 40 mm
    the body reaches its shaft from 0.1875 bar on one fan: a scene to 0.15 bar at 5 % gets the surrogate,
    one to 0.2 bar is refused by every answering rung's range. At 20 mm the surrogate and the section
    rung (section-8) are 4.1 % / 4.5 % off fe3d at 0.05 / 0.10 bar on one fan (6.2-6.3 % on section-7,
    before the rings' bending): a 5 % scene there gets the surrogate, a 4 % scene nothing (fe3d too
    slow)."""
    from softcath_ros.core.model_selection import measured_envelope

    env = load_envelope()
    fan = scene(design="three_sector_5mm", pressure_range=[0.0, 15000.0], required_accuracy=0.05)
    sel = select_model(fan, env)
    assert sel.rung == "surrogate"
    measured = measured_envelope(env["rungs"]["surrogate"], fan)
    assert measured["_scope"] == "measured at the scene's length 40 mm"
    assert {ref for _, ref in measured["reference_by_pressure_pa"]} == {"section D/20"}
    with pytest.raises(ModelError, match="no rung qualifies") as refused:
        select_model(scene(design="three_sector_5mm", pressure_range=[0.0, 20000.0], required_accuracy=0.05), env)
    assert "surrogate: valid over 0..17500 Pa only" in str(refused.value)
    short = dict(design="three_sector_5mm", length=0.02, pressure_range=[0.0, 10000.0], required_rate=100.0)
    at_20 = measured_envelope(env["rungs"]["surrogate"], scene(**short, required_accuracy=0.05))
    assert at_20["reference_by_pressure_pa"][0] == [5000.0, "fe3d mesh 1.4, 1.2 mm layers"]
    assert 0.03 < at_20["error_rc_rel_by_pressure_pa"][0][1] < 0.05
    assert select_model(scene(**short, required_accuracy=0.05), env).rung == "surrogate"
    with pytest.raises(ModelError, match=r"surrogate: measured R_C error 4\.\d\d% exceeds"):
        select_model(scene(**short, required_accuracy=0.04), env)
