"""regulator_node and scale_node over DDS against emulated devices (test/hardware_emulators.py):
readings published as the rig contract says, every setpoint clamped, vent on command timeout, on
SIGINT and when the device dies (ERROR on /diagnostics), the lifecycle transitions, tare, and bad
inputs in one line. Margins are generous: what must happen within 0.5 s is checked on the pure
core with a fake clock (test_hardware_core.py); here only that it happens."""
import json
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("serial", reason="the hardware extra (pyserial)")
pytest.importorskip("pymodbus", reason="the hardware extra (pymodbus)")
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from lifecycle_msgs.msg import Transition  # noqa: E402
from sensor_msgs.msg import FluidPressure  # noqa: E402
from std_msgs.msg import Empty, Float64MultiArray, String  # noqa: E402

from hardware_emulators import ModbusRegulatorEmulator, SerialRegulatorEmulator, SerialScaleEmulator, free_port  # noqa: E402
from lifecycle_listener import LifecycleListener  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.graph import NodeGraph  # noqa: E402

MAX = 50000.0        # implemented_5mm's max_pressure, Pa (one channel)
CH0 = topics.pressure_measured_topic(0)


def regulator_listener(graph):
    return LifecycleListener(graph.domain, topics.REGULATOR_NODE, {CH0: FluidPressure})


def command(listener, pascal, seconds, until=None):
    """Publish ``pascal`` at 10 Hz for up to ``seconds`` (or until ``until()``)."""
    pub = getattr(listener, "_cmd_pub", None) or listener.node.create_publisher(Float64MultiArray, topics.PRESSURE_CMD, 100)
    listener._cmd_pub = pub
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pub.publish(Float64MultiArray(data=[float(pascal)]))
        if listener.spin(0.1, until=until):
            return True
    return False


@pytest.mark.timeout(300)
def test_regulator_node_on_a_serial_device_clamps_streams_vents_and_errs_when_it_dies():
    emu = SerialRegulatorEmulator(1).start()
    try:
        with NodeGraph() as graph:
            proc = graph.start("regulator_node", {"backend": "serial", "port": emu.port})
            graph.wait_ready(proc)
            listener = regulator_listener(graph)
            try:
                readings = listener.got[CH0]
                # commanded far above max_pressure: the device is told max_pressure, and says so back
                assert command(listener, 1e6, 60.0, until=lambda: any(r.fluid_pressure == MAX for r in readings))
                assert f"SET 0 {MAX:.0f}" in emu.lines and not any(
                    line.startswith("SET") and float(line.split()[2]) > MAX for line in emu.lines)
                r = readings[-1]
                assert r.header.frame_id == topics.FRAME_ID and 0 < time.time() - (r.header.stamp.sec + r.header.stamp.nanosec * 1e-9) < 60
                # commands stop: the regulator vents by itself (the device still answers)
                n = len(emu.lines)
                assert listener.spin(30.0, until=lambda: "VENT" in emu.lines[n:])
                assert listener.spin(30.0, until=lambda: readings[-1].fluid_pressure == 0.0)
                # the device dies: ERROR on /diagnostics with the reason, and it is told to vent
                assert command(listener, 20000.0, 60.0, until=lambda: readings[-1].fluid_pressure == 20000.0)
                emu.mode = "dead"
                n = len(emu.lines)
                assert command(listener, 20000.0, 30.0, until=lambda: listener.status is not None
                               and listener.status["level"] == DiagnosticStatus.ERROR)
                assert "no valid reading for" in listener.status["message"] and "vented" in listener.status["message"]
                assert listener.status["state"] == "error"
                assert listener.spin(30.0, until=lambda: "VENT" in emu.lines[n:])
            finally:
                listener.close()
            assert graph.stop()["regulator_node"] == 0
            text = proc.stdout.read()
        assert "Traceback" not in text
    finally:
        emu.close()


@pytest.mark.timeout(300)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_regulator_node_vents_on_sigint_and_sigterm(sig):
    emu = SerialRegulatorEmulator(1).start()
    try:
        with NodeGraph() as graph:
            proc = graph.start("regulator_node", {"backend": "serial", "port": emu.port, "command_timeout": 60.0})
            graph.wait_ready(proc)
            listener = regulator_listener(graph)
            try:
                assert command(listener, 30000.0, 60.0, until=lambda: "SET 0 30000" in emu.lines)
            finally:
                listener.close()
            n = len(emu.lines)
            proc.send_signal(sig)
            assert proc.wait(timeout=30) == 0
            end = time.monotonic() + 10
            while "VENT" not in emu.lines[n:] and time.monotonic() < end:
                time.sleep(0.05)
            assert "VENT" in emu.lines[n:], (sig, emu.lines[n:])
    finally:
        emu.close()


@pytest.mark.timeout(300)
def test_regulator_node_lifecycle_on_a_modbus_device():
    port = free_port()
    with NodeGraph() as graph:
        proc = graph.start("regulator_node", {"backend": "modbus", "modbus_host": "127.0.0.1", "modbus_port": port,
                                              "setpoint_registers": [0], "reading_registers": [100],
                                              "setpoint_pa_per_count": 10.0, "reading_pa_per_count": 10.0,
                                              "autostart": False})
        graph.wait_ready(proc)
        listener = LifecycleListener(graph.domain, topics.REGULATOR_NODE, {CH0: FluidPressure, topics.BENCH_RIG: String})
        emu = None
        try:
            assert listener.state() == "unconfigured"
            assert not listener.transition(Transition.TRANSITION_CONFIGURE)      # nothing listens there yet
            assert listener.spin(10.0, until=lambda: listener.status and listener.status["level"] == DiagnosticStatus.ERROR)
            assert f"cannot connect to Modbus TCP 127.0.0.1:{port}" in listener.status["message"]
            emu = ModbusRegulatorEmulator(1, port=port)
            assert listener.transition(Transition.TRANSITION_CONFIGURE)
            assert listener.state() == "inactive"
            assert listener.spin(30.0, until=lambda: listener.got[topics.BENCH_RIG])    # what the recording will say
            rig = json.loads(listener.got[topics.BENCH_RIG][-1].data)
            assert rig["simulated"] is False and rig["backend"] == "modbus" and rig["device"] == f"modbus:127.0.0.1:{port}/1"
            assert not command(listener, 20000.0, 1.0, until=lambda: listener.got[CH0])   # configured: no stream
            assert listener.transition(Transition.TRANSITION_ACTIVATE)
            assert command(listener, 20000.0, 60.0, until=lambda: listener.got[CH0]
                           and listener.got[CH0][-1].fluid_pressure == 20000.0)
            assert (0, 2000) in emu.writes                                   # 10 Pa per count
            n = len(emu.writes)
            assert listener.transition(Transition.TRANSITION_DEACTIVATE)      # vents
            assert emu.writes[n:] and emu.writes[-1] == (0, 0)
            assert listener.state() == "inactive"
        finally:
            listener.close()
            if emu is not None:
                emu.stop()
        assert graph.stop()["regulator_node"] == 0


@pytest.mark.timeout(300)
def test_scale_node_publishes_the_force_tares_errs_while_silent_and_recovers():
    emu = SerialScaleEmulator(load=0.3).start()
    try:
        with NodeGraph() as graph:
            proc = graph.start("scale_node", {"port": emu.port})
            graph.wait_ready(proc)
            listener = LifecycleListener(graph.domain, topics.SCALE_NODE, {topics.BENCH_WRENCH: WrenchStamped})
            try:
                forces = listener.got[topics.BENCH_WRENCH]
                assert listener.spin(30.0, until=lambda: len(forces) >= 5)
                w = forces[-1]
                assert w.wrench.force.z == pytest.approx(0.3) and w.header.frame_id == topics.SCALE_FRAME_ID
                tare = listener.node.create_publisher(Empty, topics.BENCH_TARE, 10)
                end = time.monotonic() + 30
                while emu.tares == 0 and time.monotonic() < end:
                    tare.publish(Empty())
                    listener.spin(0.2)
                assert emu.tares >= 1
                assert listener.spin(30.0, until=lambda: forces[-1].wrench.force.z == 0.0)
                emu.mode = "nan"                                   # lies: refused, then silent -> ERROR
                assert listener.spin(30.0, until=lambda: listener.status is not None
                                     and listener.status["level"] == DiagnosticStatus.ERROR)
                assert int(listener.status["refused"]) >= 1
                assert all(f.wrench.force.z == f.wrench.force.z for f in forces)     # no NaN published
                seen = len(forces)
                emu.mode = "ok"                                    # speaks again: forces, WARN counting it
                assert listener.spin(30.0, until=lambda: len(forces) > seen and listener.status["level"]
                                     == DiagnosticStatus.WARN and listener.status["silences"] == "1")
                assert "1 silence(s), the last: serial:" in listener.status["message"]
            finally:
                listener.close()
            assert graph.stop()["scale_node"] == 0
    finally:
        emu.close()


@pytest.mark.parametrize("node, params, words", [
    ("regulator_node", {"backend": "serial", "port": "/nonexistent/tty"}, "cannot open serial port /nonexistent/tty"),
    ("regulator_node", {"backend": "canbus"}, "backend = 'canbus': not one of"),
    ("regulator_node", {"backend": "modbus", "setpoint_registers": [0, 1]}, "2 setpoint register(s) for 1 channels"),
    ("regulator_node", {"max_pressure": 1e6}, "max_pressure"),
    ("scale_node", {"port": "/nonexistent/tty"}, "cannot open serial port /nonexistent/tty"),
    ("scale_node", {"max_forse": 1.0}, "'max_forse' (did you mean 'max_force'?)"),
])
def test_bad_inputs_end_the_node_in_one_line(node, params, words):
    cmd = [sys.executable, "-m", f"softcath_ros.nodes.{node}", "--ros-args"]
    for k, v in params.items():
        cmd += ["-p", f"{k}:={v}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in proc.stderr, proc.stderr


def test_shipped_params_files_set_only_declared_parameters():
    """As test_node_parameters does for the other nodes (autostart off: no device here)."""
    from softcath_ros.core.yaml_io import load_yaml_file
    from softcath_ros.nodes.regulator_node import RegulatorNode
    from softcath_ros.nodes.scale_node import ScaleNode
    from softcath_ros.resources import find

    for name, cls in (("regulator_node", RegulatorNode), ("scale_node", ScaleNode)):
        path = find("params", name)
        (node_key, body), = load_yaml_file(path).items()
        context = rclpy.Context()
        rclpy.init(context=context, args=["--ros-args", "--params-file", str(path), "-p", "autostart:=false"])
        node = cls(context=context)
        try:
            assert node.get_name() == node_key
            for key, value in body["ros__parameters"].items():
                got = node.get_parameter(key).value
                assert got == (pytest.approx(value) if isinstance(value, float) else value), key
        finally:
            node.destroy_node()
            rclpy.shutdown(context=context)
