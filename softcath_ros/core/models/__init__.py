"""The model ladder: every rung behind one interface (``BendModel``), chosen by name.

Each rung class declares what it can do (``RungInfo``: scene features, linear gain, solved
backbone, options); ``rung_info`` reads that without building a rung or loading a heavy engine.
Names that choose a rung instead of naming one ("auto") are looked up the same lazy way: the
chooser's module (core/model_selection.py) is imported when the name is first used, so this
registry imports no selection and no module registers anything by import side effect.
"""
from __future__ import annotations

import importlib
from typing import Callable

from ..design import Design
from ..errors import ModelError
from .base import BendModel, BendState, RungInfo, SolverDiagnostics, TipPose

# name -> "module:Class"; imported lazily so heavy engines (NGSolve) load only when used.
RUNGS: dict[str, str] = {
    "closed_form": "softcath_ros.core.models.closed_form:ClosedFormModel",
    "section": "softcath_ros.core.models.section:SectionModel",
    "fe3d": "softcath_ros.core.models.fe3d:Fe3dModel",
    "surrogate": "softcath_ros.core.models.surrogate:SurrogateModel",
    "rod": "softcath_ros.core.models.rod:RodModel",
}

# name -> "module:function" make(design, **options): names that pick a rung instead of naming one.
CHOOSERS: dict[str, str] = {
    "auto": "softcath_ros.core.model_selection:make_auto_model",
}


def _chooser(name: str) -> Callable[..., BendModel]:
    module_name, func_name = CHOOSERS[name].split(":")
    return getattr(importlib.import_module(module_name), func_name)


def available_models() -> list[str]:
    return sorted(RUNGS)


def rung_class(name: str) -> type[BendModel]:
    """The class of rung ``name`` (its module imported; engines such as NGSolve load only when built)."""
    if name not in RUNGS:
        raise ModelError(f"unknown model '{name}'; available: {', '.join(available_models())}")
    module_name, cls_name = RUNGS[name].split(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ModelError(f"model '{name}' needs an optional dependency that is not installed: {exc}") from None
    return getattr(module, cls_name)


def rung_info(name: str) -> RungInfo:
    """What rung ``name`` declares it can do, without building it."""
    return rung_class(name).info


def run_options(name: str, *, progress: bool | None = None, cache: bool | None = None) -> dict:
    """Of ``progress`` and ``cache`` (None: leave the rung's default), those rung ``name`` declares:
    what a command passes for ``--no-cache`` and its progress bar (rungs differ; "auto" takes neither)."""
    if name not in RUNGS:
        return {}
    info = rung_info(name)
    return {k: v for k, v in (("progress", progress), ("cache", cache)) if v is not None and info.accepts(k)}


def make_model(name: str, design: Design, **options) -> BendModel:
    """Instantiate the rung ``name`` for ``design``; unknown names list the known ones.
    ``"auto"`` picks a rung for ``scene=`` (core/model_selection.py)."""
    if name in CHOOSERS:
        return _chooser(name)(design, **options)
    model = rung_class(name)(design, **options)
    model.made_with = dict(options)
    return model


__all__ = ["BendModel", "BendState", "CHOOSERS", "RUNGS", "RungInfo", "SolverDiagnostics",
           "TipPose", "available_models", "make_model", "rung_class", "rung_info",
           "run_options"]
