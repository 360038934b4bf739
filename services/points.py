"""onebox points: depth and colour into a coloured point cloud (the seed's depth_image_proc).

Reads (keys under --namespace), matched by header.stamp_ns (exactly, or within --slop-ms):
  camera/depth/image_raw  Image, 32FC1 metres (NaN = no reading) or 16UC1 millimetres (0 = no
                          reading)
  camera/image_raw        Image, rgb8 (also bgr8, rgba8, bgra8, mono8), the same size
  camera/camera_info      CameraInfo: the lens (fx, fy, cx, cy from K); a lens with
                          distortion has its pictures rectified onto P's pinhole first
Writes:
  camera/points           PointCloud in the depth picture's frame (camera_optical_frame), one
                          point a pixel with a reading: x, y, z float32 metres and rgb uint32
                          0x00RRGGBB, 16 bytes a point; pixels with no reading are skipped, so
                          the cloud is dense. One cloud a capture, stamped like the capture.

The middle of pixel u is at u, as CameraInfo and depth_image_proc have it. A message it cannot
use is logged with its key once per interval and dropped.
"""

from __future__ import annotations

import argparse
import logging
import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onebox import bus, geometry, pictures, settings, sync
from onebox.errors import SettingError
from onebox.rectify import lens_of
from onebox.sync import StampClock, Stamped, StampMatcher
from schemas import FLOAT32, UINT32, CameraInfo, Header, Image, PointCloud, PointField

log = logging.getLogger("points")

DEPTH_KEY = "camera/depth/image_raw"
COLOUR_KEY = "camera/image_raw"
INFO_KEY = "camera/camera_info"
POINTS_KEY = "camera/points"
MATCH_TIMEOUT_S = 1.0

FIELDS = [
    PointField(name="x", offset=0, datatype=FLOAT32),
    PointField(name="y", offset=4, datatype=FLOAT32),
    PointField(name="z", offset=8, datatype=FLOAT32),
    PointField(name="rgb", offset=12, datatype=UINT32),
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)
    settings.add(
        parser,
        "slop_ms",
        0.0,
        "pair messages stamped up to this many milliseconds apart; 0 pairs equal stamps only",
    )
    parser.add_argument(
        "--frames", type=int, metavar="N", help="stop after publishing N point clouds"
    )
    parser.add_argument(
        "--log-interval-s",
        type=float,
        default=2.0,
        metavar="S",
        help="how often to say how many clouds were published (default 2)",
    )


def point_cloud(
    depth_m: geometry.Float32Array,
    lens: geometry.Intrinsics,
    colour: npt.NDArray[np.uint8] | None,
    header: Header,
) -> PointCloud:
    """The cloud message of one capture."""
    points = pictures.cloud_points(depth_m, lens, colour)
    return PointCloud(
        header=header,
        height=1,
        width=len(points),
        fields=FIELDS,
        point_step=pictures.CLOUD_DTYPE.itemsize,
        row_step=pictures.CLOUD_DTYPE.itemsize * len(points),
        data=points.tobytes(),
        is_dense=True,
    )


@dataclass(frozen=True)
class PointsSettings:
    """What ``onebox points`` was asked to do, checked."""

    slop_ns: int
    frames: int | None
    log_interval_s: float

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> PointsSettings:
        if not args.slop_ms >= 0:
            raise SettingError(f"slop_ms {args.slop_ms}: must be 0 or more (milliseconds)")
        if not args.log_interval_s > 0:
            raise SettingError(f"--log-interval-s {args.log_interval_s}: must be above 0")
        if args.frames is not None and args.frames < 1:
            raise SettingError(f"--frames {args.frames}: must be at least 1")
        return cls(round(args.slop_ms * 1e6), args.frames, args.log_interval_s)


class Points:
    """Decodes in the Zenoh callbacks, matches by stamp, builds clouds on the main thread."""

    def __init__(self, b: bus.Bus, config: PointsSettings) -> None:
        self._bus = b
        self._report = sync.ReportLimiter(log, interval_s=config.log_interval_s)
        self._matcher = StampMatcher(
            ["depth", "colour", "info"],
            slop_ns=config.slop_ns,
            on_unmatched=self._unmatched,
        )
        self._matched: sync.NewestQueue[dict[str, Stamped]] = sync.NewestQueue(maxlen=2)
        self._clock = StampClock()
        self._publisher = b.publisher(POINTS_KEY, PointCloud)
        self.published = 0

    def subscribe(self) -> None:
        self._bus.subscribe(DEPTH_KEY, Image, self._on_depth)
        self._bus.subscribe(COLOUR_KEY, Image, self._on_colour)
        self._bus.subscribe(INFO_KEY, CameraInfo, self._on_info)

    def _offer(self, key: str, stream: str, stamp_ns: int, item: object) -> None:
        if not self._clock.accept(key, stamp_ns, self._report, self._matcher):
            return
        matched = self._matcher.add(stream, stamp_ns, item)
        if matched is not None:
            self._matched.put(matched)

    def _on_depth(self, key: str, image: Image) -> None:
        try:
            depth_m = pictures.depth_m(image)
        except pictures.ImageError as e:
            self._report.warn(key, e.kind, f"dropped: {e}")
            return
        self._offer(key, "depth", image.header.stamp_ns, (image.header, depth_m))

    def _on_colour(self, key: str, image: Image) -> None:
        try:
            rgb = pictures.rgb(image)
        except pictures.ImageError as e:
            self._report.warn(key, e.kind, f"dropped: {e}")
            return
        self._offer(key, "colour", image.header.stamp_ns, rgb)

    def _on_info(self, key: str, info: CameraInfo) -> None:
        try:
            lens, rectifier = lens_of(info)
        except ValueError as e:
            self._report.warn(key, "lens", f"dropped: {e}")
            return
        self._offer(key, "info", info.header.stamp_ns, (info.width, info.height, lens, rectifier))

    def _unmatched(self, stamped: Stamped, why: str) -> None:
        self._report.warn(
            self._bus.key(DEPTH_KEY),
            "unmatched",
            f"depth picture stamped {stamped.stamp_ns:,} ns dropped: no colour picture and "
            f"camera info to match ({why})",
        )

    def process(self, found: dict[str, Stamped]) -> None:
        header, depth_m = found["depth"].item
        rgb = found["colour"].item
        width, height, lens, rectifier = found["info"].item
        if depth_m.shape != (height, width) or rgb.shape[:2] != depth_m.shape:
            self._report.warn(
                self._bus.key(DEPTH_KEY),
                "size",
                f"depth {depth_m.shape[1]} x {depth_m.shape[0]}, colour {rgb.shape[1]} x "
                f"{rgb.shape[0]} and camera info {width} x {height} differ; dropped",
            )
            return
        if rectifier is not None:
            depth_m, rgb = rectifier.depth(depth_m), rectifier.colour(rgb)
        self._publisher.publish(point_cloud(depth_m, lens, rgb, header))
        self.published += 1

    def run(self, frames: int | None, interval_s: float) -> None:
        next_log = time.monotonic() + interval_s
        logged = 0
        while frames is None or self.published < frames:
            found = self._matched.get(timeout_s=0.25)
            if found is not None:
                self.process(found)
            if time.monotonic() >= next_log:
                self._matcher.expire(MATCH_TIMEOUT_S)
                if self.published == logged:
                    log.info(
                        "waiting: no cloud lately; needs %s, %s and %s",
                        *(self._bus.key(k) for k in (DEPTH_KEY, COLOUR_KEY, INFO_KEY)),
                    )
                logged = self.published
                next_log = time.monotonic() + interval_s


def main(args: argparse.Namespace) -> int:
    """Turn every matched depth + colour + camera info into camera/points."""
    config = PointsSettings.from_args(args)
    with bus.open_bus(args) as b:
        points = Points(b, config)
        points.subscribe()
        log.info(
            "clouds from %s and %s on %s", b.key(DEPTH_KEY), b.key(COLOUR_KEY), b.key(POINTS_KEY)
        )
        try:
            points.run(config.frames, config.log_interval_s)
        finally:
            log.info("published %d point clouds", points.published)
    return 0
