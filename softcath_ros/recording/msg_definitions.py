"""Complete message definitions and type hashes from the installed interface files.

rosbag2 stores, per schema, the ``ros2msg`` text of the type followed by every type it
depends on (recursively), each preceded by a line of 80 '=' and ``MSG: pkg/Type``
(rosbag2 docs/message_definition_encoding.md). This module rebuilds that text from
``share/<pkg>/msg/<Type>.msg`` the way rosbag2's LocalMessageDefinitionSource does
(same dependency regex, same sorted depth-first order), and reads the RIHS01 type
hash that rosidl generates next to it (``<Type>.json``).
"""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path

from ..core.errors import SoftcathError

DELIMITER = "=" * 80 + "\n"
_TYPENAME = re.compile(r"^([a-zA-Z0-9_]+)/(?:msg/|srv/)?([a-zA-Z0-9_]+)$")
# Same as rosbag2: a field type at the start of a line, optionally an array suffix.
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string"}


class DefinitionNotFound(SoftcathError):
    pass


def _prefixes() -> list[Path]:
    """Install prefixes to search: AMENT_PREFIX_PATH (a sourced workspace), then this Python's."""
    out = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for p in (Path(sys.prefix), Path(sys.base_prefix)):
        if p not in out:
            out.append(p)
    return out


@functools.lru_cache(maxsize=None)
def interface_file(package: str, name: str, ext: str) -> Path:
    for prefix in _prefixes():
        candidate = prefix / "share" / package / "msg" / f"{name}{ext}"
        if candidate.is_file():
            return candidate
    raise DefinitionNotFound(f"no {name}{ext} for package '{package}' under share/ of "
                             f"{[str(p) for p in _prefixes()]}")


def split_type_name(type_name: str) -> tuple[str, str]:
    m = _TYPENAME.match(type_name)
    if not m:
        raise DefinitionNotFound(f"message type name '{type_name}' is not pkg/msg/Type")
    return m.group(1), m.group(2)


def dependencies(text: str, package: str) -> set[str]:
    deps = set()
    for m in _FIELD_TYPE.finditer(text):
        t = m.group(1)
        if t in _PRIMITIVES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return deps


@functools.lru_cache(maxsize=None)
def _msg_text(type_name: str) -> str:
    package, name = split_type_name(type_name)
    return interface_file(package, name, ".msg").read_text()


@functools.lru_cache(maxsize=None)
def full_definition(type_name: str) -> str:
    """The complete ``ros2msg`` definition of ``type_name`` (e.g. ``std_msgs/msg/Float64``)."""
    seen: set[str] = set()

    def append(t: str) -> str:
        package, _ = split_type_name(t)
        text = _msg_text(t)
        out = text
        for dep in sorted(dependencies(text, package)):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + DELIMITER + f"MSG: {dep}\n" + append(dep)
        return out

    return append(type_name)


@functools.lru_cache(maxsize=None)
def type_description_hash(type_name: str) -> str:
    """RIHS01 hash string of ``type_name`` from rosidl's generated JSON, or '' if not installed."""
    package, name = split_type_name(type_name)
    try:
        data = json.loads(interface_file(package, name, ".json").read_text())
    except (DefinitionNotFound, ValueError):
        return ""
    canonical = f"{package}/msg/{name}"
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == canonical:
            return entry.get("hash_string", "")
    return ""
