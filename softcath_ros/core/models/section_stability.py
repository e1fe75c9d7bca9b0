"""The section rung's stable states and limit points: where saddles are likely, leaving a saddle
for the stable state next to it (``solver.leave_saddle``), and telling a limit point from a
numerical failure when a ramp stops (a mixin of ``SectionModel``, which holds the problem, the
settings and the records ``left_saddles``)."""
from __future__ import annotations

import numpy as np

from ..continuation import LIMIT_POINT, NUMERICAL_FAILURE, UNSTABLE, Correction, StepControl, ramp

# a limit point: the tangent's smallest eigenvalue below this fraction of its value at rest
LIMIT_RATIO = 0.25
# iterations of the minimiser that leaves a saddle (it steps with shifted tangents until past the
# indefinite region: 48-49 at D/30 near 0.27 bar); also of the stable-only minimiser where the walls touch
ESCAPE_ITERATIONS = 80


class StableStates:
    """Saddles and limit points of the section rung's ramps."""

    def _saddles_likely(self, x: np.ndarray) -> bool:
        """Where saddles are met (the lumen filled, or a wall's contact active at ``x``)."""
        return self.problem.fill is not None or self.problem.contact_active(x)

    def _leave_saddle(self, corr: Correction, pressures: np.ndarray, where: str) -> Correction:
        """A converged state whose tangent has negative directions is a saddle of the potential, not
        a state the body rests in. Where the lumen wall's contact is active, or the lumen is filled
        (the creased shoulders of a closing lumen make such saddles), it is left for the stable
        state next to it (``solver.leave_saddle``) and the ramp goes on from there; a saddle it
        cannot leave stops the ramp (UNSTABLE). Elsewhere (no contact, no fill) it is kept: a state
        just past a limit point, which the limit-point probe steps back from; ``_evaluate_batch``
        never answers with one."""
        count = corr.info["negative_directions"]
        if self.problem.fill is None and not self.problem.contact_active(corr.state):
            return corr
        stable, here = self._escape(corr.state, pressures)
        if here == 0:          # stable at the state itself (the count was the iterate's before it)
            corr.info["negative_directions"] = 0
            return corr
        if stable is None:
            return Correction(corr.state, False, corr.iterations, stop_reason=UNSTABLE, outside_domain=True,
                              message=f"the equilibrium at {where} is a saddle ({count} direction(s) of negative "
                                      "stiffness at the closed lumen's wall) and minimising the potential from "
                                      "it finds no stable state below it")
        stable.iterations += corr.iterations
        stable.info["restart_predictor"] = True     # the secant through the saddle's branch would overshoot
        return stable

    def _stable_answer(self, x: np.ndarray, pressures: np.ndarray) -> tuple[np.ndarray, int]:
        """(state, negative directions) to answer with at the saddle ``x``: the stable state next to
        it (``solver.leave_saddle``) with 0, or ``x`` itself with its count when there is none."""
        stable, count = self._escape(x, pressures)
        return (x, count) if stable is None else (stable.state, 0)

    def _escape(self, x: np.ndarray, pressures: np.ndarray):
        """``solver.leave_saddle`` at ``x`` with this rung's settings, a stable state found recorded in
        ``left_saddles``: (its Correction or None, the negative directions at ``x``)."""
        from ..section_fe.solver import leave_saddle   # (scipy: not on a node's start-up path)

        stable, count = leave_saddle(self.problem, x, pressures, tol=self.settings.tol,
                                     max_iterations=ESCAPE_ITERATIONS, linear=self.linear)
        if stable is not None:
            self.left_saddles.append({"pressure": (pressures * self.problem.c_ref).tolist(),
                                      "negative_directions": count, "energy_drop": stable.info["energy_drop"]})
        return stable, count

    def _probe_limit_point(self, result, corrector, t_probe: float, pressure_of, describe):
        """A ramp that failed for no named reason, looked at closer: creep on from its last state
        with steps of min_step / 64 and compare the tangent's smallest eigenvalue there with its
        value at rest. Near zero (below LIMIT_RATIO of it), the path has reached a limit point or a
        bifurcation that pressure control cannot pass; otherwise it stays a numerical failure."""
        from ..section_fe.solver import unstable_directions

        s = self.settings
        probe = ramp(corrector, result.last_state, [t_probe],
                     StepControl(initial_step=s.min_step / 8, max_step=s.min_step, min_step=s.min_step / 64),
                     start=result.last_load, describe=describe)
        crossed = 0
        if probe.steps:
            crossed = unstable_directions(self.problem, probe.last_state, pressure_of(probe.last_load))
            if not crossed:       # an unstable state is never reported as the last converged one
                result.last_load, result.last_state = probe.last_load, probe.last_state
        if self._rest_eigenvalue is None:
            x0 = self.problem.consistent_pressures(self.problem.initial_state())
            self._rest_eigenvalue = self.problem.smallest_tangent_eigenvalue(x0, pressure_of(0.0) * 0)
        ratio = self.problem.smallest_tangent_eigenvalue(result.last_state, pressure_of(result.last_load)) \
            / self._rest_eigenvalue
        if crossed:
            result.stop_reason = LIMIT_POINT
            result.message += (f"; {LIMIT_POINT} at {describe(result.last_load)}: just past it, at "
                               f"{describe(probe.last_load)}, the equilibrium is unstable ({crossed} direction(s) "
                               "of negative stiffness; pressure control cannot pass it)")
        elif ratio < LIMIT_RATIO:
            result.stop_reason = LIMIT_POINT
            result.message += (f"; {LIMIT_POINT} at {describe(result.last_load)}: the tangent's smallest "
                               f"eigenvalue is {ratio:.1%} of its value at rest (pressure control cannot pass it)")
        else:
            result.message += (f"; {NUMERICAL_FAILURE}: the tangent's smallest eigenvalue at the last converged "
                               f"state ({describe(result.last_load)}) is {ratio:.0%} of its value at rest, "
                               "so no limit point is near")
        return result


__all__ = ["ESCAPE_ITERATIONS", "LIMIT_RATIO", "StableStates"]
