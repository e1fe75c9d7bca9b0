"""Fan a study's cases out over an executor, with a per-case cache so an interrupted study resumes.

Any ``concurrent.futures``-compatible executor works (``submit`` returning a
``concurrent.futures.Future``): the default is a local ``ProcessPoolExecutor`` with one worker
per CPU; Dask distributed's ``Client.get_executor()`` runs the same cases on a cluster.
Results are cached by the main process as they arrive (cluster workers need no shared disk),
under a hash of the design content, the rung, its options and version, and the pressures.
Ctrl-C cancels the queued cases, keeps every finished one in the cache and re-raises.
"""
from __future__ import annotations

import os
import signal
import sys
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from ..cache import CacheStore
from ..errors import SoftcathError
from .cases import STUDY_CODE_VERSION, CaseSpec, solve_case


@dataclass
class RunStats:
    cases: int = 0      # cases asked for
    cached: int = 0     # answered from the cache
    solved: int = 0     # solved in this run
    errors: int = 0     # raised in a worker (reported as not converged, not cached)


def _ignore_sigint() -> None:
    # Workers leave Ctrl-C to the main process, which cancels the queue and shuts them down.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


SCHEDULER_TIMEOUT_S = 10.0   # to reach a Dask scheduler before refusing the address


def make_executor(workers: int | None = None, scheduler: str | None = None) -> tuple[Executor | None, str]:
    """(executor, description). ``scheduler``: address of a Dask distributed scheduler (imported
    only then); ``workers == 1``: None (solve in this process, no pool); otherwise a local
    process pool with ``workers`` (default os.cpu_count()) processes."""
    if scheduler:
        try:
            from dask.distributed import Client
        except ImportError:
            raise SoftcathError(f"--scheduler {scheduler}: Dask distributed is not installed; "
                                "install it with pip install 'softcath_ros[cluster]'") from None
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SoftcathError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        return client.get_executor(), f"dask scheduler {scheduler}"
    n = workers or os.cpu_count() or 1
    if n < 1:
        raise SoftcathError(f"--workers {workers}: need at least 1")
    if n == 1:
        return None, "1 process (serial)"
    return ProcessPoolExecutor(max_workers=n, initializer=_ignore_sigint), f"{n} local processes"


class CaseCache:
    """One JSON entry per case (kind ``studies``, named by rung) in the cache store rooted at
    ``directory`` (default: the project cache, core/cache.py)."""

    def __init__(self, directory: str | Path | None = None):
        self.store = CacheStore(directory)

    def get(self, spec: CaseSpec) -> dict | None:
        """The case's recorded answer, or None (absent or damaged: solve again)."""
        return self.store.load_json("studies", STUDY_CODE_VERSION, spec.cache_parts(), spec.rung)

    def put(self, spec: CaseSpec, value: dict) -> None:
        self.store.save_json("studies", STUDY_CODE_VERSION, spec.cache_parts(), value, spec.rung)


def run_cases(specs: list[CaseSpec], executor: Executor | None = None, workers: int | None = None,
              cache: CaseCache | bool = True, progress: bool = True, desc: str = "cases",
              stats: RunStats | None = None) -> list[dict]:
    """Solve every spec (solve_case's dict per spec, in order), from the cache where possible.

    ``executor``: used as given and left running; without one, ``make_executor(workers)``'s pool
    is created and shut down here. A case that raised in its worker comes back as not converged
    with the exception as its message (and is not cached)."""
    stats = stats if stats is not None else RunStats()
    store = CaseCache() if cache is True else (cache or None)
    keys = [s.key() for s in specs]
    out: list[dict | None] = [None] * len(specs)
    todo: dict[str, list[int]] = {}          # identical cases are solved once
    for i, k in enumerate(keys):
        hit = store.get(specs[i]) if store is not None else None
        if hit is not None:
            out[i] = hit
            stats.cached += 1
        else:
            todo.setdefault(k, []).append(i)
    stats.cases += len(specs)
    if not todo:
        return out

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=desc, unit="case", file=sys.stderr)

    def finish(key: str, result: dict | None, error: BaseException | None) -> None:
        if error is not None:
            result = _failed_case(specs[todo[key][0]], error)
            stats.errors += 1
        else:
            stats.solved += 1
            if store is not None:
                store.put(specs[todo[key][0]], result)
        for i in todo[key]:
            out[i] = result
        if bar is not None:
            bar.update(1)

    own = None
    if executor is None:
        own, _ = make_executor(workers)
        executor = own
    try:
        if executor is None:      # serial, in this process
            for key, idx in todo.items():
                try:
                    result, error = solve_case(specs[idx[0]]), None
                except Exception as exc:  # noqa: BLE001 - a crashed case is reported, not fatal
                    result, error = None, exc
                finish(key, result, error)
        else:
            _solve_in_pool(executor, specs, todo, finish)
    except KeyboardInterrupt:
        msg = (f"interrupted: {stats.solved} case(s) solved and cached in this run, {len(todo) - stats.solved} "
               "still to solve; run the same command again to resume")
        (bar.write if bar is not None else print)(msg, file=sys.stderr)
        if own is not None:
            own.shutdown(wait=False, cancel_futures=True)
            own = None
        raise
    finally:
        if bar is not None:
            bar.close()
        if own is not None:
            own.shutdown(wait=True)
    return out


def _failed_case(spec: CaseSpec, error: BaseException) -> dict:
    """What a case that raised in its worker records: every command not converged, saying why."""
    return {"results": [{"pressures_pa": list(p), "converged": False, "curvature_per_m": None,
                         "radius_of_curvature_m": None, "axial_stretch": None,
                         "max_principal_stretch": None,
                         "message": f"case failed: {type(error).__name__}: {error}"}
                        for p in spec.pressures], "solve_time_s": None}


def _solve_in_pool(executor: Executor, specs: list[CaseSpec], todo: dict[str, list[int]], finish) -> None:
    """Each case of ``todo`` solved on ``executor``, handed to ``finish`` as it completes; on an
    interrupt the rest is cancelled and what had finished is still handed over."""
    futures: dict = {}
    finished: set = set()
    try:
        for key, idx in todo.items():
            futures[executor.submit(solve_case, specs[idx[0]])] = key
        for fut in as_completed(futures):
            exc = fut.exception()
            finish(futures[fut], None if exc else fut.result(), exc)
            finished.add(fut)
    except KeyboardInterrupt:
        for fut in futures:
            fut.cancel()
        for fut in futures:   # keep what finished before the interrupt was seen
            if fut not in finished and fut.done() and not fut.cancelled() and fut.exception() is None:
                finish(futures[fut], fut.result(), None)
        raise
