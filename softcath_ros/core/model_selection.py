"""`model: auto`: the cheapest rung that models everything in a scene, is valid over its pressure
range, and meets its accuracy and rate, judged from the measured envelope (the shipped
ladder_envelope.yaml, written by `softcath envelope`). It says what it picked and why, or why nothing qualifies.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .errors import ModelError
from .models import make_model
from .scene import Scene
from .yaml_io import load_yaml_file



@dataclass
class Selection:
    rung: str
    reason: str                 # why this rung (one line)
    rejected: dict[str, str]    # rung -> why not


def load_envelope(path: str | Path | None = None) -> dict:
    """The measured envelope: {"reference": ..., "rungs": {name: {capabilities, designs: {design: {...}}}}}."""
    from ..resources import envelope_path

    p = Path(path) if path is not None else envelope_path()
    if not p.is_file():
        raise ModelError(f"no ladder envelope at {p}: measure the rungs with `softcath envelope --out FILE`")
    data = load_yaml_file(p)
    if not isinstance(data, dict) or not isinstance(data.get("rungs"), dict):
        raise ModelError(f"ladder envelope {p}: expected a mapping with 'rungs'")
    return data


def select_model(scene: Scene, envelope: dict | None = None) -> Selection:
    """The cheapest qualifying rung for ``scene``; ModelError listing every rung's reason if none."""
    env = envelope if envelope is not None else load_envelope()
    design = scene.design.name
    lo, hi = scene.pressure_range
    period = 1.0 / scene.required_rate
    candidates, rejected = [], {}
    for name, rung in env["rungs"].items():
        caps = set(rung.get("capabilities", []))
        missing = [f for f in scene.features if f not in caps]
        if missing:
            rejected[name] = f"does not model {', '.join(missing)}"
            continue
        measured = measured_envelope(rung, scene)
        if measured is None:
            rejected[name] = f"no measured envelope for design '{design}'"
            continue
        # a scene with contact: the range the rung was measured to hold with the tip on a plane
        blocked = "contact" in scene.features and "valid_pressure_pa_with_contact" in measured
        v_lo, v_hi = measured["valid_pressure_pa_with_contact" if blocked else "valid_pressure_pa"]
        if lo < v_lo or hi > v_hi:
            rejected[name] = (f"valid over {v_lo:g}..{v_hi:g} Pa only{' with contact' if blocked else ''}, "
                              f"the scene needs {lo:g}..{hi:g} Pa")
            continue
        err = error_over(measured, hi)
        if err is None or err > scene.required_accuracy:
            rejected[name] = (f"measured R_C error {_pct(err)} exceeds the required {_pct(scene.required_accuracy)}")
            continue
        cost = measured["cost_s_per_eval"]
        if cost > period:
            rejected[name] = (f"{cost * 1e3:.3g} ms per evaluation cannot keep up with "
                              f"{scene.required_rate:g} Hz ({period * 1e3:.3g} ms)")
            continue
        candidates.append((cost, name, err, measured))
    if not candidates:
        why = "; ".join(f"{n}: {r}" for n, r in rejected.items())
        raise ModelError(f"model auto: no rung qualifies for scene '{scene.name}' "
                         f"(needs {', '.join(scene.features)}, {lo:g}..{hi:g} Pa, R_C error <= "
                         f"{_pct(scene.required_accuracy)}, {scene.required_rate:g} Hz): {why}")
    cost, name, err, measured = min(candidates, key=lambda c: (c[0], c[1]))
    ref = measured.get("reference") or env.get("reference", "the reference")
    reason = (f"model auto picked '{name}' for scene '{scene.name}': the cheapest rung ({cost * 1e6:.3g} us per "
              f"evaluation) that models {', '.join(scene.features)}, is valid over {lo:g}..{hi:g} Pa and whose "
              f"measured R_C error {_pct(err)} (against {'/'.join(ref) if isinstance(ref, list) else ref}; "
              f"{measured['_scope']}) meets {_pct(scene.required_accuracy)} at {scene.required_rate:g} Hz")
    return Selection(rung=name, reason=reason, rejected=rejected)


def require_live_rung(name: str, design_name: str, envelope: dict | None = None) -> None:
    """ModelError unless rung ``name`` may answer a node's commands live: a rung that declares itself
    offline only (``RungInfo.live``) is refused at once, with the seconds per command the measured
    envelope gives for ``design_name`` where it has them (a node would otherwise wait that long at
    start, then answer nothing meanwhile). Names that are no rung (auto) pass."""
    from .models import RUNGS, rung_info

    if name not in RUNGS or rung_info(name).live:
        return
    try:
        measured = (envelope or load_envelope())["rungs"][name]["designs"][design_name]
        cost = f"about {float(measured['cost_s_per_eval']):.0f} s for design {design_name} (the measured envelope)"
    except (ModelError, KeyError, TypeError, ValueError):
        cost = "a minute or more"
    raise ModelError(f"model {name} is no live rung: one command takes {cost} and a node would answer nothing "
                     f"meanwhile; live, use model:=surrogate (the section rung's shipped table); {name} offline: "
                     f"`softcath predict --model {name}` or `softcath sweep --model {name}`")


def error_over(measured: dict, high: float):
    """The measured R_C error that applies to pressures up to ``high`` (Pa): the worst at the measured
    pressures up to it and, unless ``high`` is one of them, at the next one above (which brackets the
    range); the overall maximum
    when the envelope has no errors per pressure or a point in that set was not measured."""
    by_p = measured.get("error_rc_rel_by_pressure_pa")
    if not by_p:
        return measured["error_rc_rel_max"]
    points = sorted((float(p), e) for p, e in by_p)
    use = [pt for pt in points if pt[0] <= high]
    if not use or use[-1][0] < high:   # the scene goes past the last measured pressure below its top
        use += [pt for pt in points if pt[0] > high][:1]
    if any(e is None for _, e in use):
        return measured["error_rc_rel_max"]
    return max(e for _, e in use)


def measured_envelope(rung: dict, scene: Scene) -> dict | None:
    """A rung's measured envelope for the scene's design: the one measured at the scene's length
    (``by_length``, keyed by the length in m) when there is one, else the design's (the worst over
    its measured cases). Adds ``_scope`` saying which."""
    measured = (rung.get("designs") or {}).get(scene.design.name)
    if measured is None:
        return None
    length = scene.design.length
    for key, entry in (measured.get("by_length") or {}).items():
        if entry is not None and abs(float(key) - length) <= 1e-9:
            return {**entry, "_scope": f"measured at the scene's length {length * 1e3:g} mm"}
    lengths = sorted(float(k) for k in (measured.get("by_length") or {}))
    scope = (f"the worst over the measured lengths {', '.join(f'{v * 1e3:g}' for v in lengths)} mm "
             f"(not at {length * 1e3:g} mm)" if lengths else "the design's measured cases")
    return {**measured, "_scope": scope}


def _pct(x) -> str:
    return "unmeasured" if x is None else f"{x:.2%}"


def make_auto_model(design, scene: Scene | None = None, envelope: dict | None = None, **options):
    """``make_model("auto", design, scene=...)``: the selected rung for the scene's design (the scene's
    device included). The returned model carries the ``selection`` (what was picked and why)."""
    if scene is None:
        raise ModelError("model auto needs a scene (CLI: --scene FILE; model_node: parameter 'scene')")
    if scene.design.name != design.name:
        raise ModelError(f"model auto: scene '{scene.name}' is for design '{scene.design.name}', "
                         f"not '{design.name}'")
    selection = select_model(scene, envelope)
    if scene.loads.any:   # only a rung that models loads qualifies, and it needs to know them
        options = {**options, "loads": scene.loads}
    model = make_model(selection.rung, scene.design, **options)
    model.selection = selection
    return model


