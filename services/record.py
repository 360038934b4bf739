"""Record keys into an MCAP file, as ``ros2 bag record`` did.

    onebox record OUT.mcap                       every key (``**`` under the namespace)
    onebox record OUT.mcap --keys 'camera/**' --keys tf_static
    onebox record OUT.mcap --compression none --duration 10

Reads: every key matching ``--keys`` (default ``**``), any type; ``tf_static`` and other latched
keys are asked for their last sample, so a recorder started late still records them.
Writes: OUT.mcap, one channel a key as it travelled (namespace included), message encoding
msgpack, schema encoding jsonschema with the key's msgspec JSON schema (a key onebox does not
know is recorded with no schema). The bytes written are the bytes that travelled; log time is
the arrival time (wall clock), publish time the header stamp (simulated time).

Chunks are compressed with zstd by default, as the MCAP C++ writer does (``--compression none``
or ``lz4`` to choose otherwise); every chunk carries its checksum.

The Zenoh callback only stamps and queues each message; a writer thread writes chunks straight
to the file and closes a chunk at least every ``--flush-interval-s``, so a ``kill -9`` loses at
most the chunk being built. Ctrl-C, SIGTERM and ``--duration`` finish the file with its summary.
If the disk falls more than ``--queue-mb`` behind, new messages are dropped and counted per key.
A message whose stamp MCAP cannot hold (below 0, say) is recorded with its time held to the
nearest MCAP can store, and said once per key. If the writer stops (a full disk), the recorder
says so in one line, closes the file after its last whole chunk so that it reads back, and
exits 2 at once.
Refuses to overwrite OUT.mcap unless ``--overwrite``. On a terminal, a progress line shows
messages and MB so far, per key.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import logging
import shutil
import signal
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import TextIO

import zenoh

from onebox import bus, memory, settings
from onebox.errors import RecordingError
from onebox.recording import COMPRESSIONS, ByteBudgetQueue, RecordingWriter

log = logging.getLogger("record")

MB = 1e6


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, metavar="OUT.mcap", help="the file to write")
    parser.add_argument(
        "--keys",
        action="append",
        metavar="EXPR",
        help="a key expression to record, repeatable (default ** : every key)",
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace OUT.mcap if it already exists"
    )
    settings.add(
        parser,
        "compression",
        "zstd",
        f"compress each chunk: {', '.join(COMPRESSIONS)} (zstd, as MCAP's C++ writer does)",
    )
    settings.add(parser, "chunk_size_mb", 4.0, "close a chunk once it holds this many MB")
    settings.add(
        parser,
        "flush_interval_s",
        1.0,
        "close the chunk being built at least this often, so a kill loses at most this much",
    )
    settings.add(
        parser, "queue_mb", 512.0, "how far (MB) the disk may fall behind before messages drop"
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after this many seconds (default: until Ctrl-C or SIGTERM)",
    )
    bus.add_arguments(parser)


def key_expressions(exprs: list[str] | None) -> list[str]:
    """The expressions to subscribe to, without any that another one already includes.

    Two overlapping subscriptions would deliver, and so record, the same sample twice.
    """
    unique = list(dict.fromkeys(exprs or ["**"]))
    kept: list[str] = []
    for expr in unique:
        try:
            ke = zenoh.KeyExpr(expr)
        except zenoh.ZError as e:
            raise RecordingError(f"--keys {expr!r} is not a Zenoh key expression: {e}") from e
        if any(zenoh.KeyExpr(other).includes(ke) for other in unique if other != expr):
            log.info("--keys %s is already included in another --keys; subscribed once", expr)
            continue
        kept.append(expr)
    return kept


class Progress:
    """Counts what was written, per key, and draws it as one line on a terminal."""

    def __init__(self, stream: TextIO, path: Path) -> None:
        self._stream = stream
        self._path = path
        self._tty = stream.isatty()
        self._start = time.monotonic()
        self._last_draw = 0.0
        self.messages: collections.Counter[str] = collections.Counter()
        self.bytes: collections.Counter[str] = collections.Counter()

    def add(self, key: str, nbytes: int) -> None:
        self.messages[key] += 1
        self.bytes[key] += nbytes

    def line(self, dropped: dict[str, int]) -> str:
        elapsed_s = time.monotonic() - self._start
        total_mb = sum(self.bytes.values()) / MB
        parts = [
            f"{key} {self.messages[key]}/{self.bytes[key] / MB:.1f}MB"
            for key in sorted(self.messages)
        ]
        drops = sum(dropped.values())
        dropped_text = f", {drops} dropped" if drops else ""
        return (
            f"{self._path}: {elapsed_s:.0f} s, {sum(self.messages.values())} messages, "
            f"{total_mb:.1f} MB{dropped_text} | " + "  ".join(parts)
        )

    def draw(self, dropped: dict[str, int], *, force: bool = False) -> None:
        now = time.monotonic()
        if not self._tty or (not force and now - self._last_draw < 0.5):
            return
        self._last_draw = now
        # Cut to the terminal's width: a wrapped line would not be redrawn in place.
        columns = shutil.get_terminal_size().columns
        self._stream.write("\r\x1b[K" + self.line(dropped)[: max(columns - 1, 20)])
        self._stream.flush()

    def end(self) -> None:
        if self._tty:
            self._stream.write("\n")
            self._stream.flush()


class Recorder:
    """Takes samples from Zenoh callbacks and writes them from its own thread."""

    def __init__(self, writer: RecordingWriter, queue_bytes: int, flush_interval_s: float) -> None:
        self.writer = writer
        self.queue = ByteBudgetQueue(queue_bytes)
        self.progress = Progress(sys.stderr, writer.path)
        self._flush_interval_s = flush_interval_s
        self._stop = threading.Event()
        self.failed: BaseException | None = None
        """Why the writer thread stopped early, if it did."""
        self._thread = threading.Thread(target=self._run, name="mcap-writer", daemon=True)

    def on_sample(self, key: str, payload: bytes) -> None:
        """The Zenoh callback: stamp and queue, nothing else."""
        self.queue.put(key, payload)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        last_flush = time.monotonic()
        try:
            while True:
                stopping = self._stop.is_set()
                items = self.queue.get_all(timeout_s=0.1)
                for key, log_time_ns, payload in items:
                    self.writer.add(key, payload, log_time_ns)
                    self.progress.add(key, len(payload))
                self.queue.release(sum(len(p) for _, _, p in items))
                if time.monotonic() - last_flush >= self._flush_interval_s:
                    self.writer.flush()
                    memory.trim()
                    last_flush = time.monotonic()
                if stopping and not items:
                    return
        except BaseException as e:  # any end of the writer must end the recorder
            self.failed = e
            self.queue.close()  # nothing more is queued: memory cannot grow while we stop

    @property
    def running(self) -> bool:
        return self.failed is None

    def stop(self) -> None:
        """Write everything still queued, then return (the caller finishes the file)."""
        self._stop.set()
        self._thread.join()


@contextlib.contextmanager
def finishing(path: Path) -> Iterator[None]:
    """While the file is finished, a second Ctrl-C or SIGTERM waits instead of cutting it short."""

    def _wait(signum: int, frame: FrameType | None) -> None:
        log.warning("finishing %s; it is complete in a moment", path)

    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    on_main_thread = threading.current_thread() is threading.main_thread()
    if on_main_thread:
        for sig in previous:
            signal.signal(sig, _wait)
    try:
        yield
    finally:
        if on_main_thread:
            for sig, handler in previous.items():
                signal.signal(sig, handler)


@dataclass(frozen=True)
class RecordSettings:
    """What ``onebox record`` was asked to do, checked."""

    out: Path
    exprs: list[str]
    overwrite: bool
    compression: str
    chunk_size_bytes: int
    flush_interval_s: float
    queue_bytes: int
    duration_s: float | None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RecordSettings:
        if args.chunk_size_mb <= 0 or args.flush_interval_s <= 0 or args.queue_mb <= 0:
            raise RecordingError(
                "--chunk-size-mb, --flush-interval-s and --queue-mb must be more than 0"
            )
        if args.compression not in COMPRESSIONS:
            raise RecordingError(
                f"--compression {args.compression!r}: choose one of {', '.join(COMPRESSIONS)}"
            )
        if args.duration is not None and args.duration <= 0:
            raise RecordingError(f"--duration {args.duration}: must be more than 0 seconds")
        return cls(
            out=args.out,
            exprs=key_expressions(args.keys),
            overwrite=args.overwrite,
            compression=args.compression,
            chunk_size_bytes=int(args.chunk_size_mb * MB),
            flush_interval_s=args.flush_interval_s,
            queue_bytes=int(args.queue_mb * MB),
            duration_s=args.duration,
        )


def _stopped(recorder: Recorder, writer: RecordingWriter) -> RecordingError:
    """The one line for a writer thread that ended early."""
    failed = recorder.failed
    if isinstance(failed, OSError) and writer.failed is not None:
        # A full or vanished disk: finish() closes the file by hand and says how.
        try:
            writer.finish()
        except RecordingError as e:
            return e
    with contextlib.suppress(OSError, RecordingError):
        writer.finish()
    return RecordingError(
        f"stopped recording {writer.path}: the writer failed with {type(failed).__name__}: "
        f"{failed}; the file holds what was written before"
    )


def main(args: argparse.Namespace) -> int:
    config = RecordSettings.from_args(args)
    if config.out.exists() and not config.overwrite:  # say so before connecting to anything
        raise RecordingError(
            f"{config.out} already exists: delete it, choose another name, or pass --overwrite"
        )
    memory.bound_heap()  # before Zenoh's threads start: payloads must not fragment the heap
    with bus.open_bus(args) as b:
        writer = RecordingWriter(
            config.out,
            namespace=b.namespace,
            compression=config.compression,
            chunk_size_bytes=config.chunk_size_bytes,
            overwrite=config.overwrite,
        )
        recorder = Recorder(writer, config.queue_bytes, config.flush_interval_s)
        try:
            recorder.start()
            for expr in config.exprs:
                b.subscribe_raw(expr, recorder.on_sample, history=True)
            log.info(
                "recording %s into %s, %s (Ctrl-C to stop)",
                ", ".join(b.key(e) for e in config.exprs),
                config.out,
                "uncompressed" if config.compression == "none" else f"{config.compression} chunks",
            )
            deadline = None if config.duration_s is None else time.monotonic() + config.duration_s
            try:
                while recorder.running and (deadline is None or time.monotonic() < deadline):
                    recorder.progress.draw(recorder.queue.dropped)
                    time.sleep(0.1)  # the progress line's pace; the writer runs on its own
            except KeyboardInterrupt:
                pass  # Ctrl-C and SIGTERM end the recording; the file is finished below
        finally:
            with finishing(config.out):
                b.close()  # no more samples after this, so the queue can only drain
                recorder.stop()
                recorder.progress.draw(recorder.queue.dropped, force=True)
                recorder.progress.end()
                if recorder.running:
                    writer.finish()
        if not recorder.running:
            raise _stopped(recorder, writer)
    dropped = recorder.queue.dropped
    log.info("%s", recorder.progress.line(dropped))
    if dropped:
        log.warning(
            "dropped %s while the disk was behind",
            ", ".join(f"{k} {n}" for k, n in dropped.items()),
        )
    return 0
