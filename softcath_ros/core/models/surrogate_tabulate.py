"""How a surrogate table is built: the source rung sampled along rays of commands (solved in
parallel by ``surrogate_build.RayPool``), refined where the response bends, and the table's error
measured against the source at held-out commands (see ``surrogate.py`` for what is tabulated)."""
from __future__ import annotations

import math
import time
from dataclasses import asdict

import numpy as np

from ..errors import ModelError
from ..units import PA_PER_BAR
from .base import BendState
from .surrogate_build import direction_error_deg, rc_error
from .surrogate_settings import SURROGATE_VERSION


def source_options(model) -> dict:
    """The source rung's options for the build: no bars of its own, the model's cache."""
    opts = dict(model.settings.source_options)
    if model.settings.source in ("section", "fe3d"):
        opts.setdefault("progress", False)
        opts.setdefault("cache", model.store if model.store is not None else False)
    return opts


def build_table(model) -> tuple[dict, dict]:
    """The table and its metadata for ``model`` (a SurrogateModel), its source's rays solved in parallel."""
    from tqdm import tqdm

    from .surrogate_build import RayPool

    t0 = time.perf_counter()
    with tqdm(total=0, desc=f"surrogate {model.design.name}: {model.settings.source} rays", unit="ray",
              disable=not model.progress) as bar:
        pool = RayPool(model.design, model.settings.source, source_options(model), model.workers, bar)
        try:
            table, meta = _one_channel(model, pool) if model.kind == "one_channel" else _three_channel(model, pool)
        except BaseException:
            pool.close(cancel=True)
            raise
        pool.close()
    meta.update({"version": SURROGATE_VERSION, "key": model.key, "design": model.design.name,
                 "design_hash": model.design_hash(), "kind": model.kind, "rotated": model.rotated,
                 "settings": asdict(model.settings), "source_version": model.cache_parts()[2],
                 "build_seconds": time.perf_counter() - t0, "workers": model.workers})
    return table, meta


def _one_channel(model, pool) -> tuple[dict, dict]:
    s = model.settings
    pmax = model.design.max_pressure
    grid = np.linspace(0.0, pmax, max(int(math.ceil(pmax / s.pressure_step)), 4) + 1)
    mids = 0.5 * (grid[1:] + grid[:-1])     # held out: where interpolation error is largest
    pool.submit("table", grid[:, None])
    pool.submit("held", mids[:, None])
    res = dict(pool.results())
    r = res["table"]
    n_ok = r["n_ok"]
    if n_ok < 4:
        raise ModelError(f"model 'surrogate': source '{s.source}' converged at only {n_ok} of the table's "
                         f"pressures from 0 ({r['message']}); too few for a table")
    p, y = grid[:n_ok], r["values"][:n_ok]
    last = r["last"]
    if last is not None and last["pressure"][0] > p[-1] + 1.0:
        p = np.append(p, last["pressure"][0])
        y = np.vstack([y, [*last["curvature"], last["axial_stretch"]]])
    model.use_table({"p": p, "y": y}, {"max_pressure": float(p[-1])})
    h = res["held"]
    n_h = h["n_ok"]
    held = mids[:n_h][mids[:n_h] <= p[-1]]
    mine = model.evaluate(held[:, None])
    bound = table_errors(mine, h["values"][:len(held)], held[:, None])
    meta = {"max_pressure": float(p[-1]), "source_failure": r["message"],
            "source_evaluations": int(len(grid) + len(mids)), "source_rays": 2,
            "error_bound": {"one_channel": bound}}
    return model.table, meta


# pool priorities: refinement rays (later rounds wait for them) first, then the held-out rays
# beside the worst miss, then rays nothing waits for (they fill the processes between rounds)
_ROUND, _BESIDE, _INDEPENDENT = 0, 1, 2
CHECK_FIRST = 6     # commands (from rest) a check ray with a large common part is first solved to


def _three_channel(model, pool) -> tuple[dict, dict]:
    from .surrogate_build import PairRays, mirrored, pair_commands, pair_surface, reflection

    s, d = model.settings, model.design
    pmax = d.max_pressure
    n_step = max(int(math.ceil(pmax / s.pressure_step)), 4)
    sums = np.linspace(0.0, 2.0 * pmax, 2 * n_step + 1)      # a + b along a pair's ray
    mids = sums[:-1] + 0.5 * (sums[1] - sums[0])            # held out: sums between the table's
    mags = np.linspace(0.0, pmax, n_step + 1)                # the largest channel pressure
    pairs = (0,) if model.rotated else (0, 1, 2)
    half = 0.5 if model.rotated else 1.0
    refl = reflection(d) if model.rotated else None
    rays = {r: PairRays(sums) for r in pairs}
    rng = np.random.default_rng(0)
    n0 = s.initial_rays if model.rotated else 2 * s.initial_rays - 1
    rounds = {0: [(r, float(t)) for r in pairs for t in np.linspace(0.0, half, n0)]}
    for r, t in rounds[0]:
        pool.submit(("ray", 0, r, t), pair_commands(3, r, t, sums, pmax), _ROUND)
    held, checks, cut = _submit_independent_rays(pool, s, rng, mids, mags, pmax)

    def surface(r):
        arrays = rays[r].arrays()
        return pair_surface(*(mirrored(*arrays, refl) if model.rotated else arrays), sums)

    results: dict = {}
    refine_log = _refine_rays(pool, s, rays, rounds, results, sums, pmax, surface)
    # held out too: the middles of the two intervals beside the last round's worst miss, where the
    # finished table is least sure (random rays rarely land in a narrow steep band), and of every
    # interval left unsplit beside a middle ray that missed by more than the answer tolerances
    for r, t in dict.fromkeys(_beside_worst_miss(refine_log, rays, s) + _suspect_middles(refine_log, rays, s)):
        held.append((r, t))
        pool.submit(("held", len(held) - 1), pair_commands(3, r, t, mids, pmax, beyond=False), _BESIDE)
    for tag, res in pool.results():
        results[tag] = res
    # the table
    arrs = [rays[r].arrays() for r in pairs]
    cm = results[("common",)]
    n_cm = cm["n_ok"]
    table = {"sums": sums, "ray_pair": np.concatenate([np.full(len(a[0]), r) for r, a in zip(pairs, arrs)]),
             "ray_t": np.concatenate([a[0] for a in arrs]), "ray_values": np.concatenate([a[1] for a in arrs]),
             "ray_reach": np.concatenate([a[2] for a in arrs]), "ray_complete": np.concatenate([a[3] for a in arrs]),
             "common_p": mags[:n_cm], "common_stretch": cm["values"][:n_cm, 2]}
    max_common = float(mags[n_cm - 1]) if n_cm else 0.0
    answer = {"max_pressure": float(pmax), "rotated": model.rotated, "max_common_pressure": max_common}
    model.use_table(table, answer)
    refused = _refused_intervals(model, results, held, mids, rays)
    _refuse(model, table, answer, refused)
    bound, n_held = _held_out_bound(model, results, held, mids, pmax)
    limit, cbound, full = _common_mode_bound(model, results, checks, mags, max_common)
    again = [i for i, c in enumerate(cut) if c and full[i] and results[("check", i)]["n_ok"] == CHECK_FIRST]
    if again:    # every command of a shortened check ray was within: the whole ray, from rest
        for i in again:
            pool.submit(("check", i), mags[:, None] * checks[i][None, :], _ROUND)
        for tag, res in pool.results():
            results[tag] = res
        limit, cbound, _ = _common_mode_bound(model, results, checks, mags, max_common)
    failures = [res["message"] for tag, res in sorted(results.items(), key=lambda x: str(x[0]))
                if tag[0] in ("ray", "common") and res["message"]]
    failures += [m for r in pairs for m in rays[r].messages]
    reach_bar = {f"{r}:{t:.4f}": None if c else float(sums[n - 1] / PA_PER_BAR) if n else 0.0
                 for r, a in zip(pairs, arrs) for t, n, c in zip(a[0], a[2], a[3])}
    n_rays = sum(len(a[0]) for a in arrs)
    n_checked = sum(len(results[("check", i)]["values"]) for i in range(len(checks)))
    bound["refused_regions"] = len(refused)
    meta = {"max_pressure": float(pmax), "rotated": model.rotated, "max_common_pressure": limit,
            "max_common_table_pressure": max_common,
            "source_failure": "; ".join(dict.fromkeys(failures[:3])),
            "source_rays": int(n_rays + len(held) + 1 + len(checks) + len(again)), "table_rays": int(n_rays),
            "source_evaluations": int(sum(len(pair_commands(3, r, t, sums, pmax))
                                          for r, a in zip(pairs, arrs) for t in a[0])
                                      + n_held + len(mags) + n_checked),
            "ray_reach_sum_bar": reach_bar, "refinement": refine_log, "refused_regions": refused,
            "error_bound": {"pair": bound, "common_mode": cbound},
            "common_checks_direction": [w.round(4).tolist() for w in checks],
            "common_curvature_max_per_m": float(np.nanmax(np.abs(cm["values"][:n_cm, :2]))) if n_cm else 0.0}
    return table, meta


def _submit_independent_rays(pool, s, rng, mids, mags, pmax: float) -> tuple[list, list, list]:
    """The rays no refinement round waits for: held-out rays (every pair, t off the table's rays,
    sums between the table's, up to max_pressure), the common ray, and the common-mode check rays.
    Returns (held rays as (pair, t), check directions, whether each check ray was cut short)."""
    from .surrogate_build import pair_commands

    held = [(i % 3, float(rng.uniform(0.03, 0.97))) for i in range(s.held_out_rays)]
    for i, (r, t) in enumerate(held):
        pool.submit(("held", i), pair_commands(3, r, t, mids, pmax, beyond=False), _INDEPENDENT)
    pool.submit(("common",), np.repeat(mags[:, None], 3, 1), _INDEPENDENT)
    # all three > 0: a pair command plus a common part of 20%, 2%, 0.2% ... of the larger channel
    # (a vented channel that has not yet reached zero is the usual case). A check ray is off beyond
    # its first command off the tolerance (a larger common pressure), so those with a large common
    # part are first solved to CHECK_FIRST commands only, and to the end only if all were within.
    checks, cut = [], []
    for i in range(s.common_rays):
        w = np.array([1.0, rng.uniform(0.2, 1.0), 0.2 / 10 ** i])
        checks.append(np.roll(w, i % 3))
        cut.append(i < s.common_rays - 1 and len(mags) > CHECK_FIRST)
        pool.submit(("check", i), mags[:CHECK_FIRST if cut[-1] else len(mags), None] * checks[-1][None, :],
                    _INDEPENDENT)
    return held, checks, cut


def _refuse(model, table: dict, answer: dict, refused: list) -> None:
    """Store the ``refused`` regions in ``table`` and, if any, resample the model's table without them."""
    table.update({"refused_pair": np.array([g["pair"] for g in refused], dtype=int),
                  "refused_t": np.array([g["t"] for g in refused], dtype=float).reshape(-1, 2),
                  "refused_sums": np.array([[g["from_sum_bar"] * PA_PER_BAR, np.inf if g["to_sum_bar"] is None
                                             else g["to_sum_bar"] * PA_PER_BAR] for g in refused],
                                           dtype=float).reshape(-1, 2)})
    if refused:
        for key in ("fine_table", "fine_ok", "fine_resolved"):
            table.pop(key, None)
        model.use_table(table, answer)


def _ray_misses(s, surf, t: float, got: dict, sums, pmax: float) -> dict:
    """How a solved middle ray ``got`` misses the table without it (``surf``: its surface and
    reach) at the commands the surrogate answers (up to max_pressure, where both bracketing rays
    reached), and whether by more than the answer tolerances."""
    n = got["n_ok"]
    ev, reachable = surf
    m = sums[1:n]
    inside = reachable(np.full(len(m), t), m) & (m * max(t, 1.0 - t) <= pmax * (1 + 1e-12))
    if not inside.any():
        return {"rc_miss": float("inf"), "direction_miss_deg": float("inf"), "beyond_answer": False}
    want = ev(np.full(int(inside.sum()), t), m[inside])
    rc = float(np.nanmax(rc_error(want[:, :2], got["values"][1:n][inside, :2])))
    dr = float(np.nanmax(direction_error_deg(want[:, :2], got["values"][1:n][inside, :2])))
    return {"rc_miss": rc, "direction_miss_deg": dr,
            "beyond_answer": rc > s.answer_tolerance or dr > s.answer_direction_tolerance}


def _refine_rays(pool, s, rays: dict, rounds: dict, results: dict, sums, pmax, surface) -> list:
    """Collect the pool's results into ``results`` and ``rays``; each time a round of rays is
    complete, add rays between neighbours where the table misses a middle ray (up to
    ``max_rays``). Returns the refinement log (each judged ray's misses)."""
    from .surrogate_build import pair_commands

    pairs = tuple(rays)
    waiting, refine_log = {0: len(rounds[0])}, []
    for tag, res in pool.results():
        if tag[0] != "ray":
            results[tag] = res
            continue
        _, k, r, t = tag
        results[tag] = res
        waiting[k] -= 1
        if waiting[k]:
            continue
        # round k is complete: judge its middle rays against the table without them, then add them
        split = []
        if k > 0:
            surf = {r: surface(r) for r in pairs}
            for r, t, lo, hi, _ in rounds[k]:
                entry = {"round": k, "pair": r, "t": t, "lo": lo, "hi": hi,
                         **_ray_misses(s, surf[r], t, results[("ray", k, r, t)], sums, pmax)}
                refine_log.append(entry)
                score = _miss_score(s, entry["rc_miss"], entry["direction_miss_deg"])
                if score > 1.0:
                    split += [(r, 0.5 * (lo + t), lo, t, score), (r, 0.5 * (t + hi), t, hi, score)]
        for item in rounds[k]:
            r, t = item[0], item[1]
            rays[r].add(t, results.pop(("ray", k, r, t)))
        if k == 0:
            split = []
            for r in pairs:
                ts = sorted(rays[r].t)
                split += [(r, 0.5 * (a + b), a, b, math.inf) for a, b in zip(ts[:-1], ts[1:])]
        nxt = rays_with_room(split, {r: s.max_rays - len(rays[r].t) for r in pairs})
        if nxt:
            rounds[k + 1], waiting[k + 1] = nxt, len(nxt)
            for r, t, _, _, _ in nxt:
                pool.submit(("ray", k + 1, r, t), pair_commands(3, r, t, sums, pmax), _ROUND)
    return refine_log


def _miss_score(s, miss_rc: float, miss_dir: float) -> float:
    """A middle ray's miss of the table as a multiple of the refinement's tolerance (> 1: split)."""
    return max(miss_rc / s.ray_tolerance, miss_dir / s.ray_direction_tolerance)


def _suspect_middles(refine_log: list, rays: dict, s) -> list:
    """(pair, t) at the middles of the final intervals beside a middle ray that missed the table by
    more than the answer tolerances and were not split again (out of rays or too narrow)."""
    out = []
    for e in refine_log:
        if e.get("beyond_answer"):
            ts = rays[e["pair"]].t
            out += [(e["pair"], 0.5 * (lo + hi)) for lo, hi in ((e["lo"], e["t"]), (e["t"], e["hi"]))
                    if not any(lo < x < hi for x in ts)]
    return out


def _refused_intervals(model, results: dict, held: list, mids, rays: dict) -> list:
    """The bands of the finished table the held-out rays found off the source by more than the answer
    tolerances: the interval between the table's rays around the held-out ray, over the sums from
    the one before each run of such commands to the one after it (to the end when the run reaches
    the ray's last answer). The table cannot be refined there: the build is done."""
    s = model.settings
    step = float(mids[1] - mids[0])
    regions: dict = {}
    for i, (r, t) in enumerate(held):
        cmds, vals = _held_commands(results, i, r, t, mids, model.design.max_pressure)
        mine = model.evaluate(cmds)
        use = mine.converged & np.isfinite(vals).all(1)
        rc, dr = np.zeros(len(cmds)), np.zeros(len(cmds))
        rc[use] = rc_error(mine.curvature[use], vals[use, :2])
        dr[use] = direction_error_deg(mine.curvature[use], vals[use, :2])
        off = (rc > s.answer_tolerance) | (dr > s.answer_direction_tolerance)
        if not off.any():
            continue
        pair, tt = (0, min(t, 1.0 - t)) if model.rotated else (r, t)
        ts = np.sort(rays[pair].t)
        j = int(np.clip(np.searchsorted(ts, tt), 1, len(ts) - 1))
        m = cmds.sum(1)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], off.astype(int), [0]])))
        for first, end in zip(edges[::2], edges[1::2]):      # runs of commands off: [first, end)
            band = (max(m[first] - step, 0.0), m[end] + 1.0 if end < len(m) else np.inf)
            key = (pair, float(ts[j - 1]), float(ts[j]), band)
            regions[key] = {"pair": pair, "t": [key[1], key[2]], "from_sum_bar": band[0] / PA_PER_BAR,
                            "to_sum_bar": band[1] / PA_PER_BAR if np.isfinite(band[1]) else None,
                            "rc_miss": float(rc[first:end].max()), "direction_miss_deg": float(dr[first:end].max()),
                            "tolerance_rc_rel": s.answer_tolerance,
                            "tolerance_direction_deg": s.answer_direction_tolerance}
    return list(regions.values())


def _beside_worst_miss(refine_log: list, rays: dict, s) -> list:
    """(pair, t) at the middles of the final intervals on either side of the ray that missed the
    table most in the last refinement round (none without refinement)."""
    if not refine_log:
        return []
    last = refine_log[-1]["round"]
    worst = max((e for e in refine_log if e["round"] == last),
                key=lambda e: _miss_score(s, e["rc_miss"], e["direction_miss_deg"]))
    ts = sorted(rays[worst["pair"]].t)
    i = ts.index(worst["t"])
    return [(worst["pair"], 0.5 * (ts[j] + ts[j + 1])) for j in (i - 1, i) if 0 <= j < len(ts) - 1]


def rays_with_room(split: list, room: dict, narrowest: float = 1.0 / 256) -> list:
    """The new rays ``split`` proposes (pair, t, lo, hi, score: the middle ray's miss over the
    tolerance) that fit in each pair's ``room``, the largest misses first: a pair's ray budget goes
    where the table is worst (near an equal pair a fan design's direction swings 18 deg with a 5 %
    change of the pressure ratio), not to the first intervals in t."""
    room = dict(room)
    chosen = []
    for item in sorted(split, key=lambda item: -item[4]):
        if room[item[0]] > 0 and item[3] - item[2] > narrowest:
            room[item[0]] -= 1
            chosen.append(item)
    return chosen


def _held_commands(results: dict, i: int, r: int, t: float, mids, pmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Held-out ray i's commands (pair r, ray t, at the sums ``mids``) the source answered, and its answers."""
    from .surrogate_build import pair_commands

    h = results[("held", i)]
    c = pair_commands(3, r, t, mids, pmax, beyond=False)[:h["n_ok"]]
    return c, h["values"][:h["n_ok"]]


def _held_out_bound(model, results: dict, held: list, mids, pmax: float) -> tuple[dict, int]:
    """The table's error at the held-out pair rays (at the sums ``mids`` between the table's), and
    how many commands that measured."""
    cmds, vals = zip(*(_held_commands(results, i, r, t, mids, pmax) for i, (r, t) in enumerate(held)))
    cmds, vals = np.vstack(cmds), np.vstack(vals)
    return table_errors(model.evaluate(cmds), vals, cmds), len(cmds)


def _common_mode_bound(model, results: dict, checks: list, mags, max_common: float) -> tuple[float, dict, list]:
    """Commands with all three channels > 0: the error of treating the common part as pure
    stretch, the common pressure up to which it stayed within the tolerances (Pa), and per check
    ray whether every command on it was."""
    s = model.settings
    cc, cv, ray = [], [], []
    for i, w in enumerate(checks):
        h = results[("check", i)]
        cc.append(mags[1:h["n_ok"], None] * w[None, :])
        cv.append(h["values"][1:h["n_ok"]])
        ray += [i] * len(cc[-1])
    cc, cv, ray = np.vstack(cc), np.vstack(cv), np.array(ray, dtype=int)
    mine = model.evaluate(cc)
    use = mine.converged
    rc = rc_error(mine.curvature[use], cv[use, :2])
    dr = direction_error_deg(mine.curvature[use], cv[use, :2])
    common = cc[use].min(1)
    bad = (rc > s.common_tolerance) | (dr > s.common_direction_tolerance)
    # answered up to the largest checked common pressure below the first one off by too much
    # (every checked one when none was: then up to the equal-pressure table's end)
    answered = common < common[bad].min() if bad.any() else np.ones(len(common), dtype=bool)
    if bad.any():
        limit = float(common[answered].max()) if answered.any() else 0.0
    else:
        limit = max_common
    cbound = table_errors(mine, cv, cc, within=np.flatnonzero(use)[answered])
    cbound.update({"checked_points": int(use.sum()), "rc_rel_max_checked": float(rc.max()) if rc.size else None,
                   "direction_deg_max_checked": float(dr.max()) if dr.size else None,
                   "max_common_pressure_pa": limit, "tolerance_rc_rel": s.common_tolerance,
                   "tolerance_direction_deg": s.common_direction_tolerance})
    full = [not bad[ray[use] == i].any() for i in range(len(checks))]
    return limit, cbound, full


def table_errors(mine: BendState, ref: np.ndarray, pressures: np.ndarray, within=None) -> dict:
    """R_C, direction and stretch errors of ``mine`` against the source's values ``ref`` (N, 3)
    where both answered (and, if given, only at the indices ``within``)."""
    use = mine.converged & np.isfinite(ref).all(1)
    if within is not None:
        keep = np.zeros(len(use), dtype=bool)
        keep[within] = True
        use &= keep
    out = {"points": int(use.sum()), "refused": int((~mine.converged & np.isfinite(ref).all(1)).sum())}
    if not use.any():
        return out
    rc = rc_error(mine.curvature[use], ref[use, :2])
    worst = int(np.argmax(rc))
    out.update({"rc_rel_max": float(rc.max()), "rc_rel_median": float(np.median(rc)),
                "direction_deg_max": float(direction_error_deg(mine.curvature[use], ref[use, :2]).max()),
                "stretch_abs_max": float(np.abs(mine.axial_stretch[use] - ref[use, 2]).max()),
                "worst_at_bar": (pressures[use][worst] / PA_PER_BAR).round(4).tolist()})
    return out


__all__ = ["build_table", "source_options", "table_errors"]
