"""onebox locator: find every box in each depth picture and publish where it is (box_locator).

Reads (keys under --namespace):
  camera/depth/image_raw  Image, 32FC1 metres (NaN = no reading) or 16UC1 millimetres (0 = no
                          reading); stamped in the camera's optical frame
  camera/camera_info      CameraInfo (the middle of pixel u at u, as real cameras write it),
                          matched to each depth picture by header.stamp_ns (exactly, or within
                          --slop-ms for a real camera); a lens with distortion (plumb_bob,
                          rational_polynomial, equidistant) has its pictures rectified first
  camera/image_raw        Image, colour aligned with the depth pixel for pixel (optional): its
                          edges split touching cartons whose seam depth alone cannot see
  tf_static               TFMessage, latched: any chain of transforms from world_frame to the
                          picture's frame (with --pose-source tf, the default)
  camera/pose             TransformStamped world_frame -> the picture's frame, stamp-matched
                          like the camera info (with --pose-source pose: a camera that moves)
Writes:
  detections              Detection3DArray, stamped like the depth picture, one for each picture
                          measured: one Detection3D a box, topmost first (class "box", bbox
                          centre and orientation, size = length >= width, height in metres,
                          score = how much of its top is a flat rectangle, id stable while the
                          box does not move, hidden_sides and height_seen; with --catalogue a
                          second class, the entry the box fits), or none when no box is in view
  support                 SupportPlane: the surface the boxes stand on (normal, offset, inlier
                          share, tilt from the world's up)
Both are in world_frame; with no pose at all (--pose-source none, or no tf_static within a few
seconds) they are in the picture's own frame, "up" being the surface's normal.

Every 2 s it logs the latest measurement, as the seed did:
  box: middle (+0.065, +0.040) m, height 0.060 m, from 2,445 points on its top
one line a box when there are several (with its size and turn), or says that no box is in
view, or what it is waiting for. Queues are bounded: when it falls behind it keeps the newest
capture, and says how many it dropped. A message it cannot use (garbage, the wrong type, a size
or step that does not fit its data, all NaN, no matching camera info, a stamp going back) is
logged with its key once per interval and dropped.

--method seed measures the seed's way instead (one box: the readings within a millimetre of the
highest one, over a table at table_z), kept as the reference.

Settings (flag > environment variable > config/onebox.toml > default) are listed below.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from onebox import bus, geometry, keys, memory, pictures, settings, sync
from onebox.errors import SettingError
from onebox.geometry import FrameError, FrameTree, matrix_of
from onebox.perception import kernels, register, seed
from onebox.perception.boxes import MAX_PIXELS, Box, FinderSettings, Found
from onebox.perception.catalogue import Entry, read_catalogue
from onebox.perception.stream import BoxFinder
from onebox.rectify import Rectifier, lens_of
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
    Quaternion,
    SupportPlane,
    TFMessage,
    TransformStamped,
    Vector3,
)

log = logging.getLogger("locator")

MATCH_TIMEOUT_S = 1.0
"""How long a depth picture waits for its camera info (or pose) before it is reported."""
COLOUR_WAIT_S = 0.05
"""How long a matched capture waits for its colour picture once colour has been seen."""
POSE_WAIT_S = 3.0
"""How long after starting a picture with no transform to world_frame is dropped (tf_static
is on its way) before the locator settles for the camera's own frame."""
LUMPY_PX = 0.5
"""Lumps narrower than this (pixels) are not mentioned: the errors are all but independent."""


def optional_metres(text: str) -> float | None:
    """A setting that is a number of metres, or empty / ``auto`` for "find it"."""
    if text.strip().lower() in {"", "auto", "none"}:
        return None
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text!r} is not a number of metres")
    return value


def workspace_limits(text: str) -> tuple[tuple[float, float], ...] | None:
    """``XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX`` metres, or empty for none."""
    if not text.strip():
        return None
    numbers = [float(part) for part in text.split(",")]
    if len(numbers) != 6 or not all(math.isfinite(n) for n in numbers):
        raise ValueError(f"{text!r}: expected six numbers XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX")
    pairs = tuple((numbers[i], numbers[i + 1]) for i in range(0, 6, 2))
    if any(low >= high for low, high in pairs):
        raise ValueError(f"{text!r}: each minimum must be below its maximum")
    return pairs


def colour_shift(text: str) -> tuple[int, int] | None:
    """``DY,DX`` whole pixels, or ``auto`` (None: measured from the pictures)."""
    if text.strip() == "auto":
        return None
    parts = text.split(",")
    try:
        dy, dx = (int(part) for part in parts)
    except ValueError:
        raise ValueError(f"{text!r}: expected auto or two whole numbers DY,DX") from None
    if max(abs(dy), abs(dx)) > register.REACH_PX * 4:
        raise ValueError(f"{text!r}: more than {register.REACH_PX * 4} pixels off")
    return dy, dx


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)
    group = parser.add_argument_group("locator")
    settings.add(group, "world_frame", "world", "the frame the boxes are reported in")
    settings.add(
        group,
        "table_z",
        "auto",
        "the surface is the world plane at this height, metres, instead of the plane found in "
        "the picture; auto finds it",
        kind=optional_metres,
    )
    settings.add(group, "min_height", 0.01, "how far above the surface a box's top must be, metres")
    settings.add(
        group,
        "noise_sigma",
        "auto",
        "the depth's noise (one sigma, metres, near the surface); auto measures it on the surface",
        kind=optional_metres,
    )
    settings.add(
        group,
        "workspace",
        "",
        "report only boxes whose top middle lies within XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX (metres, "
        "world_frame), e.g. to leave out a robot or a machine at the edge of the view; write "
        "--workspace=-0.5,... when the first number is negative",
        kind=str,
    )
    settings.add(
        group,
        "max_height",
        "auto",
        "ignore anything standing higher than this above the surface, metres",
        kind=optional_metres,
    )
    settings.add(
        group,
        "max_pixels",
        MAX_PIXELS,
        "pictures with more pixels are read at every k-th pixel to keep up with the camera "
        "(1280 x 720 at every 2nd); 0 reads every pixel",
    )
    group.add_argument(
        "--method",
        choices=("boxes", "seed"),
        default="boxes",
        help="boxes: every box, oriented (the default); seed: the seed's one-box measurement",
    )
    settings.add(
        group,
        "colour_shift",
        "auto",
        "how far the colour picture lies off the depth, DY,DX whole pixels (its pixel "
        "(v + DY, u + DX) shows the depth's (v, u)); auto measures it from the pictures; 0,0 "
        "takes them as aligned; write --colour-shift=-1,2 when the first number is negative",
        kind=str,
    )
    group.add_argument(
        "--no-colour",
        dest="colour",
        action="store_false",
        help="measure from depth alone, even when a colour picture comes",
    )
    group.add_argument(
        "--catalogue",
        type=Path,
        metavar="FILE.toml",
        help="the box sizes the site handles ([[box]] tables: name, length, width, height in "
        "metres): a top that fits one takes its height, and its name as a second class",
    )
    match = parser.add_argument_group("matching")
    settings.add(
        match,
        "slop_ms",
        0.0,
        "pair a depth picture with camera info, colour (and pose) stamped up to this many "
        "milliseconds apart; 0 pairs equal stamps only, as the simulated camera sends",
    )
    match.add_argument(
        "--pose-source",
        choices=("tf", "pose", "none"),
        default="tf",
        help="where the camera is: the chain on tf_static (a fixed camera, the default), "
        "camera/pose matched by stamp (a camera that moves), or none (report in the camera's "
        "own frame)",
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


@dataclass(frozen=True)
class LocatorSettings:
    """The locator's settings, checked."""

    world_frame: str = "world"
    table_z_m: float | None = None
    min_height_m: float = 0.01
    noise_sigma_m: float | None = None
    workspace: tuple[tuple[float, float], ...] | None = None
    max_height_m: float | None = None
    max_pixels: int = MAX_PIXELS
    colour_shift: tuple[int, int] | None = None
    method: str = "boxes"
    use_colour: bool = True
    catalogue: tuple[Entry, ...] = ()
    slop_ns: int = 0
    pose_source: str = "tf"
    queue_size: int = 4
    log_interval_s: float = 2.0
    frames: int | None = None
    duration_s: float | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> LocatorSettings:
        """Check the parsed flags; raises SettingError naming the one that cannot be used."""
        if args.min_height < 0:
            raise SettingError(f"min_height {args.min_height}: must be 0 or more (metres)")
        if args.slop_ms < 0:
            raise SettingError(f"slop_ms {args.slop_ms}: must be 0 or more (milliseconds)")
        if args.queue_size < 1:
            raise SettingError(f"--queue-size {args.queue_size}: must be at least 1")
        if args.log_interval_s <= 0:
            raise SettingError(f"--log-interval-s {args.log_interval_s}: must be above 0")
        if args.noise_sigma is not None and args.noise_sigma <= 0:
            raise SettingError(f"noise_sigma {args.noise_sigma}: must be above 0 (metres)")
        if args.max_pixels < 0:
            raise SettingError(f"max_pixels {args.max_pixels}: must be 0 (every pixel) or more")
        if args.max_height is not None and args.max_height <= args.min_height:
            raise SettingError(f"max_height {args.max_height}: must be above min_height")
        if args.table_z is not None and args.pose_source == "none":
            raise SettingError("table_z is a height in world_frame: it needs a camera pose")
        if args.method == "seed" and args.pose_source == "none":
            raise SettingError("--method seed measures over a world table: it needs a pose")
        try:
            workspace = workspace_limits(args.workspace)
        except ValueError as e:
            raise SettingError(f"workspace {e}") from e
        try:
            shift = colour_shift(args.colour_shift)
        except ValueError as e:
            raise SettingError(f"colour_shift {e}") from e
        return cls(
            world_frame=args.world_frame,
            table_z_m=args.table_z,
            min_height_m=args.min_height,
            noise_sigma_m=args.noise_sigma,
            workspace=workspace,
            max_height_m=args.max_height,
            max_pixels=args.max_pixels,
            colour_shift=shift,
            method=args.method,
            use_colour=args.colour,
            catalogue=() if args.catalogue is None else read_catalogue(args.catalogue),
            slop_ns=round(args.slop_ms * 1e6),
            pose_source=args.pose_source,
            queue_size=args.queue_size,
            log_interval_s=args.log_interval_s,
            frames=args.frames,
            duration_s=args.duration_s,
        )

    def finder(self) -> FinderSettings:
        return FinderSettings(
            min_height_m=self.min_height_m,
            noise_sigma_m=self.noise_sigma_m,
            table_z_m=self.table_z_m,
            workspace=self.workspace,  # type: ignore[arg-type]
            max_height_m=self.max_height_m,
            max_pixels=self.max_pixels or None,
            colour_shift=self.colour_shift,
            catalogue=self.catalogue,
        )


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
    """The pinhole the maths measures with (P's when the camera's lens distorts)."""
    rectifier: Rectifier | None = None
    """Remaps a distorted camera's pictures onto ``intrinsics`` first."""


@dataclass(frozen=True)
class Result:
    """The outcome of one picture, kept for the log every few seconds."""

    stamp_ns: int
    found: Found | None = None
    seed_box: seed.BoxMeasurement | None = None
    frame: str = "world"


class ColourCache:
    """The last few colour pictures by stamp, for the worker to pick its capture's colour."""

    def __init__(self, keep: int = 4) -> None:
        self._pictures: dict[int, npt.NDArray[np.uint8]] = {}
        self._keep = keep
        self._ready = threading.Condition()
        self.last_seen_s = -math.inf

    def put(self, stamp_ns: int, rgb: npt.NDArray[np.uint8]) -> None:
        with self._ready:
            if self._pictures and stamp_ns < max(self._pictures):
                # The camera's clock went back (a restarted sim or replay): the pictures kept
                # are of another run, and their stamps would match this run's depth later.
                self._pictures.clear()
            self._pictures[stamp_ns] = rgb
            while len(self._pictures) > self._keep:
                del self._pictures[min(self._pictures)]
            self.last_seen_s = time.monotonic()
            self._ready.notify_all()

    def take(self, stamp_ns: int, slop_ns: int, wait_s: float) -> npt.NDArray[np.uint8] | None:
        """The colour picture nearest ``stamp_ns`` (within ``slop_ns``), waiting up to ``wait_s``
        for it when colour has been arriving lately; None when there is none."""

        def nearest() -> npt.NDArray[np.uint8] | None:
            if not self._pictures:
                return None
            stamp = min(self._pictures, key=lambda s: abs(s - stamp_ns))
            return self._pictures[stamp] if abs(stamp - stamp_ns) <= slop_ns else None

        with self._ready:
            if time.monotonic() - self.last_seen_s > 2.0:
                return None  # no colour lately: depth alone, without waiting
            self._ready.wait_for(lambda: nearest() is not None, timeout=wait_s)
            return nearest()


def _quaternion(q: tuple[float, float, float, float]) -> Quaternion:
    return Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def _vector(v: tuple[float, float, float]) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def detection_array(found: Found, stamp_ns: int, frame_id: str) -> Detection3DArray:
    """The message for one picture: every box, topmost first."""
    header = Header(stamp_ns=stamp_ns, frame_id=frame_id)
    detections = [
        Detection3D(
            header=header,
            results=[ObjectHypothesis(class_id="box", score=float(box.score))]
            + ([ObjectHypothesis(class_id=box.name, score=float(box.score))] if box.name else []),
            bbox=BoundingBox3D(
                center=Pose(
                    position=_vector(box.centre), orientation=_quaternion(box.quaternion_xyzw)
                ),
                size=_vector(box.size),
            ),
            id=str(box.id),
            hidden_sides=box.hidden_sides,
            height_seen=box.height_seen,
        )
        for box in found.boxes
    ]
    return Detection3DArray(header=header, detections=detections)


def seed_detection_array(
    box: seed.BoxMeasurement | None, stamp_ns: int, world_frame: str, table_z: float
) -> Detection3DArray:
    """The message for one picture measured the seed's way: one box, or none."""
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


def support_message(found: Found, stamp_ns: int, frame_id: str) -> SupportPlane | None:
    support = found.support
    if support is None:
        return None
    return SupportPlane(
        header=Header(stamp_ns=stamp_ns, frame_id=frame_id),
        normal=_vector(support.normal),
        offset_m=float(support.offset_m),
        inlier_share=float(support.inlier_share),
        tilt_deg=None if support.tilt_deg is None else float(support.tilt_deg),
    )


def seed_box_line(box: seed.BoxMeasurement) -> str:
    """The seed's log line."""
    return (
        f"box: middle ({box.x:+.3f}, {box.y:+.3f}) m, height {box.height:.3f} m, "
        f"from {box.top_count:,} points on its top"
    )


def box_line(box: Box, several: bool) -> str:
    """The seed's line for one box; with several, each names its id, size and turn."""
    x, y = box.top_middle[0], box.top_middle[1]
    if not several:
        return (
            f"box: middle ({x:+.3f}, {y:+.3f}) m, height {box.size[2]:.3f} m, "
            f"from {box.top_pixels:,} points on its top"
        )
    on = f", on box {box.on}" if box.on is not None else ""
    return (
        f"box {box.id}: middle ({x:+.3f}, {y:+.3f}) m, height {box.size[2]:.3f} m, "
        f"{box.size[0]:.3f} x {box.size[1]:.3f} m turned {box.yaw_deg:+.1f} deg{on}, "
        f"from {box.top_pixels:,} points on its top"
    )


def describe_pose(matrix: geometry.Float64Array | None) -> str:
    """A camera's place in a log line: where it is and how it is turned."""
    if matrix is None:
        return "not connected"
    x, y, z = matrix[:3, 3]
    r, p, w = Rotation.from_matrix(matrix[:3, :3]).as_euler("xyz", degrees=True)
    return f"at ({x:+.3f}, {y:+.3f}, {z:+.3f}) m, rpy ({r:+.1f}, {p:+.1f}, {w:+.1f}) deg"


class Locator:
    """Matches depth, camera info (and pose), measures on a worker thread, publishes."""

    def __init__(self, b: bus.Bus, config: LocatorSettings) -> None:
        self._bus = b
        self._config = config
        self._world_frame = config.world_frame
        self._use_pose = config.pose_source == "pose"
        self._keys = {
            "depth": b.key(keys.CAMERA.depth),
            "info": b.key(keys.CAMERA.info),
            "colour": b.key(keys.CAMERA.colour),
            "pose": b.key(keys.CAMERA.pose),
            "tf": b.key(keys.TF_STATIC),
        }
        self._report = sync.ReportLimiter(log, interval_s=config.log_interval_s)
        streams = ["depth", "info", "pose"] if self._use_pose else ["depth", "info"]
        self._matcher = StampMatcher(
            streams,
            slop_ns=config.slop_ns,
            queue_size=config.queue_size,
            on_unmatched=self._unmatched,
        )
        self._matched: sync.NewestQueue[dict[str, Stamped]] = sync.NewestQueue(maxlen=2)
        self._colour = ColourCache()
        self._clock = StampClock()
        self._tree = FrameTree(roots=[self._world_frame])
        self._tree_lock = threading.Lock()
        self._camera_cache: tuple[int, str, geometry.Float64Array] | None = None
        self._camera_chain: tuple[str, geometry.Float64Array | None] | None = None
        """The camera's frame and world_frame <- it as last used, to say when tf_static moves it."""
        self._said_rectified = False
        self._finder = BoxFinder(config.finder())
        if config.method == "boxes":
            # Compile the finder's kernels (or load them from the cache) now, not on the
            # first picture.
            started = time.monotonic()
            kernels.warm_up()
            log.info("finder ready in %.1f s", time.monotonic() - started)
        self._said_shift = self._finder.registration.shift
        self._started_s = time.monotonic()
        self._detections = b.publisher(keys.DETECTIONS, Detection3DArray)
        self._support = b.publisher(keys.SUPPORT, SupportPlane)
        self.published = 0
        self.measure_s = 0.0
        """Time spent measuring since the last log line."""
        self.measured = 0
        self.latest: Result | None = None

    def subscribe(self) -> None:
        self._bus.subscribe(keys.CAMERA.depth, Image, self._on_depth)
        self._bus.subscribe(keys.CAMERA.info, CameraInfo, self._on_info)
        if self._config.use_colour and self._config.method == "boxes":
            self._bus.subscribe(keys.CAMERA.colour, Image, self._on_colour)
        if self._config.pose_source == "tf":
            self._bus.subscribe(keys.TF_STATIC, TFMessage, self._on_tf, history=True)
        if self._use_pose:
            self._bus.subscribe(keys.CAMERA.pose, TransformStamped, self._on_pose)

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

    def _on_colour(self, key: str, image: Image) -> None:
        try:
            rgb = pictures.rgb(image)
        except pictures.ImageError as e:
            self._report.warn(key, e.kind, f"dropped: {e}")
            return
        self._colour.put(image.header.stamp_ns, rgb)

    def _on_info(self, key: str, info: CameraInfo) -> None:
        try:
            lens = Lens(info.width, info.height, *lens_of(info))
        except ValueError as e:
            self._report.warn(key, "lens", f"dropped: {e}")
            return
        if lens.rectifier is not None and not self._said_rectified:
            self._said_rectified = True
            log.info(
                "%s: the lens has %s distortion; its pictures are rectified (nearest pixel) "
                "onto fx %.1f, fy %.1f, cx %.1f, cy %.1f before they are measured",
                key,
                info.distortion_model,
                lens.intrinsics.fx,
                lens.intrinsics.fy,
                lens.intrinsics.cx,
                lens.intrinsics.cy,
            )
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
            try:
                self._tree.add_all(message.transforms)
            except FrameError as e:
                self._report.warn(
                    key,
                    "transform",
                    f"refused a message of {len(message.transforms):,} transforms, all of it: {e}",
                )
                return
            if self._camera_chain is None:
                return
            camera, before = self._camera_chain
            try:
                after: geometry.Float64Array | None = self._tree.lookup(self._world_frame, camera)
            except FrameError:
                after = None
            if before is None and after is None:
                return
            if before is not None and after is not None and np.allclose(before, after, atol=1e-9):
                return
            self._camera_chain = (camera, after)
        log.warning(
            "%s: the camera's chain changed: %s in %s was %s, now %s",
            key,
            camera,
            self._world_frame,
            describe_pose(before),
            describe_pose(after),
        )

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

    def _camera_to_world(
        self, frame: DepthFrame, found: dict[str, Stamped]
    ) -> geometry.Float64Array | None:
        """world_frame <- the picture's frame; None to report in the picture's own frame.
        Raises FrameError when the picture must wait for its transform."""
        if self._config.pose_source == "none":
            return None
        if self._use_pose:
            child, matrix = found["pose"].item
            if child != frame.frame_id:
                raise FrameError(
                    f"camera/pose is of {child!r} but the depth picture is in {frame.frame_id!r}"
                )
            result: geometry.Float64Array = matrix
            return result
        with self._tree_lock:
            cached = self._camera_cache
            if cached is not None and cached[:2] == (self._tree.version, frame.frame_id):
                return cached[2]
            try:
                matrix = self._tree.lookup(self._world_frame, frame.frame_id)
            except FrameError:
                self._camera_chain = (frame.frame_id, None)
                if self._tree.frames or time.monotonic() - self._started_s < POSE_WAIT_S:
                    raise
                self._report.warn(
                    self._keys["tf"],
                    "no-pose",
                    f"nothing on {self._keys['tf']} places {frame.frame_id!r}: reporting in "
                    f"{frame.frame_id!r} itself, up being the surface's normal",
                )
                return None
            self._camera_cache = (self._tree.version, frame.frame_id, matrix)
            self._camera_chain = (frame.frame_id, matrix)
            return matrix

    def process(self, found: dict[str, Stamped]) -> None:
        """Measure one matched capture and publish its detections and support."""
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
        if camera_to_world is None and self._config.method == "seed":
            self._report.warn(
                depth_key,
                "seed-no-pose",
                f"--method seed needs the camera's pose, and nothing places {frame.frame_id!r} "
                f"in {self._world_frame!r}: depth picture stamped {frame.stamp_ns:,} ns dropped",
            )
            return
        if not seed.has_reading(frame.depth_m):
            self._report.warn(
                depth_key,
                "no-reading",
                f"depth picture stamped {frame.stamp_ns:,} ns has no reading at all "
                "(every pixel NaN, 0 or infinite), dropped",
            )
            return
        frame_id = self._world_frame if camera_to_world is not None else frame.frame_id
        started = time.perf_counter()
        depth_m = frame.depth_m if lens.rectifier is None else lens.rectifier.depth(frame.depth_m)
        if self._config.method == "seed":
            assert camera_to_world is not None  # dropped above without one
            table_z = self._config.table_z_m or 0.0
            box = seed.locate_box(
                depth_m, lens.intrinsics, camera_to_world, table_z, self._config.min_height_m
            )
            self._count(started)
            self._detections.publish(
                seed_detection_array(box, frame.stamp_ns, self._world_frame, table_z)
            )
            result = Result(frame.stamp_ns, seed_box=box, frame=frame_id)
        else:
            colour = self._colour_for(frame)
            if colour is not None and lens.rectifier is not None:
                colour = lens.rectifier.colour(colour)
            found_boxes = self._finder(depth_m, lens.intrinsics, camera_to_world, colour)
            self._count(started)
            self._say_registration()
            self._detections.publish(detection_array(found_boxes, frame.stamp_ns, frame_id))
            support = support_message(found_boxes, frame.stamp_ns, frame_id)
            if support is not None:
                self._support.publish(support)
            result = Result(frame.stamp_ns, found=found_boxes, frame=frame_id)
        self.published += 1
        self.latest = result

    def _say_registration(self) -> None:
        measured = self._finder.registration
        if measured.shift != self._said_shift:
            self._said_shift = measured.shift
            log.info(
                "%s: the colour picture lies %s (measured on %d depth jumps, %.1f standard "
                "errors); it is moved back before it is read (--colour-shift sets it)",
                self._keys["colour"],
                measured,
                measured.jumps,
                measured.t,
            )

    def _colour_for(self, frame: DepthFrame) -> npt.NDArray[np.uint8] | None:
        if not self._config.use_colour:
            return None
        rgb = self._colour.take(frame.stamp_ns, self._config.slop_ns, COLOUR_WAIT_S)
        if rgb is not None and rgb.shape[:2] != frame.depth_m.shape:
            self._report.warn(
                self._keys["colour"],
                "size",
                f"colour picture is {rgb.shape[1]} x {rgb.shape[0]} but depth is "
                f"{frame.depth_m.shape[1]} x {frame.depth_m.shape[0]}: not aligned with the "
                "depth, measuring from depth alone",
            )
            return None
        return rgb

    def _count(self, started: float) -> None:
        self.measure_s += time.perf_counter() - started
        self.measured += 1

    def log_latest(self, since: Result | None) -> None:
        """The seed's line about the newest measurement, or what is missing."""
        latest = self.latest
        if latest is not None and latest is not since:
            for line in self.result_lines(latest):
                log.info(line)
            return
        waiting = [self._keys["depth"], self._keys["info"]]
        if self._use_pose:
            waiting.append(self._keys["pose"])
        elif self._config.pose_source == "tf":
            waiting.append(self._keys["tf"])
        log.info("waiting: no capture measured lately; needs %s", ", ".join(waiting))

    def result_lines(self, result: Result) -> list[str]:
        """The log lines of one measurement."""
        if self._config.method == "seed":
            if result.seed_box is not None:
                return [seed_box_line(result.seed_box)]
            return [
                f"no box in view: nothing stands more than {self._config.min_height_m:.3f} m "
                f"above the table (table_z {self._config.table_z_m or 0.0:.3f} m in "
                f"{self._world_frame})"
            ]
        found = result.found
        assert found is not None
        if found.support is None:
            return ["no surface found: no large flat plane in the picture to stand boxes on"]
        if not found.boxes:
            return [
                f"no box in view: nothing flat stands more than {self._config.min_height_m:.3f} "
                f"m above the surface ({describe_support(found, result.frame)})"
            ]
        several = len(found.boxes) > 1
        lines = [box_line(box, several) for box in found.boxes]
        if several:
            lines.insert(0, f"{len(found.boxes)} boxes ({describe_support(found, result.frame)}):")
        return lines

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
                try:
                    self.process(found)
                except Exception as e:  # one bad picture must never stop the locator
                    log.exception(
                        "%s: measuring a capture failed, dropped: %s", self._keys["depth"], e
                    )
            if time.monotonic() >= next_log:
                self._matcher.expire(MATCH_TIMEOUT_S)
                memory.trim()
                self.log_latest(logged)
                logged = self.latest
                if self._matched.dropped > dropped:
                    log.warning(
                        "dropped %d captures in the last %g s: measuring (%.1f ms a picture) is "
                        "slower than the camera, so the newest is kept",
                        self._matched.dropped - dropped,
                        interval_s,
                        1000 * self.measure_s / max(self.measured, 1),
                    )
                    dropped = self._matched.dropped
                self.measure_s, self.measured = 0.0, 0
                next_log = time.monotonic() + interval_s


def describe_support(found: Found, frame: str) -> str:
    support = found.support
    assert support is not None
    n = support.normal
    where = f"surface {-support.offset_m:+.3f} m along ({n[0]:+.2f}, {n[1]:+.2f}, {n[2]:+.2f})"
    tilt = f", {support.tilt_deg:.1f} deg from level" if support.tilt_deg is not None else ""
    noise = f", depth noise {1000 * support.sigma_m:.1f} mm at {support.distance_m:.2f} m"
    if support.lump_px >= LUMPY_PX:
        noise += f" in lumps {support.lump_px:.1f} px wide"
    return f"{where} in {frame}{tilt}{noise}"


def main(args: argparse.Namespace) -> int:
    """Subscribe, measure every matched capture, publish detections, log every interval."""
    config = LocatorSettings.from_args(args)
    memory.bound_heap()  # before Zenoh's threads start: pictures must not fragment the heap
    with bus.open_bus(args) as b:
        locator = Locator(b, config)
        locator.subscribe()
        source = {
            "tf": b.key(keys.TF_STATIC),
            "pose": b.key(keys.CAMERA.pose),
            "none": "nowhere (reporting in the camera's frame)",
        }[config.pose_source]
        log.info(
            "finding %s in %s with %s, camera from %s; detections in %s on %s",
            "every box" if config.method == "boxes" else "the box the seed's way",
            b.key(keys.CAMERA.depth),
            b.key(keys.CAMERA.info),
            source,
            config.world_frame,
            b.key(keys.DETECTIONS),
        )
        try:
            locator.run(config.frames, config.duration_s, config.log_interval_s)
        finally:
            log.info("published %d detection arrays", locator.published)
    return 0
