"""TopicRecorder: subscribes to topics as they appear and hands serialized messages to a BagWriter.

As rosbag2 does: a topic is subscribed once a publisher is seen; the subscription's
reliability and durability are adapted to what every publisher offers
(recording.qos.adapt_request_to_offers); the offered profiles and the type hash from
the graph go into the channel's metadata; messages arrive raw (CDR bytes, never
deserialized); log time is the reception time, publish time the source timestamp.
Messages the middleware reports lost, and writes that fail, are counted as dropped.

Speed (benchmarks/recorder_throughput.py): the node should spin on the EventsExecutor
(C++ dispatch; rclpy's wait-set executors cost ~100 us per message) and the writer run
in the background (BagWriter(background=True)) so callbacks never wait for compression
or fsync. The EventsExecutor does not pass MessageInfo (rclpy 9.1 fails on two-argument
callbacks), so with ``message_info=False`` log time is the clock read on entry to the
callback and publish time equals it; with ``message_info=True`` (wait-set executors)
they are the middleware's reception and source timestamps, as rosbag2 writes them.
Messages lost in the middleware are counted (message-lost events) only with
``message_info=True``: on the EventsExecutor of rclpy 9.1 taking that event can deadlock
(see the comment in ``poll``), so there ``lost`` stays 0 and ``counts_middleware_loss`` is
False; the subscription is reliable with a deep history so the middleware has no reason
to drop, and benchmarks/recorder_throughput.py measures loss by counting.
"""
from __future__ import annotations

import importlib
import time

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy)

from ..recording import BagWriter, OfferedQos, RecordingError, adapt_request_to_offers
from .diagnostics import ThrottledLog

_REL = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
_DUR = {"transient_local": DurabilityPolicy.TRANSIENT_LOCAL, "volatile": DurabilityPolicy.VOLATILE}


def offered_qos(profile) -> OfferedQos:
    """rclpy QoSProfile (from the graph) -> the recorder's OfferedQos."""
    def name(enum_cls, value):
        try:
            return enum_cls(value).name.lower()
        except ValueError:
            return "unknown"

    return OfferedQos(history=name(HistoryPolicy, profile.history), depth=int(profile.depth),
                      reliability=name(ReliabilityPolicy, profile.reliability),
                      durability=name(DurabilityPolicy, profile.durability),
                      deadline_ns=int(profile.deadline.nanoseconds), lifespan_ns=int(profile.lifespan.nanoseconds),
                      liveliness=name(LivelinessPolicy, profile.liveliness),
                      liveliness_lease_duration_ns=int(profile.liveliness_lease_duration.nanoseconds),
                      avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


def message_class(type_name: str):
    pkg, sub, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{sub}"), name)


class TopicRecorder:
    def __init__(self, node, writer: BagWriter, topics: list[str], *, depth: int = 10000, poll_period: float = 0.25,
                 message_info: bool = True):
        self.node = node
        self.writer = writer
        self.pending = list(dict.fromkeys(topics))
        self.subscriptions = {}
        self.received: dict[str, int] = {}
        self.lost = 0
        self.write_failures = 0
        self.depth = depth
        self.message_info = message_info
        self._error: str | None = None
        self._log = ThrottledLog(node.get_logger(), 5.0)
        self.poll()
        self._timer = node.create_timer(poll_period, self.poll)
        self._flush_timer = node.create_timer(0.2, self._flush_if_due)

    @property
    def counts_middleware_loss(self) -> bool:
        return self.message_info

    @property
    def dropped(self) -> int:
        return self.lost + self.write_failures + self.writer.write_failures

    @property
    def error(self) -> str | None:
        return self._error or self.writer.error

    @error.setter
    def error(self, value: str | None) -> None:
        self._error = value

    def poll(self) -> None:
        for topic in list(self.pending):
            infos = self.node.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            types = {i.topic_type for i in infos}
            if len(types) > 1:
                self._log.warning(topic, f"{topic}: publishers disagree on the type {sorted(types)}; not recorded")
                continue
            type_name = types.pop()
            offers = [offered_qos(i.qos_profile) for i in infos]
            reliability, durability, warnings = adapt_request_to_offers(offers)
            for w in warnings:
                self.node.get_logger().warning(f"{topic}: {w}")
            h = str(infos[0].topic_type_hash)
            try:
                self.writer.add_topic(topic, type_name, offers, h if h.startswith("RIHS01_") else None)
                cls = message_class(type_name)
            except (RecordingError, ImportError, AttributeError, ValueError) as exc:
                self.node.get_logger().error(f"{topic}: cannot record: {exc}")
                self.pending.remove(topic)
                continue
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.depth, reliability=_REL[reliability],
                             durability=_DUR[durability])
            self.received[topic] = 0
            # Loss events only on the wait-set executors: on rclpy 9.1's EventsExecutor, taking a
            # message-lost event while Fast DDS reports another deadlocks the process (seen at 40k msg/s).
            events = SubscriptionEventCallbacks(message_lost=self._on_lost) if self.message_info else None
            self.subscriptions[topic] = self.node.create_subscription(
                cls, topic, self._callback(topic), qos, raw=True, event_callbacks=events)
            self.pending.remove(topic)

    def _callback(self, topic: str):
        write = self.writer.write
        received = self.received
        now_ns = time.time_ns

        def on_message_info(data: bytes, info) -> None:
            t = info.get("received_timestamp") or now_ns()
            try:
                write(topic, data, t, info.get("source_timestamp") or t)
            except RecordingError as exc:
                self.write_failures += 1
                self.error = str(exc)
                return
            received[topic] += 1

        def on_message(data: bytes) -> None:
            t = now_ns()
            try:
                write(topic, data, t, t)
            except RecordingError as exc:
                self.write_failures += 1
                self.error = str(exc)
                return
            received[topic] += 1
        return on_message_info if self.message_info else on_message

    def _on_lost(self, status) -> None:
        self.lost += int(status.total_count_change)

    def _flush_if_due(self) -> None:
        try:
            self.writer.flush_if_due()
        except RecordingError as exc:
            self.error = str(exc)
