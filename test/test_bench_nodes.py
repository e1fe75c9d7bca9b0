"""bench_node + sim_bench_node as separate processes: a short protocol end to end, SIGINT, bad paths."""
import json
import re
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader

from bench_procs import procs, start as _start, summary as _summary  # noqa: F401 (procs: fixture)
from domains import private_env
from softcath_ros import topics
from softcath_ros.graph import wait_output
from softcath_ros.graph import graph_env
from softcath_ros.recording.reader import read_metadata

pytestmark = [pytest.mark.ros, pytest.mark.slow]

RUN_TIMEOUT_S = 180  # a protocol of ~20 s: generous for a loaded machine


def _env():
    return private_env()


def test_quick_protocol_records_a_simulated_run(tmp_path, procs):
    env = _env()
    _start(procs, ["sim_bench_node"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                           "-p", "name:=run"], env)
    out, _ = bench.communicate(timeout=RUN_TIMEOUT_S)
    assert bench.returncode == 0, out
    s = _summary(out)
    assert s["state"] == "done" and s["dropped"] == 0 and s["unsettled_steps"] == []
    path = tmp_path / "run" / "run_0.mcap"
    assert s["recording"] == str(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        names = {a.name for a in reader.iter_attachments()}
    assert meta["softcath"]["simulated"] == "true" and meta["softcath"]["protocol"] == "quick"
    assert yaml.safe_load(meta["rosbag2"]["serialized_metadata"])["custom_data"]["simulated"] == "true"
    assert names == {"protocol.yaml", "design.yaml"}
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts[topics.BENCH_STEP] == 2 + 28 * (3 + 2)  # start/end + per step: start, settled, end, samples
    assert counts[topics.pressure_measured_topic(0)] > 200 and counts[topics.PRESSURE_CMD] > 100
    for c in summary.channels.values():
        assert c.message_encoding == "cdr" and yaml.safe_load(c.metadata["offered_qos_profiles"])
    from softcath_ros.bench.report import write_report
    rep = write_report(path, out_dir=tmp_path / "report")
    assert len(rep["rows"]) == 28 * 2
    top = [st for st in rep["stats"] if st.bench == "angle" and st.level == 30000.0][0]
    assert top.curvature_mean > 0 and top.radius_mean < top.model["closed_form"]["radius"] * 2


def test_sigint_finalises_the_recording(tmp_path, procs):
    env = _env()
    _start(procs, ["sim_bench_node"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=default", "-p",
                           f"output_dir:={tmp_path}", "-p", "name:=cut"], env)
    path = tmp_path / "cut" / "cut_0.mcap"
    # An event, not a file size or a time: the protocol has started (after a start delay in which
    # the recorder already took the rig's readings), so the recording holds messages by then.
    before = wait_output(bench, timeout_s=120, mark="starting protocol")
    bench.send_signal(signal.SIGINT)
    out = before + bench.communicate(timeout=60)[0]
    assert bench.returncode == 130 and _summary(out)["state"] == "interrupted"
    assert _summary(out)["messages"] > 0
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()  # a finished file: summary section present
    assert summary is not None and summary.statistics.message_count == _summary(out)["messages"]


def test_unwritable_output_fails_at_start_with_a_clear_message(tmp_path, procs):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p",
                           f"output_dir:={blocker}/sub"], _env())
    out, _ = bench.communicate(timeout=60)
    assert bench.returncode == 2
    assert "cannot create recording directory" in out


def test_direction_protocol_runs_through_allocation_node(tmp_path, procs):
    """bench_node sends /softcath/bend_cmd, allocation_node (the only pressure_cmd publisher) turns it
    into pressures, the simulated three-channel rig follows: the top step bends towards the direction."""
    import numpy as np

    from softcath_ros.bench.analysis import rows_from_recording
    from softcath_ros.core.allocation import Allocator
    from softcath_ros.core.design import load_design
    from softcath_ros.core.models import make_model

    protocol = tmp_path / "dir.yaml"
    protocol.write_text(yaml.safe_dump({
        "name": "dir_test", "design": "three_channel_5mm", "drive": "direction", "directions_deg": [60.0],
        "staircase": {"levels": [0.0, 0.5, 1.0], "down": True}, "trials": 1, "dwell": 0.2,
        "settle": {"tolerance": 1000.0, "max_offset": 3000.0, "hold": 0.1, "timeout": 3.0},
        "samples_per_step": 2, "sample_period": 0.03,
        "benches": [{"kind": "angle", "samples": [{"name": "a", "length": 0.02}]}]}))
    env = _env()
    _start(procs, ["sim_bench_node", "--ros-args", "-p", "design:=three_channel_5mm"], env)
    _start(procs, ["allocation_node", "--ros-args", "-p", "design:=three_channel_5mm"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", f"protocol:={protocol}", "-p",
                           f"output_dir:={tmp_path}", "-p", "name:=dir"], env)
    out, _ = bench.communicate(timeout=RUN_TIMEOUT_S)
    assert bench.returncode == 0, out
    s = _summary(out)
    assert s["state"] == "done" and s["dropped"] == 0 and s["unsettled_steps"] == []
    assert s["per_topic"][topics.BEND_CMD] > 20 and s["per_topic"][topics.PRESSURE_CMD] > 20
    path = tmp_path / "dir" / "dir_0.mcap"
    from softcath_ros.recording.reader import iter_messages
    bends = [m.message for m in iter_messages(path, topics=[topics.BEND_CMD])]
    assert all(b.header.frame_id == topics.FRAME_ID for b in bends)
    top = max(bends, key=lambda b: np.hypot(b.vector.x, b.vector.y))
    assert np.degrees(np.arctan2(top.vector.y, top.vector.x)) == pytest.approx(60.0, abs=1e-6)
    expected = Allocator(make_model("surrogate", load_design("three_channel_5mm"))).allocate(   # the default rung
        (top.vector.x, top.vector.y)).pressures
    rows = [r for r in rows_from_recording(path) if r.level == 1.0]
    assert len(rows) == 2
    for r in rows:  # the rig reached what the allocator asks for (gauge error +-2 kPa)
        assert np.allclose(r.pressure, expected, atol=3000.0) and r.curvature > 1.0


def test_per_channel_protocol_refuses_a_second_pressure_publisher(tmp_path, procs):
    """allocation_node publishes /softcath/pressure_cmd too: a staircase would be fought, so no run."""
    env = _env()
    _start(procs, ["sim_bench_node"], env)
    _start(procs, ["allocation_node", "--ros-args", "-p", "design:=implemented_5mm"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                           "-p", "name:=fight"], env)
    out, _ = bench.communicate(timeout=RUN_TIMEOUT_S)
    assert bench.returncode == 4, out
    # Refused at the start, or stopped within a second if allocation_node appeared after it.
    assert f"/{topics.ALLOCATION_NODE}" in _summary(out)["error"] and topics.PRESSURE_CMD in _summary(out)["error"]
    assert (tmp_path / "fight" / "fight_0.mcap").is_file()  # the recording is still finalised


@pytest.mark.timeout(240)   # the whole main job on the quick protocol: about a minute, longer under load
def test_characterise_records_model_predictions_and_writes_the_report(tmp_path, procs):
    """README's `softcath characterise --protocol quick`, as written (in a fresh folder: runs/ lands
    there): the main job on the quick protocol, sim_bench_node, model_node, bench_node as processes."""
    argv = readme_command("softcath characterise --protocol quick")
    assert argv == ["softcath", "characterise", "--protocol", "quick"]
    run = _start(procs, argv, _env(), cwd=tmp_path)
    out, _ = run.communicate(timeout=RUN_TIMEOUT_S + 60)
    assert run.returncode == 0, out
    assert re.search(r"^\[characterise\] done[^:]*: \d+ messages recorded, 0 dropped$", out, re.M), out
    result = dict(line.split(":", 1) for line in out.splitlines() if line.startswith(("recording:", "report:")))
    result = {k: v.strip() for k, v in result.items()}
    assert Path(result["report"]).is_file()
    with open(result["recording"], "rb") as f:
        summary = make_reader(f).get_summary()
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts[topics.TIP_POSE] > 50 and counts[topics.BACKBONE] > 50
    assert counts[topics.PRESSURE_CMD] > 50 and topics.BEND_CMD not in counts  # no allocation_node
    text = Path(result["report"]).read_text()
    assert "## Hysteresis" in text
    # the rig's fresh seed is recorded and shown; the overlay says why it misses; the 20 mm sample's tips
    # are compared with the model's for 20 mm (not left out as "not the design's 40 mm")
    rig = json.loads(read_metadata(result["recording"])["softcath"]["rig"])["rig"]
    assert 0 <= rig["seed"] < 2**32 and f"seed {rig['seed']}," in text
    assert f"(1 − {rig['pressure_shift']:g}) × the true pressure" in text and "softcath calibrate" in text
    assert "| 20 |" in text.split("## Tip position")[1] and "Not compared" not in text
    # the logs stay out of the README's `softcath report runs/bench_quick_*/` glob
    run_dir = Path(result["recording"]).parent
    assert run_dir.parent == tmp_path / "runs" and [p.name for p in run_dir.parent.glob("bench_quick_*/")] == [run_dir.name]
    assert (tmp_path / "runs" / "logs" / run_dir.name / "bench_node.log").is_file()
    # The Foxglove layout opens this recording: every topic it names is here with its type.
    from layout_check import ONLY_WITH_A_TRACKER, check_recording
    assert check_recording(result["recording"]) <= ONLY_WITH_A_TRACKER
    assert counts[topics.BODY_MARKER] > 10 and counts[topics.BACKBONE_PATH] == counts[topics.BODY_MARKER]


def readme_command(prefix: str) -> list[str]:
    """The README line that starts with ``prefix``, as argv (its shell comment dropped)."""
    readme = Path(__file__).resolve().parents[1] / "README.md"
    for line in readme.read_text().splitlines():
        if line.startswith(prefix):
            return shlex.split(line, comments=True)
    raise AssertionError(f"README.md has no line starting {prefix!r}")


@pytest.mark.timeout(300)   # 54 steps: about 45 s on a quiet machine
def test_readme_direction_protocol_runs_through_the_cli_as_written(tmp_path, procs):
    """README Quick start: `softcath characterise --protocol three_channel_directions`, as written
    (in a fresh folder: runs/ lands there). The graph bends the 2-DOF design by direction through
    allocation_node, and each direction's curvature grows with its fraction of the reach."""
    from softcath_ros.bench.analysis import rows_from_recording

    argv = readme_command("softcath characterise --protocol three_channel_directions")
    assert argv == ["softcath", "characterise", "--protocol", "three_channel_directions"]
    run = _start(procs, argv, _env(), cwd=tmp_path)
    out, _ = run.communicate(timeout=RUN_TIMEOUT_S + 60)
    assert run.returncode == 0, out
    assert "allocation_node" in out
    recording = Path([x for x in out.splitlines() if x.startswith("recording: ")][-1].split(": ", 1)[1])
    assert recording.is_relative_to(tmp_path / "runs") and (recording.parent / "report.md").is_file()
    with open(recording, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts[topics.BEND_CMD] > 50 and counts[topics.PRESSURE_CMD] > 50
    rows = rows_from_recording(recording)
    assert {r.drive for r in rows} == {"direction 0 deg", "direction 60 deg", "direction 210 deg"}
    for drive in {r.drive for r in rows}:
        bend = {lv: np.mean([r.angle / r.length for r in rows if r.drive == drive and r.level == lv
                             and r.phase == "loading"]) for lv in (0.0, 0.5, 1.0)}
        assert abs(bend[0.0]) < 2.0 < bend[0.5] < bend[1.0], (drive, bend)


def test_a_domain_another_graph_uses_is_not_leased(procs):
    """Leases exclude each other (also across processes); with a probe, a domain on which a graph
    started by other means answers is skipped."""
    from softcath_ros.core.errors import SoftcathError
    from softcath_ros.graph import lease_domain

    with lease_domain() as held:
        with pytest.raises(SoftcathError, match="no free ROS_DOMAIN_ID"):
            lease_domain((held.domain, held.domain))
        other = subprocess.run([sys.executable, "-c", "from softcath_ros.graph import lease_domain; "
                                f"lease_domain(({held.domain}, {held.domain}))"], capture_output=True, text=True)
        assert other.returncode != 0 and "no free ROS_DOMAIN_ID" in other.stderr
        busy = held.domain
        sim = _start(procs, ["sim_bench_node"], graph_env(busy))
        assert "simulated bench" in sim.stdout.readline()  # its node is up
    with lease_domain((busy, busy)) as unprobed:          # the lock is free again ...
        assert unprobed.domain == busy
    with pytest.raises(SoftcathError, match="no free ROS_DOMAIN_ID"):
        lease_domain((busy, busy), probe_s=60.0)          # ... but the probe sees sim_bench_node (when discovered)
