"""The hardware core without ROS or devices: the serial line protocol refuses what is malformed,
non-finite or out of range; the regulator's state machine on a fake clock clamps every setpoint,
vents on command timeout, on deactivate and close, and when the device stops giving valid readings
for 0.4 s (ERROR within 0.5 s); configure checks that every channel answers; the scale's tare and silence."""
import math

import numpy as np
import pytest

from softcath_ros.bench.hardware import protocol
from softcath_ros.bench.hardware.devices import DeviceFault, RegisterMap
from softcath_ros.bench.hardware.protocol import DeviceError, LineSplitter, Reading, Refused, parse_line
from softcath_ros.bench.hardware.regulator import Regulator
from softcath_ros.bench.hardware.scale import Scale

MAX = 50000.0


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t

    def sleep(self, dt):
        self.t += dt


class FakeDevice:
    """Answers each poll with ``answer()`` (default: one reading per channel at its setpoint)."""
    name = "fake"

    def __init__(self, n=2, fail_open=False):
        self.n, self.fail_open = n, fail_open
        self.setpoints = np.zeros(n)
        self.log = []                  # ("send", values) / ("vent",) / ("open",) / ("close",)
        self.answer = lambda: [Reading(c, float(p)) for c, p in enumerate(self.setpoints)]

    def open(self):
        if self.fail_open:
            raise DeviceFault("cannot open serial port /dev/nothing")
        self.log.append(("open",))

    def send(self, p):
        self.setpoints = np.array(p, dtype=float)
        self.log.append(("send", tuple(float(x) for x in p)))

    def vent(self):
        self.setpoints[:] = 0
        self.log.append(("vent",))

    def tare(self):
        self.log.append(("tare",))

    def poll(self):
        return self.answer()

    def close(self):
        self.log.append(("close",))

    def sends(self):
        return [e[1] for e in self.log if e[0] == "send"]


def active(n=2, **kw):
    clock, dev = FakeClock(), FakeDevice(n)
    reg = Regulator(dev, n, MAX, clock, **kw)
    assert reg.configure(clock.sleep) and reg.state == "inactive"
    reg.activate()
    return clock, dev, reg


def run(clock, reg, seconds, dt=0.02):
    out = []
    for _ in range(round(seconds / dt)):
        clock.t += dt
        out += reg.tick()
    return out


# -- the line protocol -------------------------------------------------------------------------------
@pytest.mark.parametrize("line, expected", [
    ("P 0 1234", Reading(0, 1234.0)),
    ("P 1 -50.5\r", Reading(1, -50.5)),
    ("ERR sensor 1 outside its range", DeviceError("sensor 1 outside its range")),
])
def test_the_parser_takes_well_formed_lines(line, expected):
    assert parse_line(line, "P", 2, -20000.0, 2 * MAX) == expected


@pytest.mark.parametrize("line, why", [
    ("P 0 nan", "not a finite number"), ("P 0 inf", "not a finite number"), ("P 0 -inf", "not a finite number"),
    ("P 0 1e9", "outside"), ("P 0 -30000", "outside"), ("P 2 100", "channel 2"), ("P -1 100", "channel"),
    ("P 0", "not 'P <ch> <Pa>'"), ("P 0 12 13", "not 'P"), ("Q 0 12", "not 'P"), ("P 0 12abc", "not a finite"),
    ("", "not 'P"), ("P 0 " + "1" * 90, "longer than"), ("F 0.5", "not 'P"),
])
def test_the_parser_refuses_malformed_non_finite_and_out_of_range_lines(line, why):
    got = parse_line(line, "P", 2, -20000.0, 2 * MAX)
    assert isinstance(got, Refused) and why in got.reason, got


def test_the_scale_lines_and_host_commands():
    assert parse_line("F -0.0125", "F", 1, -5.0, 5.0) == Reading(0, -0.0125)
    assert isinstance(parse_line("F 7", "F", 1, -5.0, 5.0), Refused)
    assert isinstance(parse_line("F NaN", "F", 1, -5.0, 5.0), Refused)
    assert protocol.format_set(1, 12345.6) == b"SET 1 12346\n"
    assert protocol.VENT == b"VENT\n" and protocol.TARE == b"TARE\n"


def test_a_flood_without_newlines_never_grows_the_buffer():
    s = LineSplitter()
    for _ in range(1000):
        assert s.feed(b"x" * 997) == []
        assert len(s.buffer) <= protocol.MAX_LINE
    assert s.overlong >= 1000 * 997 // (protocol.MAX_LINE + 997)
    assert s.feed(b"\nP 0 5\n")[-1] == "P 0 5"


def test_lines_split_across_reads_are_joined():
    s = LineSplitter()
    assert s.feed(b"P 0 1") == [] and s.feed(b"23\nP 1") == ["P 0 123"] and s.feed(b" 4\n") == ["P 1 4"]


# -- configure ----------------------------------------------------------------------------------------
def test_configure_opens_vents_and_needs_every_channel_to_answer():
    clock, dev, reg = active()
    assert dev.log[:2] == [("open",), ("vent",)]


def test_configure_fails_when_a_channel_stays_silent_and_says_which():
    clock, dev = FakeClock(), FakeDevice(3)
    dev.answer = lambda: [Reading(0, 0.0), Refused("P 2 nan", "value 'nan' is not a finite number")]
    reg = Regulator(dev, 3, MAX, clock, check_timeout=2.0)
    t0 = clock.t
    assert not reg.configure(clock.sleep) and reg.state == "unconfigured"
    assert "channel(s) [1, 2] within 2 s" in reg.reason and "nan" in reg.reason
    assert 2.0 <= clock.t - t0 < 2.1
    assert dev.log[-2:] == [("vent",), ("close",)]


def test_configure_fails_in_one_line_when_the_device_cannot_open():
    clock = FakeClock()
    reg = Regulator(FakeDevice(fail_open=True), 2, MAX, clock)
    assert not reg.configure(clock.sleep) and reg.reason == "cannot open serial port /dev/nothing"


# -- active ---------------------------------------------------------------------------------------------
def test_every_setpoint_is_clamped_to_max_pressure_and_zero():
    clock, dev, reg = active()
    assert reg.command([1e9, -5.0], clock()) == "clamped"
    run(clock, reg, 0.04)
    assert dev.sends()[-1] == (MAX, 0.0)
    assert reg.counters.clamped == 1


@pytest.mark.parametrize("bad", [[1000.0], [1000.0, math.nan], [1000.0, math.inf], [1.0, 2.0, 3.0]])
def test_a_wrong_or_non_finite_command_is_refused_and_not_applied(bad):
    clock, dev, reg = active()
    assert reg.command([2000.0, 3000.0], clock()) == "ok"
    run(clock, reg, 0.04)
    assert reg.command(bad, clock()) == "rejected"
    run(clock, reg, 0.2)
    assert set(dev.sends()) <= {(0.0, 0.0), (2000.0, 3000.0)} and dev.sends()[-1] == (2000.0, 3000.0)
    assert reg.counters.rejected == 1


def test_it_vents_at_once_when_commands_stop_for_command_timeout():
    clock, dev, reg = active(command_timeout=0.5, max_rate=10.0)   # (a slow ramp: the vent does not wait for it)
    for _ in range(110):                                          # reaches 100 Pa at 10 Pa/s
        reg.command([100.0, 100.0], clock())
        run(clock, reg, 0.1)
    assert dev.sends()[-1] == pytest.approx((100.0, 100.0))
    reg.command([100.0, 100.0], clock())
    t_last = clock()
    n = len(dev.log)
    for _ in range(100):
        clock.t += 0.02
        reg.tick()
        if ("vent",) in dev.log[n:]:
            break
    assert 0.5 < clock() - t_last <= 0.52 + 1e-9
    assert reg.counters.timeouts == 1
    run(clock, reg, 0.2)
    assert all(s == (0.0, 0.0) for s in dev.sends()[-2:])        # stays vented


def test_a_command_older_than_the_timeout_is_not_applied():
    clock, dev, reg = active()
    assert reg.command([1000.0, 1000.0], clock() - 0.6) == "stale"
    run(clock, reg, 0.1)
    assert all(s == (0.0, 0.0) for s in dev.sends()) and reg.counters.stale == 1


def test_an_unchanged_command_is_re_sent_every_keep_alive():
    clock, dev, reg = active()
    for _ in range(10):                      # 1 s of ticks at 50 Hz, commands at 10 Hz
        reg.command([500.0, 600.0], clock())
        run(clock, reg, 0.1)
    assert 10 <= len(dev.sends()) <= 12      # not 50: once per keep_alive (0.1 s)


def test_readings_come_back_newest_per_channel_and_a_flood_is_counted():
    clock, dev, reg = active()
    dev.answer = lambda: [Reading(c % 2, float(c)) for c in range(1000)]
    clock.t += 0.02
    assert reg.tick() == [Reading(0, 998.0), Reading(1, 999.0)]
    assert reg.counters.superseded == 998


def test_a_device_that_goes_silent_is_vented_and_in_error_within_half_a_second():
    clock, dev, reg = active()
    reg.command([20000.0, 20000.0], clock())
    run(clock, reg, 0.2)
    dev.answer = list                                 # dies
    t_dead = clock()
    n = len(dev.log)
    while reg.state == "active":
        clock.t += 0.02
        reg.tick()
        assert clock() - t_dead < 1.0
    assert 0.4 < clock() - t_dead <= 0.42 + 1e-9             # at 50 Hz ticks: within 0.5 s
    assert ("vent",) in dev.log[n:] and "no valid reading for 0.4" in reg.reason
    reg.command([20000.0, 20000.0], clock())           # latched: commands do nothing, it keeps venting
    n = len(dev.log)
    run(clock, reg, 0.5)
    assert dev.sends()[-1] == (0.0, 0.0) and not [e for e in dev.log[n:] if e[0] == "send"]
    assert ("vent",) in dev.log[n:]


@pytest.mark.parametrize("lie", [Refused("P 0 nan", "nan"), Refused("P 0 1e9", "out of range"), DeviceError("valve")])
def test_a_device_that_only_lies_counts_as_silent(lie):
    clock, dev, reg = active()
    dev.answer = lambda: [lie]
    out = run(clock, reg, 0.6)
    assert out == [] and reg.state == "error"
    assert reg.counters.refused + reg.counters.device_errors >= 25


def test_deactivate_and_close_vent():
    clock, dev, reg = active()
    reg.command([20000.0, 20000.0], clock())
    run(clock, reg, 0.1)
    reg.deactivate()
    assert dev.log[-1] == ("vent",) and reg.state == "inactive" and reg.tick() == []
    reg.close()
    assert dev.log[-2:] == [("vent",), ("close",)] and reg.state == "unconfigured"


def test_a_command_from_before_activation_is_not_applied():
    clock, dev, reg = active()
    reg.command([20000.0, 20000.0], clock())
    reg.deactivate()
    reg.activate()
    run(clock, reg, 0.1)
    assert dev.sends() == [] or set(dev.sends()) == {(0.0, 0.0)}


# -- the register map ------------------------------------------------------------------------------------
def test_the_register_map_scales_and_checks():
    m = RegisterMap(setpoints=(0, 1), readings=(100, 101), setpoint_pa_per_count=100.0, reading_pa_per_count=10.0,
                    reading_offset_pa=-500.0, signed=True)
    m.check(2)
    assert m.counts(12345.0) == 123 and m.counts(-5.0) == 0 and m.counts(1e12) == 65535
    assert m.pascal(100) == 500.0 and m.pascal(65535) == -510.0
    with pytest.raises(DeviceFault, match="1 setpoint register"):
        RegisterMap(setpoints=(0,), readings=(1, 2)).check(2)
    with pytest.raises(DeviceFault, match="reading_kind"):
        RegisterMap(setpoints=(0,), readings=(1,), reading_kind="coil").check(1)


# -- the scale ----------------------------------------------------------------------------------------------
def test_the_scale_publishes_the_newest_force_tares_errs_while_silent_and_recovers():
    clock, dev = FakeClock(), FakeDevice(1)
    forces = iter([[Reading(0, 0.01)]] + [[Reading(0, 0.02), Reading(0, 0.03)]] * 10)
    dev.answer = lambda: next(forces, [])
    scale = Scale(dev, clock)
    assert not scale.tare()                    # not configured: nothing sent
    assert scale.configure(clock.sleep)
    scale.activate()
    clock.t += 0.01
    assert scale.tick() == Reading(0, 0.03) and scale.counters.superseded == 1
    assert scale.tare() and dev.log[-1] == ("tare",)
    while scale.state == "active":
        clock.t += 0.01
        scale.tick()
    assert scale.state == "error" and "no valid reading" in scale.reason and scale.silences == 1
    clock.t += 0.01
    assert scale.tick() is None and scale.state == "error"          # still silent: nothing published
    dev.answer = lambda: [Reading(0, 0.04)]                          # the board speaks again
    clock.t += 0.01
    assert scale.tick() == Reading(0, 0.04) and scale.state == "active" and scale.silences == 1


def test_the_scale_refuses_to_configure_on_lies():
    clock, dev = FakeClock(), FakeDevice(1)
    dev.answer = lambda: [Refused("F nan", "value 'nan' is not a finite number")]
    scale = Scale(dev, clock, check_timeout=1.0)
    assert not scale.configure(clock.sleep) and "no valid force reading within 1 s" in scale.reason
    assert dev.log[-1] == ("close",)


# -- the sim backend ------------------------------------------------------------------------------------------
def test_the_sim_backend_is_the_simulated_rigs_regulator_and_gauge():
    from softcath_ros.bench.hardware.devices import SimRegulator
    from softcath_ros.bench.sim_rig import RigParams

    clock = FakeClock()
    device = SimRegulator("implemented_5mm", clock, seed=3)
    reg = Regulator(device, 1, MAX, clock)
    assert reg.configure(clock.sleep) and device.name == "simulated"
    reg.activate()
    got = []
    for _ in range(50):                                       # 1 s at 50 Hz, commands at 10 Hz
        reg.command([1e9], clock())                           # clamped to max_pressure
        got += run(clock, reg, 0.1)
    tau, bound = RigParams().regulator_time_constant, RigParams().gauge_error + 5 * RigParams().gauge_noise
    assert 1.0 > 10 * tau and abs(got[-1].value - MAX) < bound           # settled at max_pressure, within the gauge
    assert abs(got[0].value) < bound                                      # read before the first setpoint went out
    assert abs(got[1].value - MAX * (1 - math.exp(-0.02 / tau))) < bound  # then one 20 ms step of the first-order lag

