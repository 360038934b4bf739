"""An MCAP of Foxglove's well-known protobuf schemas, written by the Foxglove SDK.

  camera/image_raw, camera/depth/image_raw   foxglove.RawImage
  camera/camera_info                         foxglove.CameraCalibration (K copied as it is)
  camera/points                              foxglove.PointCloud
  tf_static                                  foxglove.FrameTransforms on tf_static
  camera/pose                                foxglove.FrameTransforms on tf
  detections                                 foxglove.SceneUpdate: a cube and a label a box

Foxglove's 3D panel places the pictures and the cloud by their frame_id through the transforms,
so the scene stands as in the live viewer. The clock, the support plane and the ground truth
have no Foxglove schema and are left out.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import foxglove
from foxglove import channels as fc
from foxglove import messages as fm

from onebox.export import stamp_ok
from schemas import (
    UINT32,
    CameraInfo,
    Detection3DArray,
    Image,
    Message,
    PointCloud,
    TFMessage,
    TransformStamped,
)

NUMERIC_TYPES = {
    1: fm.PackedElementFieldNumericType.Int8,
    2: fm.PackedElementFieldNumericType.Uint8,
    3: fm.PackedElementFieldNumericType.Int16,
    4: fm.PackedElementFieldNumericType.Uint16,
    5: fm.PackedElementFieldNumericType.Int32,
    UINT32: fm.PackedElementFieldNumericType.Uint32,
    7: fm.PackedElementFieldNumericType.Float32,
    8: fm.PackedElementFieldNumericType.Float64,
}
"""sensor_msgs/PointField datatypes (onebox's) to Foxglove's numeric types."""
BYTES_OF = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8}

BOX_COLOUR = fm.Color(r=0.0, g=0.47, b=1.0, a=0.35)
LABEL_COLOUR = fm.Color(r=1.0, g=1.0, b=1.0, a=1.0)


def _timestamp(stamp_ns: int) -> fm.Timestamp:
    if not stamp_ok(stamp_ns):
        raise ValueError(f"stamp {stamp_ns} ns does not fit Foxglove time (0 to 2^31 s)")
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return fm.Timestamp(sec, nsec)


def yaw_deg(x: float, y: float, z: float, w: float) -> float:
    """The turn about the world's up of a quaternion, degrees."""
    return math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


class FoxgloveTarget:
    """Writes Foxglove messages into a new MCAP file."""

    def __init__(self, path: Path) -> None:
        self._context = foxglove.Context()
        self._writer = foxglove.open_mcap(path, context=self._context)
        self._channels: dict[str, Any] = {}
        self._closed = False

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._writer.close()

    def _channel(self, topic: str, kind: type[Any]) -> Any:
        channel = self._channels.get(topic)
        if channel is None:
            channel = kind(topic, context=self._context)
            self._channels[topic] = channel
        return channel

    def write(self, name: str, topic: str, message: Message, log_time_ns: int) -> bool:
        namespace = topic.removesuffix(name).strip("/")
        if isinstance(message, Image):
            self._channel(topic, fc.RawImageChannel).log(self._image(message), log_time=log_time_ns)
        elif isinstance(message, CameraInfo):
            calibration = self._calibration(message)
            self._channel(topic, fc.CameraCalibrationChannel).log(calibration, log_time=log_time_ns)
        elif isinstance(message, PointCloud):
            cloud = self._cloud(message)
            self._channel(topic, fc.PointCloudChannel).log(cloud, log_time=log_time_ns)
        elif isinstance(message, TFMessage):
            if not message.transforms:
                return False
            transforms = fm.FrameTransforms(transforms=[_frame(t) for t in message.transforms])
            self._channel(topic, fc.FrameTransformsChannel).log(transforms, log_time=log_time_ns)
        elif isinstance(message, TransformStamped):
            tf_topic = f"{namespace}/tf" if namespace else "tf"
            transforms = fm.FrameTransforms(transforms=[_frame(message)])
            self._channel(tf_topic, fc.FrameTransformsChannel).log(transforms, log_time=log_time_ns)
        elif isinstance(message, Detection3DArray):
            update = self._scene(message)
            self._channel(topic, fc.SceneUpdateChannel).log(update, log_time=log_time_ns)
        else:
            return False
        return True

    def _image(self, m: Image) -> fm.RawImage:
        if m.height < 0 or m.width < 0 or m.step < 0 or len(m.data) != m.step * m.height:
            raise ValueError(
                f"picture of {m.height} rows of {m.step} bytes has {len(m.data)} bytes"
            )
        return fm.RawImage(
            timestamp=_timestamp(m.header.stamp_ns),
            frame_id=m.header.frame_id,
            width=m.width,
            height=m.height,
            encoding=m.encoding,
            step=m.step,
            data=m.data,
        )

    def _calibration(self, m: CameraInfo) -> fm.CameraCalibration:
        if len(m.k) != 9:
            raise ValueError(f"camera info k has {len(m.k)} numbers, not 9")
        r = list(m.r) if len(m.r) == 9 else [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        p = list(m.p) if len(m.p) == 12 else [*m.k[0:3], 0.0, *m.k[3:6], 0.0, *m.k[6:9], 0.0]
        return fm.CameraCalibration(
            timestamp=_timestamp(m.header.stamp_ns),
            frame_id=m.header.frame_id,
            width=m.width,
            height=m.height,
            distortion_model=m.distortion_model,
            D=list(m.d),
            K=list(m.k),
            R=r,
            P=p,
        )

    def _cloud(self, m: PointCloud) -> fm.PointCloud:
        if m.height != 1 and m.row_step != m.point_step * m.width:
            raise ValueError("an organised cloud with padded rows has no Foxglove counterpart")
        fields = []
        for f in m.fields:
            numeric = NUMERIC_TYPES.get(f.datatype)
            if numeric is None:
                raise ValueError(f"field {f.name} has unknown datatype {f.datatype}")
            if f.offset < 0 or f.offset + BYTES_OF[f.datatype] * max(f.count, 1) > m.point_step:
                raise ValueError(
                    f"field {f.name} at byte {f.offset} does not fit a point of {m.point_step}"
                )
            fields.append(fm.PackedElementField(name=f.name, offset=f.offset, type=numeric))
        count = m.width * m.height
        if len(m.data) < count * m.point_step:
            raise ValueError(f"{len(m.data)} bytes of data for {count} points")
        return fm.PointCloud(
            timestamp=_timestamp(m.header.stamp_ns),
            frame_id=m.header.frame_id,
            pose=fm.Pose(position=fm.Vector3(), orientation=fm.Quaternion(w=1.0)),
            point_stride=m.point_step,
            fields=fields,
            data=m.data[: count * m.point_step],
        )

    def _scene(self, m: Detection3DArray) -> fm.SceneUpdate:
        stamp = _timestamp(m.header.stamp_ns)
        # Each capture replaces the boxes of the last one.
        deletions = [fm.SceneEntityDeletion(timestamp=stamp, type=fm.SceneEntityDeletionType.All)]
        entities = []
        for i, d in enumerate(m.detections):
            c, s, q = d.bbox.center.position, d.bbox.size, d.bbox.center.orientation
            pose = fm.Pose(
                position=fm.Vector3(x=c.x, y=c.y, z=c.z),
                orientation=fm.Quaternion(x=q.x, y=q.y, z=q.z, w=q.w),
            )
            label_pose = fm.Pose(
                position=fm.Vector3(x=c.x, y=c.y, z=c.z + s.z / 2 + 0.02),
                orientation=fm.Quaternion(w=1.0),
            )
            best = d.results[0].class_id if d.results else "object"
            label = (
                f"{d.id or best} {s.x * 1000:.0f} x {s.y * 1000:.0f} x {s.z * 1000:.0f} mm, "
                f"yaw {yaw_deg(q.x, q.y, q.z, q.w):+.0f}°"
            )
            entities.append(
                fm.SceneEntity(
                    timestamp=stamp,
                    frame_id=d.header.frame_id or m.header.frame_id,
                    id=d.id or f"box{i}",
                    cubes=[
                        fm.CubePrimitive(
                            pose=pose, size=fm.Vector3(x=s.x, y=s.y, z=s.z), color=BOX_COLOUR
                        )
                    ],
                    texts=[
                        fm.TextPrimitive(
                            pose=label_pose,
                            billboard=True,
                            font_size=14.0,
                            scale_invariant=True,
                            color=LABEL_COLOUR,
                            text=label,
                        )
                    ],
                )
            )
        return fm.SceneUpdate(deletions=deletions, entities=entities)


def _frame(t: TransformStamped) -> fm.FrameTransform:
    tr, q = t.transform.translation, t.transform.rotation
    return fm.FrameTransform(
        timestamp=_timestamp(t.header.stamp_ns),
        parent_frame_id=t.header.frame_id,
        child_frame_id=t.child_frame_id,
        translation=fm.Vector3(x=tr.x, y=tr.y, z=tr.z),
        rotation=fm.Quaternion(x=q.x, y=q.y, z=q.z, w=q.w),
    )
