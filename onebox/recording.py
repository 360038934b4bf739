"""Reading and writing onebox's MCAP recordings, shared by record, snapshot, replay, info and view.

A recording has one channel a key (the key as it travelled, namespace included), message
encoding ``msgpack`` and schema encoding ``jsonschema``: the schema is the msgspec JSON schema
of the key's type and its name the type's name (``onebox.sensor.Image``), so a reader with only
the ``mcap`` library can decode and check every message. A key with no known type is still
recorded, on a channel with no schema (schema id 0, as the MCAP spec allows).

Message bytes are written exactly as they travelled. The log time is when a message arrived
(wall clock, ns since the Unix epoch); the publish time its header stamp (simulated ns), or
``Clock.clock_ns`` for ``clock``, or the first transform's stamp for a TFMessage, or the log
time when a message has none of these (the MCAP spec's rule).

Reading is strict by default: a missing, empty, non-MCAP or truncated file raises
:class:`RecordingError` naming the file. ``recover=True`` reads every complete chunk of a
truncated file (a recorder killed with SIGKILL), in file order, which for onebox's recorder is
log-time order.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import msgspec
from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from onebox.errors import RecordingError
from onebox.keys import TF_STATIC, TYPES, type_for_key
from schemas import Message, codec, json_schema, type_name

log = logging.getLogger("recording")

MAGIC = b"\x89MCAP0\r\n"
MESSAGE_ENCODING = "msgpack"
SCHEMA_ENCODING = "jsonschema"
PROFILE = "onebox"
METADATA_NAME = "onebox"
"""The metadata record that holds the simulated time a recording spans (header stamps)."""
COMPRESSIONS: dict[str, CompressionType] = {
    "none": CompressionType.NONE,
    "lz4": CompressionType.LZ4,
    "zstd": CompressionType.ZSTD,
}

MAX_TIME_NS = 2**64 - 1
"""MCAP stores times as unsigned 64-bit nanoseconds."""

TYPES_BY_NAME: dict[str, type[Message]] = {type_name(t): t for t in TYPES.values()}
"""Every pipeline type by the schema name a recording stores for it."""


@dataclass(frozen=True, slots=True)
class Recorded:
    """One recorded message: its key as it travelled, its times and its bytes."""

    key: str
    log_time_ns: int
    """When it arrived at the recorder, ns since the Unix epoch."""
    publish_time_ns: int
    """Its header stamp, simulated ns (the log time when it has none)."""
    payload: bytes
    schema_name: str = ""
    """The type the file names for this key (``onebox.sensor.Image``), empty when none."""


@dataclass
class KeyInfo:
    """What one channel of a recording holds."""

    key: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    count: int = 0


@dataclass
class RecordingInfo:
    """The summary of a recording, as ``onebox info`` prints it."""

    path: Path
    size_bytes: int
    complete: bool
    """False for a truncated file read with ``recover=True``."""
    message_count: int
    start_ns: int
    end_ns: int
    chunk_count: int
    compression: str
    library: str
    keys: list[KeyInfo] = field(default_factory=list)
    sim_start_ns: int | None = None
    """The earliest header stamp of the messages that tell when the recording ran (see
    :func:`sim_stamp`); None when no message has one."""
    sim_end_ns: int | None = None
    damaged_chunks: int = 0
    """Chunks skipped because their checksum or compression did not hold (``recover``)."""

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9 if self.message_count else 0.0


# --- stamps -------------------------------------------------------------------------------------


class _Stamp(msgspec.Struct):
    stamp_ns: int = 0


class _Stamped(msgspec.Struct):
    """Only the fields that carry a message's time; msgpack skips everything else cheaply."""

    header: _Stamp | None = None
    clock_ns: int | None = None
    transforms: list[_Stamped] | None = None


_STAMP_DECODER = msgspec.msgpack.Decoder(_Stamped)


def stamp_ns(payload: bytes | memoryview) -> int | None:
    """The simulated time a payload describes, without decoding its pictures; None if none."""
    try:
        stamped = _STAMP_DECODER.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None
    if stamped.header is not None:
        return stamped.header.stamp_ns
    if stamped.clock_ns is not None:
        return stamped.clock_ns
    if stamped.transforms and stamped.transforms[0].header is not None:
        return stamped.transforms[0].header.stamp_ns
    return None


def sim_stamp(key: str, payload: bytes | memoryview) -> int | None:
    """The stamp a message adds to the simulated time a recording spans, or None.

    A latched key (``tf_static``, published once and handed to every late joiner) and an
    unstamped message (stamp 0, as static transforms are written) say nothing about when the
    recording ran: counted, one tf_static stamped 0 made an 11.5 s recording span 209.6 s.
    """
    if key == TF_STATIC or key.endswith(f"/{TF_STATIC}"):
        return None
    stamp = stamp_ns(payload)
    return stamp if stamp is not None and 0 < stamp <= MAX_TIME_NS else None


def has_header(message_type: type[Message] | None) -> bool:
    """Whether a type's publish time is a header stamp (simulated time)."""
    return message_type is not None and "header" in message_type.__struct_fields__


# --- writing ------------------------------------------------------------------------------------


class _WriteThrough:
    """A file the MCAP writer writes straight to the OS, without a buffer in this process.

    The writer emits a whole chunk (and its message index) per write, so what it has written
    is in the kernel's page cache at once and survives SIGKILL; only the chunk being built in
    memory is lost.
    """

    def __init__(self, fd: int) -> None:
        self._fd = fd
        self._position = 0
        self.failed: OSError | None = None
        """The error that stopped writing (a full disk); ``tell()`` is then where whole
        records end, since the writer hands over whole records in each call."""

    def write(self, data: bytes | bytearray | memoryview) -> int:
        if self.failed is not None:
            raise self.failed
        view = memoryview(data)
        try:
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
        except OSError as e:
            self.failed = e
            raise
        self._position += len(data)
        return len(data)

    def close_after_failure(self) -> bool:
        """Cut the file back to its last whole record and end it with an empty summary, so
        that it reads back without ``--recover``; False when not even that fits."""
        builder = RecordBuilder()
        DataEnd(data_section_crc=0).write(builder)
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
        tail = builder.end() + MAGIC  # type: ignore[no-untyped-call]  # mcap leaves it unannotated
        try:
            os.ftruncate(self._fd, self._position)
            os.lseek(self._fd, self._position, os.SEEK_SET)
            view = memoryview(tail)
            while view:
                view = view[os.write(self._fd, view) :]
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self._position)
            return False
        return True

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        """Nothing is buffered here."""

    def close(self) -> None:
        os.close(self._fd)


def open_new(path: Path, *, overwrite: bool) -> int:
    """Open ``path`` for writing; refuse, naming it, when it exists and ``overwrite`` is off."""
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
    try:
        return os.open(path, flags, 0o644)
    except FileExistsError:
        raise RecordingError(
            f"{path} already exists: delete it, choose another name, or pass --overwrite"
        ) from None
    except OSError as e:
        raise RecordingError(f"cannot create {path}: {e.strerror}") from e


class RecordingWriter:
    """Writes messages into a new MCAP file, one channel a key; use it in a ``with`` block.

    ``add`` is not thread-safe: one thread writes (the recorder hands messages to its writer
    thread through a queue). Chunks close when they reach ``chunk_size_bytes`` or when
    :meth:`flush` is called, whichever is first.
    """

    def __init__(
        self,
        path: Path,
        *,
        namespace: str = "",
        compression: str = "none",
        chunk_size_bytes: int = 4 * 1024 * 1024,
        overwrite: bool = False,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise RecordingError(
                f"unknown compression {compression!r}: choose one of {', '.join(COMPRESSIONS)}"
            )
        self.path = path
        self.namespace = namespace
        self._stream = _WriteThrough(open_new(path, overwrite=overwrite))
        self._writer = Writer(
            self._stream,  # type: ignore[arg-type]  # a file-like object is all it needs
            chunk_size=chunk_size_bytes,
            compression=COMPRESSIONS[compression],
            enable_data_crcs=True,
        )
        self._writer.start(profile=PROFILE, library="onebox")
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sequence = 0
        self._finished = False
        self.message_count = 0
        self.byte_count = 0
        self.sim_start_ns: int | None = None
        self.sim_end_ns: int | None = None
        self.out_of_range: dict[str, int] = {}
        """Messages per key whose times MCAP could not hold, recorded with the nearest it can."""

    def channel(self, key: str) -> int:
        """The channel of ``key``, registered with its type's schema the first time."""
        channel_id = self._channels.get(key)
        if channel_id is not None:
            return channel_id
        message_type = type_for_key(key, self.namespace)
        schema_id = 0
        if message_type is not None:
            name = type_name(message_type)
            schema_id = self._schemas.get(name, 0)
            if not schema_id:
                schema_id = self._writer.register_schema(
                    name=name, encoding=SCHEMA_ENCODING, data=json_schema(message_type)
                )
                self._schemas[name] = schema_id
        channel_id = self._writer.register_channel(
            topic=key, message_encoding=MESSAGE_ENCODING, schema_id=schema_id
        )
        self._channels[key] = channel_id
        return channel_id

    def add(
        self, key: str, payload: bytes, log_time_ns: int, publish_time_ns: int | None = None
    ) -> None:
        """Write one message; ``publish_time_ns`` defaults to the payload's stamp."""
        if publish_time_ns is None:
            stamp = stamp_ns(payload)
            publish_time_ns = log_time_ns if stamp is None else stamp
            counted = sim_stamp(key, payload)
            if counted is not None:
                start, end = self.sim_start_ns, self.sim_end_ns
                self.sim_start_ns = counted if start is None else min(start, counted)
                self.sim_end_ns = counted if end is None else max(end, counted)
        log_time_ns = self._in_range(key, "log", log_time_ns)
        publish_time_ns = self._in_range(key, "publish", publish_time_ns)
        self._sequence += 1
        self._writer.add_message(
            channel_id=self.channel(key),
            log_time=log_time_ns,
            data=payload,
            publish_time=publish_time_ns,
            sequence=self._sequence & 0xFFFFFFFF,
        )
        self.message_count += 1
        self.byte_count += len(payload)

    def _in_range(self, key: str, which: str, time_ns: int) -> int:
        """``time_ns`` held to what MCAP can store (0 to 2^64 - 1); said once per key."""
        if 0 <= time_ns <= MAX_TIME_NS:
            return time_ns
        held = min(max(time_ns, 0), MAX_TIME_NS)
        self.out_of_range[key] = self.out_of_range.get(key, 0) + 1
        if self.out_of_range[key] == 1:
            log.warning(
                "%s: a %s time of %d ns is outside what MCAP can store (0 to 2^64 - 1 ns); "
                "recorded with %d instead (said once per key; the bytes are unchanged)",
                key,
                which,
                time_ns,
                held,
            )
        return held

    def flush(self) -> None:
        """Close the chunk being built and hand it to the OS, so a SIGKILL cannot lose it."""
        self._writer.flush()  # type: ignore[no-untyped-call]  # mcap leaves it unannotated

    def finish(self) -> None:
        """Write the last chunk, the indexes and the summary, and close the file."""
        if self._finished:
            return
        self._finished = True
        try:
            if self._stream.failed is None:
                try:
                    if self.sim_start_ns is not None and self.sim_end_ns is not None:
                        self._writer.add_metadata(
                            METADATA_NAME,
                            {
                                "sim_start_ns": str(self.sim_start_ns),
                                "sim_end_ns": str(self.sim_end_ns),
                            },
                        )
                    self._writer.finish()  # type: ignore[no-untyped-call]
                    return
                except OSError:
                    pass  # the stream noted it; the file is closed by hand below
            failed = self._stream.failed
            closed = self._stream.close_after_failure()
        finally:
            self._stream.close()
        how = (
            "it is closed after the last whole chunk and reads back as it is"
            if closed
            else "it ends at the last whole chunk: read it with --recover"
        )
        reason = failed.strerror if failed is not None and failed.strerror else str(failed)
        raise RecordingError(f"cannot write {self.path}: {reason}; {how}")

    @property
    def failed(self) -> OSError | None:
        """The error that stopped writing the file (a full disk), if one did."""
        return self._stream.failed

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.finish()


# --- reading ------------------------------------------------------------------------------------


def _check_file(path: Path) -> bool:
    """Raise for a file that cannot be a recording; return whether it ends complete."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except OSError as e:
        raise RecordingError(f"{path}: {e.strerror}") from e
    if path.is_dir():
        raise RecordingError(f"{path} is a directory, not an MCAP file")
    if size == 0:
        raise RecordingError(f"{path} is empty, not an MCAP recording")
    try:
        with path.open("rb") as f:
            head = f.read(len(MAGIC))
            f.seek(max(0, size - len(MAGIC)))
            tail = f.read(len(MAGIC))
    except OSError as e:
        raise RecordingError(f"{path}: {e.strerror}") from e
    if head != MAGIC:
        raise RecordingError(f"{path} is not an MCAP file (it does not start with MCAP's magic)")
    return size >= 2 * len(MAGIC) + 1 and tail == MAGIC


def _truncated(path: Path) -> RecordingError:
    return RecordingError(
        f"{path} is truncated (no summary at its end: was the recorder killed, or the copy "
        "cut short?); pass --recover to read its complete chunks"
    )


def _damaged(path: Path, where: str, error: BaseException) -> RecordingError:
    return RecordingError(
        f"{path} is damaged ({where}: {type(error).__name__}: {_short(error)}); "
        "pass --recover to read what is intact"
    )


def _short(error: BaseException) -> str:
    text = str(error).splitlines()[0] if str(error) else ""
    return text[:200]


@dataclass
class ReadReport:
    """What a pass over a recording found besides its records."""

    damaged_chunks: int = 0
    """Chunks whose checksum or compression did not hold; skipped with ``recover``."""
    stopped_at: int | None = None
    """The offset where the records stopped making sense (a cut or damaged file), if they did."""
    complete: bool = False
    """Whether the pass reached the data section's end (a file not cut short)."""
    chunks: int = 0
    """Chunks read whole."""
    compressions: set[str] = field(default_factory=set)

    def say(self, path: Path) -> None:
        """Log, once, what a recovered read could not use."""
        if self.damaged_chunks:
            log.warning(
                "%s: skipped %d damaged chunk%s (checksum or compression did not hold)",
                path,
                self.damaged_chunks,
                "" if self.damaged_chunks == 1 else "s",
            )
        if self.stopped_at is not None:
            log.warning(
                "%s: read up to byte %d; the rest is cut short or damaged", path, self.stopped_at
            )


# A damaged file can make mcap's record parsers and the decompressors raise almost anything
# (struct.error, ValueError, OverflowError, zstandard.ZstdError, lz4's RuntimeError, ...):
# every one of them means "this part of the file is not what it says", so each is caught at
# the one place a record is read and turned into a RecordingError or a skipped chunk.
_READ_ERRORS = (Exception,)


def _records(path: Path, recover: bool, report: ReadReport) -> Iterator[Any]:
    """Every record of the data section in file order, chunks broken up, checksums checked.

    Strict (``recover`` off), the first damage raises RecordingError. With ``recover`` a chunk
    whose checksum or compression fails is skipped and counted, and a record that cannot be
    framed ends the pass; ``report`` says what happened.
    """
    try:
        f = path.open("rb")
    except OSError as e:
        raise RecordingError(f"{path}: {e.strerror}") from e
    with f:
        reader = StreamReader(f, emit_chunks=True, validate_crcs=True)
        records = reader.records
        while True:
            offset = f.tell()
            try:
                record = next(records)
            except StopIteration:
                return
            except _READ_ERRORS as e:
                if isinstance(e, CRCValidationError) and isinstance(e.record, DataEnd):
                    # Something in the data section (a chunk's header, an index) was changed.
                    if not recover:
                        raise _damaged(path, "the data section's checksum", e) from e
                    report.complete = True
                    return
                if not recover:
                    if isinstance(e, (EndOfFile, EOFError)):
                        raise _truncated(path) from e
                    raise _damaged(path, f"a record near byte {offset}", e) from e
                report.stopped_at = offset
                return
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except _READ_ERRORS as e:
                    if not recover:
                        raise _damaged(path, f"the chunk near byte {offset}", e) from e
                    report.damaged_chunks += 1
                    continue
                report.chunks += 1
                report.compressions.add(record.compression or "none")
                yield from inner
            elif isinstance(record, DataEnd):
                report.complete = True
                yield record
                return
            else:
                yield record


def _messages(path: Path, keys: set[str] | None, recover: bool) -> Iterator[Recorded]:
    """The messages of one pass, in file order (log-time order for onebox's recorder)."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    report = ReadReport()
    for record in _records(path, recover, report):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, McapMessage):
            channel = channels.get(record.channel_id)
            if channel is None or (keys is not None and channel.topic not in keys):
                continue
            schema = schemas.get(channel.schema_id)
            yield Recorded(
                key=channel.topic,
                log_time_ns=record.log_time,
                publish_time_ns=record.publish_time,
                payload=record.data,
                schema_name=schema.name if schema else "",
            )
    if recover:
        report.say(path)


def iter_messages(
    path: Path | str, keys: list[str] | None = None, *, recover: bool = False
) -> Iterator[Recorded]:
    """Every message of a recording (only ``keys``, if given), in file order, which for
    onebox's recorder is log-time order. Every chunk's checksum is checked.

    Raises :class:`RecordingError` naming the file when it is missing, empty, not MCAP or
    truncated at once, and when it is damaged as soon as that is found. With ``recover`` a
    truncated file gives its complete chunks and a damaged chunk is skipped; how many were
    skipped is logged at the end.
    """
    path = Path(path)
    complete = _check_file(path)
    if not complete and not recover:
        raise _truncated(path)
    return _messages(path, set(keys) if keys is not None else None, recover)


def read_capture(
    path: Path | str, namespace: str = "", *, recover: bool = False
) -> dict[str, Message]:
    """The last message on each key, decoded with the schemas' types.

    Keys are as recorded, less ``namespace``. A key whose type the schemas do not know is
    left out; a message that does not decode as its type raises :class:`RecordingError`.
    """
    last: dict[str, Recorded] = {}
    for recorded in iter_messages(path, recover=recover):
        last[recorded.key] = recorded
    prefix = f"{namespace.strip('/')}/" if namespace else ""
    capture: dict[str, Message] = {}
    for key, recorded in last.items():
        message_type = TYPES_BY_NAME.get(recorded.schema_name) or type_for_key(key, namespace)
        if message_type is None:
            log.info("%s: %s has no known type; left out", path, key)
            continue
        try:
            capture[key.removeprefix(prefix)] = codec(message_type).decode(recorded.payload)
        except (msgspec.DecodeError, msgspec.ValidationError) as e:
            raise RecordingError(
                f"{path}: the message on {key} is not a {type_name(message_type)}: {e}"
            ) from e
    return capture


def describe(path: Path | str, *, recover: bool = False) -> RecordingInfo:
    """What a recording holds, counted by reading it through with every checksum checked.

    Reading the whole file (rather than trusting its summary) is what lets ``info`` refuse a
    file whose messages were changed after it was written.
    """
    path = Path(path)
    complete = _check_file(path)
    if not complete and not recover:
        raise _truncated(path)
    size = path.stat().st_size
    schemas: dict[int, Schema] = {}
    keys: dict[int, KeyInfo] = {}
    info = RecordingInfo(path, size, False, 0, 0, 0, 0, "", "")
    report = ReadReport()
    for record in _records(path, recover, report):
        if isinstance(record, Header):
            info.library = record.library
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            schema = schemas.get(record.schema_id)
            keys[record.id] = KeyInfo(
                record.topic,
                schema.name if schema else "",
                schema.encoding if schema else "",
                record.message_encoding,
            )
        elif isinstance(record, McapMessage) and record.channel_id in keys:
            keys[record.channel_id].count += 1
            if info.message_count == 0:
                info.start_ns = info.end_ns = record.log_time
            info.start_ns = min(info.start_ns, record.log_time)
            info.end_ns = max(info.end_ns, record.log_time)
            info.message_count += 1
            # From the messages, not the file's metadata: files recorded before latched and
            # unstamped messages were left out of it still print the true span.
            stamp = sim_stamp(keys[record.channel_id].key, record.data)
            if stamp is not None:
                start, end = info.sim_start_ns, info.sim_end_ns
                info.sim_start_ns = stamp if start is None else min(start, stamp)
                info.sim_end_ns = stamp if end is None else max(end, stamp)
    info.complete = complete and report.complete and report.stopped_at is None
    info.damaged_chunks = report.damaged_chunks
    info.chunk_count = report.chunks
    info.compression = ", ".join(sorted(report.compressions)) or "none"
    info.keys = sorted(keys.values(), key=lambda k: k.key)
    if recover:
        report.say(path)
    return info


# --- a queue between a Zenoh callback and a writer thread ---------------------------------------


class ByteBudgetQueue:
    """A FIFO of (key, log_time_ns, payload) that holds at most ``budget_bytes`` of payloads.

    The Zenoh callback puts and never blocks or touches the disk; the writer thread gets. The
    log time is taken under the queue's lock, so queue order is log-time order and the file is
    written in log-time order. The budget covers what is queued and what the writer has taken
    but not yet :meth:`release`d; when the writer falls that far behind, new messages are
    dropped and counted per key rather than growing memory without bound.
    """

    def __init__(self, budget_bytes: int) -> None:
        self._items: list[tuple[str, int, bytes]] = []
        self._bytes = 0
        self._budget_bytes = budget_bytes
        self._ready = threading.Condition()
        self._closed = False
        self.dropped: dict[str, int] = {}

    def put(self, key: str, payload: bytes) -> bool:
        """Queue ``payload`` stamped with the time now; False (and counted) when over budget
        or closed."""
        with self._ready:
            if self._closed or (self._bytes + len(payload) > self._budget_bytes and self._bytes):
                self.dropped[key] = self.dropped.get(key, 0) + 1
                return False
            self._items.append((key, time.time_ns(), payload))
            self._bytes += len(payload)
            self._ready.notify()
            return True

    def get_all(self, timeout_s: float) -> list[tuple[str, int, bytes]]:
        """Everything queued, oldest first; empty when nothing came within ``timeout_s``."""
        with self._ready:
            if not self._ready.wait_for(lambda: bool(self._items), timeout=timeout_s):
                return []
            items, self._items = self._items, []
            return items

    def close(self) -> None:
        """Take nothing more and let go of what is queued (the writer stopped for good)."""
        with self._ready:
            self._closed = True
            self._items = []
            self._bytes = 0

    def release(self, nbytes: int) -> None:
        """The writer has written ``nbytes`` of what it took; make room for that much."""
        with self._ready:
            self._bytes -= nbytes

    def __len__(self) -> int:
        with self._ready:
            return len(self._items)


def output_problem(source: Path, destination: Path, *, overwrite: bool) -> str | None:
    """Why ``destination`` may not be written from ``source`` (a line that says what to do),
    or None when it may."""
    if destination.exists() and destination.resolve() == source.resolve():
        return f"{destination} is the input: choose another name for the output"
    if destination.exists() and not overwrite:
        return f"{destination} already exists: delete it, choose another name, or pass --overwrite"
    if destination.is_dir():
        return f"{destination} is a folder: give a file name ending in .mcap"
    return None


@contextlib.contextmanager
def written_whole(destination: Path) -> Iterator[Path]:
    """A hidden file beside ``destination`` to write: renamed onto it when the block ends,
    removed when the block raises, so a failure never leaves a partial file under the name
    asked for."""
    partial = destination.with_name(f".{destination.name}.{os.getpid()}.partial")
    try:
        yield partial
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()
        raise
    os.replace(partial, destination)


def counted(counts: Mapping[str, int]) -> str:
    """``a (3), b (1)``: names with their counts, sorted by name, for a one-line summary."""
    return ", ".join(f"{name} ({n})" for name, n in sorted(counts.items()))


class Progress:
    """Prints ``VERB: 1200 of 5000 messages (24 %)`` at most every ``interval_s``."""

    def __init__(self, verb: str, interval_s: float = 2.0) -> None:
        self._verb = verb
        self._interval_s = interval_s
        self._last = time.monotonic()

    def __call__(self, done: int, total: int) -> None:
        now = time.monotonic()
        if now - self._last < self._interval_s:
            return
        self._last = now
        share = f" ({100 * done / total:.0f} %)" if total else ""
        print(f"{self._verb}: {done} of {total} messages{share}", flush=True)
