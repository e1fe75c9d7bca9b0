"""The rig contract without DDS: freshness and follow checks, the analysis of stamped, stale and
cut-short recordings, and a disk that fills up under the recorder (an injected ENOSPC)."""
import errno
import json
import math

import numpy as np
import pytest

from softcath_ros import topics
from softcath_ros.bench.analysis import rows_from_events, rows_from_recording
from softcath_ros.bench.rig_contract import FollowCheck, RigMonitor, follow_test_command, with_driver_reports
from softcath_ros.core.errors import SoftcathError


def test_monitor_names_missing_stale_and_skewed_topics():
    m = RigMonitor(["/a", "/b", "/c", "/d"], stale_after=0.5)
    m.seen("/a", 10.0, 100.0)          # fresh
    m.seen("/b", 9.0, 99.0)            # arrived 1 s ago
    m.seen("/c", 10.0, 96.0)           # arrived now, but stamped 4 s ago (a stale reading re-sent)
    p = m.problems(10.1, 100.1)
    assert set(p) == {"/b", "/c", "/d"}
    assert p["/d"] == "no message yet"
    assert "no message for 1.10 s" in p["/b"]
    assert "+4.10 s off this clock" in p["/c"]
    m.seen("/d", 10.1, 0.0)
    assert "stamp is zero" in m.problem("/d", 10.1, 100.1)
    assert m.problem("/b", 10.1, 100.1, limit=2.0) is None   # the longer limit that ends a run
    m.seen("/e", 10.1)                  # unstamped: arrival only
    assert m.alive("/e", 10.5, 100.5) and not m.alive("/e", 10.7, 100.7)
    with pytest.raises(ValueError):
        RigMonitor(["/a"], stale_after=math.nan)


def test_follow_check_passes_on_a_following_source_and_fails_on_a_dead_one():
    test = np.array([0.0, 5000.0])
    ok = FollowCheck(test, timeout=1.0, baseline_s=0.2)
    ok.start(0.0)
    t, p = 0.0, np.array([300.0, -800.0])  # gauge offsets: the rise is measured from the baseline
    while not ok.done:
        t += 0.01
        cmd = ok.test_pressures if ok.commanding else np.zeros(2)
        p = p + 0.2 * (cmd + np.array([300.0, -800.0]) - p)
        ok.update(t, p)
    assert ok.state == "passed" and ok.rise[1] >= 2500.0 and t < 0.5
    dead = FollowCheck(test, timeout=1.0, baseline_s=0.2)
    dead.start(0.0)
    for k in range(200):
        dead.update(0.01 * k, np.array([300.0, -800.0]))
    assert dead.state == "failed" and "channel 1: commanded 5000 Pa, rose 0 Pa" in dead.message


def test_follow_command_scales_the_first_pressurised_step(implemented_design):
    from softcath_ros.bench.protocol import expand_steps, load_protocol

    steps = expand_steps(load_protocol("quick"), 1, implemented_design.max_pressure)
    p, bend = follow_test_command(steps, 5000.0)
    assert p.tolist() == [5000.0] and bend is None
    assert follow_test_command(steps, 1e9)[0].tolist() == [10000.0]  # never more than the step asks


def _sample(step, t, level=0.0, bench="angle"):
    return (t, {"event": "sample", "step": step, "bench": bench, "sample_name": "s", "sample_length_m": 0.02,
                "trial": 0, "phase": "loading", "drive": "channel 0", "level": level, "pressure_cmd_pa": [level]})


def test_stale_readings_and_unfinished_steps_are_not_analysed():
    """The rig died during step 1: its reading stopped at t = 2 s. Samples after that must not
    reuse the last reading, and the step that never ended is left out."""
    s = 1_000_000_000
    events = [(0, {"event": "step_start", "step": 0}), _sample(0, int(1.0 * s)), (int(1.1 * s), {"event": "step_end", "step": 0}),
              (int(1.2 * s), {"event": "step_start", "step": 1}), _sample(1, int(1.9 * s), 10000.0),
              _sample(1, int(3.0 * s), 10000.0), (int(3.1 * s), {"event": "protocol_abort", "step": 1})]
    streams = {"pressure_ch0": [(int(k * 0.1 * s), 100.0 * k) for k in range(21)],
               "angle": [(int(k * 0.1 * s), 0.01 * k) for k in range(21)]}
    skipped = []
    rows = rows_from_events(events, streams, stale_after=0.5, skipped=skipped)
    assert [r.step for r in rows] == [0]
    assert rows[0].pressure.tolist() == [1000.0] and rows[0].angle == pytest.approx(0.1)
    assert [e["step"] for e in skipped] == [1]   # the 3.0 s sample: its reading was 1 s old
    events.insert(-1, (int(3.05 * s), {"event": "step_end", "step": 1}))
    assert [r.step for r in rows_from_events(events, streams, stale_after=0.5)] == [0, 1]  # 1.9 s: fresh
    assert len(rows_from_events(events, streams)) == 3   # no staleness rule: the old behaviour


def _write_stamped(bag_dir, n=20, rig_dies_after=None, stale_after="0.5"):
    """A recording with the contract's stamped types, one pressure topic per channel (2 channels)."""
    from geometry_msgs.msg import Vector3Stamped, WrenchStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import FluidPressure
    from std_msgs.msg import String

    from softcath_ros.recording import BagWriter

    s = 1_000_000_000
    chans = [topics.pressure_measured_topic(c) for c in range(2)]
    with BagWriter(bag_dir) as w:
        for t in chans:
            w.add_topic(t, topics.FLUID_PRESSURE_TYPE)
        for t in (topics.BENCH_BEND_ANGLE, topics.BENCH_WRENCH, topics.BENCH_STEP):
            w.add_topic(t, topics.MESSAGE_TYPES[t])
        w.add_metadata("softcath", {"stale_after_s": stale_after})
        for k in range(n):  # one step per second, readings every 0.1 s
            t0 = (k + 1) * s
            w.write(topics.BENCH_STEP, serialize_message(String(data=json.dumps({"event": "step_start", "step": k}))), t0)
            for j in range(10):
                tr = t0 + j * s // 10
                if rig_dies_after is not None and tr > rig_dies_after * s:
                    continue
                for c, topic in enumerate(chans):
                    w.write(topic, serialize_message(FluidPressure(fluid_pressure=1000.0 * k + c, variance=4e4)), tr)
                a = Vector3Stamped()
                a.vector.x = 0.01 * k
                w.write(topics.BENCH_BEND_ANGLE, serialize_message(a), tr)
                f = WrenchStamped()
                f.wrench.force.z = 0.001 * k
                w.write(topics.BENCH_WRENCH, serialize_message(f), tr)
            ev = _sample(k, t0 + 95 * s // 100, 1000.0 * k)[1]
            w.write(topics.BENCH_STEP, serialize_message(String(data=json.dumps(ev))), t0 + 95 * s // 100)
            w.write(topics.BENCH_STEP, serialize_message(String(data=json.dumps({"event": "step_end", "step": k}))),
                    t0 + 96 * s // 100)
    return bag_dir / f"{bag_dir.name}_0.mcap"


def test_analysis_reads_the_stamped_topics(tmp_path):
    rows = rows_from_recording(_write_stamped(tmp_path / "st", n=4))
    assert [r.step for r in rows] == [0, 1, 2, 3]
    assert rows[2].pressure.tolist() == [2000.0, 2001.0]
    assert rows[2].angle == pytest.approx(0.02)
    assert rows[3].force == pytest.approx(0.003)


def test_analysis_drops_samples_whose_reading_went_stale(tmp_path):
    """The rig stops publishing at 2.5 s but the markers (and the ends of steps) go on, as when a
    reading is reused: samples from 3.95 s on have only stale readings."""
    rows = rows_from_recording(_write_stamped(tmp_path / "dead", n=4, rig_dies_after=2.5))
    assert [r.step for r in rows] == [0, 1]


class _FillingDisk:
    """A file that takes ``room`` bytes and then fails as a full disk does."""

    def __init__(self, f, room: int):
        self.f, self.room = f, room

    def write(self, data):
        if len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


def test_disk_full_says_so_and_keeps_what_was_flushed(tmp_path, monkeypatch):
    """Background writer as in bench_node: the failing write is counted, 'disk full' said in one
    line, close fails with it, abandon() lets go; recover gets every flushed message back."""
    from std_msgs.msg import Float64
    from rclpy.serialization import serialize_message

    import softcath_ros.recording.writer as writer_mod
    from softcath_ros.recording import BagWriter, RecordingError
    from softcath_ros.recording.recover import recover

    real_open = open
    monkeypatch.setattr(writer_mod, "open", lambda p, mode: _FillingDisk(real_open(p, mode), 6000), raising=False)
    w = BagWriter(tmp_path / "full", background=True, compression="none", min_free_bytes=0)
    w.add_topic(topics.BENCH_ANGLE, topics.MESSAGE_TYPES[topics.BENCH_ANGLE])
    for i in range(40):
        w.write(topics.BENCH_ANGLE, serialize_message(Float64(data=float(i))), (i + 1) * 1000)
    w.flush()                                  # 40 messages fit: on disk
    for i in range(40, 2000):
        w.write(topics.BENCH_ANGLE, serialize_message(Float64(data=float(i))), (i + 1) * 1000)
    with pytest.raises(RecordingError, match="disk full") as exc:
        w.flush()
        w.close()
    assert "\n" not in str(exc.value)
    w.abandon()
    assert w.closed
    report = recover(w.path, tmp_path / "recovered.mcap")
    assert report.per_topic[topics.BENCH_ANGLE] >= 40


def test_recording_topics_of_a_torn_file(tmp_path):
    from softcath_ros.recording.reader import recording_topics

    path = _write_stamped(tmp_path / "t", n=2)
    assert recording_topics(path)[topics.pressure_measured_topic(1)] == topics.FLUID_PRESSURE_TYPE
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])          # no summary: the channels are found by a scan
    found = recording_topics(path)
    assert found[topics.pressure_measured_topic(0)] == topics.FLUID_PRESSURE_TYPE
    (tmp_path / "text.mcap").write_text("not a recording")
    with pytest.raises(SoftcathError, match="cannot read its topics"):
        recording_topics(tmp_path / "text.mcap")


def test_graph_problems_name_each_topic_without_publisher_and_a_command_nobody_hears():
    from softcath_ros.bench.rig_contract import graph_problems

    contract, legacy = RigMonitor(topics.rig_topics(1), 0.5), RigMonitor(topics.deprecated_rig_topics(), 0.5)
    pubs = {topics.pressure_measured_topic(0): 1, topics.PRESSURE_MEASURED: 1}
    subs = {topics.PRESSURE_CMD: 1}
    monitor, found = graph_problems(contract, legacy, 1, lambda t: pubs.get(t, 0), lambda t: subs.get(t, 0), False)
    assert monitor is contract    # a stamped topic is published: the contract's, even beside deprecated ones
    assert found == {topics.BENCH_BEND_ANGLE: "no publisher", topics.BENCH_WRENCH: "no publisher"}
    del pubs[topics.pressure_measured_topic(0)]
    monitor, found = graph_problems(contract, legacy, 1, lambda t: pubs.get(t, 0), lambda t: 0, True)
    assert monitor is legacy and topics.PRESSURE_MEASURED not in found
    assert {topics.PRESSURE_CMD, topics.BEND_CMD} <= set(found) and "pressure source" in found[topics.PRESSURE_CMD]


def test_wait_for_rig_waits_its_bounded_time_then_names_what_is_missing_in_one_line():
    from softcath_ros.bench.rig_contract import NoRig, wait_for_rig

    clock = [0.0]

    def sleep(dt):
        clock[0] += dt

    seen = iter([{"/a": "no publisher"}] * 5)
    wait_for_rig(lambda: next(seen, {}), 2.0, lambda: clock[0], sleep)   # appears after 0.5 s
    assert clock[0] == pytest.approx(0.5)
    clock[0] = 0.0
    with pytest.raises(NoRig) as err:
        wait_for_rig(lambda: {"/a": "no publisher", "/b": "nothing subscribes"}, 2.0, lambda: clock[0], sleep)
    assert clock[0] == pytest.approx(2.0, abs=0.11) and err.value.exit_code == 3
    assert str(err.value) == "no rig after 2 s: /a: no publisher; /b: nothing subscribes"


def test_a_problem_topic_carries_what_its_driver_reports():
    problems = {"/w": "no message yet", "/a": "no publisher"}
    reports = {"scale": "ERROR serial:/dev/x: no valid reading for 0.42 s", "other": "WARN 2 line(s) refused"}
    out = with_driver_reports(problems, {"/w": ["scale"], "/a": []}.__getitem__, reports)
    assert out == {"/w": "no message yet (scale reports ERROR serial:/dev/x: no valid reading for 0.42 s)",
                   "/a": "no publisher"}
