"""Surrogate rung: tables built offline from a higher rung (default ``section``) for one design.

What is tabulated (pressures in Pa, from 0 to the design's max_pressure or to where the source
stops converging, whichever comes first; the table ends there):

- 1 channel: curvature vector and axial stretch over the channel pressure, a cubic spline
  through the source's answers on a grid (plus the last pressure the source reached).
- 3 channels: the response to two active channels (a, b) = (p_r, p_r+1) with the third at
  zero, which is how the allocator drives the body: one table over (a, b) per pair, a cubic
  spline through the source's grid resampled onto a fine grid that is read bilinearly
  (bilinear on the fine grid is what makes a batch of 1e6 commands take a fraction of a
  second). With ``pairs="rotated"`` (3-fold symmetric sections only) just pair 0-1 is built
  and rotated by 120 and 240 degrees for the others (rotating the body by 120 degrees maps
  channel i onto channel i + 1): a third of the cost, but the section rung's mesh is not
  exactly symmetric, which costs up to ~2% in R_C near lumen contact, so the default
  tabulates each pair.
- Commands with all three pressures > 0 (the allocator never sends them, an operator might):
  the common part m = min(p) is subtracted and treated as pure stretch,
      k(p) ~ k_pair(p - m),   lambda(p) ~ lambda_pair(p - m) + lambda_common(m) - 1,
  with lambda_common tabulated from the source at equal pressures. A common pressure also
  stiffens the body a little, which this leaves out; the error this makes is measured against
  the source at a few such commands and stored (``error_bound['common_mode']``).

The error against the source is measured at held-out commands (not on the grid; for 3
channels on all three pairs, so the symmetry assumption is checked too) and stored with the
table: ``error_bound``. Outside the built range the surrogate refuses: ``converged`` False,
NaN numbers and a message naming the range and, if the source failed, where and why.

Tables are stored in the cache (core/cache.py, kind ``surrogate``) under a hash of the design's
content, the source rung, its options and the table settings: a changed design builds anew.
"""
from __future__ import annotations

import json
import math
import time
from bisect import bisect_right
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..cache import CacheStore, store_for
from ..design import Design
from ..errors import ModelError
from ..options import Option
from .base import BendModel, BendState, RungInfo, options_of
from ..units import PA_PER_BAR

# Bump when the table layout or the way it is built changes.
SURROGATE_VERSION = "surrogate-2"
_KIND = "surrogate"   # the cache kind of the tables
_ROT = np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0])
_COS, _SIN = np.cos(_ROT), np.sin(_ROT)


@dataclass(frozen=True)
class SurrogateSettings:
    source: str = "section"             # the rung the table is built from
    source_options: dict = field(default_factory=dict)  # its options (mesh_size, ...): part of the key
    grid_points: int = 21               # source evaluations per pressure axis
    fine_points: int = 321              # 3 channels: resampled points per axis (bilinear read-out)
    held_out: int = 24                  # source evaluations used only to measure the error
    common_points: int = 9              # equal-pressure commands for lambda_common
    common_checks: int = 5              # commands with all three pressures > 0 to bound that error
    common_tolerance: float = 0.005     # relative R_C error above which such commands are refused
    pairs: str = "each"                 # 3 channels: "each" tabulates all three pairs; "rotated" only
                                        # pair 0-1 and rotates it (a third of the cost, exact only if
                                        # the source is exactly 3-fold symmetric: the section rung's
                                        # mesh is not, up to ~2% in R_C near lumen contact)


def _symmetric_three(design: Design, tol: float = 1e-7) -> bool:
    """True when the section maps onto itself under a 120 degree rotation (channel i -> i + 1)."""
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


def _rc_error(k_model: np.ndarray, k_ref: np.ndarray) -> np.ndarray:
    """Relative error in R_C = 1/|k|: |R_model - R_ref| / R_ref."""
    km = np.hypot(k_model[..., 0], k_model[..., 1])
    kr = np.hypot(k_ref[..., 0], k_ref[..., 1])
    return np.abs(kr / km - 1.0)


def _direction_error_deg(k_model: np.ndarray, k_ref: np.ndarray) -> np.ndarray:
    d = np.arctan2(k_model[..., 1], k_model[..., 0]) - np.arctan2(k_ref[..., 1], k_ref[..., 0])
    return np.degrees(np.abs((d + np.pi) % (2 * np.pi) - np.pi))


class SurrogateModel(BendModel):
    name = "surrogate"
    solver_version = SURROGATE_VERSION
    info = RungInfo(
        summary="tables built offline from a higher rung (default section) for one design",
        models=("free_bending", "device_stiffness"),
        options=options_of(SurrogateSettings, {
            "source": "the rung the table is built from (default section)",
            "source_options": "that rung's options (mesh_size, ...): part of the table's key",
            "grid_points": "source evaluations per pressure axis",
            "fine_points": "3 channels: resampled points per axis (bilinear read-out)",
            "held_out": "source evaluations used only to measure the error",
            "common_points": "equal-pressure commands for the common-mode stretch",
            "common_checks": "commands with all three pressures > 0 that bound the common-mode error",
            "common_tolerance": "relative R_C error above which such commands are refused",
            "pairs": "3 channels: 'each' tabulates all three pairs, 'rotated' pair 0-1 only"}) + (
            Option("cache", "object", "True (the project cache), a cache root directory, or False (build every time)"),
            Option("progress", "bool", "progress bars while building"),
            Option("rebuild", "bool", "build the table even if the cache holds it")))

    def __init__(self, design: Design, source: str = "section", source_options: dict | None = None,
                 cache: bool | str | Path = True, progress: bool = False, rebuild: bool = False,
                 **table_settings):
        """``source``: the rung to tabulate; ``source_options``: its options (mesh_size, ...).
        ``cache``: True (the project cache), a cache root directory, or False (build every time).
        ``progress``: tqdm bars while building. ``table_settings``: ``SurrogateSettings`` fields."""
        super().__init__(design)
        try:
            self.settings = SurrogateSettings(source=source, source_options=dict(source_options or {}),
                                              **table_settings)
        except TypeError as exc:
            raise ModelError(f"model 'surrogate': {exc}; settings: {list(SurrogateSettings.__annotations__)}") from None
        if self.settings.source == "surrogate":
            raise ModelError("model 'surrogate': source 'surrogate' would tabulate itself")
        if design.n_channels == 1:
            self.kind = "one_channel"
        elif design.n_channels == 3 and (self.settings.pairs == "each" or _symmetric_three(design)):
            self.kind = "three_channel"
        else:
            raise ModelError(f"model 'surrogate': design '{design.name}' has {design.n_channels} channels and "
                             f"pairs='{self.settings.pairs}'; the surrogate tabulates 1-channel designs, 3-channel "
                             "designs (pairs='each') and 3-fold symmetric 3-channel designs (pairs='rotated')")
        if self.settings.pairs not in ("each", "rotated"):
            raise ModelError(f"model 'surrogate': pairs '{self.settings.pairs}' must be 'each' or 'rotated'")
        self.progress = progress
        self.store = store_for(cache)
        self.key = CacheStore.key(self.solver_version, self._cache_parts())
        loaded = None if rebuild or self.store is None else self._load()
        self.built_now = loaded is None   # the table was built by this constructor (not from the cache)
        if loaded is None:
            self.table, self.meta = self._build()
            if self.store is not None:
                self._save()
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
        return [self.design.content_hash(), asdict(self.settings), source_version]

    def _cache_name(self) -> str:
        return f"{self.design.name}_{self.settings.source}"

    @property
    def path(self) -> Path | None:
        """The table's file in the cache (None without a cache)."""
        if self.store is None:
            return None
        return self.store.path(_KIND, self.solver_version, self._cache_parts(), self._cache_name(), "npz")

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
    def _source(self, progress: bool | None = None):
        from . import make_model

        opts = dict(self.settings.source_options)
        if self.settings.source in ("section", "fe3d"):
            opts.setdefault("progress", self.progress if progress is None else progress)
            opts.setdefault("cache", self.store if self.store is not None else True)
        return make_model(self.settings.source, self.design, **opts)

    def _build(self) -> tuple[dict, dict]:
        t0 = time.perf_counter()
        src = self._source()
        if self.kind == "one_channel":
            table, meta = self._build_one(src)
        else:
            table, meta = self._build_three(src)
        meta.update({"version": SURROGATE_VERSION, "key": self.key, "design": self.design.name,
                     "design_hash": self.design.content_hash(), "kind": self.kind,
                     "settings": asdict(self.settings), "build_seconds": time.perf_counter() - t0})
        return table, meta

    def _stage(self, desc: str, total: int):
        from tqdm import tqdm

        return tqdm(total=total, desc=f"surrogate: {desc}", unit="cmd", disable=not self.progress)

    def _run(self, src, pressures: np.ndarray, desc: str) -> BendState:
        with self._stage(desc, len(pressures)) as bar:
            state = src.evaluate(pressures)
            bar.update(len(pressures))
        return state

    def _build_one(self, src) -> tuple[dict, dict]:
        s = self.settings
        pmax = self.design.max_pressure
        grid = np.linspace(0.0, pmax, s.grid_points)
        st = self._run(src, grid[:, None], "grid")
        ok = st.converged
        n_ok = int(np.argmin(ok)) if not ok.all() else len(grid)  # the table ends at the first failure
        if n_ok < 4:
            raise ModelError(f"model 'surrogate': source '{s.source}' converged at only {n_ok} of the grid "
                             f"pressures from 0 ({st.message}); too few for a table")
        p = grid[:n_ok]
        y = np.column_stack([st.curvature[:n_ok], st.axial_stretch[:n_ok]])
        failure = ""
        if n_ok < len(grid):
            failure = st.message.split("; ")[0]  # the later ones repeat the first failure
            last = (st.last_converged or [None] * len(grid))[n_ok]
            if last is not None and last["pressure"][0] > p[-1] + 1.0:
                p = np.append(p, last["pressure"][0])
                y = np.vstack([y, [*last["curvature"], last["axial_stretch"]]])
        # held-out: midpoints between knots (where interpolation error is largest)
        mids = 0.5 * (p[1:] + p[:-1])
        take = np.linspace(0, len(mids) - 1, min(s.held_out, len(mids))).round().astype(int)
        held = np.unique(mids[take])
        table = {"p": p, "y": y}
        self.table, self.meta = table, {"max_pressure": float(p[-1])}
        self._prepare()
        ref = self._run(src, held[:, None], "held-out")
        mine = self.evaluate(held[:, None])
        good = ref.converged
        bound = self._errors(mine, ref, good, held[:, None])
        meta = {"max_pressure": float(p[-1]), "source_failure": failure, "source_evaluations":
                int(len(grid) + len(held)), "error_bound": {"one_channel": bound}}
        return table, meta

    def _build_three(self, src) -> tuple[dict, dict]:
        s = self.settings
        pmax = self.design.max_pressure
        g = np.linspace(0.0, pmax, s.grid_points)
        n = len(g)
        # pair r: channel r at a, channel r + 1 at b, the third at zero; "rotated" builds pair 0 only
        pairs = 1 if s.pairs == "rotated" else 3
        tabs, oks, messages, failed = [], [], [], 0
        for r in range(pairs):
            z, conv, msgs = self._pair_grid(g, r)
            cell_ok = conv[:-1, :-1] & conv[1:, :-1] & conv[:-1, 1:] & conv[1:, 1:]
            # and not next to a failed cell: the response turns sharply where the source is about to
            # fail (lumen walls closing), which a spline through the grid does not follow
            near = np.pad(cell_ok, 1, constant_values=True)
            oks.append(cell_ok & near[:-2, 1:-1] & near[2:, 1:-1] & near[1:-1, :-2] & near[1:-1, 2:])
            tabs.append(self._resample(g, z, conv))
            messages += msgs
            failed += int((~conv).sum())
        fine = np.linspace(0.0, pmax, s.fine_points)
        tab, cell_ok = np.stack(tabs), np.stack(oks)
        # equal pressures: pure stretch (the curvature there is the source's asymmetry, kept as a check)
        cm = np.linspace(0.0, pmax, s.common_points)
        stc = self._run(src, np.repeat(cm[:, None], 3, 1), "common pressure")
        cm_ok = stc.converged
        n_cm = int(np.argmin(cm_ok)) if not cm_ok.all() else len(cm)
        table = {"grid": g, "fine": fine, "table": tab, "cell_ok": cell_ok,
                 "common_p": cm[:n_cm], "common_stretch": stc.axial_stretch[:n_cm]}
        self.table = table
        self.meta = {"max_pressure": float(pmax), "max_common_pressure": float(cm[n_cm - 1]) if n_cm else 0.0}
        self._prepare()
        rng = np.random.default_rng(0)
        # held-out pair commands on all three pairs, inside usable cells
        held = []
        while len(held) < s.held_out:
            a, b = rng.uniform(0.05 * pmax, pmax, 2)
            ia, ib = min(int(a / g[1]), n - 2), min(int(b / g[1]), n - 2)
            zero = len(held) % 3
            if not cell_ok[((zero + 1) % 3) % pairs, ia, ib]:
                continue
            p = np.zeros(3)
            p[(zero + 1) % 3], p[(zero + 2) % 3] = a, b
            held.append(p)
        held = np.array(held)
        ref = self._fresh_each(held, "held-out")
        bound = self._errors(self.evaluate(held), ref, ref.converged, held)
        # commands with all three > 0: the common-part approximation
        common = []
        while len(common) < s.common_checks:
            p = rng.uniform(0.05 * pmax, 0.6 * pmax, 3)
            if p.min() <= self.meta["max_common_pressure"]:
                common.append(p)
        common = np.array(common)
        refc = self._fresh_each(common, "common-mode checks")
        cbound = self._errors(self.evaluate(common), refc, refc.converged, common)
        failure = "; ".join(messages[:3] + [stc.message.split("; ")[0]] if stc.message else messages[:3])
        meta = {"max_pressure": float(pmax), "max_common_pressure": self.meta["max_common_pressure"],
                "source_failure": failure, "failed_grid_points": failed,
                "source_evaluations": int(pairs * n * n + len(cm) + len(held) + len(common)),
                "error_bound": {"pair": bound, "common_mode": cbound},
                "common_checks_bar": (common / PA_PER_BAR).round(4).tolist(),
                "common_curvature_max_per_m": float(np.nanmax(np.abs(stc.curvature[:n_cm]))) if n_cm else 0.0}
        return table, meta

    def _fresh_each(self, pressures: np.ndarray, desc: str) -> BendState:
        """The source's answer to each command on its own ramp from zero (see the pair grid)."""
        states = []
        with self._stage(desc, len(pressures)) as bar:
            for p in pressures:
                states.append(self._source(progress=False).evaluate(p[None, :]))
                bar.update(1)
        return BendState(curvature=np.vstack([st.curvature for st in states]),
                         axial_stretch=np.concatenate([st.axial_stretch for st in states]),
                         converged=np.concatenate([st.converged for st in states]),
                         message="; ".join(st.message for st in states if st.message))

    def _pair_grid(self, g: np.ndarray, r: int):
        """The source on the grid g x g for pair r, one monotone ramp per row, each from a fresh
        source: (0, 0) -> (a, 0) -> (a, b) with b rising. Fresh because the section rung's answers
        were seen to depend on the path after it had visited high pressures or failed (up to ~10%
        in R_C on one serpentine path through the grid), so no row inherits another's."""
        n = len(g)
        z = np.full((n, n, 3), np.nan)
        conv = np.zeros((n, n), dtype=bool)
        messages = []
        with self._stage(f"pair {r}-{(r + 1) % 3} grid", n * n) as bar:
            for i, a in enumerate(g):
                row = np.zeros((n, 3))
                row[:, r], row[:, (r + 1) % 3] = a, g
                st = self._source(progress=False).evaluate(row)
                conv[i] = st.converged
                z[i] = np.column_stack([st.curvature, st.axial_stretch])
                if st.message:
                    messages.append(st.message.split("; ")[0])
                bar.update(n)
        return z, conv, messages

    def _resample(self, g: np.ndarray, z: np.ndarray, conv: np.ndarray) -> np.ndarray:
        """Cubic spline through the grid, sampled on the fine grid. Failed grid points are filled
        from the nearest converged one only so the spline can be built (their cells are refused)."""
        from scipy.interpolate import RectBivariateSpline

        z = z.copy()
        if not conv.all():
            good = np.argwhere(conv)
            for i, j in np.argwhere(~conv):
                gi, gj = good[np.argmin(np.abs(good - (i, j)).sum(1))]
                z[i, j] = z[gi, gj]
        fine = np.linspace(g[0], g[-1], self.settings.fine_points)
        return np.stack([RectBivariateSpline(g, g, z[..., c], kx=3, ky=3, s=0)(fine, fine) for c in range(3)], -1)

    @staticmethod
    def _errors(mine: BendState, ref: BendState, good: np.ndarray, pressures: np.ndarray) -> dict:
        use = good & mine.converged
        if not use.any():
            return {"points": 0}
        rc = _rc_error(mine.curvature[use], ref.curvature[use])
        worst = int(np.argmax(rc))
        return {"points": int(use.sum()), "rc_rel_max": float(rc.max()), "rc_rel_median": float(np.median(rc)),
                "direction_deg_max": float(_direction_error_deg(mine.curvature[use], ref.curvature[use]).max()),
                "stretch_abs_max": float(np.abs(mine.axial_stretch[use] - ref.axial_stretch[use]).max()),
                "worst_at_bar": (pressures[use][worst] / PA_PER_BAR).round(4).tolist(),
                "source_not_converged": int((~good).sum())}

    # ------------------------------------------------------------------ storage
    def _save(self) -> None:
        self.store.save_arrays(_KIND, self.solver_version, self._cache_parts(),
                               {"meta": np.array(json.dumps(self.meta)), **self.table}, self._cache_name())

    def _load(self):
        table = self.store.load_arrays(_KIND, self.solver_version, self._cache_parts(), self._cache_name(),
                                       require=("meta",))
        if table is None:
            return None
        meta = json.loads(str(table.pop("meta")))
        return (table, meta) if meta.get("key") == self.key else None

    # ------------------------------------------------------------------ evaluation
    def _prepare(self) -> None:
        t = self.table
        self._pmax = float(self.meta["max_pressure"])
        if self.kind == "one_channel":
            from scipy.interpolate import CubicSpline

            self._spline = CubicSpline(t["p"], t["y"], axis=0)
            # plain-float copies for the single-command path
            self._breaks = t["p"].tolist()
            self._coeffs = self._spline.c  # (4, m, 3)
        else:
            fine = t["fine"]
            self._nf = len(fine) - 1
            self._hf = float(fine[1] - fine[0])
            self._flat = np.ascontiguousarray(t["table"].reshape(-1, 3))
            self._rotated = t["table"].shape[0] == 1
            g = t["grid"]
            self._hg = float(g[1] - g[0])
            self._ng = len(g) - 1
            self._cell_ok = t["cell_ok"]
            self._all_ok = bool(self._cell_ok.all())
            self._cp, self._cs = t["common_p"], t["common_stretch"]
            self._max_common = float(self.meta["max_common_pressure"])
            cm_err = (self.meta.get("error_bound") or {}).get("common_mode", {}).get("rc_rel_max")
            self._common_refused = cm_err is not None and not cm_err <= self.settings.common_tolerance
            if self._common_refused:
                self._max_common = 0.0

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
            y = self._spline(np.clip(pressures[:, 0], 0.0, self._pmax))
            k, lam = y[:, :2], y[:, 2]
            ok = inside
            reason = "is outside the table's pressure range"
        else:
            k, lam, ok = self._three(pressures, inside)
            reason = "is outside the table's range (negative, above the range, or where the source failed)"
            first = np.flatnonzero(~ok)
            if first.size and inside[first[0]] and pressures[first[0]].min() > 0.0 and self._common_refused:
                err = self.meta["error_bound"]["common_mode"]["rc_rel_max"]
                reason = (f"has all three pressures > 0: treating the common part as pure stretch was measured "
                          f"{err:.1%} off the source in R_C (tolerance {self.settings.common_tolerance:.1%}), "
                          "so the surrogate does not answer it")
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
            ia = np.minimum((a / self._hg).astype(np.intp), self._ng - 1)
            ib = np.minimum((b / self._hg).astype(np.intp), self._ng - 1)
            ok &= self._cell_ok[pair, ia, ib]
        return k, lam, ok

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
