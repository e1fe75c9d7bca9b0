"""Inputs a user gets wrong: unit slips in design files, pressures above the limit, exit codes that
agree between predict and sweep, --no-cache wherever a command reads the cache, the documented
report command on a runs/ folder."""
import math
import os
import time

import numpy as np
import pytest

from softcath_ros.cli import build_parser, main
from softcath_ros.core.design import design_from_dict
from softcath_ros.core.errors import DesignError
from softcath_ros.core.models import RUNGS, BendModel, BendState, RungInfo


@pytest.mark.parametrize("path, value, fragment", [
    (("outer_diameter",), 4, "4 m outer_diameter is implausible: design files are in metres; 0.004?"),
    (("length",), 40, "40 m length is implausible: design files are in metres; 0.04?"),
    (("limits", "max_pressure"), 0.5, "0.5 Pa limits.max_pressure is implausible: design files are in pascals; "
                                      "50000 (0.5 bar)?"),
    (("limits", "max_pressure"), 50, "50000 (50 kPa)?"),
    (("limits", "max_pressure"), 5e7, "implausible"),
    (("material", "c1"), 12.7, "12.7 Pa material.c1 is implausible: design files are in pascals; 12700 (12.7 kPa)?"),
    (("cap_thickness",), 1.0, "1 m cap_thickness is implausible"),
])
def test_unit_slips_in_a_design_file_are_refused_with_the_likely_value(design_dict, path, value, fragment):
    d = design_dict
    for key in path[:-1]:
        d = d[key]
    d[path[-1]] = value
    with pytest.raises(DesignError) as exc:
        design_from_dict(design_dict)
    assert fragment in str(exc.value) and exc.value.field == ".".join(path)


def test_channel_diameter_in_millimetres_is_refused_as_a_slip(design_dict):
    design_dict["channels"][0]["diameter"] = 1.7
    with pytest.raises(DesignError, match=r"channels\[0\].diameter.*in metres; 0.0017\?"):
        design_from_dict(design_dict)


@pytest.mark.parametrize("command", [
    ["predict", "--design", "implemented_5mm", "--pressure", "0.2", "0.6", "--unit", "bar"],
    ["sweep", "--design", "implemented_5mm", "--to", "0.6", "--unit", "bar", "--no-plot"],
    ["predict", "--design", "implemented_5mm", "--pressure", "60kPa"],
])
def test_pressures_above_max_pressure_are_refused_by_predict_and_sweep(command, capsys, tmp_path):
    if command[0] == "sweep":
        command += ["--out", str(tmp_path / "s")]
    assert main(command) == 2
    err = capsys.readouterr().err.strip()
    assert "exceeds design 'implemented_5mm' max_pressure 50000 Pa (0.5 bar)" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "s.json").exists()


class HalfFailingRung(BendModel):
    """Converges below 20 kPa only (for exit codes without a slow solver)."""

    name = "half_failing"
    info = RungInfo(summary="test rung")

    def _evaluate_batch(self, pressures):
        n = len(pressures)
        ok = pressures.max(axis=1) < 20000.0
        return BendState(np.column_stack([np.zeros(n), -pressures[:, 0] * 1e-3]), np.ones(n), ok,
                         message="" if ok.all() else "toy limit at 20 kPa")


@pytest.fixture
def half_failing(monkeypatch):
    monkeypatch.setitem(RUNGS, "half_failing", "test_inputs:HalfFailingRung")


def test_predict_and_sweep_agree_on_exit_codes(half_failing, capsys, tmp_path):
    import json

    base = ["--design", "implemented_5mm", "--model", "half_failing"]
    assert main(["predict", *base, "--pressure", "0.1", "--unit", "bar", "--json"]) == 0
    assert main(["predict", *base, "--pressure", "0.1", "0.3", "--unit", "bar", "--json"]) == 1
    capsys.readouterr()
    assert main(["predict", *base, "--pressure", "0.1", "0.3", "--unit", "bar", "--json"]) == 1
    printed = json.loads(capsys.readouterr().out)        # the JSON is still printed
    assert [r["converged"] for r in printed["results"]] == [True, False]
    assert main(["sweep", *base, "--to", "0.15", "--unit", "bar", "--steps", "3", "--no-plot",
                 "--out", str(tmp_path / "a")]) == 0
    assert main(["sweep", *base, "--to", "0.3", "--unit", "bar", "--steps", "3", "--no-plot",
                 "--out", str(tmp_path / "b")]) == 1
    assert (tmp_path / "b.json").is_file()
    assert main(["sweep", *base, "--to", "0.3", "--unit", "bar", "--steps", "1"]) == 2


def _subparsers():
    return build_parser().subcommands


@pytest.mark.parametrize("command", ["predict", "sweep", "allocate", "report", "calibrate", "characterise",
                                     "study", "envelope"])
def test_every_command_that_reads_the_cache_has_no_cache(command):
    options = {o for a in _subparsers()[command]._actions for o in a.option_strings}
    assert "--no-cache" in options


def test_no_cache_reaches_the_rung(monkeypatch, capsys):
    """predict --no-cache builds a caching rung with cache=False (the section rung declares it)."""
    import softcath_ros.core.calibration_file as cf

    seen = {}
    real = cf.make_model

    def spy(name, design, **options):
        seen.update(options)
        return real("closed_form", design)

    monkeypatch.setattr(cf, "make_model", spy)
    assert main(["predict", "--design", "implemented_5mm", "--model", "section", "--pressure", "1000Pa",
                 "--no-cache"]) == 0
    assert seen == {"cache": False}


def test_documented_report_glob_matches_recordings_only(tmp_path, monkeypatch, capsys):
    """`softcath report runs/bench_default_*/` (docs/bench.md): characterise keeps its logs out of that glob, and
    several matching runs mean the newest; no argument means the newest under runs/."""
    import yaml

    from bench_sim_helpers import run_offline, write_recording
    from softcath_ros.bench.protocol import load_protocol
    from softcath_ros.bench.sim_rig import RigParams, SimulatedRig
    from softcath_ros.cli import characterise
    from softcath_ros.core.design import load_design
    from softcath_ros.core.models import make_model

    src = open(characterise.__file__).read()
    assert 'out_dir / "logs" / name' in src and '_logs"' not in src
    design = load_design("implemented_5mm")
    events, streams = run_offline(load_protocol("quick"), SimulatedRig(make_model("closed_form", design),
                                                                       RigParams(seed=1)))
    monkeypatch.chdir(tmp_path)
    runs = tmp_path / "runs"
    for i, name in enumerate(("bench_default_20261201_100000", "bench_default_20261201_110000")):
        write_recording(runs / name, events, streams, yaml.safe_dump(design.to_dict()))
        os.utime(runs / name, (time.time() + i, time.time() + i))
    (runs / "logs" / "bench_default_20261201_110000").mkdir(parents=True)
    matched = sorted(str(p) + "/" for p in runs.glob("bench_default_*/"))
    assert len(matched) == 2
    # a logs folder of the old layout beside them, written last, is passed over
    (runs / "bench_default_20261201_110000_logs").mkdir()
    (runs / "bench_default_20261201_110000_logs" / "bench_node.log").write_text("log")
    matched = sorted(str(p) + "/" for p in runs.glob("bench_default_*/"))
    assert len(matched) == 3
    assert main(["report", *matched]) == 0
    out = capsys.readouterr()
    assert "newest of 2" in out.err and "bench_default_20261201_110000" in out.err
    assert (runs / "bench_default_20261201_110000" / "report.md").is_file()
    assert main(["report"]) == 0
    assert "bench_default_20261201_110000" in capsys.readouterr().err


def test_pressure_sweep_table_reports_r_c_as_l_over_theta():
    """The tool's table (tools/pressure_sweep.py) reads R_C = l / theta off the tip pose, 1/|k| apart."""
    import io

    from softcath_ros.core.kinematics import tip_pose
    from softcath_ros.tools.pressure_sweep import SweepPoint, print_table

    k, length, stretch = np.array([0.0, -30.0]), 0.04, 1.1
    pos, quat = tip_pose(k[None, :], np.array([length * stretch]))
    point = SweepPoint([20000.0], pos[0].tolist(), quat[0].tolist(), [], 0)
    out = io.StringIO()
    print_table([point], [[20000.0]], length, file=out)
    cells = out.getvalue().splitlines()[1].split()
    theta = 30.0 * length * stretch
    assert float(cells[1]) == pytest.approx(length / theta * 1e3, abs=0.006)   # printed to 0.01 mm
    assert float(cells[2]) == pytest.approx(1e3 / 30.0, abs=0.006)
    # past 180 degrees the angle is the received backbone's integrated tangent angle, not the tip's folded one
    from softcath_ros.core.kinematics import backbone_poses

    k = np.array([0.0, -math.radians(283.0) / (length * stretch)])
    pos, quat = backbone_poses(k, length * stretch, 20)
    point = SweepPoint([25000.0], pos[-1].tolist(), quat[-1].tolist(), pos.tolist(), 0, quat.tolist())
    out = io.StringIO()
    print_table([point], [[25000.0]], length, file=out)
    cells = out.getvalue().splitlines()[1].split()
    assert float(cells[3]) == pytest.approx(283.0, abs=0.006)
    assert float(cells[1]) == pytest.approx(length / math.radians(283.0) * 1e3, abs=0.006)


def test_wrong_inputs_on_every_command_are_one_line_exit_2(tmp_path, capsys):
    """The CLI audit's cases (in-process, each refused before any solve, node or build starts): a unit
    slip in --length or --max-pressure, limits above the design's, unbounded sizes and durations, an
    unknown rung named where nodes would start, files that are not text, outputs under a file.
    Nothing is written where the command was refused."""
    import yaml

    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"\x89PNG\xff\xfe\x00")
    chart_csv = tmp_path / "chart.csv"
    head = ("case,family,setting,reference,converged,fails_beyond,pressure_pa,s_per_eval,boundary_pa,rc_rel_error,"
            "tip_error_mm,direction_error_deg,length_m,rc_m")
    chart_csv.write_text(head + "\n1ch,1ch,rod,fe3d,True,False,abc,1,1,1,1,1,0.04,0.1\n")
    cal = {"design": "implemented_5mm", "design_hash": "0" * 16, "rung": "no_such_rung", "pressure_shift": 0.1,
           "material_scale": 1.0, "covariance": [[0, 0], [0, 0]], "rms_before": 1.0, "rms_after": 1.0,
           "n_residuals": 2, "recording": "r.mcap", "recording_sha256": "0", "date": "2026-12-01", "schema": 2}
    bad_rung = tmp_path / "bad_rung.calibration.yaml"
    bad_rung.write_text(yaml.safe_dump(cal))
    from softcath_ros.core.yaml_io import load_yaml_file
    from softcath_ros.resources import find

    quick = load_yaml_file(find("protocol", "quick"))
    above, in_bar = tmp_path / "above.yaml", tmp_path / "in_bar.yaml"
    above.write_text(yaml.safe_dump({**quick, "staircase": {"max": 60000.0, "step": 10000.0}}))
    in_bar.write_text(yaml.safe_dump({**quick, "staircase": {"levels": [0.0, 0.1, 0.2, 0.3]}}))
    predict = ["predict", "--design", "implemented_5mm", "--model", "closed_form", "--pressure", "1000Pa"]
    out = tmp_path / "out"
    cases = [
        (predict + ["--length", "40"], "--length 40: 40 m length is implausible"),
        (predict + ["--length", "1e-12"], "below 1 mm"),
        (["predict", "--design", "implemented_5mm", "--model", "auto", "--scene", "blocking_force_bench",
          "--pressure", "1000Pa", "--length", "0.03"], "scene 'blocking_force_bench' sets the length (0.017 m)"),
        (["sweep", "--design", "implemented_5mm", "--model", "closed_form", "--to", "1000Pa", "--length", "40",
          "--no-plot", "--out", str(out / "s")], "--length 40"),
        (["predict", "--design", "implemented_5mm", "--model", "rod", "--option", "source=closed_form",
          "--option", "n_segments=100000000", "--pressure", "1000Pa"], "n_segments 100000000 must lie in [4, 1000]"),
        (predict + ["--calibration", str(tmp_path)], "a folder, not a calibration file"),
        (predict + ["--calibration", str(bad_rung)], "field 'rung' = 'no_such_rung': not a rung"),
        (["allocate", "--design", "three_channel_5mm", "--model", "closed_form", "--curvature", "3,0",
          "--max-pressure", "0.3Pa"], "0.3 Pa is implausible (below 1000 Pa): it is in pascals; 30000 (0.3 bar)?"),
        (["allocate", "--design", "three_channel_5mm", "--model", "closed_form", "--curvature", "3,0",
          "--max-pressure", "0.3"], "--max-pressure 0.3: which unit? write 0.3bar, 0.3kPa or 0.3Pa"),
        (["steer-sim", "--max-pressure", "1e9Pa", "--output-dir", str(out)], "at most design 'three_sector_5mm''s"),
        (["steer-sim", "--max-pressure", "0.3", "--unit", "Pa", "--output-dir", str(out)], "in pascals"),
        (["steer-sim", "--max-pressure", "0.3", "--output-dir", str(out)], "--max-pressure 0.3: which unit?"),
        (["steer-sim", "--duration", "1e9", "--output-dir", str(out)], "at most 3600 s"),
        (["steer-sim", "--model", "bogus", "--output-dir", str(out)], "unknown model 'bogus'"),
        (["characterise", "--model", "bogus", "--output-dir", str(out)], "unknown model 'bogus'"),
        (["characterise", "--sim-model", "bogus", "--output-dir", str(out)], "unknown model 'bogus'"),
        (["characterise", "--wait-timeout", "-1", "--output-dir", str(out)], "must lie in [0.1, 3600]"),
        (["characterise", "--timeout", "nan", "--output-dir", str(out)], "must be a finite number"),
        (["characterise", "--protocol", str(above), "--output-dir", str(out)], "outside [0, max_pressure 50000]"),
        (["characterise", "--protocol", str(in_bar), "--output-dir", str(out)], "0.3 Pa is implausible"),
        (["envelope", "--refresh", "bogus", "--out", str(out / "e.yaml")], "--refresh: unknown rung(s) ['bogus']"),
        (["envelope", "--cases", "1ch 40mm", "--out", str(tmp_path)], "a folder; name the envelope file"),
        (["envelope", "--cases", "1ch 40mm", "--out", str(tmp_path / "e.yaml"), "--results", str(out / "x" / "r")],
         "does not exist"),
        (["import", str(binary), "--design", "implemented_5mm", "--output-dir", str(out)], "not a CSV text file (not UTF-8 at byte 0)"),
        (["chart", "--csv", str(binary)], "not a CSV text file"),
        (["chart", "--csv", str(chart_csv), "--out", str(out / "c.png")], "row 2: pressure_pa = 'abc' is not a number"),
        (["study", "sensitivity", "--design", "implemented_5mm", "--model", "closed_form", "--out",
          str(a_file / "s")], "Not a directory"),
        (["surrogate", "build", "implemented_5mm", "--option", "source=bogus"], "unknown model 'bogus'"),
        (["surrogate", "build", "implemented_5mm", "--workers", "0"], "must lie in [1, 256]"),
        (["surrogate", "build", "implemented_5mm", "--option", "source=closed_form", "--out",
          str(a_file / "t.npz")], str(a_file)),
    ]
    for argv, words in cases:
        code = main(argv)
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err and words in err, (argv, err)
    assert not out.exists()   # refused before anything was written


@pytest.mark.parametrize("rig", ["sim", "ros"])
def test_a_direction_protocol_passes_characterise_checks_to_the_graph(rig, monkeypatch):
    """README: `softcath characterise --protocol three_channel_directions` (and `--rig ros`) was refused
    before any node started ("needs the allocator"). Its steps are allocated as bench_node allocates
    them, and the graph gets the protocol's 2-DOF design (the graph itself: test_bench_nodes.py)."""
    from softcath_ros.cli import characterise

    handed = []
    monkeypatch.setitem(characterise.RIGS, rig, characterise.RigChoice(
        "stand-in", lambda args, protocol, design: handed.append((protocol.drive, design.name)) or 0))
    args = ["characterise", "--protocol", "three_channel_directions"] + (["--rig", rig] if rig != "sim" else [])
    assert main(args) == 0
    assert handed == [("direction", "three_sector_5mm")]


def test_a_direction_protocol_beyond_the_design_is_refused_in_one_line(capsys):
    """A 1-channel design cannot bend in the protocol's directions: one line, exit 2, before any node."""
    code = main(["characterise", "--protocol", "three_channel_directions", "--design", "implemented_5mm"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "directions_deg" in err, err
