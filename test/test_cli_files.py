"""`softcath report`, `calibrate` and `recover` on damaged recordings, bad calibrations and
unwritable outputs; names that would become paths outside their folder. Every fault is one line
on stderr and exit 2, in-process (cli.main)."""
import io
import re
from contextlib import redirect_stderr, redirect_stdout

import pytest
import yaml

pytest.importorskip("rclpy", reason="the recording helper serialises ROS messages")

from bench_sim_helpers import run_offline, write_recording  # noqa: E402
from softcath_ros.bench.protocol import ProtocolError, load_protocol, protocol_from_dict  # noqa: E402
from softcath_ros.bench.sim_rig import SimulatedRig  # noqa: E402
from softcath_ros.cli import main  # noqa: E402
from softcath_ros.core.design import design_from_dict  # noqa: E402
from softcath_ros.core.errors import DesignError  # noqa: E402
from softcath_ros.core.models import make_model  # noqa: E402
from softcath_ros.core.yaml_io import load_yaml_file  # noqa: E402
from softcath_ros.resources import find  # noqa: E402


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from softcath_ros.core.design import load_design

    design = load_design("implemented_5mm")
    events, streams = run_offline(load_protocol("quick"), SimulatedRig(make_model("closed_form", design)))
    return write_recording(tmp_path_factory.mktemp("rec") / "bench_quick", events, streams,
                           yaml.safe_dump(design.to_dict()))


def cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


def assert_one_line_exit_2(result, *words):
    code, err = result
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err


@pytest.mark.parametrize("fraction", [0.3, 0.6, 0.9])
@pytest.mark.parametrize("command", ["report", "calibrate"])
def test_truncated_recording_is_one_line_that_points_to_recover(tmp_path, recording, command, fraction):
    data = recording.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:int(len(data) * fraction)])
    assert_one_line_exit_2(cli(command, cut, "--design", "implemented_5mm"), "recover")


def test_bad_calibrations_are_one_line(tmp_path, recording):
    missing = tmp_path / "missing.calibration.yaml"
    assert_one_line_exit_2(cli("report", recording, "--calibration", missing, "--out", tmp_path / "r"), "no such file")
    good = tmp_path / "good.calibration.yaml"
    assert cli("calibrate", recording, "--model", "closed_form", "--output", good)[0] == 0
    fields = yaml.safe_load(good.read_text())
    for text, words in [("rung: [", "not valid YAML"), ("- 1\n", "a mapping"), ("\xff\xfe", "not UTF-8"),
                        (yaml.safe_dump({**fields, "material_scale": float("nan")}), "'material_scale'"),
                        (yaml.safe_dump({**fields, "pressure_shift": 1.5}), "'pressure_shift'"),
                        (yaml.safe_dump({**fields, "design_hash": "0" * 16}), "another design"),
                        (yaml.safe_dump({**fields, "covariance": [[1, 2], [3]]}), "'covariance'")]:
        bad = tmp_path / "bad.calibration.yaml"
        bad.write_bytes(text.encode("latin-1") if text.startswith("\xff") else text.encode())
        assert_one_line_exit_2(cli("report", recording, "--calibration", bad, "--out", tmp_path / "r"), words)


def test_unwritable_outputs_are_one_line(tmp_path, recording):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    assert_one_line_exit_2(cli("report", recording, "--out", a_file / "sub"))
    assert_one_line_exit_2(cli("calibrate", recording, "--output", a_file / "sub" / "d.yaml"))
    assert_one_line_exit_2(cli("recover", recording, "--output", tmp_path / "missing" / "r.mcap"), "does not exist")
    assert_one_line_exit_2(cli("calibrate", recording, "--model", "closed_form", "--output", tmp_path), "a folder")
    assert_one_line_exit_2(cli("sweep", "--design", "implemented_5mm", "--to", "1000Pa", "--no-plot",
                               "--out", a_file / "sub" / "s"))


def test_report_and_calibrate_still_work_on_the_good_recording(tmp_path, recording):
    cal = tmp_path / "cal.calibration.yaml"
    code, err = cli("calibrate", recording, "--model", "closed_form", "--output", cal)
    assert code == 0, err
    code, err = cli("report", recording, "--calibration", cal, "--out", tmp_path / "report")
    assert code == 0 and (tmp_path / "report" / "report.md").is_file(), err


@pytest.mark.parametrize("name", ["../../ESCAPED", "x/../../../ESCAPED", "a/b", "..", ".hidden", "", "a" * 101,
                                  "name with space", "c:\\x"])
def test_names_that_become_paths_are_refused(name):
    design = load_yaml_file(find("design", "implemented_5mm"))
    with pytest.raises(DesignError, match="'name'"):
        design_from_dict({**design, "name": name})
    protocol = load_yaml_file(find("protocol", "default"))
    with pytest.raises(ProtocolError, match="'name'"):
        protocol_from_dict({**protocol, "name": name})


@pytest.mark.parametrize("patch, field", [
    ({"channels": 5}, "channels"), ({"directions_deg": ["abc"], "drive": "direction"}, "directions_deg"),
    ({"benches": [{"kind": "angle", "samples": [5]}]}, "benches[0].samples[0]"),
    ({"staircase": {"max": 35000.0, "step": 1.0}}, "staircase.step"), ({"trials": 1e8}, "trials"),
    ({"trials": 100, "samples_per_step": 1000, "staircase": {"max": 35000.0, "step": 100.0}}, "protocol"),
    ({"staircase": {"max": 35000.0, "step": 5000.0, "down": "yes"}}, "staircase.down"),
    ({"settle": {"timeout": 1e9}}, "settle.timeout"), ({"settle": [1]}, "settle"),
])
def test_protocol_types_and_size_are_checked(patch, field):
    protocol = load_yaml_file(find("protocol", "default"))
    with pytest.raises(ProtocolError, match=re.escape(f"'{field}")) as e:
        protocol_from_dict({**protocol, **patch})
    assert "\n" not in str(e.value)


def test_a_recording_read_as_another_design_is_one_line_and_writes_nothing(tmp_path, recording):
    """A one-channel recording with a three-channel design named: report and calibrate refuse it before
    a rung sees the readings; no report folder, no calibration file."""
    assert_one_line_exit_2(cli("report", recording, "--design", "three_channel_5mm", "--model", "closed_form",
                               "--out", tmp_path / "r"), "carry 1 channel pressure(s); design 'three_channel_5mm' has 3")
    assert_one_line_exit_2(cli("calibrate", recording, "--design", "three_channel_5mm", "--model", "closed_form",
                               "--output", tmp_path / "c.calibration.yaml"), "name the design it recorded")
    assert not (tmp_path / "r").exists() and not (tmp_path / "c.calibration.yaml").exists()
