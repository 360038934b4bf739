"""Show an .mcap recording in Rerun as ``onebox viewer`` shows the live system, or write an .rrd.

  onebox view FILE.mcap                   open it (native viewer, or the web viewer on loopback)
  onebox view FILE.mcap --save OUT.rrd    write a Rerun recording and exit

Reads the file's keys (under --namespace) that the viewer draws: CAMERA/image_raw,
CAMERA/depth/image_raw, CAMERA/camera_info, CAMERA/pose, CAMERA/points, tf_static,
detections and sim/ground_truth; other keys are counted and left out. Each message is placed on
Rerun's ``sim_time`` timeline at its header stamp, so scrubbing the timeline replays it. A
message that does not decode is reported with its key and skipped. A truncated file (a recorder
that was killed) is read up to its last complete chunk with --recover.

A message the viewer will not draw (a stamp outside 0..2^63 ns, NaN, a zero quaternion, a
tf_static cycle, a picture whose sizes do not fit its bytes) is reported with its key and left
out, as in the live viewer.

Showing serves the recording until Ctrl-C; --save writes the file and exits. --save refuses to
replace an existing file without --overwrite, and leaves nothing behind when it fails (a file
that is not MCAP, say): the .rrd is written beside it and renamed when complete.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from pathlib import Path

import msgspec

from onebox import recording, rerun_scene, rerun_sink, settings, sync
from onebox.errors import RecordingError
from onebox.keys import type_for_key
from schemas import codec

log = logging.getLogger("view")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, metavar="FILE.mcap", help="the recording to show")
    parser.add_argument(
        "--save", type=Path, metavar="FILE.rrd", help="write a Rerun recording instead of showing"
    )
    parser.add_argument(
        "--camera", default="camera", help="which camera's keys to show (default camera)"
    )
    parser.add_argument(
        "--recover", action="store_true", help="read a truncated file up to its last whole chunk"
    )
    parser.add_argument(
        "--web", action="store_true", help="serve the web viewer even when a display exists"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --save file")
    settings.add(parser, "web_port", 0, "web viewer port on 127.0.0.1; 0: 9090 or any free")
    settings.add(parser, "grpc_port", 0, "Rerun's data port on 127.0.0.1; 0: 9876 or any free")
    settings.add(parser, "memory_limit", "1GiB", "what the web server keeps for browsers")
    settings.add(
        parser,
        "table_z",
        "auto",
        "height of the table top, metres; auto draws it at 0 (the found plane is on support)",
        kind=rerun_scene.table_z_setting,
    )
    settings.add(parser, "namespace", "", "the prefix the recorded keys carry, if any")


def log_file(path: Path, scene: rerun_scene.SceneLog, namespace: str, recover: bool) -> int:
    """Log every drawable message of ``path``; returns how many were logged."""
    prefix = f"{namespace.strip('/')}/" if namespace else ""
    logged = skipped = 0
    last_report = time.monotonic()
    limiter = sync.ReportLimiter(log)
    for item in recording.iter_messages(path, recover=recover):
        message_type = recording.TYPES_BY_NAME.get(item.schema_name) or type_for_key(
            item.key, namespace
        )
        if message_type is None:
            skipped += 1
            continue
        name = item.key.removeprefix(prefix)
        try:
            message = codec(message_type).decode(item.payload)
            kind = scene.log(name, message)
        except (msgspec.DecodeError, msgspec.ValidationError, ValueError, OverflowError) as e:
            # ValueError covers the scene's BadMessage and ImageError.
            limiter.warn(item.key, str(e)[:24], f"skipped: {e}")
            continue
        if kind is None:
            skipped += 1
        else:
            logged += 1
        if time.monotonic() - last_report > 2.0:
            print(f"view: {logged} messages shown so far", flush=True)
            last_report = time.monotonic()
    print(f"view: {path}: {logged} messages shown, {skipped} on keys the viewer does not draw")
    return logged


def main(args: argparse.Namespace) -> int:
    sink = rerun_sink.Sink.from_args(args)
    if not args.file.exists():
        raise RecordingError(f"{args.file} does not exist: give the path of an .mcap recording")
    with rerun_sink.open_recording(sink) as rec:
        scene = rerun_scene.SceneLog(rec, camera=args.camera, table_z_m=args.table_z)
        scene.start()
        logged = log_file(args.file, scene, args.namespace, args.recover)
        if logged == 0:
            log.warning("%s holds nothing the viewer draws for camera %r", args.file, args.camera)
        if args.save is None:
            print("view: serving until Ctrl-C", flush=True)
            threading.Event().wait()
    if args.save is not None:
        print(f"view: wrote {args.save}")
    return 0
