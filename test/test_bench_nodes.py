"""bench_node + sim_bench_node as separate processes: a short protocol end to end, SIGINT, bad paths."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader

pytestmark = [pytest.mark.ros, pytest.mark.slow]

VENV_BIN = Path(sys.executable).parent
DOMAINS = iter(range(181, 190))  # this file's ROS_DOMAIN_IDs


def _env():
    env = dict(os.environ, ROS_DOMAIN_ID=str(next(DOMAINS)), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1")
    return env


@pytest.fixture
def procs():
    started = []
    yield started
    for p in started:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=10)


def _start(procs, args, env, **kw):
    p = subprocess.Popen([str(VENV_BIN / args[0]), *args[1:]], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, **kw)
    procs.append(p)
    return p


def _summary(output: str) -> dict:
    line = [x for x in output.splitlines() if x.startswith("summary: ")][-1]
    return json.loads(line[len("summary: "):])


def test_quick_protocol_records_a_simulated_run(tmp_path, procs):
    env = _env()
    _start(procs, ["sim_bench_node"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                           "-p", "name:=run"], env)
    out, _ = bench.communicate(timeout=90)
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
    assert counts["/softcath/bench/step"] == 2 + 28 * (3 + 2)  # start/end + per step: start, settled, end, samples
    assert counts["/softcath/pressure_measured"] > 200 and counts["/softcath/pressure_cmd"] > 100
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
    deadline = time.time() + 40
    while time.time() < deadline and (not path.exists() or path.stat().st_size < 20000):
        time.sleep(0.2)
    bench.send_signal(signal.SIGINT)
    out, _ = bench.communicate(timeout=20)
    assert _summary(out)["state"] == "interrupted"
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()  # a finished file: summary section present
    assert summary is not None and summary.statistics.message_count == _summary(out)["messages"]


def test_unwritable_output_fails_at_start_with_a_clear_message(tmp_path, procs):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p",
                           f"output_dir:={blocker}/sub"], _env())
    out, _ = bench.communicate(timeout=30)
    assert bench.returncode == 2
    assert "cannot create recording directory" in out
