"""QoS profiles from node parameters, so every node spells them the same way."""
from __future__ import annotations

RELIABILITIES = ("reliable", "best_effort")


def stream_qos(depth: int, reliability: str = "reliable"):
    """Keep-last ``depth``, volatile; ``reliable`` so no command or pose is dropped silently."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    if reliability not in RELIABILITIES:
        raise ValueError(f"reliability {reliability!r} is not one of {RELIABILITIES}")
    if depth < 1:
        raise ValueError(f"qos_depth {depth}: must be at least 1")
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.RELIABLE if reliability == "reliable"
                                   else ReliabilityPolicy.BEST_EFFORT))
