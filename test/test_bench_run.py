"""The bench run's state machine (bench/bench_run.py) on a fake clock: no ROS, no wall-clock windows."""
import numpy as np
import pytest

from softcath_ros.bench.bench_run import (ABORT_VENT_S, EXIT_FIGHT, EXIT_NO_RIG, EXIT_RECORDING, EXIT_RIG_LOST,
                                          VENT_S, Begin, BenchRun, Command, Markers, RunState, Say, Vent,
                                          VentDirectly)
from softcath_ros.bench.protocol import ProtocolRunner, expand_steps, load_protocol
from softcath_ros.bench.rig_contract import FollowCheck, follow_test_command

DT = 0.02   # the node's 50 Hz tick


class FakeRig:
    """A perfect regulator behind the RigView the node offers: it reads back the last command."""

    def __init__(self, n=1):
        self.missing = {}
        self.stale_topics = {}
        self.pressures = np.zeros(n)
        self.error = None
        self.others = []
        self.asked_stale = []

    def problems(self):
        return dict(self.missing)

    def stale(self, lost_after):
        self.asked_stale.append(lost_after)
        return dict(self.stale_topics)

    def measured(self):
        return self.pressures.copy()

    def recording_error(self):
        return self.error

    def other_commanders(self):
        return list(self.others)


def _run(n_steps=3, by_direction=False, wait_timeout=20.0, start_delay=1.0, lost_after=1.0):
    p = load_protocol("quick")
    steps = expand_steps(p, 1, 50000.0)[:n_steps]
    test_pressures, bend = follow_test_command(steps, 5000.0)
    return BenchRun(ProtocolRunner(p, steps), FollowCheck(test_pressures, timeout=3.0), bend, 1, by_direction,
                    wait_timeout, start_delay, lost_after)


def _advance(run, rig, t, until, on_begin=True):
    """Tick every DT from ``t`` while ``until(run)`` is false; the actions and the time reached."""
    actions = []
    while not until(run):
        t = round(t + DT, 9)
        out = run.tick(t, rig)
        for a in out:
            if isinstance(a, Command):
                rig.pressures = np.asarray(a.pressures, dtype=float)
            elif isinstance(a, Vent):
                rig.pressures = np.zeros_like(rig.pressures)
            elif isinstance(a, Begin) and on_begin:
                out += run.begin(t)
        actions += out
        assert t < 600, run.state
    return actions, t


def test_the_run_starts_start_delay_after_the_rig_is_ready_and_restarts_the_wait_on_a_problem():
    run, rig = _run(), FakeRig()
    rig.missing = {"/softcath/bench/bend_angle": "no publisher"}
    actions, t = _advance(run, rig, 0.0, lambda r: r.t_last_tick >= 5.0)
    assert run.state is RunState.WAITING and actions == []
    rig.missing = {}
    actions, t_ready = _advance(run, rig, t, lambda r: r.t_ready is not None)
    rig.missing = {"/softcath/pressure_cmd": "nothing subscribes"}   # a problem before start_delay
    _advance(run, rig, t_ready, lambda r: r.t_last_tick >= t_ready + 0.5)
    assert run.t_ready is None and run.state is RunState.WAITING
    rig.missing = {}
    actions, t = _advance(run, rig, t_ready + 0.5, lambda r: r.state is not RunState.WAITING)
    assert isinstance(actions[-1], Begin) and run.state is RunState.CHECKING
    assert t - (t_ready + 0.5 + DT) == pytest.approx(1.0, abs=1e-6)   # exactly start_delay of readiness


def test_no_rig_after_wait_timeout_names_each_missing_topic():
    run, rig = _run(wait_timeout=2.0), FakeRig()
    rig.missing = {"/softcath/pressure_measured/ch0": "no publisher", "/softcath/bench/wrench": "stale"}
    actions, t = _advance(run, rig, 0.0, lambda r: r.done)
    assert t == pytest.approx(2.0 + DT) and run.result == EXIT_NO_RIG
    assert [a.level for a in actions] == ["error"]
    assert "no rig after 2 s: /softcath/pressure_measured/ch0: no publisher; /softcath/bench/wrench: stale" \
        in actions[0].text


def test_a_whole_run_follows_the_test_command_runs_every_step_and_vents_for_vent_s():
    run, rig = _run(n_steps=3), FakeRig()
    actions, t = _advance(run, rig, 0.0, lambda r: r.done)
    assert run.result == 0 and run.error is None and run.completed_steps == 3
    said = [a.text for a in actions if isinstance(a, Say)]
    assert len(said) == 1 and "starting protocol" in said[0]
    events = [e["event"] for a in actions if isinstance(a, Markers) for e in a.events]
    assert events[0] == "protocol_start" and events[-1] == "protocol_end" and events.count("step_end") == 3
    commands = [a for a in actions if isinstance(a, Command)]
    assert max(float(np.max(c.pressures)) for c in commands) == max(s.pressures[0] for s in run.runner.steps)
    vents = [i for i, a in enumerate(actions) if isinstance(a, Vent)]
    assert vents and all(not isinstance(a, Command) for a in actions[vents[0]:])   # nothing after the vent
    assert len(vents) == pytest.approx(VENT_S / DT, abs=2)


@pytest.mark.parametrize("when", ["checking", "running"])
def test_a_stale_rig_aborts_at_once_vents_for_abort_vent_s_and_stops(when):
    run, rig = _run(n_steps=28), FakeRig()
    state = RunState.CHECKING if when == "checking" else RunState.RUNNING
    _, t = _advance(run, rig, 0.0, lambda r: r.state is state and (when == "checking" or r.completed_steps >= 2))
    rig.stale_topics = {"/softcath/bench/bend_angle": "no message for 1.0 s"}
    actions = run.tick(t + DT, rig)
    assert run.state is RunState.FINISHING
    assert run.result == (EXIT_NO_RIG if when == "checking" else EXIT_RIG_LOST)
    abort = [e for a in actions if isinstance(a, Markers) for e in a.events]
    assert [e["event"] for e in abort] == ["protocol_abort"] and "/softcath/bench/bend_angle" in abort[0]["reason"]
    if when == "running":
        assert abort[0]["completed_steps"] == 2 and "at step 3/28" in run.error and "2 steps completed" in run.error
    rest, t_done = _advance(run, rig, t + DT, lambda r: r.done)
    assert all(isinstance(a, Vent) for a in rest)
    assert t_done - (t + DT) == pytest.approx(ABORT_VENT_S + DT, abs=DT + 1e-9)   # stops 0.3 s after the abort


def test_a_tick_after_a_long_starvation_does_not_judge_freshness():
    run, rig = _run(), FakeRig()
    _, t = _advance(run, rig, 0.0, lambda r: r.state is RunState.RUNNING)
    rig.stale_topics = {"/softcath/bench/bend_angle": "stale"}
    n = len(rig.asked_stale)
    run.tick(t + 0.5, rig)                  # 0.5 s since the last tick > 0.25 * lost_after: starved
    assert len(rig.asked_stale) == n and run.state is RunState.RUNNING
    run.tick(t + 0.5 + DT, rig)             # the next regular tick judges
    assert run.state is RunState.FINISHING and run.result == EXIT_RIG_LOST


def test_a_failing_recording_aborts_with_its_own_exit_code():
    run, rig = _run(), FakeRig()
    _, t = _advance(run, rig, 0.0, lambda r: r.state is RunState.RUNNING)
    rig.error = "disk full"
    run.tick(t + DT, rig)
    assert run.result == EXIT_RECORDING and run.error.startswith("recording failed: disk full")


def test_a_source_that_does_not_follow_is_refused_and_another_commander_is_named():
    for others, code in (([], EXIT_NO_RIG), (["/intruder"], EXIT_FIGHT)):
        run, rig = _run(), FakeRig()
        rig.others = others
        _, t = _advance(run, rig, 0.0, lambda r: r.state is RunState.CHECKING)
        actions = []
        while run.state is RunState.CHECKING:   # the source never moves
            t += DT
            actions += run.tick(t, rig)
        assert run.result == code and "did not follow a test command within 3 s" in run.error
        assert ("/intruder also publish(es)" in run.error) == bool(others)
        assert run.completed_steps == 0


def test_an_abort_by_direction_opens_a_direct_vent_once_and_a_second_abort_is_ignored():
    run, rig = _run(by_direction=True), FakeRig()
    _, t = _advance(run, rig, 0.0, lambda r: r.state is RunState.RUNNING)
    first = run.abort(t, "stopped (the commands would fight)", EXIT_FIGHT)
    assert sum(isinstance(a, VentDirectly) for a in first) == 1
    assert run.abort(t, "again", EXIT_RIG_LOST) == [] and run.result == EXIT_FIGHT


def test_fail_before_any_command_stops_at_once_without_venting():
    run = _run()
    assert [type(a) for a in run.fail("recording failed: x", EXIT_RECORDING)] == [Say]
    assert run.done and run.result == EXIT_RECORDING and run.tick(1.0, FakeRig()) == []
