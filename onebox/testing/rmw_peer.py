"""A ROS 2 node as rmw_zenoh makes one, for testing ``onebox ros2`` without a ROS installation.

Written from rmw_zenoh's docs/design.md (the 2025 layout), not from the bridge's code, and
sharing none of it: its own parsing of liveliness tokens, Zenoh's own serializer for the
attachment (``zenoh.ext.z_serialize``), mcap-ros2-support's CDR reader and writer (not
``rosbags``) with the message definitions written out below from ROS 2's .msg files, and the
type hashes as ROS 2 Jazzy states them (not computed):

- std_msgs/msg/String: rmw_zenoh's docs/design.md, its ``chatter`` example key;
- sensor_msgs/msg/Image: ROS 2 Jazzy's image_pipeline tutorials ("Using QoS Overrides",
  docs.ros.org/en/jazzy/p/image_pipeline/tutorials.html), ``ros2 topic info -v`` output;
- sensor_msgs/msg/CameraInfo: rosidl_generator_c's camera_info__description.c (the bytes
  b3 df d6 8f ...), as published in hpmicro/hpm_sdk's micro-ROS headers;
- the others: rosidl_generator_c's generated headers and the rmw_zenoh keys of public ROS 2
  projects (tf2_msgs__msg__TFMessage__TYPE_HASH e3 69 d0 f0 ..., and so on).

What it does, as the design document says rmw_zenoh does:

- declares a node's liveliness token, ``@ros2_lv/<domain>/<zid>/<node>/<node>/NN/%/<ns>/<name>``;
- reads the graph (``ros2 node list``, ``ros2 topic list -t``) from every token under
  ``@ros2_lv/<domain>/``;
- subscribes to ``<domain>/<topic>/<dds type>/<hash>`` with its MS token, reads each sample's
  attachment (sequence number, source time, GID) and decodes its CDR;
- publishes with its MP token and the attachment, TRANSIENT_LOCAL through a Zenoh advanced
  publisher's cache, as a camera driver's tf_static is.
"""

from __future__ import annotations

import hashlib
import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh
import zenoh.ext
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from zenoh.ext import Int64, UInt8, z_deserialize, z_serialize

JAZZY_HASHES = {
    "std_msgs/msg/String": "RIHS01_"
    "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "sensor_msgs/msg/Image": "RIHS01_"
    "d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    "sensor_msgs/msg/CameraInfo": "RIHS01_"
    "b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    "sensor_msgs/msg/PointCloud2": "RIHS01_"
    "9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    "tf2_msgs/msg/TFMessage": "RIHS01_"
    "e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    "rosgraph_msgs/msg/Clock": "RIHS01_"
    "692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
    "vision_msgs/msg/Detection3DArray": "RIHS01_"
    "793f5eab9595ac1c0da07873cc859db42eae51f0ee76056db8562515d830e018",
}
"""RIHS01 type hashes as ROS 2 Jazzy has them (see the module docstring for where each is
stated)."""

_SEP = "=" * 80
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
_TRANSFORM_STAMPED = (
    "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
    "geometry_msgs/Transform transform\n"
)
_TRANSFORM = (
    "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\n"
    "geometry_msgs/Quaternion rotation\n"
)


def _definition(main: str, *subs: str) -> str:
    return main + "".join(f"{_SEP}\n{sub}" for sub in subs)


DEFINITIONS = {
    "sensor_msgs/msg/Image": _definition(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data\n",
        _HEADER,
    ),
    "sensor_msgs/msg/CameraInfo": _definition(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
        "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
        "uint32 binning_y\nsensor_msgs/RegionOfInterest roi\n",
        _HEADER,
        "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n"
        "uint32 width\nbool do_rectify\n",
    ),
    "sensor_msgs/msg/PointCloud2": _definition(
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\n"
        "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
        _HEADER,
        "MSG: sensor_msgs/PointField\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n",
    ),
    "tf2_msgs/msg/TFMessage": _definition(
        "geometry_msgs/TransformStamped[] transforms\n",
        _TRANSFORM_STAMPED,
        _HEADER,
        _TRANSFORM,
        _VECTOR3,
        _QUATERNION,
    ),
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock\n",
    "vision_msgs/msg/Detection3DArray": _definition(
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
        _HEADER,
        "MSG: vision_msgs/Detection3D\nstd_msgs/Header header\n"
        "vision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox3D bbox\n"
        "string id\n",
        "MSG: vision_msgs/ObjectHypothesisWithPose\nvision_msgs/ObjectHypothesis hypothesis\n"
        "geometry_msgs/PoseWithCovariance pose\n",
        "MSG: vision_msgs/ObjectHypothesis\nstring class_id\nfloat64 score\n",
        "MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n",
        "MSG: vision_msgs/BoundingBox3D\ngeometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
        "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\n"
        "geometry_msgs/Quaternion orientation\n",
        _POINT,
        _QUATERNION,
        _VECTOR3,
    ),
}
"""ROS 2's message definitions (common_interfaces, vision_msgs 4), comments left out, in the
concatenated form rosbag2 writes into MCAP."""

TRANSIENT_LOCAL_QOS = ":1:,1:,:,:,,"
"""A tf2 static broadcaster's QoS as rmw_zenoh writes it: TRANSIENT_LOCAL, keep last 1."""
DEFAULT_QOS = "::,10:,:,:,,"
"""QoS(10): reliable, volatile, keep last 10 (rmw_zenoh writes only what differs from its
defaults: reliable, volatile, keep last 42)."""


def dds_name(typename: str) -> str:
    """``sensor_msgs/msg/Image`` -> ``sensor_msgs::msg::dds_::Image_``, as the design says."""
    package, kind, name = typename.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def short_name(typename: str) -> str:
    package, _, name = typename.split("/")
    return f"{package}/{name}"


@dataclass(frozen=True)
class GraphEntry:
    """One liveliness token of the graph, read field by field as the design document lists."""

    kind: str
    node: str
    """``/namespace/name``."""
    session: str
    topic: str = ""
    typename: str = ""
    """``sensor_msgs/msg/Image`` (from the DDS name in the token)."""
    type_hash: str = ""
    qos: str = ""

    @classmethod
    def read(cls, key: str) -> GraphEntry:
        parts = key.split("/")
        assert parts[0] == "@ros2_lv", key
        namespace = parts[7].replace("%", "/")
        node = f"{namespace.rstrip('/')}/{parts[8]}" if namespace != "/" else f"/{parts[8]}"
        if parts[5] == "NN":
            assert len(parts) == 9, key
            return cls("NN", node, parts[2])
        assert len(parts) == 13, key
        package, kind, dds = parts[10].split("::", 2)
        assert dds.startswith("dds_::") and dds.endswith("_"), key
        typename = f"{package}/{kind}/{dds.removeprefix('dds_::')[:-1]}"
        return cls(
            parts[5], node, parts[2], parts[9].replace("%", "/"), typename, parts[11], parts[12]
        )


@dataclass
class Received:
    """One sample a peer subscription took."""

    key: str
    message: Any
    sequence: int
    source_time_ns: int
    gid: bytes
    size: int


@dataclass
class Subscription:
    """What a peer subscription received, with a way to wait for it."""

    topic: str
    received: list[Received] = field(default_factory=list)
    undecodable: list[str] = field(default_factory=list)
    _cond: threading.Condition = field(default_factory=threading.Condition)

    def add(self, item: Received) -> None:
        with self._cond:
            self.received.append(item)
            self._cond.notify_all()

    def wait(self, count: int = 1, timeout_s: float = 20.0) -> list[Received]:
        with self._cond:
            if not self._cond.wait_for(lambda: len(self.received) >= count, timeout_s):
                raise AssertionError(
                    f"{self.topic}: {len(self.received)} of {count} messages in {timeout_s} s"
                    f" (undecodable: {self.undecodable[:3]})"
                )
            return list(self.received)


class PeerPublisher:
    """A peer's publisher: CDR from mcap-ros2-support, the attachment from zenoh.ext."""

    def __init__(self, publisher: Any, encode: Callable[[Any], bytes], gid: bytes) -> None:
        self._publisher = publisher
        self._encode = encode
        self._gid = gid
        self._sequence = itertools.count(1)

    def publish(self, message: Any) -> None:
        """``message`` as a dict of the definition's fields."""
        self.publish_raw(self._encode(message))

    def publish_raw(self, payload: bytes) -> None:
        attachment = z_serialize(
            (Int64(next(self._sequence)), Int64(time.time_ns()), [UInt8(b) for b in self._gid])
        )
        self._publisher.put(payload, attachment=attachment)


class RmwPeer:
    """One ROS 2 node on a Zenoh session, as rmw_zenoh would make it."""

    def __init__(
        self, session: zenoh.Session, domain: int = 0, name: str = "peer", namespace: str = "/"
    ) -> None:
        self.session = session
        self.domain = domain
        self.name = name
        self.namespace = namespace
        self.zid = str(session.zid())
        self._ids = itertools.count(1)
        self._closers: list[Callable[[], None]] = []
        self._tokens: dict[str, GraphEntry] = {}
        self._changed = threading.Condition()
        # The graph cache, as rmw_zenoh keeps it: the tokens already there, then each change.
        watcher = session.liveliness().declare_subscriber(
            f"@ros2_lv/{domain}/**", self._on_token, history=True
        )
        self._closers.append(watcher.undeclare)
        self._token("NN", 0, "")

    def _on_token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        with self._changed:
            if sample.kind == zenoh.SampleKind.DELETE:
                self._tokens.pop(key, None)
            else:
                self._tokens[key] = GraphEntry.read(key)
            self._changed.notify_all()

    def _token(self, kind: str, entity_id: int, topic_part: str) -> bytes:
        ns = "%" if self.namespace == "/" else self.namespace.replace("/", "%")
        key = f"@ros2_lv/{self.domain}/{self.zid}/0/{entity_id}/{kind}/%/{ns}/{self.name}"
        if topic_part:
            key += "/" + topic_part
        token = self.session.liveliness().declare_token(key)
        self._closers.append(token.undeclare)
        return hashlib.sha256(key.encode()).digest()[:16]

    def graph(self) -> list[GraphEntry]:
        """Every entity of this domain now (what ``ros2 node list`` and ``ros2 topic list``
        read)."""
        with self._changed:
            return list(self._tokens.values())

    def wait_for(
        self, done: Callable[[list[GraphEntry]], bool], timeout_s: float = 20.0
    ) -> list[GraphEntry]:
        """The graph once ``done`` holds for it."""
        with self._changed:
            if not self._changed.wait_for(lambda: done(list(self._tokens.values())), timeout_s):
                raise AssertionError(f"graph never as expected: {list(self._tokens.values())}")
            return list(self._tokens.values())

    def subscribe(
        self, topic: str, typename: str, *, transient_local: bool = False
    ) -> Subscription:
        """Take ``topic``'s samples of ``typename`` (Jazzy's hash), decoded with the peer's
        own definitions."""
        decode = generate_dynamic(short_name(typename), DEFINITIONS[typename])[short_name(typename)]
        key = f"{self.domain}/{topic.strip('/')}/{dds_name(typename)}/{JAZZY_HASHES[typename]}"
        found = Subscription(topic)

        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            attachment = sample.attachment
            if attachment is None:
                found.undecodable.append("no attachment")
                return
            seq, stamp, gid = z_deserialize(tuple[Int64, Int64, list[UInt8]], attachment)
            try:
                message = decode(payload)
            except Exception as e:  # a test peer reports whatever did not decode
                found.undecodable.append(f"{type(e).__name__}: {e}")
                return
            found.add(Received(str(sample.key_expr), message, seq, stamp, bytes(gid), len(payload)))

        qos = TRANSIENT_LOCAL_QOS if transient_local else DEFAULT_QOS
        subscriber: Any
        if transient_local:
            subscriber = zenoh.ext.declare_advanced_subscriber(
                self.session,
                key,
                on_sample,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
                recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
                subscriber_detection=True,
            )
        else:
            subscriber = self.session.declare_subscriber(key, on_sample)
        self._closers.append(subscriber.undeclare)
        mangled = topic.replace("/", "%")
        self._token(
            "MS",
            next(self._ids),
            f"{mangled}/{dds_name(typename)}/{JAZZY_HASHES[typename]}/{qos}",
        )
        return found

    def publisher(
        self, topic: str, typename: str, *, transient_local: bool = False
    ) -> PeerPublisher:
        """A publisher on ``topic`` with its MP token; TRANSIENT_LOCAL keeps its last sample."""
        encode = serialize_dynamic(short_name(typename), DEFINITIONS[typename])[
            short_name(typename)
        ]
        key = f"{self.domain}/{topic.strip('/')}/{dds_name(typename)}/{JAZZY_HASHES[typename]}"
        publisher: Any
        if transient_local:
            publisher = zenoh.ext.declare_advanced_publisher(
                self.session,
                key,
                cache=zenoh.ext.CacheConfig(max_samples=1),
                publisher_detection=True,
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=0.5
                ),
            )
        else:
            publisher = self.session.declare_publisher(key)
        self._closers.append(publisher.undeclare)
        qos = TRANSIENT_LOCAL_QOS if transient_local else DEFAULT_QOS
        mangled = topic.replace("/", "%")
        gid = self._token(
            "MP",
            next(self._ids),
            f"{mangled}/{dds_name(typename)}/{JAZZY_HASHES[typename]}/{qos}",
        )
        return PeerPublisher(publisher, encode, gid)

    def close(self) -> None:
        while self._closers:
            self._closers.pop()()
