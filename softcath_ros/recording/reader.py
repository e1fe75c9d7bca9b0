"""Reading recordings back: decoded messages, metadata records and attachments."""
from __future__ import annotations

from pathlib import Path
from typing import Iterator, NamedTuple

from mcap.reader import make_reader

from ..core.errors import SoftcathError


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
            raise SoftcathError(f"{p}: no .mcap file in this directory")
        p = files[0]
    if not p.is_file():
        raise SoftcathError(f"{p}: no such recording")
    return p


def recording_file(path) -> Path:
    """The .mcap file of a recording given as the file or its bag directory."""
    return _open(path)


def iter_messages(path, topics: list[str] | None = None) -> Iterator[RecordedMessage]:
    from mcap_ros2.decoder import DecoderFactory

    p = _open(path)
    with open(p, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        try:
            for _schema, channel, message, decoded in reader.iter_decoded_messages(topics=topics,
                                                                                   log_time_order=True):
                yield RecordedMessage(channel.topic, message.log_time, message.publish_time, decoded)
        except Exception as exc:  # noqa: BLE001 - torn or foreign files: say what to do
            raise SoftcathError(f"{p}: cannot read messages ({type(exc).__name__}: {exc}); "
                                f"if the recorder was killed, run `softcath recover {p}` first") from None


def read_metadata(path) -> dict[str, dict[str, str]]:
    p = _open(path)
    with open(p, "rb") as f:
        reader = make_reader(f)
        try:
            return {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        except Exception as exc:  # noqa: BLE001
            raise SoftcathError(f"{p}: cannot read metadata ({exc}); try `softcath recover {p}`") from None


def read_attachments(path) -> dict[str, bytes]:
    p = _open(path)
    with open(p, "rb") as f:
        return {a.name: a.data for a in make_reader(f).iter_attachments()}


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
        raise SoftcathError(f"{p}: cannot read its topics (not an MCAP recording, or cut before its first chunk)")
    return out
