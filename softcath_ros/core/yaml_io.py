"""The one bounded, safe YAML reader every loader uses (designs, scenes, protocols, params files,
calibrations, the envelope, attachments of a recording).

- YAML 1.2 number rules: PyYAML follows YAML 1.1, where ``12.7e3`` or ``1e-3`` (no sign or no
  dot) are strings; design files written by people use exactly those, so we resolve them as floats.
- Bounded: a file larger than ``MAX_BYTES`` is refused before it is read whole; nesting deeper
  than ``MAX_DEPTH`` and documents with more than ``MAX_NODES`` nodes are refused while composing,
  and aliases (``*name``) are refused, so an alias bomb cannot expand.
- Strict: duplicate keys are an error (a second ``limits:`` must not silently win); an integer
  literal beyond the float range (``length: 1000...0``) is an error naming its field; bytes that
  are not UTF-8 are one line naming the offset.

Every fault is a one-line ``YamlError`` (a SoftcathError): file, line and reason.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

import yaml
from yaml.nodes import MappingNode, ScalarNode

from .errors import SoftcathError

MAX_BYTES = 1 << 20        # 1 MiB: the largest shipped file is a few kB
MAX_DEPTH = 64             # nesting levels (a design is 4 deep)
MAX_NODES = 200_000        # scalars + collections in one document
# Longest integer literal that can still be a float (1.8e308 has 309 digits).
_MAX_INT_DIGITS = len(str(int(sys.float_info.max)))
_INT_TAG = "tag:yaml.org,2002:int"


class YamlError(SoftcathError):
    """A file that is not acceptable YAML for softcath (too large, not UTF-8, malformed, ...)."""


class SoftcathLoader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 floats, no aliases, bounded depth and size, unique keys."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(None, None, "aliases (*name) are not accepted", event.start_mark)
        self._nodes += 1
        if self._nodes > MAX_NODES:
            raise yaml.composer.ComposerError(None, None, f"more than {MAX_NODES} values in one document",
                                              self.peek_event().start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_DEPTH} levels",
                                                  self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        if isinstance(node, MappingNode):
            seen = {}
            for key_node, value_node in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    hash(key)
                except TypeError:
                    raise yaml.constructor.ConstructorError(None, None, "a key must be a plain value",
                                                            key_node.start_mark) from None
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"duplicate key '{key}' (first at line {seen[key] + 1})", key_node.start_mark)
                seen[key] = key_node.start_mark.line
                self._check_int(value_node, f"field '{key}'")
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        self._check_int(node, "value")
        return super().construct_yaml_int(node)

    def _check_int(self, node, what: str) -> None:
        """An integer literal must fit a float (designs and protocols compute in floats)."""
        if not (isinstance(node, ScalarNode) and node.tag == _INT_TAG):
            return
        too_big = len(node.value) > _MAX_INT_DIGITS + 8 or abs(
            yaml.constructor.SafeConstructor.construct_yaml_int(self, node)) > sys.float_info.max
        if too_big:
            raise yaml.constructor.ConstructorError(
                None, None, f"{what}: integer {node.value[:12]}... is too large for a number", node.start_mark)


SoftcathLoader.add_constructor(_INT_TAG, SoftcathLoader.construct_yaml_int)
SoftcathLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def _one_line(exc: yaml.YAMLError) -> str:
    """PyYAML's multi-line message as one line: the problem and where."""
    problem = getattr(exc, "problem", None) or getattr(exc, "context", None) or str(exc).splitlines()[0]
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
    return f"{problem}{where}"


def load_yaml(text: str, source: str = "YAML"):
    """Parse ``text`` (one document) with the bounds above; ``YamlError`` names ``source``."""
    if len(text) > MAX_BYTES:
        raise YamlError(f"{source}: larger than {MAX_BYTES >> 10} KiB; not read")
    try:
        return yaml.load(text, Loader=SoftcathLoader)  # noqa: S506 - SafeLoader subclass
    except yaml.YAMLError as exc:
        raise YamlError(f"{source}: not valid YAML: {_one_line(exc)}") from None
    except RecursionError:
        raise YamlError(f"{source}: nested too deeply") from None


def decode_text(data: bytes, source: str = "YAML") -> str:
    """``data`` as UTF-8 text, bounded like a file."""
    if len(data) > MAX_BYTES:
        raise YamlError(f"{source}: larger than {MAX_BYTES >> 10} KiB; not read")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlError(f"{source}: not UTF-8 text (byte {exc.start})") from None


def read_text(path, source: str | None = None) -> str:
    """A text file, refused (one line) when missing, unreadable, too large or not UTF-8."""
    p = Path(path)
    source = source or str(p)
    try:
        with open(p, "rb") as f:
            data = f.read(MAX_BYTES + 1)
    except IsADirectoryError:
        raise YamlError(f"{source}: is a folder, not a file") from None
    except OSError as exc:
        raise YamlError(f"{source}: cannot read ({exc.strerror or exc})") from None
    return decode_text(data, source)


def load_yaml_file(path, source: str | None = None):
    """Read and parse a YAML file with every bound above."""
    source = source or str(path)
    return load_yaml(read_text(path, source), source)
