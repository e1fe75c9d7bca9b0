"""The manual bench (characterise --rig manual) through its terminal, and imported CSV data."""
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
import yaml

from bench_sim_helpers import run_offline, write_recording
from softcath_ros import topics
from softcath_ros.bench.analysis import rows_from_recording
from softcath_ros.bench.blocking import BlockingForce
from softcath_ros.bench.manual import parse_entry
from softcath_ros.bench.protocol import expand_steps, load_protocol
from softcath_ros.bench import report as report_module
from softcath_ros.bench.session import STANDARD_GRAVITY
from softcath_ros.bench.sim_rig import RigParams, SimulatedRig
from softcath_ros.cli import main
from softcath_ros.core.models import make_model
from softcath_ros.recording.reader import iter_messages, read_metadata

SOFTCATH = [sys.executable, "-m", "softcath_ros.cli"]
TARE_G = 3.0


def typed_readings(design, steps):
    """What an operator would type off a closed-form actuator: degrees to 0.5, grams to 0.01."""
    model = make_model("closed_form", design)
    force = BlockingForce(model)
    out = []
    for s in steps:
        k = model.evaluate(np.asarray(s.pressures)).curvature
        if s.bench == "angle":
            out.append(round(math.degrees(float(np.hypot(*k)) * s.sample.length) * 2) / 2)
        else:
            out.append(round(TARE_G + force.from_curvature(k, s.sample.length) * 1e3 / STANDARD_GRAVITY, 2))
    return out


def report_form(text: str) -> list[str]:
    """The report's shape: headings, info keys, table heads, and per table row its first three cells."""
    form = []
    for line in text.splitlines():
        if line.startswith("#") or line.startswith("|---"):
            form.append(line)
        elif line.startswith("- **"):
            form.append(line.split("**")[1])
        elif line.startswith("| drive") or line.startswith("| bench"):
            form.append(line)
        elif line.startswith("| "):
            form.append("|".join(line.split("|")[:4]))
    return [f for f in form if f not in ("note",)]  # the simulated report adds a note that it is simulated


def test_entries_are_parsed_and_bad_ones_refused():
    mp = 35000.0
    assert parse_entry("12.5", "angle", mp).values == (12.5,)
    e = parse_entry(" 7 @ 0.2 ", "force", mp)
    assert (e.kind, e.values, e.gauge_bar) == ("reading", (7.0,), 0.2)
    assert parse_entry("7 @ 20kPa", "force", mp).gauge_bar == pytest.approx(0.2)   # the one pressure rule
    assert parse_entry("12 12.5, 13 @0.1", "angle", mp).values == (12.0, 12.5, 13.0)
    assert [parse_entry(x, "angle", mp).kind for x in ("u", "s", "q", "?")] == ["undo", "skip", "quit", "help"]
    for text, bench, words in (("abc", "angle", "not a number"), ("361", "angle", "outside 0-360"),
                               ("-0.1", "angle", "outside 0-360"), ("-2", "force", "negative"),
                               ("nan", "force", "not a number"), ("", "angle", "empty"),
                               ("5 @ 0.5", "angle", "max_pressure"), ("5 @ x", "force", "not a pressure"),
                               ("12 400", "angle", "outside 0-360"), ("3 -1", "force", "negative"),
                               ("@ 0.1", "angle", "no reading")):
        msg = parse_entry(text, bench, mp)
        assert isinstance(msg, str) and words in msg, (text, msg)


def test_encoded_messages_equal_rclpy_serialisation():
    """Same length and same values as rclpy's bytes (rclpy leaves its padding bytes uninitialised)."""
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64, Float64MultiArray, String

    from softcath_ros.recording.encode import encode

    from geometry_msgs.msg import Vector3Stamped, WrenchStamped
    from sensor_msgs.msg import FluidPressure

    from softcath_ros.bench.session import message_fields

    for cls, type_name, fields in ((Float64, "std_msgs/msg/Float64", {"data": 0.125}),
                                   (Float64MultiArray, "std_msgs/msg/Float64MultiArray", {"data": [1.0, 2.5]}),
                                   (String, "std_msgs/msg/String", {"data": '{"a": 1}'})):
        ours = encode(type_name, fields)
        assert len(ours) == len(serialize_message(cls(**fields)))
        assert deserialize_message(ours, cls) == cls(**fields)
    # the stamped readings of the rig contract, as the manual bench writes them
    t_ns = 1_700_000_000_123_456_789
    for cls, type_name, value, read in (
            (FluidPressure, "sensor_msgs/msg/FluidPressure", 31000.0, lambda m: m.fluid_pressure),
            (Vector3Stamped, "geometry_msgs/msg/Vector3Stamped", 0.75, lambda m: m.vector.x),
            (WrenchStamped, "geometry_msgs/msg/WrenchStamped", 0.04, lambda m: m.wrench.force.z)):
        ours = encode(type_name, message_fields(type_name, value, t_ns))
        back = deserialize_message(ours, cls)
        assert read(back) == value and (back.header.stamp.sec, back.header.stamp.nanosec) == divmod(t_ns, 10**9)
        assert len(ours) == len(serialize_message(back))


def test_ninety_step_protocol_typed_through_stdin(tmp_path, monkeypatch, implemented_design):
    protocol = load_protocol("default")
    steps = expand_steps(protocol, 1, implemented_design.max_pressure)
    assert len(steps) == 90
    values = typed_readings(implemented_design, steps)
    lines = []
    for i, (s, v) in enumerate(zip(steps, values)):
        if i == 5:
            lines += ["twelve", "400" if s.bench == "angle" else "-1"]   # refused, asked again
        if i == 50:
            lines += ["-3", "zero"]                                        # force bench: refused twice
        if i == 20:
            lines += ["99", "u"]                                           # entered on step 21, undone below
        lines.append(f"{v:g}")
        if i == 30:
            lines += ["u", f"{v:g} @ {s.pressures[0] / 1e5 + 0.002:.3f}"]  # undone, re-entered with the gauge
        if i == 62:
            lines += ["u", f"{v:g} {v + 0.5:g} {v + 1:g}"]                  # re-entered as three readings
    stdin = "\n".join(lines) + "\n"
    proc = subprocess.run(SOFTCATH + ["characterise", "--rig", "manual", "--output-dir", str(tmp_path), "--json"],
                          input=stdin, capture_output=True, text=True, timeout=100)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    assert (out["outcome"], out["n_steps"], out["readings"], out["skipped"], out["refused"]) == \
        ("complete", 90, 90, 0, 4)
    assert proc.stderr.count("refused:") == 4 and proc.stderr.count("undone: step") == 3
    # Every entry is in the recording, in order, with the value typed (the undone ones retracted).
    angles = [m.message.vector.x for m in iter_messages(out["recording"], [topics.BENCH_BEND_ANGLE])]
    forces = [m.message.wrench.force.z for m in iter_messages(out["recording"], [topics.BENCH_WRENCH])]
    markers = [json.loads(m.message.data) for m in iter_messages(out["recording"], [topics.BENCH_STEP])]
    assert len(angles) + len(forces) == 90 + 3 + 2   # 90 + the three taken back + step 63's two more
    assert sum(e["event"] == "retract" for e in markers) == 3
    rows = rows_from_recording(out["recording"])
    # one reading per step (three for step 63), none of the undone ones left
    assert sorted(r.step for r in rows) == sorted(list(range(90)) + [62, 62])
    assert steps[62].bench == "force" and steps[60].bench == "force" and steps[60].level == 0   # its tare
    assert [r.force for r in rows if r.step == 62] == \
        pytest.approx([(values[62] + d - values[60]) * 1e-3 * STANDARD_GRAVITY for d in (0, 0.5, 1)], abs=1e-12)
    by_step = {r.step: r for r in rows}
    for s, v in zip(steps, values):
        r = by_step[s.index]
        if s.bench == "angle":
            assert r.angle == pytest.approx(math.radians(v), abs=1e-12)
        assert r.pressure[0] == pytest.approx(s.pressures[0] + (200.0 if s.index == 30 else 0.0), abs=1e-6)
    assert by_step[50].force == pytest.approx((values[50] - values[45]) * 1e-3 * STANDARD_GRAVITY, abs=1e-9)
    meta = read_metadata(out["recording"])
    assert meta["softcath"]["simulated"] == "false" and json.loads(meta["softcath"]["rig"])["kind"] == "manual"
    assert meta["softcath_result"]["complete"] == "true"
    # The report has the simulated report's form (the simulated one without drawing its plots again:
    # the manual run drew the same three).
    assert [Path(p).name for p in out["plots"]] == ["report_radius.png", "report_curvature.png", "report_force.png"]
    events, streams = run_offline(protocol, SimulatedRig(make_model("closed_form", implemented_design),
                                                         RigParams(seed=3)), dt=0.05)
    sim_bag = write_recording(tmp_path / "sim", events, streams, yaml.safe_dump(implemented_design.to_dict()))
    monkeypatch.setattr(report_module, "plot", lambda stats, out_dir, stem: [str(out_dir / Path(p).name)
                                                                               for p in out["plots"]])
    sim = report_module.write_report(sim_bag, implemented_design)
    manual_text = Path(out["report"]).read_text()
    assert report_form(manual_text) == report_form(Path(sim["report"]).read_text())


def _inherit_ignored_and_blocked_sigint():
    """What a shell script's background job (`cmd &`) or a parent that blocks SIGINT hands down."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


@pytest.mark.parametrize("how", ["interrupt", "interrupt_inherited_ignored", "kill"])
def test_entries_survive_ctrl_c_and_a_crash(tmp_path, how):
    """Ctrl-C finalises the recording (exit 130), also when characterise was started with SIGINT
    ignored and blocked (it restores the default); a crash leaves a recoverable file."""
    proc = subprocess.Popen(SOFTCATH + ["characterise", "--rig", "manual", "--protocol", "quick",
                                        "--output-dir", str(tmp_path)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_inherit_ignored_and_blocked_sigint if how.endswith("ignored") else None)
    for v in range(1, 8):
        proc.stdin.write(f"{v}\n")
    proc.stdin.flush()
    deadline = time.monotonic() + 30
    seen = ""
    while "[8/28]" not in seen and time.monotonic() < deadline:
        seen += os.read(proc.stdout.fileno(), 4096).decode()
    assert "[8/28]" in seen
    proc.send_signal(signal.SIGKILL if how == "kill" else signal.SIGINT)
    proc.communicate(timeout=20)
    bag = next(tmp_path.glob("bench_quick_manual_*"))
    mcap = next(bag.glob("*.mcap"))
    if how != "kill":
        assert proc.returncode == 130
        assert read_metadata(mcap)["softcath_result"]["complete"] == "false"
    else:
        assert proc.returncode == -signal.SIGKILL
        assert main(["recover", str(mcap)]) == 0
    rows = rows_from_recording(mcap)
    assert [round(math.degrees(r.angle)) for r in rows] == list(range(1, 8))


def test_import_csv_to_report_and_calibrate(tmp_path, implemented_design):
    protocol = load_protocol("quick")
    steps = expand_steps(protocol, 1, implemented_design.max_pressure)
    values = typed_readings(implemented_design, steps)
    lines = ["pressure_kpa,reading,unit,trial,phase,sample_length_mm,sample"]
    for s, v in zip(steps, values):
        unit = "deg" if s.bench == "angle" else "g"
        lines.append(f"{s.pressures[0] / 1e3:g},{v:g},{unit},{s.trial + 1},{s.phase},{s.sample.length * 1e3:g},"
                     f"{s.sample.name}")
        if s.bench == "angle" and s.level > 0:   # a second reading of the same step
            lines.append(lines[-1].replace(f",{v:g},", f",{v + 0.5:g},", 1))
    csv = tmp_path / "lab.csv"
    csv.write_text("\n".join(lines) + "\n")
    assert main(["import", str(csv), "--design", "implemented_5mm", "--output-dir", str(tmp_path), "--json",
                 "--no-report"]) == 0
    bag = tmp_path / "bench_imported_lab"
    rows = rows_from_recording(bag)
    n_angle_extra = sum(s.bench == "angle" and s.level > 0 for s in steps)
    assert len(rows) == len(steps) + n_angle_extra
    assert [r.force for r in rows if r.bench == "force" and r.level == 0 and r.phase == "loading"] == \
        pytest.approx([0.0] * protocol.trials, abs=1e-12)   # tared at 0 bar of each trial
    # calibrate (which writes the report, before and after) on the imported recording
    assert main(["calibrate", str(bag), "--model", "closed_form", "--output", str(tmp_path / "c.calibration.yaml")]) == 0
    assert "Blocking-force bench" in (bag / "report.md").read_text()
    assert yaml.safe_load((tmp_path / "c.calibration.yaml").read_text())["material_scale"] == \
        pytest.approx(1.0, abs=0.1)


def _small_csv(tmp_path) -> Path:
    csv = tmp_path / "lab.csv"
    csv.write_text("pressure_bar,reading,unit,trial,phase,sample_length_mm\n0,0,deg,1,loading,20\n"
                   "0.1,20,deg,1,loading,20\n0.2,45,deg,1,loading,20\n0.1,21,deg,1,unloading,20\n"
                   "0,0.5,deg,1,unloading,20\n")
    return csv


def test_import_names_its_design_and_overlays_what_report_overlays(tmp_path, capsys):
    """--design is required (the CSV does not say which design; a silent implemented_5mm was wrong for
    any other), the output names it, and its report overlays the same rungs as `softcath report`."""
    csv = _small_csv(tmp_path)
    assert main(["import", str(csv), "--output-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--design" in err[0] and "required" in err[0], err
    assert main(["import", str(csv), "--design", "implemented_5mm", "--output-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "design implemented_5mm" in out and "overlaid: surrogate, closed_form" in out, out
    bag = tmp_path / "bench_imported_lab"
    imported = (bag / "report.md").read_text()
    assert main(["report", str(bag), "--out", str(tmp_path / "again")]) == 0
    again = (tmp_path / "again" / "report.md").read_text()
    assert "**models overlaid**: surrogate, closed_form" in imported
    assert report_form(imported) == report_form(again)
    assert [x for x in imported.splitlines() if x.startswith("| ")] == \
        [x for x in again.splitlines() if x.startswith("| ")]   # the same overlay, number for number


def test_a_reimport_says_to_give_another_name(tmp_path, capsys):
    csv = _small_csv(tmp_path)
    base = ["import", str(csv), "--design", "implemented_5mm", "--output-dir", str(tmp_path), "--no-report"]
    assert main(base) == 0
    capsys.readouterr()
    assert main(base) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bench_imported_lab already exists" in err[0] and "--name" in err[0], err
    assert main([*base, "--name", "lab_again"]) == 0 and (tmp_path / "lab_again").is_dir()


@pytest.mark.parametrize("row, column, bad, words", [
    (3, "reading", "abc", "not a number"),
    (2, "unit", "furlong", "expected deg"),
    (4, "phase", "up", "loading or unloading"),
    (3, "trial", "0", "trial number"),
    (4, "pressure_bar", "0.9", "max_pressure"),
    (5, "reading", "-1", "negative"),
])
def test_import_errors_name_the_row_and_column(tmp_path, capsys, row, column, bad, words):
    header = ["pressure_bar", "reading", "unit", "trial", "phase", "sample_length_mm"]
    table = [["0", "0", "deg", "1", "loading", "20"], ["0.1", "5", "deg", "1", "loading", "20"],
             ["0.2", "11", "deg", "1", "loading", "20"], ["0", "3.1", "g", "1", "loading", "17"]]
    table[row - 2][header.index(column)] = bad
    csv = tmp_path / "bad.csv"
    csv.write_text("\n".join(",".join(r) for r in [header] + table) + "\n")
    assert main(["import", str(csv), "--design", "implemented_5mm", "--output-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"row {row}, column {column}:" in err and words in err, err


def test_report_compares_predicted_and_measured_tip_for_each_sample_length(tmp_path, implemented_design):
    """Synthesised: the 40 mm design on the quick protocol, whose angle sample is 20 mm long; a tracker
    reads that sample's tip 0.4 mm off in x (and 0.1 mm in z) from the closed form's tip of a 20 mm body
    at the step's commanded pressure. The report predicts each sample's own length, so every angle step
    is compared and the error is the offset."""
    from softcath_ros.core.prediction import predict
    from softcath_ros.recording.encode import encode, stamp

    model = make_model("closed_form", implemented_design)
    events, streams = run_offline(load_protocol("quick"), SimulatedRig(model, RigParams(seed=5)), dt=0.05)
    offset = np.array([0.4e-3, 0.0, 0.1e-3])
    pose_type = topics.MESSAGE_TYPES[topics.TIP_MEASURED]
    measured = []
    for t, ev in events:
        if ev["event"] == "sample" and ev["bench"] == "angle":
            assert ev["sample_length_m"] == 0.020 != implemented_design.length
            tip = predict(model, np.array([ev["pressure_cmd_pa"]]), 0.020)[0]
            msg = {"header": {"stamp": stamp(t - 1), "frame_id": topics.FRAME_ID},
                   "pose": {"position": dict(zip("xyz", map(float, np.array(tip.tip_position_m) + offset))),
                            "orientation": dict(zip("xyzw", map(float, tip.tip_orientation_xyzw)))}}
            measured.append((t - 1, encode(pose_type, msg)))
    path = write_recording(tmp_path / "tips", events, streams, yaml.safe_dump(implemented_design.to_dict()),
                           extra={topics.TIP_MEASURED: measured})
    result = report_module.write_report(path, implemented_design, ["closed_form"])
    tips = result["tips"]
    angle_levels = {(s.phase, s.level) for s in result["stats"] if s.bench == "angle"}
    assert {(s.phase, s.level) for s in tips} == angle_levels and not result["tips_skipped"]
    for s in tips:
        assert s.length == 0.020 and s.error_mean == pytest.approx(np.linalg.norm(offset), rel=1e-6)
        np.testing.assert_allclose(s.measured - s.predicted, offset, atol=1e-9)
    top = max(tips, key=lambda s: s.level)
    assert np.linalg.norm(top.predicted) < 0.025 and np.hypot(*top.predicted[:2]) > 1e-3   # the bent 20 mm tip
    text = Path(result["report"]).read_text()
    assert "## Tip position: predicted against measured" in text and "| 20 |" in text and "| 0.41 | 0.41 |" in text
    assert "Not compared" not in text
