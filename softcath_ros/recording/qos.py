"""QoS as rosbag2 records it, and its rule for choosing a subscription QoS (pure Python).

``offered_qos_profiles`` in a channel's metadata is the YAML that rosbag2's
``serialize_rclcpp_qos_vector`` (metadata version 9) emits: a sequence of mappings
with policy names as strings and durations as {sec, nsec}.
"""
from __future__ import annotations

from dataclasses import dataclass

import yaml

# RMW_DURATION_INFINITE as rosbag2 writes it.
INFINITE_NS = 9223372036854775807


@dataclass(frozen=True)
class OfferedQos:
    """One publisher's offered QoS. Policy names are rmw's strings ('reliable', 'volatile', ...)."""

    history: str = "unknown"
    depth: int = 0
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = INFINITE_NS
    lifespan_ns: int = INFINITE_NS
    liveliness: str = "automatic"
    liveliness_lease_duration_ns: int = INFINITE_NS
    avoid_ros_namespace_conventions: bool = False

    def to_yaml_node(self) -> dict:
        return {
            "history": self.history,
            "depth": int(self.depth),
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": _duration(self.deadline_ns),
            "lifespan": _duration(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": _duration(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": bool(self.avoid_ros_namespace_conventions),
        }


def _duration(ns: int) -> dict:
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def qos_profiles_yaml(profiles: list[OfferedQos]) -> str:
    """The ``offered_qos_profiles`` string of a channel (empty list -> '[]')."""
    return yaml.safe_dump([p.to_yaml_node() for p in profiles], sort_keys=False,
                          default_flow_style=False)


def adapt_request_to_offers(offers: list[OfferedQos]) -> tuple[str, str, list[str]]:
    """rosbag2's Rosbag2QoS::adapt_request_to_offers: (reliability, durability, warnings).

    Reliable only if every publisher offers reliable, transient_local only if every one
    does; otherwise fall back to what connects to all of them, and say what that costs.
    """
    if not offers:
        return "reliable", "volatile", []
    warnings = []
    n_rel = sum(o.reliability == "reliable" for o in offers)
    n_tl = sum(o.durability == "transient_local" for o in offers)
    reliability = "reliable" if n_rel == len(offers) else "best_effort"
    if 0 < n_rel < len(offers):
        warnings.append("some, but not all, publishers offer reliable: subscribing best_effort, "
                        "messages from reliable publishers may be dropped")
    durability = "transient_local" if n_tl == len(offers) else "volatile"
    if 0 < n_tl < len(offers):
        warnings.append("some, but not all, publishers offer transient_local: subscribing volatile, "
                        "latched messages published before the recorder started are not recorded")
    return reliability, durability, warnings


def parse_qos_yaml(text: str) -> list[OfferedQos]:
    """Inverse of ``qos_profiles_yaml`` (tolerates an empty string, as rosbag2 does)."""
    from ..core.errors import SoftcathError
    from ..core.yaml_io import load_yaml

    if not text or not text.strip():
        return []
    nodes = load_yaml(text, "offered_qos_profiles") or []

    def ns(d):
        return int(d["sec"]) * 1_000_000_000 + int(d["nsec"])

    try:
        return _profiles(nodes, ns)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise SoftcathError(f"offered_qos_profiles: not a list of QoS profiles ({type(exc).__name__}: {exc})") from None


def _profiles(nodes, ns) -> list[OfferedQos]:
    return [OfferedQos(history=str(n["history"]), depth=int(n["depth"]), reliability=str(n["reliability"]),
                       durability=str(n["durability"]), deadline_ns=ns(n["deadline"]),
                       lifespan_ns=ns(n["lifespan"]), liveliness=str(n["liveliness"]),
                       liveliness_lease_duration_ns=ns(n["liveliness_lease_duration"]),
                       avoid_ros_namespace_conventions=bool(n["avoid_ros_namespace_conventions"]))
            for n in nodes]
