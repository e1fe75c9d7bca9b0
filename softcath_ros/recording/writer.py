"""BagWriter: a rosbag2-compatible MCAP recording (one bag directory, one .mcap file).

Layout as ``ros2 bag record -s mcap`` makes it: ``DIR/`` with ``DIR_0.mcap`` and
``metadata.yaml``. Inside the file: profile ``ros2``; one schema per type (encoding
``ros2msg``, the complete definition); one channel per topic (encoding ``cdr``,
metadata ``offered_qos_profiles`` and ``topic_type_hash``); messages with log time
(reception) and publish time; zstd chunks; on close the ``rosbag2`` metadata record
(key ``serialized_metadata``) and the summary.

No data lost: the open chunk is closed and written (and fsynced) at least every
``flush_period_s`` and whenever ``flush()`` is called (the bench calls it at each
step end), so a killed recorder loses at most the last period; ``recover`` rebuilds
the rest. An unwritable path or a nearly full disk fails in the constructor; a disk that fills
up later fails the write (or flush, or close) with a RecordingError that says "disk full", and
``abandon()`` then lets go of the file as it is: everything flushed before is recoverable.

``background=True`` moves the writing to a writer thread: ``write`` only appends to a
queue (a SimpleQueue put, about a microsecond), so the DDS callbacks that call it
never wait for chunk compression or fsync; ``flush`` and ``close`` first drain the
queue, so order and the flush guarantees are the same as in the synchronous mode. A
write that fails in the thread is counted in ``write_failures`` (``error`` says why);
beyond ``max_queued`` messages waiting, new ones are refused and counted there too.
"""
from __future__ import annotations

import errno
import os
import queue
import shutil
import threading
import time
from pathlib import Path

from mcap.writer import CompressionType, Writer

from ..core.errors import SoftcathError
from . import bag_metadata as bm
from .bag_metadata import TopicInfo
from .msg_definitions import full_definition, type_description_hash
from .qos import OfferedQos, qos_profiles_yaml

_STOP = object()   # queued by close/abandon: the writer thread ends there

LIBRARY = "softcath_ros recorder (python mcap)"


class RecordingError(SoftcathError):
    pass


def _write_failed(path, exc: OSError) -> RecordingError:
    """One line for a failed write; ENOSPC/EDQUOT say "disk full" (what the user must fix)."""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return RecordingError(f"disk full writing {path} ({exc.strerror or exc})")
    return RecordingError(f"writing {path} failed: {exc.strerror or exc}")


_EXISTS = "recording directory {} already exists; choose a new name (recordings are never overwritten)"


def check_destination(bag_dir: Path) -> None:
    """RecordingError (one line) if no recording can be made at ``bag_dir``: it exists, or the folder
    it goes in cannot be made. Creates that folder, not ``bag_dir`` (bench_node checks before it
    waits for a rig; the writer again when it makes ``bag_dir``)."""
    bag_dir = Path(bag_dir)
    if bag_dir.exists():
        raise RecordingError(_EXISTS.format(bag_dir))
    try:
        bag_dir.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecordingError(f"cannot create recording directory {bag_dir}: {exc.strerror or exc}") from None


class BagWriter:
    def __init__(self, bag_dir, *, compression: str = "zstd", chunk_size: int = 1 << 20,
                 flush_period_s: float = 1.0, fsync: bool = True, min_free_bytes: int = 64 << 20,
                 custom_data: dict[str, str] | None = None, distro: str | None = None,
                 background: bool = False, max_queued: int = 2_000_000):
        self.bag_dir = Path(bag_dir)
        self.path = self.bag_dir / f"{self.bag_dir.name}_0.mcap"
        self.flush_period_s = float(flush_period_s)
        self.fsync = fsync
        self.custom_data = dict(custom_data or {})
        self.distro = distro or bm.ros_distro()
        self.topics: dict[str, TopicInfo] = {}
        self._channel_ids: dict[str, int] = {}
        self._schema_ids: dict[str, int] = {}
        self._lock = threading.Lock()
        self._closed = False
        self.message_count = 0
        self._t_min: int | None = None
        self._t_max = 0
        self._check_destination(min_free_bytes)
        try:
            self._file = open(self.path, "xb")
        except OSError as exc:
            raise RecordingError(f"cannot create recording {self.path}: {exc.strerror or exc}") from None
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in comp:
            raise RecordingError(f"compression {compression!r}: expected one of {sorted(comp)}")
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=comp[compression])
        self._writer.start(profile="ros2", library=LIBRARY)
        self._sync()
        self._last_flush = time.monotonic()
        self.write_failures = 0
        self.error: str | None = None
        self._queue: queue.SimpleQueue | None = None
        if background:
            self._queue = queue.SimpleQueue()
            self._max_queued = int(max_queued)
            self._thread = threading.Thread(target=self._drain_loop, name="bag-writer", daemon=True)
            self._thread.start()

    def _check_destination(self, min_free_bytes: int) -> None:
        check_destination(self.bag_dir)
        try:
            self.bag_dir.mkdir(exist_ok=False)
        except FileExistsError:    # made since the check
            raise RecordingError(_EXISTS.format(self.bag_dir)) from None
        except OSError as exc:
            raise RecordingError(f"cannot create recording directory {self.bag_dir}: "
                                 f"{exc.strerror or exc}") from None
        if not os.access(self.bag_dir, os.W_OK):
            raise RecordingError(f"recording directory {self.bag_dir} is not writable")
        free = shutil.disk_usage(self.bag_dir).free
        if free < min_free_bytes:
            raise RecordingError(f"only {free / 2**20:.1f} MiB free at {self.bag_dir}; the recorder "
                                 f"needs at least {min_free_bytes / 2**20:.0f} MiB")

    # ------------------------------------------------------------------ topics and messages
    def add_topic(self, name: str, type_name: str, offered_qos: list[OfferedQos] | None = None,
                  type_hash: str | None = None) -> None:
        """Declare a topic before writing to it (schema and channel as rosbag2's create_topic)."""
        with self._lock:
            if name in self.topics:
                return
            if type_name not in self._schema_ids:
                try:
                    text = full_definition(type_name)
                except SoftcathError as exc:
                    raise RecordingError(f"topic {name}: {exc}") from None
                self._schema_ids[type_name] = self._writer.register_schema(
                    name=type_name, encoding="ros2msg", data=text.encode())
            info = TopicInfo(name=name, type=type_name, offered_qos=list(offered_qos or []),
                             type_hash=type_hash if type_hash is not None else type_description_hash(type_name))
            self._channel_ids[name] = self._writer.register_channel(
                topic=name, message_encoding="cdr", schema_id=self._schema_ids[type_name],
                metadata={"offered_qos_profiles": qos_profiles_yaml(info.offered_qos),
                          "topic_type_hash": info.type_hash})
            self.topics[name] = info

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """One serialized (CDR) message. ``log_time_ns``: reception time; publish time defaults to it.

        In background mode the message is queued and errors surface in ``write_failures``/``error``."""
        q = self._queue
        if q is not None:
            if q.qsize() >= self._max_queued or self._closed:
                self.write_failures += 1
                self.error = self.error or (f"recording {self.path} is closed" if self._closed else
                                            f"writer queue full ({self._max_queued} messages waiting)")
                return
            if topic not in self._channel_ids:
                raise RecordingError(f"topic {topic} was not added to the recording")
            q.put((topic, data, log_time_ns, publish_time_ns))
            return
        self._write_now(topic, data, log_time_ns, publish_time_ns)

    def _write_now(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None) -> None:
        with self._lock:
            if self._closed:
                raise RecordingError(f"recording {self.path} is closed")
            try:
                channel = self._channel_ids[topic]
            except KeyError:
                raise RecordingError(f"topic {topic} was not added to the recording") from None
            try:
                self._writer.add_message(channel_id=channel, log_time=log_time_ns, data=data,
                                         publish_time=log_time_ns if publish_time_ns is None else publish_time_ns)
            except OSError as exc:
                raise _write_failed(self.path, exc) from None
            self.topics[topic].message_count += 1
            self.message_count += 1
            self._t_min = log_time_ns if self._t_min is None else min(self._t_min, log_time_ns)
            self._t_max = max(self._t_max, log_time_ns)
            if time.monotonic() - self._last_flush >= self.flush_period_s:
                self._flush_locked()

    # ------------------------------------------------------------------ writer thread
    def _drain_loop(self) -> None:
        """Writes queued messages; sleeps on the queue until a message comes or the open chunk's
        flush is due (no polling); ends at the stop marker that ``close``/``abandon`` queue."""
        q = self._queue
        while True:
            due = self.flush_period_s - (time.monotonic() - self._last_flush)
            try:
                item = q.get(timeout=max(due, 0.001))
            except queue.Empty:
                try:
                    self.flush_if_due()
                except RecordingError as exc:
                    self.error = str(exc)
                continue
            if item is _STOP:
                return
            if item[0] is None:  # a flush/close barrier: everything before it is written
                item[1].set()
                continue
            try:
                self._write_now(*item)
            except RecordingError as exc:
                self.write_failures += 1
                self.error = str(exc)

    def _drain(self) -> None:
        """Wait until the writer thread has written everything queued so far."""
        if self._queue is None or not self._thread.is_alive():
            return
        done = threading.Event()
        self._queue.put((None, done))
        done.wait()

    @property
    def queued(self) -> int:
        """Messages waiting for the writer thread (0 in synchronous mode)."""
        return 0 if self._queue is None else self._queue.qsize()

    def flush_if_due(self) -> None:
        """Call periodically (timer): closes the open chunk once it is older than the flush period."""
        with self._lock:
            if not self._closed and time.monotonic() - self._last_flush >= self.flush_period_s:
                self._flush_locked()

    def flush(self) -> None:
        """Close the open chunk and push it to disk now (step ends), after every queued message."""
        self._drain()
        with self._lock:
            if not self._closed:
                self._flush_locked()

    def _flush_locked(self) -> None:
        try:
            self._writer.flush()
            self._sync()
        except OSError as exc:
            raise _write_failed(self.path, exc) from None
        self._last_flush = time.monotonic()

    def _sync(self) -> None:
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    # ------------------------------------------------------------------ metadata and attachments
    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        with self._lock:
            try:
                self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            except OSError as exc:
                raise _write_failed(self.path, exc) from None

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time_ns: int | None = None) -> None:
        now = time.time_ns() if log_time_ns is None else log_time_ns
        with self._lock:
            try:
                self._writer.add_attachment(create_time=now, log_time=now, name=name, media_type=media_type,
                                            data=data)
            except OSError as exc:
                raise _write_failed(self.path, exc) from None

    # ------------------------------------------------------------------ closing
    def bag_metadata(self) -> dict:
        start = self._t_min or 0
        return bm.bag_metadata(list(self.topics.values()), self.path.name, start, self._t_max - start,
                               self.message_count, self.custom_data, self.distro)

    def close(self) -> None:
        """Write the rosbag2 metadata record and the summary; idempotent. RecordingError ("disk
        full") if that cannot be written: call ``abandon()`` then."""
        if self._queue is not None and not self._closed:
            self._drain()
            self._queue.put(_STOP)
            self._thread.join()
            while not self._queue.empty():  # a write that raced the stop
                item = self._queue.get_nowait()
                if item is _STOP:
                    continue
                if item[0] is None:
                    item[1].set()
                else:
                    self._write_now(*item)
        with self._lock:
            if self._closed:
                return
            self._closed = True
            node = self.bag_metadata()
            try:
                self._writer.add_metadata("rosbag2", {"serialized_metadata": bm.dump(node)})
                self._writer.finish()
                self._sync()
                self._file.close()
                (self.bag_dir / "metadata.yaml").write_text(bm.metadata_yaml(node))
            except OSError as exc:
                raise _write_failed(self.path, exc) from None

    def abandon(self) -> None:
        """After a failed close: stop the writer thread and let go of the file as it is (torn at
        the end; `softcath recover` rebuilds what was flushed). Never raises."""
        self._closed = True
        if self._queue is not None and self._thread.is_alive():
            self._queue.put(_STOP)
            self._thread.join(timeout=5.0)
        try:
            self._file.close()
        except OSError:
            pass  # the buffered tail cannot be written: the disk is full

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
