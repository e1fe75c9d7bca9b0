"""Shipped data are found the same way from a source checkout, a pip (wheel) install and a
colcon-style install (setup.py install into a prefix, as colcon's ament_python build does)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Run in a fresh interpreter whose softcath_ros comes from the install under test (PYTHONPATH is
# searched before the development install); prints the package folder and what the finder found.
PROBE = """
import json, sys
import softcath_ros
from softcath_ros.resources import checkout_root, envelope_path, find, shipped_names
from softcath_ros.core.design import load_design
from softcath_ros.core.scene import load_scene
from softcath_ros.core.model_selection import select_model
from softcath_ros.bench.protocol import load_protocol
scene = load_scene("free_bending_live")
print(json.dumps({
    "package": softcath_ros.__file__,
    "design": load_design("implemented_5mm").name,
    "protocol": load_protocol("quick").name,
    "envelope": str(envelope_path()), "envelope_exists": envelope_path().is_file(),
    "params": str(find("params", "model_node")),
    "designs": shipped_names("design"), "scenes": shipped_names("scene"),
    "auto": select_model(scene).rung,
    "tables": shipped_names("surrogate_table"),
    "default_rung_origin": __import__("softcath_ros.core.models", fromlist=["make_model"]).make_model(
        "surrogate", load_design("three_channel_5mm"), build=False, cache=False).origin,
    "checkout": str(checkout_root()),
    "foxglove_layout": __import__("softcath_ros.resources", fromlist=["config_dir"]).config_dir().joinpath(
        "foxglove", "softcath.json").is_file(),
}))
"""


def _probe(site: Path, cwd: Path) -> dict:
    import json

    env = dict(os.environ, PYTHONPATH=str(site))
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=cwd, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _clean_copy(src: Path) -> Path:
    """The tracked tree copied to ``src``: builds see what a clone has (no stale build/ or untracked
    files of this checkout) and leave nothing behind in it."""
    files = subprocess.run(["git", "-C", str(REPO), "ls-files", "-z"], check=True, capture_output=True,
                           text=True).stdout.split("\0")
    for f in filter(None, files):
        if (REPO / f).is_file():
            (src / f).parent.mkdir(parents=True, exist_ok=True)
            (src / f).write_bytes((REPO / f).read_bytes())
    return src


def _check(found: dict, root: Path, data_root: Path | None = None) -> None:
    """``root``: where the package must come from; ``data_root``: where its shipped data must (the
    checkout, or the install prefix whose share/softcath_ros/config holds them)."""
    assert Path(found["package"]).resolve().is_relative_to(root.resolve()), found["package"]
    assert Path(found["envelope"]).resolve().is_relative_to((data_root or root).resolve()), found["envelope"]
    assert found["design"] == "implemented_5mm" and found["protocol"] == "quick" and found["envelope_exists"]
    assert {"implemented_5mm", "three_channel_5mm"} <= set(found["designs"])
    assert "free_bending_live" in found["scenes"]
    assert found["auto"]  # model: auto picked a rung from the shipped envelope and scene
    assert found["foxglove_layout"]  # the Foxglove layout ships as package data
    # the nodes' default rung finds its shipped table in every install route: nothing to build
    assert {"implemented_5mm_section", "three_channel_5mm_section"} <= set(found["tables"])
    assert found["default_rung_origin"] == "shipped"
    # the benchmark results (softcath chart's default) exist only in a source checkout
    assert found["checkout"] == (str(REPO) if root == REPO else "None")


def test_the_licence_is_one_and_its_text_ships():
    """setup.py and package.xml name the licence LICENSE holds (Apache-2.0, its full text)."""
    import re

    text = (REPO / "LICENSE").read_text()
    assert "Apache License" in text and "Version 2.0, January 2004" in text and "END OF TERMS AND CONDITIONS" in text
    assert 'license="Apache-2.0"' in (REPO / "setup.py").read_text()
    assert re.findall(r"<license>(.*?)</license>", (REPO / "package.xml").read_text()) == ["Apache-2.0"]


def test_source_checkout(tmp_path):
    found = _probe(REPO, tmp_path)
    _check(found, REPO)


@pytest.mark.slow
def test_pip_wheel_install(tmp_path):
    wheels, site = tmp_path / "wheels", tmp_path / "site"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(wheels), str(_clean_copy(tmp_path / "src"))], capture_output=True, text=True,
                           timeout=300)
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next(wheels.glob("softcath_ros-*.whl"))
    import zipfile

    with zipfile.ZipFile(wheel) as z:   # the licence text travels with the package
        assert any(n.endswith(".dist-info/LICENSE") for n in z.namelist()), z.namelist()
    inst = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site),
                           str(wheel)], capture_output=True, text=True, timeout=300)
    assert inst.returncode == 0, inst.stderr[-2000:]
    _check(_probe(site, tmp_path), site)


@pytest.mark.slow
def test_colcon_style_install(tmp_path):
    """What `colcon build` runs for an ament_python package: setup.py egg_info, build and install
    into a prefix with a record (no colcon needed)."""
    src = _clean_copy(tmp_path / "src")
    prefix, build = tmp_path / "install", tmp_path / "build"
    build.mkdir()  # colcon creates the build folder first
    cmd = [sys.executable, "setup.py", "-q", "egg_info", "--egg-base", str(build), "build", "--build-base",
           str(build), "install", "--prefix", str(prefix), "--single-version-externally-managed", "--record",
           str(build / "install.log")]
    out = subprocess.run(cmd, cwd=src, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    site = next(prefix.glob("lib/python3*/site-packages"))
    share = prefix / "share" / "softcath_ros"
    assert (share / "package.xml").is_file() and (share / "LICENSE").read_text() == (REPO / "LICENSE").read_text()
    params = {"model_node", "allocation_node", "bench_node", "sim_bench_node", "steer_node", "two_dof_pair",
              "regulator_node", "scale_node"}
    assert {p.stem for p in (share / "config").glob("*.yaml")} == params | {"ladder_envelope"}  # `--params-file`
    assert (share / "config" / "designs" / "implemented_5mm.yaml").is_file()
    assert (prefix / "share/ament_index/resource_index/packages/softcath_ros").is_file()
    assert (prefix / "lib" / "softcath_ros" / "model_node").is_file()  # `ros2 run softcath_ros model_node`
    _check(_probe(site, tmp_path), site, data_root=share)
