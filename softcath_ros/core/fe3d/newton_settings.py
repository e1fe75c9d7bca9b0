"""The settings of a Newton solve on the 3D problem (core/fe3d/newton.py ``Fe3dNewton``): tolerances,
budgets, the shifted tangent, when to give up, factorisation reuse, steps in contact."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NewtonSettings:
    max_iterations: int = 12
    rtol: float = 1e-8          # residual norm relative to the load's norm
    energy_tol: float = 1e-9    # |du . r| relative to c1 * volume (displacement error ~ sqrt of it)
    min_step: float = 1.0 / 64  # smallest step factor (halved from 1 while a step is rejected) before the solve fails
    threads: int = 2
    # where the Newton step is no descent direction of the energy, or every step length is
    # rejected (an indefinite tangent: past a saddle), step with the tangent shifted by
    # sigma x (the H1 seminorm's form), sigma growing until the step descends the condensed energy
    # and stays admissible (Fe3dProblem._shifted_step); converged only on an unshifted step.
    # Off: on the 20 mm ramp the stop is the wall crossing itself, which it cannot pass, and it
    # made that ramp 5x slower (docs/models/fe3d.md, "Where it fails")
    shifted_tangent: bool = False
    shifted_steps: int = 12     # shifted steps per solve, on top of max_iterations
    # give up on a solve whose |du.r| has not fallen tenfold over this many iterations (None: never;
    # with contact, solves that fail wander with |du.r| flat for their whole budget, those that
    # converge fall from the start), so a step that will fail is cut early
    stall_iterations: int | None = 4
    # give up on a solve once this many iterations in a row had their full step rejected and cut
    # (an inverted element, the wall through itself): a step overshot past recovery. None: never.
    # On the 20 mm default ramp no solve that converged cut a step at all; those that failed cut
    # up to 10 in a row before their budget ran out
    cut_iterations: int | None = 3
    # reuse a solve's factorisation while Newton contracts with it: after its first iteration
    # (always factorised), an iteration solves with the tangent of an earlier iterate of the same
    # solve (at most reuse_age iterations old) and keeps that increment while its |du.r| is at
    # most reuse_ratio of the last step's; else it takes Newton's own step (a fresh factorisation),
    # from the start of the last step when that step was the reused one, and at once when the
    # reused step is no descent or not admissible (an inverted element, crossing walls). A solve
    # ends on a reused factorisation only at REUSED_TOLERANCE of the tolerance. None: a
    # factorisation at every iteration.
    reuse_ratio: float | None = 0.25
    reuse_age: int = 8
    # with the lumen walls in contact, halve a descent step far from convergence while it raises the
    # condensed energy: there the pairing's energy is nonconvex and full steps wandered
    descent_in_contact: bool = True
