"""The Foxglove layout (config/foxglove/softcath.json) against a recording."""
import json
from pathlib import Path

from mcap.reader import make_reader

from softcath_ros import topics
from softcath_ros.resources import config_dir

LAYOUT = config_dir() / "foxglove" / "softcath.json"
# Named by the layout but published only by a rig with a tip tracker (or the simulated rig that
# plays one): not in every recording.
ONLY_WITH_A_TRACKER = {topics.TIP_MEASURED}


def layout_topics(layout: dict | None = None) -> set[str]:
    """Every topic a panel of the layout names (3D topics, plot message paths)."""
    layout = layout or json.loads(LAYOUT.read_text())
    found = set()
    for panel_id, config in layout["configById"].items():
        if panel_id.startswith("3D!"):
            found.update(config["topics"])
        elif panel_id.startswith("Plot!"):
            found.update(p["value"].split(".")[0] for p in config["paths"])
    return found


def check_recording(recording) -> set[str]:
    """Assert that each topic the layout names is in ``recording`` with the type the suite gives it;
    returns the ones the recording lacks (only those allowed to be missing)."""
    with open(recording, "rb") as f:
        summary = make_reader(f).get_summary()
    recorded = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    missing = set()
    for topic in layout_topics():
        if topic not in recorded and topic in ONLY_WITH_A_TRACKER:
            missing.add(topic)
            continue
        assert topic in recorded, f"the layout names {topic}, the recording has no such topic"
        assert recorded[topic] == topics.message_type(topic), (topic, recorded[topic])
        assert counts.get(topic, 0) > 0, f"{topic} recorded without messages"
    return missing
