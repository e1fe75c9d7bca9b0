"""The base of every softcath_ros error: a message fit to print as one CLI line. It sits below
every layer (the resource finder and core both raise it); core/errors.py adds the domain errors."""


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
