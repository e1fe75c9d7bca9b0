"""ament_python package, also pip-installable into a plain virtual environment.

The ROS 2 client libraries are an extra (`[ros]`) so that a sourced ROS
workspace, which already provides rclpy, does not get a second copy.
"""
from pathlib import Path

from setuptools import find_packages, setup

package_name = "softcath_ros"


def config_data_files():
    """Every file under config/ to share/softcath_ros/config/<same folder> (what ROS packages install
    and softcath_ros.resources finds by name)."""
    folders = {}
    for f in sorted(Path("config").rglob("*")):
        if f.is_file():
            folders.setdefault(str(Path("share", package_name) / f.parent), []).append(str(f))
    return sorted(folders.items())


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks"]),
    # Shipped data (designs, scenes, protocols, node parameters, the ladder envelope, surrogate
    # tables, the Foxglove layout) live in the top-level config/ and install to
    # share/softcath_ros/config, where softcath_ros.resources finds them by name from any route.
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "LICENSE"]),
        *config_data_files(),
    ],
    python_requires=">=3.10",
    install_requires=[
        "numpy>=1.24",
        "scipy>=1.10",
        "pyyaml>=6.0",
        "matplotlib>=3.7",
        "tqdm>=4.60",
        # Recording (rosbag2-compatible MCAP) and reading it back without ROS installed.
        "mcap>=1.6",
        "mcap-ros2-support>=0.6",
        "zstandard>=0.22",
        # Sparse LDL^T for the section rung's Newton steps (it falls back to SuperLU without it).
        "qdldl>=0.1.7",
        # The cross-section's outlines (core/geometry): validation, walls, polygons for meshers.
        "shapely>=2.1",
        # Hole outlines drawn in CAD (`shape: file`): DXF layers and SVG elements.
        "ezdxf>=1.1",
        "svgelements>=1.9",
        # The section rung's mesher (Shewchuk's Triangle: constrained Delaunay, numpy only).
        "triangle>=20230923",
    ],
    extras_require={
        "ros": [
            "ros-rclpy>=9.1",
            "ros-std-msgs>=5.5",
            "ros-geometry-msgs>=5.5",
            "ros-sensor-msgs>=5.5",   # the rig contract: FluidPressure (docs/rig.md)
            "ros-diagnostic-msgs>=5.5",
            # the live 3D view: body Marker and backbone Path (model_node)
            "ros-visualization-msgs>=5.5",
            "ros-nav-msgs>=5.5",
            "ros-rmw-fastrtps-cpp>=9.3",
            # managed (lifecycle) hardware nodes: tracker_node (rclpy.lifecycle needs its messages)
            "ros-lifecycle-msgs>=2.0",
        ],
        "test": ["pytest>=7.4", "pytest-timeout>=2.2", "pytest-xdist>=3.5", "psutil>=5.9", "mcap-ros2-support>=0.6",
                 "hypothesis>=6.80",
                 # test_install.py builds a wheel offline (no build isolation): bdist_wheel
                 "wheel>=0.40",
                 # the camera tracker's tests (the `vision` extra)
                 "opencv-python-headless>=4.8"],
        "bench": ["psutil>=5.9"],
        # regulator_node and scale_node on real devices: serial line protocols and Modbus TCP
        # (docs/lab.md), imported lazily by the serial and modbus backends.
        "hardware": ["pyserial>=3.5", "pymodbus>=3.6"],
        # `softcath track` and tracker_node: the camera measurement (OpenCV with ArUco, imported lazily).
        "vision": ["opencv-python-headless>=4.8"],
        # 3D finite-element rung (fe3d): NGSolve with the netgen mesher, imported lazily.
        "fe": ["ngsolve>=6.2.2404"],
        # `softcath study --scheduler ADDR`: run study cases on an existing Dask cluster (imported lazily).
        "cluster": ["dask[distributed]>=2023.1"],
    },
    zip_safe=False,  # the shipped data are read as files
    maintainer="softcath_ros developers",
    maintainer_email="softcath@example.org",
    description="Model, steering and bench nodes for a steerable soft fluidic catheter.",
    license="Apache-2.0",   # the text: LICENSE (package.xml says the same)
    license_files=["LICENSE"],
    entry_points={
        "console_scripts": [
            "softcath = softcath_ros.cli:main",
            "model_node = softcath_ros.nodes.model_node:main",
            "bench_node = softcath_ros.nodes.bench_node:main",
            "sim_bench_node = softcath_ros.nodes.sim_bench_node:main",
            "allocation_node = softcath_ros.nodes.allocation_node:main",
            "steer_node = softcath_ros.nodes.steer_node:main",
            "steer_driver = softcath_ros.nodes.steer_driver:main",
            "tracker_node = softcath_ros.nodes.tracker_node:main",
            "regulator_node = softcath_ros.nodes.regulator_node:main",
            "scale_node = softcath_ros.nodes.scale_node:main",
        ],
    },
)
