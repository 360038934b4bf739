"""Show the running system in Rerun, live: the seed's RViz.

Reads (under the namespace), for the camera named by --camera (default ``camera``):
  CAMERA/image_raw        Image rgb8           the colour picture, 5 Hz
  CAMERA/depth/image_raw  Image 32FC1          the depth picture, metres, NaN = no reading
  CAMERA/camera_info      CameraInfo           the lens, drawn as a pinhole
  CAMERA/pose             TransformStamped     world -> camera_optical_frame, with each capture
  CAMERA/points           PointCloud           the cloud in colour, in camera_optical_frame
  tf_static               TFMessage            latched: world -> camera_link -> optical frame
  detections              Detection3DArray     each box as a labelled 3D box with its size
  sim/ground_truth        GroundTruth          the true box, as a thin green wireframe
Writes: nothing on the bus. Rerun's time is simulated time (``sim_time``, each header's stamp).

Where it shows them:
  - with a display ($DISPLAY or $WAYLAND_DISPLAY): the native Rerun viewer;
  - without one: a web viewer served on loopback (a ``rerun --serve-web`` child process); the
    address to open is printed;
  - --save FILE.rrd: a recording instead, which ``rerun FILE.rrd`` opens later.
The layout is the seed's config/one_box.rviz: the 3D view beside the colour and depth pictures.

Settings: viewer (environment VIEWER, config [viewer] viewer; the seed's rviz:=false). With
``VIEWER=false`` it logs "viewer off" and idles until stopped, so ``honcho start`` keeps the
other processes running. --frames N stops after N complete captures (colour, depth, info, points
and detections of one stamp), --duration-s S after S seconds: for tests and benchmarks.
A slow viewer keeps the newest message on each key and says how many it dropped.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import logging
import os
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import rerun as rr

from schemas import (
    CameraInfo,
    Detection3DArray,
    GroundTruth,
    Image,
    Message,
    PointCloud,
    TFMessage,
    TransformStamped,
)
from services import bus, rerun_log, settings
from services.errors import OneboxError
from services.images import ImageError

log = logging.getLogger("viewer")

APPLICATION_ID = "onebox"
COMPLETE = frozenset({"colour", "depth", "info", "points", "detections"})
"""What one capture must have logged to count towards --frames. Not the pose: a recording
without one (the committed capture) places the camera by tf_static instead."""


class ViewerError(OneboxError):
    """The Rerun viewer could not be started or reached."""


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
    parser.add_argument(
        "--web-port", type=int, default=9090, help="web viewer port on 127.0.0.1 (default 9090)"
    )
    parser.add_argument(
        "--grpc-port",
        type=int,
        default=9876,
        help="Rerun's data port on 127.0.0.1 (default 9876)",
    )
    parser.add_argument(
        "--memory-limit",
        default="1GiB",
        help="how much the web viewer's server keeps for late-joining browsers (default 1GiB)",
    )
    settings.add(parser, "table_z", 0.0, "height of the table top, metres")
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


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def rerun_executable() -> str:
    """The ``rerun`` binary the rerun-sdk wheel ships (RERUN_CLI_PATH overrides it)."""
    override = os.environ.get("RERUN_CLI_PATH")
    if override:
        return override
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin is not None:
        bundled = Path(spec.origin).parent / "rerun"
        if bundled.exists():
            return str(bundled)
    found = shutil.which("rerun")
    if found is None:
        raise ViewerError("no `rerun` executable: reinstall rerun-sdk (pip install rerun-sdk)")
    return found


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        # As the server will: a port whose last connections linger in TIME_WAIT is free.
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _wait_for_port(port: int, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
            return
        if proc.poll() is not None:
            raise ViewerError(f"the Rerun web server exited with code {proc.returncode}")
        if time.monotonic() > deadline:
            raise ViewerError(f"the Rerun web server did not listen on 127.0.0.1:{port}")
        time.sleep(0.05)  # polling a port that has no event to wait on


@contextlib.contextmanager
def web_server(grpc_port: int, web_port: int, memory_limit: str) -> Iterator[str]:
    """A loopback-only ``rerun --serve-web`` child; yields the gRPC address to log to."""
    for port, flag in ((grpc_port, "--grpc-port"), (web_port, "--web-port")):
        if not _port_free(port):
            raise ViewerError(
                f"port {port} on 127.0.0.1 is taken (another viewer?): choose another with {flag}"
            )
    # The SDK's own serve_web_viewer() binds every interface; the CLI can bind loopback only.
    cmd = [
        rerun_executable(),
        "--serve-web",
        "--bind",
        "127.0.0.1",
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(web_port),
        "--server-memory-limit",
        memory_limit,
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_for_port(grpc_port, proc, timeout_s=20.0)
        _wait_for_port(web_port, proc, timeout_s=20.0)
        yield f"rerun+http://127.0.0.1:{grpc_port}/proxy"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def web_address(grpc_port: int, web_port: int) -> str:
    """The page to open: the web viewer, told where the data is."""
    return f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"


@contextlib.contextmanager
def open_recording(args: argparse.Namespace) -> Iterator[rr.RecordingStream]:
    """A recording sent where the flags say; a saved file is complete when the block ends."""
    rec = rr.RecordingStream(APPLICATION_ID)
    blueprint = rerun_log.blueprint(args.camera)
    with contextlib.ExitStack() as stack:
        if args.save is not None:
            args.save.parent.mkdir(parents=True, exist_ok=True)
            rec.save(args.save, default_blueprint=blueprint)
            print(f"viewer: writing {args.save}", flush=True)
        elif has_display() and not args.web:
            rec.spawn(port=args.grpc_port, default_blueprint=blueprint)
            print("viewer: opened the Rerun viewer", flush=True)
        else:
            url = stack.enter_context(web_server(args.grpc_port, args.web_port, args.memory_limit))
            rec.connect_grpc(url, default_blueprint=blueprint)
            print(
                f"viewer: no display; open {web_address(args.grpc_port, args.web_port)}",
                flush=True,
            )
        # Leaving `with rec` flushes and finalizes the .rrd (writes its footer).
        try:
            with rec:
                yield rec
        except RuntimeError as e:
            # honcho stops the whole process group at once, so the web server (our child) may
            # be gone before the last flush; what was not sent had no one left to see it.
            if args.save is not None or "gRPC" not in str(e):
                raise
            log.info("the web viewer stopped first; nothing more to send")


def idle() -> int:
    """The seed's rviz:=false: stay up, doing nothing, so honcho keeps the rest running."""
    log.info("viewer off (VIEWER=false); idling until stopped")
    threading.Event().wait()
    return 0


KEYS: dict[str, type[Message]] = {
    "image_raw": Image,
    "depth/image_raw": Image,
    "camera_info": CameraInfo,
    "pose": TransformStamped,
    "points": PointCloud,
}


def main(args: argparse.Namespace) -> int:
    if not args.viewer:
        return idle()
    inbox = LatestPerKey()
    limiter = bus.ReportLimiter(log, interval_s=10.0)
    kinds_by_stamp: dict[int, set[str]] = {}
    complete = 0
    started = time.monotonic()
    with bus.open_bus(args) as b, open_recording(args) as rec:
        scene = rerun_log.SceneLog(rec, camera=args.camera, table_z_m=args.table_z)
        scene.start()

        def on_message(key: str, message: Message) -> None:
            inbox.put(b.unkey(key), message)

        for suffix, message_type in KEYS.items():
            b.subscribe(f"{args.camera}/{suffix}", message_type, on_message)
        b.subscribe("tf_static", TFMessage, on_message, history=True)
        b.subscribe("detections", Detection3DArray, on_message)
        b.subscribe("sim/ground_truth", GroundTruth, on_message)
        log.info("showing %s/*, tf_static, detections and sim/ground_truth", args.camera)
        dropped_reported = 0
        while args.frames is None or complete < args.frames:
            if args.duration_s is not None and time.monotonic() - started > args.duration_s:
                break
            for name, message in inbox.take(timeout_s=0.5):
                try:
                    kind = scene.log(name, message)
                except ImageError as e:
                    limiter.warn(name, "bad", f"not shown: {e}")
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
