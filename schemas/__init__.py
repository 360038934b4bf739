"""onebox's messages: msgspec structs, msgpack on the wire, field names as in the ROS messages."""

from schemas.base import Header, Message
from schemas.codec import Codec, codec, json_schema, type_name
from schemas.geometry import Pose, Quaternion, TFMessage, Transform, TransformStamped, Vector3
from schemas.sensor import (
    FLOAT32,
    UINT32,
    CameraInfo,
    Image,
    ImageView,
    PointCloud,
    PointCloudView,
    PointField,
)
from schemas.sim import BoxTruth, Clock, GroundTruth, ObjectTruth, TablePlane
from schemas.vision import (
    BoundingBox3D,
    Detection3D,
    Detection3DArray,
    ObjectHypothesis,
    SupportPlane,
)

__all__ = [
    "FLOAT32",
    "UINT32",
    "BoundingBox3D",
    "BoxTruth",
    "CameraInfo",
    "Clock",
    "Codec",
    "Detection3D",
    "Detection3DArray",
    "GroundTruth",
    "Header",
    "Image",
    "ImageView",
    "Message",
    "ObjectHypothesis",
    "ObjectTruth",
    "PointCloud",
    "PointCloudView",
    "PointField",
    "Pose",
    "Quaternion",
    "SupportPlane",
    "TFMessage",
    "TablePlane",
    "Transform",
    "TransformStamped",
    "Vector3",
    "codec",
    "json_schema",
    "type_name",
]
