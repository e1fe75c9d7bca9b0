"""Rebuild a truncated recording (recorder killed, power lost), keeping every complete message.

The recorder writes self-contained chunks (schemas and channels travel in the chunk
that first uses them), so a file cut anywhere holds a readable prefix: every record
before the cut. This reads that prefix record by record, keeps each chunk whose
length and CRC check out (a torn last chunk is dropped), and writes a complete file
with summary, statistics and a fresh ``rosbag2`` metadata record. That record keeps the
recording's ``custom_data`` (protocol, design, simulated): from the old ``rosbag2`` record when
the file still has one, else from the ``softcath`` metadata record the bench writes at the start.

Recovered in place, the damaged original is kept outside the bag folder (``ros2 bag`` reads
every ``.mcap`` listed in, or found in, the folder): ``<bag>.damaged/<name>.mcap`` beside the bag
folder; a file that is not in a bag folder keeps it beside itself as ``<name>.mcap.truncated``.
"""
from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from ..core.errors import SoftcathError
from . import bag_metadata as bm
from .bag_metadata import TopicInfo
from .qos import parse_qos_yaml


@dataclass
class RecoveryReport:
    source: str
    output: str
    messages: int = 0
    chunks: int = 0
    dropped_chunks: int = 0
    was_complete: bool = False
    stop_reason: str = ""
    per_topic: dict[str, int] = field(default_factory=dict)
    last_log_time_ns: int = 0
    custom_data: dict[str, str] = field(default_factory=dict)
    damaged_original: str = ""       # where the damaged file was kept (in-place recovery)

    def to_json(self) -> dict:
        return dict(self.__dict__)


def _records(path: Path, report: RecoveryReport):
    """Every readable record of the file's prefix, chunks opened; stops at the first torn record."""
    with open(path, "rb") as f:
        reader = StreamReader(f, emit_chunks=True, record_size_limit=None)
        it = reader.records
        while True:
            try:
                record = next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - any parse failure marks the torn end
                report.stop_reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                return
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as exc:  # noqa: BLE001 - a corrupt chunk is skipped, not fatal
                    report.dropped_chunks += 1
                    report.stop_reason = f"chunk dropped: {exc}"
                    continue
                report.chunks += 1
                yield from inner
            else:
                yield record
            if isinstance(record, (DataEnd, Footer)):
                report.was_complete = True
                return


# custom_data keys taken from the bench's ``softcath`` metadata record when no rosbag2 record survived.
CUSTOM_KEYS = ("protocol", "design", "simulated")


def in_bag_folder(path: Path) -> bool:
    """Whether ``path`` is the recording of a bag folder (``<bag>/<bag>_0.mcap``)."""
    return path.name == f"{path.parent.name}_0.mcap"


def damaged_copy_path(src: Path) -> Path:
    """Where in-place recovery keeps the damaged original (module docstring)."""
    if in_bag_folder(src):
        return src.parent.parent / f"{src.parent.name}.damaged" / src.name
    return src.with_name(src.name + ".truncated")


def _custom_data_of(rosbag2_record: dict) -> dict[str, str]:
    from ..core.yaml_io import load_yaml

    try:
        node = load_yaml(rosbag2_record.get("serialized_metadata", ""), "rosbag2 metadata record")
    except SoftcathError:
        return {}
    custom = node.get("custom_data") if isinstance(node, dict) else None
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def _offered_qos(text: str):
    """The channel's offered QoS, or none when a damaged file holds something else there."""
    try:
        return parse_qos_yaml(text)
    except SoftcathError:
        return []


def recover(source, output=None) -> RecoveryReport:
    """Write the recoverable content of ``source`` to ``output`` (default: in place, the damaged
    original kept where ``damaged_copy_path`` says). Returns what was kept."""
    src = Path(source)
    in_place = output is None
    dst = _target(src, output)
    report = RecoveryReport(source=str(src), output=str(src if in_place else dst))
    schemas: dict[int, int] = {}       # old id -> new id
    channels: dict[int, int] = {}
    topics: dict[int, TopicInfo] = {}
    schema_names: dict[int, str] = {}
    t_min, t_max = None, 0
    custom: dict[str, str] = {}        # from the softcath record
    old_custom: dict[str, str] = {}    # from a surviving rosbag2 record (wins)
    header_ok = False
    with open(dst, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        for rec in _records(src, report):
            if isinstance(rec, Header):
                writer.start(profile=rec.profile, library=rec.library)
                header_ok = True
            elif not header_ok:
                break
            elif isinstance(rec, Schema):
                if rec.id not in schemas:
                    schemas[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
                    schema_names[rec.id] = rec.name
            elif isinstance(rec, Channel):
                if rec.id not in channels and (rec.schema_id in schemas or rec.schema_id == 0):
                    channels[rec.id] = writer.register_channel(
                        rec.topic, rec.message_encoding, schemas.get(rec.schema_id, 0), dict(rec.metadata))
                    topics[rec.id] = TopicInfo(
                        name=rec.topic, type=schema_names.get(rec.schema_id, ""),
                        offered_qos=_offered_qos(rec.metadata.get("offered_qos_profiles", "")),
                        type_hash=rec.metadata.get("topic_type_hash", ""),
                        serialization_format=rec.message_encoding)
            elif isinstance(rec, Message):
                if rec.channel_id not in channels:
                    continue
                writer.add_message(channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time,
                                   rec.sequence)
                topics[rec.channel_id].message_count += 1
                report.messages += 1
                t_min = rec.log_time if t_min is None else min(t_min, rec.log_time)
                t_max = max(t_max, rec.log_time)
            elif isinstance(rec, Metadata):
                if rec.name == "rosbag2":
                    old_custom = _custom_data_of(rec.metadata)
                    continue  # rebuilt below from what was actually kept
                writer.add_metadata(rec.name, dict(rec.metadata))
                if rec.name == "softcath":
                    custom.update({k: v for k, v in rec.metadata.items() if k in CUSTOM_KEYS})
            elif isinstance(rec, Attachment):
                writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
        if not header_ok:
            out.close()
            dst.unlink(missing_ok=True)
            raise SoftcathError(f"{src}: not an MCAP file or its header is damaged; nothing to recover")
        start = t_min or 0
        relative = src.name
        report.custom_data = {**custom, **old_custom}
        node = bm.bag_metadata(list(topics.values()), relative, start, t_max - start, report.messages,
                               report.custom_data)
        writer.add_metadata("rosbag2", {"serialized_metadata": bm.dump(node)})
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    report.per_topic = {t.name: t.message_count for t in topics.values()}
    report.last_log_time_ns = t_max
    if in_place:
        report.damaged_original = str(_replace_damaged(src, dst, node))
    return report


def _target(src: Path, output) -> Path:
    """Where the recovered file is written: beside ``src`` when in place (``output`` None)."""
    if not src.is_file():
        raise SoftcathError(f"{src}: no such file")
    if output is None:
        return src.with_suffix(".recovering.mcap")
    dst = Path(output)
    if not dst.parent.is_dir():
        raise SoftcathError(f"--output {dst}: folder {dst.parent} does not exist")
    if dst.exists() and dst.resolve() == src.resolve():
        raise SoftcathError(f"--output {dst}: is the damaged file itself; leave --output out to recover in place")
    return dst


def _replace_damaged(src: Path, dst: Path, node) -> Path:
    """The recovered ``dst`` takes the place of ``src``, whose damaged copy is kept (returned); a bag
    folder's metadata.yaml is rewritten from ``node``."""
    backup = damaged_copy_path(src)
    backup.parent.mkdir(exist_ok=True)
    if backup.exists():   # an earlier recovery's damaged copy: keep both
        backup = backup.with_name(f"{backup.name}.{time.strftime('%Y%m%d_%H%M%S')}")
    shutil.move(src, backup)
    os.replace(dst, src)
    if in_bag_folder(src):
        (src.parent / "metadata.yaml").write_text(bm.metadata_yaml(node))
    return backup
