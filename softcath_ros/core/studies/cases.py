"""One case of a study: a design at a batch of pressures through one rung, solved anywhere.

``CaseSpec`` is plain data (the design-file mapping, the rung's name and options, the
pressures) so that it pickles to a worker process or a cluster worker; ``solve_case`` is the
function the workers run. It never raises for a physics failure: a command the rung cannot
reach comes back with ``converged = False`` and the rung's message.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..cache import CacheStore
from ..design import design_from_dict

# Bump when what a case records changes (it is part of every case's cache key).
STUDY_CODE_VERSION = "studies-3"   # 2: radius_of_curvature_m is l / theta (was 1/|k|); 3: the tip cap straight


@dataclass(frozen=True)
class CaseSpec:
    design: dict                    # design-file mapping (Design.to_dict())
    rung: str                       # model rung name (core/models RUNGS)
    pressures: tuple                # ((p_0, .., p_C-1), ...) Pa, one row per command
    options: dict = field(default_factory=dict)   # rung options, e.g. {"mesh_size": 4e-4}

    def cache_parts(self) -> list:
        """What the case's answer depends on: design content, rung, its options and declared
        solver version, pressures (with ``STUDY_CODE_VERSION``: the case's cache entry)."""
        design = design_from_dict(self.design)
        return [design.content_hash(), self.rung, self.options, _rung_version(self.rung),
                [list(map(float, p)) for p in self.pressures]]

    def key(self) -> str:
        """Cache key (equal for equal cases)."""
        return CacheStore.key(STUDY_CODE_VERSION, self.cache_parts())


def _rung_version(rung: str) -> str | None:
    """The rung's declared ``solver_version`` (bumped when its answers change); None for an
    unknown rung or one whose optional dependency is missing (the case then reports that)."""
    from ..errors import ModelError
    from ..models import rung_class

    try:
        return rung_class(rung).solver_version
    except ModelError:
        return None


def solve_case(spec: CaseSpec) -> dict:
    """Evaluate one case: {"results": [per command], "solve_time_s": wall time of the solve}.

    Per command: curvature (1/m), R_C = l / theta = 1 / (|k| x stretch) (m; None if straight or not
    converged), the centreline's radius 1/|k| (``centreline_radius_m``), axial
    stretch, converged, message, and for the section rung the largest principal stretch in
    the silicone (``max_principal_stretch``), the strain measure the optimiser limits."""
    from ..models import make_model
    from ..prediction import angle_per_length

    design = design_from_dict(spec.design)
    pressures = np.asarray(spec.pressures, dtype=float)
    t0 = time.perf_counter()
    model = make_model(spec.rung, design, **spec.options)
    state = model.evaluate(pressures)
    elapsed = time.perf_counter() - t0
    messages = _split_messages(state.message, int(np.sum(~np.asarray(state.converged))))
    per_length = angle_per_length(state, model)   # theta / l
    results = []
    j = 0
    for i, p in enumerate(pressures):
        ok = bool(state.converged[i])
        k = state.curvature[i]
        kappa = float(np.hypot(*k)) if ok else float("nan")
        theta_per_length = float(per_length[i]) if ok else float("nan")
        row = {"pressures_pa": [float(v) for v in p], "converged": ok,
               "curvature_per_m": [float(v) for v in k] if ok else None,
               "radius_of_curvature_m": (1.0 / theta_per_length) if ok and kappa > 0 else None,
               "centreline_radius_m": (1.0 / kappa) if ok and kappa > 0 else None,
               "axial_stretch": float(state.axial_stretch[i]) if ok else None,
               "max_principal_stretch": max_principal_stretch(model, p) if ok else None,
               "message": ""}
        if not ok:
            row["message"] = messages[j] if j < len(messages) else (state.message or "did not converge")
            j += 1
        results.append(row)
    return {"results": results, "solve_time_s": elapsed}


def _split_messages(message: str, n_failed: int) -> list[str]:
    """The rung joins one message per failed command with '; ' (section.py); split them back
    when the count matches, else give every failed command the whole message."""
    parts = [m for m in message.split("; section model:")] if message else []
    if len(parts) == n_failed and n_failed > 1:
        return [parts[0]] + [f"section model:{m}" for m in parts[1:]]
    return [message] * n_failed


def max_principal_stretch(model, pressures) -> float | None:
    """Largest principal stretch in the silicone at a converged command, from rungs that resolve
    the section's strain field (``SectionModel.max_principal_stretch``); None for the others."""
    return model.max_principal_stretch(pressures)
