"""A declared option: what a rung's constructor or a study's ``run`` takes, by name, kind and
purpose, so the command line validates and documents options from the declaration."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Option:
    """One option: its name, the kind of value and what it does."""

    name: str
    kind: str            # "bool", "int", "float", "str", "mapping" or "object" (a Python object)
    description: str


def option_names(options: tuple[Option, ...]) -> list[str]:
    return [o.name for o in options]
