"""The ladder's bookkeeping (core/ladder.py), without solving: the reference chosen per point (fe3d
where it converged, else the section rung with contact), errors against that point's reference,
the accuracy boundary per tolerance, the named stop reason, and the envelope built from the rows."""
import dataclasses

import pytest

from softcath_ros.core import ladder
from softcath_ros.core.ladder_envelope import envelope_document
from softcath_ros.core.continuation import (LIMIT_POINT, NUMERICAL_FAILURE, OUTSIDE_MODEL, STOP_REASONS, UNSTABLE,
                                            stop_tag, tagged_stop)
from softcath_ros.core.errors import ModelError
from softcath_ros.core.model_selection import select_model
from softcath_ros.core.scene import scene_from_dict
from softcath_ros.resources import checkout_root

CASE = ladder.Case("1ch 40mm", "length", "implemented_5mm", 0.040, (1.0,), (10000.0, 20000.0, 30000.0, 40000.0))


def _pred(p, rc, converged=True):
    return {"pressures_pa": [p], "converged": converged, "curvature_per_m": [0.0, -1.0 / rc] if converged else None,
            "radius_of_curvature_m": rc if converged else None, "centreline_radius_m": rc if converged else None,
            "tip_position_m": [0.0, -rc / 10, 0.04] if converged else None}


COST = {"fe3d": 30.0, "section": 0.2, "surrogate": 1e-5, "rod": 1e-3}


def _result(rung, rcs, converged=(True,) * 4, boundary=40000.0, stop="", contact=None):
    return {"rung": rung, "s_per_eval": COST[rung], "boundary_pa": boundary, "stop_reason": stop, "fails_beyond": bool(stop),
            "first_failure": "", "contact_boundary_pa": contact,
            "predictions": [_pred(p, rc, ok) for p, rc, ok in zip(CASE.magnitudes_pa, rcs, converged)]}


FAKE = {  # fe3d converges at the first two points only, as fe3d without contact stops at 0.252 bar
    "fe3d mesh 1.4, 1.2 mm layers": _result("fe3d", [0.10, 0.05, 1, 1], (True, True, False, False), 20000.0, NUMERICAL_FAILURE),
    "section D/20": _result("section", [0.11, 0.055, 0.03, 0.02]),
    "surrogate (of section D/20)": _result("surrogate", [0.11, 0.055, 0.0303, 0.0202]),
    "rod": _result("rod", [0.11, 0.055, 0.03, 0.02], boundary=30000.0, stop=ladder.stop_reason("x"),
                   contact=20000.0),
}
SETTINGS = [(label, res["rung"], {}, True) for label, res in FAKE.items()]


@pytest.fixture
def rows(monkeypatch):
    monkeypatch.setattr(ladder, "run_rung", lambda case, rung, options, solver, refresh=False:
                        next(r for r in FAKE.values() if r["rung"] == rung))
    rows, label = ladder.run_case(CASE, SETTINGS, say=lambda *a, **k: None)
    assert label == "fe3d mesh 1.4, 1.2 mm layers / section D/20"
    return rows


def _of(rows, setting):
    return [r for r in rows if r["setting"] == setting]


def test_reference_per_point_and_errors_against_it(rows):
    section = _of(rows, "section D/20")
    assert [r["reference"] for r in section] == ["fe3d mesh 1.4, 1.2 mm layers"] * 2 + ["section D/20"] * 2
    assert section[0]["rc_rel_error"] == pytest.approx(0.10) and section[1]["rc_rel_error"] == pytest.approx(0.10)
    assert section[2]["rc_rel_error"] == 0.0        # its own reference there
    surrogate = _of(rows, "surrogate (of section D/20)")
    assert surrogate[2]["rc_rel_error"] == pytest.approx(0.01) and surrogate[3]["rc_rel_error"] == pytest.approx(0.01)
    fe3d = _of(rows, "fe3d mesh 1.4, 1.2 mm layers")
    assert [r["rc_rel_error"] for r in fe3d] == [0.0, 0.0, None, None]


def test_accuracy_boundary_per_tolerance(rows):
    sur = _of(rows, "surrogate (of section D/20)")[0]
    # 10 % error against fe3d at the first points: within 10 % to the end, within 5 % nowhere
    assert sur["accurate_to_pa_10pct"] == 40000.0 and sur["accurate_to_pa_5pct"] == 0.0
    # the section rung is not measured where it is its own reference: its boundary ends at fe3d's last point
    assert _of(rows, "section D/20")[0]["accurate_to_pa_10pct"] == 20000.0
    assert _of(rows, "fe3d mesh 1.4, 1.2 mm layers")[0]["accurate_to_pa_2pct"] == 20000.0
    assert ladder.accurate_to([0.01, None, 0.01], [1.0, 2.0, 3.0], 0.05) == 1.0


def test_stop_reasons_are_named():
    assert ladder.stop_reason("") == ""
    assert ladder.stop_reason(f"did not converge at p = 0.27 bar [stop: {NUMERICAL_FAILURE}]") == NUMERICAL_FAILURE
    assert ladder.stop_reason(f"...; {LIMIT_POINT} at p = 0.4 bar: the tangent's ...") == LIMIT_POINT
    assert ladder.stop_reason("rod Newton did not converge in 40 iterations") == "unnamed"
    # one tag, written by continuation.stop_tag and read by continuation.tagged_stop: the tag wins over a
    # reason the message's text mentions
    assert all(tagged_stop(f"did not converge (...) {stop_tag(r)}; next") == r for r in STOP_REASONS)
    assert tagged_stop("rod Newton did not converge") is None
    assert ladder.stop_reason(f"past the {LIMIT_POINT} the law ends {stop_tag(OUTSIDE_MODEL)}") == OUTSIDE_MODEL


def test_no_reference_is_refused(monkeypatch):
    monkeypatch.setattr(ladder, "run_rung", lambda case, rung, options, solver, refresh=False: FAKE["rod"])
    with pytest.raises(ModelError, match="no reference"):
        ladder.run_case(CASE, [("rod", "rod", {}, True)], say=lambda *a, **k: None)


def test_envelope_from_the_rows_drives_selection(rows):
    doc = envelope_document(rows, "now")
    sur = doc["rungs"]["surrogate"]["designs"]["implemented_5mm"]
    assert sur["valid_pressure_pa"] == [0.0, 40000.0] and sur["accurate_to_pa"]["0.1"] == 40000.0
    assert sur["reference_by_pressure_pa"][0] == [10000.0, "fe3d mesh 1.4, 1.2 mm layers"]
    assert sur["reference_by_pressure_pa"][-1] == [40000.0, "section D/20"]
    fe3d = doc["rungs"]["fe3d"]["designs"]["implemented_5mm"]
    assert fe3d["valid_pressure_pa"] == [0.0, 20000.0] and fe3d["stop_reasons"] == [NUMERICAL_FAILURE]
    rod = doc["rungs"]["rod"]["designs"]["implemented_5mm"]
    assert rod["valid_pressure_pa_with_contact"] == [0.0, 20000.0]
    # free bending to 0.35 bar at 15 %: the surrogate (cheapest, range to 0.4 bar, 10 % worst)
    free = scene_from_dict({"name": "t", "design": "implemented_5mm", "pressure_range": [0.0, 35000.0],
                            "required_accuracy": 0.15, "required_rate": 0.5})
    assert select_model(free, doc).rung == "surrogate"
    # a contact scene only the rod models, judged by its range with the tip on the plane
    raw = {"name": "b", "design": "implemented_5mm", "pressure_range": [0.0, 25000.0], "required_accuracy": 0.2,
           "required_rate": 0.5, "loads": {"contact": {"kind": "tip_plane", "normal": [0, 1, 0],
                                                        "point": "rest_tip"}}}
    with pytest.raises(ModelError, match="rod: valid over 0..20000 Pa only with contact"):
        select_model(scene_from_dict(raw), doc)
    assert select_model(scene_from_dict({**raw, "pressure_range": [0.0, 20000.0]}), doc).rung == "rod"


def test_a_point_beyond_the_references_ramp_boundary_is_no_reference():
    """The section rung answered the case's last point but its ramp to max_pressure stopped before it
    (another branch): that point has no reference, so no error is recorded there."""
    results = {"section D/20": {**FAKE["section D/20"], "boundary_pa": 30000.0}}
    assert ladder.reference_labels(results) == ["section D/20"] * 3 + [None]


SHORT = ladder.Case("1ch 17mm", "length", "implemented_5mm", 0.017, (1.0,), (10000.0, 20000.0))
LINEAR_ROD = {"source": "closed_form"}   # the rod on the closed form's linear law: models contact, solves fast


def test_a_cached_rung_result_is_complete_and_an_old_one_still_reads(monkeypatch):
    """run_rung caches the whole record; reading it computes nothing. A result cached in the former
    format (no contact_boundary_pa) reads under the same key and gains the field once."""
    from softcath_ros.core import cache
    from softcath_ros.core.models import make_model, rung_class

    fresh = ladder.run_rung(SHORT, "rod", LINEAR_ROD, True, refresh=True)
    assert fresh["record"] == ladder.RECORD and fresh["contact_boundary_pa"] > 0
    # the key is the format every cached ladder result was written under; a rung whose tip comes
    # through the arc and the straight cap has the kinematics' version in it, fe3d (its own tip) not
    design = ladder.load_design(SHORT.design).with_length(SHORT.length)
    key = ladder._key_parts(SHORT, "rod", LINEAR_ROD)
    assert key == [design.content_hash(), "rod", rung_class("rod").solver_version + "/" + ladder.KINEMATICS_VERSION,
                   LINEAR_ROD, SHORT.pressures.tolist()]
    assert ladder._key_parts(SHORT, "fe3d", {})[2] == rung_class("fe3d").solver_version
    assert cache.load_json("ladder", ladder.LADDER_VERSION, key, "rod") == fresh

    def no_solving(*args, **kwargs):
        raise AssertionError("a cached result was computed again")

    calls = []
    real_boundary = ladder.contact_boundary
    monkeypatch.setattr(ladder, "make_model", no_solving)
    monkeypatch.setattr(ladder, "contact_boundary", no_solving)
    assert ladder.run_rung(SHORT, "rod", LINEAR_ROD, True) == fresh
    # a result in format 1, as written before the field existed
    old = {k: v for k, v in fresh.items() if k not in ("record", "contact_boundary_pa")}
    cache.save_json("ladder", ladder.LADDER_VERSION, key, old, "rod")
    monkeypatch.setattr(ladder, "make_model", make_model)
    monkeypatch.setattr(ladder, "contact_boundary", lambda *a: calls.append(a) or real_boundary(*a))
    upgraded = ladder.run_rung(SHORT, "rod", LINEAR_ROD, True)
    assert upgraded == fresh and len(calls) == 1
    assert ladder.run_rung(SHORT, "rod", LINEAR_ROD, True) == fresh and len(calls) == 1   # saved: once


def test_a_case_loads_its_design_once(monkeypatch):
    """Its key, its rungs and its ramp with the tip on the scale share one loaded design."""
    loads = []
    real = ladder.load_design
    monkeypatch.setattr(ladder, "load_design", lambda name: loads.append(name) or real(name))
    case = dataclasses.replace(SHORT)          # a new case: nothing loaded yet
    ladder.run_rung(case, "rod", LINEAR_ROD, True, refresh=True)
    assert ladder.is_cached(case, "rod", LINEAR_ROD) and ladder.is_cached(case, "closed_form", {}) is False
    assert ladder._key_parts(case, "rod", LINEAR_ROD)[0] == real(SHORT.design).with_length(SHORT.length).content_hash()
    assert loads == [SHORT.design]


def test_fe3d_runs_the_three_channel_cases_on_a_mirror_plane_on_the_half_body():
    """One channel and an equal pair lie on a mirror plane: fe3d gets half=True there (a new key for
    those rows only); the 2:1 pair and the 1-channel cases keep their options (and cached rows)."""
    from softcath_ros.core.ladder import CASES, FE3D, fe3d_options

    by_name = {c.name: fe3d_options(c, FE3D[2]) for c in CASES}
    assert by_name["3ch one channel"] == {**FE3D[2], "half": True}
    assert by_name["3ch pair equal"] == {**FE3D[2], "half": True}
    assert by_name["3ch pair 2:1"] == FE3D[2]
    assert all(by_name[c.name] == FE3D[2] for c in CASES if c.family == "length")


def test_a_rungs_boundary_ends_where_its_answers_end():
    """A 40 mm body bends through its shaft from about 0.26 bar: the surrogate's own ramp reaches
    max_pressure, but its answers (predict) end below 0.3 bar, named outside the model's validity;
    that is the boundary run_rung records, and a result cached in format 2 (the rung's own ramp) is
    upgraded to it once."""
    from softcath_ros.core import cache
    from softcath_ros.core.models import make_model

    case = ladder.Case("1ch 40mm", "length", "implemented_5mm", 0.040, (1.0,), (10000.0, 20000.0))
    model = make_model("surrogate", case.sample)
    own, own_beyond, _ = ladder.ramp_boundary(model, case.direction)
    answered, beyond, message = ladder.ramp_boundary(model, case.direction, answers=True)
    assert own == model.design.max_pressure and not own_beyond
    assert 20000.0 < answered < 30000.0 and beyond and ladder.stop_reason(message) == OUTSIDE_MODEL
    fresh = ladder.run_rung(case, "surrogate", {}, False, refresh=True)
    assert fresh["boundary_pa"] == answered and fresh["stop_reason"] == OUTSIDE_MODEL and fresh["record"] == 3
    key = ladder._key_parts(case, "surrogate", {})
    cache.save_json("ladder", ladder.LADDER_VERSION, key,
                    {**fresh, "record": 2, "boundary_pa": own, "fails_beyond": False, "stop_reason": "",
                     "first_failure": ""}, "surrogate")
    assert ladder.run_rung(case, "surrogate", {}, False) == fresh
    assert cache.load_json("ladder", ladder.LADDER_VERSION, key, "surrogate") == fresh


SECTOR = {c.name: c for c in ladder.CASES if c.design == "three_sector_5mm"}


def _sweep_rows(name):
    import json

    return json.loads((checkout_root() / "benchmarks" / "results" / f"{name}.json").read_text())["results"]


def test_the_fan_design_is_measured_on_one_channel_and_an_equal_pair_at_two_lengths():
    assert {(c.length, c.direction) for c in SECTOR.values()} == {
        (0.040, (1.0, 0.0, 0.0)), (0.040, (0.0, 1.0, 1.0)), (0.020, (1.0, 0.0, 0.0)), (0.020, (0.0, 1.0, 1.0))}
    assert all(c.family == "direction" for c in SECTOR.values())
    # fe3d where a committed sweep exists (20 mm), of the design at the case's length as it is now
    assert [c.name for c in SECTOR.values() if c.fe3d_sweep] == ["sector one channel 20mm", "sector pair equal 20mm"]
    assert all(c.fe3d_sweep[1] == c.sample.content_hash() for c in SECTOR.values() if c.fe3d_sweep)


@pytest.mark.skipif(checkout_root() is None, reason="the committed fe3d sweeps (source checkout only)")
def test_a_committed_fe3d_sweep_stands_as_the_cases_fe3d(monkeypatch):
    """The one-fan sweep stopped at 0.1458 bar, named (an unstable equilibrium): fe3d converged at the
    ladder's 0.05 and 0.10 bar with the sweep's R_C, and nowhere above; the case's fe3d stops with the
    sweep's named reason. In
    run_case those points have fe3d as reference (no tip error: the sweep records no tip), the section
    rung's own error there is its error against fe3d, and the points above have the section rung."""
    case = SECTOR["sector one channel 20mm"]
    fe3d = ladder.committed_fe3d(case)
    by_bar = {round(r["pressure_bar"], 3): r for r in _sweep_rows("fe3d_sector_ch0_20mm")}
    conv = [p["converged"] for p in fe3d["predictions"]]
    assert conv == [True, True] + [False] * 8
    assert [p["radius_of_curvature_m"] for p in fe3d["predictions"][:2]] == [
        by_bar[b]["radius_l_over_theta_mm"] * 1e-3 for b in (0.05, 0.1)]
    assert fe3d["boundary_pa"] == 10000.0 and fe3d["stop_reason"] == UNSTABLE
    assert "last converged p = 0.1458 bar" in fe3d["first_failure"]
    # the section rung on the same points: its rows as run_rung records them (fake, fast)
    section = {**fe3d, "rung": "section", "boundary_pa": 27500.0, "stop_reason": "", "fails_beyond": False,
               "predictions": [_pred(p, 0.9 * (0.0744 if i == 0 else 0.0243 if i == 1 else 0.01))
                               | {"pressures_pa": [p, 0.0, 0.0]} for i, p in enumerate(case.magnitudes_pa)]}
    monkeypatch.setattr(ladder, "run_rung", lambda *a, **k: section)
    rows, label = ladder.run_case(case, [ladder.FE3D, ("section D/20", "section", {}, True)], say=lambda *a, **k: None)
    assert label == "fe3d mesh 1.4, 1.2 mm layers / section D/20"
    sec = _of(rows, "section D/20")
    assert [r["reference"] for r in sec[:3]] == ["fe3d mesh 1.4, 1.2 mm layers"] * 2 + ["section D/20"]
    fe3d_rc = fe3d["predictions"][0]["radius_of_curvature_m"]
    assert sec[0]["rc_rel_error"] == pytest.approx(abs(0.9 * 0.0744 / fe3d_rc - 1))
    assert sec[0]["tip_error_mm"] is None and sec[0]["direction_error_deg"] == pytest.approx(0.0, abs=1e-9)
    # without fe3d (--no-fe3d) the sweep is not read: the section rung is the reference everywhere
    rows, label = ladder.run_case(case, [ladder.FE3D, ("section D/20", "section", {}, True)], fe3d=False,
                                  say=lambda *a, **k: None)
    assert label == "section D/20"


@pytest.mark.skipif(checkout_root() is None, reason="the committed fe3d sweeps (source checkout only)")
def test_a_committed_sweep_that_is_not_the_case_is_refused():
    """Another length, other channels, or the design changed since the sweep: refused in one line."""
    pair = SECTOR["sector pair equal 20mm"]
    assert [p["converged"] for p in ladder.committed_fe3d(pair)["predictions"]][:2] == [True, False]
    for wrong, match in ((dataclasses.replace(pair, direction=(1.0, 1.0, 0.0)), "is not this case"),
                         (dataclasses.replace(pair, length=0.04, fe3d_sweep=(pair.fe3d_sweep[0],
                          pair.sample.with_length(0.04).content_hash())), "is not this case"),
                         (dataclasses.replace(pair, fe3d_sweep=(pair.fe3d_sweep[0], "0" * 16)), "changed since")):
        with pytest.raises(ModelError, match=match) as exc:
            ladder.committed_fe3d(wrong)
        assert "\n" not in str(exc.value)


def test_a_reference_without_a_tip_gives_no_tip_error():
    p, r = _pred(10000.0, 0.1), {**_pred(10000.0, 0.11), "tip_position_m": None}
    e = ladder.errors(p, r)
    assert e["tip_error_mm"] is None and e["rc_rel_error"] == pytest.approx(abs(0.1 / 0.11 - 1))
    assert ladder.errors(p, _pred(10000.0, 0.11))["tip_error_mm"] > 0
