"""Reading recordings back: decoded messages, metadata records and attachments.

Whatever is wrong with a file (not MCAP, truncated, a record longer than the file, random
bytes, an unreadable path) comes out as one ``RecordingReadError`` line, never mcap's own
exceptions (InvalidMagic, RecordLengthLimitExceeded, EndOfFile, struct/zstd errors, ...).
"""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, NamedTuple

from mcap.reader import make_reader

from ..core.errors import SoftcathError

MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingReadError(SoftcathError):
    """A recording that cannot be read (not MCAP, damaged, unreadable)."""


class RecordedMessage(NamedTuple):
    topic: str
    log_time_ns: int
    publish_time_ns: int
    message: object  # decoded (mcap_ros2 dynamic type: attribute access like the ROS message)


def _open(path) -> Path:
    p = Path(path)
    if p.is_dir():
        files = sorted(p.glob("*.mcap"))
        if not files:
            raise RecordingReadError(f"{p}: no .mcap file in this directory")
        p = files[0]
    if not p.is_file():
        raise RecordingReadError(f"{p}: no such recording")
    return p


def recording_file(path) -> Path:
    """The .mcap file of a recording given as the file or its bag directory."""
    return _open(path)


@contextmanager
def _reader(path, what: str, **kwargs):
    """An mcap reader over ``path``; any failure while opening or reading is one line."""
    p = _open(path)
    try:
        with open(p, "rb") as f:
            if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                raise RecordingReadError(f"{p}: not an MCAP recording (no MCAP magic at its start)")
            f.seek(0)
            yield make_reader(f, **kwargs)
    except SoftcathError:
        raise
    except Exception as exc:  # noqa: BLE001 - torn or foreign files: say what to do
        detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise RecordingReadError(f"{p}: cannot read {what} ({detail.splitlines()[0]}); if the recorder was "
                                 f"killed, run `softcath recover {p}` first") from None


def iter_messages(path, topics: list[str] | None = None) -> Iterator[RecordedMessage]:
    from mcap_ros2.decoder import DecoderFactory

    with _reader(path, "messages", decoder_factories=[DecoderFactory()]) as reader:
        for _schema, channel, message, decoded in reader.iter_decoded_messages(topics=topics, log_time_order=True):
            yield RecordedMessage(channel.topic, message.log_time, message.publish_time, decoded)


def read_metadata(path) -> dict[str, dict[str, str]]:
    with _reader(path, "metadata") as reader:
        return {m.name: dict(m.metadata) for m in reader.iter_metadata()}


def read_attachments(path) -> dict[str, bytes]:
    with _reader(path, "attachments") as reader:
        return {a.name: a.data for a in reader.iter_attachments()}


def recording_topics(path) -> dict[str, str]:
    """Topic -> message type of every channel in the recording: from its summary, or for a torn
    file (no summary) from the readable prefix, as `recover` reads it."""
    from mcap.records import Channel, Schema

    from .recover import RecoveryReport, _records

    p = _open(path)
    try:
        with open(p, "rb") as f:
            summary = make_reader(f).get_summary()
        if summary is not None:
            return {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    except Exception:  # noqa: BLE001 - torn end or foreign file: scan the prefix below
        pass
    schemas, out = {}, {}
    for record in _records(p, RecoveryReport(str(p), "")):
        if isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, Channel):
            out[record.topic] = schemas.get(record.schema_id, "")
    if not out:
        raise RecordingReadError(f"{p}: cannot read its topics (not an MCAP recording, or cut before its first "
                                 f"chunk); if the recorder was killed, try `softcath recover {p}`")
    return out
