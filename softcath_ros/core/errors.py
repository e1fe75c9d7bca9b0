"""Errors the core raises, each naming what was wrong so a user can fix it."""


from ..errors import SoftcathError, shown  # noqa: F401  (the base lives below core)


class DesignError(SoftcathError):
    """A design file field is missing, malformed or physically impossible.

    ``field`` is the dotted path of the offending field (e.g. ``channels[0].diameter``),
    ``value`` the value found there.
    """

    def __init__(self, field: str, value, reason: str):
        self.field = field
        self.value = value
        self.reason = reason
        super().__init__(f"design field '{field}' = {shown(value)}: {reason}")


class ModelError(SoftcathError):
    """A model was asked for something it cannot do (unknown rung, bad input shape)."""


class AllocationError(SoftcathError):
    """A request the allocator cannot interpret (non-finite, negative angle, ...)."""
