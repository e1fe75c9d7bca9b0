"""Stand-in rungs for tests of what callers do when a rung stops answering."""
from dataclasses import replace

from softcath_ros.core.models.closed_form import ClosedFormModel


def closed_form_ending_at(design, reach_pa: float) -> ClosedFormModel:
    """The closed form on ``design``, not converged wherever a channel exceeds ``reach_pa`` (Pa):
    a table that ends early or a solver that stops, while its numbers stay finite."""

    class EndsEarly(ClosedFormModel):
        def _evaluate_batch(self, pressures):
            state = super()._evaluate_batch(pressures)
            state.converged = pressures.max(axis=1) <= reach_pa
            return state

    return EndsEarly(design)


def closed_form_peaking_at(design, peak_pa: float) -> ClosedFormModel:
    """The closed form on ``design`` with each channel's bend scaled by 1 - p / (2 peak_pa): a
    channel alone bends most at ``peak_pa`` (Pa) and less beyond (a wall that balloons)."""

    class Peaks(ClosedFormModel):
        info = replace(ClosedFormModel.info, linear_gain=False)   # inverted by Newton, as a rung that peaks is

        def _evaluate_batch(self, pressures):
            state = super()._evaluate_batch(pressures)
            bent = pressures * (1.0 - pressures / (2.0 * peak_pa))
            state.curvature = bent @ self.curvature_per_pa.T
            return state

    return Peaks(design)
