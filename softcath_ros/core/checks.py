"""Checks every file loader shares: numbers and names.

``finite_number``: a value from a file is a number only if it is an int or float (not a bool), fits
a float and is finite; an integer too large for a float is not a number (``float()`` would raise).

Names that end up in file and folder names (a design's or a protocol's ``name``) are refused,
not rewritten, unless they are a plain file-name word: letters, digits and
``_ . -``, starting with a letter or digit, at most 100 characters. So ``../../x`` or ``a/b``
can never send an output outside its folder, and the name in a file is the name on disk.
"""
from __future__ import annotations

import math
import re

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")
NAME_RULE = "must be 1-100 letters, digits, '_', '.' or '-', starting with a letter or digit (it names files)"


def is_file_name(name) -> bool:
    """Whether ``name`` is safe to use as (part of) a file name."""
    return isinstance(name, str) and _NAME.fullmatch(name) is not None and ".." not in name


def finite_number(value) -> float | None:
    """``value`` as a finite float, or None when it is not a finite number (bools, strings,
    integers beyond the float range, NaN and inf are not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        v = float(value)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None
