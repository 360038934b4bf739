"""Turning a onebox recording into one the rest of the ecosystem opens.

onebox records msgpack with JSON schemas, which no other tool decodes. :func:`export` reads a
recording and writes a new MCAP file in one of two well-known forms:

- ``ros2`` (:mod:`onebox.export.ros2`): rosbag2's own MCAP profile, CDR messages with
  ``ros2msg`` schemas, encoded by the ``rosbags`` library; ``ros2 bag play``, Foxglove and
  Rerun's MCAP reader open it.
- ``foxglove`` (:mod:`onebox.export.foxglove`): Foxglove's well-known protobuf schemas
  (RawImage, CameraCalibration, FrameTransforms, PointCloud, SceneUpdate), written by the
  Foxglove SDK, for Foxglove's 3D and image panels.

The output is written to a hidden file beside it and renamed at the end, so a failure never
leaves a partial file under the name asked for. A message that does not decode, or whose stamp
the target cannot hold, is reported with its key and left out; so are keys with no counterpart.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import msgspec

from onebox import recording, sync
from onebox.errors import RecordingError
from onebox.keys import type_for_key
from schemas import Message, codec

log = logging.getLogger("export")

FORMATS = ("ros2", "foxglove")

MAX_STAMP_NS = (2**31 - 1) * 1_000_000_000
"""ROS's Time holds int32 seconds; Foxglove's uint32. Both hold everything below this."""


class ExportError(RecordingError):
    """A recording could not be exported; the message says why and what to do."""


class Target(Protocol):
    """A writer of one export format."""

    def write(self, name: str, topic: str, message: Message, log_time_ns: int) -> bool:
        """Write one message (``name`` is its key less the namespace, ``topic`` as recorded).

        Returns False when the format has no counterpart for it. Raises ValueError for a
        message whose numbers the format cannot hold.
        """
        ...

    def close(self) -> None:
        """Finish the file."""
        ...


@dataclass
class ExportResult:
    """What an export wrote and what it left out."""

    written: int = 0
    left_out: Counter[str] = field(default_factory=Counter)
    """Messages on keys the format has no counterpart for, by key."""
    bad: Counter[str] = field(default_factory=Counter)
    """Messages that did not decode or could not be converted, by key."""
    topics: Counter[str] = field(default_factory=Counter)
    """Messages written, by output topic."""


def stamp_ok(stamp_ns: int) -> bool:
    """Whether a stamp fits both formats' time: not negative, seconds within 32 bits."""
    return 0 <= stamp_ns <= MAX_STAMP_NS


def _open_target(to: str, path: Path) -> Target:
    if to == "ros2":
        from onebox.export.ros2 import Ros2Target

        return Ros2Target(path)
    if to == "foxglove":
        from onebox.export.foxglove import FoxgloveTarget

        return FoxgloveTarget(path)
    raise ExportError(f"unknown format {to!r}: choose one of {', '.join(FORMATS)}")


def export(
    source: Path,
    destination: Path,
    to: str,
    *,
    namespace: str = "",
    overwrite: bool = False,
    recover: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> ExportResult:
    """Write ``source`` (a onebox .mcap) to ``destination`` in format ``to``.

    ``progress(done, total)`` is called every few hundred messages. Raises ExportError (or
    RecordingError for an unreadable source) with a line that says what to do; nothing is left
    at ``destination`` then.
    """
    if to not in FORMATS:
        raise ExportError(f"unknown format {to!r}: choose one of {', '.join(FORMATS)}")
    if not source.exists():
        raise ExportError(f"{source} does not exist: give the path of a onebox .mcap recording")
    problem = recording.output_problem(source, destination, overwrite=overwrite)
    if problem is not None:
        raise ExportError(problem)
    # Read the summary first: a file that is not MCAP fails here, before anything is created.
    total = recording.describe(source, recover=recover).message_count
    try:
        with recording.written_whole(destination) as partial:
            try:
                target = _open_target(to, partial)
            except OSError as e:
                raise ExportError(f"cannot create {destination}: {e.strerror}") from e
            try:
                result = _copy(source, target, namespace, recover, total, progress)
            finally:
                target.close()
    except OSError as e:
        raise ExportError(f"cannot write {destination}: {e.strerror or e}") from e
    return result


def _copy(
    source: Path,
    target: Target,
    namespace: str,
    recover: bool,
    total: int,
    progress: Callable[[int, int], None] | None,
) -> ExportResult:
    result = ExportResult()
    limiter = sync.ReportLimiter(log)
    prefix = f"{namespace.strip('/')}/" if namespace else ""
    done = 0
    for item in recording.iter_messages(source, recover=recover):
        done += 1
        if progress is not None and done % 200 == 0:
            progress(done, total)
        message_type = recording.TYPES_BY_NAME.get(item.schema_name) or type_for_key(
            item.key, namespace
        )
        if message_type is None:
            result.left_out[item.key] += 1
            continue
        try:
            message = codec(message_type).decode(item.payload)
            written = target.write(
                item.key.removeprefix(prefix), item.key, message, item.log_time_ns
            )
        except (msgspec.DecodeError, msgspec.ValidationError, ValueError, OverflowError) as e:
            result.bad[item.key] += 1
            limiter.warn(item.key, "bad", f"left out: {e}")
            continue
        if written:
            result.written += 1
            result.topics[item.key] += 1
        else:
            result.left_out[item.key] += 1
    if progress is not None:
        progress(done, total)
    return result
