"""docs/lab.md's node and tracker lines run as written, against emulated devices: the only change
is the device each names (the serial ports /dev/ttyACM0 and /dev/ttyUSB0 become the emulators'
pseudo-terminals, the Modbus address 192.168.0.10:502 the emulator on 127.0.0.1, camera 0 a folder
of rendered frames, replayed in a loop as a camera never ends). Its `softcath` lines parse in
test_docs_commands.py; `softcath track` and `softcath characterise --rig ros` run here."""
import shlex
import subprocess
import sys
from contextlib import ExitStack
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("serial", reason="the hardware extra (pyserial)")
pytest.importorskip("pymodbus", reason="the hardware extra (pymodbus)")
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from geometry_msgs.msg import Vector3Stamped, WrenchStamped  # noqa: E402
from sensor_msgs.msg import FluidPressure  # noqa: E402

from hardware_emulators import ModbusRegulatorEmulator, SerialRegulatorEmulator, SerialScaleEmulator  # noqa: E402
from lifecycle_listener import LifecycleListener  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.graph import NodeGraph  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def lab_lines(prefix: str) -> list[list[str]]:
    fenced, out = False, []
    for line in (ROOT / "docs" / "lab.md").read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif fenced and line.strip().startswith(prefix + " "):
            out.append(shlex.split(line.strip(), comments=True))
    assert out, f"docs/lab.md shows no {prefix} line"
    return out


def run_line(argv, devices: dict, topic: str, msg_type, node_name: str, cwd=ROOT):
    """Start the line (devices replaced), wait until ``topic`` carries a message, stop it: exit 0."""
    args = [b for a in argv[1:] for b in devices.get(a, [a])]
    assert args[0] == "--ros-args"
    with NodeGraph() as graph:
        proc = graph.start(argv[0], extra_ros_args=args[1:], cwd=cwd)
        graph.wait_ready(proc)
        listener = LifecycleListener(graph.domain, node_name, {topic: msg_type})
        try:
            assert listener.spin(60.0, until=lambda: listener.got[topic]), " ".join(argv)
        finally:
            listener.close()
        assert graph.stop()[argv[0]] == 0


@pytest.mark.timeout(600)
def test_the_regulator_lines_run_as_written():
    serial = SerialRegulatorEmulator(1).start()
    modbus = ModbusRegulatorEmulator(1)
    devices = {"port:=/dev/ttyACM0": [f"port:={serial.port}"], "modbus_host:=192.168.0.10": ["modbus_host:=127.0.0.1"],
               "modbus_port:=502": [f"modbus_port:={modbus.port}"]}
    try:
        lines = lab_lines("regulator_node")
        assert {("backend:=sim" in line, "backend:=modbus" in line) for line in lines} == {
            (True, False), (False, False), (False, True)}
        for line in lines:
            run_line(line, devices, topics.pressure_measured_topic(0), FluidPressure, topics.REGULATOR_NODE)
        assert "VENT" in serial.lines and modbus.writes
    finally:
        serial.close()
        modbus.stop()


@pytest.mark.timeout(300)
def test_the_scale_line_runs_as_written():
    scale = SerialScaleEmulator(load=0.1).start()
    try:
        (line,) = lab_lines("scale_node")
        run_line(line, {"port:=/dev/ttyUSB0": [f"port:={scale.port}"]}, topics.BENCH_WRENCH, WrenchStamped,
                 topics.SCALE_NODE)
    finally:
        scale.close()


@pytest.mark.timeout(300)
def test_the_camera_lines_run_as_written(tmp_path, monkeypatch):
    pytest.importorskip("cv2", reason="the vision extra")
    from softcath_ros.bench.tracker_render import write_demo_frames
    from softcath_ros.cli import main

    write_demo_frames(tmp_path / "frames", angles_deg=(0, 90, 180))
    (tmp_path / "frames" / "frame_000.png").rename(tmp_path / "first.png")
    (track,) = lab_lines("softcath track")
    monkeypatch.chdir(tmp_path)
    assert main(track[1:]) == 0
    assert list((tmp_path / "overlay").iterdir())
    (line,) = lab_lines("tracker_node")
    # the camera never ends: its stand-in, the folder, loops
    run_line(line, {"input:=0": [f"input:={tmp_path / 'frames'}", "-p", "loop:=true"]}, topics.BENCH_BEND_ANGLE, Vector3Stamped,
             topics.TRACKER_NODE, cwd=tmp_path)


@pytest.mark.timeout(400)   # the quick protocol as the page runs it: about 90 s
def test_the_first_recording_line_runs_as_written_and_drives_every_managed_node(tmp_path):
    """The three node lines with ``autostart:=false`` (regulator: its sim line; scale: an emulated
    board; camera: a folder of rendered frames), then the characterise line as written:
    characterise configures and activates each node and bench_node, and the run completes."""
    pytest.importorskip("cv2", reason="the vision extra")
    from softcath_ros.bench.tracker_render import write_demo_frames

    write_demo_frames(tmp_path / "frames", angles_deg=(0, 45, 90))
    scale = SerialScaleEmulator(load=0.1).start()
    devices = {"port:=/dev/ttyUSB0": [f"port:={scale.port}"],
               "input:=0": [f"input:={tmp_path / 'frames'}", "-p", "loop:=true"]}
    manual = ["-p", "autostart:=false"]
    [regulator] = [line for line in lab_lines("regulator_node") if "backend:=sim" in line]
    [characterise] = [line for line in lab_lines("softcath characterise") if "--rig" in line]
    node_lines = (regulator, *lab_lines("scale_node"), *lab_lines("tracker_node"))
    logs = [tmp_path / f"{line[0]}.log" for line in node_lines]   # each node's own log, shown on a failure
    try:
        with NodeGraph() as graph, ExitStack() as files:
            procs = [graph.start(line[0], extra_ros_args=[b for a in line[2:] for b in devices.get(a, [a])] + manual,
                                 cwd=ROOT, stdout=files.enter_context(log.open("w")))
                     for line, log in zip(node_lines, logs)]
            graph.wait_ready(*procs, timeout_s=120)
            run = subprocess.run([str(Path(sys.executable).parent / "softcath"), *characterise[1:]], env=graph.env,
                                 cwd=tmp_path, capture_output=True, text=True, timeout=350)
    finally:
        scale.close()
    assert run.returncode == 0, run.stdout + run.stderr + "".join(
        f"\n--- {log.name}\n" + "\n".join(log.read_text().splitlines()[-15:]) for log in logs)
    for node in (topics.REGULATOR_NODE, topics.SCALE_NODE, topics.TRACKER_NODE, topics.BENCH_NODE):
        for transition in ("configure", "activate"):
            assert f"[characterise] {transition} /{node}" in run.stdout, run.stdout
    assert list((tmp_path / "runs").glob("bench_quick_*/*.mcap")) and "report:" in run.stdout
