"""The section's moment-curvature table (section_fe/moment.py), computed once per design and grid, cached.

The table depends on the cross-section only: the length and the device in the lumen (whose
stiffness the rod adds) are not part of the key.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..cache import store_for
from ..design import Design
from ..errors import ModelError
from ..section_fe.moment import MomentTable, moment_curvature
from ..section_fe.settings import SectionSettings, discretise
from .law import TabulatedLaw

# bump when the law changes (2: lumen contact; 3: stable held states only; 4: the held minimiser's 200
# iterations; 5: between grid pressures bent back each column is read at the fraction of its peak)
LAW_VERSION = "section-moment-5"


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


def section_law(design: Design, grid: LawGrid = LawGrid(), cache=True, progress: bool = False,
                **section_settings) -> TabulatedLaw:
    """``TabulatedLaw`` of the bare section (no device) of a one-channel ``design``.

    ``cache``: True (the project cache, core/cache.py), a cache root directory, or False.
    ``section_settings`` are ``SectionSettings`` fields, e.g. ``contact_distance`` (the lumen wall's
    self-contact, on by default) or ``lumen_fill=0.02`` (the former soft-solid proxy): a body bent
    back against its pressure (a blocked tip) closes the lumen from 0.225 bar (docs/models/rod.md)."""
    body = replace(design, device=None, length=1.0)
    try:
        settings = SectionSettings(**section_settings)
    except TypeError as exc:
        raise ModelError(f"model 'section': {exc}; settings: {list(SectionSettings.__annotations__)}") from None
    section = discretise(body, settings)
    store = store_for(cache)
    parts = [body.content_hash(), settings.key(), asdict(grid), section.mesh.n_nodes]
    z = store.load_arrays(_KIND, LAW_VERSION, parts, design.name, require=_TABLE_ARRAYS) if store else None
    table = _from_arrays(z) if z is not None else None
    if table is None:
        table = moment_curvature(section.problem, settings, grid.pressures(), grid.curvatures(), progress=progress)
        if store is not None:
            store.save_arrays(_KIND, LAW_VERSION, parts, _to_arrays(table), design.name)
    mesh = f"section D/{design.outer_diameter / section.mesh.h:.0f}"
    if settings.lumen_fill is not None:
        mesh += f", lumen fill {settings.lumen_fill:g}"
    elif section.problem.contact:
        mesh += f", lumen contact {settings.contact_distance:g}"
    return TabulatedLaw(table, source=f"rod law from {mesh}")


_KIND = "rod_law"   # the cache kind of the tables
_TABLE_ARRAYS = ("curvatures", "pressures", "moment", "stretch", "messages", "direction", "pressure_direction")


def _to_arrays(t: MomentTable) -> dict:
    return dict(curvatures=t.curvatures, pressures=t.pressures, moment=t.moment, stretch=t.stretch,
                messages=np.array(json.dumps(t.messages)), direction=t.direction,
                pressure_direction=t.pressure_direction)


def _from_arrays(z: dict) -> MomentTable:
    return MomentTable(curvatures=z["curvatures"], pressures=z["pressures"], moment=z["moment"],
                       stretch=z["stretch"], messages=json.loads(str(z["messages"])),
                       direction=z["direction"], pressure_direction=z["pressure_direction"])
