"""The one cache store (core/cache.py): round trips, atomic writes, damaged entries, versions,
where it lives; and the rungs' use of it (a damaged entry is rebuilt, ``cache=`` options)."""
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softcath_ros.core import cache
from softcath_ros.core.cache import CacheStore, cache_root, default_root, key_of, store_for
from softcath_ros.core.design import load_design
from softcath_ros.core.models import RUNGS, make_model, rung_class

REPO = Path(__file__).resolve().parents[1]
PARTS = {"design": "abc", "settings": {"mesh_size": 2.5e-4, "tol": 1e-6}, "pressures": [[0.0], [1500.5]]}


def test_arrays_and_json_round_trip(tmp_path):
    store = CacheStore(tmp_path)
    arrays = {"k": np.array([[1.0, -2.5e-7], [np.nan, np.inf]]), "ok": np.array([True, False]),
              "msg": np.array("did not converge at p = 0.3 bar")}
    path = store.save_arrays("section", "v1", PARTS, arrays, name="implemented_5mm")
    back = store.load_arrays("section", "v1", PARTS, name="implemented_5mm")
    assert set(back) == set(arrays)
    for k in arrays:
        np.testing.assert_array_equal(back[k], arrays[k])
    doc = {"a": [1, 2.5, None], "b": {"c": "d"}, "inf": float("inf")}
    store.save_json("fe3d", "v1", PARTS, doc, name="implemented_5mm")
    assert store.load_json("fe3d", "v1", PARTS, name="implemented_5mm") == doc
    # readable names: <root>/<kind>/<name>_<key>.<ext>
    assert path == tmp_path / "section" / f"implemented_5mm_{key_of('v1', PARTS)}.npz"
    assert store.load_arrays("section", "v1", PARTS, name="other") is None   # the name is part of the file


def test_same_inputs_one_key_other_inputs_or_version_miss(tmp_path):
    store = CacheStore(tmp_path)
    same = {"pressures": np.array([[0.0], [1500.5]]), "settings": {"tol": 1e-6, "mesh_size": 2.5e-4},
            "design": "abc"}
    assert store.key("v1", same) == store.key("v1", PARTS)      # arrays and dict order do not matter
    store.save_json("studies", "v1", PARTS, {"x": 1})
    assert store.load_json("studies", "v1", same) == {"x": 1}
    assert store.load_json("studies", "v2", PARTS) is None      # a changed version is a miss
    assert store.load_json("studies", "v1", {**PARTS, "pressures": [[0.0], [1500.50001]]}) is None
    assert key_of(1e-16) != key_of(0.0) and key_of([0.1 + 0.2]) != key_of([0.3])  # floats exactly


def test_write_is_atomic(tmp_path, monkeypatch):
    """A writer that dies half way leaves the old entry whole and no stray file; during a write the
    entry's own path never holds a partial file."""
    store = CacheStore(tmp_path)
    store.save_arrays("rod_law", "v1", PARTS, {"m": np.arange(5.0)}, name="d")
    target = store.path("rod_law", "v1", PARTS, "d", "npz")
    real_savez = np.savez

    def dies_half_way(f, **arrays):
        assert target.is_file() and np.load(target)["m"].size == 5   # the old entry is untouched
        f.write(b"PK\x03\x04 partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", dies_half_way)
    with pytest.raises(KeyboardInterrupt):
        store.save_arrays("rod_law", "v1", PARTS, {"m": np.arange(9.0)}, name="d")
    monkeypatch.setattr(np, "savez", real_savez)
    assert store.load_arrays("rod_law", "v1", PARTS, name="d")["m"].size == 5
    assert sorted(p.name for p in target.parent.iterdir()) == [target.name]   # no temporary left


@pytest.mark.parametrize("damage", [b"", b"PK\x03\x04 truncated", b"\x00" * 40, b"{not json"])
def test_damaged_entry_is_a_miss_with_one_warning(tmp_path, caplog, damage):
    store = CacheStore(tmp_path)
    for kind, ext in (("surrogate", "npz"), ("ladder", "json")):
        path = store.path(kind, "v1", PARTS, "d", ext)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(damage)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="softcath_ros.cache"):
            got = (store.load_arrays if ext == "npz" else store.load_json)(kind, "v1", PARTS, "d")
        assert got is None
        assert len(caplog.records) == 1 and "cannot be read" in caplog.text and path.name in caplog.text
        assert "\n" not in caplog.records[0].getMessage()


def test_entry_without_a_required_array_is_a_miss_with_a_warning(tmp_path, caplog):
    store = CacheStore(tmp_path)
    store.save_arrays("section", "v1", PARTS, {"curvature": np.zeros((1, 2))}, name="d")
    assert store.load_arrays("section", "v1", PARTS, "d", require=("curvature",)) is not None
    with caplog.at_level(logging.WARNING, logger="softcath_ros.cache"):
        assert store.load_arrays("section", "v1", PARTS, "d", require=("curvature", "message")) is None
    assert len(caplog.records) == 1 and "no array message" in caplog.text


def test_truncated_npz_of_a_real_entry_is_rebuilt(tmp_path, caplog):
    """A section batch whose file was cut short (a full disk, a killed copy) is solved again, with a
    warning line and no traceback."""
    d = load_design("implemented_5mm")
    opts = {"mesh_size": d.outer_diameter / 8, "cache": tmp_path}
    p = np.array([[0.05e5]])
    first = make_model("section", d, **opts).evaluate(p)
    [entry] = (tmp_path / "section").iterdir()
    assert entry.name.startswith("implemented_5mm_") and entry.suffix == ".npz"
    entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 2])
    again = make_model("section", d, **opts).evaluate(p)
    assert not again.diagnostics.cached
    np.testing.assert_allclose(again.curvature, first.curvature, rtol=1e-12)
    assert "cannot be read" in caplog.text
    third = make_model("section", d, **opts).evaluate(p)    # rewritten whole
    assert third.diagnostics.cached


def test_surrogate_table_damaged_is_rebuilt(tmp_path):
    d = load_design("implemented_5mm")
    m = make_model("surrogate", d, source="closed_form", cache=tmp_path, pressure_step=6250.0)
    assert m.built_now and m.path.parent == tmp_path / "surrogate" and m.path.name.startswith("implemented_5mm_")
    assert not make_model("surrogate", d, source="closed_form", cache=tmp_path, pressure_step=6250.0).built_now
    m.path.write_bytes(b"garbage")
    again = make_model("surrogate", d, source="closed_form", cache=tmp_path, pressure_step=6250.0)
    assert again.built_now and again.meta["key"] == m.meta["key"]


def test_cache_options_of_the_rungs(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTCATH_CACHE", str(tmp_path / "env"))
    assert store_for(False) is None and store_for(None) is None and store_for("") is None
    assert store_for(True).root == tmp_path / "env"
    assert store_for(tmp_path / "mine").root == tmp_path / "mine"
    assert store_for(str(tmp_path / "mine")).root == tmp_path / "mine"
    d = load_design("implemented_5mm")
    assert make_model("surrogate", d, source="closed_form", cache=False, pressure_step=6250.0).path is None
    m = make_model("surrogate", d, source="closed_form", cache=True, pressure_step=6250.0)
    assert m.path.is_file() and tmp_path / "env" / "surrogate" == m.path.parent


def test_location_comes_from_softcath_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFTCATH_CACHE", str(tmp_path))
    assert cache_root() == tmp_path
    path = cache.save_json("ladder", "v1", PARTS, {"x": 1}, name="rod")
    assert path.parent == tmp_path / "ladder"
    # the setting is read at each access, and child processes see the same store
    code = ("from softcath_ros.core import cache; import sys; "
            f"sys.exit(0 if cache.load_json('ladder', 'v1', {PARTS!r}, name='rod') == {{'x': 1}} else 3)")
    r = subprocess.run([sys.executable, "-c", code], env={**os.environ, "SOFTCATH_CACHE": str(tmp_path)},
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr


def test_default_is_the_users_cache_dir_never_the_source_tree(tmp_path, monkeypatch):
    monkeypatch.delenv("SOFTCATH_CACHE", raising=False)
    assert REPO not in default_root().parents and REPO != default_root()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == default_root() == tmp_path / "xdg" / "softcath_ros"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/dir")   # ignored, as the XDG rule says
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_root() == tmp_path / "home" / ".cache" / "softcath_ros"


def test_this_run_has_its_own_empty_cache():
    root = Path(os.environ["SOFTCATH_CACHE"])
    assert root.name.startswith("softcath-test-cache-") and REPO not in root.parents
    assert cache_root() == root


def test_every_rung_declares_its_solver_version():
    versions = {name: rung_class(name).solver_version for name in RUNGS}
    assert all(isinstance(v, str) and v for v in versions.values()), versions
    assert len(set(versions.values())) == len(versions)
