"""The simulated world: a scene description compiled into MuJoCo, and what it implies.

The look (lights, the table's grid, materials, the cameras' bodies) comes from
scene/one_box.xml; the camera's pose, the table, the boxes, the objects and the stand come from
the scene description (onebox.world.spec: a scene/*.toml file, a random scene, or the seed's
world from the settings).

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
from onebox.world.spec import (
    ARM_RADIUS_M,
    MIN_RANGE_M,
    POST_RADIUS_M,
    BoxDesc,
    CameraDesc,
    SceneDesc,
    TableDesc,
    check,
    link_quat,
    place,
    stand,
    tops_in_picture,
)
from schemas import (
    BoxTruth,
    CameraInfo,
    GroundTruth,
    Header,
    ObjectTruth,
    Pose,
    Quaternion,
    TablePlane,
    Transform,
    TransformStamped,
    Vector3,
)

SCENE_FILE = SCENE_DIR / "one_box.xml"
WORLD_FRAME = "world"
LINK_FRAME = "camera_link"
OPTICAL_FRAME = "camera_optical_frame"
BASIC_WIDTH, BASIC_HEIGHT = 80, 60
MAX_RANGE_M = 3.0
"""The depth camera's range (the seed's <clip>, from MIN_RANGE_M): outside it a pixel reads NaN."""

# A MuJoCo camera looks along its own -Z with +Y up: the optical frame turned half a turn
# about X. As a matrix this is its own inverse.
MUJOCO_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class SceneSettings:
    """The seed scene's settings, with the seed's defaults: one box on a table at z = 0 under a
    camera looking straight down. A scene file (:class:`SceneDesc`) describes any other world."""

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


SEED_RED = (0.85, 0.05, 0.05, 1.0)
TAPE_WIDTH_M = 0.048
TAPE_THICKNESS_M = 0.0003
TAPE_FOLD_M = 0.002
TAPE_RGBA = (0.78, 0.6, 0.4, 1.0)
"""Brown packing tape, 48 mm (the common roll), a little lighter than a carton."""


def seed_scene(settings: SceneSettings = SceneSettings()) -> SceneDesc:
    """The seed's world as a scene description (scene/one_box.toml says the same)."""
    if settings.box_size <= 0:
        raise SceneError(f"box_size {settings.box_size} m: must be positive")
    if settings.mount_height <= MIN_RANGE_M:
        raise SceneError(
            f"mount_height {settings.mount_height} m: the camera must be above the table, "
            f"more than {MIN_RANGE_M} m up"
        )
    boxes = (
        (
            BoxDesc(
                x=settings.box_x,
                y=settings.box_y,
                size=(settings.box_size,) * 3,
                yaw_deg=settings.box_yaw_deg,
                rgba=SEED_RED,
                edges=False,
            ),
        )
        if settings.box
        else ()
    )
    return SceneDesc(
        camera=CameraDesc(
            z=settings.mount_height,
            width=settings.width,
            height=settings.height,
            hfov_deg=settings.hfov_deg,
        ),
        table=TableDesc(z=0.0, size=(2.0, 2.0)),
        boxes=boxes,
        description="the seed's world: a red 6 cm box on a table, the camera 0.40 m above it",
    )


def _scene(scene: SceneDesc | SceneSettings) -> SceneDesc:
    return seed_scene(scene) if isinstance(scene, SceneSettings) else scene


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


def cameras(scene: SceneDesc | SceneSettings) -> list[CameraSpec]:
    """The main camera at the scene's size and the 80 x 60 basic camera, same lens angle."""
    cam = _scene(scene).camera
    return [
        CameraSpec("camera", cam.width, cam.height, cam.hfov_deg),
        CameraSpec("basic_camera", BASIC_WIDTH, BASIC_HEIGHT, cam.hfov_deg),
    ]


def box_name(index: int) -> str:
    """The MuJoCo body and geom of box[index]; the first keeps the seed's name, "box"."""
    return "box" if index == 0 else f"box_{index}"


def object_name(index: int) -> str:
    return f"object_{index}"


def _rounded(rgba: tuple[float, ...]) -> list[float]:
    return [float(v) for v in rgba]


def build_model(scene: SceneDesc | SceneSettings, base: Path = SCENE_FILE) -> mujoco.MjModel:
    """Compile the scene: the look of ``base`` (lights, table, materials, cameras) with the
    scene's camera pose, table, boxes, objects and a stand drawn from the camera's pose."""
    if isinstance(scene, SceneSettings):
        base = scene.scene_file
    desc = _scene(scene)
    check(desc)
    try:
        spec = mujoco.MjSpec.from_file(str(base))
    except (ValueError, FileNotFoundError) as e:
        raise SceneError(f"cannot load scene {base}: {e}") from e
    for name in ("stand_post", "stand_arm"):
        spec.delete(spec.geom(name))
    spec.delete(spec.body("box"))

    cam = desc.camera
    link = spec.body(LINK_FRAME)
    link.pos = [cam.x, cam.y, cam.z]
    link.quat = list(link_quat(cam))

    table = spec.geom("table")
    table.pos = [0.0, 0.0, desc.table.z]
    table.size = [desc.table.size[0] / 2, desc.table.size[1] / 2, 0.01]

    # Cartons show their seams: a cube texture, white with darker lines along every face's
    # edges, tinted by each box's colour. A box with edges = false is plain (the seed's).
    # A line is one texel of a face: 160 texels make it 1-2 mm on a carton 0.2-0.36 m
    # across, as a real seam's dark gap (48 painted bands ~7.5 mm wide, which no carton has).
    spec.add_texture(
        name="carton_edges",
        type=mujoco.mjtTexture.mjTEXTURE_CUBE,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_FLAT,
        mark=mujoco.mjtMark.mjMARK_EDGE,
        width=160,
        height=160,
        rgb1=[1.0, 1.0, 1.0],
        markrgb=[0.55, 0.55, 0.55],
    )
    for i, (box, placed) in enumerate(zip(desc.boxes, place(desc), strict=True)):
        material = spec.add_material(
            name=f"{box_name(i)}_material",
            rgba=_rounded(box.rgba),
            specular=0.1,
            shininess=0.2,
        )
        if box.edges:
            material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "carton_edges"
        body = spec.worldbody.add_body(
            name=box_name(i), pos=list(placed.centre), quat=list(placed.quat_wxyz)
        )
        body.add_geom(
            name=box_name(i),
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[s / 2 for s in placed.size],
            material=material.name,
        )
        if box.tape:
            # Along the length (the body's x), over the line where the flaps meet; seen,
            # never touched. It stops short of the ends by the edges' dark line: it folds over
            # the edge there, and the seam between two cartons shows across it.
            length, _, height = placed.size
            body.add_geom(
                name=f"{box_name(i)}_tape",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                pos=[0.0, 0.0, height / 2 + TAPE_THICKNESS_M / 2],
                size=[length / 2 - TAPE_FOLD_M, TAPE_WIDTH_M / 2, TAPE_THICKNESS_M / 2],
                rgba=list(TAPE_RGBA),
                contype=0,
                conaffinity=0,
            )
    for i, obj in enumerate(desc.objects):
        kind = {
            "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
            "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
            "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
        }[obj.shape]
        spec.worldbody.add_geom(
            name=object_name(i),
            type=kind,
            pos=[obj.x, obj.y, desc.table.z + obj.height / 2],
            size=[*obj.size, 0.0, 0.0][:3],
            rgba=_rounded(obj.rgba),
        )
    held = stand(cam, desc.table.z)
    for name, (start, end), radius in (
        ("stand_post", held.post, POST_RADIUS_M),
        ("stand_arm", held.arm, ARM_RADIUS_M),
        ("stand_drop", held.drop, ARM_RADIUS_M),
    ):
        spec.worldbody.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            fromto=[*start, *end],
            size=[radius, 0.0, 0.0],
            material="stand",
            contype=0,
            conaffinity=0,
        )

    specs = cameras(desc)
    for c in specs:
        spec.camera(c.name).fovy = c.fovy_deg
    spec.visual.global_.offwidth = max(c.width for c in specs)
    spec.visual.global_.offheight = max(c.height for c in specs)
    try:
        return spec.compile()
    except ValueError as e:
        raise SceneError(f"MuJoCo cannot build the scene: {e}") from e


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
    """The first box's middle and edges from MuJoCo, or None when the scene has no box."""
    geom_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "box")
    if geom_id < 0:
        return None
    quat_wxyz = np.empty(4)
    mujoco.mju_mat2Quat(quat_wxyz, data.geom_xmat[geom_id])
    pose = Pose(position=_vector(data.geom_xpos[geom_id]), orientation=_quat_xyzw(quat_wxyz))
    return pose, _vector(2 * model.geom_size[geom_id])


def _geom_pose(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> tuple[Pose, int]:
    geom_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
    quat_wxyz = np.empty(4)
    mujoco.mju_mat2Quat(quat_wxyz, data.geom_xmat[geom_id])
    return Pose(position=_vector(data.geom_xpos[geom_id]), orientation=_quat_xyzw(quat_wxyz)), (
        geom_id
    )


def ground_truth(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    scene: SceneDesc,
    top_pixels: list[int],
    stamp_ns: int = 0,
) -> GroundTruth:
    """Everything true of the world at ``stamp_ns``, poses read back from MuJoCo.

    ``top_pixels`` are the counts of :func:`visible_top_pixels` on the main camera's
    noise-free depth picture."""
    in_view = tops_in_picture(scene.camera, place(scene))
    boxes = []
    for i, box in enumerate(scene.boxes):
        pose, geom_id = _geom_pose(model, data, box_name(i))
        boxes.append(
            BoxTruth(
                pose=pose,
                size=_vector(2 * model.geom_size[geom_id]),
                on=box.on,
                top_in_view=in_view[i],
                top_pixels=top_pixels[i],
            )
        )
    objects = []
    for i, obj in enumerate(scene.objects):
        pose, _ = _geom_pose(model, data, object_name(i))
        objects.append(ObjectTruth(shape=obj.shape, pose=pose, size=list(obj.size)))
    first = box_pose(model, data)
    return GroundTruth(
        header=Header(stamp_ns=stamp_ns, frame_id=WORLD_FRAME),
        box_pose=first[0] if first else None,
        box_size=first[1] if first else None,
        camera_pose=optical_pose(model, data, "camera"),
        boxes=boxes,
        objects=objects,
        table=TablePlane(
            offset_m=-scene.table.z, size_x_m=scene.table.size[0], size_y_m=scene.table.size[1]
        ),
    )
