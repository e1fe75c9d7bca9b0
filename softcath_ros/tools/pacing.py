"""A send loop on absolute deadlines: command i goes out at start + i / rate, so the
rate never drifts however long one send takes (a late send is not made up by a burst
beyond catching up to its own deadline)."""
from __future__ import annotations

import time
from typing import Callable

import numpy as np


def run_paced(n: int, rate_hz: float, send: Callable[[int], None], start_ns: int | None = None,
              should_stop: Callable[[], bool] = lambda: False) -> tuple[np.ndarray, np.ndarray]:
    """Call ``send(i)`` for i < n at deadlines start + i/rate; return (deadline_ns, sent_ns) arrays.

    ``sent_ns`` is the wall clock (time.time_ns, the clock ROS stamps use) read just
    before ``send(i)``. Stops early (arrays truncated) when ``should_stop()`` is true.
    """
    period_ns = int(round(1e9 / rate_hz))
    start_ns = time.time_ns() if start_ns is None else start_ns
    deadlines = start_ns + period_ns * np.arange(n, dtype=np.int64)
    sent = np.zeros(n, dtype=np.int64)
    for i in range(n):
        wait_ns = int(deadlines[i]) - time.time_ns()
        if wait_ns > 0:
            time.sleep(wait_ns * 1e-9)
        if should_stop():
            return deadlines[:i], sent[:i]
        sent[i] = time.time_ns()
        send(i)
    return deadlines, sent
