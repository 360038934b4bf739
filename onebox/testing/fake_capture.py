"""One capture's messages, built by hand with the real schemas, for the viewer, pixels and check.

The camera looks straight down from 0.40 m; the depth picture reads 0.400 on the table and
0.340 on a box top whose pixels are a rectangle; the colour picture is grey with a red box.
Good enough to drive the tools without a simulator; the seed's numbers come from the sim.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from onebox.recording import RecordingWriter
from schemas import (
    FLOAT32,
    UINT32,
    BoundingBox3D,
    CameraInfo,
    Detection3D,
    Detection3DArray,
    Header,
    Image,
    Message,
    ObjectHypothesis,
    PointCloud,
    PointField,
    Pose,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    codec,
)

OPTICAL = "camera_optical_frame"
BOX_CENTRE = (0.065, 0.0405, 0.03)
BOX_SIZE = (0.06, 0.06, 0.06)


def k(width: int, height: int, hfov_deg: float = 60.0) -> list[float]:
    f = width / 2 / math.tan(math.radians(hfov_deg) / 2)
    return [f, 0.0, (width - 1) / 2, 0.0, f, (height - 1) / 2, 0.0, 0.0, 1.0]


def pictures(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """rgb (height, width, 3) uint8 and depth (height, width) float32 metres."""
    rgb = np.full((height, width, 3), 121, np.uint8)
    depth = np.full((height, width), 0.4, np.float32)
    rows = slice(height // 3, height // 2)
    cols = slice(width // 2 + width // 20, width // 2 + width // 5)
    rgb[rows, cols] = (200, 20, 20)
    depth[rows, cols] = 0.34
    depth[0, 0] = np.nan  # one pixel with no reading
    return rgb, depth


def capture(
    stamp_ns: int, camera: str = "camera", width: int = 320, height: int = 240
) -> dict[str, Message]:
    """Every key one capture of ``camera`` puts on the bus, by key (no namespace)."""
    header = Header(stamp_ns=stamp_ns, frame_id=OPTICAL)
    rgb, depth = pictures(width, height)
    intrinsics = k(width, height)
    fx, cx, cy = intrinsics[0], intrinsics[2], intrinsics[5]
    v, u = np.mgrid[0:height, 0:width]
    xyz = np.stack([(u - cx) * depth / fx, (v - cy) * depth / fx, depth], axis=-1)
    packed = (
        (rgb[..., 0].astype(np.uint32) << 16)
        | (rgb[..., 1].astype(np.uint32) << 8)
        | rgb[..., 2].astype(np.uint32)
    )
    points = np.zeros(
        width * height, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")]
    )
    points["x"], points["y"], points["z"] = (xyz[..., i].reshape(-1) for i in range(3))
    points["rgb"] = packed.reshape(-1)
    cx_m, cy_m, cz_m = BOX_CENTRE
    return {
        f"{camera}/image_raw": Image(
            header=header,
            height=height,
            width=width,
            encoding="rgb8",
            step=width * 3,
            data=rgb.tobytes(),
        ),
        f"{camera}/depth/image_raw": Image(
            header=header,
            height=height,
            width=width,
            encoding="32FC1",
            step=width * 4,
            data=depth.astype("<f4").tobytes(),
        ),
        f"{camera}/camera_info": CameraInfo(
            header=header, height=height, width=width, d=[0.0] * 5, k=intrinsics
        ),
        f"{camera}/pose": TransformStamped(
            header=Header(stamp_ns=stamp_ns, frame_id="world"),
            child_frame_id=OPTICAL,
            transform=Transform(
                translation=Vector3(z=0.4), rotation=Quaternion(x=1.0, y=0.0, z=0.0, w=0.0)
            ),
        ),
        f"{camera}/points": PointCloud(
            header=header,
            width=width * height,
            fields=[
                PointField(name="x", offset=0, datatype=FLOAT32),
                PointField(name="y", offset=4, datatype=FLOAT32),
                PointField(name="z", offset=8, datatype=FLOAT32),
                PointField(name="rgb", offset=12, datatype=UINT32),
            ],
            point_step=16,
            row_step=16 * width * height,
            data=points.tobytes(),
            is_dense=False,
        ),
        "detections": Detection3DArray(
            header=Header(stamp_ns=stamp_ns, frame_id="world"),
            detections=[
                Detection3D(
                    header=Header(stamp_ns=stamp_ns, frame_id="world"),
                    results=[ObjectHypothesis(class_id="box", score=1.0)],
                    bbox=BoundingBox3D(
                        center=Pose(position=Vector3(x=cx_m, y=cy_m, z=cz_m)),
                        size=Vector3(x=BOX_SIZE[0], y=BOX_SIZE[1], z=BOX_SIZE[2]),
                    ),
                )
            ],
        ),
    }


def tf_static() -> TFMessage:
    """world -> camera_link (0.40 m up, looking down) -> camera_optical_frame."""
    return TFMessage(
        transforms=[
            TransformStamped(
                header=Header(frame_id="world"),
                child_frame_id="camera_link",
                transform=Transform(
                    translation=Vector3(z=0.4), rotation=Quaternion(x=-0.5, y=0.5, z=0.5, w=0.5)
                ),
            ),
            TransformStamped(
                header=Header(frame_id="camera_link"),
                child_frame_id=OPTICAL,
                transform=Transform(rotation=Quaternion(x=-0.5, y=0.5, z=-0.5, w=0.5)),
            ),
        ]
    )


def write_mcap(path: Path, captures: int = 3, period_ns: int = 200_000_000) -> Path:
    """An .mcap as ``onebox record`` writes it: tf_static, then ``captures`` whole captures."""
    with RecordingWriter(path) as writer:
        writer.add("tf_static", codec(TFMessage).encode(tf_static()), log_time_ns=1)
        for i in range(1, captures + 1):
            for key, message in capture(i * period_ns).items():
                writer.add(key, codec(type(message)).encode(message), log_time_ns=1 + i * period_ns)
    return path
