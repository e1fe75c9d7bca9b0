"""Recording: rosbag2-compatible MCAP round trip, every record rosbag2 relies on, recovery."""
import os
import random
import shutil
import signal
import struct
import subprocess
import sys
import textwrap

import pytest
import yaml
from mcap.reader import make_reader

from softcath_ros import topics
from softcath_ros.core.errors import SoftcathError
from softcath_ros.recording import BagWriter, OfferedQos, RecordingError, adapt_request_to_offers
from softcath_ros.recording.msg_definitions import full_definition, type_description_hash
from softcath_ros.recording.qos import parse_qos_yaml, qos_profiles_yaml
from softcath_ros.recording.reader import iter_messages
from softcath_ros.recording.recover import recover

F64 = "std_msgs/msg/Float64"


def cdr_float64(value: float) -> bytes:
    """CDR (little endian) encoding of std_msgs/Float64, written by hand so the test needs no rclpy."""
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)


def _messages(path):
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


# --------------------------------------------------------------------------- definitions, QoS

def test_full_definition_has_every_dependency_once():
    text = full_definition("diagnostic_msgs/msg/DiagnosticArray")
    delim = "=" * 80 + "\n"
    names = [line[5:] for line in text.split("\n") if line.startswith("MSG: ")]
    assert sorted(names) == sorted(set(names))
    for dep in ("diagnostic_msgs/DiagnosticStatus", "diagnostic_msgs/KeyValue", "std_msgs/Header",
                "builtin_interfaces/Time"):
        assert f"{delim}MSG: {dep}\n" in text
    assert text.startswith("# This message is used to send diagnostic")  # the main definition first


def test_type_hash_is_rihs01():
    assert type_description_hash(F64).startswith("RIHS01_") and len(type_description_hash(F64)) == 71
    assert type_description_hash(F64) != type_description_hash("std_msgs/msg/String")


def test_qos_yaml_round_trip_and_adaptation():
    offers = [OfferedQos(reliability="reliable", durability="transient_local", depth=5, history="keep_last"),
              OfferedQos(reliability="best_effort", durability="volatile")]
    text = qos_profiles_yaml(offers)
    node = yaml.safe_load(text)
    assert node[0]["deadline"] == {"sec": 9223372036, "nsec": 854775807}
    assert node[0]["reliability"] == "reliable" and node[1]["reliability"] == "best_effort"
    assert parse_qos_yaml(text) == offers
    rel, dur, warnings = adapt_request_to_offers(offers)
    assert (rel, dur) == ("best_effort", "volatile") and len(warnings) == 2
    assert adapt_request_to_offers(offers[:1])[:2] == ("reliable", "transient_local")
    assert adapt_request_to_offers([])[:2] == ("reliable", "volatile")


# --------------------------------------------------------------------------- round trip

ROUND_TRIP_TYPES = {t: topics.MESSAGE_TYPES[t] for t in (topics.PRESSURE_CMD, topics.BENCH_ANGLE, topics.TIP_POSE,
                                                          topics.BACKBONE, topics.DIAGNOSTICS, topics.BENCH_STEP)}


def _sample_messages():
    """Real ROS messages of every recorded type, serialized by rclpy."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import Pose, PoseArray, PoseStamped
    from std_msgs.msg import Float64, Float64MultiArray, String

    out = []
    for i in range(25):
        ps = PoseStamped()
        ps.header.frame_id = topics.FRAME_ID
        ps.header.stamp.sec, ps.header.stamp.nanosec = i, 7 * i
        ps.pose.position.x, ps.pose.orientation.w = 0.001 * i, 1.0
        arr = PoseArray(poses=[Pose() for _ in range(i % 4)])
        arr.header.frame_id = topics.FRAME_ID
        diag = DiagnosticArray(status=[DiagnosticStatus(level=b"\x01", name="softcath_bench", message=f"m{i}",
                                                        values=[KeyValue(key="k", value=str(i))])])
        out += [(topics.PRESSURE_CMD, Float64MultiArray(data=[1000.0 * i, 2.5])),
                (topics.BENCH_ANGLE, Float64(data=0.01 * i)),
                (topics.TIP_POSE, ps), (topics.BACKBONE, arr), (topics.DIAGNOSTICS, diag),
                (topics.BENCH_STEP, String(data='{"step": %d}' % i))]
    return out


def _assert_same(original, decoded):
    for name in original.get_fields_and_field_types():
        a, b = getattr(original, name), getattr(decoded, name)
        if hasattr(a, "get_fields_and_field_types"):
            _assert_same(a, b)
        elif isinstance(a, (list, tuple)) and a and hasattr(a[0], "get_fields_and_field_types"):
            assert len(a) == len(b)
            for x, y in zip(a, b):
                _assert_same(x, y)
        elif isinstance(a, bytes):
            assert a == (b if isinstance(b, bytes) else bytes([b]))
        else:
            assert list(a) == list(b) if hasattr(a, "__len__") and not isinstance(a, str) else a == b, name


def test_round_trip_decodes_every_message_and_carries_rosbag2_records(tmp_path):
    from rclpy.serialization import serialize_message

    qos = [OfferedQos(history="keep_last", depth=10, reliability="reliable", durability="volatile")]
    bag = tmp_path / "bench_run"
    msgs = _sample_messages()
    with BagWriter(bag, custom_data={"simulated": "true"}) as w:
        for topic, typ in ROUND_TRIP_TYPES.items():
            w.add_topic(topic, typ, qos)
        w.add_metadata("softcath", {"simulated": "true", "protocol": "default"})
        w.add_attachment("protocol.yaml", "application/yaml", b"name: default\n")
        for k, (topic, msg) in enumerate(msgs):
            w.write(topic, serialize_message(msg), log_time_ns=1_000_000_000 + k, publish_time_ns=999_000_000 + k)
    path = bag / "bench_run_0.mcap"

    decoded = list(iter_messages(path))
    assert len(decoded) == len(msgs)
    for (topic, original), rec in zip(msgs, decoded):
        assert rec.topic == topic
        _assert_same(original, rec.message)
    assert decoded[0].publish_time_ns == 999_000_000 and decoded[0].log_time_ns == 1_000_000_000

    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert header.profile == "ros2"
    assert {s.name for s in summary.schemas.values()} == set(ROUND_TRIP_TYPES.values())
    for s in summary.schemas.values():
        assert s.encoding == "ros2msg" and s.data.decode() == full_definition(s.name)
    for c in summary.channels.values():
        assert c.message_encoding == "cdr"
        assert parse_qos_yaml(c.metadata["offered_qos_profiles"]) == qos
        assert c.metadata["topic_type_hash"] == type_description_hash(ROUND_TRIP_TYPES[c.topic])
        assert summary.statistics.channel_message_counts[c.id] == 25
    assert summary.statistics.message_count == len(msgs)
    assert summary.chunk_indexes and all(ci.compression == "zstd" for ci in summary.chunk_indexes)
    assert all(ci.message_index_offsets for ci in summary.chunk_indexes)
    meta = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap" and meta["ros_distro"]
    assert meta["message_count"] == len(msgs)
    assert meta["custom_data"] == {"simulated": "true"}
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == \
        {t: 25 for t in ROUND_TRIP_TYPES}
    assert meta["duration"]["nanoseconds"] == len(msgs) - 1
    assert metadata["softcath"]["simulated"] == "true"
    assert attachments["protocol.yaml"] == b"name: default\n"
    on_disk = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert on_disk == meta and on_disk["relative_file_paths"] == ["bench_run_0.mcap"]


def test_mcap_ros2_reader_decodes_file(tmp_path):
    """The reader Foxglove's Python tooling uses (mcap-ros2-support) opens the file as ROS 2."""
    from mcap_ros2.decoder import DecoderFactory

    with BagWriter(tmp_path / "b") as w:
        w.add_topic("/x", F64)
        for i in range(10):
            w.write("/x", cdr_float64(i * 0.5), log_time_ns=i + 1)
    with open(tmp_path / "b" / "b_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        values = [msg.data for _, _, _, msg in reader.iter_decoded_messages()]
    assert values == [i * 0.5 for i in range(10)]


# --------------------------------------------------------------------------- start-up errors

def test_unwritable_destination_fails_at_start(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root ignores permission bits
            target = "/proc/softcath_cannot_be_here/bag"
        else:
            target = locked / "bag"
        with pytest.raises(RecordingError, match="cannot create|not writable"):
            BagWriter(target)
    finally:
        locked.chmod(0o700)
    with pytest.raises(RecordingError, match="MiB free"):
        BagWriter(tmp_path / "full", min_free_bytes=1 << 62)
    (tmp_path / "exists").mkdir()
    with pytest.raises(RecordingError, match="already exists"):
        BagWriter(tmp_path / "exists")


def test_write_to_unknown_topic_is_an_error(tmp_path):
    with BagWriter(tmp_path / "b") as w:
        with pytest.raises(RecordingError, match="not added"):
            w.write("/nope", cdr_float64(1.0), 1)


def test_background_writer_keeps_order_flushes_after_the_queue_and_counts_refusals(tmp_path):
    """Writer thread: every message lands in call order; flush() returns only once everything queued
    before it is on disk (recover of the flushed prefix finds it); writes after close are counted."""
    w = BagWriter(tmp_path / "bg", flush_period_s=1e9, fsync=False, background=True)
    w.add_topic("/x", F64)
    with pytest.raises(RecordingError, match="not added"):
        w.write("/nope", cdr_float64(0.0), 1)
    for i in range(3000):
        w.write("/x", cdr_float64(float(i)), log_time_ns=i + 1)
    w.flush()
    assert w.queued == 0 and w.message_count == 3000
    prefix = tmp_path / "prefix.mcap"
    prefix.write_bytes(w.path.read_bytes())
    recover(prefix)
    assert [struct.unpack("<d", d[4:])[0] for _, _, d in _messages(prefix)] == [float(i) for i in range(3000)]
    for i in range(3000, 5000):
        w.write("/x", cdr_float64(float(i)), log_time_ns=i + 1)
    w.close()
    assert [struct.unpack("<d", d[4:])[0] for _, _, d in _messages(w.path)] == [float(i) for i in range(5000)]
    assert w.write_failures == 0
    w.write("/x", cdr_float64(1.0), 9999)
    assert w.write_failures == 1 and "closed" in w.error


def test_idle_background_writer_sleeps_until_a_message_or_a_flush_is_due(tmp_path, monkeypatch):
    """The writer thread waits on its queue: idle, it wakes only when the open chunk's flush is due
    (never polls), and a message wakes it at once."""
    import time

    wakes, mine = [], []
    # counted for this writer only: another test's writer thread may still run in this process
    monkeypatch.setattr(BagWriter, "flush_if_due", lambda self: wakes.append(time.monotonic()) if self in mine else None)
    w = BagWriter(tmp_path / "idle", flush_period_s=60.0, fsync=False, background=True)
    mine.append(w)
    w.add_topic("/x", F64)
    time.sleep(0.3)
    assert wakes == []          # a 2 ms poll would have woken ~150 times
    w.write("/x", cdr_float64(1.0), 1)
    w.flush()
    assert w.message_count == 1 and wakes == []
    w.close()
    assert not w._thread.is_alive()


# --------------------------------------------------------------------------- recovery

def test_recover_complete_file_keeps_everything(tmp_path):
    with BagWriter(tmp_path / "b") as w:
        w.add_topic("/x", F64)
        for i in range(100):
            w.write("/x", cdr_float64(i), log_time_ns=i + 1)
    path = tmp_path / "b" / "b_0.mcap"
    before = _messages(path)
    report = recover(path, tmp_path / "copy.mcap")
    assert report.was_complete and report.messages == 100
    assert _messages(tmp_path / "copy.mcap") == before


def test_recover_truncated_at_random_offsets_keeps_every_flushed_message(tmp_path):
    """Cut the file anywhere: every message flushed before the cut survives, bit for bit."""
    bag = tmp_path / "b"
    flushed_at = []  # (file size after flush, messages written so far)
    w = BagWriter(bag, flush_period_s=1e9, fsync=False)
    w.add_topic("/x", F64)
    w.add_topic("/y", "std_msgs/msg/String")
    for i in range(400):
        w.write("/x", cdr_float64(float(i)), log_time_ns=10 * i + 1)
        if i % 40 == 39:
            w.flush()
            flushed_at.append((w.path.stat().st_size, i + 1))
    w.close()
    full = w.path.read_bytes()
    original = _messages(w.path)
    rng = random.Random(5)
    offsets = [rng.randrange(8, len(full)) for _ in range(25)] + [flushed_at[3][0], flushed_at[3][0] - 1]
    for cut in offsets:
        damaged = tmp_path / f"cut_{cut}.mcap"
        damaged.write_bytes(full[:cut])
        report = recover(damaged)
        kept = _messages(damaged)
        expected_min = max([n for size, n in flushed_at if size <= cut], default=0)
        assert len(kept) >= expected_min, (cut, report)
        assert kept == original[:len(kept)]
        assert (tmp_path / f"cut_{cut}.mcap.truncated").read_bytes() == full[:cut]


def test_recover_rejects_non_mcap(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(SoftcathError, match="nothing to recover|not an MCAP"):
        recover(bad, tmp_path / "out.mcap")


RECORDER_SCRIPT = textwrap.dedent("""
    import struct, sys, time
    from softcath_ros.recording import BagWriter
    w = BagWriter(sys.argv[1], flush_period_s=float(sys.argv[2]))
    w.add_topic("/x", "std_msgs/msg/Float64")
    print("ready", flush=True)
    i, flushed_at = 0, w._last_flush
    while True:
        t = time.time_ns()
        w.write("/x", b"\\x00\\x01\\x00\\x00" + struct.pack("<d", float(i)), log_time_ns=t)
        i += 1
        w.flush_if_due()
        if w._last_flush != flushed_at:      # a periodic flush happened: the first i messages are on disk
            flushed_at = w._last_flush
            print(f"flushed {i}", flush=True)
        time.sleep(0.0005)
""")


@pytest.mark.slow
def test_sigkill_recorder_then_recover_keeps_all_but_the_last_second(tmp_path):
    bag = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-c", RECORDER_SCRIPT, str(bag), "1.0"],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        flushes = [int(proc.stdout.readline().split()[1]) for _ in range(3)]   # three periodic flushes
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    path = bag / "killed_0.mcap"
    report = recover(path)
    assert not report.was_complete
    kept = _messages(path)
    times = [t for _, t, _ in kept]
    values = [struct.unpack("<d", d[4:])[0] for _, _, d in kept]
    assert values == [float(i) for i in range(len(values))]  # a gap-free prefix
    # Everything up to the last periodic flush the recorder reported survived (a logical clock: the
    # flush count, not a wall-clock window, so a loaded machine cannot make it flaky).
    assert len(kept) >= flushes[-1] > flushes[0] > 0
    assert times == sorted(times)


def test_recover_in_a_bag_folder_keeps_custom_data_and_moves_the_damaged_original_out(tmp_path):
    """The bench's custom_data (protocol, design, simulated) survives recovery, and the damaged
    original leaves the bag folder (ros2 bag would read it as part of the bag)."""
    bag = tmp_path / "bench_x"
    w = BagWriter(bag, flush_period_s=1e9, fsync=False, custom_data={"protocol": "quick", "design": "d1"})
    w.add_topic("/x", F64)
    w.custom_data["simulated"] = "true"
    w.add_metadata("softcath", {"protocol": "quick", "design": "d1", "simulated": "true", "n_steps": "3"})
    for i in range(50):
        w.write("/x", cdr_float64(float(i)), log_time_ns=i + 1)
    w.flush()
    cut = w.path.read_bytes()          # the recorder killed here: no rosbag2 record, no summary
    w.close()
    complete = w.path.read_bytes()
    for content, label in ((cut, "truncated"), (complete, "complete")):
        w.path.write_bytes(content)
        for stale in tmp_path.glob("bench_x.damaged*"):
            shutil.rmtree(stale)
        report = recover(w.path)
        assert report.custom_data == {"protocol": "quick", "design": "d1", "simulated": "true"}, label
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["custom_data"] == report.custom_data and meta["message_count"] == 50, label
        assert sorted(p.name for p in bag.iterdir()) == ["bench_x_0.mcap", "metadata.yaml"], label
        kept = tmp_path / "bench_x.damaged" / "bench_x_0.mcap"
        assert report.damaged_original == str(kept) and kept.read_bytes() == content, label
        assert len(_messages(w.path)) == 50


def test_recover_output_into_a_missing_folder_is_one_line(tmp_path):
    with BagWriter(tmp_path / "b") as w:
        w.add_topic("/x", F64)
        w.write("/x", cdr_float64(1.0), log_time_ns=1)
    with pytest.raises(SoftcathError, match="does not exist"):
        recover(w.path, tmp_path / "missing" / "out.mcap")
    with pytest.raises(SoftcathError, match="damaged file itself"):
        recover(w.path, w.path)
