"""The one finder for data shipped with the package: designs, scenes, protocols, node parameter
files, the ladder envelope and surrogate tables.

The data live in the repository's top-level ``config/`` folder, as a ROS package keeps them, and are
installed to ``<prefix>/share/softcath_ros/config`` (setup.py ``data_files``: pip wheel, pip
``--target``/``--user``, colcon). The finder looks in the source checkout first, then in the
``share`` folder of the prefix the package is installed under, then in every ``AMENT_PREFIX_PATH``
entry (a sourced ROS workspace). No ROS import.
"""
from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from .errors import SoftcathError

ENVELOPE_NAME = "ladder_envelope"
PACKAGE = "softcath_ros"
# kind -> (folder under config/, "" = the folder itself; file suffix)
KINDS = {
    "design": ("designs", ".yaml"),
    "scene": ("scenes", ".yaml"),
    "protocol": ("protocols", ".yaml"),
    "params": ("", ".yaml"),
    "envelope": ("", ".yaml"),
    "surrogate_table": ("surrogate_tables", ".npz"),
}


class ResourceNotFound(SoftcathError):
    """Neither a file nor the name of a shipped resource of that kind."""

    def __init__(self, kind: str, name: str, known: list[str]):
        self.kind, self.name, self.known = kind, name, known
        super().__init__(f"{kind} '{name}': no such file or shipped {kind}; shipped: {', '.join(known) or 'none'}")


def _package_dir() -> Path:
    return Path(str(resources.files(PACKAGE))).resolve()


def config_candidates() -> list[Path]:
    """Where the shipped data may be, in the order they are searched."""
    package = _package_dir()
    found = [package.parent / "config"] if (package.parent / "package.xml").is_file() else []  # checkout
    # an install prefix: <prefix>/lib/python3.X/site-packages/softcath_ros, or pip --target's <dir>/softcath_ros
    found += [a / "share" / PACKAGE / "config" for a in list(package.parents)[:4]]
    found += [Path(p) / "share" / PACKAGE / "config" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
              if p]
    return found


def config_dir() -> Path:
    """The shipped data folder: the first of ``config_candidates()`` that holds the designs."""
    candidates = config_candidates()
    for folder in candidates:
        if (folder / "designs").is_dir():
            return folder
    raise SoftcathError(f"{PACKAGE}: shipped data not found (looked in {', '.join(map(str, candidates))}); "
                        "reinstall the package")


def shipped_dir(kind: str) -> Path:
    if kind not in KINDS:
        raise ValueError(f"unknown resource kind '{kind}'; known: {', '.join(KINDS)}")
    folder = KINDS[kind][0]
    return config_dir() / folder if folder else config_dir()


def shipped_names(kind: str) -> list[str]:
    """Names of the shipped resources of ``kind`` (file stems), sorted."""
    folder, suffix = shipped_dir(kind), KINDS[kind][1]
    names = sorted(p.stem for p in folder.glob(f"*{suffix}")) if folder.is_dir() else []
    if kind == "envelope":   # params and the envelope share the top folder
        return [n for n in names if n == ENVELOPE_NAME]
    return [n for n in names if n != ENVELOPE_NAME] if kind == "params" else names


def find(kind: str, name_or_path: str | Path) -> Path:
    """A user's file as given when it exists, else the shipped resource of that name (a bare name,
    with or without its suffix); ``ResourceNotFound`` (one line, listing the shipped names)
    otherwise. A path with a folder part is never replaced by a shipped file of the same name."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    known = shipped_names(kind)
    suffix = KINDS[kind][1]
    stem = p.name[: -len(suffix)] if p.name.endswith(suffix) else p.name
    if len(p.parts) == 1 and stem in known:
        return shipped_dir(kind) / f"{stem}{suffix}"
    raise ResourceNotFound(kind, str(name_or_path), known)


def checkout_root() -> Path | None:
    """The repository folder when the package runs from a source checkout (the benchmark results
    live there, not in the package), else None."""
    root = _package_dir().parent
    return root if (root / "setup.py").is_file() and (root / "benchmarks").is_dir() else None


def envelope_path() -> Path:
    """The shipped ladder envelope (written by ``softcath envelope``) that model selection reads."""
    return shipped_dir("envelope") / f"{ENVELOPE_NAME}{KINDS['envelope'][1]}"


__all__ = ["ENVELOPE_NAME", "KINDS", "ResourceNotFound", "checkout_root", "config_dir", "envelope_path", "find",
           "shipped_dir", "shipped_names"]
