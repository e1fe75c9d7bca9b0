"""Recording to MCAP as rosbag2's MCAP storage plugin writes it (pure Python, no rclpy).

The writer takes already-serialized CDR bytes plus the topic's type name and the
QoS its publishers offer; the ROS adapter (bench_node) does the serializing.
"""
from .qos import OfferedQos, adapt_request_to_offers, qos_profiles_yaml
from .bag_metadata import TopicInfo
from .writer import BagWriter, RecordingError, check_destination

__all__ = ["BagWriter", "OfferedQos", "RecordingError", "TopicInfo", "adapt_request_to_offers", "check_destination",
           "qos_profiles_yaml"]
