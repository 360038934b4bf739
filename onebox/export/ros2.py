"""A rosbag2-compatible MCAP: CDR messages with ``ros2msg`` schemas, as ``ros2 bag record`` writes.

The ``rosbags`` library supplies the message definitions (ROS 2 Humble's) and the CDR encoding;
vision_msgs, which it does not ship, is registered from its .msg text below. Each key becomes
the ROS topic it was named after, with the leading slash:

  camera/image_raw, camera/depth/image_raw   sensor_msgs/msg/Image
  camera/camera_info                         sensor_msgs/msg/CameraInfo (K copied: both put the
                                             middle of pixel u at u)
  camera/points                              sensor_msgs/msg/PointCloud2
  camera/pose                                geometry_msgs/msg/TransformStamped, and on /tf
  tf_static                                  tf2_msgs/msg/TFMessage (transient local, latched)
  clock                                      rosgraph_msgs/msg/Clock
  detections                                 vision_msgs/msg/Detection3DArray

The support plane and the simulator's ground truth have no standard message and are left out.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from onebox.export import stamp_ok
from schemas import (
    CameraInfo,
    Clock,
    Detection3DArray,
    Header,
    Image,
    ImageView,
    Message,
    PointCloud,
    PointCloudView,
    TFMessage,
    TransformStamped,
)

VISION_MSGS = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection3DArray": (
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n"
    ),
}
"""vision_msgs 4 (ROS 2 Humble and later), as its .msg files say."""

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POINT_CLOUD = "sensor_msgs/msg/PointCloud2"
TF = "tf2_msgs/msg/TFMessage"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
CLOCK = "rosgraph_msgs/msg/Clock"
DETECTIONS = "vision_msgs/msg/Detection3DArray"


def _qos(durability: int) -> str:
    """rosbag2's offered_qos_profiles: reliable, keep last; 1 transient local, 2 volatile."""
    never = "    sec: 2147483647\n    nsec: 4294967295\n"
    return (
        f"- history: 3\n  depth: 0\n  reliability: 1\n  durability: {durability}\n"
        f"  deadline:\n{never}  lifespan:\n{never}  liveliness: 1\n"
        f"  liveliness_lease_duration:\n{never}  avoid_ros_namespace_conventions: false\n"
    )


LATCHED_QOS = _qos(1)
VOLATILE_QOS = _qos(2)


@functools.cache
def typestore(release: Stores = Stores.ROS2_HUMBLE) -> Typestore:
    """A ROS 2 release's messages (default Humble's, which every later release reads) plus
    vision_msgs."""
    store = get_typestore(release)
    types: dict[str, Any] = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


class RosMessages:
    """onebox messages as ROS 2 message objects of a ``rosbags`` typestore, ready for its CDR.

    Shared by ``onebox export --to ros2`` and the live bridge (``onebox ros2``). A picture or a
    cloud may be an :class:`ImageView` or :class:`PointCloudView`: its data is then read where
    it lies, and copied once, by the CDR encoder. Raises ValueError for numbers ROS cannot hold.
    """

    def __init__(self, store: Typestore) -> None:
        self.store = store

    def convert(self, message: Message) -> tuple[str, Any] | None:
        """``(ROS type name, message)``, or None for a type with no counterpart or an empty
        TFMessage (nothing a ROS tool could use)."""
        if isinstance(message, Image | ImageView):
            return IMAGE, self.image(message)
        if isinstance(message, CameraInfo):
            return CAMERA_INFO, self.camera_info(message)
        if isinstance(message, PointCloud | PointCloudView):
            return POINT_CLOUD, self.cloud(message)
        if isinstance(message, TFMessage):
            if not message.transforms:
                return None
            return TF, self.store.types[TF](
                transforms=[self.transform(t) for t in message.transforms]
            )
        if isinstance(message, TransformStamped):
            return TRANSFORM, self.transform(message)
        if isinstance(message, Clock):
            _check_stamp(message.clock_ns)
            return CLOCK, self.store.types[CLOCK](clock=self.time(message.clock_ns))
        if isinstance(message, Detection3DArray):
            return DETECTIONS, self.detections(message)
        return None

    def time(self, stamp_ns: int) -> Any:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        return self.store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)

    def header(self, header: Header) -> Any:
        _check_stamp(header.stamp_ns)
        return self.store.types["std_msgs/msg/Header"](
            stamp=self.time(header.stamp_ns), frame_id=header.frame_id
        )

    def image(self, m: Image | ImageView) -> Any:
        if m.height < 0 or m.width < 0 or m.step < 0 or len(m.data) != m.step * m.height:
            raise ValueError(
                f"picture of {m.height} rows of {m.step} bytes has {len(m.data)} bytes"
            )
        return self.store.types[IMAGE](
            header=self.header(m.header),
            height=m.height,
            width=m.width,
            encoding=m.encoding,
            is_bigendian=int(bool(m.is_bigendian)),
            step=m.step,
            data=np.frombuffer(m.data, np.uint8),
        )

    def camera_info(self, m: CameraInfo) -> Any:
        if len(m.k) != 9:
            raise ValueError(f"camera info k has {len(m.k)} numbers, not 9")
        k = np.asarray(m.k, np.float64)
        r = np.asarray(m.r, np.float64) if len(m.r) == 9 else np.eye(3).reshape(-1)
        if len(m.p) == 12:
            p = np.asarray(m.p, np.float64)
        else:
            p = np.hstack([k.reshape(3, 3), np.zeros((3, 1))]).reshape(-1)
        roi = self.store.types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        return self.store.types[CAMERA_INFO](
            header=self.header(m.header),
            height=m.height,
            width=m.width,
            distortion_model=m.distortion_model,
            d=np.asarray(m.d, np.float64),
            k=k,
            r=r,
            p=p,
            binning_x=0,
            binning_y=0,
            roi=roi,
        )

    def cloud(self, m: PointCloud | PointCloudView) -> Any:
        for f in m.fields:
            if f.offset < 0 or f.offset + 4 * max(f.count, 1) > m.point_step:
                raise ValueError(
                    f"field {f.name} at byte {f.offset} does not fit a point of {m.point_step}"
                )
        if len(m.data) < m.width * m.height * m.point_step:
            raise ValueError(f"{len(m.data)} bytes of data for {m.width * m.height} points")
        field_type = self.store.types["sensor_msgs/msg/PointField"]
        return self.store.types[POINT_CLOUD](
            header=self.header(m.header),
            height=m.height,
            width=m.width,
            fields=[
                field_type(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                for f in m.fields
            ],
            is_bigendian=m.is_bigendian,
            point_step=m.point_step,
            row_step=m.row_step or m.point_step * m.width,
            data=np.frombuffer(m.data, np.uint8),
            is_dense=m.is_dense,
        )

    def vector(self, x: float, y: float, z: float) -> Any:
        return self.store.types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    def quaternion(self, x: float, y: float, z: float, w: float) -> Any:
        return self.store.types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)

    def transform(self, t: TransformStamped) -> Any:
        tr, q = t.transform.translation, t.transform.rotation
        transform = self.store.types["geometry_msgs/msg/Transform"](
            translation=self.vector(tr.x, tr.y, tr.z),
            rotation=self.quaternion(q.x, q.y, q.z, q.w),
        )
        return self.store.types[TRANSFORM](
            header=self.header(t.header), child_frame_id=t.child_frame_id, transform=transform
        )

    def detections(self, m: Detection3DArray) -> Any:
        types = self.store.types
        detections = []
        for d in m.detections:
            c, s = d.bbox.center, d.bbox.size
            pose = types["geometry_msgs/msg/Pose"](
                position=types["geometry_msgs/msg/Point"](
                    x=c.position.x, y=c.position.y, z=c.position.z
                ),
                orientation=self.quaternion(
                    c.orientation.x, c.orientation.y, c.orientation.z, c.orientation.w
                ),
            )
            results = [
                types["vision_msgs/msg/ObjectHypothesisWithPose"](
                    hypothesis=types["vision_msgs/msg/ObjectHypothesis"](
                        class_id=r.class_id, score=r.score
                    ),
                    pose=types["geometry_msgs/msg/PoseWithCovariance"](
                        pose=pose, covariance=np.zeros(36)
                    ),
                )
                for r in d.results
            ]
            detections.append(
                types["vision_msgs/msg/Detection3D"](
                    header=self.header(d.header),
                    results=results,
                    bbox=types["vision_msgs/msg/BoundingBox3D"](
                        center=pose, size=self.vector(s.x, s.y, s.z)
                    ),
                    id=d.id,
                )
            )
        return types[DETECTIONS](header=self.header(m.header), detections=detections)


class Ros2Target:
    """Writes ROS 2 messages into a new MCAP file with rosbag2's profile."""

    def __init__(self, path: Path) -> None:
        self._store = typestore()
        self._messages = RosMessages(self._store)
        self._file = path.open("xb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="onebox export")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._closed = False

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]  # mcap ships no types
        finally:
            self._file.close()

    # --- writing ---------------------------------------------------------------------------

    def _channel(self, topic: str, typename: str) -> int:
        key = f"{topic}\0{typename}"
        channel_id = self._channels.get(key)
        if channel_id is None:
            schema_id = self._schemas.get(typename)
            if schema_id is None:
                text, _ = self._store.generate_msgdef(typename, ros_version=2)
                schema_id = self._writer.register_schema(typename, "ros2msg", text.encode())
                self._schemas[typename] = schema_id
            qos = LATCHED_QOS if topic.endswith("/tf_static") else VOLATILE_QOS
            channel_id = self._writer.register_channel(
                topic, "cdr", schema_id, metadata={"offered_qos_profiles": qos}
            )
            self._channels[key] = channel_id
        return channel_id

    def _put(
        self, topic: str, typename: str, message: Any, stamp_ns: int, log_time_ns: int
    ) -> None:
        data = self._store.serialize_cdr(message, typename)
        self._writer.add_message(
            self._channel(topic, typename),
            log_time=log_time_ns,
            data=bytes(data),
            publish_time=stamp_ns,
        )

    def write(self, name: str, topic: str, message: Message, log_time_ns: int) -> bool:
        ros_topic = "/" + topic.strip("/")
        namespace = topic.removesuffix(name).strip("/")
        converted = self._messages.convert(message)
        if converted is None:
            return False
        typename, ros = converted
        stamp = _stamp_of(message)
        self._put(ros_topic, typename, ros, stamp, log_time_ns)
        if isinstance(message, TransformStamped):
            # The camera's pose is also the dynamic transform every ROS tool reads from /tf.
            tf_topic = f"/{namespace}/tf" if namespace else "/tf"
            tf = self._store.types[TF](transforms=[ros])
            self._put(tf_topic, TF, tf, stamp, log_time_ns)
        return True


def _stamp_of(message: Message) -> int:
    """The stamp a message's MCAP publish time takes: its header's, a clock's own time, a
    TFMessage's first transform's."""
    if isinstance(message, Clock):
        return message.clock_ns
    if isinstance(message, TFMessage):
        return _stamp(message.transforms[0].header)
    header = getattr(message, "header", None)
    return _stamp(header) if isinstance(header, Header) else 0


def _check_stamp(stamp_ns: int) -> None:
    if not stamp_ok(stamp_ns):
        raise ValueError(f"stamp {stamp_ns} ns does not fit ROS time (0 to 2^31 s)")


def _stamp(header: Header) -> int:
    _check_stamp(header.stamp_ns)
    return header.stamp_ns
