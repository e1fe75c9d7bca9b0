"""CDR encoding of messages given as plain mappings, without rclpy (the manual bench and import).

The encoder is built from the same complete ``ros2msg`` definition the writer stores as the
schema (msg_definitions.full_definition), by mcap_ros2's dynamic serializer; fields left out
take their defaults. The bytes are what rclpy's serialize_message gives for the same values
(test/test_manual_bench.py checks it).
"""
from __future__ import annotations

import functools

from .msg_definitions import full_definition


@functools.lru_cache(maxsize=None)
def _encoder(type_name: str):
    # mcap_ros2 (0.6) offers CDR encoding only inside its Writer (write_message into an MCAP stream);
    # serialize_dynamic is the function that Writer itself calls, and there is no public equivalent.
    from mcap_ros2._dynamic import serialize_dynamic

    return serialize_dynamic(type_name, full_definition(type_name))[type_name]


def encode(type_name: str, message: dict) -> bytes:
    """``message`` (nested mappings, field name -> value) as CDR bytes of ``type_name``."""
    return _encoder(type_name)(message)


def stamp(time_ns: int) -> dict:
    """builtin_interfaces/Time of a time in ns since the epoch."""
    sec, nanosec = divmod(int(time_ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}
