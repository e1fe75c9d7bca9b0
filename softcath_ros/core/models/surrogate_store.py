"""Where a surrogate table is kept: its key, the cache file, the package's shipped tables and
table files, and why a found table is stale (see ``surrogate.py``)."""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..errors import ModelError
from .surrogate_settings import SURROGATE_VERSION

_KIND = "surrogate"   # the cache kind of the tables


class SurrogateTableStore:
    """Storage of a SurrogateModel's table (mixed into it: uses its design, settings, store, key,
    table and meta; sets origin, table_path and stale_reason)."""

    def cache_parts(self) -> list:
        """The design, the table settings and the source rung's declared version (a changed
        solver rebuilds the table)."""
        from . import rung_class

        try:
            source_version = rung_class(self.settings.source).solver_version
        except ModelError:
            source_version = None   # an unknown source: refused when the table is built
        return [self.design_hash(), asdict(self.settings), source_version]

    def design_hash(self) -> str:
        """The design's hash a table is keyed on: without the length when the source answers per
        section (a table serves every length), with it when the source solves a whole body."""
        return self.design.content_hash() if self.info.depends_on_length else self.design.per_section_hash()

    def _cache_name(self) -> str:
        return f"{self.design.name}_{self.settings.source}"

    @property
    def path(self) -> Path | None:
        """The table's file in the cache (None without a cache)."""
        if self.store is None:
            return None
        return self.store.path(_KIND, self.solver_version, self.cache_parts(), self._cache_name(), "npz")

    def shipped_path(self) -> Path:
        """Where the package keeps (or would keep) this design's table."""
        from ...resources import shipped_dir

        return shipped_dir("surrogate_table") / f"{self._cache_name()}.npz"

    def _arrays(self) -> dict:
        return {"meta": np.array(json.dumps(self.meta)), **self.table}

    def _save(self) -> Path:
        return self.store.save_arrays(_KIND, self.solver_version, self.cache_parts(), self._arrays(),
                                      self._cache_name())

    def write(self, path: str | Path) -> Path:
        """The table as a file (``softcath surrogate build --out``; the shipped tables)."""
        from ..cache import _atomic_write

        path = Path(path)
        _atomic_write(path, lambda f: np.savez_compressed(f, **self._arrays()))
        return path

    @staticmethod
    def _split(arrays: dict):
        meta = json.loads(str(arrays.pop("meta")))
        return arrays, meta

    def _load(self):
        table = self.store.load_arrays(_KIND, self.solver_version, self.cache_parts(), self._cache_name(),
                                       require=("meta",))
        if table is None:
            return None
        table, meta = self._split(table)
        return (table, meta) if meta.get("key") == self.key else None

    def _load_file(self, path: Path, required: bool = False):
        """The table in ``path`` if it is this model's (same key); else None, or with ``required`` a
        one-line error saying why it does not fit."""
        try:
            with np.load(path, allow_pickle=False) as z:
                table, meta = self._split({k: z[k] for k in z.files})
        except Exception as exc:
            if required:
                raise ModelError(f"model 'surrogate': table {path} cannot be read ({type(exc).__name__})") from None
            return None
        if meta.get("key") == self.key:
            return table, meta
        self.stale_reason = self._stale_reason(meta)
        if required:
            raise ModelError(f"model 'surrogate': table {path} is not current for design '{self.design.name}' "
                             f"({self.stale_reason}); rebuild it: softcath surrogate build {self.design.name}")
        return None

    def _stale_reason(self, meta: dict) -> str:
        if meta.get("design_hash") != self.design_hash():
            return f"built for another design content (hash {meta.get('design_hash')})"
        if meta.get("version") != SURROGATE_VERSION:
            return f"built by {meta.get('version')}, this is {SURROGATE_VERSION}"
        now = self.cache_parts()[2]
        if meta.get("source_version", now) != now:
            return f"built from {meta.get('source_version')}, the source rung is now {now}"
        return "built with other table settings"

    def _load_shipped(self):
        path = self.shipped_path()
        if not path.is_file():
            return None
        loaded = self._load_file(path)
        if loaded is not None:
            self.origin, self.table_path = "shipped", path
        else:
            self.stale_reason = f"the shipped table {path.name} is stale: {self.stale_reason}"
        return loaded


__all__ = ["SurrogateTableStore"]
