"""Load-ramp continuation for nonlinear solvers: adaptive steps, a predictor, step cutting,
and a failure report that carries the last converged state.

Generic: the caller supplies a *corrector* that solves the equilibrium at one value of a
scalar load parameter ``t`` starting from a guess, and says whether it converged. The ramp
walks ``t`` from ``start`` through every checkpoint (the loads the caller wants answers at)
and returns the converged state at each one, or stops at the first load it cannot reach,
never returning a state that did not converge.

    def corrector(guess, t, previous) -> Correction: ...
    result = ramp(corrector, state0, checkpoints=[t1, t2, ...], control=StepControl(...))
    if not result.converged:
        print(result.message)            # "did not converge at <describe(t)> (...)"
        result.last_state, result.last_load   # the last converged state and its load

States are numpy arrays for the default secant predictor (linear extrapolation through
the last two converged states); any other state type needs ``extrapolate=None``
(constant predictor) or a custom ``extrapolate(t0, s0, t1, s1, t) -> guess``.

Past a limit point of the load-controlled path (the load cannot grow on this branch),
``arc_length`` follows the path by pseudo-arc length with the caller's arc corrector until
the load rises above the limit again (a snap: passed, and the ramp can go on from there) or
falls below a floor (the end of the branch: the stop is LIMIT_POINT).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

# Why a ramp stopped (``RampResult.stop_reason``): every stop is one of these.
LIMIT_POINT = "physical limit point"               # the tangent turns singular: p cannot grow further on this branch
MATERIAL_RANGE = "material outside its fitted range"  # e.g. a Yeoh set with c3 < 0 past its convexity limit
OUTSIDE_MODEL = "outside the model's validity"     # e.g. walls touching with contact switched off
UNSTABLE = "unstable equilibrium"                  # the equilibrium reached is a saddle and no stable state is near
NUMERICAL_FAILURE = "numerical failure"            # the corrector failed for none of the reasons above
STOP_REASONS = (LIMIT_POINT, MATERIAL_RANGE, OUTSIDE_MODEL, UNSTABLE, NUMERICAL_FAILURE)
_STOP_TAG = re.compile(r"\[stop: ([^\]]+)\]")


def stop_tag(reason: str) -> str:
    """How a failure message names its stop reason: ``[stop: <reason>]`` (read back by ``tagged_stop``)."""
    return f"[stop: {reason}]"


def tagged_stop(message: str) -> str | None:
    """The stop reason the first ``stop_tag`` in ``message`` names, or None when it has none."""
    found = _STOP_TAG.search(message or "")
    return found.group(1) if found else None


@dataclass
class StepControl:
    """Step-size policy, in the units of the load parameter."""

    initial_step: float
    max_step: float
    min_step: float
    grow: float = 1.5                # after an easy step (an effort below target_iterations)
    shrink: float = 0.5              # after a failed attempt
    target_iterations: int = 4
    adaptive: bool = True            # False: fixed steps of initial_step, no cutting (stability studies)
    domain_step: float | None = None  # stop cutting at this step when the failure is outside_domain
                                      # (a validity limit needs less precision than a hard turn)
    retry_from_last: bool = True     # after a predicted guess fails, try once more from the last state


@dataclass
class Correction:
    """What a corrector returns for one attempt."""

    state: Any
    converged: bool
    iterations: int = 0
    message: str = ""                # why it failed (inverted element, diverged, ...)
    info: dict = field(default_factory=dict)
    outside_domain: bool = False     # the solve converged but the state is outside the model's
                                     # validity (e.g. self-contact): another predictor will not help
    stop_reason: str = ""            # one of the reasons above when the corrector knows it
    effort: float | None = None      # how hard the solve was, in full iterations, for the step size
                                     # (None: ``iterations``; e.g. cheaper iterations weighted less)


@dataclass
class RampPoint:
    load: float
    state: Any
    iterations: int
    info: dict


@dataclass
class RampResult:
    points: list[RampPoint]          # converged states at the checkpoints reached, in order
    converged: bool                  # True when every checkpoint was reached
    message: str                     # empty when converged
    last_load: float                 # last converged load
    last_state: Any                  # and its state
    steps: int = 0                   # accepted steps
    cuts: int = 0                    # rejected attempts
    iterations: int = 0              # corrector iterations in total (accepted and rejected)
    stop_reason: str = ""            # empty when converged, else LIMIT_POINT, MATERIAL_RANGE, ...
    previous: tuple[float, Any] | None = None   # the converged (load, state) before the last one


def secant(t0: float, s0, t1: float, s1, t: float):
    """Linear extrapolation through (t0, s0), (t1, s1) to t."""
    return s1 + (s1 - s0) * ((t - t1) / (t1 - t0))


def ramp(corrector: Callable[[Any, float, Any], Correction], state0, checkpoints: Sequence[float],
         control: StepControl, start: float = 0.0, history: tuple[float, Any] | None = None,
         extrapolate: Callable | None = secant, describe: Callable[[float], str] = lambda t: f"load {t:g}",
         on_step: Callable[[float, Correction], None] | None = None) -> RampResult:
    """Continue from ``state0`` (converged at ``start``) through the increasing ``checkpoints``.

    ``history``: an earlier converged (load, state) to seed the secant predictor.
    ``on_step`` is called after every accepted step (progress bars).
    """
    t, state = start, state0
    prev = history
    step = control.initial_step
    result = RampResult(points=[], converged=True, message="", last_load=start, last_state=state0)
    last = None
    for target in checkpoints:
        if target < t - 1e-12 * max(1.0, abs(t)):
            raise ValueError(f"checkpoints must not decrease: {target} after {t}")
        while t < target:
            dt = min(step, target - t)
            # do not leave a sliver smaller than a tenth of a step before the checkpoint
            if target - (t + dt) < 0.1 * dt:
                dt = target - t
            t_new = t + dt
            if prev is not None and extrapolate is not None and t > prev[0]:
                guess = extrapolate(prev[0], prev[1], t, state, t_new)
            else:
                guess = state
            corr = corrector(guess, t_new, state)
            if not corr.converged and not corr.outside_domain and prev is not None and extrapolate is not None \
                    and control.retry_from_last:
                # the secant can overshoot near a limit point: retry from the last state
                result.iterations += corr.iterations
                corr = corrector(state, t_new, state)
            result.iterations += corr.iterations
            if corr.converged:
                last = corr
                # a corrector that jumped to another branch (info "restart_predictor") restarts the secant
                prev = None if corr.info.get("restart_predictor") else (t, state)
                result.previous = prev
                t, state = (target if t_new >= target else t_new), corr.state
                result.steps += 1
                result.last_load, result.last_state = t, state
                if on_step is not None:
                    on_step(t, corr)
                effort = corr.iterations if corr.effort is None else corr.effort
                if control.adaptive and effort < control.target_iterations:
                    step = min(control.max_step, step * control.grow)
                continue
            result.cuts += 1
            floor = control.min_step
            if corr.outside_domain and control.domain_step is not None:
                floor = max(floor, control.domain_step)
            if not control.adaptive or dt * control.shrink < floor:
                why = f": {corr.message}" if corr.message else ""
                result.converged = False
                result.stop_reason = corr.stop_reason or NUMERICAL_FAILURE
                result.message = (f"did not converge at {describe(t_new)} (last converged "
                                  f"{describe(t)}, step {dt:.3g} after {result.cuts} cut(s){why})")
                return result
            step = dt * control.shrink
        landed = last is not None and result.last_load == target
        result.points.append(RampPoint(load=target, state=state, iterations=last.iterations if landed else 0,
                                       info=last.info if landed else {}))
    return result


# ---------------------------------------------------------------------------------- arc length
@dataclass
class ArcControl:
    """Pseudo-arc-length steps past a limit point (units of the caller's arc norm)."""

    initial_step: float
    min_step: float
    max_step: float
    max_steps: int = 60              # arc steps before giving up on the load recovering
    recover: float = 1e-9            # the load must exceed the limit load by this (relative) to count as passed
    target_iterations: int = 4


@dataclass
class ArcResult:
    passed: bool                     # True: the path came back above the limit load (a snap, passed)
    state: Any                       # the last converged state on the path
    load: float                      # and its load
    limit_load: float                # the largest load before the path turned back (the limit point)
    lowest_load: float               # the smallest load on the path after it turned
    steps: int = 0
    iterations: int = 0
    message: str = ""                # why the arc stopped when it did not pass
    below_floor: bool = False        # it stopped because the load fell below ``floor``: the branch's end


def arc_length(corrector: Callable[[Any, float, Any, float], Correction], state0, load0: float,
               control: ArcControl, floor: float | None = None) -> ArcResult:
    """Follow the equilibrium path by pseudo-arc length from ``state0`` (converged at ``load0``,
    just below a limit point of the load-controlled path) until the load exceeds the limit load
    again on a rising branch (the limit point is passed: a snap), or until the path falls below
    ``floor`` or ``max_steps`` pass without that (the limit point is the end of the branch).

    ``corrector(state, load, previous_state, ds)`` takes one arc step of length ``ds`` from the
    converged ``state`` (it keeps its own tangent and its orientation) and returns a Correction
    whose ``info["load"]`` is the load at the new state."""
    state, load = state0, load0
    ds = control.initial_step
    peak, lowest, turned = load0, load0, False
    result = ArcResult(False, state0, load0, load0, load0)
    previous = None
    while result.steps < control.max_steps:
        corr = corrector(state, load, previous, ds)
        result.iterations += corr.iterations
        if not corr.converged:
            if ds * 0.5 < control.min_step:
                result.message = f"the arc-length corrector failed ({corr.message})"
                return result
            ds *= 0.5
            continue
        new_load = float(corr.info["load"])
        result.steps += 1
        previous, state = state, corr.state
        rising = new_load > load
        load = new_load
        result.state, result.load = state, load
        if not rising:
            turned = True
        if turned:
            lowest = min(lowest, load)
        else:
            peak = max(peak, load)
        result.limit_load, result.lowest_load = peak, lowest
        if turned and rising and load > peak * (1 + control.recover):
            result.passed = True
            return result
        if floor is not None and load < floor:
            result.below_floor = True
            result.message = f"the load falls below {floor:g} after the limit point"
            return result
        if corr.iterations < control.target_iterations:
            ds = min(control.max_step, 1.5 * ds)
    result.message = f"the load does not recover within {control.max_steps} arc-length steps"
    return result
