"""onebox's messages as Rerun entities: what RViz's displays did in the seed.

One :class:`SceneLog` turns each message into Rerun archetypes on one recording, on the
``sim_time`` timeline (the message's ``header.stamp_ns``), so the live viewer and
``onebox view FILE.mcap`` show the same thing. The entities mirror the frames:

- ``world``: right-handed, Z up; the table (its top at ``table_z``, with the 5 cm grid);
- ``world/camera_link``, ``world/camera_link/camera_optical_frame``: ``tf_static``'s chain, with
  axes, static;
- ``world/camera``: the camera at its pose (``camera/pose``, world -> camera_optical_frame, or,
  until a pose arrives, the chain on ``tf_static`` to the pictures' frame);
  ``world/camera/image`` the pinhole (``camera/camera_info``), with ``.../rgb`` the colour
  picture (JPEG in a saved recording, raw pixels live) and ``.../depth`` the depth picture
  under it; ``world/camera/points`` the point cloud, thinned, only when asked for;
- ``world/detections``: each detected box as an oriented see-through box labelled with its id,
  size in millimetres and yaw; ``world/support`` the plane the boxes stand on, a translucent
  patch; ``world/ground_truth`` the simulator's true boxes, as thin green wireframes.

What never changes (the table, tf_static's frames, the lens) is logged static, so a viewer that
joins late, or one that has dropped old data to stay within its memory, still has it.

Every message is checked before anything is logged (:class:`BadMessage`): a stamp outside
0..2^63 ns, a number that is not finite, a zero quaternion, a tf_static that would make a cycle,
give the world frame a parent or a chain deeper than :data:`MAX_CHAIN` frames, a picture or cloud
whose sizes do not fit its bytes. The caller reports it with its key and goes on.

:func:`blueprint` is the seed's ``config/one_box.rviz``: the 3D view beside colour and depth.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt
import rerun as rr
import rerun.blueprint as rrb
from scipy.spatial.transform import Rotation

from onebox import pictures
from schemas import (
    FLOAT32,
    UINT32,
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
from schemas.base import Header
from schemas.geometry import Pose, Quaternion, Vector3

log = logging.getLogger("rerun_log")

TIMELINE = "sim_time"
WORLD = "world"
DETECTIONS = f"{WORLD}/detections"
GROUND_TRUTH = f"{WORLD}/ground_truth"
SUPPORT = f"{WORLD}/support"
TABLE = f"{WORLD}/table"
WORLD_FRAME = "world"
"""The root of tf_static's tree: a transform that gives it a parent is refused."""
MAX_CHAIN = 64
"""The deepest chain of frames drawn; a deeper tf_static is refused (and cannot recurse)."""
MAX_STAMP_NS = 2**63 - 1
"""Rerun's timeline holds signed 64-bit nanoseconds."""
SUPPORT_COLOUR = (255, 200, 0, 70)
SUPPORT_HALF_M = 0.25
JPEG_QUALITY = 85
POINTS_STRIDE = 4
"""When the cloud is drawn, every 4th point of it: a 320 x 240 cloud becomes 19 200 points."""
POINTS_INTERVAL_NS = 1_000_000_000
"""...and at most once a simulated second."""
SAME = 1e-3
"""A live pose, support plane or set of true boxes whose numbers (metres, quaternion terms) all
changed by less than this since it was last sent is not sent again: 1 mm, about 0.1°."""
SAME_PLANE = 5e-3
"""...and for the found support plane, which moves a little with every capture's noise:
5 mm, about 0.3°."""
RESEND_NS = 1_000_000_000
"""Live, the support plane stays on the timeline (being found anew, it may change often,
and every static message is kept by the web server): sent again at least once a simulated
second, so the little history the server keeps always holds one."""

BOX_COLOUR = (0, 120, 255)
TRUTH_COLOUR = (0, 200, 80)
TABLE_COLOUR = (205, 205, 200)
"""Lighter than the table in the pictures, so the cloud's own grey stands out on it."""
GRID_COLOUR = (90, 90, 90)
GRID_SPACING_M = 0.05
POINT_RADIUS_M = 0.001
AXIS_LENGTH_M = 0.05
IMAGE_PLANE_M = 0.08
"""How far in front of the camera the pinhole's frustum ends and its picture is drawn."""


def camera_entity(camera: str) -> str:
    """The entity at the camera's pose: ``world/camera``."""
    return f"{WORLD}/{camera}"


def blueprint(camera: str = "camera") -> rrb.Blueprint:
    """The 3D view beside the colour and the depth picture, as the seed's RViz layout."""
    cam = camera_entity(camera)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                name="3D",
                origin=WORLD,
                # Not the depth picture back-projected (76,800 points a capture): a
                # software-rendered browser drew the page at 0.3 frames a second with it and
                # 1 to 3 without (benchmarks/bench_live_view.py). --points draws a thinned cloud.
                contents=["$origin/**", "- $origin/camera/image/depth"],
                eye_controls=rrb.EyeControls3D(
                    position=[0.36, -0.5, 0.42], look_target=[0.0, 0.02, 0.13], eye_up=[0, 0, 1]
                ),
                # The view's own endless grid is a full-view shader every frame: in a
                # software-rendered browser it held an empty view to 1 to 2 frames a second
                # (60 without it) and made the first frame with data seconds later. The
                # table's 5 cm grid is the floor to read; the background, white, is one colour.
                background=rrb.Background(
                    kind=rrb.BackgroundKind.SolidColor, color=[255, 255, 255]
                ),
                line_grid=rrb.LineGrid3D(visible=False),
            ),
            rrb.Vertical(
                rrb.Spatial2DView(name="colour", origin=f"{cam}/image", contents=["$origin/rgb"]),
                rrb.Spatial2DView(name="depth", origin=f"{cam}/image", contents=["$origin/depth"]),
            ),
            column_shares=[2, 1],
        ),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=True,
    )


def table_z_setting(text: str) -> float | None:
    """The table_z setting: a height in metres, or ``auto`` (the locator finds the surface;
    the table is drawn at 0 and the found plane on ``support``)."""
    if str(text).strip().lower() in {"auto", "none", ""}:
        return None
    return float(text)


def yaw_deg(q: Quaternion) -> float:
    """The turn of a quaternion about the world's up (z), degrees."""
    return math.degrees(math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)))


def box_label(name: str, size_m: tuple[float, float, float], yaw: float) -> str:
    """``box0: 60 x 40 x 30 mm, yaw +30°``."""
    sx, sy, sz = (round(v * 1000) for v in size_m)
    return f"{name}: {sx} x {sy} x {sz} mm, yaw {yaw:+.0f}°"


class BadMessage(ValueError):
    """A message the viewer will not draw; the text says what is wrong with it."""


def check_stamp(stamp_ns: int) -> None:
    if not 0 <= stamp_ns <= MAX_STAMP_NS:
        raise BadMessage(f"stamp {stamp_ns} ns is outside 0 to 2^63 ns")


def check_numbers(value: Any, where: str = "") -> None:
    """Every float finite and every header stamp in range, through nested structs and lists.

    Bytes (pixels, points) are not looked into: the pictures module checks their sizes.
    """
    if isinstance(value, float):
        if not math.isfinite(value):
            raise BadMessage(f"{where or 'a number'} is {value}")
    elif isinstance(value, msgspec.Struct):
        if isinstance(value, Header):
            check_stamp(value.stamp_ns)
        for name in value.__struct_fields__:
            check_numbers(getattr(value, name), f"{where}.{name}" if where else name)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            check_numbers(item, f"{where}[{i}]")


def unit_quaternion(q: Quaternion) -> rr.Quaternion:
    """``q`` normalised; a zero (or not finite) quaternion is no turn at all: refused."""
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if not math.isfinite(norm) or norm < 1e-6:
        raise BadMessage(f"quaternion ({q.x}, {q.y}, {q.z}, {q.w}) has no direction")
    return rr.Quaternion(xyzw=[q.x / norm, q.y / norm, q.z / norm, q.w / norm])


def check_cloud(message: PointCloud) -> None:
    """Each field inside one point, and the data long enough for every point."""
    sizes = {FLOAT32: 4, UINT32: 4}
    for f in message.fields:
        size = sizes.get(f.datatype, 8) * max(f.count, 1)
        if f.offset < 0 or f.offset + size > message.point_step:
            raise pictures.ImageError(
                f"field {f.name} at byte {f.offset} does not fit a point of "
                f"{message.point_step} bytes",
                "fields",
            )
    if message.width < 0 or message.height < 0:
        raise pictures.ImageError("a cloud of negative size", "size")


def grid_lines(half_m: float, z_m: float, spacing_m: float) -> npt.NDArray[np.float32]:
    """The table's printed grid: lines every ``spacing_m`` across a square of side 2 half_m."""
    ticks = np.arange(-half_m, half_m + spacing_m / 2, spacing_m)
    along_x = [[[-half_m, t, z_m], [half_m, t, z_m]] for t in ticks]
    along_y = [[[t, -half_m, z_m], [t, half_m, z_m]] for t in ticks]
    return np.asarray(along_x + along_y, dtype=np.float32)


def world_from_frame(
    static: dict[str, TransformStamped], frame: str
) -> tuple[npt.NDArray[np.float64], Rotation] | None:
    """The pose of ``frame`` in the root of the transform tree, or None when it is not in it."""
    translation = np.zeros(3)
    rotation = Rotation.identity()
    seen: set[str] = set()
    if frame not in static:
        return None
    while frame in static and frame not in seen:  # `seen` stops a loop in bad data
        seen.add(frame)
        t = static[frame].transform
        parent_rotation = Rotation.from_quat(
            [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w]
        )
        # parent <- frame applied after frame <- child: rotate, then shift.
        shift = np.array([t.translation.x, t.translation.y, t.translation.z])
        translation = parent_rotation.apply(translation) + shift
        rotation = parent_rotation * rotation
        frame = static[frame].header.frame_id
    return translation, rotation


def shrink_rgb(rgb: npt.NDArray[np.uint8], n: int) -> npt.NDArray[np.uint8]:
    """A colour picture ``n`` times smaller each way, each pixel the mean of its n x n block
    (edge rows and columns that do not fill a block are left out)."""
    if n <= 1:
        return rgb
    h, w = rgb.shape[0] // n * n, rgb.shape[1] // n * n
    blocks = rgb[:h, :w].reshape(h // n, n, w // n, n, -1).astype(np.uint16)
    shrunk: npt.NDArray[np.uint8] = (blocks.mean(axis=(1, 3)) + 0.5).astype(np.uint8)
    return shrunk


def pinhole_matrix(k: list[float]) -> npt.NDArray[np.float64]:
    """A CameraInfo K (the middle of pixel u at u) as Rerun's pinhole, whose pixel u spans u
    to u + 1: the principal point moves half a pixel."""
    matrix = np.asarray(k, dtype=np.float64).reshape(3, 3).copy()
    matrix[0, 2] += 0.5
    matrix[1, 2] += 0.5
    return matrix


@dataclass(frozen=True)
class Live:
    """What a live page is sent, thinner than a recording: a software-rendered browser takes
    data in only as fast as it draws (1 to 3 frames a second), so every message costs.

    ``picture_hz``: the colour and depth pictures at most this often (simulated time; 0: every
    one); the boxes still come with every capture. ``scale``: the pictures shrunk by this
    factor (the lens with them). The camera's pose and the true boxes are sent only when they
    change, as static data: the one copy a late page gets, kept by the web server however
    much temporal data its memory limit drops. The support plane is sent when it changes and
    at least every :data:`RESEND_NS`.
    """

    picture_hz: float = 1.0
    scale: int = 2


class SceneLog:
    """Logs onebox messages to one Rerun recording; the key decides what a message becomes.

    ``points``: draw camera/points too (thinned to every :data:`POINTS_STRIDE` th point, at
    most once per :data:`POINTS_INTERVAL_NS`); off by default, as the depth picture under the
    pinhole already shows the same points.

    ``jpeg``: send the colour picture as JPEG (a saved recording: a tenth of the bytes). Live,
    raw pixels: the web viewer decodes a JPEG after the frame that shows it, and with a new
    picture five times a second a software-rendered page showed only its loading spinner.

    ``live``: thin what is sent for a live page (:class:`Live`); None (a recording) keeps
    every picture at full size and every pose, plane and true box on the timeline.
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        *,
        camera: str = "camera",
        table_z_m: float | None = 0.0,
        table_size_m: float = 1.0,
        points: bool = False,
        jpeg: bool = True,
        live: Live | None = None,
    ) -> None:
        self.rec = recording
        self.camera = camera
        self._cam = camera_entity(camera)
        self._table_z_m = 0.0 if table_z_m is None else table_z_m
        self._table_size_m = table_size_m
        self._points = points
        self._jpeg = jpeg
        self._live = live
        self._scale = live.scale if live is not None and live.scale > 1 else 1
        self._picture_interval_ns = (
            round(1e9 / live.picture_hz) if live is not None and live.picture_hz > 0 else 0
        )
        self._last_sent_ns: dict[str, int] = {}
        """Live: the stamp each kind (colour, depth, support) was last sent with."""
        self._last_sent: dict[str, npt.NDArray[np.float64]] = {}
        """Live: what the pose, support plane and true boxes were when last sent."""
        self._last_points_ns: int | None = None
        self._last_info: tuple[tuple[float, ...], int, int] | None = None
        self._static: dict[str, TransformStamped] = {}
        """tf_static's transforms by child frame."""
        self._have_pose = False
        self._tf_pose_frame: str | None = None
        self._picture_frame: str | None = None
        """The frame the pictures came in, for placing the camera when tf_static comes late."""

    def start(self) -> None:
        """The static parts: the world's axes and the table."""
        self.rec.log(WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.rec.log(WORLD, rr.TransformAxes3D(AXIS_LENGTH_M), static=True)
        half = self._table_size_m / 2
        thickness_m = 0.004
        self.rec.log(
            TABLE,
            rr.Boxes3D(
                centers=[[0.0, 0.0, self._table_z_m - thickness_m / 2 - 0.0005]],
                sizes=[[self._table_size_m, self._table_size_m, thickness_m]],
                colors=[TABLE_COLOUR],
                fill_mode=rr.components.FillMode.Solid,
            ),
            static=True,
        )
        self.rec.log(
            f"{TABLE}/grid",
            rr.LineStrips3D(
                grid_lines(half, self._table_z_m, GRID_SPACING_M),
                colors=[GRID_COLOUR],
                radii=rr.Radius.ui_points(0.5),
            ),
            static=True,
        )

    def log(self, name: str, message: Message) -> str | None:
        """Log one message that arrived on ``name`` (the key without namespace).

        Returns what it became (``colour``, ``depth``, ``info``, ``pose``, ``points``,
        ``tf_static``, ``detections``, ``support``, ``ground_truth``), or None for a key the
        viewer does not draw. Raises BadMessage or pictures.ImageError (both ValueError) for a
        message it will not draw; nothing of that message is logged then.
        """
        check_numbers(message)
        if isinstance(message, TFMessage):
            self._tf_static(message)
            return "tf_static"
        if isinstance(message, Detection3DArray):
            self._detections(message)
            return "detections"
        if isinstance(message, SupportPlane):
            self._support(message)
            return "support"
        if isinstance(message, GroundTruth):
            self._ground_truth(message)
            return "ground_truth"
        prefix = f"{self.camera}/"
        if not name.startswith(prefix):
            return None
        rest = name.removeprefix(prefix)
        if isinstance(message, Image) and rest == "image_raw":
            rgb = pictures.rgb(message)
            self._pose_from_tf(message.header.frame_id)
            self._time(message.header.stamp_ns)
            if not self._due("colour", message.header.stamp_ns, self._picture_interval_ns):
                return "colour"
            self._last_sent_ns["colour"] = message.header.stamp_ns
            picture = rr.Image(shrink_rgb(rgb, self._scale), color_model="RGB")
            self.rec.log(
                f"{self._cam}/image/rgb",
                picture.compress(jpeg_quality=JPEG_QUALITY) if self._jpeg else picture,
            )
            return "colour"
        if isinstance(message, Image) and rest == "depth/image_raw":
            self._depth(message)
            return "depth"
        if isinstance(message, CameraInfo) and rest == "camera_info":
            self._camera_info(message)
            return "info"
        if isinstance(message, TransformStamped) and rest == "pose":
            t = message.transform
            rotation = unit_quaternion(t.rotation)
            self._have_pose = True
            self._time(message.header.stamp_ns)
            translation = [t.translation.x, t.translation.y, t.translation.z]
            if self._unchanged("pose", translation, list(rotation.xyzw)):
                return "pose"
            self.rec.log(
                self._cam,
                rr.Transform3D(translation=translation, quaternion=rotation),
                rr.TransformAxes3D(AXIS_LENGTH_M),
                static=self._live is not None,
            )
            return "pose"
        if isinstance(message, PointCloud) and rest == "points":
            check_cloud(message)
            cloud = pictures.cloud(message)
            stamp_ns = message.header.stamp_ns
            if not self._points or (
                self._last_points_ns is not None
                and 0 <= stamp_ns - self._last_points_ns < POINTS_INTERVAL_NS
            ):
                return "points"
            self._last_points_ns = stamp_ns
            self._time(stamp_ns)
            self.rec.log(
                f"{self._cam}/points",
                rr.Points3D(
                    cloud.xyz[::POINTS_STRIDE],
                    colors=cloud.rgb[::POINTS_STRIDE],
                    radii=POINT_RADIUS_M * 2,
                ),
            )
            return "points"
        return None

    def _time(self, stamp_ns: int) -> None:
        check_stamp(stamp_ns)
        self.rec.set_time(TIMELINE, duration=np.timedelta64(stamp_ns, "ns"))

    def _due(self, kind: str, stamp_ns: int, interval_ns: int) -> bool:
        """Whether ``interval_ns`` of simulated time has passed since ``kind`` was last sent
        (a stamp that goes back, a restarted sim, counts as passed)."""
        last = self._last_sent_ns.get(kind)
        return last is None or not 0 <= stamp_ns - last < interval_ns

    def _unchanged(self, what: str, *values: Any, within: float = SAME) -> bool:
        """Live: whether ``values`` are what was last sent for ``what`` (each within
        ``within``); if not, they become the last sent. A recording sends everything."""
        if self._live is None:
            return False
        now = np.concatenate([np.ravel(np.asarray(v, dtype=np.float64)) for v in values])
        last = self._last_sent.get(what)
        if last is not None and last.shape == now.shape and np.all(np.abs(last - now) < within):
            return True
        self._last_sent[what] = now
        return False

    def _depth(self, message: Image) -> None:
        depth = pictures.depth_m(message)
        self._pose_from_tf(message.header.frame_id)
        self._time(message.header.stamp_ns)
        if not self._due("depth", message.header.stamp_ns, self._picture_interval_ns):
            return
        self._last_sent_ns["depth"] = message.header.stamp_ns
        # Every scale-th reading: an average would mix near and far at an edge.
        n = self._scale
        depth = depth[: depth.shape[0] // n * n : n, : depth.shape[1] // n * n : n]
        with np.errstate(invalid="ignore"):
            valid = depth[np.isfinite(depth) & (depth > 0)]
        # Colour the readings this picture has, near bright (yellow), far dark, as `onebox pixels`
        # draws them: the range is given far to near.
        near_far = (float(valid.min()), float(valid.max())) if valid.size else (0.05, 3.0)
        if near_far[1] - near_far[0] < 1e-3:
            near_far = (near_far[0] - 0.01, near_far[1] + 0.01)
        # Millimetres in 16 bits: half the bytes of float metres, and 0 is "no reading" both
        # for Rerun and for a 16UC1 picture.
        with np.errstate(invalid="ignore"):
            mm = np.where(np.isfinite(depth) & (depth > 0), depth * 1000.0 + 0.5, 0.0)
        self.rec.log(
            f"{self._cam}/image/depth",
            rr.DepthImage(
                np.clip(mm, 0, 65535).astype(np.uint16),
                meter=1000.0,
                colormap="viridis",
                depth_range=(near_far[1] * 1000.0, near_far[0] * 1000.0),
                point_fill_ratio=0.5,
            ),
        )

    def _camera_info(self, info: CameraInfo) -> None:
        if len(info.k) != 9:
            raise pictures.ImageError(f"camera info k has {len(info.k)} numbers, not 9", "lens")
        if not 0 < info.width <= 65535 or not 0 < info.height <= 65535:
            raise pictures.ImageError(f"camera info of {info.width} x {info.height}", "lens")
        if info.k[0] <= 0 or info.k[4] <= 0:
            raise BadMessage(f"camera info focal lengths {info.k[0]}, {info.k[4]}")
        lens = (tuple(info.k), info.width, info.height)
        # The lens rarely changes: log it again only when it does, not five times a second.
        if lens == self._last_info:
            return
        self._last_info = lens
        # Shrunk pictures (live) are under a lens shrunk with them: Rerun's pixel u spans u to
        # u + 1, so pixel u of a picture shrunk n times spans n u to n (u + 1) of the full one.
        matrix = pinhole_matrix(info.k)
        matrix[:2] /= self._scale
        # Static: a late viewer, or one that dropped old data, must still have the lens.
        self.rec.log(
            f"{self._cam}/image",
            rr.Pinhole(
                image_from_camera=matrix,
                resolution=[info.width // self._scale, info.height // self._scale],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=IMAGE_PLANE_M,
            ),
            static=True,
        )

    def _pose_from_tf(self, frame_id: str) -> None:
        """Place the camera by tf_static's chain to ``frame_id`` when no pose has come.

        A recording without ``camera/pose`` (the committed capture) still shows the camera where
        the transforms say, as the locator's tf_static fallback does. Static, as the chain is.
        """
        self._picture_frame = frame_id
        if self._have_pose or frame_id == self._tf_pose_frame:
            return
        chain = world_from_frame(self._static, frame_id)
        if chain is None:
            return
        translation, rotation = chain
        self._tf_pose_frame = frame_id
        self.rec.log(
            self._cam,
            rr.Transform3D(
                translation=translation, quaternion=rr.Quaternion(xyzw=rotation.as_quat())
            ),
            rr.TransformAxes3D(AXIS_LENGTH_M),
            static=True,
        )

    def _tf_static(self, message: TFMessage) -> None:
        """A newer transform for a child replaces the older; a message that would make a
        cycle, give the world a parent or a chain deeper than MAX_CHAIN is refused whole."""
        tree = dict(self._static)
        for t in message.transforms:
            parent, child = t.header.frame_id, t.child_frame_id
            if not parent or not child or parent == child:
                raise BadMessage(f"transform {parent!r} -> {child!r} needs two different frames")
            if child == WORLD_FRAME:
                raise BadMessage(f"transform {parent!r} -> {child!r} gives the world a parent")
            unit_quaternion(t.transform.rotation)
            tree[child] = t
        paths: dict[str, str] = {}
        for child in tree:
            chain = [child]
            frame = tree[child].header.frame_id
            while frame in tree:
                if frame in chain:
                    raise BadMessage(f"tf_static makes a cycle through {frame!r}")
                if len(chain) >= MAX_CHAIN:
                    raise BadMessage(f"tf_static has a chain deeper than {MAX_CHAIN} frames")
                chain.append(frame)
                frame = tree[frame].header.frame_id
            root = [] if frame == WORLD_FRAME else [frame]
            paths[child] = "/".join([WORLD, *root, *reversed(chain)])
        moved = self._static != tree
        self._static = tree
        for child, t in tree.items():
            tr = t.transform
            self.rec.log(
                paths[child],
                rr.Transform3D(
                    translation=[tr.translation.x, tr.translation.y, tr.translation.z],
                    quaternion=unit_quaternion(tr.rotation),
                ),
                rr.TransformAxes3D(AXIS_LENGTH_M),
                static=True,
            )
        if moved:
            self._tf_pose_frame = None  # the camera's chain may have changed: place it again
            if self._picture_frame is not None:  # now, if the pictures came first
                self._pose_from_tf(self._picture_frame)

    def _boxes(
        self, poses: list[tuple[Pose, Vector3]]
    ) -> tuple[list[list[float]], list[list[float]], list[rr.Quaternion]]:
        centres, sizes, quats = [], [], []
        for pose, size in poses:
            if min(size.x, size.y, size.z) < 0:
                raise BadMessage(f"a box of size {size.x} x {size.y} x {size.z}")
            quats.append(unit_quaternion(pose.orientation))
            centres.append([pose.position.x, pose.position.y, pose.position.z])
            sizes.append([size.x, size.y, size.z])
        return centres, sizes, quats

    def _detections(self, message: Detection3DArray) -> None:
        boxes = [(d.bbox.center, d.bbox.size) for d in message.detections]
        centres, sizes, quats = self._boxes(boxes)
        self._time(message.header.stamp_ns)
        if not message.detections:
            self.rec.log(DETECTIONS, rr.Clear(recursive=True))
            return
        labels = []
        for i, d in enumerate(message.detections):
            s = d.bbox.size
            name = d.id or (d.results[0].class_id if d.results else "") or f"box {i}"
            labels.append(box_label(name, (s.x, s.y, s.z), yaw_deg(d.bbox.center.orientation)))
        self.rec.log(
            DETECTIONS,
            rr.Boxes3D(
                centers=centres,
                sizes=sizes,
                quaternions=quats,
                labels=labels,
                show_labels=True,
                colors=[BOX_COLOUR],
                radii=rr.Radius.ui_points(2.0),
                fill_mode=rr.components.FillMode.TransparentFillMajorWireframe,
            ),
        )

    def _support(self, message: SupportPlane) -> None:
        """The plane n . p + offset = 0 as a translucent square around its point nearest the
        origin of its frame, drawn in that frame (world, or the camera's when no pose)."""
        n = np.array([message.normal.x, message.normal.y, message.normal.z])
        norm = float(np.linalg.norm(n))
        if norm < 1e-6:
            raise BadMessage("support plane normal has no direction")
        n = n / norm
        centre = -message.offset_m / norm * n
        # Two directions in the plane.
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = np.cross(n, helper)
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        h = SUPPORT_HALF_M
        corners = [centre + h * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        self._time(message.header.stamp_ns)
        tilt = "" if message.tilt_deg is None else f", tilt {message.tilt_deg:.1f}°"
        entity = SUPPORT if message.header.frame_id in ("", WORLD_FRAME) else f"{self._cam}/support"
        stamp_ns = message.header.stamp_ns
        changed = not self._unchanged(entity, n, message.offset_m, within=SAME_PLANE)
        if not changed and not self._due(entity, stamp_ns, RESEND_NS):
            return
        self._last_sent_ns[entity] = stamp_ns
        self.rec.log(
            entity,
            rr.Mesh3D(
                vertex_positions=np.asarray(corners, np.float32),
                triangle_indices=[[0, 1, 2], [0, 2, 3]],
                albedo_factor=SUPPORT_COLOUR,
            ),
            rr.AnyValues(label=f"support {message.inlier_share:.0%} inliers{tilt}"),
        )

    def _ground_truth(self, message: GroundTruth) -> None:
        truth: list[tuple[Pose, Vector3]] = []
        # A newer sim lists every box; an older one has box_pose and box_size only.
        for item in getattr(message, "boxes", None) or []:
            pose = getattr(item, "pose", None) or getattr(item, "center", None)
            size = getattr(item, "size", None)
            if isinstance(pose, Pose) and isinstance(size, Vector3):
                truth.append((pose, size))
        if not truth and message.box_pose is not None and message.box_size is not None:
            truth.append((message.box_pose, message.box_size))
        centres, sizes, quats = self._boxes(truth)
        self._time(message.header.stamp_ns)
        if self._unchanged(GROUND_TRUTH, centres, sizes, [q.xyzw for q in quats]):
            return
        if not truth:
            if self._live is None:
                self.rec.log(GROUND_TRUTH, rr.Clear(recursive=True))
            else:  # static: no boxes (a static Clear would hide every later static box too)
                self.rec.log(GROUND_TRUTH, rr.Boxes3D(centers=[], half_sizes=[]), static=True)
            return
        self.rec.log(
            GROUND_TRUTH,
            rr.Boxes3D(
                centers=centres,
                sizes=sizes,
                quaternions=quats,
                colors=[TRUTH_COLOUR],
                radii=rr.Radius.ui_points(0.75),
            ),
            static=self._live is not None,
        )
