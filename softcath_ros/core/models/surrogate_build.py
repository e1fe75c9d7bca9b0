"""Building the surrogate's tables from its source rung: rays of commands, solved in parallel.

The section rung answers a command by ramping the channels in proportion from rest (along the
command's ray), so one ramp answers every command on a ray for about the price of its last one.
The tables are therefore built from rays:

- 1 channel: one ray (the channel from 0 to max_pressure) and one held-out ray at the midpoints.
- 3 channels: for a pair (channel r at a, channel r + 1 at b, the third at zero) the rays are
  t = b / (a + b) in [0, 1], each sampled at sums m = a + b every ``pressure_step`` up to the
  design's max_pressure per channel or where the source fails. A design whose section is 3-fold
  symmetric (equal channels at equal angles) needs only the rays with t in [0, 1/2] of pair 0-1:
  the other half is the mirror image (across the line between the two channels) and the other
  pairs are rotations by 120 and 240 degrees. Rays are added where the response bends: a ray at
  the middle of an interval is solved and compared with what the table without it predicts
  there; where they differ by more than ``ray_tolerance`` both halves are split again.

Every ray is one fresh source ramp from rest (no state carried between rays), solved on
``workers`` processes (concurrent.futures). Held-out rays (on every pair and both sides of the
mirror, at pressures between the table's) and rays with all three channels pressurised measure
the table's error; the surrogate stores it.
"""
from __future__ import annotations

import heapq
import math
import multiprocessing
import os
import signal
import sys
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

import numpy as np

from ..design import Design


def default_workers() -> int:
    return max(1, min(os.cpu_count() or 1, 8))


def _quiet_worker() -> None:
    # Ctrl-C goes to the whole process group: the parent stops the pool, workers say nothing
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent()


def _die_with_parent() -> None:
    """On Linux, SIGTERM this worker when the process that started it dies: a node killed while it
    builds a table (a test's clean-up, a supervisor) must not leave its workers solving on."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass


def solve_ray(design: Design, source: str, source_options: dict, commands: np.ndarray) -> dict:
    """The source's answers along one ray (commands in rising order on it), from a fresh rung."""
    from . import make_model

    st = make_model(source, design, **source_options).evaluate(commands)
    ok = np.asarray(st.converged, dtype=bool)
    n_ok = int(np.argmin(ok)) if not ok.all() else len(ok)   # the ray ends at its first failure
    last = (st.last_converged or [None] * len(ok))[n_ok] if n_ok < len(ok) else None
    return {"values": np.column_stack([st.curvature, st.axial_stretch]), "n_ok": n_ok,
            "message": st.message.split("; ")[0] if st.message else "", "last": last}


class RayPool:
    """Rays solved on ``workers`` processes (1: in this process), with a progress bar over rays.

    ``submit(tag, commands, priority)`` queues a ray; ``results()`` yields (tag, result) as rays
    finish. At most ``workers`` rays are in the processes at a time, the lowest ``priority`` first:
    rays that later rays wait for (a refinement round) go before independent ones, which fill the
    processes while the last rays of a round finish (no idle tail between rounds).
    Fork is used when this process has no other threads (quick start), spawn otherwise (a ROS
    node's executor threads must not be forked)."""

    def __init__(self, design: Design, source: str, source_options: dict, workers: int, bar):
        self.design, self.source, self.options = design, source, dict(source_options)
        self.bar = bar
        self.workers = workers
        self.pending: dict = {}
        self.order = 0
        self.queued: list = []      # heap of (priority, order, tag, commands) not yet in a process
        self.done: list = []
        self.pool = None
        if workers > 1:
            others = [th for th in threading.enumerate()
                      if th is not threading.main_thread() and type(th).__name__ != "TMonitor"]  # tqdm's own
            method = "fork" if not others and "fork" in multiprocessing.get_all_start_methods() else "spawn"
            self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                                            initializer=_quiet_worker)

    def submit(self, tag, commands: np.ndarray, priority: int = 0) -> None:
        self.bar.total = (self.bar.total or 0) + 1
        self.bar.refresh()
        if self.pool is None:
            self.done.append((tag, solve_ray(self.design, self.source, self.options, commands)))
            self.bar.update(1)
        else:
            self.order += 1
            heapq.heappush(self.queued, (priority, self.order, tag, commands))
            self._feed()

    def _feed(self) -> None:
        while self.queued and len(self.pending) < self.workers:
            _, _, tag, commands = heapq.heappop(self.queued)
            self.pending[self.pool.submit(solve_ray, self.design, self.source, self.options, commands)] = tag

    def results(self):
        """Finished rays as they come, until none is pending."""
        while self.done or self.pending or self.queued:
            while self.done:
                yield self.done.pop(0)
            self._feed()
            if self.pending:
                finished, _ = wait(list(self.pending), return_when=FIRST_COMPLETED)
                for f in finished:
                    tag = self.pending.pop(f)
                    self.bar.update(1)
                    self._feed()
                    yield tag, f.result()

    def close(self, cancel: bool = False) -> None:
        if cancel:
            self.queued.clear()
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=cancel)


def reflection(design: Design) -> np.ndarray:
    """2 x 2 reflection across the section's mirror line that swaps channels 0 and 1 (found from
    the outlines, models/surrogate ``pair_mirror_angle``): curvature of (b, a, 0) = R k(a, b, 0)."""
    from .surrogate_settings import pair_mirror_angle

    al = pair_mirror_angle(design)
    if al is None:
        raise ValueError(f"design '{design.name}' has no mirror swapping channels 0 and 1 in a 3-fold section")
    return np.array([[math.cos(2 * al), math.sin(2 * al)], [math.sin(2 * al), -math.cos(2 * al)]])


def pair_commands(n_channels: int, pair: int, t: float, sums: np.ndarray, pmax: float,
                  beyond: bool = True) -> np.ndarray:
    """Commands on the ray t of a pair: channel pair at (1 - t) m, channel pair + 1 at t m, for the
    sums m whose channel pressures stay within pmax, and (``beyond``) the next one (so the table
    covers the commands up to pmax itself; the source is asked slightly beyond it, the surrogate
    never answers beyond it, so held-out rays stop at pmax)."""
    w = np.zeros(n_channels)
    w[pair], w[(pair + 1) % n_channels] = 1.0 - t, t
    if beyond:
        n = int(np.searchsorted(sums * w.max(), pmax * (1 - 1e-12))) + 1
    else:
        n = int(np.searchsorted(sums * w.max(), pmax * (1 + 1e-12), side="right"))
    return sums[:n, None] * w[None, :]


class PairRays:
    """The rays of one pair: t -> values (len(sums), 3) with NaN past the ray's end (``reach``)."""

    def __init__(self, sums: np.ndarray):
        self.sums = sums
        self.t: list[float] = []
        self.values: list[np.ndarray] = []
        self.reach: list[int] = []      # number of converged sums on the ray
        self.complete: list[bool] = []  # the source converged on all of it (up to max_pressure and beyond)
        self.messages: list[str] = []   # why rays ended early (the source's first failure on each)

    def add(self, t: float, result: dict) -> None:
        v = np.full((len(self.sums), 3), np.nan)
        n = result["n_ok"]
        v[:n] = result["values"][:n]
        self.t.append(float(t))
        self.values.append(v)
        self.reach.append(n)
        self.complete.append(n == len(result["values"]))
        if result["message"]:
            self.messages.append(result["message"])

    def arrays(self):
        order = np.argsort(self.t)
        return (np.asarray(self.t)[order], np.stack(self.values)[order], np.asarray(self.reach)[order],
                np.asarray(self.complete)[order])


def pair_surface(t: np.ndarray, values: np.ndarray, reach: np.ndarray, complete: np.ndarray, sums: np.ndarray):
    """Bicubic spline through the rays over (t, m), each component, and the reach per t (a
    complete ray has none: max_pressure bounds it).

    Past a ray's end its values are continued linearly from its last two points, only so the
    spline can be built (those commands are refused: ``reachable``)."""
    from scipy.interpolate import RectBivariateSpline

    v = values.copy()
    for i, n in enumerate(reach):
        if n < len(sums):
            if n >= 2:
                slope = v[i, n - 1] - v[i, n - 2]
                v[i, n:] = v[i, n - 1] + slope * np.arange(1, len(sums) - n + 1)[:, None]
            else:
                v[i, n:] = v[i, max(n - 1, 0)] if n else 0.0
    kt = min(3, len(t) - 1)
    splines = [RectBivariateSpline(t, sums, v[..., c], kx=kt, ky=3, s=0) for c in range(3)]
    reach_sum = np.array([np.inf if c else sums[n - 1] if n else -1.0 for n, c in zip(reach, complete)])

    def evaluate(tq: np.ndarray, mq: np.ndarray) -> np.ndarray:
        return np.stack([s.ev(tq, mq) for s in splines], -1)

    def reachable(tq: np.ndarray, mq: np.ndarray) -> np.ndarray:
        """Inside the converged part of both bracketing rays (conservative between rays)."""
        j = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, len(t) - 2)
        return mq <= np.minimum(reach_sum[j], reach_sum[j + 1]) + 1e-9

    return evaluate, reachable


def mirrored(t: np.ndarray, values: np.ndarray, reach: np.ndarray, complete: np.ndarray, refl: np.ndarray):
    """Rays on t in [0, 1/2] completed to [0, 1] by the mirror image: ray 1 - t is ray t with the
    channel pressures swapped and the curvature reflected."""
    mt = t < 0.5 - 1e-12
    v2 = values[mt][::-1].copy()
    v2[..., :2] = v2[..., :2] @ refl.T
    return (np.concatenate([t, 1.0 - t[mt][::-1]]), np.concatenate([values, v2]),
            np.concatenate([reach, reach[mt][::-1]]), np.concatenate([complete, complete[mt][::-1]]))


def rc_error(k_model: np.ndarray, k_ref: np.ndarray) -> np.ndarray:
    """Relative error in R_C = 1/|k|: |R_model - R_ref| / R_ref."""
    km = np.hypot(k_model[..., 0], k_model[..., 1])
    kr = np.hypot(k_ref[..., 0], k_ref[..., 1])
    return np.abs(kr / km - 1.0)


def direction_error_deg(k_model: np.ndarray, k_ref: np.ndarray) -> np.ndarray:
    d = np.arctan2(k_model[..., 1], k_model[..., 0]) - np.arctan2(k_ref[..., 1], k_ref[..., 0])
    return np.degrees(np.abs((d + np.pi) % (2 * np.pi) - np.pi))


__all__ = ["PairRays", "RayPool", "default_workers", "mirrored", "pair_commands",
           "pair_surface", "rc_error", "direction_error_deg", "reflection", "solve_ray"]
