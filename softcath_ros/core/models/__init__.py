"""The model ladder: every rung behind one interface (``BendModel``), chosen by name."""
from __future__ import annotations

import importlib

from ..design import Design
from ..errors import ModelError
from .base import BendModel, BendState

# name -> "module:Class"; imported lazily so heavy engines (NGSolve) load only when used.
RUNGS: dict[str, str] = {
    "closed_form": "softcath_ros.core.models.closed_form:ClosedFormModel",
    "section": "softcath_ros.core.models.section:SectionModel",
    "fe3d": "softcath_ros.core.models.fe3d:Fe3dModel",
    "surrogate": "softcath_ros.core.models.surrogate:SurrogateModel",
    "rod": "softcath_ros.core.models.rod:RodModel",
}


def available_models() -> list[str]:
    return sorted(RUNGS)


def make_model(name: str, design: Design, **options) -> BendModel:
    """Instantiate the rung ``name`` for ``design``; unknown names list the known ones.
    ``"auto"`` picks a rung for ``scene=`` (core/model_selection.py)."""
    if name == "auto":
        from ..model_selection import make_auto_model

        return make_auto_model(design, **options)
    if name not in RUNGS:
        raise ModelError(f"unknown model '{name}'; available: {', '.join(available_models())}")
    module_name, cls_name = RUNGS[name].split(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ModelError(f"model '{name}' needs an optional dependency that is not installed: {exc}") from None
    return getattr(module, cls_name)(design, **options)


__all__ = ["BendModel", "BendState", "RUNGS", "available_models", "make_model"]
