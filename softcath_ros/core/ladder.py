"""The model ladder measured: every rung on the same cases against a reference rung, and the
envelope that model selection (``model: auto``) reads.

Cases (``CASES``), 0.05..0.5 bar in steps of 0.05 bar (the design limit, max_pressure):
- family ``length``: the 1-channel design (implemented_5mm) at 40 mm, 20 mm and 17 mm (the
  blocking-force sample).
- family ``direction``: the 3-channel design (three_channel_5mm, 40 mm) bent by one channel
  (on a channel), by two channels at equal pressure (between two) and by a pair at 2:1 (off
  every mirror plane); the pressure is the largest channel's. fe3d runs on the half body about
  the direction's mirror plane for the first two (option ``half``: ``fe3d_options``), on the full
  body for the third; being slow there (minutes per case), it runs on these cases only when asked
  for (``fe3d_three_channel``); a case it was run on before (in the cache, same solver version and
  options) uses that result.
- family ``direction`` on the fan design (three_sector_5mm, the 2-DOF default): one channel and an
  equal pair at 40 mm (its length; reference: the section rung) and at 20 mm, where fe3d is the
  committed sweep the case names (``Case.fe3d_sweep``, read by ``committed_fe3d``, never solved:
  fe3d on this design takes minutes per point; it reached 0.125 bar on one channel, 0.05 bar on the pair).

The reference is chosen per point (the row's ``reference``): fe3d at its default mesh (mesh_size
1.0, threads=1) where it converged at that pressure, else the section rung with lumen contact at
its default mesh (D/20, ``SECTION_REFERENCE``), else none (no errors at that point).

Settings (``SETTINGS``): closed_form, surrogate (its table of section D/20), section at D/12,
D/20 and D/40, rod and fe3d. Per case and pressure each records R_C = l / theta, its relative
error against the point's reference, the tip position error (mm) and the bending-direction error
(degrees); per case its time per evaluation (single commands for the table rungs; a cold sweep
divided by its commands for the solvers) and its failure boundaries: where it stops (the last
pressure reached on a ramp along the case's direction up to the design's max_pressure, fe3d: the
case's own ramp, and the stop's named reason) and, per tolerance in ``TOLERANCES``, the last
measured pressure up to which its R_C error stays within it.
Results are cached per rung and case (the cache store, core/cache.py, kind ``ladder``, keyed by
the design's content hash, rung, its declared solver version, options and pressures), so
re-running only redraws, and a rung whose solver version changes (fe3d with contact) is the only
one measured again.
"""
from __future__ import annotations

import json
import math
import os
import statistics
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import cache
from .continuation import STOP_REASONS, tagged_stop
from .design import Design, load_design
from .errors import ModelError
from .models import RUNGS, make_model, rung_class, rung_info
from .prediction import KINEMATICS_VERSION, predict
from .units import PA_PER_BAR


@dataclass(frozen=True)
class Case:
    name: str
    family: str               # "length" (1 channel, lengths) or "direction" (3 channels, directions)
    design: str
    length: float             # m
    direction: tuple          # channel pressures per unit of the largest (the case's ray)
    magnitudes_pa: tuple      # the largest channel pressure at each point
    # a committed fe3d sweep standing as the case's fe3d (committed_fe3d): (its name in
    # benchmarks/results, the content hash of the design at the case's length it ran on)
    fe3d_sweep: tuple = ()

    @property
    def pressures(self) -> np.ndarray:
        return np.outer(self.magnitudes_pa, self.direction)

    @cached_property
    def sample(self) -> Design:
        """The case's design at its length, loaded once per case (its key, its rungs, its contact ramp)."""
        return load_design(self.design).with_length(self.length)


PRESSURES_PA = tuple(5000.0 * i for i in range(1, 11))   # 0.05 .. 0.5 bar
CASES = [
    Case("1ch 40mm", "length", "implemented_5mm", 0.040, (1.0,), PRESSURES_PA),
    Case("1ch 20mm", "length", "implemented_5mm", 0.020, (1.0,), PRESSURES_PA),
    Case("1ch 17mm", "length", "implemented_5mm", 0.017, (1.0,), PRESSURES_PA),
    Case("3ch one channel", "direction", "three_channel_5mm", 0.040, (1.0, 0.0, 0.0), PRESSURES_PA),
    Case("3ch pair equal", "direction", "three_channel_5mm", 0.040, (1.0, 1.0, 0.0), PRESSURES_PA),
    Case("3ch pair 2:1", "direction", "three_channel_5mm", 0.040, (1.0, 0.5, 0.0), PRESSURES_PA),
    Case("sector one channel", "direction", "three_sector_5mm", 0.040, (1.0, 0.0, 0.0), PRESSURES_PA),
    Case("sector pair equal", "direction", "three_sector_5mm", 0.040, (0.0, 1.0, 1.0), PRESSURES_PA),
    Case("sector one channel 20mm", "direction", "three_sector_5mm", 0.020, (1.0, 0.0, 0.0), PRESSURES_PA,
         ("fe3d_sector_ch0_20mm", "6abc807f699478e3")),
    Case("sector pair equal 20mm", "direction", "three_sector_5mm", 0.020, (0.0, 1.0, 1.0), PRESSURES_PA,
         ("fe3d_sector_pair_20mm", "6abc807f699478e3")),
]
FE3D = ("fe3d mesh 1.4, 1.2 mm layers", "fe3d", {"threads": 1}, True)   # the rung's default mesh and element
# (label, rung, options, is a solver: timed as a cold sweep)
SETTINGS = [
    ("closed_form", "closed_form", {}, False),
    ("surrogate (of section D/20)", "surrogate", {}, False),
    ("section D/12", "section", {"mesh_size": 0.005 / 12}, True),
    ("section D/20", "section", {}, True),
    ("section D/40", "section", {"mesh_size": 0.005 / 40}, True),
    ("rod", "rod", {}, True),
    FE3D,
]
# the setting of each rung a scene runs (its default), recorded in the envelope
DEFAULT_SETTING = {"closed_form": "closed_form", "surrogate": "surrogate (of section D/20)",
                   "section": "section D/20", "rod": "rod", "fe3d": FE3D[0]}
SECTION_REFERENCE = "section D/20"   # the section rung with lumen contact at its default mesh
# R_C error tolerances at which the accuracy boundary is recorded (accurate_to_pa_<n>pct)
TOLERANCES = (0.02, 0.05, 0.10)
LADDER_VERSION = "ladder-3"   # bump when what a cached row records changes (3: R_C = l / theta, 0-0.5 bar)
# The format of a cached rung result, kept in the value (a change of the key voids every cached result,
# hours of fe3d): 2 adds contact_boundary_pa; 3: the boundary of a rung other than fe3d is where its
# answers end (predict refuses a body through itself or its shaft); a result without "record" is format 1.
RECORD = 3


def run_rung(case: Case, rung: str, options: dict, solver: bool, refresh: bool = False) -> dict:
    """Predictions at the case's pressures, time per evaluation and failure boundary (cached)."""
    design = case.sample
    pressures = case.pressures
    key_parts = _key_parts(case, rung, options)
    hit = None if refresh else cache.load_json("ladder", LADDER_VERSION, key_parts, rung)
    if hit is not None:
        return _current_record(hit, case, rung, options, key_parts)
    opts = _solver_options(rung, options)
    load0 = os.getloadavg()[0]
    model = make_model(rung, design, **opts)
    t0 = time.perf_counter()
    preds = predict(model, pressures)
    sweep = time.perf_counter() - t0
    if rung == "fe3d":
        # minutes per sweep: its own cache is kept, and the cost is the ramp's wall time to its last
        # converged point over the points it reached (not evaluated again: a failed point would ramp again)
        reached = [pt for ramp in model.last_ramps for pt in ramp.points if pt.load > 0]
        per_eval = (sum(max(pt.wall_time for pt in ramp.points) for ramp in model.last_ramps if ramp.points)
                    / len(reached)) if reached else sweep / len(pressures)
    elif solver:
        per_eval = sweep / len(pressures)
    else:
        one = pressures[len(pressures) // 2]
        times = []
        for _ in range(7):
            t = time.perf_counter()
            for _ in range(2000):
                model.evaluate(one)
            times.append((time.perf_counter() - t) / 2000)
        per_eval = statistics.median(times)
    # failure boundary: a ramp along the case's direction to max_pressure (fe3d: the case ramp only)
    if rung == "fe3d":
        ok = [p.converged for p in preds]
        n_ok = ok.index(False) if not all(ok) else len(ok)
        boundary = float(case.magnitudes_pa[n_ok - 1]) if n_ok else 0.0
        beyond = not all(ok)
        first_failure = next((p.reason for p in preds if not p.converged), "")
        stop = stop_reason(first_failure)
    else:
        boundary, beyond, first_failure, stop = _answer_boundary(make_model(rung, design, **opts), case)
    out = {"record": RECORD, "rung": rung, "options": options, "s_per_eval": per_eval, "boundary_pa": boundary,
           "stop_reason": stop,
           "capabilities": list(model.info.models),   # what the rung declares it models (scene features)
           "fails_beyond": beyond, "first_failure": first_failure[:300], "loadavg_1min": [load0, os.getloadavg()[0]],
           "predictions": [p.to_json() for p in preds], "contact_boundary_pa": contact_boundary(case, rung, options)}
    cache.save_json("ladder", LADDER_VERSION, key_parts, out, rung)
    return out


SWEEP_INTERRUPTED = "sweep interrupted"   # a committed fe3d sweep's stop: measured no further, not a failure


def committed_fe3d(case: Case) -> dict | None:
    """fe3d's result on a case read from the committed sweep it names (``Case.fe3d_sweep``: written by
    benchmarks/fe3d_sweep.py into benchmarks/results, so None outside a source checkout), in
    ``run_rung``'s format. The sweep must be the case: the design it names at the case's length with
    the content hash pinned in the case (a design changed since is refused), the case's channels at
    equal pressure, the half body at the rung's default mesh (``FE3D``). A case point the sweep did not
    reach (or that did not converge) is not converged, its message the sweep's; no tip (the sweep does
    not record it)."""
    from ..resources import checkout_root
    from .models.fe3d import DEFAULT_LAYER_H, DEFAULT_MESH_SIZE

    name, design_hash = case.fe3d_sweep
    root = checkout_root()
    if root is None:
        return None
    path = root / "benchmarks" / "results" / f"{name}.json"
    if not path.is_file():
        raise ModelError(f"case {case.name}: committed fe3d sweep {path} is missing")
    doc = json.loads(path.read_text())
    meta, rows = doc["meta"], doc["results"]
    channels = meta["channel"] if isinstance(meta["channel"], list) else [meta["channel"]]
    want = [i for i, v in enumerate(case.direction) if v]
    if case.sample.content_hash() != design_hash:
        raise ModelError(f"case {case.name}: design {case.design} changed since fe3d sweep {name} (content hash "
                         f"{case.sample.content_hash()}, the sweep's {design_hash}): run fe3d on it again")
    if (meta["design"] != case.design or abs(meta["length_m"] - case.length) > 1e-12 or sorted(channels) != want
            or any(case.direction[i] != 1.0 for i in want) or not meta["half_model"]
            or meta["mesh_size"] != DEFAULT_MESH_SIZE or meta["layer_h"] != DEFAULT_LAYER_H):
        raise ModelError(f"case {case.name}: fe3d sweep {name} is not this case (design {meta['design']}, "
                         f"{meta['length_m'] * 1e3:g} mm, channels {channels}, mesh {meta['mesh_size']}, "
                         f"layers {meta['layer_h']} m, half {meta['half_model']})")
    at = {round(r["pressure_bar"] * PA_PER_BAR, 3): r for r in rows}
    preds, reached_s = [], 0.0
    for mag, pressures in zip(case.magnitudes_pa, case.pressures):
        r = at.get(round(float(mag), 3))
        pred = {"pressures_pa": pressures.tolist(), "converged": bool(r and r["converged"])}
        if pred["converged"]:
            k, ky = r["curvature_per_m"], r["curvature_y_per_m"]
            if abs(abs(ky) - k) > 1e-9 * max(k, 1.0):   # the half body about x = 0 bends in the y-z plane
                raise ModelError(f"case {case.name}: fe3d sweep {name} bends off the y-z plane at "
                                 f"{r['pressure_bar']} bar")
            pred.update(curvature_per_m=[0.0, ky], radius_of_curvature_m=r["radius_l_over_theta_mm"] * 1e-3,
                        centreline_radius_m=1.0 / k, tip_position_m=None)
            reached_s = r["time_s"]
        else:
            pred.update(reason=meta["message"], curvature_per_m=None, radius_of_curvature_m=None,
                        centreline_radius_m=None, tip_position_m=None)
        preds.append(pred)
    ok = [p["converged"] for p in preds]
    n_ok = ok.index(False) if not all(ok) else len(ok)
    return {"record": RECORD, "rung": "fe3d", "options": {**FE3D[2], "half": True},
            # its cost as run_rung's fe3d: the wall time to its last case point reached over those points
            "s_per_eval": reached_s / n_ok if n_ok else float(meta["total_s"]),
            "boundary_pa": float(case.magnitudes_pa[n_ok - 1]) if n_ok else 0.0,
            "stop_reason": "" if all(ok) else stop_reason(meta["stop_reason"]) or SWEEP_INTERRUPTED,
            "capabilities": list(rung_info("fe3d").models), "fails_beyond": not all(ok),
            "first_failure": "" if all(ok) else f"{name}: {meta['message']}"[:300],
            "loadavg_1min": [meta["load_average_before"][0], meta["load_average_after"][0]],
            "predictions": preds, "contact_boundary_pa": None,
            "source": {"sweep": name, "git_commit": meta["git_commit"], "date": meta["date"]}}


def _solver_options(rung: str, options: dict) -> dict:
    """The options a rung is measured with: the section rung cold (its time is the solver's)."""
    return {**options, "cache": False} if rung == "section" else dict(options)


def _answer_boundary(model, case: Case) -> tuple[float, bool, str, str]:
    """The free-bending failure boundary of a rung other than fe3d: where its answers end on a ramp to
    max_pressure (``ramp_boundary`` through ``predict``), whether it fails beyond, the first failure and
    its named stop."""
    boundary, beyond, message = ramp_boundary(model, case.direction, answers=True)
    return boundary, beyond, (message.split("; ")[0] if beyond else ""), (stop_reason(message) if beyond else "")


def _current_record(hit: dict, case: Case, rung: str, options: dict, key_parts: list) -> dict:
    """A cached result in the current format (``RECORD``), upgraded and saved again under the same key
    once: format 1 (before the range with the tip on the scale was recorded) gains
    ``contact_boundary_pa``; before format 3 a rung other than fe3d had its boundary from the rung's own
    solves, now from its answers (fe3d's always were: its ramp checks the body). A current one is
    returned as it was cached (one written with the field before the format was recorded counts as 2)."""
    record = hit.get("record", 2 if "contact_boundary_pa" in hit else 1)
    if record >= RECORD:
        return hit
    hit = {**hit, "record": RECORD}
    if record < 2:
        hit["contact_boundary_pa"] = contact_boundary(case, rung, options)
    if rung != "fe3d":
        boundary, beyond, first, stop = _answer_boundary(make_model(rung, case.sample,
                                                                    **_solver_options(rung, options)), case)
        hit.update(boundary_pa=boundary, fails_beyond=beyond, first_failure=first[:300], stop_reason=stop)
    cache.save_json("ladder", LADDER_VERSION, key_parts, hit, rung)
    return hit


def _key_parts(case: Case, rung: str, options: dict) -> list:
    version = rung_class(rung).solver_version
    if rung == "surrogate":     # its answers are its source rung's: a new source version is a new table
        version += "/" + rung_class(options.get("source", "section")).solver_version
    if not rung_class(rung).info.arc_spans_cap:   # its R_C and tip come through the arc and the straight cap
        version += "/" + KINEMATICS_VERSION
    return [case.sample.content_hash(), rung, version, options, case.pressures.tolist()]


def is_cached(case: Case, rung: str, options: dict) -> bool:
    """Whether the rung's result on the case is in the cache (measured before, same solver version)."""
    return cache.load_json("ladder", LADDER_VERSION, _key_parts(case, rung, options), rung) is not None


def contact_boundary(case: Case, rung: str, options: dict):
    """For a rung that models contact, on a 1-channel case: the last pressure reached on a ramp to
    max_pressure with the tip on the blocking-force bench's scale (the loads of the shipped scene
    blocking_force_bench at the case's length), which is where a contact scene's range ends; else None."""
    if "contact" not in rung_info(rung).models or case.family != "length":
        return None
    from .scene import load_scene

    model = make_model(rung, case.sample, loads=load_scene("blocking_force_bench").loads, **options)
    return ramp_boundary(model, case.direction)[0]


def ramp_boundary(model, direction, answers: bool = False) -> tuple[float, bool, str]:
    """A ramp of 41 commands along ``direction`` from 0 to the design's max_pressure: the last pressure
    reached, whether it failed beyond it, and the rung's message. ``answers``: reached means answered
    by ``predict``, which also refuses a free body bent through itself or its shaft."""
    mags = np.linspace(0.0, model.design.max_pressure, 41)
    if answers:
        preds = predict(model, np.outer(mags, direction))
        ok = np.array([p.converged for p in preds])
        message = next((p.reason for p in preds if not p.converged), "")
    else:
        st = model.evaluate(np.outer(mags, direction))
        ok, message = st.converged, st.message
    n_ok = int(np.argmin(ok)) if not ok.all() else len(mags)
    return float(mags[max(n_ok - 1, 0)]), n_ok < len(mags), message


def stop_reason(message: str) -> str:
    """The named reason (core/continuation.py) a failure message gives; "unnamed" if it names none."""
    if not message:
        return ""
    # untagged: a message written before the tag (a cached result), naming the reason in its text
    return tagged_stop(message) or next((name for name in STOP_REASONS if name in message), "unnamed")


def reference_labels(results: dict) -> list:
    """Per point of a case the setting used as its reference: fe3d where it converged there, else
    the section rung's default (with lumen contact) where it converged, else None. A point beyond the
    setting's failure boundary (a ramp to max_pressure stopped before it: the point may sit on another
    branch) is no reference."""
    n = len(next(iter(results.values()))["predictions"])
    labels = []
    for i in range(n):
        label = next((lab for lab in (FE3D[0], SECTION_REFERENCE) if lab in results
                      and results[lab]["predictions"][i]["converged"]
                      and max(results[lab]["predictions"][i]["pressures_pa"]) <= results[lab]["boundary_pa"]),
                     None)
        labels.append(label)
    return labels


def accurate_to(errs: list, pressures: list, tolerance: float) -> float:
    """The last of ``pressures`` (ascending) up to which every error is known and <= ``tolerance``
    (0.0 if the first is not)."""
    reached = 0.0
    for p, e in zip(pressures, errs):
        if e is None or e > tolerance:
            break
        reached = p
    return reached


def tolerance_key(tolerance: float) -> str:
    return f"accurate_to_pa_{tolerance * 100:g}pct"


def errors(p: dict, r: dict) -> dict:
    """R_C relative error, tip position error (mm), bending-direction error (degrees) of p against r."""
    if not (p["converged"] and r["converged"]):
        return {"rc_rel_error": None, "tip_error_mm": None, "direction_error_deg": None}
    kp, kr = p["curvature_per_m"], r["curvature_per_m"]
    d = math.atan2(kp[1], kp[0]) - math.atan2(kr[1], kr[0])
    tips = (p["tip_position_m"], r["tip_position_m"])   # None: not recorded (a committed fe3d sweep's)
    return {"rc_rel_error": abs(p["radius_of_curvature_m"] / r["radius_of_curvature_m"] - 1.0),
            "tip_error_mm": None if None in tips else 1e3 * float(np.linalg.norm(np.subtract(*tips))),
            "direction_error_deg": abs(math.degrees((d + math.pi) % (2 * math.pi) - math.pi))}


def fe3d_options(case: Case, options: dict) -> dict:
    """fe3d's options for a case: with ``half`` True where the case's direction lies on a mirror
    plane of a design that is not symmetric about x = 0 as a whole (the 3-channel design bent by one
    channel or by an equal pair: the half body about that plane); the others as given (so their
    cached rows keep their key)."""
    from .fe3d.symmetry import can_use_half_model, mirror_plane

    design = case.sample
    if can_use_half_model(design) or mirror_plane(design, case.direction) is None:
        return options
    return {**options, "half": True}


def run_case(case: Case, settings=SETTINGS, fe3d: bool = True, fe3d_three_channel: bool = False,
             refresh: tuple = (), say=print) -> tuple[list[dict], str]:
    """Rows (one per setting and pressure) for one case, and its reference label. ``refresh``:
    rungs whose cached results are recomputed ("all": every rung)."""
    results = {}
    for label, rung, options, solver in settings:
        if rung not in RUNGS:
            say(f"  {label}: rung '{rung}' is not registered in core/models RUNGS: skipped")
            continue
        if rung == "fe3d" and case.fe3d_sweep:   # read from the committed sweep, never solved here
            try:
                committed = committed_fe3d(case) if fe3d else None
            except ModelError as exc:
                say(f"  {label}: not available ({exc})")
                continue
            if committed is not None:
                results[label] = committed
                say(f"  {label:28s} from the committed sweep {case.fe3d_sweep[0]}")
            continue
        if rung == "fe3d":
            options = fe3d_options(case, options)
        # fe3d on the 3-channel cases (minutes each) when asked for, or when measured before (cached)
        if rung == "fe3d" and (not fe3d or (case.family == "direction" and not fe3d_three_channel
                                            and not is_cached(case, rung, options))):
            continue
        t0, load0 = time.perf_counter(), os.getloadavg()[0]
        try:
            results[label] = run_rung(case, rung, options, solver, rung in refresh or "all" in refresh)
        except ModelError as exc:
            say(f"  {label}: not available ({exc})")
            continue
        say(f"  {label:28s} {time.perf_counter() - t0:8.1f} s wall (load {load0:.1f} -> {os.getloadavg()[0]:.1f})",
              flush=True)
        if results[label].get("first_failure"):
            say(f"    boundary {results[label]['boundary_pa'] / PA_PER_BAR:.4f} bar: {results[label]['first_failure']}")
    if not results:
        raise ModelError(f"case {case.name}: no rung answered")
    refs = reference_labels(results)
    if not any(refs):
        raise ModelError(f"case {case.name}: no reference ({FE3D[0]} or {SECTION_REFERENCE}) converged at any "
                         "pressure (was it run?)")
    rows = []
    for label, res in results.items():
        errs = [errors(p, results[ref]["predictions"][i]) if ref else errors(p, {"converged": False})
                for i, (p, ref) in enumerate(zip(res["predictions"], refs))]
        mags = [max(p["pressures_pa"]) for p in res["predictions"]]
        # a point where the setting is its own reference measures nothing (but fe3d's, the top rung's)
        measured = [None if ref == label and label != FE3D[0] else e["rc_rel_error"] for e, ref in zip(errs, refs)]
        bounds = {tolerance_key(tol): accurate_to(measured, mags, tol) for tol in TOLERANCES}
        for p, ref, err in zip(res["predictions"], refs, errs):
            rows.append({"case": case.name, "family": case.family, "design": case.design, "length_m": case.length,
                         "direction": " ".join(f"{v:g}" for v in case.direction),
                         "setting": label, "rung": res["rung"], "pressure_pa": max(p["pressures_pa"]),
                         "pressures_pa": " ".join(f"{v:g}" for v in p["pressures_pa"]),
                         "s_per_eval": res["s_per_eval"], "load_1min": (res.get("loadavg_1min") or [None])[0],
                         "converged": p["converged"], "reference": ref or "",
                         "boundary_pa": res["boundary_pa"], "fails_beyond": res["fails_beyond"],
                         "stop_reason": res["stop_reason"], "stop_message": res["first_failure"][:200],
                         "contact_boundary_pa": res.get("contact_boundary_pa"),
                         **bounds,
                         "rc_m": p["radius_of_curvature_m"], "centreline_radius_m": p["centreline_radius_m"], **err})
    ref_label = " / ".join(dict.fromkeys(r for r in refs if r))
    return rows, ref_label
