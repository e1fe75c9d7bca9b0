"""rosbag2's BagMetadata (version 9) as a mapping: the ``rosbag2`` metadata record and metadata.yaml.

Field names and nesting follow rosbag2_storage/yaml.hpp: times as
{nanoseconds_since_epoch}, durations as {nanoseconds}, per-topic QoS as a sequence.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata

import yaml

from .qos import OfferedQos

BAG_METADATA_VERSION = 9
# rclpy major version -> ROS 2 distribution (the PyPI wheels carry no ROS_DISTRO).
_RCLPY_DISTRO = {3: "humble", 7: "jazzy", 9: "kilted", 10: "rolling"}


def ros_distro() -> str:
    """ROS_DISTRO if set (a sourced workspace), else inferred from the installed rclpy."""
    if os.environ.get("ROS_DISTRO"):
        return os.environ["ROS_DISTRO"]
    for dist in ("ros-rclpy", "rclpy"):
        try:
            major = int(importlib_metadata.version(dist).split(".")[0])
        except (importlib_metadata.PackageNotFoundError, ValueError):
            continue
        return _RCLPY_DISTRO.get(major, "unknown")
    return "unknown"


@dataclass
class TopicInfo:
    """A recorded topic: rosbag2's TopicMetadata plus its message count."""

    name: str
    type: str                                   # e.g. "std_msgs/msg/Float64"
    offered_qos: list[OfferedQos] = field(default_factory=list)
    type_hash: str = ""                         # RIHS01_... or ''
    serialization_format: str = "cdr"
    message_count: int = 0


def bag_metadata(topics: list[TopicInfo], relative_file: str, starting_time_ns: int, duration_ns: int,
                 message_count: int, custom_data: dict[str, str] | None = None,
                 distro: str | None = None) -> dict:
    return {
        "version": BAG_METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": int(duration_ns)},
        "starting_time": {"nanoseconds_since_epoch": int(starting_time_ns)},
        "message_count": int(message_count),
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.name, "type": t.type,
                                "serialization_format": t.serialization_format,
                                "offered_qos_profiles": [q.to_yaml_node() for q in t.offered_qos],
                                "type_description_hash": t.type_hash},
             "message_count": int(t.message_count)} for t in topics],
        # rosbag2's own (per-message) compression; MCAP chunk compression is not it.
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [relative_file],
        "files": [{"path": relative_file,
                   "starting_time": {"nanoseconds_since_epoch": int(starting_time_ns)},
                   "duration": {"nanoseconds": int(duration_ns)},
                   "message_count": int(message_count)}],
        "custom_data": {str(k): str(v) for k, v in (custom_data or {}).items()},
        "ros_distro": distro or ros_distro(),
    }


def dump(node: dict) -> str:
    return yaml.safe_dump(node, sort_keys=False, default_flow_style=False)


def metadata_yaml(node: dict) -> str:
    """The bag directory's metadata.yaml, as ``ros2 bag info DIR`` reads it."""
    return dump({"rosbag2_bagfile_information": node})
