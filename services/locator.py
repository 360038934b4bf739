"""onebox locator: find the box in each depth picture and publish where it is (box_locator).

Reads (keys under --namespace):
  camera/depth/image_raw  Image, 32FC1 metres (NaN = no reading) or 16UC1 millimetres (0 = no
                          reading); stamped in the camera's optical frame
  camera/camera_info      CameraInfo, matched to each depth picture by header.stamp_ns (exactly,
                          or within --slop-ms for a real camera)
  tf_static               TFMessage, latched: any chain of transforms from world_frame to the
                          picture's frame (with --pose-source tf, the default)
  camera/pose             TransformStamped world_frame -> the picture's frame, stamp-matched
                          like the camera info (with --pose-source pose: a camera that moves)
Writes:
  detections              Detection3DArray in world_frame, stamped like the depth picture, one
                          for each picture measured: one Detection3D (class "box", bbox centre
                          and size in metres, score = the share of the standing points that are
                          its flat top), or no detection when no box is in view

Every 2 s it logs the latest measurement, as the seed did:
  box: middle (+0.064, +0.040) m, height 0.060 m, from 2,401 points on its top
or says that no box is in view, or what it is waiting for. Queues are bounded: when it falls
behind it keeps the newest capture, and says how many it dropped. A message it cannot use
(garbage, the wrong type, a size or step that does not fit its data, all NaN, no matching
camera info, no transform to world_frame, a stamp going back) is logged with its key once per
interval and dropped.

Settings (flag > environment variable > config/onebox.toml > default) are listed below.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from onebox import bus, geometry, pictures, settings, sync
from onebox.errors import SettingError
from onebox.geometry import FrameError, FrameTree, matrix_of
from onebox.perception import seed
from onebox.sync import StampClock, Stamped, StampMatcher
from schemas import (
    BoundingBox3D,
    CameraInfo,
    Detection3D,
    Detection3DArray,
    Header,
    Image,
    ObjectHypothesis,
    Pose,
    TFMessage,
    TransformStamped,
    Vector3,
)

log = logging.getLogger("locator")

DEPTH_KEY = "camera/depth/image_raw"
INFO_KEY = "camera/camera_info"
POSE_KEY = "camera/pose"
TF_KEY = "tf_static"
DETECTIONS_KEY = "detections"
MATCH_TIMEOUT_S = 1.0
"""How long a depth picture waits for its camera info (or pose) before it is reported."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)
    group = parser.add_argument_group("locator (the seed's parameters)")
    settings.add(group, "world_frame", "world", "the frame the box is reported in")
    settings.add(group, "table_z", 0.0, "how high the table top is in world_frame, metres")
    settings.add(
        group, "min_height", 0.01, "how far above the table a point must be to count, metres"
    )
    match = parser.add_argument_group("matching")
    match.add_argument(
        "--slop-ms",
        type=float,
        default=0.0,
        metavar="MS",
        help="pair a depth picture with camera info (and pose) stamped up to MS apart; "
        "0 pairs equal stamps only, as the simulated camera sends (default 0)",
    )
    match.add_argument(
        "--pose-source",
        choices=("tf", "pose"),
        default="tf",
        help="where the camera is: the chain on tf_static (a fixed camera, the default) or "
        "camera/pose matched by stamp (a camera that moves)",
    )
    match.add_argument(
        "--queue-size",
        type=int,
        default=4,
        metavar="N",
        help="messages kept per key while waiting for their partners (default 4)",
    )
    run = parser.add_argument_group("run")
    run.add_argument(
        "--log-interval-s",
        type=float,
        default=2.0,
        metavar="S",
        help="how often to log the latest measurement (default 2)",
    )
    run.add_argument(
        "--frames", type=int, metavar="N", help="stop after publishing N detection arrays"
    )
    run.add_argument("--duration-s", type=float, metavar="S", help="stop after S seconds")


# --- the locator ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class DepthFrame:
    """A depth picture, decoded in the Zenoh callback."""

    stamp_ns: int
    frame_id: str
    depth_m: geometry.Float32Array
    arrived_s: float


@dataclass(frozen=True)
class Lens:
    """A camera info, checked in the Zenoh callback."""

    width: int
    height: int
    intrinsics: geometry.Intrinsics


@dataclass(frozen=True)
class Result:
    """The outcome of one picture, kept for the log every few seconds."""

    stamp_ns: int
    box: seed.BoxMeasurement | None


def detection_array(
    box: seed.BoxMeasurement | None, stamp_ns: int, world_frame: str, table_z: float
) -> Detection3DArray:
    """The message for one picture: one box, or none."""
    header = Header(stamp_ns=stamp_ns, frame_id=world_frame)
    if box is None:
        return Detection3DArray(header=header)
    centre = Pose(position=Vector3(x=box.x, y=box.y, z=table_z + box.height / 2))
    size = Vector3(x=box.extent_x + box.pixel_m, y=box.extent_y + box.pixel_m, z=box.height)
    return Detection3DArray(
        header=header,
        detections=[
            Detection3D(
                header=header,
                results=[ObjectHypothesis(class_id="box", score=box.score)],
                bbox=BoundingBox3D(center=centre, size=size),
                id="box",
            )
        ],
    )


def box_line(box: seed.BoxMeasurement) -> str:
    """The seed's log line."""
    return (
        f"box: middle ({box.x:+.3f}, {box.y:+.3f}) m, height {box.height:.3f} m, "
        f"from {box.top_count:,} points on its top"
    )


class Locator:
    """Matches depth, camera info (and pose), measures on a worker thread, publishes."""

    def __init__(self, b: bus.Bus, args: argparse.Namespace) -> None:
        self._bus = b
        self._world_frame: str = args.world_frame
        self._table_z: float = args.table_z
        self._min_height: float = args.min_height
        self._use_pose = args.pose_source == "pose"
        self._keys = {
            "depth": b.key(DEPTH_KEY),
            "info": b.key(INFO_KEY),
            "pose": b.key(POSE_KEY),
            "tf": b.key(TF_KEY),
        }
        self._report = sync.ReportLimiter(log, interval_s=args.log_interval_s)
        streams = ["depth", "info", "pose"] if self._use_pose else ["depth", "info"]
        self._matcher = StampMatcher(
            streams,
            slop_ns=round(args.slop_ms * 1e6),
            queue_size=args.queue_size,
            on_unmatched=self._unmatched,
        )
        self._matched: sync.NewestQueue[dict[str, Stamped]] = sync.NewestQueue(maxlen=2)
        self._clock = StampClock()
        self._tree = FrameTree()
        self._tree_lock = threading.Lock()
        self._camera_cache: tuple[int, str, geometry.Float64Array] | None = None
        self._publisher = b.publisher(DETECTIONS_KEY, Detection3DArray)
        self.published = 0
        self.latest: Result | None = None

    def subscribe(self) -> None:
        self._bus.subscribe(DEPTH_KEY, Image, self._on_depth)
        self._bus.subscribe(INFO_KEY, CameraInfo, self._on_info)
        self._bus.subscribe(TF_KEY, TFMessage, self._on_tf, history=True)
        if self._use_pose:
            self._bus.subscribe(POSE_KEY, TransformStamped, self._on_pose)

    # Zenoh callbacks: decode and check, then hand over; nothing slow here.

    def _stamp_ok(self, key: str, stamp_ns: int) -> bool:
        return self._clock.accept(key, stamp_ns, self._report, self._matcher)

    def _on_depth(self, key: str, image: Image) -> None:
        try:
            depth_m = pictures.depth_m(image)
        except pictures.ImageError as e:
            self._report.warn(key, e.kind, f"dropped: {e}")
            return
        stamp_ns = image.header.stamp_ns
        if not self._stamp_ok(key, stamp_ns):
            return
        frame = DepthFrame(stamp_ns, image.header.frame_id, depth_m, time.monotonic())
        self._offer("depth", stamp_ns, frame)

    def _on_info(self, key: str, info: CameraInfo) -> None:
        try:
            lens = Lens(info.width, info.height, geometry.Intrinsics.from_k(info.k))
        except ValueError as e:
            self._report.warn(key, "lens", f"dropped: {e}")
            return
        if self._stamp_ok(key, info.header.stamp_ns):
            self._offer("info", info.header.stamp_ns, lens)

    def _on_pose(self, key: str, pose: TransformStamped) -> None:
        if pose.header.frame_id != self._world_frame:
            self._report.warn(
                key,
                "frame",
                f"dropped: the pose is of {pose.child_frame_id!r} in {pose.header.frame_id!r}, "
                f"but world_frame is {self._world_frame!r}",
            )
            return
        try:
            matrix = matrix_of(pose)
        except FrameError as e:
            self._report.warn(key, "pose", f"dropped: {e}")
            return
        if self._stamp_ok(key, pose.header.stamp_ns):
            self._offer("pose", pose.header.stamp_ns, (pose.child_frame_id, matrix))

    def _on_tf(self, key: str, message: TFMessage) -> None:
        with self._tree_lock:
            for transform in message.transforms:
                try:
                    self._tree.add(transform)
                except FrameError as e:
                    self._report.warn(key, "transform", f"one transform dropped: {e}")

    def _offer(self, stream: str, stamp_ns: int, item: Any) -> None:
        matched = self._matcher.add(stream, stamp_ns, item)
        if matched is not None:
            self._matched.put(matched)

    def _unmatched(self, stamped: Stamped, why: str) -> None:
        partners = " and ".join(self._keys[s] for s in self._matcher.streams[1:])
        self._report.warn(
            self._keys["depth"],
            "unmatched",
            f"depth picture stamped {stamped.stamp_ns:,} ns dropped: no {partners} with "
            f"{'that stamp' if self._matcher.exact else 'a stamp close enough'} "
            f"({why}); is the camera publishing its camera info?",
        )

    # The worker thread.

    def _camera_to_world(self, frame: DepthFrame, found: dict[str, Stamped]) -> Any:
        if self._use_pose:
            child, matrix = found["pose"].item
            if child != frame.frame_id:
                raise FrameError(
                    f"camera/pose is of {child!r} but the depth picture is in {frame.frame_id!r}"
                )
            return matrix
        with self._tree_lock:
            cached = self._camera_cache
            if cached is not None and cached[:2] == (self._tree.version, frame.frame_id):
                return cached[2]
            matrix = self._tree.lookup(self._world_frame, frame.frame_id)
            self._camera_cache = (self._tree.version, frame.frame_id, matrix)
            return matrix

    def process(self, found: dict[str, Stamped]) -> None:
        """Measure one matched capture and publish its detections."""
        frame: DepthFrame = found["depth"].item
        lens: Lens = found["info"].item
        depth_key = self._keys["depth"]
        rows, cols = frame.depth_m.shape
        if (lens.width, lens.height) != (cols, rows):
            self._report.warn(
                self._keys["info"],
                "size",
                f"camera info is for {lens.width} x {lens.height} but the depth picture "
                f"stamped {frame.stamp_ns:,} ns is {cols} x {rows}; dropped",
            )
            return
        try:
            camera_to_world = self._camera_to_world(frame, found)
        except FrameError as e:
            self._report.warn(
                depth_key,
                "transform",
                f"no transform from {frame.frame_id!r} to world_frame {self._world_frame!r}, "
                f"dropped: {e}",
            )
            return
        box = seed.locate_box(
            frame.depth_m, lens.intrinsics, camera_to_world, self._table_z, self._min_height
        )
        if box is None and not seed.has_reading(frame.depth_m):
            self._report.warn(
                depth_key,
                "no-reading",
                f"depth picture stamped {frame.stamp_ns:,} ns has no reading at all "
                "(every pixel NaN, 0 or infinite), dropped",
            )
            return
        self._publisher.publish(
            detection_array(box, frame.stamp_ns, self._world_frame, self._table_z)
        )
        self.published += 1
        self.latest = Result(frame.stamp_ns, box)

    def log_latest(self, since: Result | None) -> None:
        """The seed's line about the newest measurement, or what is missing."""
        latest = self.latest
        if latest is not None and latest is not since:
            if latest.box is not None:
                log.info(box_line(latest.box))
            else:
                log.info(
                    "no box in view: nothing stands more than %.3f m above the table "
                    "(table_z %.3f m in %s)",
                    self._min_height,
                    self._table_z,
                    self._world_frame,
                )
            return
        waiting = [self._keys["depth"], self._keys["info"]]
        waiting.append(self._keys["pose"] if self._use_pose else self._keys["tf"])
        log.info("waiting: no capture measured lately; needs %s", ", ".join(waiting))

    def run(self, frames: int | None, duration_s: float | None, interval_s: float) -> None:
        """Measure matched captures until stopped, --frames or --duration-s."""
        start = time.monotonic()
        next_log = start + interval_s
        logged: Result | None = None
        dropped = 0
        while frames is None or self.published < frames:
            now = time.monotonic()
            if duration_s is not None and now - start >= duration_s:
                break
            found = self._matched.get(timeout_s=min(0.25, max(0.0, next_log - now)))
            if found is not None:
                self.process(found)
            if time.monotonic() >= next_log:
                self._matcher.expire(MATCH_TIMEOUT_S)
                self.log_latest(logged)
                logged = self.latest
                if self._matched.dropped > dropped:
                    log.warning(
                        "dropped %d captures in the last %g s: measuring is slower than the "
                        "camera, so the newest is kept",
                        self._matched.dropped - dropped,
                        interval_s,
                    )
                    dropped = self._matched.dropped
                next_log = time.monotonic() + interval_s


def main(args: argparse.Namespace) -> int:
    """Subscribe, measure every matched capture, publish detections, log every interval."""
    if args.min_height < 0:
        raise SettingError(f"min_height {args.min_height}: must be 0 or more (metres)")
    if args.slop_ms < 0:
        raise SettingError(f"--slop-ms {args.slop_ms}: must be 0 or more")
    if args.queue_size < 1:
        raise SettingError(f"--queue-size {args.queue_size}: must be at least 1")
    if args.log_interval_s <= 0:
        raise SettingError(f"--log-interval-s {args.log_interval_s}: must be above 0")
    if not np.isfinite(args.table_z):
        raise SettingError(f"table_z {args.table_z}: must be a number of metres")
    with bus.open_bus(args) as b:
        locator = Locator(b, args)
        locator.subscribe()
        log.info(
            "finding the box in %s with %s, camera from %s; detections in %s on %s",
            b.key(DEPTH_KEY),
            b.key(INFO_KEY),
            b.key(POSE_KEY) if args.pose_source == "pose" else f"{b.key(TF_KEY)}",
            args.world_frame,
            b.key(DETECTIONS_KEY),
        )
        try:
            locator.run(args.frames, args.duration_s, args.log_interval_s)
        finally:
            log.info("published %d detection arrays", locator.published)
    return 0
