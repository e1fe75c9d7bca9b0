"""JSON output that is always valid JSON: non-finite floats (NaN, inf) become null.

``json.dumps`` writes ``NaN`` and ``Infinity`` by default, which no strict JSON reader accepts.
Every JSON a softcath command writes goes through ``dumps``/``dump`` here (``allow_nan=False``
after the replacement, so a missed case fails loudly instead of writing invalid JSON).
"""
from __future__ import annotations

import json
import math

import numpy as np


def finite(obj):
    """``obj`` with every non-finite float (also inside lists, tuples, dicts, numpy) as None."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, np.floating):
        return finite(float(obj))
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def dumps(obj, **kwargs) -> str:
    return json.dumps(finite(obj), allow_nan=False, **kwargs)


def dump(obj, fp, **kwargs) -> None:
    fp.write(dumps(obj, **kwargs))
