"""The steering controller's core without ROS (core/steering.py, bench/steering_sim.py, the tracker):
convergence on a plant with a known mismatch, saturation along the target's direction,
anti-windup after a long saturation, fallback on stale or jumping measurements, the watchdog.
Closed form rung for model and truth (fast; its mismatch is a pure gain (1 - 0.25) / 1.2)."""
import math

import numpy as np
import pytest

from softcath_ros.bench.sim_rig import RigParams, SimulatedRig, TipTracker, TrackerParams, truth_model
from softcath_ros.bench.steering_sim import (SteeringScenario, build, metrics, run_metrics, simulate,
                                             steering_rig_params)
from softcath_ros.core.allocation import Allocator
from softcath_ros.core.design import load_design
from softcath_ros.core.kinematics import tip_pose_single
from softcath_ros.core.models import make_model
from softcath_ros.core.prediction import arc_and_cap
from softcath_ros.core.steering import SteeringController, SteeringError, SteeringParams, bend_of_tip
from softcath_ros.core.steering_range import (STEERING_MAX_BEND_DEG, STEERING_MAX_PRESSURE, steering_allocator,
                                              steering_design, steering_model, steering_range)

DESIGN = steering_design(load_design("three_channel_5mm"), STEERING_MAX_PRESSURE)


@pytest.fixture(scope="module", params=["three_channel_5mm", "three_sector_5mm"])
def built(request):
    """Each design at its default steering range (three_sector_5mm's on the closed form: 0.22 bar)."""
    return build(SteeringScenario(design=request.param))


def _controller(**params):
    return SteeringController(Allocator(make_model("closed_form", DESIGN)), SteeringParams(**params))


def _tip_of_bend(theta, phi, length=DESIGN.length):
    k = theta / length
    return np.array(tip_pose_single(k * math.cos(phi), k * math.sin(phi), length)[0])


def test_bend_of_tip_inverts_the_arc():
    tip = _tip_of_bend(0.4, 1.1)
    b = bend_of_tip(tip)
    assert math.hypot(*b) == pytest.approx(0.4, rel=1e-12)
    assert math.atan2(b[1], b[0]) == pytest.approx(1.1, rel=1e-12)
    assert np.all(bend_of_tip([0.0, 0.0, 0.04]) == 0.0)


@pytest.mark.parametrize("theta", [1e-6, 0.4, 2.5, 4.0])
def test_bend_of_tip_inverts_the_arc_with_a_straight_cap(theta):
    """The tip of an arc of 39 mm continued by a 1 mm straight cap: the bend is the arc's angle,
    not that of the arc through the tip (which differs by about cap / length)."""
    arc, cap = 0.039, 0.001
    k = theta / arc
    tip = tip_pose_single(k * math.cos(-0.7), k * math.sin(-0.7), arc, cap)[0]
    b = bend_of_tip(tip, cap)
    assert math.hypot(*b) == pytest.approx(theta, rel=1e-10)
    assert math.atan2(b[1], b[0]) == pytest.approx(-0.7, rel=1e-10)
    assert math.hypot(*bend_of_tip(tip)) != pytest.approx(theta, rel=1e-3)


@pytest.mark.parametrize("mode", ["integral", "adaptive"])
def test_closed_loop_converges_on_a_plant_with_known_mismatch(built, mode):
    """Truth: 25% pressure shift and material scale 1.2 (gain 0.625), 50 ms latency, 20% dropped."""
    open_loop = run_metrics(simulate(SteeringScenario(controller=SteeringParams(mode="open_loop")), "step", 4.5,
                                     built), 4.5)
    run = simulate(SteeringScenario(controller=SteeringParams(mode=mode)), "step", 4.5, built)
    closed = run_metrics(run, 4.5)
    assert open_loop["steady_state_error_m"] > 4e-4          # the model's error, uncorrected
    assert closed["steady_state_error_m"] < 0.1e-3           # feedback removes it
    assert closed["settling_time_s"] <= 1.0
    assert run.closed[-1]
    if mode == "adaptive":   # on a linear rung shift and scale are one gain: (1 - 0.25) / 1.2
        assert run.gain[-1] == pytest.approx(0.75 / 1.2, rel=0.03)


def test_saturation_along_the_target_direction_and_within_max_pressure():
    ctrl = _controller(mode="integral")
    phi = math.radians(70.0)                  # between two channels' directions: a pair drives it
    for i in range(400):                       # 2 s at 200 Hz, no measurement: open loop
        ctrl.set_target(_tip_of_bend(1.2, phi), i * 0.005)   # far beyond reach at 0.3 bar
        out = ctrl.step(i * 0.005)
    assert out.saturated
    assert np.all(out.pressures <= DESIGN.max_pressure) and np.all(out.pressures >= 0.0)
    assert max(out.pressures) == pytest.approx(DESIGN.max_pressure)
    b = ctrl.model_bend(out.pressures)
    assert math.degrees(abs(math.atan2(b[1], b[0]) - phi)) < 0.5


def test_saturation_with_an_adapted_gain_below_one_keeps_limit_and_direction():
    """The actuator bends as the model at half the pressure: the model's inverse is limited to half
    of max_pressure, so the pressures sent (the model's doubled) reach max_pressure without a
    channel clipping off the target's direction."""
    ctrl = _controller(mode="adaptive")
    ctrl.gain = 0.5                           # as adapted (kept in open loop, as after a fallback)
    phi = math.radians(70.0)
    for i in range(400):
        ctrl.set_target(_tip_of_bend(1.2, phi), i * 0.005)   # far beyond reach
        out = ctrl.step(i * 0.005)
        assert np.all(out.pressures <= DESIGN.max_pressure) and np.all(out.pressures >= 0.0)
    assert out.saturated and max(out.pressures) == pytest.approx(DESIGN.max_pressure)
    b = ctrl.model_bend(0.5 * out.pressures)
    assert math.degrees(abs(math.atan2(b[1], b[0]) - phi)) < 0.5


def test_adapted_pressure_gain_is_the_shift_and_scale_on_a_nonlinear_rung():
    """three_sector_5mm on its shipped surrogate (nonlinear in pressure), the rig 25% shifted and
    20% stiffer: the truth bends as the model at (1 - 0.25) / 1.2 of the pressure, and the adapted
    gain finds it, so the 0.2 Hz circle is followed within 0.3 mm (50 ms latency, 20% dropped)."""
    scenario = SteeringScenario(model="surrogate", truth="surrogate", controller=SteeringParams(mode="adaptive"))
    run = simulate(scenario, "circle", 6.0, build(scenario))
    assert run.gain[-1] == pytest.approx(0.75 / 1.2, rel=0.02)
    assert run_metrics(run, 6.0)["steady_state_error_m"] < 0.3e-3


def test_circle_error_splits_into_radial_tangential_and_axial_parts():
    """A tip 0.05 rad behind the target on a 10 mm circle and 0.2 mm too high: a lag (negative
    tangential mean), the chord's small radial part, the axial offset."""
    t = np.linspace(0.0, 10.0, 2001)
    a, lag, r = 2 * math.pi * 0.2 * t, 0.05, 0.01
    target = np.column_stack([r * np.cos(a), r * np.sin(a), np.full_like(t, 0.03)])
    tip = np.column_stack([r * np.cos(a - lag), r * np.sin(a - lag), np.full_like(t, 0.0302)])
    m = metrics(t, target, tip, "circle", 10.0)
    assert m["tangential_error_mean_m"] == pytest.approx(-r * math.sin(lag), rel=1e-9)
    assert m["tangential_error_rms_m"] == pytest.approx(r * math.sin(lag), rel=1e-9)
    assert m["radial_error_rms_m"] == pytest.approx(r * (1 - math.cos(lag)), rel=1e-9)
    assert m["axial_error_rms_m"] == pytest.approx(2e-4, rel=1e-9)


def test_rate_limit_on_every_step():
    ctrl = _controller(mode="open_loop", max_pressure_rate=1.0e5)
    prev = np.zeros(3)
    for i in range(100):
        ctrl.set_target(_tip_of_bend(0.2, -math.pi / 2), i * 0.005)
        out = ctrl.step(i * 0.005)
        assert np.max(np.abs(out.pressures - prev)) <= 1.0e5 * 0.005 + 1e-9
        prev = out.pressures


def _loop(ctrl, rig, tracker, t0, t1, target, dt=0.005):
    """Run the controller against the rig from t0 to t1 (s); returns the last step."""
    out = None
    for i in range(int(round((t1 - t0) / dt))):
        t = t0 + i * dt
        tip, _ = rig.true_tip()
        if i % 2 == 0:
            tracker.capture(t, tip)
        ctrl.set_target(target, t)
        for stamp, pos in tracker.due(t):
            ctrl.on_measurement(pos, stamp, t)
        out = ctrl.step(t)
        rig.advance(dt, out.pressures)
    return out


def test_anti_windup_after_a_long_saturation():
    """5 s against an unreachable target, then a reachable one: the integral stayed bounded and
    the tip settles as fast as from rest."""
    params = steering_rig_params()
    truth = truth_model("closed_form", DESIGN, params)
    ctrl = _controller(mode="integral")
    rig = SimulatedRig(truth, params)
    tracker = TipTracker(TrackerParams(noise=0.0, drop_fraction=0.0))
    far = _tip_of_bend(1.0, -math.pi / 2)
    out = _loop(ctrl, rig, tracker, 0.0, 5.0, far)
    assert out.saturated and out.state == "closed_loop"
    assert math.hypot(*out.integral) < ctrl.params.max_integral      # back-calculated, not wound up
    reach_true = Allocator(truth, max_pressure=0.75 * DESIGN.max_pressure).allocate_bend(-math.pi / 2, 9.0)
    near = _tip_of_bend(0.7 * reach_true.extras["max_angle_rad"], -math.pi / 2)
    _loop(ctrl, rig, tracker, 5.0, 6.0, near)
    assert np.linalg.norm(rig.true_tip()[0] - near) < 0.5e-3        # settled within 1 s


def test_fallback_on_stale_measurements_and_resume():
    ctrl = _controller(mode="adaptive", measurement_timeout=0.2, resume_samples=3)
    target = _tip_of_bend(0.1, -math.pi / 2)
    ctrl.set_target(target, 0.0)
    t = 0.0
    for i in range(20):                            # 100 Hz samples, a little short of the target
        t = i * 0.01
        assert ctrl.on_measurement(target * [0.9, 0.9, 1.0], t - 0.05, t) == "accepted"
        out = ctrl.step(t)
    assert out.state == "closed_loop" and math.hypot(*out.integral) > 0
    assert ctrl.on_measurement(target, t - 0.5, t) == "stale"          # older than the timeout
    assert ctrl.on_measurement(target + [0.05, 0, 0], t + 0.01, t + 0.01) == "jump"   # 50 mm in 60 ms
    for i in range(1, 40):                          # the tracker stops; targets keep coming
        ctrl.set_target(target, t + i * 0.01)
        out = ctrl.step(t + i * 0.01)
    assert out.state == "open_loop" and "no valid measurement" in out.reason
    assert np.all(out.integral == 0) and ctrl.counters.fallbacks == 1
    assert out.gain != 1.0                          # the adapted gain is kept as a calibration
    t += 0.4
    states = []
    for i in range(5):                              # the tracker comes back
        ctrl.set_target(target, t + i * 0.01)
        ctrl.on_measurement(target, t + i * 0.01 - 0.01, t + i * 0.01)
        states.append(ctrl.step(t + i * 0.01).state)
    assert states[0] == "open_loop" and states[-1] == "closed_loop"


def test_late_measurement_is_compared_with_the_target_of_its_stamp():
    """A target moving round the axis, measured exactly where it was 50 ms earlier: the tip is on
    its path, so the integral stays near zero (compared with the newest target it would wind up
    a tangential lead of speed x latency)."""
    ctrl = _controller(mode="integral")
    theta, hz, latency = 0.15, 0.2, 0.05

    def target(t):
        return _tip_of_bend(theta, 2 * math.pi * hz * t)

    times = [i * 0.005 for i in range(600)]          # 3 s at 200 Hz, samples at 100 Hz
    late = round(latency / 0.005)
    for i, t in enumerate(times):
        ctrl.set_target(target(t), t)
        if i % 2 == 0 and i >= late:
            assert ctrl.on_measurement(target(times[i - late]), times[i - late], t) == "accepted"
        out = ctrl.step(t)
    assert out.state == "closed_loop"
    lag = theta * 2 * math.pi * hz * latency           # rad: what the newest target would have read
    assert math.hypot(*out.integral) < 0.02 * lag
    assert np.allclose(ctrl.target_bend_at(2.9), bend_of_tip(target(2.9), ctrl.cap))


def test_watchdog_vents_when_targets_stop():
    ctrl = _controller(mode="integral", command_timeout=0.3)
    ctrl.set_target(_tip_of_bend(0.15, -math.pi / 2), 0.0)
    for i in range(40):
        out = ctrl.step(i * 0.005)
    assert max(out.pressures) > 0
    for i in range(40, 400):
        out = ctrl.step(i * 0.005)
    assert out.state == "vented" and np.all(out.pressures == 0.0)


def test_queued_targets_count_from_arrival_and_stale_ones_are_dropped():
    """A target handled late (queued behind a busy controller) feeds the watchdog from its arrival,
    and one older than command_timeout is dropped: the vent is not postponed by a backlog."""
    ctrl = _controller(mode="open_loop", command_timeout=0.3)
    ctrl.set_target(_tip_of_bend(0.15, -math.pi / 2), now=0.2, arrived=0.0)
    assert ctrl.step(0.25).state == "open_loop"
    assert ctrl.step(0.31).state == "vented"        # 0.3 s after it arrived, not after it was handled
    with pytest.raises(SteeringError, match="stale"):
        ctrl.set_target(_tip_of_bend(0.15, -math.pi / 2), now=0.7, arrived=0.35)
    assert ctrl.step(0.71).state == "vented"


def test_bad_inputs_are_one_line_errors():
    with pytest.raises(SteeringError):
        SteeringParams(mode="pid")
    with pytest.raises(SteeringError):
        SteeringParams(forgetting=1.5)
    ctrl = _controller()
    with pytest.raises(SteeringError):
        ctrl.set_target([float("nan"), 0.0, 0.04], 0.0)
    assert ctrl.on_measurement([float("inf"), 0, 0], 0.0, 0.0) == "invalid"


def test_tracker_latency_and_drops():
    tracker = TipTracker(TrackerParams(latency=0.05, drop_fraction=0.2, noise=1e-4, seed=3))
    got = []
    for i in range(2000):
        t = i * 0.01
        tracker.capture(t, [0.0, 0.0, 0.04])
        got += [(t, s, p) for s, p in tracker.due(t)]
    assert abs(tracker.dropped / tracker.taken - 0.2) < 0.03
    assert all(t - s == pytest.approx(0.05, abs=1e-9) for t, s, _ in got)
    noise = np.std([p[2] for *_, p in got])
    assert noise == pytest.approx(1e-4, rel=0.1)


def test_rig_actuator_lag_and_material_scale():
    design = load_design("three_channel_5mm")
    stiff = SimulatedRig(truth_model("closed_form", design, RigParams(material_scale=1.2, pressure_shift=0.0)),
                         RigParams(pressure_shift=0.0, actuator_time_constant=0.016))
    soft = SimulatedRig(make_model("closed_form", design), RigParams(pressure_shift=0.0))
    for rig in (stiff, soft):
        rig.advance(10.0, [3e4, 0, 0])
    ratio = np.hypot(*stiff.true_curvature()) / np.hypot(*soft.true_curvature())
    assert ratio == pytest.approx(1 / 1.2, rel=0.02)      # closed form: gain ~ 1/modulus
    rig = SimulatedRig(make_model("closed_form", design), RigParams(regulator_time_constant=1e-4,
                                                                     actuator_time_constant=0.016))
    rig.advance(0.016, [3e4, 0, 0])
    assert rig.actuated_pressures[0] == pytest.approx(3e4 * (1 - math.exp(-1)), rel=0.01)


@pytest.mark.parametrize("argv, words", [(["--duration", "-1"], "--duration"), (["--drop", "1.5"], "--drop"),
                                         (["--design", "no_such_design"], "no_such_design")])
def test_steer_sim_bad_input_is_one_line_exit_2(argv, words, capsys):
    from softcath_ros.cli import main

    assert main(["steer-sim", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("softcath steer-sim: error:") and words in err[0]


def _lone_channel_tip_angles(allocator) -> list[float]:
    """Degrees between the tip's direction and the base's axis, each channel alone at the allocator's
    limit: the saturated bend along its own direction, read back from the tip position."""
    _, cap = arc_and_cap(allocator.model, allocator.design.length)
    angles = []
    for direction in allocator.channel_directions:
        tip = allocator.tip_position(allocator.allocate_bend(float(direction), 1e3))
        angles.append(math.degrees(math.hypot(*bend_of_tip(tip, cap))))
    return angles


def test_default_steering_range_keeps_a_soft_tip_in_front_of_its_base():
    """three_sector_5mm bends about ten times more than three_channel_5mm per bar: at 0.3 bar one
    channel alone would wrap its 40 mm body far past its shaft (650 degrees), so its default range
    ends where a channel alone turns the tip 90 degrees from the base's axis."""
    allocator = steering_allocator("surrogate", load_design("three_sector_5mm"))
    assert STEERING_MAX_BEND_DEG == 90.0
    assert 0.05e5 < allocator.max_pressure < 0.95 * STEERING_MAX_PRESSURE
    assert max(_lone_channel_tip_angles(allocator)) == pytest.approx(STEERING_MAX_BEND_DEG, abs=0.05)
    below = steering_allocator(allocator.model, allocator.design, 0.98 * allocator.max_pressure)
    assert max(_lone_channel_tip_angles(below)) < STEERING_MAX_BEND_DEG - 1.0
    # the simulation, steer-sim and steer_node default to it
    _, _, design = build(SteeringScenario(model="surrogate", truth="surrogate"))
    assert design.name == "three_sector_5mm" and design.max_pressure == allocator.max_pressure


def test_three_channel_keeps_its_0_3_bar_steering_range():
    """A stiffer body is limited by 0.3 bar, not by the bend: one channel alone turns its tip ~61 deg."""
    for rung in ("surrogate", "closed_form"):
        model = steering_model(rung, load_design("three_channel_5mm"))
        assert steering_range(model) == STEERING_MAX_PRESSURE
    allocator = steering_allocator(model, model.design)
    assert max(_lone_channel_tip_angles(allocator)) < 0.8 * STEERING_MAX_BEND_DEG


def test_an_explicit_steering_limit_wins_lowered_to_the_design():
    design = load_design("three_sector_5mm")
    model = steering_model("closed_form", design)
    assert steering_allocator(model, design, 2.5e4).max_pressure == 2.5e4 > steering_range(model)
    assert steering_design(design, 1e7).max_pressure == design.max_pressure


def test_steering_reads_the_shipped_surrogate_table_and_builds_none(monkeypatch):
    """The controller's and the rig's surrogate are the shipped table of the design as shipped: no
    table is built at start-up (the steering range is the allocator's limit, not a new design)."""

    def no_build(model):
        raise AssertionError(f"a surrogate table was built for {model.design.name} "
                             f"(max_pressure {model.design.max_pressure:g} Pa)")

    monkeypatch.setattr("softcath_ros.core.models.surrogate_tabulate.build_table", no_build)
    alloc = steering_allocator("surrogate", load_design("three_channel_5mm"))
    assert alloc.model.origin == "shipped" and alloc.max_pressure == STEERING_MAX_PRESSURE
    assert np.all(alloc.allocate([0.0, -200.0]).pressures <= STEERING_MAX_PRESSURE)
    allocator, truth, design = build(SteeringScenario(model="surrogate", truth="surrogate"))
    assert allocator.model.origin == "shipped" and design.max_pressure == steering_range(allocator.model)
    # the rig's truth answers all three channels pressurised (a rate-limited change of sector), the
    # controller's table refuses beyond its measured common-mode limit
    three = np.array([[8e3, 12e3, 4e3]])
    assert truth.evaluate(three).converged.all() and not allocator.model.evaluate(three).converged.any()


