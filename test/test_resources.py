"""softcath_ros.resources: shipped names per kind, a user's file before a shipped name, and a
one-line refusal that lists what is shipped."""
import pytest

from softcath_ros.core.design import load_design
from softcath_ros.core.errors import DesignError
from softcath_ros.resources import ResourceNotFound, envelope_path, find, shipped_dir, shipped_names


def test_shipped_names_per_kind():
    assert {"implemented_5mm", "three_channel_5mm"} <= set(shipped_names("design"))
    assert "free_bending_live" in shipped_names("scene") and "quick" in shipped_names("protocol")
    assert shipped_names("params") == ["allocation_node", "bench_node", "model_node", "regulator_node", "scale_node",
                                      "sim_bench_node", "steer_node", "two_dof_pair"]
    assert shipped_names("envelope") == ["ladder_envelope"] and find("envelope", "ladder_envelope") == envelope_path()
    assert isinstance(shipped_names("surrogate_table"), list)   # none shipped yet: still a kind
    with pytest.raises(ValueError, match="unknown resource kind 'designs'"):
        shipped_dir("designs")


def test_a_name_with_or_without_suffix_and_a_users_file(tmp_path, monkeypatch):
    shipped = find("design", "implemented_5mm")
    assert shipped.is_file() and find("design", "implemented_5mm.yaml") == shipped
    mine = tmp_path / "implemented_5mm.yaml"
    mine.write_text(shipped.read_text())
    assert find("design", str(mine)) == mine
    monkeypatch.chdir(tmp_path)          # a file of that name in the working folder is the user's
    assert find("design", "implemented_5mm.yaml").resolve() == mine


def test_not_found_is_one_line_listing_the_shipped_names(tmp_path):
    with pytest.raises(ResourceNotFound) as exc:
        find("scene", "free_bending_dead")
    msg = str(exc.value)
    assert "\n" not in msg and "free_bending_live" in msg and msg.startswith("scene 'free_bending_dead'")
    # a path with a folder part is the user's: never replaced by the shipped file of that name
    with pytest.raises(ResourceNotFound):
        find("design", str(tmp_path / "implemented_5mm.yaml"))
    with pytest.raises(ResourceNotFound, match="params 'ladder_envelope'"):
        find("params", "ladder_envelope")
    with pytest.raises(DesignError, match="implemented_5mm") as exc:
        load_design("implemented_6mm")
    assert "\n" not in str(exc.value)


def test_ros_package_layout():
    """The layout a ROS package has: package.xml, setup.py, the Python package, config/, test/ and
    README.md at the top; the finder reads config/ from a checkout; the params files' usage lines
    name paths that exist from the repository root."""
    import re
    from pathlib import Path

    from softcath_ros.resources import config_dir

    root = Path(__file__).resolve().parents[1]
    for name in ("package.xml", "setup.py", "softcath_ros", "config", "test", "README.md"):
        assert (root / name).exists(), name
    assert not (root / "softcath_ros" / "config").exists()
    assert config_dir() == root / "config"
    for params in (root / "config").glob("*.yaml"):
        for path in re.findall(r"--params-file ([\w./-]+\w)", params.read_text()):
            assert (root / path).is_file(), (params.name, path)
