"""Pressure ramps on the 3D problem: the generic continuation (core/continuation.py) with
the 3D Newton as corrector and a tangent predictor.

The load parameter t is the pressure, Pa, of the most pressurised channel; channel i gets
t * direction[i]. Every checkpoint reached gives one ``Fe3dPoint`` (measured there); a
ramp that cannot go on stops with "did not converge at p = ... bar" and keeps what
converged. Ctrl-C stops the ramp the same way (``interrupted``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..body_contact import body_contact
from ..continuation import (LIMIT_POINT, MATERIAL_RANGE, NUMERICAL_FAILURE, OUTSIDE_MODEL, UNSTABLE, Correction,
                            StepControl, ramp, secant, stop_tag)
from ..energy import yeoh_convexity_limit
from .measure import deformed_backbone, measure
from .newton import NewtonFailure
from .predictor import CorotationalPredictor
from .solver import Fe3dProblem
from ..units import PA_PER_BAR, describe_pressure


def default_step_control(adaptive: bool = True, step: float = 1000.0) -> StepControl:
    """Pa. The first step is small: Newton from the straight state overshoots on long bodies. The
    largest step is the benchmarks' checkpoint spacing (0.025 bar), so easy stretches take one
    step per checkpoint; a stop outside the model's validity (the body reaching itself or its
    shaft) is located to DOMAIN_STEP. A failed step is cut at once, not tried again from the last
    state: on the 20 mm default ramp every such second try failed as well."""
    return StepControl(initial_step=step, max_step=2500.0, min_step=20.0, grow=1.6, shrink=0.5,
                       target_iterations=5, adaptive=adaptive, domain_step=DOMAIN_STEP, retry_from_last=False)


# Pa: how finely a stop outside the model's validity is located (the section rung's contact_resolution)
DOMAIN_STEP = 250.0


@dataclass
class Fe3dPoint:
    load: float                     # Pa (most pressurised channel)
    pressures: np.ndarray           # (C,) Pa
    measured: dict                  # measure(): angle, direction, arc length, tip, volumes, areas
    iterations: int                 # Newton iterations of the step that landed here
    wall_time: float                # s since the ramp started


@dataclass
class Fe3dRamp:
    points: list[Fe3dPoint] = field(default_factory=list)
    converged: bool = True
    message: str = ""
    interrupted: bool = False
    stop_reason: str = ""           # empty when converged, else one of core/continuation.py's reasons
    min_gap_m: list = field(default_factory=list)   # (load Pa, lumen wall's min gap m) per accepted step
    stability: object = None        # a failed ramp's Stability at its last converged state (stability.py)
    steps: int = 0
    cuts: int = 0
    iterations: int = 0
    wall_time: float = 0.0


# a failed ramp's last converged state counts as singular (a limit point or a bifurcation) when the
# condensed tangent's smallest eigenvalue over 2 c1 is below SINGULAR_BELOW there (the unloaded
# coarse 10 mm body's is 0.13), or when its straight line through the last two converged states
# reaches zero within SINGULAR_WITHIN of the last converged load (the step control cannot step
# closer than its smallest step, where the eigenvalue may still be a tenth of its unloaded value)
SINGULAR_BELOW = 1e-3
SINGULAR_WITHIN = 0.01


def _contact_made(split, threshold: float) -> bool:
    """Whether a state's singular or negative eigenvalue is the lumen contact's making, not the body's:
    without the contact term the tangent is positive definite (smallest at least ``threshold``) while
    some of the held pairs are past the barrier's log range, where its energy is the Taylor
    continuation that pushes an overshooting iterate back, not the barrier that models contact. On
    the 1-DOF optimum at 20 mm (0.1041 bar) such a mode lay in 12 elements at the lumen wall and the
    energy along it was nonconvex only within 0.3 um, a hundredth of d_hat (docs/models/fe3d.md)."""
    return split is not None and split.past_log_range_m2 > 0.0 and split.without_contact >= threshold


def _split_text(split) -> str:
    return (f"without the lumen contact's term {split.without_contact:.3g}, with "
            f"{split.past_log_range_m2 * 1e6:.2g} mm^2 of its pairs past the barrier's log range")


# what a singular tangent at a stop is, said where the stop is named
SINGULAR_KIND = ("singular: a limit point or bifurcation of this mesh's equations; only a mesh study tells a physical "
                 "one from a discretisation mode")


def _back_to_last_converged(problem: Fe3dProblem, result) -> None:
    """Leave the problem at the ramp's last converged state (its stop is measured at other states)."""
    problem.set_state(result.last_state)
    problem.load.Set(result.last_load)


def _name_the_stop(problem: Fe3dProblem, result, threshold: float, within: float = SINGULAR_WITHIN):
    """(Stability, stop reason, message tail) at the ramp's last converged state: UNSTABLE when its
    smallest eigenvalue is negative, LIMIT_POINT when it is singular (see SINGULAR_BELOW), else
    NUMERICAL_FAILURE; a negative or singular eigenvalue of the contact's making (``_contact_made``)
    leaves it a NUMERICAL_FAILURE. A NUMERICAL_FAILURE whose failed solve stalled near equilibrium
    where the tangent is singular is a LIMIT_POINT (``_at_the_stall``). The problem is left at that state."""
    def at(load, state):
        problem.set_state(state)
        problem.load.Set(load)
        if problem.contact is not None:
            problem.contact.update()   # that state's pairs, not the failed attempt's
        st = problem.stability(k=1)
        split = problem.contact_split() if problem.contact is not None and st.smallest < threshold else None
        return st, split

    try:
        s, split = at(result.last_load, result.last_state)
        before = result.previous
        s0, split0 = at(*before) if before is not None and before[0] < result.last_load else (None, None)
    except Exception as exc:  # noqa: BLE001 - the failure stays named as it was
        _back_to_last_converged(problem, result)
        return None, NUMERICAL_FAILURE, f"; its stability not measured ({exc})"
    _back_to_last_converged(problem, result)
    lam = s.smallest
    lam0 = s0.smallest if s0 is not None else None
    zero = None   # the load where the eigenvalue's line through the last two states reaches 0
    trend = ""
    if lam0 is not None:
        slope = (lam - lam0) / (result.last_load - before[0])
        if slope < 0.0:
            zero = result.last_load - lam / slope
        trend = f", {lam0:.3g} at {describe_pressure(before[0])}" + (f" ({_split_text(split0)})" if split0 else "") + (
            f": zero by {describe_pressure(zero)} on their line" if zero is not None else ": not falling")
    near = zero is not None and zero - result.last_load <= within * result.last_load
    reason = UNSTABLE if lam < 0.0 else LIMIT_POINT if lam < threshold or near else NUMERICAL_FAILURE
    kind = {UNSTABLE: "a saddle", LIMIT_POINT: SINGULAR_KIND}.get(reason, "not singular")
    if lam < threshold and _contact_made(split, threshold):
        reason = NUMERICAL_FAILURE
        kind = (f"{'a saddle' if lam < 0.0 else 'singular'} of the lumen contact's making, not the body's: "
                f"{_split_text(split)}")
    elif split is not None:
        kind = f"{kind}; {_split_text(split)}"
    stalled, at_stall = _at_the_stall(problem, at, threshold, result)
    if stalled and reason == NUMERICAL_FAILURE:
        reason = LIMIT_POINT
    return s, reason, (f"; the condensed tangent's smallest eigenvalue at the last converged state is "
                       f"{lam:.3g} x 2 c1{trend} ({kind}; load share of its mode {s.load_share:.2g}), "
                       f"its mode largest at the {s.where}{at_stall}{_mirror_text(problem)}")


# a stalled Newton solve's iterates count as equilibria for naming the stop while their |du.r| is at most
# STALL_NEAR x Newton's tolerance (a converged state is one at 1 x)
STALL_NEAR = 10.0


def _at_the_stall(problem: Fe3dProblem, at, threshold: float, result) -> tuple[bool, str]:
    """(whether the tangent is singular there, a message tail) where the ramp's failed solve stalled within
    STALL_NEAR x its tolerance of equilibrium (``Fe3dProblem.stalled``); (False, "") otherwise. Singular:
    the smallest eigenvalue at its last iterate below ``threshold``, or an indefinite tangent at one of its
    iterates that near (a fresh Newton increment with du.r < -tol, the shifted tangent's test of a saddle),
    unless the contact term made it (``_contact_made``). Next to a bifurcation the energy along the soft mode
    is quartic: on the 1-DOF optimum at 20 mm (0.1124 bar) the residual along it grew as its amplitude cubed
    over 2-20 um, so the states Newton accepts or stalls at lie microns along the mode, where the curvature
    is that offset's (0.0224 x 2 c1 at the last converged state, 0.0055 and 7e-4 at stalled iterates), and
    within 1.7 x the tolerance the tangent is indefinite. The problem is left at the ramp's last converged
    state (``result``)."""
    stall = getattr(problem, "stalled", None)
    if stall is None or not stall.tolerances <= STALL_NEAR:
        return False, ""
    indefinite = stall.indefinite <= STALL_NEAR
    try:
        st, split = at(stall.load, stall.state)
        if split is None and indefinite and problem.contact is not None:
            split = problem.contact_split()   # (``at`` splits only a singular eigenvalue)
    except Exception as exc:  # noqa: BLE001 - the stop stays named as it was
        return False, f"; at the stalled iterate not measured ({exc})"
    finally:
        _back_to_last_converged(problem, result)
    singular = (st.smallest < threshold or indefinite) and not _contact_made(split, threshold)
    kind = SINGULAR_KIND if singular else "not singular"
    if split is not None:
        kind = f"{kind}; {_split_text(split)}"
    seen = f", the tangent indefinite at {stall.indefinite:.2g} x its tolerance" if indefinite else ""
    return singular, (f"; Newton stalled at {describe_pressure(stall.load)} {stall.tolerances:.2g} x its tolerance "
                      f"from equilibrium{seen}, its last iterate's smallest eigenvalue {st.smallest:.3g} x 2 c1 "
                      f"({kind}; load share of its mode {st.load_share:.2g}), its mode largest at the {st.where}")


def _mirror_text(problem: Fe3dProblem) -> str:
    """The half model's lumen wall past its mirror plane at the current state, as a message tail ("" when
    it is not past it by MIRROR_SAID d_hat): through the mirror term's barrier (LumenContact.mirror_crossing)."""
    if problem.contact is None:
        return ""
    past = problem.contact.mirror_crossing()
    if past <= MIRROR_SAID * problem.contact.d_hat:
        return ""
    return f"; its lumen wall lies {past * 1e6:.1f} um past the half body's mirror plane, through its mirror image"


# d_hat: how far past the half body's mirror plane the lumen wall must lie for a stop to say so
MIRROR_SAID = 0.01


class _Steps:
    """The corrector, predictor and accepted-step hook of one fe3d ramp (``run_ramp``) on the shared
    continuation: the 3D Newton at a load, refused past the Yeoh set's convex range or the body
    reaching itself; the tangent (or corotational, or secant) predictor; each accepted state measured."""

    def __init__(self, problem: Fe3dProblem, direction, targets, out: Fe3dRamp, tangent_predictor: bool,
                 corotational: bool, progress, t0: float):
        self.problem, self.direction, self.targets, self.out = problem, direction, targets, out
        self.tangent_predictor, self.progress = tangent_predictor, progress
        self.radius = problem.design.outer_radius
        mat = problem.design.material
        self.limit = yeoh_convexity_limit(mat.c1, mat.c2, mat.c3)
        self.corot = CorotationalPredictor(problem) if tangent_predictor and corotational else None
        self.curvature_at: dict[float, np.ndarray] = {}   # fitted curvature of accepted states, by load
        self.accepted = t0   # the last accepted load, for an interrupt's message
        self.shown = 0.0
        self.t_start = time.perf_counter()

    def corrector(self, guess, t, previous):
        problem, limit = self.problem, self.limit
        problem.set_state(guess)
        problem.load.Set(t)
        try:
            its = problem.newton()
        except NewtonFailure as exc:
            problem.set_state(previous)
            return Correction(state=previous, converged=False, iterations=exc.iterations, message=exc.reason)
        if limit is not None:
            i1 = problem.max_isochoric_i1()
            if i1 > limit[0]:
                problem.set_state(previous)
                return Correction(state=previous, converged=False, iterations=its, outside_domain=True,
                                  stop_reason=MATERIAL_RANGE,
                                  message=(f"the silicone reaches I1b = {i1:.3g}, past I1b = {limit[0]:.3g} "
                                           f"(uniaxial stretch {limit[1]:.3g}) where its Yeoh energy (c3 < 0) "
                                           "stops being convex"))
        reached = body_contact(deformed_backbone(problem, 0.5 * self.radius), self.radius)
        if reached is not None:
            problem.set_state(previous)
            return Correction(state=previous, converged=False, iterations=its, outside_domain=True,
                              stop_reason=OUTSIDE_MODEL, message=reached.describe())
        return Correction(state=problem.get_state(), converged=True, iterations=its, effort=problem.last_effort)

    def predictor(self, t0, s0, t1, s1, t):
        if not self.tangent_predictor:
            return secant(t0, s0, t1, s1, t)
        curvature_at = self.curvature_at
        if self.corot is not None and t0 in curvature_at and t1 in curvature_at:
            guess = self.corot.predict(t0, s0, curvature_at[t0], t1, s1, curvature_at[t1], t)
            if guess is not None:
                return guess
        problem = self.problem
        problem.set_state(s1)
        problem.load.Set(t1)   # the tangent of the state at its own load (a failed attempt left its own)
        try:
            return s1 + (t - t1) * problem.tangent()
        except Exception:  # noqa: BLE001 - a singular tangent falls back to the secant
            return secant(t0, s0, t1, s1, t)

    def on_step(self, t, corr):
        # The problem holds the accepted state: measure it (the predictor needs its curvature).
        out = self.out
        self.accepted = t
        self.problem.set_state(corr.state)
        m = measure(self.problem)
        if "lumen_min_gap_m" in m:
            out.min_gap_m.append((t, m["lumen_min_gap_m"]))
        if m["arc_length_m"] > 0:
            self.curvature_at[t] = m["bending_angle_rad"] / m["arc_length_m"] * m["bending_direction"]
        if any(abs(t - c) <= 1e-9 * max(1.0, c) for c in self.targets) and \
                (not out.points or out.points[-1].load != t):
            out.points.append(Fe3dPoint(load=t, pressures=t * self.direction, measured=m,
                                        iterations=corr.iterations,
                                        wall_time=time.perf_counter() - self.t_start))
        if self.progress is not None:
            self.progress.update(t - self.shown)
            self.shown = t
            self.progress.set_postfix_str(f"{t / PA_PER_BAR:.3f} bar, {corr.iterations} it")


def run_ramp(problem: Fe3dProblem, direction, checkpoints, control: StepControl | None = None,
             tangent_predictor: bool = True, progress=None, corotational: bool = False,
             start: tuple[float, np.ndarray] | None = None,
             singular_below: float | None = SINGULAR_BELOW) -> Fe3dRamp:
    """Ramp from the straight state (or ``start``: a load, Pa, and a state to continue from, e.g. a
    converged state with an imperfection added) through increasing ``checkpoints`` (Pa).

    ``progress``: an object with ``update(n)`` and ``set_postfix_str(s)`` (a tqdm bar).
    ``corotational``: extrapolate in the bent frame (CorotationalPredictor) instead of along
    the tangent; experimental (in trials it predicted no better than the tangent).
    ``singular_below``: where the corrector fails for no named reason, the condensed tangent's
    smallest eigenvalue at the last two converged states (only then, ``Fe3dProblem.stability``)
    names the stop: singular (below this fraction of 2 c1, or falling to zero within SINGULAR_WITHIN
    of the load) a LIMIT_POINT, negative UNSTABLE, else it stays NUMERICAL_FAILURE; the message gives
    the eigenvalues and where the mode lives. None: no check.
    """
    control = control or default_step_control()
    direction = np.asarray(direction, dtype=float)
    problem.set_direction(direction)
    t0 = 0.0 if start is None else float(start[0])
    problem.set_state(np.zeros(problem.fes.ndof) if start is None else np.asarray(start[1], dtype=float))
    out = Fe3dRamp()
    targets = [float(c) for c in checkpoints]
    steps = _Steps(problem, direction, targets, out, tangent_predictor, corotational, progress, t0)
    if start is None and targets and targets[0] <= 0.0:  # the straight state needs no solve
        out.points.append(Fe3dPoint(0.0, 0.0 * direction, measure(problem), 0, 0.0))
    targets = [t for t in targets if t > t0]
    try:
        result = ramp(steps.corrector, problem.get_state(), targets, control, start=t0,
                      extrapolate=steps.predictor if control.adaptive else None,
                      describe=describe_pressure, on_step=steps.on_step)
        out.converged, out.stop_reason = result.converged, result.stop_reason
        why = ""
        # (a given start state, e.g. with an imperfection, is not known to be converged)
        if not result.converged and result.stop_reason == NUMERICAL_FAILURE and singular_below is not None \
                and (start is None or result.steps > 0):
            if start is not None and result.steps == 1:
                result.previous = None   # that was the given start state
            out.stability, out.stop_reason, why = _name_the_stop(problem, result, singular_below)
        out.message = f"{result.message}{why} {stop_tag(out.stop_reason)}" if not result.converged else ""
        out.steps, out.cuts, out.iterations = result.steps, result.cuts, result.iterations
    except KeyboardInterrupt:
        out.converged, out.interrupted = False, True
        last = f", checkpoint {describe_pressure(out.points[-1].load)}" if out.points else ""
        out.message = f"interrupted after {describe_pressure(steps.accepted)} (the last accepted state{last})"
    out.wall_time = time.perf_counter() - steps.t_start
    return out
