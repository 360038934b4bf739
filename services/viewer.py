"""Show the running system in Rerun, live: the seed's RViz.

Reads (under the namespace), for the camera named by --camera (default ``camera``):
  CAMERA/image_raw        Image rgb8           the colour picture (JPEG in --save)
  CAMERA/depth/image_raw  Image 32FC1          the depth picture (near bright), under the
                                               pinhole (the 3D view leaves it out: --points)
  CAMERA/camera_info      CameraInfo           the lens, drawn as a pinhole (static)
  CAMERA/pose             TransformStamped     world -> camera_optical_frame, with each capture
  CAMERA/points           PointCloud           checked; drawn (thinned, 1 Hz) only with --points
  tf_static               TFMessage            latched: world -> camera_link -> optical frame
  detections              Detection3DArray     each box oriented, labelled id, size (mm), yaw
  support                 SupportPlane         the plane the boxes stand on, a translucent patch
  sim/ground_truth        GroundTruth          the true boxes, as thin green wireframes
Writes: nothing on the bus. Rerun's time is simulated time (``sim_time``, each header's stamp).

Where it shows them:
  - with a display ($DISPLAY or $WAYLAND_DISPLAY): the native Rerun viewer;
  - without one: a web viewer served on loopback (a ``rerun --serve-web`` child process); the
    address to open is printed. Its ports are settings (ONEBOX_GRPC_PORT, ONEBOX_WEB_PORT); left at
    0 they are 9876 and 9090 when free and any free ports otherwise, so a second pipeline's viewer
    starts beside the first. The server keeps --memory-limit of data for late browsers and sends a
    late page the newest first; what never changes (lens, tf_static, table) and the newest pose,
    support plane and true boxes are static and always kept. The page's viewer drops its oldest data
    once its memory passes --page-memory-limit (Rerun's own page keeps everything up to 2.3 GiB), so
    its heap stops growing. A live page gets the pictures at most --picture-hz times a second,
    --picture-scale times smaller, and the boxes with every capture: a software-rendered browser
    takes data in only as fast as it draws, so every message costs;
  - --save FILE.rrd: a recording instead, which ``rerun FILE.rrd`` opens later (refused if it
    exists, unless --overwrite; nothing is left behind on failure).
The layout is the seed's config/one_box.rviz: the 3D view beside the colour and depth pictures;
the 3D view on a plain white background without Rerun's endless grid (the table's grid is the
floor), which a software-rendered page redrew at 1 to 2 frames a second with nothing else shown.

Settings: viewer (environment ONEBOX_VIEWER, config [viewer] viewer; the seed's rviz:=false).
With ``ONEBOX_VIEWER=false`` it logs "viewer off" and idles until stopped, so ``honcho start``
keeps the other processes running. --frames N stops after N complete captures (colour, depth,
info and detections of one stamp), --duration-s S after S seconds: for tests and benchmarks.
A slow viewer keeps the newest message on each key and says how many it dropped. A message it
will not draw (a stamp outside 0..2^63 ns, NaN, a zero quaternion, a tf_static cycle or a chain
deeper than 64 frames, a picture or cloud whose sizes do not fit its bytes) is logged with its
key and dropped; the next valid one is shown.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from onebox import bus, keys, rerun_scene, rerun_sink, settings, sync
from schemas import (
    CameraInfo,
    Detection3DArray,
    GroundTruth,
    Image,
    Message,
    PointCloud,
    SupportPlane,
    TFMessage,
    TransformStamped,
)

log = logging.getLogger("viewer")

COMPLETE = frozenset({"colour", "depth", "info", "detections"})
"""What one capture must have logged to count towards --frames. Not the pose: a recording
without one (the committed capture) places the camera by tf_static instead; not the cloud,
which the depth picture under the pinhole already shows."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    settings.add(parser, "viewer", True, "show anything at all; false idles (the seed's rviz:=)")
    parser.add_argument(
        "--camera", default="camera", help="which camera's keys to show (default camera)"
    )
    parser.add_argument(
        "--save", type=Path, metavar="FILE.rrd", help="write a Rerun recording instead of showing"
    )
    parser.add_argument(
        "--web",
        action="store_true",
        help="serve the web viewer even when a display exists",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --save file")
    settings.add(parser, "web_port", 0, "web viewer port on 127.0.0.1; 0: 9090 or any free")
    settings.add(parser, "grpc_port", 0, "Rerun's data port on 127.0.0.1; 0: 9876 or any free")
    settings.add(
        parser,
        "memory_limit",
        "256KiB",
        "what the web server keeps (as compressed) for a page that joins late, sent newest "
        "first; static data is dropped last. Small, so a late page catches up in seconds",
    )
    settings.add(
        parser,
        "page_memory_limit",
        "128MiB",
        "the web page's viewer drops its oldest data once its memory (Rerun's own count) passes "
        "this, e.g. 128MiB, 1GB, 10%%; the newest of each kind is always kept; empty: 2.3 GiB",
    )
    settings.add(
        parser,
        "picture_hz",
        1.0,
        "live: send the colour and depth pictures at most this often (the boxes come with every "
        "capture; 0: every picture); --save keeps every one",
    )
    settings.add(
        parser,
        "picture_scale",
        2,
        "live: shrink the pictures this many times each way (1: full size); --save keeps all",
    )
    parser.add_argument(
        "--points", action="store_true", help="also draw camera/points (thinned, once a second)"
    )
    settings.add(
        parser,
        "table_z",
        "auto",
        "height of the table top, metres; auto draws it at 0 (the found plane is on support)",
        kind=rerun_scene.table_z_setting,
    )
    parser.add_argument("--frames", type=int, help="stop after this many complete captures")
    parser.add_argument("--duration-s", type=float, help="stop after this many seconds")
    bus.add_arguments(parser)


class LatestPerKey:
    """The newest message on each key, for one consumer thread; older ones are dropped, counted."""

    def __init__(self) -> None:
        self._items: dict[str, Message] = {}
        self._ready = threading.Condition()
        self.dropped = 0

    def put(self, key: str, message: Message) -> None:
        with self._ready:
            if key in self._items:
                self.dropped += 1
            # Re-inserting moves the key last, so take() hands them out in arrival order.
            self._items.pop(key, None)
            self._items[key] = message
            self._ready.notify()

    def take(self, timeout_s: float) -> list[tuple[str, Message]]:
        """Everything waiting, oldest key first; empty when nothing came within ``timeout_s``."""
        with self._ready:
            self._ready.wait_for(lambda: bool(self._items), timeout=timeout_s)
            items = list(self._items.items())
            self._items.clear()
            return items


def idle() -> int:
    """The seed's rviz:=false: stay up, doing nothing, so honcho keeps the rest running."""
    log.info("viewer off (ONEBOX_VIEWER=false); idling until stopped")
    threading.Event().wait()
    return 0


KEYS: dict[str, type[Message]] = {
    "image_raw": Image,
    "depth/image_raw": Image,
    "camera_info": CameraInfo,
    "pose": TransformStamped,
    "points": PointCloud,
}


@dataclass(frozen=True)
class ViewerSettings:
    viewer: bool
    camera: str
    table_z_m: float | None
    points: bool
    live: rerun_scene.Live | None
    """What a live page is sent; None for --save, which keeps everything."""
    frames: int | None
    duration_s: float | None


def main(args: argparse.Namespace) -> int:
    sink = rerun_sink.Sink.from_args(args)
    s = ViewerSettings(
        viewer=args.viewer,
        camera=args.camera,
        table_z_m=args.table_z,
        points=args.points,
        live=None
        if args.save is not None
        else rerun_scene.Live(picture_hz=args.picture_hz, scale=max(1, args.picture_scale)),
        frames=args.frames,
        duration_s=args.duration_s,
    )
    if not s.viewer:
        return idle()
    inbox = LatestPerKey()
    limiter = sync.ReportLimiter(log, interval_s=10.0)
    kinds_by_stamp: dict[int, set[str]] = {}
    complete = 0
    started = time.monotonic()
    with bus.open_bus(args) as b, rerun_sink.open_recording(sink) as rec:
        scene = rerun_scene.SceneLog(
            rec,
            camera=s.camera,
            table_z_m=s.table_z_m,
            points=s.points,
            jpeg=args.save is not None,
            live=s.live,
        )
        scene.start()

        def on_message(key: str, message: Message) -> None:
            inbox.put(b.unkey(key), message)

        for suffix, message_type in KEYS.items():
            b.subscribe(f"{s.camera}/{suffix}", message_type, on_message)
        b.subscribe(keys.TF_STATIC, TFMessage, on_message, history=True)
        b.subscribe(keys.DETECTIONS, Detection3DArray, on_message)
        b.subscribe(keys.SUPPORT, SupportPlane, on_message)
        b.subscribe(keys.GROUND_TRUTH, GroundTruth, on_message)
        log.info("showing %s/*, tf_static, detections, support and sim/ground_truth", s.camera)
        dropped_reported = 0
        while s.frames is None or complete < s.frames:
            if s.duration_s is not None and time.monotonic() - started > s.duration_s:
                break
            for name, message in inbox.take(timeout_s=0.5):
                try:
                    kind = scene.log(name, message)
                except (ValueError, OverflowError) as e:
                    # BadMessage and ImageError are ValueErrors; whatever else Rerun refuses
                    # in a message is too. One bad message never stops the viewer.
                    limiter.warn(name, str(e)[:24], f"not shown: {e}")
                    continue
                stamp_ns = getattr(getattr(message, "header", None), "stamp_ns", None)
                if kind is None or stamp_ns is None:
                    continue
                kinds = kinds_by_stamp.setdefault(stamp_ns, set())
                kinds.add(kind)
                if COMPLETE <= kinds:
                    complete += 1
                    del kinds_by_stamp[stamp_ns]
                    if complete == 1 or complete % 50 == 0:
                        log.info("capture at %.3f s shown (%d so far)", stamp_ns / 1e9, complete)
                # A capture that never completes (no locator running, say) must not grow this.
                while len(kinds_by_stamp) > 50:
                    del kinds_by_stamp[next(iter(kinds_by_stamp))]
            if inbox.dropped > dropped_reported:
                limiter.warn(
                    "viewer",
                    "slow",
                    f"too slow: kept the newest, dropped {inbox.dropped - dropped_reported}",
                )
                dropped_reported = inbox.dropped
    return 0
