"""Depth pictures of a box on a table, worked out exactly by casting one ray per pixel.

The seed's scene without a renderer: a pinhole camera ``mount_height`` above the table looking
straight down (camera right = world +x, camera down = world -y), a box standing on the table.
Tests and benchmarks use it where they need a picture whose answer is known analytically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from schemas import CameraInfo, Header, Image, TFMessage, Transform, TransformStamped
from schemas import Quaternion as Q
from schemas import Vector3 as V

OPTICAL = "camera_optical_frame"


@dataclass(frozen=True)
class Scene:
    width: int = 320
    height: int = 240
    hfov_deg: float = 60.0
    mount_height: float = 0.40
    box_x: float = 0.065
    box_y: float = 0.0405
    box_size: float = 0.06
    box_yaw_deg: float = 0.0
    has_box: bool = True

    @property
    def fx(self) -> float:
        return (self.width / 2) / math.tan(math.radians(self.hfov_deg) / 2)

    @property
    def k(self) -> list[float]:
        cx, cy = (self.width - 1) / 2, (self.height - 1) / 2
        return [self.fx, 0.0, cx, 0.0, self.fx, cy, 0.0, 0.0, 1.0]

    def camera_to_world(self) -> npt.NDArray[np.float64]:
        matrix = np.eye(4)
        matrix[:3, :3] = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]
        matrix[:3, 3] = [0.0, 0.0, self.mount_height]
        return matrix


def depth_picture(scene: Scene) -> npt.NDArray[np.float32]:
    """Depth (metres along the optical axis) of every pixel's middle: the box's top or side, or
    the table."""
    u = np.arange(scene.width) + 0.5
    v = np.arange(scene.height) + 0.5
    ray_x = ((u - scene.width / 2) / scene.fx)[np.newaxis, :]
    ray_y = ((v - scene.height / 2) / scene.fx)[:, np.newaxis]
    # World direction per unit of depth: (ray_x, -ray_y, -1); the camera at (0, 0, mount).
    dir_x = np.broadcast_to(ray_x, (scene.height, scene.width))
    dir_y = np.broadcast_to(-ray_y, (scene.height, scene.width))
    depth = np.full((scene.height, scene.width), scene.mount_height)  # the table, z = 0
    if scene.has_box:
        yaw = math.radians(scene.box_yaw_deg)
        c, s = math.cos(yaw), math.sin(yaw)
        # The ray in the box's own axes: origin and direction.
        ox, oy = -scene.box_x, -scene.box_y
        lo_x, lo_y = c * ox + s * oy, -s * ox + c * oy
        dx, dy = c * dir_x + s * dir_y, -s * dir_x + c * dir_y
        half = scene.box_size / 2
        near = np.zeros_like(depth)
        far = np.full_like(depth, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for origin, direction in ((lo_x, dx), (lo_y, dy)):
                t1 = (-half - origin) / direction
                t2 = (half - origin) / direction
                near = np.maximum(near, np.minimum(t1, t2))
                far = np.minimum(far, np.maximum(t1, t2))
        # z slab: z = mount - t between 0 and box_size
        near = np.maximum(near, scene.mount_height - scene.box_size)
        far = np.minimum(far, scene.mount_height)
        hit = near <= far
        depth = np.where(hit, near, depth)
    return depth.astype(np.float32)


def header(stamp_ns: int, frame_id: str = OPTICAL) -> Header:
    return Header(stamp_ns=stamp_ns, frame_id=frame_id)


def depth_image(depth_m: npt.NDArray[np.float32], stamp_ns: int) -> Image:
    height, width = depth_m.shape
    return Image(
        header=header(stamp_ns),
        height=height,
        width=width,
        encoding="32FC1",
        step=width * 4,
        data=np.ascontiguousarray(depth_m, dtype="<f4").tobytes(),
    )


def camera_info(scene: Scene, stamp_ns: int) -> CameraInfo:
    fx, cx, cy = scene.fx, (scene.width - 1) / 2, (scene.height - 1) / 2
    return CameraInfo(
        header=header(stamp_ns),
        width=scene.width,
        height=scene.height,
        d=[0.0] * 5,
        k=scene.k,
        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=[fx, 0.0, cx, 0.0, 0.0, fx, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def tf_static(mount_height: float = 0.40) -> TFMessage:
    """world -> camera_link (0.40 m up, rpy (0, pi/2, pi/2)) -> camera_optical_frame."""
    mount = Q(x=-0.5, y=0.5, z=0.5, w=0.5)  # rpy (0, pi/2, pi/2), exactly
    return TFMessage(
        transforms=[
            TransformStamped(
                header=header(0, "world"),
                child_frame_id="camera_link",
                transform=Transform(translation=V(z=mount_height), rotation=mount),
            ),
            TransformStamped(
                header=header(0, "camera_link"),
                child_frame_id=OPTICAL,
                transform=Transform(rotation=Q(x=-0.5, y=0.5, z=-0.5, w=0.5)),
            ),
        ]
    )


def camera_pose(mount_height: float, stamp_ns: int) -> TransformStamped:
    """world -> camera_optical_frame directly: right = +x, down = -y, forward = -z."""
    return TransformStamped(
        header=header(stamp_ns, "world"),
        child_frame_id=OPTICAL,
        transform=Transform(translation=V(z=mount_height), rotation=Q(x=1.0, y=0.0, z=0.0, w=0.0)),
    )
