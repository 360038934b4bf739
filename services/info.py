"""Summarise an MCAP recording, as ``ros2 bag info`` did.

    onebox info tests/data/one_box.mcap

Reads: FILE.mcap only (no Zenoh). Prints its size, duration, start and end (log time: when the
messages arrived), the simulated time they span (their header stamps; latched ``tf_static`` and
unstamped messages, stamp 0, are left out: they say nothing about when the recording ran),
the message and chunk counts and the compression, then per key its type, count, message
encoding and schema. A file cut short by a killed recorder is reported as truncated;
``--recover`` summarises its complete chunks instead.
"""

from __future__ import annotations

import argparse
import datetime
from dataclasses import dataclass
from pathlib import Path

from onebox.recording import RecordingInfo, describe


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, metavar="FILE.mcap", help="the recording to describe")
    parser.add_argument(
        "--recover",
        action="store_true",
        help="describe the complete chunks of a file whose recorder was killed",
    )


def _when(ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(ns / 1e9, tz=datetime.UTC).astimezone()
    return f"{moment:%b %d %Y %H:%M:%S}.{moment.microsecond // 1000:03d} ({ns / 1e9:.9f})"


def _size(nbytes: int) -> str:
    if nbytes < 1024:
        return f"{nbytes} B"
    if nbytes < 1024**2:
        return f"{nbytes / 1024:.1f} KiB"
    if nbytes < 1024**3:
        return f"{nbytes / 1024**2:.1f} MiB"
    return f"{nbytes / 1024**3:.2f} GiB"


def render(info: RecordingInfo) -> str:
    """The text ``onebox info`` prints."""
    lines = [
        f"Files:             {info.path}",
        f"Size:              {_size(info.size_bytes)}",
        "Storage:           mcap" + ("" if info.complete else " (truncated: complete chunks only)"),
        f"Duration:          {info.duration_s:.9f} s",
    ]
    if info.message_count:
        lines += [
            f"Start:             {_when(info.start_ns)}",
            f"End:               {_when(info.end_ns)}",
        ]
    if info.sim_start_ns is not None and info.sim_end_ns is not None:
        lines.append(
            f"Simulated time:    {info.sim_start_ns / 1e9:.3f} s to {info.sim_end_ns / 1e9:.3f} s"
            " (header stamps)"
        )
    lines += [
        f"Messages:          {info.message_count}",
        f"Chunks:            {info.chunk_count} (compression: {info.compression})",
    ]
    width = max((len(k.key) for k in info.keys), default=0)
    for i, k in enumerate(info.keys):
        label = "Keys:              " if i == 0 else " " * 19
        schema = f"{k.schema_name} ({k.schema_encoding})" if k.schema_name else "none"
        lines.append(
            f"{label}Key: {k.key:<{width}} | Type: {k.schema_name or 'unknown'} | "
            f"Count: {k.count} | Encoding: {k.message_encoding} | Schema: {schema}"
        )
    if not info.keys:
        lines.append("Keys:              none")
    return "\n".join(lines)


@dataclass(frozen=True)
class InfoSettings:
    """Which recording ``onebox info`` describes, and how strictly it reads it."""

    file: Path
    recover: bool


def main(args: argparse.Namespace) -> int:
    settings = InfoSettings(file=args.file, recover=args.recover)
    info = describe(settings.file, recover=settings.recover)
    print(render(info))
    return 0
