"""Faults of a bench run with the nodes as processes (docs/rig.md): the rig killed at a random
step, allocation_node killed during a direction protocol, SIGTERM to `softcath characterise`, a
disk that fills up mid-run, a rig that is not there, and `characterise --rig ros` on a rig
started by hand."""
import json
import os
import random
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from bench_procs import procs, start as _start, summary as _summary  # noqa: F401 (procs: fixture)
from domains import private_env
from softcath_ros import topics
from softcath_ros.graph import wait_output

pytestmark = [pytest.mark.ros, pytest.mark.slow]

# The contract is a stop within 2 s of the rig's death on a quiet machine: benchmarks/rig_kill.py
# measures it. Here the bench must stop by itself (its own staleness check, not the test's timeout);
# a loaded machine may stretch the stop, so the bound is the test's patience, not the target.
STOP_BY_ITSELF_S = 20.0


def _markers(path):
    from softcath_ros.recording.reader import iter_messages

    return [json.loads(m.message.data) for m in iter_messages(path, topics=[topics.BENCH_STEP])]


def _log_stamp(line: str) -> float:
    """The time (s since the epoch) of a ROS log line ``[LEVEL] [1765000000.123456789] [node]: ...``."""
    return float(line.split("] [", 2)[1])


def _kill_and_time(victim, bench):
    victim.send_signal(signal.SIGKILL)
    t0 = time.monotonic()
    out = bench.communicate(timeout=30)[0]
    return out, time.monotonic() - t0


def test_rig_killed_at_a_random_step_stops_the_bench_and_keeps_every_completed_step(tmp_path, procs):
    from softcath_ros.bench.analysis import rows_from_recording
    from softcath_ros.bench.calibration import calibrate
    from softcath_ros.bench.report import write_report
    from softcath_ros.core.design import load_design
    from softcath_ros.recording.reader import read_metadata

    delay = random.Random().uniform(0.3, 4.0)   # a random step of the quick protocol (~8 s of steps)
    env = private_env()
    rig = _start(procs, ["sim_bench_node"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                           "-p", "name:=killed"], env)
    before = wait_output(bench, timeout_s=120, mark="starting protocol")
    time.sleep(delay)
    rest, took = _kill_and_time(rig, bench)
    out = before + rest
    assert bench.returncode == 5, out
    assert took < STOP_BY_ITSELF_S, f"bench stopped {took:.2f} s after the rig was killed (delay {delay:.2f} s)"
    s = _summary(out)
    assert s["complete"] is False and "stopped answering" in s["error"]
    # every rig signal stops at once: the first the bench finds stale is named (which one is a race)
    assert any(t in s["error"] for t in topics.rig_topics(1)), s["error"]
    path = tmp_path / "killed" / "killed_0.mcap"
    result = read_metadata(path)["softcath_result"]
    assert result["complete"] == "false" and int(result["completed_steps"]) == s["completed_steps"]
    marks = _markers(path)
    ended = {m["step"] for m in marks if m["event"] == "step_end"}
    assert len(ended) == s["completed_steps"] and ended == set(range(s["completed_steps"]))  # none lost
    assert marks[-1]["event"] == "protocol_abort"
    rows = rows_from_recording(path)
    assert {r.step for r in rows} == ended and len(rows) == 2 * len(ended)  # 2 samples per step
    if rows:
        rep = write_report(path, out_dir=tmp_path / "report")
        assert "steps completed (only those are analysed)" in Path(rep["report"]).read_text()
        assert calibrate(rows, load_design("implemented_5mm"), "closed_form") is not None


def test_allocation_node_killed_during_a_direction_protocol_stops_and_vents(tmp_path, procs):
    protocol = tmp_path / "dir.yaml"
    protocol.write_text(yaml.safe_dump({
        "name": "dir_fault", "design": "three_channel_5mm", "drive": "direction", "directions_deg": [60.0],
        "staircase": {"levels": [0.0, 0.25, 0.5, 0.75, 1.0], "down": True}, "trials": 3, "dwell": 0.2,
        "settle": {"tolerance": 1000.0, "max_offset": 3000.0, "hold": 0.1, "timeout": 3.0},
        "samples_per_step": 2, "sample_period": 0.03,
        "benches": [{"kind": "angle", "samples": [{"name": "a", "length": 0.02}]}]}))
    env = private_env()
    _start(procs, ["sim_bench_node", "--ros-args", "-p", "design:=three_channel_5mm"], env)
    alloc = _start(procs, ["allocation_node", "--ros-args", "-p", "design:=three_channel_5mm"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", f"protocol:={protocol}", "-p",
                           f"output_dir:={tmp_path}", "-p", "name:=dir"], env)
    before = wait_output(bench, timeout_s=120, mark="starting protocol")
    time.sleep(1.5)   # mid-staircase: the rig holds pressure
    rest, took = _kill_and_time(alloc, bench)
    out = before + rest
    assert bench.returncode == 5, out
    assert took < STOP_BY_ITSELF_S, f"bench stopped {took:.2f} s after allocation_node was killed"
    assert topics.PRESSURE_CMD in _summary(out)["error"]
    from softcath_ros.recording.reader import iter_messages

    path = tmp_path / "dir" / "dir_0.mcap"
    cmds = [m.message.data for m in iter_messages(path, topics=[topics.PRESSURE_CMD])]
    assert list(cmds[-1]) == [0.0, 0.0, 0.0]        # bench_node vented the rig itself
    peak = max(max(m.message.fluid_pressure for m in iter_messages(path, topics=[topics.pressure_measured_topic(c)]))
               for c in range(3))
    last = [list(iter_messages(path, topics=[topics.pressure_measured_topic(c)]))[-1].message.fluid_pressure
            for c in range(3)]
    assert peak > 10000.0 and max(last) < 3000.0     # held pressure before, vented (gauge error 2 kPa) at the end


@pytest.mark.timeout(180)
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_to_characterise_stops_every_child_and_finalises(tmp_path, procs, sig):
    """The signal to characterise alone (not its process group, as a terminal's Ctrl-C would).
    SIGINT also when characterise was started with it ignored (a shell script's `cmd &` does so)."""
    import psutil

    from softcath_ros.recording.reader import read_metadata

    ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sig == signal.SIGINT else None
    run = _start(procs, ["softcath", "characterise", "--protocol", "quick", "--output-dir", str(tmp_path)], private_env(),
                 preexec_fn=ignore)
    wait_output(run, timeout_s=150, mark="step 8/28")
    children = psutil.Process(run.pid).children(recursive=True)
    assert {c.name() for c in children} >= {"sim_bench_node", "model_node", "bench_node"}
    run.send_signal(sig)
    out = run.communicate(timeout=60)[0]
    assert run.returncode == 128 + sig, out
    assert f"stopped by {sig.name}" in out and "Traceback" not in out
    # bench_node stopped through its lifecycle: deactivate (it vents, finalises and ends)
    assert f"[characterise] deactivate /{topics.BENCH_NODE}" in out, out
    gone, alive = psutil.wait_procs(children, timeout=5)
    assert not alive, [c.name() for c in alive]
    bag = next(tmp_path.glob("bench_quick_*/*.mcap"))
    result = read_metadata(bag)["softcath_result"]        # finalised: metadata readable
    assert result["complete"] == "false" and "interrupted" in result["reason"]


def _mount_tmpfs(where: Path, size: str) -> bool:
    if os.geteuid() != 0:
        return False
    where.mkdir()
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                          capture_output=True).returncode == 0


def test_disk_full_mid_run_says_so_and_keeps_a_recoverable_file(tmp_path, procs):
    """A 1 MiB tmpfs, mostly filled: the recording runs out of space during the protocol."""
    from softcath_ros.recording.recover import recover

    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "1m"):
        pytest.skip("cannot mount a tmpfs here (needs root); the injected-ENOSPC test covers the writer")
    try:
        (disk / "filler").write_bytes(b"\0" * (1024 * 1024 - 96 * 1024))   # leave ~96 KiB
        env = private_env()
        _start(procs, ["sim_bench_node"], env)
        bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=default", "-p", f"output_dir:={disk}",
                               "-p", "name:=full", "-p", "min_free_mb:=0"], env)
        out = bench.communicate(timeout=180)[0]
        assert bench.returncode == 6, out
        assert "disk full" in _summary(out)["error"] and "Traceback" not in out
        report = recover(disk / "full" / "full_0.mcap", tmp_path / "recovered.mcap")
        assert report.per_topic.get(topics.BENCH_STEP, 0) > 0 and report.messages > 100
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def _cannot_start(out: str) -> str:
    """bench_node's one start-up error line (configure's rig check failed)."""
    [line] = [x for x in out.splitlines() if "cannot start" in x]
    assert "Traceback" not in out, out
    return line


def test_no_rig_names_each_missing_topic(tmp_path, procs):
    """configure's check: no publisher on the rig's topics within wait_timeout: one line, exit 3, no recording."""
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                           "-p", "wait_timeout:=1.0", "-p", "name:=none"], private_env())
    out = bench.communicate(timeout=60)[0]
    assert bench.returncode == 3, out
    line = _cannot_start(out)
    assert "no rig after 1 s" in line, line
    for t in topics.rig_topics(1):
        assert f"{t}: no publisher" in line
    assert not (tmp_path / "none").exists()      # nothing recorded for a run that never was


def _short_protocol(tmp_path, levels=(0.0, 10000.0, 20000.0), trials=1) -> Path:
    """A few steps on the angle bench only: a run of a couple of seconds."""
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump({
        "name": "short", "design": "implemented_5mm", "drive": "channels", "channels": [0],
        "staircase": {"levels": list(levels), "down": True}, "trials": trials, "dwell": 0.1,
        "settle": {"tolerance": 1000.0, "max_offset": 3000.0, "hold": 0.05, "timeout": 2.0},
        "samples_per_step": 2, "sample_period": 0.03,
        "benches": [{"kind": "angle", "samples": [{"name": "a", "length": 0.02}]}]}))
    return path


@pytest.mark.timeout(180)
def test_a_protocol_on_the_angle_bench_alone_needs_no_scale(tmp_path, procs):
    """A rig without a scale (its wrench topic remapped away, no deprecated topics) runs a protocol
    on the angle bench only; a protocol on both benches still names the missing scale."""
    env = private_env()
    _start(procs, ["sim_bench_node", "--ros-args",
                   "-r", f"{topics.BENCH_WRENCH}:=/hidden{topics.BENCH_WRENCH}"], env)
    angle_only = _start(procs, ["bench_node", "--ros-args", "-p", f"protocol:={_short_protocol(tmp_path)}",
                                "-p", f"output_dir:={tmp_path}", "-p", "name:=angle_only"], env)
    out = angle_only.communicate(timeout=120)[0]
    assert angle_only.returncode == 0, out
    assert _summary(out)["complete"] is True
    # wait_timeout: long enough for a loaded machine's discovery of the rig's other topics (at 2 s one
    # was still unseen), as the error must name the scale alone
    both = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                          "-p", "wait_timeout:=8.0", "-p", "name:=both"], env)
    out = both.communicate(timeout=60)[0]
    assert both.returncode == 3, out
    err = _cannot_start(out)
    assert f"{topics.BENCH_WRENCH}: no publisher" in err and topics.BENCH_BEND_ANGLE not in err, err


@pytest.mark.timeout(180)
def test_no_rig_says_what_a_silent_driver_reports(tmp_path, procs):
    """The scale's board goes silent: scale_node latches ERROR and publishes no force; bench_node's
    "no rig" line names the silent topic and what scale_node says on /diagnostics."""
    pytest.importorskip("serial", reason="the hardware extra (pyserial)")
    from hardware_emulators import SerialScaleEmulator

    env = private_env()
    board = SerialScaleEmulator(load=0.1).start()
    try:
        _start(procs, ["sim_bench_node", "--ros-args", "-r", f"{topics.BENCH_WRENCH}:=/hidden{topics.BENCH_WRENCH}"], env)
        scale = _start(procs, ["scale_node", "--ros-args", "-p", f"port:={board.port}"], env)
        wait_output(scale, "configured", timeout_s=60)
        board.mode = "dead"
        wait_output(scale, "no valid reading", timeout_s=60)
        bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                               "-p", "wait_timeout:=10.0", "-p", "name:=silent_scale"], env)
        out = bench.communicate(timeout=90)[0]
    finally:
        board.close()
    assert bench.returncode == 3, out
    line = [x for x in out.splitlines() if "no rig after" in x][-1]
    assert f"{topics.BENCH_WRENCH}: no message" in line, line
    assert f"{topics.SCALE_NODE} reports ERROR serial:{board.port}: no valid reading" in line, line
    assert "Traceback" not in out, out


def _short_direction_protocol(tmp_path) -> Path:
    """The shipped three_channel_directions, cut to one direction and one trial."""
    from softcath_ros.core.yaml_io import load_yaml_file
    from softcath_ros.resources import find

    data = load_yaml_file(find("protocol", "three_channel_directions"))
    data.update(name="short_directions", directions_deg=[60.0], trials=1,
                staircase={"levels": [0.0, 0.5, 1.0], "down": True})
    path = tmp_path / "short_directions.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.timeout(240)
@pytest.mark.parametrize("drive", ["channels", "direction"])
def test_characterise_rig_ros_runs_against_a_rig_started_by_hand(tmp_path, procs, drive):
    """Per channel, and by direction (the 2-DOF design: characterise starts allocation_node)."""
    from softcath_ros.bench.analysis import rows_from_recording
    from softcath_ros.recording.reader import read_metadata

    env = private_env()
    design = "implemented_5mm" if drive == "channels" else "three_sector_5mm"   # the protocols' designs
    protocol = _short_protocol(tmp_path) if drive == "channels" else _short_direction_protocol(tmp_path)
    _start(procs, ["sim_bench_node", "--ros-args", "-p", f"design:={design}"], env)
    run = _start(procs, ["softcath", "characterise", "--rig", "ros", "--protocol", str(protocol),
                         "--output-dir", str(tmp_path), "--json"], env)
    out = run.communicate(timeout=200)[0]
    assert run.returncode == 0, out
    result = json.loads(out[out.index("{"):])
    meta = read_metadata(result["recording"])
    assert meta["softcath"]["simulated"] == "true" and meta["softcath"]["rig_topics"] == "stamped"
    assert meta["softcath_result"]["complete"] == "true"
    rows = rows_from_recording(result["recording"])
    assert len(rows) == 5 * (2 if drive == "channels" else 3) and np.all(np.isfinite([r.angle for r in rows]))
    if drive == "direction":
        top = np.mean([r.angle for r in rows if r.level == 1.0])
        assert top > np.mean([r.angle for r in rows if r.level == 0.5]) > 0.1


@pytest.mark.timeout(180)
def test_characterise_stops_the_bench_when_a_child_dies(tmp_path, procs):
    """model_node is no rig (bench_node would not notice it): characterise stops the run itself."""
    import psutil

    run = _start(procs, ["softcath", "characterise", "--protocol", "quick", "--output-dir", str(tmp_path)],
                 private_env())
    wait_output(run, timeout_s=150, mark="starting protocol")
    kids = {c.name(): c for c in psutil.Process(run.pid).children(recursive=True)}
    kids["model_node"].kill()
    t0 = time.monotonic()
    kids["bench_node"].wait(timeout=30)
    took = time.monotonic() - t0
    out = run.communicate(timeout=60)[0]
    assert run.returncode == 5, out
    assert took < STOP_BY_ITSELF_S, f"bench_node stopped {took:.2f} s after model_node was killed"
    assert "model_node exited (-9) during the run" in out and "Traceback" not in out


@pytest.mark.timeout(180)
def test_characterise_on_a_full_disk_says_disk_full(tmp_path, procs):
    """The disk fills up after the protocol started (a tmpfs just above the recorder's 64 MiB
    minimum, then filled to the last byte)."""
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "70m"):
        pytest.skip("cannot mount a tmpfs here (needs root); the injected-ENOSPC test covers the writer")
    try:
        run = _start(procs, ["softcath", "characterise", "--protocol", "quick", "--output-dir", str(disk)],
                     private_env())
        wait_output(run, timeout_s=150, mark="step 8/28")
        with open(disk / "filler", "wb", buffering=0) as f:
            for block in (1 << 20, 1 << 12):
                try:
                    while True:
                        f.write(b"\0" * block)
                except OSError:
                    pass
        out = run.communicate(timeout=170)[0]
        assert run.returncode == 6, out
        assert "disk full" in out and "Traceback" not in out
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def test_a_rig_on_the_deprecated_unstamped_topics_still_works(tmp_path, procs):
    """sim_bench_node with the old topics turned on (off by default) and its stamped topics remapped
    away: bench_node falls back to the old topics with a warning; the analysis reads them from the
    recording."""
    from softcath_ros.bench.analysis import rows_from_recording
    from softcath_ros.recording.reader import read_metadata

    env = private_env()
    hide = [x for t in topics.rig_topics(1) for x in ("-r", f"{t}:=/hidden{t}")]
    _start(procs, ["sim_bench_node", "--ros-args", "-p", "legacy_topics:=true", *hide], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", f"protocol:={_short_protocol(tmp_path)}", "-p",
                           f"output_dir:={tmp_path}", "-p", "name:=old"], env)
    out = bench.communicate(timeout=120)[0]
    assert bench.returncode == 0, out
    assert "deprecated unstamped" in out
    path = tmp_path / "old" / "old_0.mcap"
    assert read_metadata(path)["softcath"]["rig_topics"] == "deprecated unstamped"
    # every sample of the 5 steps x 2 is a row, or left out because a reading was stale (a loaded
    # machine can hold the rig's unstamped readings back past stale_after_s: never analysed as fresh)
    skipped = []
    rows = rows_from_recording(path, skipped=skipped)
    assert len(rows) + len(skipped) == 5 * 2 and rows, (len(rows), skipped)
    # each settled row holds the pressure the rig measured at its step (the rig's offset is under 3 kPa)
    assert all(abs(r.pressure[0] - r.level) < 5000.0 for r in rows if r.settled), [(r.level, r.pressure) for r in rows]


@pytest.mark.timeout(180)
def test_bench_killed_the_rig_vents_and_characterise_says_recover(tmp_path, procs):
    """The rig's watchdog (docs/rig.md): bench_node SIGKILLed, the pressure commands stop, the
    simulated rig vents within its command_timeout; characterise names the dead bench."""
    import psutil

    env = private_env()
    rig = _start(procs, ["sim_bench_node"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", "protocol:=quick", "-p", f"output_dir:={tmp_path}",
                           "-p", "name:=b"], env)
    wait_output(bench, timeout_s=120, mark="starting protocol")
    killed = time.time()
    bench.kill()
    out = wait_output(rig, timeout_s=30, mark="venting")
    # The rig vents because its commands stopped, and after they stopped: the line's own stamp (the rig's
    # clock, not when this test read it; how soon on a quiet machine: benchmarks, not here).
    [line] = [x for x in out.splitlines() if "venting" in x]
    assert "no pressure command for 0.5 s: venting" in line, line
    assert _log_stamp(line) > killed, (line, killed)

    run = _start(procs, ["softcath", "characterise", "--protocol", str(_short_protocol(tmp_path, trials=3)),
                         "--output-dir", str(tmp_path / "c")], private_env())
    wait_output(run, timeout_s=150, mark="starting protocol")
    [b] = [c for c in psutil.Process(run.pid).children(recursive=True) if c.name() == "bench_node"]
    b.kill()
    out = run.communicate(timeout=60)[0]
    assert run.returncode == 5, out
    assert "bench_node killed by SIGKILL during the run" in out and "softcath recover" in out
    assert "Traceback" not in out


def test_a_pressure_source_that_does_not_follow_is_refused_before_the_first_step(tmp_path, procs):
    """A regulator with a 10 s time constant reaches 26 % of the test command in follow_timeout."""
    env = private_env()
    _start(procs, ["sim_bench_node", "--ros-args", "-p", "regulator_time_constant:=10.0"], env)
    bench = _start(procs, ["bench_node", "--ros-args", "-p", f"protocol:={_short_protocol(tmp_path)}", "-p",
                           f"output_dir:={tmp_path}", "-p", "name:=slow"], env)
    out = bench.communicate(timeout=120)[0]
    assert bench.returncode == 3, out
    s = _summary(out)
    assert "did not follow a test command within 3 s" in s["error"] and s["completed_steps"] == 0
    assert "starting protocol" not in out


@pytest.mark.timeout(240)
def test_a_bench_node_that_never_spins_is_started_once_more(tmp_path, monkeypatch, capsys):
    """A bench_node hung before it spins (Fast DDS's start-up hang under load, stood in for by a
    process that only sleeps) is stopped after BENCH_READY_S and started again; the run completes."""
    import sys

    from softcath_ros.cli import characterise
    from softcath_ros.cli import main as softcath
    from softcath_ros.graph import NodeGraph

    starts = []
    real_start = NodeGraph.start

    def start(self, node, params=None, extra_ros_args=(), **popen):
        if node == "bench_node":
            starts.append(node)
            if len(starts) == 1:   # the first: says nothing, never spins
                proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"], env=self.env,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                self.processes.append((node, proc))
                return proc
        return real_start(self, node, params, extra_ros_args, **popen)

    monkeypatch.setattr(NodeGraph, "start", start)
    monkeypatch.setattr(characterise, "BENCH_READY_S", 3.0)
    for key, value in private_env().items():
        monkeypatch.setenv(key, value)
    code = softcath(["characterise", "--protocol", str(_short_protocol(tmp_path)), "--output-dir", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert len(starts) == 2 and "not spinning after 3 s" in out and "started again" in out
    assert len(list(tmp_path.glob("bench_short_*/*.mcap"))) == 1
