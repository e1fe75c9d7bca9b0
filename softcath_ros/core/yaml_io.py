"""YAML loading with YAML 1.2 number rules.

PyYAML follows YAML 1.1, where ``12.7e3`` or ``1e-3`` (no sign or no dot) are strings;
design files written by people use exactly those, so we resolve them as floats.
"""
from __future__ import annotations

import re

import yaml


class SoftcathLoader(yaml.SafeLoader):
    """SafeLoader whose floats follow YAML 1.2 (``1e5``, ``12.7e3`` are numbers)."""


SoftcathLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def load_yaml(text: str):
    return yaml.load(text, Loader=SoftcathLoader)  # noqa: S506 - SafeLoader subclass
