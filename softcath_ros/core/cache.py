"""One store for expensive results (section batches, fe3d ramps, surrogate tables, the rod's law,
study cases, benchmark rows): kind, version and key parts -> a value on disk.

Where: ``$SOFTCATH_CACHE`` if set, else the user's cache directory (``$XDG_CACHE_HOME/softcath_ros``,
or ``~/.cache/softcath_ros``); never the source tree unless that variable points there. A rung's
``cache=`` option may name another root (a directory) for its own entries.

Layout: ``<root>/<kind>/<name>_<key>.<npz|json>``, where the key is a hash of the version and
every input that changes the result (a changed version or input is a miss, never a stale hit) and
the name (a design's, a rung's) is there for a person listing the folder. Writes are atomic (a
temporary file in the same folder, then ``os.replace``), so a reader never sees a partial entry.
An entry that cannot be read (truncated, corrupt) is a miss: one warning line, then rebuilt.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ENV = "SOFTCATH_CACHE"          # the one setting: the cache's root directory

_log = logging.getLogger("softcath_ros.cache")


def default_root() -> Path:
    """The user's cache directory for softcath_ros (not created here)."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    # the XDG rule: a relative value is ignored
    return (Path(base) if os.path.isabs(base) else Path.home() / ".cache") / "softcath_ros"


def cache_root() -> Path:
    """The root every kind of result is cached under: ``$SOFTCATH_CACHE`` or ``default_root()``."""
    root = os.environ.get(ENV)
    return Path(root).expanduser() if root else default_root()


def _plain(value):
    """JSON form of values key parts may hold besides JSON types (arrays, numpy scalars, paths)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    return str(value)


def key_of(*parts) -> str:
    """A stable 16-hex-digit hash of the parts (JSON with sorted keys; floats exactly)."""
    blob = json.dumps(parts, sort_keys=True, default=_plain).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


class CacheStore:
    """Entries under one root (``None``: ``cache_root()``, read at each access so the setting can
    change while running). ``parts`` is anything ``key_of`` takes: a list, a dict, ..."""

    def __init__(self, root: str | Path | None = None):
        self._root = Path(root).expanduser() if root is not None else None

    @property
    def root(self) -> Path:
        return self._root if self._root is not None else cache_root()

    @staticmethod
    def key(version: str | None, parts) -> str:
        return key_of(version, parts)

    def path(self, kind: str, version: str | None, parts, name: str = "", ext: str = "json") -> Path:
        """Where the entry lives (whether or not it exists)."""
        key = self.key(version, parts)
        return self.root / kind / (f"{_safe(name)}_{key}.{ext}" if name else f"{key}.{ext}")

    # ------------------------------------------------------------------ arrays (npz)
    def load_arrays(self, kind: str, version: str | None, parts, name: str = "",
                    require: tuple[str, ...] = ()) -> dict[str, np.ndarray] | None:
        """The arrays saved under this entry, or None (absent, or unreadable or without one of the
        ``require``d arrays: warned and a miss)."""
        path = self.path(kind, version, parts, name, "npz")
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            missing = [k for k in require if k not in arrays]
            if missing:
                raise KeyError(f"no array {', '.join(missing)}")
            return arrays
        except Exception as exc:   # a damaged entry of any sort is rebuilt, never a traceback
            _warn_unreadable(path, exc)
            return None

    def save_arrays(self, kind: str, version: str | None, parts, arrays: dict[str, Any], name: str = "") -> Path:
        path = self.path(kind, version, parts, name, "npz")
        _atomic_write(path, lambda f: np.savez(f, **arrays))
        return path

    # ------------------------------------------------------------------ JSON documents
    def load_json(self, kind: str, version: str | None, parts, name: str = ""):
        """The JSON document saved under this entry, or None (absent, or unreadable: warned and a miss)."""
        path = self.path(kind, version, parts, name, "json")
        if not path.is_file():
            return None
        try:
            return json.loads(path.read_text())
        except Exception as exc:
            _warn_unreadable(path, exc)
            return None

    def save_json(self, kind: str, version: str | None, parts, value, name: str = "") -> Path:
        path = self.path(kind, version, parts, name, "json")
        _atomic_write(path, lambda f: f.write(json.dumps(value).encode()))
        return path


def store_for(cache) -> CacheStore | None:
    """The store a ``cache=`` option names: True -> the project cache (``cache_root()``);
    False, None or "" -> no cache; a directory -> a store rooted there; a store as it is."""
    if cache is True:
        return CacheStore()
    if isinstance(cache, CacheStore):
        return cache
    return CacheStore(cache) if cache else None


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-." else "_" for c in str(name))


def _atomic_write(path: Path, write) -> None:
    """Write through ``write(binary file)`` to a temporary file in the same folder, then replace."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o644)    # as an ordinary file (mkstemp's default is private)
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _warn_unreadable(path: Path, exc: Exception) -> None:
    _log.warning("cache entry %s cannot be read (%s: %s); it is computed again",
                 path, type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")


_DEFAULT = CacheStore()


def load_arrays(kind: str, version: str | None, parts, name: str = "",
                require: tuple[str, ...] = ()) -> dict[str, np.ndarray] | None:
    return _DEFAULT.load_arrays(kind, version, parts, name, require)


def save_arrays(kind: str, version: str | None, parts, arrays: dict[str, Any], name: str = "") -> Path:
    return _DEFAULT.save_arrays(kind, version, parts, arrays, name)


def load_json(kind: str, version: str | None, parts, name: str = ""):
    return _DEFAULT.load_json(kind, version, parts, name)


def save_json(kind: str, version: str | None, parts, value, name: str = "") -> Path:
    return _DEFAULT.save_json(kind, version, parts, value, name)


__all__ = ["CacheStore", "ENV", "cache_root", "default_root", "key_of", "load_arrays", "load_json",
           "save_arrays", "save_json", "store_for"]
