"""Surrogate rung: tables built offline from a higher rung (default ``section``) for one design.

What is tabulated (pressures in Pa, from 0 to the design's max_pressure or to where the source
stops converging, whichever comes first; the table ends there). The source is sampled along rays
of commands, one fresh ramp from rest per ray, in parallel (``surrogate_build.py``):

- 1 channel: curvature vector and axial stretch over the channel pressure, a cubic spline
  through the source's answers every ``pressure_step`` (plus the last pressure it reached).
- 3 channels: the response to two active channels (a, b) = (p_r, p_r+1) with the third at
  zero, which is how the allocator drives the body. Per pair, rays t = b / (a + b) sampled at
  sums a + b every ``pressure_step``, added adaptively where the response bends; a bicubic
  spline through them over (t, a + b) is resampled when the table is loaded onto a fine (a, b)
  grid that is read bilinearly (what makes a batch of 1e6 commands take a fraction of a
  second). A 3-fold symmetric section (equal channels at equal angles: ``pairs="auto"``) needs
  the rays of half of pair 0-1 only: the other half is its mirror image and pairs 1-2 and 2-0
  are rotations by 120 and 240 degrees. ``pairs="each"`` solves every pair over its whole range.
- Commands with all three pressures > 0 (the allocator never sends them, an operator might):
  the common part m = min(p) is subtracted and treated as pure stretch,
      k(p) ~ k_pair(p - m),   lambda(p) ~ lambda_pair(p - m) + lambda_common(m) - 1,
  with lambda_common tabulated from the source at equal pressures. A common pressure also
  stiffens the body, which this leaves out: the error is measured against the source along
  rays with all three channels pressurised, and such commands are answered only up to the
  common pressure below which it stayed within ``common_tolerance`` (R_C) and
  ``common_direction_tolerance``; above it they are refused (``error_bound['common_mode']``).

The error against the source is measured at held-out commands (on rays not in the table, at
pressures between its points; for 3 channels on all three pairs and both sides of the mirror,
so the symmetry assumption is checked too) and stored with the table: ``error_bound``. Outside
the built range the surrogate refuses: ``converged`` False, NaN numbers and a message naming the
range and, if the source failed, where and why.

Where a table comes from: a table shipped with the package (``config/surrogate_tables/``,
written by ``softcath surrogate build --shipped``), the cache (core/cache.py, kind ``surrogate``)
or a file given as ``table=``; each is used only if its key (a hash of the design's content, the
source rung, its options and solver version, the table settings and SURROGATE_VERSION) is the
model's. A missing or stale table is built (with a log line saying why) into the cache.
"""
from __future__ import annotations

import json
import logging
import math
import time
from bisect import bisect_right
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..cache import CacheStore, store_for
from ..design import Design
from ..errors import ModelError
from ..options import Option
from .base import BendModel, BendState, RungInfo, options_of
from .surrogate_build import direction_error_deg, rc_error
from ..units import PA_PER_BAR

# Bump when the table layout or the way it is built changes.
SURROGATE_VERSION = "surrogate-4"
_KIND = "surrogate"   # the cache kind of the tables
_ROT = np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0])
_COS, _SIN = np.cos(_ROT), np.sin(_ROT)
_log = logging.getLogger("softcath_ros.surrogate")


@dataclass(frozen=True)
class SurrogateSettings:
    source: str = "section"             # the rung the table is built from
    source_options: dict = field(default_factory=dict)  # its options (mesh_size, ...): part of the key
    pressure_step: float = 2000.0       # Pa between table points along a ray (3 channels: in a + b)
    initial_rays: int = 5               # 3 channels: rays over half a pair (t in [0, 1/2]) before refinement
    max_rays: int = 13                  # 3 channels: most rays over half a pair
    ray_tolerance: float = 0.005        # split between rays where the table misses the middle ray by more
                                        # than this in R_C (relative) ...
    ray_direction_tolerance: float = 0.2    # ... or by more than this in direction (degrees)
    held_out_rays: int = 3              # 3 channels: rays used only to measure the error, one per pair
                                        # in turn (1 channel: always one)
    fine_points: int = 321              # 3 channels: resampled points per axis (bilinear read-out)
    common_rays: int = 3                # rays with all three pressures > 0 that measure the common-mode error
    common_tolerance: float = 0.01      # such commands are answered while within this in R_C (relative) ...
    common_direction_tolerance: float = 0.5   # ... and this in direction (degrees), refused beyond
    pairs: str = "auto"                 # 3 channels: "auto" uses the section's 3-fold symmetry when it
                                        # has it, "rotated" requires it, "each" solves every pair


def _symmetric_three(design: Design, tol: float = 1e-7) -> bool:
    """True when the section maps onto itself under a 120 degree rotation (channel i -> i + 1);
    with circular holes it then is also mirror symmetric between any two channels."""
    if design.n_channels != 3:
        return False
    c, s = _COS[1], _SIN[1]
    chans = design.channels
    for i in range(3):
        x, y = chans[i].center
        nx, ny = chans[(i + 1) % 3].center
        if abs(c * x - s * y - nx) > tol or abs(s * x + c * y - ny) > tol:
            return False
        if abs(chans[i].radius - chans[(i + 1) % 3].radius) > tol:
            return False
    for part in (design.lumen, design.limiting_fibre):
        if part is not None and max(abs(v) for v in part.center) > tol:
            return False
    return True


_rc_error, _direction_error_deg = rc_error, direction_error_deg   # (tests and benchmarks import these names)


class SurrogateModel(BendModel):
    name = "surrogate"
    solver_version = SURROGATE_VERSION
    info = RungInfo(
        summary="tables built offline from a higher rung (default section) for one design",
        models=("free_bending", "device_stiffness"), pair_jacobian=True,
        builds="its table from the source rung (seconds for one channel, tens of seconds for three)",
        options=options_of(SurrogateSettings, {
            "source": "the rung the table is built from (default section)",
            "source_options": "that rung's options (mesh_size, ...): part of the table's key",
            "pressure_step": "Pa between table points along a ray (3 channels: in the pair's sum)",
            "initial_rays": "3 channels: rays over half a pair before refinement",
            "max_rays": "3 channels: most rays over half a pair",
            "ray_tolerance": "relative R_C miss at a middle ray above which rays are added",
            "ray_direction_tolerance": "direction miss (degrees) at a middle ray above which rays are added",
            "held_out_rays": "3 channels: rays used only to measure the error",
            "fine_points": "3 channels: resampled points per axis (bilinear read-out)",
            "common_rays": "rays with all three pressures > 0 that measure the common-mode error",
            "common_tolerance": "relative R_C error up to which such commands are answered",
            "common_direction_tolerance": "direction error (degrees) up to which such commands are answered",
            "pairs": "3 channels: 'auto' (symmetry if the section has it), 'rotated' (requires it), 'each'"}) + (
            Option("cache", "object", "True (the project cache), a cache root directory, or False (build every time)"),
            Option("table", "str", "a table file (softcath surrogate build --out); refused if stale"),
            Option("shipped", "bool", "use a table shipped with the package when it is current (default True)"),
            Option("workers", "int", "processes that build the table (default: the machine's cores, at most 8)"),
            Option("progress", "bool", "progress bars while building"),
            Option("rebuild", "bool", "build the table even if the cache or the package holds it"),
            Option("build", "bool", "False: refuse (one line, saying why) instead of building a missing table"),
            Option("answer_common", "bool", "answer commands whose common pressure is beyond the measured limit too "
                   "(as pure stretch, off by more than common_tolerance there): a simulated rig's truth")))

    def __init__(self, design: Design, source: str = "section", source_options: dict | None = None,
                 cache: bool | str | Path = True, progress: bool = False, rebuild: bool = False,
                 table: str | Path = "", shipped: bool = True, workers: int | None = None, build: bool = True,
                 answer_common: bool = False, **table_settings):
        """``source``: the rung to tabulate; ``source_options``: its options (mesh_size, ...).
        ``cache``: True (the project cache), a cache root directory, or False (build every time).
        ``table``: a table file to use (must be current). ``shipped``: use the package's table.
        ``workers``: build processes. ``progress``: tqdm bars while building. ``build``: False refuses
        (ModelError) instead of building a table it does not find current. ``answer_common``: answer
        commands with all three channels pressurised beyond the measured common-mode limit too (to
        the end of the equal-pressure table; not part of the table's key).
        ``table_settings``: ``SurrogateSettings`` fields."""
        super().__init__(design)
        self.answer_common = bool(answer_common)
        try:
            self.settings = SurrogateSettings(source=source, source_options=dict(source_options or {}),
                                              **table_settings)
        except TypeError as exc:
            raise ModelError(f"model 'surrogate': {exc}; settings: {list(SurrogateSettings.__annotations__)}") from None
        if self.settings.source == "surrogate":
            raise ModelError("model 'surrogate': source 'surrogate' would tabulate itself")
        from . import rung_info

        if rung_info(self.settings.source).depends_on_length:   # an unknown source: refused here, before a build
            # a table of a body of the design's length (fe3d, rod): another length is another table
            self.info = replace(self.info, depends_on_length=True)
        if self.settings.pairs not in ("auto", "each", "rotated"):
            raise ModelError(f"model 'surrogate': pairs '{self.settings.pairs}' must be 'auto', 'each' or 'rotated'")
        if not self.settings.pressure_step > 0:
            raise ModelError(f"model 'surrogate': pressure_step {self.settings.pressure_step!r} must be > 0 Pa")
        symmetric = _symmetric_three(design)
        if design.n_channels == 1:
            self.kind = "one_channel"
        elif design.n_channels == 3 and (self.settings.pairs != "rotated" or symmetric):
            self.kind = "three_channel"
        else:
            raise ModelError(f"model 'surrogate': design '{design.name}' has {design.n_channels} channels and "
                             f"pairs='{self.settings.pairs}'; the surrogate tabulates 1-channel designs, 3-channel "
                             "designs (pairs='auto' or 'each') and 3-fold symmetric 3-channel designs "
                             "(pairs='rotated')")
        self.rotated = self.kind == "three_channel" and symmetric and self.settings.pairs != "each"
        from .surrogate_build import default_workers

        self.workers = default_workers() if workers is None else max(1, int(workers))
        self.progress = progress
        self.store = store_for(cache)
        self.key = CacheStore.key(self.solver_version, self._cache_parts())
        self.origin = ""          # where the table came from: "file", "shipped", "cache" or "built"
        self.table_path: Path | None = None
        self.stale_reason = "forced rebuild" if rebuild else "none shipped, none in the cache"
        loaded = None
        if table:
            loaded = self._load_file(Path(table), required=True)
            self.origin, self.table_path = "file", Path(table)
        elif not rebuild:
            loaded = self._load_shipped() if shipped else None
            if loaded is None and self.store is not None:
                loaded = self._load()
                if loaded is not None:
                    self.origin, self.table_path = "cache", self.path
        self.built_now = loaded is None   # the table was built by this constructor (not found current)
        if loaded is None and not build:
            raise ModelError(f"model 'surrogate': no current table for design '{design.name}' from "
                             f"'{self.settings.source}': {self.stale_reason}")
        if loaded is None:
            _log.warning("surrogate: no current table for design '%s' from '%s' (%s); building one%s",
                         design.name, self.settings.source, self.stale_reason,
                         f" into {self.path}" if self.store is not None else " (no cache)")
            self.table, self.meta = self._build()
            self.origin = "built"
            if self.store is not None:
                self.table_path = self._save()
        else:
            self.table, self.meta = loaded
        self._prepare()

    # ------------------------------------------------------------------ identity
    def _cache_parts(self) -> list:
        """The design, the table settings and the source rung's declared version (a changed
        solver rebuilds the table)."""
        from . import rung_class

        try:
            source_version = rung_class(self.settings.source).solver_version
        except ModelError:
            source_version = None   # an unknown source: refused when the table is built
        return [self._design_hash(), asdict(self.settings), source_version]

    def _design_hash(self) -> str:
        """The design's hash a table is keyed on: without the length when the source answers per
        section (a table serves every length), with it when the source solves a whole body."""
        return self.design.content_hash() if self.info.depends_on_length else self.design.per_section_hash()

    def _cache_name(self) -> str:
        return f"{self.design.name}_{self.settings.source}"

    @property
    def path(self) -> Path | None:
        """The table's file in the cache (None without a cache)."""
        if self.store is None:
            return None
        return self.store.path(_KIND, self.solver_version, self._cache_parts(), self._cache_name(), "npz")

    def shipped_path(self) -> Path:
        """Where the package keeps (or would keep) this design's table."""
        from ...resources import shipped_dir

        return shipped_dir("surrogate_table") / f"{self._cache_name()}.npz"

    @property
    def error_bound(self) -> dict:
        """Measured error against the source at held-out commands (see module docstring)."""
        return self.meta["error_bound"]

    @property
    def pressure_range(self) -> tuple[float, float]:
        """Pa: every channel pressure must lie in this range (and, for 3 channels, every pair
        command in a cell where the source converged)."""
        return 0.0, float(self.meta["max_pressure"])

    # ------------------------------------------------------------------ building
    def _source_options(self) -> dict:
        opts = dict(self.settings.source_options)
        if self.settings.source in ("section", "fe3d"):
            opts.setdefault("progress", False)
            opts.setdefault("cache", self.store if self.store is not None else False)
        return opts

    def _build(self) -> tuple[dict, dict]:
        from tqdm import tqdm

        from .surrogate_build import RayPool

        t0 = time.perf_counter()
        with tqdm(total=0, desc=f"surrogate {self.design.name}: {self.settings.source} rays", unit="ray",
                  disable=not self.progress) as bar:
            pool = RayPool(self.design, self.settings.source, self._source_options(), self.workers, bar)
            try:
                table, meta = self._build_one(pool) if self.kind == "one_channel" else self._build_three(pool)
            except BaseException:
                pool.close(cancel=True)
                raise
            pool.close()
        meta.update({"version": SURROGATE_VERSION, "key": self.key, "design": self.design.name,
                     "design_hash": self._design_hash(), "kind": self.kind, "rotated": self.rotated,
                     "settings": asdict(self.settings), "source_version": self._cache_parts()[2],
                     "build_seconds": time.perf_counter() - t0, "workers": self.workers})
        return table, meta

    def _build_one(self, pool) -> tuple[dict, dict]:
        s = self.settings
        pmax = self.design.max_pressure
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
        self.table, self.meta = {"p": p, "y": y}, {"max_pressure": float(p[-1])}
        self._prepare()
        h = res["held"]
        n_h = h["n_ok"]
        held = mids[:n_h][mids[:n_h] <= p[-1]]
        mine = self.evaluate(held[:, None])
        bound = self._errors(mine, h["values"][:len(held)], held[:, None])
        meta = {"max_pressure": float(p[-1]), "source_failure": r["message"],
                "source_evaluations": int(len(grid) + len(mids)), "source_rays": 2,
                "error_bound": {"one_channel": bound}}
        return self.table, meta

    def _build_three(self, pool) -> tuple[dict, dict]:
        from .surrogate_build import PairRays, mirrored, pair_commands, pair_surface, reflection

        s, d = self.settings, self.design
        pmax = d.max_pressure
        n_step = max(int(math.ceil(pmax / s.pressure_step)), 4)
        sums = np.linspace(0.0, 2.0 * pmax, 2 * n_step + 1)      # a + b along a pair's ray
        mags = np.linspace(0.0, pmax, n_step + 1)                # the largest channel pressure
        pairs = (0,) if self.rotated else (0, 1, 2)
        half = 0.5 if self.rotated else 1.0
        refl = reflection(d) if self.rotated else None
        rays = {r: PairRays(sums) for r in pairs}
        rng = np.random.default_rng(0)
        n0 = s.initial_rays if self.rotated else 2 * s.initial_rays - 1
        rounds = {0: [(r, float(t)) for r in pairs for t in np.linspace(0.0, half, n0)]}
        for r, t in rounds[0]:
            pool.submit(("ray", 0, r, t), pair_commands(3, r, t, sums, pmax))
        # held out: every pair, t off the table's rays, sums between the table's
        held = [(i % 3, float(rng.uniform(0.03, 0.97))) for i in range(s.held_out_rays)]
        for i, (r, t) in enumerate(held):
            pool.submit(("held", i), pair_commands(3, r, t, sums[:-1] + 0.5 * (sums[1] - sums[0]), pmax))
        pool.submit(("common",), np.repeat(mags[:, None], 3, 1))
        # all three > 0: a pair command plus a common part of 20%, 2%, 0.2% ... of the larger channel
        # (a vented channel that has not yet reached zero is the usual case)
        checks = []
        for i in range(s.common_rays):
            w = np.array([1.0, rng.uniform(0.2, 1.0), 0.2 / 10 ** i])
            checks.append(np.roll(w, i % 3))
            pool.submit(("check", i), mags[:, None] * checks[-1][None, :])

        def surface(r):
            arrays = rays[r].arrays()
            return pair_surface(*(mirrored(*arrays, refl) if self.rotated else arrays), sums)

        results, waiting, refine_log = {}, {0: len(rounds[0])}, []
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
                for r, t, lo, hi in rounds[k]:
                    got = results[("ray", k, r, t)]
                    n = got["n_ok"]
                    ev, reachable = surf[r]
                    m = sums[1:n]
                    inside = reachable(np.full(len(m), t), m)
                    if inside.any():
                        want = ev(np.full(int(inside.sum()), t), m[inside])
                        miss_rc = float(np.nanmax(rc_error(want[:, :2], got["values"][1:n][inside, :2])))
                        miss_dir = float(np.nanmax(direction_error_deg(want[:, :2], got["values"][1:n][inside, :2])))
                    else:
                        miss_rc = miss_dir = float("inf")
                    refine_log.append({"pair": r, "t": t, "rc_miss": miss_rc, "direction_miss_deg": miss_dir})
                    if miss_rc > s.ray_tolerance or miss_dir > s.ray_direction_tolerance:
                        split += [(r, 0.5 * (lo + t), lo, t), (r, 0.5 * (t + hi), t, hi)]
            for item in rounds[k]:
                r, t = item[0], item[1]
                rays[r].add(t, results.pop(("ray", k, r, t)))
            if k == 0:
                split = []
                for r in pairs:
                    ts = sorted(rays[r].t)
                    split += [(r, 0.5 * (a + b), a, b) for a, b in zip(ts[:-1], ts[1:])]
            room = {r: s.max_rays - len(rays[r].t) for r in pairs}
            nxt = []
            for item in split:
                if room[item[0]] > 0 and item[3] - item[2] > 1.0 / 256:
                    room[item[0]] -= 1
                    nxt.append(item)
            if nxt:
                rounds[k + 1], waiting[k + 1] = nxt, len(nxt)
                for r, t, _, _ in nxt:
                    pool.submit(("ray", k + 1, r, t), pair_commands(3, r, t, sums, pmax))
        # the table
        arrs = [rays[r].arrays() for r in pairs]
        cm = results[("common",)]
        n_cm = cm["n_ok"]
        table = {"sums": sums, "ray_pair": np.concatenate([np.full(len(a[0]), r) for r, a in zip(pairs, arrs)]),
                 "ray_t": np.concatenate([a[0] for a in arrs]), "ray_values": np.concatenate([a[1] for a in arrs]),
                 "ray_reach": np.concatenate([a[2] for a in arrs]), "ray_complete": np.concatenate([a[3] for a in arrs]),
                 "common_p": mags[:n_cm], "common_stretch": cm["values"][:n_cm, 2]}
        max_common = float(mags[n_cm - 1]) if n_cm else 0.0
        self.table = table
        self.meta = {"max_pressure": float(pmax), "rotated": self.rotated, "max_common_pressure": max_common}
        self._prepare()
        # held-out error
        cmds, vals = [], []
        for i, (r, t) in enumerate(held):
            h = results[("held", i)]
            c = pair_commands(3, r, t, sums[:-1] + 0.5 * (sums[1] - sums[0]), pmax)[:h["n_ok"]]
            cmds.append(c[1:] if len(c) and not c[0].any() else c)
            vals.append(h["values"][:h["n_ok"]][len(c) - len(cmds[-1]):])
        cmds, vals = np.vstack(cmds), np.vstack(vals)
        inside = cmds.max(1) <= pmax                     # the rays were solved one step beyond max_pressure
        cmds, vals = cmds[inside], vals[inside]
        bound = self._errors(self.evaluate(cmds), vals, cmds)
        # commands with all three > 0: the common-mode error against the common pressure
        cc, cv = [], []
        for i, w in enumerate(checks):
            h = results[("check", i)]
            cc.append(mags[1:h["n_ok"], None] * w[None, :])
            cv.append(h["values"][1:h["n_ok"]])
        cc, cv = np.vstack(cc), np.vstack(cv)
        mine = self.evaluate(cc)
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
        cbound = self._errors(mine, cv, cc, within=np.flatnonzero(use)[answered])
        cbound.update({"checked_points": int(use.sum()), "rc_rel_max_checked": float(rc.max()) if rc.size else None,
                       "direction_deg_max_checked": float(dr.max()) if dr.size else None,
                       "max_common_pressure_pa": limit, "tolerance_rc_rel": s.common_tolerance,
                       "tolerance_direction_deg": s.common_direction_tolerance})
        failures = [res["message"] for tag, res in sorted(results.items(), key=lambda x: str(x[0]))
                    if tag[0] in ("ray", "common") and res["message"]]
        failures += [m for r in pairs for m in rays[r].messages]
        reach_bar = {f"{r}:{t:.4f}": None if c else float(sums[n - 1] / PA_PER_BAR) if n else 0.0
                     for r, a in zip(pairs, arrs) for t, n, c in zip(a[0], a[2], a[3])}
        n_rays = sum(len(a[0]) for a in arrs)
        meta = {"max_pressure": float(pmax), "rotated": self.rotated, "max_common_pressure": limit,
                "max_common_table_pressure": max_common,
                "source_failure": "; ".join(dict.fromkeys(failures[:3])),
                "source_rays": int(n_rays + len(held) + 1 + len(checks)), "table_rays": int(n_rays),
                "source_evaluations": int(sum(len(pair_commands(3, r, t, sums, pmax))
                                              for r, a in zip(pairs, arrs) for t in a[0])
                                          + len(cmds) + len(mags) * (1 + len(checks))),
                "ray_reach_sum_bar": reach_bar, "refinement": refine_log,
                "error_bound": {"pair": bound, "common_mode": cbound},
                "common_checks_direction": [w.round(4).tolist() for w in checks],
                "common_curvature_max_per_m": float(np.nanmax(np.abs(cm["values"][:n_cm, :2]))) if n_cm else 0.0}
        return table, meta

    @staticmethod
    def _errors(mine: BendState, ref: np.ndarray, pressures: np.ndarray, within=None) -> dict:
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

    # ------------------------------------------------------------------ storage
    def _arrays(self) -> dict:
        return {"meta": np.array(json.dumps(self.meta)), **self.table}

    def _save(self) -> Path:
        return self.store.save_arrays(_KIND, self.solver_version, self._cache_parts(), self._arrays(),
                                      self._cache_name())

    def write(self, path: str | Path) -> Path:
        """The table as a file (``softcath surrogate build --out``; the shipped tables)."""
        from ..cache import _atomic_write

        path = Path(path)
        _atomic_write(path, lambda f: np.savez_compressed(f, **self._arrays()))
        return path

    @staticmethod
    def _split(arrays: dict):
        meta = json.loads(str(arrays.pop("meta")))
        return arrays, meta

    def _load(self):
        table = self.store.load_arrays(_KIND, self.solver_version, self._cache_parts(), self._cache_name(),
                                       require=("meta",))
        if table is None:
            return None
        table, meta = self._split(table)
        return (table, meta) if meta.get("key") == self.key else None

    def _load_file(self, path: Path, required: bool = False):
        """The table in ``path`` if it is this model's (same key); else None, or with ``required`` a
        one-line error saying why it does not fit."""
        try:
            with np.load(path, allow_pickle=False) as z:
                table, meta = self._split({k: z[k] for k in z.files})
        except Exception as exc:
            if required:
                raise ModelError(f"model 'surrogate': table {path} cannot be read ({type(exc).__name__})") from None
            return None
        if meta.get("key") == self.key:
            return table, meta
        self.stale_reason = self._stale_reason(meta)
        if required:
            raise ModelError(f"model 'surrogate': table {path} is not current for design '{self.design.name}' "
                             f"({self.stale_reason}); rebuild it: softcath surrogate build {self.design.name}")
        return None

    def _stale_reason(self, meta: dict) -> str:
        if meta.get("design_hash") != self._design_hash():
            return f"built for another design content (hash {meta.get('design_hash')})"
        if meta.get("version") != SURROGATE_VERSION:
            return f"built by {meta.get('version')}, this is {SURROGATE_VERSION}"
        now = self._cache_parts()[2]
        if meta.get("source_version", now) != now:
            return f"built from {meta.get('source_version')}, the source rung is now {now}"
        return "built with other table settings"

    def _load_shipped(self):
        path = self.shipped_path()
        if not path.is_file():
            return None
        loaded = self._load_file(path)
        if loaded is not None:
            self.origin, self.table_path = "shipped", path
        else:
            self.stale_reason = f"the shipped table {path.name} is stale: {self.stale_reason}"
        return loaded

    # ------------------------------------------------------------------ evaluation
    def _prepare(self) -> None:
        t = self.table
        self._pmax = float(self.meta["max_pressure"])
        # What a read-out needs is stored with the table (spline coefficients, the fine grid), so
        # loading one imports no scipy (start-up time); it is computed once, when built.
        if self.kind == "one_channel":
            if "coeffs" not in t:
                from scipy.interpolate import CubicSpline

                t["coeffs"] = CubicSpline(t["p"], t["y"], axis=0).c    # (4, m, 3): highest power first
            self._breaks_arr = t["p"]
            self._breaks = t["p"].tolist()      # plain floats for the single-command path
            self._coeffs = t["coeffs"]
        else:
            if "fine_table" not in t:
                tab, t["fine_ok"] = self._fine_tables()
                t["fine_table"] = tab.astype(np.float32)   # half the file; 6e-8 relative, far below the error
            tab, self._cell_ok = t["fine_table"].astype(np.float64), t["fine_ok"]
            self._nf = self.settings.fine_points - 1
            self._hf = self._pmax / self._nf
            self._flat = np.ascontiguousarray(tab.reshape(-1, 3))
            self._rotated = tab.shape[0] == 1
            self._all_ok = bool(self._cell_ok.all())
            self._cp, self._cs = t["common_p"], t["common_stretch"]
            self._max_common = float(self.meta.get("max_common_table_pressure", self.meta["max_common_pressure"])
                                     if self.answer_common else self.meta["max_common_pressure"])
            self._stretch0 = float(np.interp(0.0, self._cp, self._cs)) if len(self._cp) else 1.0
            self._rot = [(float(c), float(s)) for c, s in zip(_COS, _SIN)]

    def _fine_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """The rays resampled onto the fine (a, b) grid of each pair table (one when rotated), and
        which of its cells lie where the source converged on both bracketing rays."""
        from .surrogate_build import mirrored, pair_surface, reflection

        t = self.table
        fine = np.linspace(0.0, self._pmax, self.settings.fine_points)
        a, b = np.meshgrid(fine, fine, indexing="ij")
        m = a + b
        tq = np.divide(b, m, out=np.zeros_like(m), where=m > 0)
        tabs, oks = [], []
        for r in ((0,) if self.meta["rotated"] else (0, 1, 2)):
            sel = t["ray_pair"] == r
            rays = (t["ray_t"][sel], t["ray_values"][sel], t["ray_reach"][sel], t["ray_complete"][sel])
            if self.meta["rotated"]:
                rays = mirrored(*rays, reflection(self.design))
            ev, reachable = pair_surface(*rays, t["sums"])
            tabs.append(ev(tq.ravel(), m.ravel()).reshape(*m.shape, 3))
            node = reachable(tq, m)
            oks.append(node[:-1, :-1] & node[1:, :-1] & node[:-1, 1:] & node[1:, 1:])
        return np.stack(tabs), np.stack(oks)

    def _refusal(self, p: np.ndarray, why: str) -> str:
        msg = (f"surrogate: command p = {', '.join(f'{v / PA_PER_BAR:.4f}' for v in p)} bar {why} "
               f"(built from '{self.settings.source}' over 0..{self._pmax / PA_PER_BAR:.4f} bar")
        fail = self.meta.get("source_failure")
        return msg + (f"; the source failed beyond: {fail})" if fail else ")")

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        n = pressures.shape[0]
        inside = (pressures >= 0.0).all(1) & (pressures <= self._pmax).all(1)
        if self.kind == "one_channel":
            if n == 1 and inside[0]:  # one command (model_node): the spline's polynomial in plain floats
                return self._one_command(float(pressures[0, 0]))
            y = self._piecewise(np.clip(pressures[:, 0], 0.0, self._pmax))
            k, lam = y[:, :2], y[:, 2]
            ok = inside
            reason = "is outside the table's pressure range"
        else:
            if n == 1 and inside[0]:   # one pair command (model_node): the read-out in plain floats
                p0, p1, p2 = pressures[0].tolist()
                zero = 0 if p0 == 0.0 else 1 if p1 == 0.0 else 2 if p2 == 0.0 else -1
                got = None if zero < 0 else self.pair_jacobian((zero + 1) % 3, (zero + 2) % 3,
                                                                (p0, p1, p2)[(zero + 1) % 3], (p0, p1, p2)[(zero + 2) % 3],
                                                                derivatives=False)
                if got is not None:
                    return BendState(curvature=np.array([got[0]]), axial_stretch=np.array([got[1]]),
                                     converged=np.ones(1, dtype=bool))
            k, lam, ok = self._three(pressures, inside)
            reason = "is outside the table's range (negative, above the range, or where the source failed)"
            first = np.flatnonzero(~ok)
            if first.size and inside[first[0]] and pressures[first[0]].min() > self._max_common:
                s = self.settings
                reason = (f"has a pressure common to all three channels above {self._max_common / PA_PER_BAR:.4f} "
                          f"bar, beyond which treating it as pure stretch was measured off the source by more than "
                          f"{s.common_tolerance:.1%} in R_C or {s.common_direction_tolerance:g} degrees, so the "
                          "surrogate does not answer it")
        if not ok.all():
            k = np.where(ok[:, None], k, np.nan)
            lam = np.where(ok, lam, np.nan)
            bad = np.flatnonzero(~ok)
            msg = self._refusal(pressures[bad[0]], reason)
            if len(bad) > 1:
                msg += f" and {len(bad) - 1} more command(s)"
        else:
            msg = ""
        return BendState(curvature=k, axial_stretch=lam, converged=ok, message=msg)

    def _piecewise(self, p: np.ndarray) -> np.ndarray:
        """The 1-channel cubic spline at pressures p (N,) -> (N, 3)."""
        j = np.clip(np.searchsorted(self._breaks_arr, p, side="right") - 1, 0, len(self._breaks) - 2)
        x = (p - self._breaks_arr[j])[:, None]
        c = self._coeffs[:, j]                      # (4, N, 3)
        return ((c[0] * x + c[1]) * x + c[2]) * x + c[3]

    def _one_command(self, p: float) -> BendState:
        j = min(max(bisect_right(self._breaks, p) - 1, 0), len(self._breaks) - 2)
        x = p - self._breaks[j]
        c = self._coeffs[:, j]                      # (4, 3): highest power first
        y = ((c[0] * x + c[1]) * x + c[2]) * x + c[3]
        return BendState(curvature=y[None, :2], axial_stretch=y[None, 2], converged=np.ones(1, dtype=bool))

    def _three(self, p: np.ndarray, inside: np.ndarray):
        m = p.min(1)
        q = p - m[:, None]
        zero = q.argmin(1)
        r = (zero + 1) % 3
        rows = np.arange(len(p))
        a = np.clip(q[rows, r], 0.0, self._pmax)
        b = np.clip(q[rows, (zero + 2) % 3], 0.0, self._pmax)
        pair = np.zeros_like(r) if self._rotated else r
        kl = self._bilinear(pair, a, b)
        if self._rotated:
            c, s = _COS[r], _SIN[r]
            k = np.column_stack([c * kl[:, 0] - s * kl[:, 1], s * kl[:, 0] + c * kl[:, 1]])
        else:
            k = kl[:, :2]
        lam = kl[:, 2] + np.interp(m, self._cp, self._cs) - 1.0
        ok = inside & (m <= self._max_common)
        if not self._all_ok:
            ia = np.minimum((a / self._hf).astype(np.intp), self._nf - 1)
            ib = np.minimum((b / self._hf).astype(np.intp), self._nf - 1)
            ok &= self._cell_ok[pair, ia, ib]
        return k, lam, ok

    def pair_jacobian(self, i: int, j: int, p_i: float, p_j: float, derivatives: bool = True):
        """Channels i and j at p_i, p_j (Pa), the others at zero: (curvature [kx, ky], stretch,
        dk/dp_i, dk/dp_j) from the same bilinear read-out as ``evaluate`` (its exact derivative
        inside a cell), in plain floats; None where ``evaluate`` refuses the command."""
        if self.kind == "one_channel":
            raise ModelError("model 'surrogate': pair_jacobian needs a 3-channel table")
        if (i + 1) % 3 == j:
            r, a, b, swap = i, p_i, p_j, False
        elif (j + 1) % 3 == i:
            r, a, b, swap = j, p_j, p_i, True
        else:
            raise ModelError(f"model 'surrogate': channels {i}, {j} are not a pair")
        if not (0.0 <= a <= self._pmax and 0.0 <= b <= self._pmax):
            return None
        n, hf = self._nf, self._hf
        x, y = a / hf, b / hf
        ia, ib = min(int(x), n - 1), min(int(y), n - 1)
        pair = 0 if self._rotated else r
        if not self._all_ok and not self._cell_ok[pair, ia, ib]:
            return None
        t, u = x - ia, y - ib
        k0 = (pair * (n + 1) + ia) * (n + 1) + ib
        f00, f01, f10, f11 = self._flat[[k0, k0 + 1, k0 + n + 1, k0 + n + 2]].tolist()
        val = [(1 - t) * ((1 - u) * f00[c] + u * f01[c]) + t * ((1 - u) * f10[c] + u * f11[c]) for c in range(3)]
        if derivatives:
            da = [((1 - u) * (f10[c] - f00[c]) + u * (f11[c] - f01[c])) / hf for c in range(2)]
            db = [((1 - t) * (f01[c] - f00[c]) + t * (f11[c] - f10[c])) / hf for c in range(2)]
        else:
            da = db = [0.0, 0.0]
        k = val[:2]
        if self._rotated and r:
            c, s = self._rot[r]
            k, da, db = ([c * v[0] - s * v[1], s * v[0] + c * v[1]] for v in (k, da, db))
        if swap:
            da, db = db, da
        return k, val[2] + self._stretch0 - 1.0, da, db

    def _bilinear(self, pair: np.ndarray, a: np.ndarray, b: np.ndarray, chunk: int = 1 << 15) -> np.ndarray:
        n, f = self._nf, self._flat
        out = np.empty((a.size, 3))
        for s0 in range(0, a.size, chunk):  # chunks keep the temporaries in cache
            x = a[s0:s0 + chunk] / self._hf
            y = b[s0:s0 + chunk] / self._hf
            i = np.minimum(x.astype(np.intp), n - 1)
            j = np.minimum(y.astype(np.intp), n - 1)
            t = (x - i)[:, None]
            u = (y - j)[:, None]
            k0 = (pair[s0:s0 + chunk] * (n + 1) + i) * (n + 1) + j
            f00, f01, f10, f11 = f[k0], f[k0 + 1], f[k0 + n + 1], f[k0 + n + 2]
            lo = f00 + (f01 - f00) * u
            out[s0:s0 + chunk] = lo + (f10 + (f11 - f10) * u - lo) * t
        return out


__all__ = ["SurrogateModel", "SurrogateSettings", "SURROGATE_VERSION"]
