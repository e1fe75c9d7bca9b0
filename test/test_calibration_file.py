"""Calibration as data: the file `softcath calibrate` writes, the calibrated model every command and
node applies, the 95% band, and the round trip against a simulated rig with a known truth."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from bench_sim_helpers import run_offline, write_recording
from softcath_ros.bench.analysis import rows_from_events
from softcath_ros.bench.blocking import BlockingForce
from softcath_ros.bench.calibration import calibrate
from softcath_ros.bench.protocol import load_protocol
from softcath_ros.bench.sim_rig import RigParams, SimulatedRig
from softcath_ros.core.calibration_file import (Calibration, CalibratedModel, CalibrationError, band95,
                                                build_model, calibration_from_dict, from_fit, load_calibration,
                                                scaled_design, section_hash)
from softcath_ros.core.design import load_design
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import angle_per_length

TRUE_SHIFT, TRUE_SCALE = 0.25, 1.3    # the rig's truth: the published shift, a 30% stiffer silicone


def softcath(*args):
    return subprocess.run([sys.executable, "-m", "softcath_ros.cli", *args], capture_output=True, text=True,
                          timeout=110)


def _calibration(design, shift=0.2, scale=1.1, cov=((1e-4, 2e-5), (2e-5, 4e-4))):
    return Calibration(design=design.name, design_hash=section_hash(design), rung="closed_form",
                       pressure_shift=shift, material_scale=scale, covariance=cov, rms_before=5.0, rms_after=1.0,
                       n_residuals=10, recording="x.mcap", recording_sha256="0" * 64, date="2026-12-01T00:00:00+00:00")


@pytest.fixture(scope="module")
def truth_run(tmp_path_factory):
    """The quick protocol on a rig whose truth is the closed form on a 1.3x stiffer material at 0.75 p,
    with reading and gauge noise but no bench bias (friction, tilt, gauge offset: the fit would absorb them)."""
    design = load_design("implemented_5mm")
    truth = make_model("closed_form", scaled_design(design, TRUE_SCALE))
    params = RigParams(pressure_shift=TRUE_SHIFT, friction_underread=0.0, out_of_plane_tilt=0.0, gauge_error=0.0,
                       seed=5)
    events, streams = run_offline(load_protocol("quick"), SimulatedRig(truth, params))
    path = write_recording(tmp_path_factory.mktemp("truth") / "truth", events, streams,
                           yaml.safe_dump(design.to_dict()))
    return design, params, rows_from_events(events, streams), path


def test_round_trip_recovers_the_truth_within_the_stated_95_percent_intervals(truth_run, tmp_path):
    design, params, rows, path = truth_run
    result = calibrate(rows, design, "closed_form")
    cal = from_fit(result, design, path)
    ci = cal.ci95
    assert result.success
    assert abs(cal.pressure_shift - TRUE_SHIFT) <= ci["pressure_shift"], (cal.pressure_shift, ci)
    assert abs(cal.material_scale - TRUE_SCALE) <= ci["material_scale"], (cal.material_scale, ci)
    assert ci["pressure_shift"] < 0.05 and ci["material_scale"] < 0.15      # the data do constrain them
    # The file round-trips exactly, and ties the recording by its hash.
    back = load_calibration(cal.save(tmp_path / "c.calibration.yaml"))
    assert back == cal and back.recording_sha256 == cal.recording_sha256 and len(cal.recording_sha256) == 64
    # The calibrated prediction lies within the rig's noise of every reading.
    model = build_model("closed_form", design, back)
    force = BlockingForce(model)
    for r in rows:
        state = model.evaluate(r.pressure)
        if r.bench == "angle":
            measured, predicted = r.curvature, float(angle_per_length(state, model, r.length)[0])
            noise = params.angle_noise / r.length
        else:
            measured, predicted = r.force, float(force.from_curvature(state.curvature, r.length))
            noise = math.sqrt(2) * params.force_noise        # a reading minus its tare reading
        # the gauge's noise moves the reading's pressure away from the one that bent the sample
        slope = abs(float(angle_per_length(model.evaluate(r.pressure + 100.0), model, r.length)[0])
                    - float(angle_per_length(state, model, r.length)[0])) / 100.0
        if r.bench == "force":
            slope *= abs(predicted) / max(float(angle_per_length(state, model, r.length)[0]), 1e-9)
        sigma = math.hypot(noise, slope * params.gauge_noise)
        assert abs(predicted - measured) <= 4.0 * sigma, (r.bench, r.level, predicted, measured, sigma)
    assert cal.rms_after < 1.5 < cal.rms_before


def test_calibrated_model_shifts_pressure_and_scales_material(implemented_design):
    cal = _calibration(implemented_design, shift=0.2, scale=1.5)
    model = build_model("closed_form", implemented_design, cal)
    assert isinstance(model, CalibratedModel) and model.name == "closed_form calibrated"
    reference = make_model("closed_form", scaled_design(implemented_design, 1.5))
    p = np.array([[10000.0], [30000.0]])
    got, want = model.evaluate(p), reference.evaluate(p * 0.8)
    assert np.allclose(got.curvature, want.curvature) and np.allclose(got.axial_stretch, want.axial_stretch)
    # still linear (the allocator and the node's fast path use the gains)
    assert np.allclose(model.curvature_per_pa, 0.8 * reference.curvature_per_pa)
    k, stretch = model.curvature_single(np.array([30000.0]))
    assert np.allclose(k, want.curvature[1]) and stretch == pytest.approx(want.axial_stretch[1])
    # the safety limit stays the design's, on the commanded pressure
    assert model.pressure_range == (0.0, implemented_design.max_pressure)
    # a stiffer material bends less, a positive shift bends less: both move R_C up
    plain = make_model("closed_form", implemented_design).evaluate(p)
    assert np.all(np.abs(got.curvature[:, 1]) < np.abs(plain.curvature[:, 1]))


def test_calibration_for_another_design_is_refused(implemented_design, tmp_path):
    cal = _calibration(implemented_design)
    other = load_design("three_channel_5mm")
    with pytest.raises(CalibrationError, match="another design"):
        build_model("closed_form", other, cal)
    # the same section at another length or a lowered limit is the same actuator
    build_model("closed_form", implemented_design.with_length(0.02), cal)
    # the CLI: one line, exit 2
    path = cal.save(tmp_path / "c.yaml")
    r = softcath("predict", "--design", "three_channel_5mm", "--pressure", "0.1,0,0", "--unit", "bar",
                 "--calibration", str(path))
    assert r.returncode == 2 and "another design" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("patch, fragment", [
    ({"pressure_shift": None}, "field 'pressure_shift' = None: must be a finite number"),
    ({"covariance": [[1, 2], [3, 4]]}, "symmetric positive semi-definite"),
    ({"covariance": [[1e-4, 0.0]]}, "2x2"),
    ({"material_scale": 0.0}, "material_scale"),
    ({"colour": "red"}, "unknown field"),
    ({"schema": 7}, "schema"),
    ({"schema": 1}, "re-run softcath calibrate"),      # schema 1 scaled the silicone only
])
def test_malformed_calibration_files_are_refused_naming_the_field(implemented_design, patch, fragment):
    d = _calibration(implemented_design).to_dict()
    d.update(patch)
    with pytest.raises(CalibrationError) as exc:
        calibration_from_dict(d, source="calibration f.yaml")
    assert fragment in str(exc.value) and "f.yaml" in str(exc.value)
    d = _calibration(implemented_design).to_dict()
    del d["recording_sha256"]
    with pytest.raises(CalibrationError, match="recording_sha256.*missing"):
        calibration_from_dict(d)


def test_band95_matches_sampling_the_covariance(implemented_design):
    """Linearised propagation against Monte Carlo over N(x, C): the two 95% half-widths of R_C agree."""
    cov = np.array([[4e-4, -1e-4], [-1e-4, 9e-4]])
    cal = _calibration(implemented_design, cov=tuple(map(tuple, cov)))
    p = np.array([[20000.0], [35000.0]])

    def rc(c):
        model = build_model("closed_form", implemented_design, c)
        return 1.0 / angle_per_length(model.evaluate(p), model)

    half = band95(cal, rc)
    rng = np.random.default_rng(0)
    samples = rng.multivariate_normal([cal.pressure_shift, cal.material_scale], cov, 4000)
    draws = np.array([rc(cal.with_values(*x)) for x in samples])
    assert half == pytest.approx(1.96 * draws.std(axis=0), rel=0.08)
    zero = _calibration(implemented_design, cov=((0.0, 0.0), (0.0, 0.0)))
    assert np.all(band95(zero, rc) == 0.0)


def test_calibrate_writes_the_file_and_predict_applies_it_with_a_band(truth_run, tmp_path):
    design, _, _, path = truth_run
    out = tmp_path / "cal.yaml"
    r = softcath("calibrate", str(path), "--model", "closed_form", "--output", str(out), "--json")
    assert r.returncode == 0, r.stderr
    doc = yaml.safe_load(out.read_text())
    assert doc["design"] == "implemented_5mm" and doc["design_hash"] == section_hash(design)
    assert doc["rung"] == "closed_form" and len(doc["covariance"]) == 2 and doc["recording_sha256"]
    assert abs(doc["pressure_shift"] - TRUE_SHIFT) < 0.05 and doc["rms_after"] < doc["rms_before"]
    cal = load_calibration(out)
    # predict: calibrated numbers with a 95% band around them
    r = softcath("predict", "--design", "implemented_5mm", "--model", "closed_form", "--pressure", "0.1", "0.3",
                 "--unit", "bar", "--calibration", str(out), "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["model"] == "closed_form calibrated" and res["calibration"]["pressure_shift"] == cal.pressure_shift
    calibrated = build_model("closed_form", design, cal)
    want = 1.0 / angle_per_length(calibrated.evaluate(np.array([[3e4]])), calibrated)[0]
    top = res["results"][1]
    assert top["radius_of_curvature_m"] == pytest.approx(want)
    band = top["band95"]
    assert 0 < band["radius_of_curvature_m"] < 0.2 * top["radius_of_curvature_m"]
    assert len(band["tip_position_m"]) == 3 and band["bending_angle_rad"] > 0


def test_report_and_sweep_apply_a_calibration(truth_run, tmp_path, capsys):
    from softcath_ros.bench.report import write_report
    from softcath_ros.cli import main

    design, _, rows, path = truth_run
    cal = from_fit(calibrate(rows, design, "closed_form"), design, path)
    out = cal.save(tmp_path / "cal.yaml")
    # report: each rung overlaid as it is and calibrated, the calibrated one with its band in the plots
    result = write_report(path, None, ["closed_form"], load_calibration(out), tmp_path / "rep")
    top = [s for s in result["stats"] if s.bench == "angle" and s.level == 30000.0][0]
    calibrated = top.model["closed_form calibrated"]
    assert 0 < calibrated["radius_band95"] < 0.2 * calibrated["radius"]
    # the calibrated overlay is nearer the readings than the plain rung
    assert abs(calibrated["radius"] - top.radius_mean) < abs(top.model["closed_form"]["radius"] - top.radius_mean)
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "closed_form calibrated" in text and cal.recording_sha256[:12] in text
    assert f"| {calibrated['radius'] * 1e3:.1f} ± {calibrated['radius_band95'] * 1e3:.1f} |" in text
    assert main(["report", str(path), "--calibration", str(out), "--out", str(tmp_path / "rep2"), "--no-cache"]) == 0
    # sweep takes it too, at another length (the calibration is of the section)
    capsys.readouterr()
    assert main(["sweep", "--design", "implemented_5mm", "--model", "closed_form", "--to", "0.3", "--unit", "bar",
                 "--steps", "3", "--length", "0.02", "--calibration", str(out), "--no-plot", "--out", str(tmp_path / "sw"),
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out.split("\nwrote")[0])
    assert doc["model"] == "closed_form calibrated"
    short = build_model("closed_form", design.with_length(0.02), cal)
    want = short.evaluate(np.array([[3e4]]))
    assert doc["results"][-1]["radius_of_curvature_m"] == pytest.approx(1 / angle_per_length(want, short)[0])


def test_model_node_applies_a_calibration_parameter(implemented_design, tmp_path):
    rclpy = pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")
    from rclpy.parameter import Parameter

    from domains import private_domain
    from softcath_ros.nodes.allocation_node import AllocationNode
    from softcath_ros.nodes.model_node import ModelNode

    cal = _calibration(implemented_design, shift=0.25, scale=1.2)
    path = cal.save(tmp_path / "c.yaml")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=private_domain())
    try:
        node = ModelNode(context=context, parameter_overrides=[Parameter("model", value="closed_form"),
                                                               Parameter("calibration", value=str(path))])
        try:
            assert node.model.name == "closed_form calibrated"
            k, _ = node._fast(np.array([20000.0]))
            assert np.allclose(k, build_model("closed_form", implemented_design, cal).evaluate([20000.0]).curvature)
        finally:
            node.destroy_node()
        # allocation_node's default design is the 3-channel one: this calibration is refused
        with pytest.raises(CalibrationError, match="another design"):
            AllocationNode(context=context, parameter_overrides=[Parameter("calibration", value=str(path))])
    finally:
        rclpy.try_shutdown(context=context)


def test_allocate_applies_a_calibration(implemented_design, tmp_path, capsys):
    """The allocator inverts the calibrated rung: with the material unscaled, a shift s needs 1 / (1 - s)
    times the pressure for the same bend."""
    from softcath_ros.cli import main

    path = _calibration(implemented_design, shift=0.2, scale=1.0).save(tmp_path / "c.yaml")
    base = ["allocate", "--design", "implemented_5mm", "--model", "closed_form", "--curvature", "0,-10", "--json"]
    assert main(base) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main(base + ["--calibration", str(path)]) == 0
    calibrated = json.loads(capsys.readouterr().out)
    assert calibrated["model"] == "closed_form calibrated"
    assert calibrated["pressures_pa"][0] == pytest.approx(plain["pressures_pa"][0] / 0.8, rel=1e-9)


def test_model_node_with_a_calibration_for_another_design_exits_2_with_one_line(implemented_design, tmp_path):
    pytest.importorskip("rclpy", reason="the ROS extra is part of the test set-up (scripts/test.sh)")
    from domains import private_env

    path = _calibration(implemented_design).save(tmp_path / "c.yaml")
    proc = subprocess.run([sys.executable, "-m", "softcath_ros.nodes.model_node", "--ros-args",
                           "-p", "design:=three_channel_5mm", "-p", f"calibration:={path}"],
                          env=private_env(), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "another design" in proc.stderr and "Traceback" not in proc.stderr


# --------------------------------------------------------------------------- a material scale is a pressure scale

@pytest.mark.parametrize("rung, options, tol", [("closed_form", {}, 1e-10), ("section", {"mesh_size": 0.005 / 8}, 1e-5)])
def test_material_scale_is_exactly_the_pressure_divided_by_it(rung, options, tol):
    """Every modulus x m scales the whole potential: the rung on the design read at (1 - s) p / m is
    the rung rebuilt on the scaled design at (1 - s) p (section: to its Newton tolerance)."""
    design = load_design("implemented_5mm").with_length(0.02)
    shift, m = 0.1, 1.3
    fast = CalibratedModel(make_model(rung, design, **options), shift, material_scale=m)
    rebuilt = CalibratedModel(make_model(rung, scaled_design(design, m), **options), shift)
    p = np.array([[10000.0], [20000.0]])
    a, b = fast.evaluate(p), rebuilt.evaluate(p)
    assert a.converged.all() and b.converged.all()
    np.testing.assert_allclose(a.curvature, b.curvature, rtol=tol, atol=1e-12)
    np.testing.assert_allclose(a.axial_stretch, b.axial_stretch, rtol=tol)
    # a force from the moduli (the blocking force through EI) scales with them
    np.testing.assert_allclose(BlockingForce(fast).from_curvature(a.curvature, 0.017),
                               BlockingForce(rebuilt).from_curvature(b.curvature, 0.017), rtol=tol)
    # the scale is not a silicone-only change: the fibre, the rings (and a device) scale too
    sd = scaled_design(design, m)
    assert sd.limiting_fibre.material.c1 == pytest.approx(m * design.limiting_fibre.material.c1)
    assert sd.reinforcement.youngs_modulus == pytest.approx(m * design.reinforcement.youngs_modulus)
    assert sd.material.bulk_modulus == pytest.approx(m * design.material.bulk_modulus)


def test_fit_by_scaled_pressures_agrees_with_rebuilding_the_rung(truth_run):
    design, _, rows, _ = truth_run
    rows = rows[::3]                      # both benches still in (fewer readings: a fast test)
    assert {r.bench for r in rows} == {"angle", "force"}
    fast = calibrate(rows, design, "closed_form")
    slow = calibrate(rows, design, "closed_form", rebuild=True)
    assert fast.pressure_shift == pytest.approx(slow.pressure_shift, abs=1e-6)
    assert fast.material_scale == pytest.approx(slow.material_scale, abs=1e-6)
    assert fast.ci95["material_scale"] == pytest.approx(slow.ci95["material_scale"], rel=1e-3)


def test_a_rung_with_loads_is_built_on_the_scaled_design():
    from softcath_ros.core.calibration_file import pressure_only

    assert pressure_only("surrogate") and pressure_only("section") and not pressure_only("rod")
    design = load_design("implemented_5mm")
    with pytest.raises(ValueError, match="scaled design"):
        CalibratedModel(make_model("rod", design, source="closed_form"), 0.1, material_scale=1.2)
    cal = _calibration(design, scale=1.2)
    rod = build_model("rod", design, cal, source="closed_form")
    assert rod.factor == pytest.approx(0.8) and rod.inner.design.material.c1 == pytest.approx(1.2 * design.material.c1)
    assert build_model("closed_form", design, cal).factor == pytest.approx(0.8 / 1.2)
