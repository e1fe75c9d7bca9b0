"""Preallocated, fixed-layout CDR buffers for the pose messages a node publishes at kHz rates.

rclpy converts a Python message to C field by field (a PoseArray of 20 poses is ~150
attribute reads) before serialising it; a publisher also accepts the serialised bytes.
For messages whose size never changes (fixed frame_id, fixed number of poses) the byte
layout is fixed too, so we keep one buffer and write only the stamp and the doubles
through numpy views. The layout is plain CDR (XCDR1, little endian, the encoding ROS 2
uses); test/test_model_node.py checks it byte for byte against rclpy.serialization.
"""
from __future__ import annotations

import struct
import sys

import numpy as np

CDR_LE_HEADER = b"\x00\x01\x00\x00"   # encapsulation: plain CDR, little endian
HOST_IS_LITTLE_ENDIAN = sys.byteorder == "little"


def _align(offset: int, n: int) -> int:
    return (offset + n - 1) // n * n


class _StampedBuffer:
    """A serialised message whose header stamp (its first field) is rewritten in place."""

    def __init__(self, data: bytearray):
        self._buf = data
        self.stamp = np.frombuffer(self._buf, dtype="<u4", count=2, offset=len(CDR_LE_HEADER))

    def set_stamp(self, stamp_ns: int) -> None:
        self.stamp[0], self.stamp[1] = divmod(stamp_ns, 1_000_000_000)

    def to_bytes(self) -> bytes:
        return bytes(self._buf)


class _PoseBuffer(_StampedBuffer):
    """Header + ``n`` poses; ``sequence``: poses are a sequence (PoseArray) or one field (PoseStamped)."""

    def __init__(self, frame_id: str, n: int, sequence: bool):
        body = bytearray(8)  # builtin_interfaces/Time: int32 sec, uint32 nanosec (filled per message)
        fid = frame_id.encode() + b"\0"
        body += struct.pack("<I", len(fid)) + fid
        if sequence:
            body += b"\0" * (_align(len(body), 4) - len(body)) + struct.pack("<I", n)
        body += b"\0" * (_align(len(body), 8) - len(body))  # CDR aligns relative to the body start
        data_offset = len(CDR_LE_HEADER) + len(body)
        super().__init__(bytearray(CDR_LE_HEADER + body + bytes(56 * n)))
        self.poses = np.frombuffer(self._buf, dtype="<f8", count=7 * n, offset=data_offset).reshape(n, 7)


class PoseArrayBuffer(_PoseBuffer):
    """geometry_msgs/PoseArray with ``n`` poses; rows of ``poses`` are (x, y, z, qx, qy, qz, qw)."""

    def __init__(self, frame_id: str, n: int):
        super().__init__(frame_id, n, sequence=True)


class PoseStampedBuffer(_PoseBuffer):
    """geometry_msgs/PoseStamped; ``poses`` has one row (x, y, z, qx, qy, qz, qw)."""

    def __init__(self, frame_id: str):
        super().__init__(frame_id, 1, sequence=False)


class MessageTemplate(_StampedBuffer):
    """A message of fixed layout, serialised once (by rclpy), whose stamp and numeric arrays are then
    rewritten in place through numpy views: for messages too big to build field by field at
    display rate (a Marker's triangle list). Fields are located by sentinel values put into the
    template before serialising (``find``); the header must be the message's first field."""

    def __init__(self, data: bytes):
        if data[:4] != CDR_LE_HEADER:
            raise ValueError("template is not little-endian plain CDR")
        super().__init__(bytearray(data))

    def find(self, sentinel: bytes, start: int = 0, end: int | None = None) -> int:
        """Offset of the one occurrence of ``sentinel`` in ``[start, end)`` of the message (CDR's
        alignment padding is not written by the serialiser: a short sentinel is looked for next to
        the field it belongs with, and long enough not to be met in stray bytes)."""
        end = len(self._buf) if end is None else end
        i = self._buf.find(sentinel, start, end)
        if i < 0 or self._buf.find(sentinel, i + 1, end) >= 0:
            raise ValueError(f"sentinel {sentinel.hex()} found {'no' if i < 0 else 'more than one'} time(s)")
        return i

    def view(self, offset: int, dtype: str, shape) -> np.ndarray:
        count = int(np.prod(shape))
        return np.frombuffer(self._buf, dtype=dtype, count=count, offset=offset).reshape(shape)
