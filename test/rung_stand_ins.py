"""Stand-in rungs for tests of what callers do when a rung stops answering."""
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
