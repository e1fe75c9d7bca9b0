"""The serial and Modbus backends against emulated devices (test/hardware_emulators.py), driven by
the regulator's state machine on a fake clock: a pseudo-terminal for the serial line protocol and a
pymodbus server on 127.0.0.1 for Modbus TCP, each with a device that dies, lies or floods. Real I/O,
but no wall-clock window: each step waits (generously) for bytes to arrive, then the fake clock says
what time it is."""
import time

import pytest

pytest.importorskip("serial", reason="the hardware extra (pyserial)")
pytest.importorskip("pymodbus", reason="the hardware extra (pymodbus)")

from hardware_emulators import ModbusRegulatorEmulator, SerialRegulatorEmulator, SerialScaleEmulator  # noqa: E402
from softcath_ros.bench.hardware import protocol  # noqa: E402
from softcath_ros.bench.hardware.devices import ModbusRegulator, RegisterMap, SerialLines  # noqa: E402
from softcath_ros.bench.hardware.protocol import Reading, Refused  # noqa: E402
from softcath_ros.bench.hardware.regulator import Regulator  # noqa: E402
from softcath_ros.bench.hardware.scale import Scale  # noqa: E402

MAX = 50000.0
WAIT = 20.0          # s: the most any byte may take to cross the pty on a loaded machine


class FakeClock:
    def __init__(self):
        self.t = 0.0
        self.first_sleep = None     # called once at configure's first wait (the port is open then)

    def __call__(self):
        return self.t

    def sleep(self, dt):
        if self.first_sleep is not None:
            self.first_sleep()
            self.first_sleep = None
            time.sleep(0.05)        # (real bytes still need a moment to arrive)
        self.t += dt
        time.sleep(0.001)


def until(condition, what):
    end = time.monotonic() + WAIT
    while time.monotonic() < end:
        got = condition()
        if got:
            return got
        time.sleep(0.002)
    raise AssertionError(f"no {what} within {WAIT} s")


@pytest.fixture
def pty_regulator():
    emulator = SerialRegulatorEmulator(2)
    yield emulator
    emulator.close()


def serial_regulator(emulator, clock, **kw):
    device = SerialLines(emulator.port, 115200, "P", 2, -20000.0, 2 * MAX)
    return device, Regulator(device, 2, MAX, clock, **kw)


def test_the_serial_backend_speaks_the_line_protocol_over_a_pty(pty_regulator):
    emu, clock = pty_regulator, FakeClock()
    device, reg = serial_regulator(emu, clock)
    clock.first_sleep = lambda: emu.say("P 0 0\n")
    assert not reg.configure(clock.sleep) and "channel(s) [1]" in reg.reason     # channel 1 never answered
    clock.first_sleep = lambda: emu.say("P 0 0\nP 1 0\n")
    assert reg.configure(clock.sleep), reg.reason
    assert "VENT" in until(emu.heard, "VENT")
    reg.activate()
    reg.command([12345.4, 1e9], clock())            # the second is clamped to max_pressure
    clock.t += 0.02
    reg.tick()
    assert until(emu.heard, "setpoints") == ["SET 0 12345", f"SET 1 {MAX:.0f}"]
    emu.say("P 0 12000\nP 1 nan\nP 1 49000\nERR valve 1 hot\n")
    got = until(lambda: reg.tick(), "readings")
    assert got == [Reading(0, 12000.0), Reading(1, 49000.0)]
    assert reg.counters.refused == 1 and reg.counters.device_errors == 1 and reg.counters.last_device_error == "valve 1 hot"
    reg.close()
    assert "VENT" in until(emu.heard, "VENT on close")


def test_a_serial_device_that_dies_is_vented_and_in_error(pty_regulator):
    emu, clock = pty_regulator, FakeClock()
    device, reg = serial_regulator(emu, clock)
    clock.first_sleep = lambda: emu.say("P 0 0\nP 1 0\n")
    assert reg.configure(clock.sleep)
    reg.activate()
    emu.heard()
    os_close = __import__("os").close
    os_close(emu.master)                           # the board is unplugged
    os_close(emu._slave)
    for _ in range(30):
        clock.t += 0.02
        reg.tick()
    assert reg.state == "error" and "no valid reading" in reg.reason


def test_a_serial_device_that_floods_is_bounded_and_lies_are_refused(pty_regulator):
    emu, clock = pty_regulator, FakeClock()
    device, reg = serial_regulator(emu, clock)
    clock.first_sleep = lambda: emu.say("P 0 0\nP 1 0\n")
    assert reg.configure(clock.sleep)
    reg.activate()
    emu.say("P 0 100\nP 1 200\n" * 2000)          # 24 kB at once
    emu.say("\xff" * 5000 + "\n")                  # and an endless line of garbage
    polls, readings = 0, []
    while True:
        emu.flush()
        clock.t += 0.001
        got = reg.tick()
        polls += 1
        readings += got
        if reg.counters.readings >= 4000:
            break
        assert polls < 100000
    assert len(device.lines.buffer) <= protocol.MAX_LINE
    assert {r.value for r in readings} == {100.0, 200.0} and polls >= 24000 // 4096
    until(lambda: (emu.flush(), reg.tick(), reg.counters.refused)[2] >= 1, "the overlong line refused")
    assert reg.state == "active"
    emu.say("P 0 nan\nP 1 inf\nP 0 -99999\nP 1 1e12\nP 7 5\n")
    until(lambda: (reg.tick(), reg.counters.refused)[1] >= 6, "the lies refused")
    assert reg.tick() == []


def test_the_serial_scale_tares_and_refuses_lies():
    emu, clock = SerialScaleEmulator(load=0.25), FakeClock()
    try:
        scale = Scale(SerialLines(emu.port, 115200, "F", 1, -5.0, 5.0), clock)
        clock.first_sleep = lambda: emu.say("F 0.25\n")
        assert scale.configure(clock.sleep)
        scale.activate()
        assert scale.tare()
        assert until(emu.heard, "TARE") == ["TARE"]
        emu.say("F nan\nF 9\nF 0.00010\n")
        got = until(scale.tick, "a force")
        assert got == Reading(0, 0.0001) and scale.counters.refused == 2
    finally:
        emu.close()


# -- Modbus TCP ------------------------------------------------------------------------------------------
@pytest.fixture
def modbus():
    emulator = ModbusRegulatorEmulator(2)
    yield emulator
    emulator.stop()


def modbus_regulator(emu, clock):
    regs = RegisterMap(setpoints=(0, 1), readings=(100, 101), setpoint_pa_per_count=10.0, reading_pa_per_count=10.0)
    device = ModbusRegulator("127.0.0.1", emu.port, regs, 2, -20000.0, 2 * MAX, timeout=0.5)
    return device, Regulator(device, 2, MAX, clock)


def test_the_modbus_backend_writes_scaled_setpoints_and_reads_scaled_pressures(modbus):
    clock = FakeClock()
    device, reg = modbus_regulator(modbus, clock)
    assert reg.configure(clock.sleep), reg.reason
    assert modbus.writes[:2] == [(0, 0), (1, 0)]            # vented first
    reg.activate()
    reg.command([12340.0, 1e9], clock())
    clock.t += 0.02
    reg.tick()
    assert modbus.writes[-2:] == [(0, 1234), (1, 5000)]     # 10 Pa per count, clamped to max_pressure
    clock.t += 0.02
    assert reg.tick() == [Reading(0, 12340.0), Reading(1, MAX)]
    modbus.mode = "range"                                    # lies: 65535 counts = 655 kPa
    for _ in range(30):
        clock.t += 0.02
        assert reg.tick() == []
    assert reg.state == "error" and reg.counters.refused >= 50 and "outside" in reg.counters.last_refused
    reg.close()


def test_a_modbus_device_that_dies_is_in_error_within_half_a_second(modbus):
    clock = FakeClock()
    device, reg = modbus_regulator(modbus, clock)
    assert reg.configure(clock.sleep)
    reg.activate()
    clock.t += 0.02
    assert len(reg.tick()) == 2
    modbus.stop()
    dead = clock()
    while reg.state == "active":
        clock.t += 0.02
        assert reg.tick() == []
    assert 0.4 < clock() - dead <= 0.42 + 1e-9 and "modbus:127.0.0.1" in reg.reason
    reg.close()


def test_modbus_configure_fails_in_one_line_when_nothing_listens():
    from hardware_emulators import free_port

    clock = FakeClock()
    regs = RegisterMap(setpoints=(0,), readings=(100,))
    reg = Regulator(ModbusRegulator("127.0.0.1", free_port(), regs, 1, 0.0, MAX), 1, MAX, clock)
    assert not reg.configure(clock.sleep)
    assert reg.reason.startswith("cannot connect to Modbus TCP 127.0.0.1:") and "\n" not in reg.reason


def test_serial_configure_fails_in_one_line_on_a_missing_port(tmp_path):
    clock = FakeClock()
    reg = Regulator(SerialLines(str(tmp_path / "ttyNONE"), 115200, "P", 1, 0.0, MAX), 1, MAX, clock)
    assert not reg.configure(clock.sleep)
    assert reg.reason.startswith(f"cannot open serial port {tmp_path / 'ttyNONE'} at 115200 baud") and "\n" not in reg.reason
