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
  picture and ``.../depth`` the depth picture under it; ``world/camera/points`` the point cloud
  (camera_optical_frame, so it sits under the camera's pose);
- ``world/detections``: each detected box as a see-through 3D box labelled with its class, score
  and size; ``world/ground_truth`` the simulator's true box, as a thin green wireframe.

:func:`blueprint` is the seed's ``config/one_box.rviz``: the 3D view beside colour and depth.
"""

from __future__ import annotations

import logging

import numpy as np
import numpy.typing as npt
import rerun as rr
import rerun.blueprint as rrb
from scipy.spatial.transform import Rotation

from onebox import pictures
from schemas import (
    CameraInfo,
    Detection3DArray,
    GroundTruth,
    Image,
    Message,
    ObjectHypothesis,
    PointCloud,
    TFMessage,
    TransformStamped,
)
from schemas.geometry import Quaternion

log = logging.getLogger("rerun_log")

TIMELINE = "sim_time"
WORLD = "world"
DETECTIONS = f"{WORLD}/detections"
GROUND_TRUTH = f"{WORLD}/ground_truth"
TABLE = f"{WORLD}/table"

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
                # The depth picture would also be drawn in 3D as a second cloud under the
                # pinhole; camera/points already shows it, in colour.
                contents=["$origin/**", f"- {cam}/image/depth"],
                eye_controls=rrb.EyeControls3D(
                    position=[0.36, -0.5, 0.42], look_target=[0.0, 0.02, 0.13], eye_up=[0, 0, 1]
                ),
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


def _quat(q: Quaternion) -> rr.Quaternion:
    return rr.Quaternion(xyzw=[q.x, q.y, q.z, q.w])


def box_label(class_id: str, score: float, size_m: tuple[float, float, float]) -> str:
    """``box 0.99: 0.060 x 0.060 x 0.060 m``."""
    sx, sy, sz = size_m
    return f"{class_id or 'object'} {score:.2f}: {sx:.3f} x {sy:.3f} x {sz:.3f} m"


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


def pinhole_matrix(k: list[float]) -> npt.NDArray[np.float64]:
    """A CameraInfo K (the middle of pixel u at u) as Rerun's pinhole, whose pixel u spans u
    to u + 1: the principal point moves half a pixel."""
    matrix = np.asarray(k, dtype=np.float64).reshape(3, 3).copy()
    matrix[0, 2] += 0.5
    matrix[1, 2] += 0.5
    return matrix


class SceneLog:
    """Logs onebox messages to one Rerun recording; the key decides what a message becomes."""

    def __init__(
        self,
        recording: rr.RecordingStream,
        *,
        camera: str = "camera",
        table_z_m: float = 0.0,
        table_size_m: float = 1.0,
    ) -> None:
        self.rec = recording
        self.camera = camera
        self._cam = camera_entity(camera)
        self._table_z_m = table_z_m
        self._table_size_m = table_size_m
        self._last_info: CameraInfo | None = None
        self._static: dict[str, TransformStamped] = {}
        """tf_static's transforms by child frame."""
        self._have_pose = False
        self._tf_pose_stamp_ns: int | None = None

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
        ``tf_static``, ``detections``, ``ground_truth``), or None for a key the viewer does not
        draw. Raises pictures.ImageError for a picture or cloud whose numbers do not agree.
        """
        prefix = f"{self.camera}/"
        if isinstance(message, TFMessage):
            self._tf_static(message)
            return "tf_static"
        if isinstance(message, Detection3DArray):
            self._detections(message)
            return "detections"
        if isinstance(message, GroundTruth):
            self._ground_truth(message)
            return "ground_truth"
        if not name.startswith(prefix):
            return None
        rest = name.removeprefix(prefix)
        if isinstance(message, (Image, CameraInfo)):
            self._pose_from_tf(message.header.stamp_ns, message.header.frame_id)
        if isinstance(message, Image) and rest == "image_raw":
            self._time(message.header.stamp_ns)
            self.rec.log(f"{self._cam}/image/rgb", rr.Image(pictures.rgb(message)))
            return "colour"
        if isinstance(message, Image) and rest == "depth/image_raw":
            self._time(message.header.stamp_ns)
            depth = pictures.depth_m(message)
            valid = depth[np.isfinite(depth)]
            # Colour the readings this picture has, not 0 to the camera's 3 m range.
            near_far = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 3.0)
            # Rerun reads 0 as "no reading"; onebox's depth pictures use NaN.
            self.rec.log(
                f"{self._cam}/image/depth",
                rr.DepthImage(
                    np.nan_to_num(depth, nan=0.0),
                    meter=1.0,
                    colormap="viridis",
                    depth_range=near_far,
                ),
            )
            return "depth"
        if isinstance(message, CameraInfo) and rest == "camera_info":
            self._camera_info(message)
            return "info"
        if isinstance(message, TransformStamped) and rest == "pose":
            self._have_pose = True
            self._time(message.header.stamp_ns)
            t = message.transform
            self.rec.log(
                self._cam,
                rr.Transform3D(
                    translation=[t.translation.x, t.translation.y, t.translation.z],
                    quaternion=_quat(t.rotation),
                ),
                rr.TransformAxes3D(AXIS_LENGTH_M),
            )
            return "pose"
        if isinstance(message, PointCloud) and rest == "points":
            self._time(message.header.stamp_ns)
            points = pictures.cloud(message)
            self.rec.log(
                f"{self._cam}/points",
                rr.Points3D(points.xyz, colors=points.rgb, radii=POINT_RADIUS_M),
            )
            return "points"
        return None

    def _time(self, stamp_ns: int) -> None:
        self.rec.set_time(TIMELINE, duration=np.timedelta64(stamp_ns, "ns"))

    def _camera_info(self, info: CameraInfo) -> None:
        if len(info.k) != 9:
            raise pictures.ImageError(f"camera info k has {len(info.k)} numbers, not 9", "lens")
        # The lens rarely changes: log it again only when it does, not five times a second.
        if info == self._last_info or (
            self._last_info is not None
            and info.k == self._last_info.k
            and (info.width, info.height) == (self._last_info.width, self._last_info.height)
        ):
            return
        self._last_info = info
        self._time(info.header.stamp_ns)
        self.rec.log(
            f"{self._cam}/image",
            rr.Pinhole(
                image_from_camera=pinhole_matrix(info.k),
                resolution=[info.width, info.height],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=IMAGE_PLANE_M,
            ),
        )

    def _pose_from_tf(self, stamp_ns: int, frame_id: str) -> None:
        """Place the camera by tf_static's chain to ``frame_id`` when no pose has come.

        A recording without ``camera/pose`` (the committed capture) still shows the camera where
        the transforms say, as the locator's tf_static fallback does.
        """
        if self._have_pose or stamp_ns == self._tf_pose_stamp_ns:
            return
        chain = world_from_frame(self._static, frame_id)
        if chain is None:
            return
        translation, rotation = chain
        self._tf_pose_stamp_ns = stamp_ns
        self._time(stamp_ns)
        self.rec.log(
            self._cam,
            rr.Transform3D(
                translation=translation, quaternion=rr.Quaternion(xyzw=rotation.as_quat())
            ),
            rr.TransformAxes3D(AXIS_LENGTH_M),
        )

    def _tf_static(self, message: TFMessage) -> None:
        self._static.update({t.child_frame_id: t for t in message.transforms})
        parent_of = {t.child_frame_id: t.header.frame_id for t in message.transforms}

        def path(frame: str, depth: int = 0) -> str:
            parent = parent_of.get(frame)
            if parent is None or depth > len(parent_of):  # a root, or a loop in bad data
                return WORLD
            return f"{path(parent, depth + 1)}/{frame}"

        for t in message.transforms:
            tr = t.transform
            self.rec.log(
                path(t.child_frame_id),
                rr.Transform3D(
                    translation=[tr.translation.x, tr.translation.y, tr.translation.z],
                    quaternion=_quat(tr.rotation),
                ),
                rr.TransformAxes3D(AXIS_LENGTH_M),
                static=True,
            )

    def _detections(self, message: Detection3DArray) -> None:
        self._time(message.header.stamp_ns)
        if not message.detections:
            self.rec.log(DETECTIONS, rr.Clear(recursive=True))
            return
        centres, sizes, quats, labels = [], [], [], []
        for d in message.detections:
            c, s = d.bbox.center, d.bbox.size
            centres.append([c.position.x, c.position.y, c.position.z])
            sizes.append([s.x, s.y, s.z])
            quats.append(_quat(c.orientation))
            best = d.results[0] if d.results else ObjectHypothesis()
            labels.append(box_label(best.class_id, best.score, (s.x, s.y, s.z)))
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

    def _ground_truth(self, message: GroundTruth) -> None:
        self._time(message.header.stamp_ns)
        if message.box_pose is None or message.box_size is None:
            self.rec.log(GROUND_TRUTH, rr.Clear(recursive=True))
            return
        p, s = message.box_pose, message.box_size
        self.rec.log(
            GROUND_TRUTH,
            rr.Boxes3D(
                centers=[[p.position.x, p.position.y, p.position.z]],
                sizes=[[s.x, s.y, s.z]],
                quaternions=[_quat(p.orientation)],
                colors=[TRUTH_COLOUR],
                radii=rr.Radius.ui_points(0.75),
            ),
        )
