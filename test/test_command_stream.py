"""The pressure stream's freshness rule, keep-alive and supersede rule (core/command_shaping.py),
on a fake clock: no ROS, no wall-clock windows."""
import numpy as np
import pytest

from softcath_ros.core.command_shaping import (KEEP_ALIVE_PERIOD, SUPERSEDE_AGE, CommandWatchdog, PressureStream,
                                               is_superseded)

FULL = np.array([44000.0, 0.0, 0.0])   # Pa: a saturated command of the 3-channel design
RATE = 2.0e5                            # Pa/s
TIMEOUT = 0.5                           # s
RAMP = FULL.max() / RATE                # 0.22 s from full pressure to zero
RIG_TIMEOUT = 0.5                       # s: the rig contract's watchdog (docs/rig.md)


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _backlog_run(allocation_s: float, command_hz: float, seconds: float, drain: bool):
    """A node that handles queued commands one by one (each allocation takes ``allocation_s``;
    fresh commands only) and ticks every 5 ms when none waits. Returns (time of the last command's
    arrival, [(t, output)])."""
    clock = FakeClock()
    stream = PressureStream(3, RATE, TIMEOUT, clock)
    arrivals = list(np.arange(0.0, seconds, 1.0 / command_hz))
    outputs, i = [], 0
    while clock.t < seconds + 3.0:
        waiting = [a for a in arrivals[i:] if a <= clock.t]
        if waiting:
            if drain:                       # take every waiting command, allocate the newest
                i += len(waiting)
                arrived = waiting[-1]
            else:
                arrived = arrivals[i]
                i += 1
            if stream.fresh(arrived):
                clock.t += allocation_s
                stream.command(FULL, arrived)
                outputs.append((clock.t, stream.output(force=True)))
        else:
            clock.t += 0.005
            out = stream.output()
            if out is not None:
                outputs.append((clock.t, out))
    return arrivals[-1], outputs


@pytest.mark.parametrize("drain", [False, True], ids=["one_by_one", "newest"])
def test_a_backlog_never_holds_pressure_past_timeout_plus_ramp(drain):
    """Saturating commands at 100 Hz for 1 s, each allocation taking 15 ms: the queue grows by a
    third of the stream. Whatever the backlog, pressure is held at most until the last command's
    arrival + timeout and is zero by + timeout + ramp (one 5 ms tick of slack)."""
    last, outputs = _backlog_run(0.015, 100.0, 1.0, drain)
    after_vent = [out for t, out in outputs if t > last + TIMEOUT + RAMP + 0.005]
    assert after_vent and all(np.all(out == 0.0) for out in after_vent)
    held = [out for t, out in outputs if t > last + TIMEOUT + 0.005]
    assert all(out[0] < FULL[0] for out in held)        # ramping down from the timeout on
    # and not vented early: full pressure is still out shortly before the timeout
    before = [out for t, out in outputs if last + 0.1 < t < last + TIMEOUT - 0.01]
    assert before and all(np.array_equal(out, FULL) for out in before)


def test_a_stale_command_is_dropped_and_counted():
    clock = FakeClock()
    stream = PressureStream(3, RATE, TIMEOUT, clock)
    clock.t = 10.0
    assert not stream.command(FULL, arrived=10.0 - TIMEOUT - 1e-3)
    assert stream.dropped == 1 and stream.vented
    assert stream.command(FULL, arrived=10.0 - TIMEOUT + 1e-3) and not stream.vented
    assert stream.watchdog.last_feed == pytest.approx(10.0 - TIMEOUT + 1e-3)   # from arrival, not now
    clock.t = 10.0 + 2e-3
    assert stream.check_watchdog() and stream.vented


def test_an_idle_stream_sends_at_the_keep_alive_rate_which_satisfies_the_rig_watchdog():
    """No command for 10 s, ticked at 200 Hz: one message per keep-alive period, never a gap the
    rig's watchdog would vent on (it tolerates several lost messages in a row)."""
    assert KEEP_ALIVE_PERIOD <= RIG_TIMEOUT / 4
    clock = FakeClock()
    stream = PressureStream(3, RATE, TIMEOUT, clock)
    sent = []
    for k in range(2000):
        clock.t = k * 0.005
        out = stream.output()
        if out is not None:
            sent.append(clock.t)
            assert np.all(out == 0.0)
    assert len(sent) == pytest.approx(10.0 / KEEP_ALIVE_PERIOD, abs=2)
    assert max(np.diff(sent)) <= KEEP_ALIVE_PERIOD + 0.005


def test_a_ramp_goes_out_every_tick_and_a_held_target_at_the_keep_alive_rate():
    clock = FakeClock()
    stream = PressureStream(3, RATE, TIMEOUT, clock)
    stream.command(FULL, arrived=0.0)
    sent = []
    for k in range(1, 61):                  # 0.3 s at 200 Hz: 0.22 s of ramp, then held
        clock.t = k * 0.005
        stream.command(FULL, arrived=clock.t)
        out = stream.output()
        if out is not None:
            sent.append((clock.t, out[0]))
    ramp = [t for t, p in sent if p < FULL[0]]
    assert len(ramp) == pytest.approx(RAMP / 0.005, abs=1)   # every tick while ramping
    held = [t for t, p in sent if p == FULL[0]]
    assert len(held) <= 2                                     # then the keep-alive only


def test_the_watchdog_counts_from_the_newest_arrival():
    dog = CommandWatchdog(0.5)
    assert dog.expired(0.0)
    dog.feed(1.0)
    dog.feed(0.8)          # handled out of order: does not move the timeout back
    assert not dog.expired(1.5) and dog.expired(1.5001)
    assert dog.fresh(1.0, 1.5) and not dog.fresh(1.0, 1.5001)


def test_only_a_stale_command_is_superseded():
    """Superseded: waited longer than the stated age while a newer one waits. The newest never is."""
    assert not is_superseded(0.0, SUPERSEDE_AGE * 0.9, newer_waiting=True)
    assert is_superseded(0.0, SUPERSEDE_AGE * 1.1, newer_waiting=True)
    assert not is_superseded(0.0, 100.0, newer_waiting=False)
