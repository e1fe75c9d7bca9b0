"""Errors the core raises, each naming what was wrong so a user can fix it."""


# Line breaks a user's text (a key, a file name) can carry into a message, shown escaped.
_BREAKS = str.maketrans({c: repr(c)[1:-1] for c in "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"})


def shown(value, limit: int = 80) -> str:
    """``repr(value)`` for a message, cut to ``limit`` characters (a file can hold huge values)."""
    try:
        text = repr(value)
    except ValueError:   # an integer with more digits than Python converts to text
        text = f"<integer of about {value.bit_length() * 0.30103:.0f} digits>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


class SoftcathError(Exception):
    """Base class: a message fit to print as a one-line CLI error (line breaks shown escaped)."""

    def __str__(self) -> str:
        return super().__str__().translate(_BREAKS)


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
