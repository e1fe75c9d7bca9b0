"""What a measured number depends on: the machine, its load, the interpreter, the package
versions and the code version. Recorded with every benchmark result and with the ladder rows
`softcath envelope` writes, because these machines are shared and noisy. No ROS import."""
from __future__ import annotations

import os
import platform
import subprocess
import time
from importlib import metadata
from pathlib import Path

from .resources import checkout_root

# distributions whose versions move the numbers (absent ones are left out)
PACKAGES = ("softcath_ros", "numpy", "scipy", "matplotlib", "qdldl", "ngsolve", "ros-rclpy", "mcap")


def package_versions() -> dict:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def git_commit() -> str:
    """The checkout's commit (with ``+dirty`` when it has uncommitted changes), or "unknown"
    outside a source checkout."""
    root = checkout_root()
    if root is None:
        return "unknown"
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (head + ("+dirty" if dirty else "")) if head else "unknown"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_meta(load_before: tuple | None = None) -> dict:
    """Interpreter, package versions, CPU, the load average before (when given) and now (after),
    code version and date."""
    return {"python": platform.python_version(), "packages": package_versions(), "machine": platform.machine(),
            "cpu": cpu_model(), "cpu_count": os.cpu_count(),
            "load_average_before": list(load_before) if load_before is not None else None,
            "load_average_after": list(os.getloadavg()), "git_commit": git_commit(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}


__all__ = ["PACKAGES", "cpu_model", "git_commit", "machine_meta", "package_versions"]
