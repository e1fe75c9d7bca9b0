"""The section rung's moment-curvature table, computed once per design and grid and cached.

The table depends on the cross-section only: the length and the device in the lumen (whose
stiffness the rod adds) are not part of the key.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..cache import cache_dir, key_of
from ..design import Design
from ..section_fe.moment import MomentTable
from .law import TabulatedLaw

LAW_VERSION = "section-moment-1"


@dataclass(frozen=True)
class LawGrid:
    """Where the table is computed: curvatures (1/m, per reference length) and pressures (Pa)."""

    kappa_min: float = -150.0
    kappa_max: float = 300.0
    kappa_step: float = 5.0
    pressure_max: float = 45000.0
    pressure_step: float = 2500.0

    def curvatures(self) -> np.ndarray:
        neg = -np.arange(0.0, -self.kappa_min + 1e-9, self.kappa_step)[1:][::-1]
        pos = np.arange(0.0, self.kappa_max + 1e-9, self.kappa_step)
        return np.concatenate([neg, pos])

    def pressures(self) -> np.ndarray:
        return np.arange(0.0, self.pressure_max + 1e-9, self.pressure_step)


def section_law(design: Design, grid: LawGrid = LawGrid(), cache: bool = True, progress: bool = False,
                **section_settings) -> TabulatedLaw:
    """``TabulatedLaw`` of the bare section (no device) of a one-channel ``design``.

    ``section_settings`` are ``SectionSettings`` fields, e.g. ``lumen_fill=0.02``: a body bent back
    against its pressure (a blocked tip) closes the empty lumen at 0.225-0.3 bar; the fill (a
    self-contact proxy) carries the table to 0.45 bar (README "Model rung: rod")."""
    from ..models.section import SectionModel

    body = replace(design, device=None, length=1.0)
    model = SectionModel(body, **section_settings)
    key = key_of(body.content_hash(), model.settings.key(), asdict(grid), LAW_VERSION, model.mesh.n_nodes)
    path = cache_dir("rod_law") / f"section_law_{key}.npz" if cache else None
    table = _load(path) if path is not None else None
    if table is None:
        table = model.moment_curvature(grid.pressures(), grid.curvatures(), progress=progress)
        if path is not None:
            _save(path, table)
    mesh = f"section D/{design.outer_diameter / model.mesh.h:.0f}"
    if model.settings.lumen_fill is not None:
        mesh += f", lumen fill {model.settings.lumen_fill:g}"
    return TabulatedLaw(table, source=f"rod law from {mesh}")


def _save(path, t: MomentTable) -> None:
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez(tmp, curvatures=t.curvatures, pressures=t.pressures, moment=t.moment, stretch=t.stretch,
             messages=np.array(json.dumps(t.messages)), direction=t.direction,
             pressure_direction=t.pressure_direction)
    os.replace(tmp, path)


def _load(path) -> MomentTable | None:
    if not path.is_file():
        return None
    try:
        z = np.load(path, allow_pickle=False)
        return MomentTable(curvatures=z["curvatures"], pressures=z["pressures"], moment=z["moment"],
                           stretch=z["stretch"], messages=json.loads(str(z["messages"])),
                           direction=z["direction"], pressure_direction=z["pressure_direction"])
    except (OSError, ValueError, KeyError):
        return None    # a damaged entry is recomputed
