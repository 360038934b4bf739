"""What was found: vision_msgs' 3D detections, as msgspec structs."""

from __future__ import annotations

from schemas.base import Header, Message
from schemas.geometry import Pose, Vector3


class ObjectHypothesis(Message, frozen=True, kw_only=True):
    """What the detector thinks the object is, and how sure it is (0 to 1)."""

    class_id: str = ""
    score: float = 0.0


class BoundingBox3D(Message, frozen=True, kw_only=True):
    """The smallest box around an object: its middle and its edges (metres)."""

    center: Pose = Pose()
    size: Vector3 = Vector3()


class Detection3D(Message, frozen=True, kw_only=True):
    header: Header = Header()
    results: list[ObjectHypothesis] = []
    bbox: BoundingBox3D = BoundingBox3D()
    id: str = ""


class Detection3DArray(Message, frozen=True, kw_only=True):
    """Everything found in one capture; empty when nothing was found."""

    header: Header = Header()
    detections: list[Detection3D] = []
