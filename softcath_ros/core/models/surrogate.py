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

Modules: ``surrogate_settings`` (the table's settings), ``surrogate_tabulate`` (building a table),
``surrogate_build`` (the source's rays in parallel), ``surrogate_store`` (where tables are kept);
this one is the rung: it finds or builds its table and reads commands out of it.
"""
from __future__ import annotations

import logging
from bisect import bisect_right
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..cache import CacheStore, store_for
from ..design import Design
from ..errors import ModelError
from ..options import Option
from ..units import PA_PER_BAR
from .base import BendModel, BendState, RungInfo, options_of
from .surrogate_settings import ROTATION_COS, ROTATION_SIN, SURROGATE_VERSION, SurrogateSettings, symmetric_three
from .surrogate_store import SurrogateTableStore

_log = logging.getLogger("softcath_ros.surrogate")


class SurrogateModel(SurrogateTableStore, BendModel):
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
            "answer_tolerance": "relative R_C miss at a middle ray that could not be refined above which "
                                "pair commands beside it are refused",
            "answer_direction_tolerance": "the same in direction (degrees)",
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
                   "(as pure stretch, off by more than common_tolerance there): a simulated rig's truth"),
            Option("answer_unresolved", "bool", "answer pair commands where the build measured the table off "
                   "beyond answer_tolerance and could not refine it too: a simulated rig's truth")))

    def __init__(self, design: Design, source: str = "section", source_options: dict | None = None,
                 cache: bool | str | Path = True, progress: bool = False, rebuild: bool = False,
                 table: str | Path = "", shipped: bool = True, workers: int | None = None, build: bool = True,
                 answer_common: bool = False, answer_unresolved: bool = False, **table_settings):
        """``source``: the rung to tabulate; ``source_options``: its options (mesh_size, ...).
        ``cache``: True (the project cache), a cache root directory, or False (build every time).
        ``table``: a table file to use (must be current). ``shipped``: use the package's table.
        ``workers``: build processes. ``progress``: tqdm bars while building. ``build``: False refuses
        (ModelError) instead of building a table it does not find current. ``answer_common``: answer
        commands with all three channels pressurised beyond the measured common-mode limit too (to
        the end of the equal-pressure table; not part of the table's key). ``answer_unresolved``: answer
        pair commands in the regions the build refuses (``meta['refused_regions']``) too.
        ``table_settings``: ``SurrogateSettings`` fields."""
        super().__init__(design)
        self.answer_common = bool(answer_common)
        self.answer_unresolved = bool(answer_unresolved)
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
        symmetric = symmetric_three(design)
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
        self.key = CacheStore.key(self.solver_version, self.cache_parts())
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
            from .surrogate_tabulate import build_table

            self.table, self.meta = build_table(self)
            self.origin = "built"
            if self.store is not None:
                self.table_path = self._save()
        else:
            self.table, self.meta = loaded
        self._prepare()


    @property
    def error_bound(self) -> dict:
        """Measured error against the source at held-out commands (see module docstring)."""
        return self.meta["error_bound"]

    @property
    def pressure_range(self) -> tuple[float, float]:
        """Pa: every channel pressure must lie in this range (and, for 3 channels, every pair
        command in a cell where the source converged)."""
        return 0.0, float(self.meta["max_pressure"])

    def refused_regions(self) -> list[str]:
        """The pair commands the table refuses because a held-out check found it off there after
        its build could refine no further, one phrase per region (``softcath surrogate check``)."""
        out = []
        for g in sorted(self.meta.get("refused_regions", []), key=lambda g: (g["pair"], g["t"][0], g["from_sum_bar"])):
            lo, hi = g["t"]
            where = (f"every pair (a, b), b / (a + b) in [{lo:.4g}, {hi:.4g}] or [{1 - hi:.4g}, {1 - lo:.4g}]"
                     if self.meta["rotated"] else f"channels {g['pair']}, {(g['pair'] + 1) % 3} (a, b), "
                     f"b / (a + b) in [{lo:.4g}, {hi:.4g}]")
            sums = (f"a + b from {g['from_sum_bar']:.3g} bar" if g["to_sum_bar"] is None
                    else f"a + b {g['from_sum_bar']:.3g}-{g['to_sum_bar']:.3g} bar")
            out.append(f"{where}, {sums} (held out there it missed by up to {g['rc_miss']:.1%} in R_C, "
                       f"{g['direction_miss_deg']:.2g} deg)")
        return out

    # ------------------------------------------------------------------ read-out
    def use_table(self, table: dict, meta: dict) -> None:
        """Answer from ``table`` (while building: the table so far, to measure its error)."""
        self.table, self.meta = table, meta
        self._prepare()

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
                tab, t["fine_ok"], t["fine_resolved"] = self._fine_tables()
                t["fine_table"] = tab.astype(np.float32)   # half the file; 6e-8 relative, far below the error
            tab, self._cell_reached = t["fine_table"].astype(np.float64), t["fine_ok"]
            self._cell_ok = self._cell_reached if self.answer_unresolved else self._cell_reached & t["fine_resolved"]
            self._nf = self.settings.fine_points - 1
            self._hf = self._pmax / self._nf
            self._flat = np.ascontiguousarray(tab.reshape(-1, 3))
            self._rotated = tab.shape[0] == 1
            self._all_ok = bool(self._cell_ok.all())
            self._cp, self._cs = t["common_p"], t["common_stretch"]
            self._max_common = float(self.meta.get("max_common_table_pressure", self.meta["max_common_pressure"])
                                     if self.answer_common else self.meta["max_common_pressure"])
            self._stretch0 = float(np.interp(0.0, self._cp, self._cs)) if len(self._cp) else 1.0
            self._rot = [(float(c), float(s)) for c, s in zip(ROTATION_COS, ROTATION_SIN)]

    def _fine_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rays resampled onto the fine (a, b) grid of each pair table (one when rotated), which
        of its cells lie where the source converged on both bracketing rays, and which lie outside
        the refused regions (``_unresolved``)."""
        from .surrogate_build import mirrored, pair_surface, reflection

        t = self.table
        fine = np.linspace(0.0, self._pmax, self.settings.fine_points)
        a, b = np.meshgrid(fine, fine, indexing="ij")
        m = a + b
        tq = np.divide(b, m, out=np.zeros_like(m), where=m > 0)
        tabs, oks, resolved = [], [], []
        for r in ((0,) if self.meta["rotated"] else (0, 1, 2)):
            sel = t["ray_pair"] == r
            rays = (t["ray_t"][sel], t["ray_values"][sel], t["ray_reach"][sel], t["ray_complete"][sel])
            if self.meta["rotated"]:
                rays = mirrored(*rays, reflection(self.design))
            ev, reachable = pair_surface(*rays, t["sums"])
            tabs.append(ev(tq.ravel(), m.ravel()).reshape(*m.shape, 3))
            node = reachable(tq, m)
            oks.append(node[:-1, :-1] & node[1:, :-1] & node[:-1, 1:] & node[1:, 1:])
            resolved.append(~self._unresolved(r, a, b))
        return np.stack(tabs), np.stack(oks), np.stack(resolved)

    def _unresolved(self, r: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Cells of pair table r's fine grid (nodes at channel pressures ``a``, ``b``) that touch a
        refused region: a corner or the middle at a ray t = b / (a + b) in its interval (or in the
        mirror image, when rotated) and a sum a + b in its band."""
        t = self.table
        out = np.zeros((a.shape[0] - 1, a.shape[1] - 1), dtype=bool)
        corners = [(slice(None, -1), slice(None, -1)), (slice(1, None), slice(None, -1)),
                   (slice(None, -1), slice(1, None)), (slice(1, None), slice(1, None))]
        ma, mb = (sum(g[c] for c in corners) / 4.0 for g in (a, b))
        points = [(a[c], b[c]) for c in corners] + [(ma, mb)]
        for pair, (lo, hi), (m0, m1) in zip(t.get("refused_pair", ()), t.get("refused_t", ()), t.get("refused_sums", ())):
            if pair != r:
                continue
            spans = [(lo, hi), (1.0 - hi, 1.0 - lo)] if self.meta["rotated"] else [(lo, hi)]
            for pa, pb in points:
                m = pa + pb
                tq = np.divide(pb, m, out=np.zeros_like(m), where=m > 0)
                for u, v in spans:
                    out |= (tq >= u - 1e-12) & (tq <= v + 1e-12) & (m >= m0) & (m <= m1)
        return out

    def _refusal(self, p: np.ndarray, why: str, where_source_failed: bool = True) -> str:
        """The refusal's line; ``where_source_failed``: add where the build's source stopped (the reason
        is the table's range, not a region the table holds but does not answer)."""
        msg = (f"surrogate: command p = {', '.join(f'{v / PA_PER_BAR:.4f}' for v in p)} bar {why} "
               f"(built from '{self.settings.source}' over 0..{self._pmax / PA_PER_BAR:.4f} bar")
        fail = self.meta.get("source_failure") if where_source_failed else None
        return msg + (f"; the source failed beyond: {fail})" if fail else ")")

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:
        n = pressures.shape[0]
        inside = (pressures >= 0.0).all(1) & (pressures <= self._pmax).all(1)
        out_of_range = True      # the refusal's reason is the table's range (else a region it does not answer)
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
                out_of_range = False
            elif first.size and inside[first[0]] and self._unresolved_cell(pressures[first[0]]):
                s = self.settings
                reason = (f"lies where the build measured the table off its source by more than {s.answer_tolerance:.1%} "
                          f"in R_C or {s.answer_direction_tolerance:g} degrees and could not refine it further "
                          "(softcath surrogate check lists the refused regions), so the surrogate does not answer it")
                out_of_range = False
        if not ok.all():
            k = np.where(ok[:, None], k, np.nan)
            lam = np.where(ok, lam, np.nan)
            bad = np.flatnonzero(~ok)
            msg = self._refusal(pressures[bad[0]], reason, out_of_range)
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

    def _unresolved_cell(self, p: np.ndarray) -> bool:
        """The command ``p`` (3,) lies in a cell the source reached but a refused region covers."""
        q = p - p.min()
        zero = int(q.argmin())
        r = (zero + 1) % 3
        a, b = (min(max(float(q[c]), 0.0), self._pmax) for c in (r, (zero + 2) % 3))
        ia, ib = (min(int(x / self._hf), self._nf - 1) for x in (a, b))
        cell = (0 if self._rotated else r, ia, ib)
        return bool(self._cell_reached[cell] and not self._cell_ok[cell])

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
            c, s = ROTATION_COS[r], ROTATION_SIN[r]
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
