"""The simulated world: scene/one_box.xml with the settings applied, and what it implies.

Everything a capture's metadata says (the lens, the transforms, the ground truth) is read back
from the compiled MuJoCo model here, so the published numbers and the rendered pictures come
from the same place and cannot disagree. No Zenoh here: the sim and the tests both use this.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import numpy.typing as npt

from onebox.errors import SceneError
from onebox.settings import SCENE_DIR
from schemas import CameraInfo, Header, Pose, Quaternion, Transform, TransformStamped, Vector3

SCENE_FILE = SCENE_DIR / "one_box.xml"
WORLD_FRAME = "world"
LINK_FRAME = "camera_link"
OPTICAL_FRAME = "camera_optical_frame"
BASIC_WIDTH, BASIC_HEIGHT = 80, 60
MIN_RANGE_M, MAX_RANGE_M = 0.05, 3.0
"""The depth camera's range (the seed's <clip>): outside it a pixel reads NaN."""

# A MuJoCo camera looks along its own -Z with +Y up: the optical frame turned half a turn
# about X. As a matrix this is its own inverse.
MUJOCO_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class SceneSettings:
    """The scene's settings, with the seed's defaults."""

    width: int = 320
    height: int = 240
    hfov_deg: float = 60.0
    mount_height: float = 0.40
    box: bool = True
    box_x: float = 0.065
    box_y: float = 0.040
    box_size: float = 0.06
    box_yaw_deg: float = 0.0
    scene_file: Path = SCENE_FILE


@dataclass(frozen=True)
class CameraSpec:
    """One camera of the scene: its name (also its key prefix) and its picture's size."""

    name: str
    width: int
    height: int
    hfov_deg: float

    @property
    def focal_px(self) -> float:
        """fx = fy: square pixels, hfov across the width."""
        return self.width / 2 / math.tan(math.radians(self.hfov_deg) / 2)

    @property
    def fovy_deg(self) -> float:
        """MuJoCo's vertical field of view giving the same focal length."""
        return math.degrees(2 * math.atan(self.height / 2 / self.focal_px))


def cameras(settings: SceneSettings) -> list[CameraSpec]:
    """The main camera at the settings' size and the 80 x 60 basic camera, same lens angle."""
    return [
        CameraSpec("camera", settings.width, settings.height, settings.hfov_deg),
        CameraSpec("basic_camera", BASIC_WIDTH, BASIC_HEIGHT, settings.hfov_deg),
    ]


def _check(settings: SceneSettings) -> None:
    if settings.width < 1 or settings.height < 1:
        raise SceneError(f"width x height {settings.width} x {settings.height}: both must be >= 1")
    if not 1.0 <= settings.hfov_deg <= 170.0:
        raise SceneError(f"hfov_deg {settings.hfov_deg}: use an angle from 1 to 170 degrees")
    if settings.mount_height <= MIN_RANGE_M:
        raise SceneError(
            f"mount_height {settings.mount_height} m: the camera must be above the table, "
            f"more than {MIN_RANGE_M} m up"
        )
    if settings.box_size <= 0:
        raise SceneError(f"box_size {settings.box_size} m: must be positive")


def build_model(settings: SceneSettings) -> mujoco.MjModel:
    """Compile the scene with the settings applied."""
    _check(settings)
    try:
        spec = mujoco.MjSpec.from_file(str(settings.scene_file))
    except (ValueError, FileNotFoundError) as e:
        raise SceneError(f"cannot load scene {settings.scene_file}: {e}") from e
    spec.body(LINK_FRAME).pos[2] = settings.mount_height
    if settings.box:
        half = settings.box_size / 2
        body = spec.body("box")
        body.pos = [settings.box_x, settings.box_y, half]
        yaw = math.radians(settings.box_yaw_deg)
        body.quat = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        spec.geom("box").size = [half, half, half]
    else:
        spec.delete(spec.body("box"))
    specs = cameras(settings)
    for cam in specs:
        spec.camera(cam.name).fovy = cam.fovy_deg
    spec.visual.global_.offwidth = max(c.width for c in specs)
    spec.visual.global_.offheight = max(c.height for c in specs)
    return spec.compile()


def camera_info(cam: CameraSpec, stamp_ns: int = 0) -> CameraInfo:
    """The lens of ``cam`` as real cameras write it: the middle of pixel u is at u, so a
    centred lens has cx = (width - 1) / 2 (159.5 for 320 pixels)."""
    f = cam.focal_px
    cx, cy = (cam.width - 1) / 2, (cam.height - 1) / 2
    return CameraInfo(
        header=Header(stamp_ns=stamp_ns, frame_id=OPTICAL_FRAME),
        height=cam.height,
        width=cam.width,
        d=[0.0] * 5,
        k=[f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0],
        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=[f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def _quat_xyzw(wxyz: npt.ArrayLike) -> Quaternion:
    w, x, y, z = (float(v) for v in np.asarray(wxyz, dtype=np.float64))
    return Quaternion(x=x, y=y, z=z, w=w)


def _vector(v: npt.ArrayLike) -> Vector3:
    x, y, z = (float(c) for c in np.asarray(v, dtype=np.float64))
    return Vector3(x=x, y=y, z=z)


def static_transforms(model: mujoco.MjModel, stamp_ns: int = 0) -> list[TransformStamped]:
    """world -> camera_link -> camera_optical_frame, read from the model's bodies."""
    out = []
    for child in (LINK_FRAME, OPTICAL_FRAME):
        body = model.body(child)
        parent = model.body(int(body.parentid[0])).name or WORLD_FRAME
        out.append(
            TransformStamped(
                header=Header(stamp_ns=stamp_ns, frame_id=parent),
                child_frame_id=child,
                transform=Transform(translation=_vector(body.pos), rotation=_quat_xyzw(body.quat)),
            )
        )
    return out


def optical_pose(model: mujoco.MjModel, data: mujoco.MjData, camera: str) -> Pose:
    """camera_optical_frame in the world, from MuJoCo's own camera (cam_xpos, cam_xmat)."""
    cam = data.cam(camera)
    world_from_mujoco_cam = np.asarray(cam.xmat, dtype=np.float64).reshape(3, 3)
    rot = world_from_mujoco_cam @ MUJOCO_TO_OPTICAL
    quat_wxyz = np.empty(4)
    mujoco.mju_mat2Quat(quat_wxyz, rot.reshape(-1))
    return Pose(position=_vector(cam.xpos), orientation=_quat_xyzw(quat_wxyz))


def box_pose(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[Pose, Vector3] | None:
    """The box's middle and edges from MuJoCo, or None when the scene has no box."""
    geom_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "box")
    if geom_id < 0:
        return None
    quat_wxyz = np.empty(4)
    mujoco.mju_mat2Quat(quat_wxyz, data.geom_xmat[geom_id])
    pose = Pose(position=_vector(data.geom_xpos[geom_id]), orientation=_quat_xyzw(quat_wxyz))
    return pose, _vector(2 * model.geom_size[geom_id])
