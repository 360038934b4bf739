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
    """One object: what it is (``results``: "box", and the catalogue entry it fits when a
    catalogue is used), where it is and how large (``bbox``), its id in the stream."""

    header: Header = Header()
    results: list[ObjectHypothesis] = []
    bbox: BoundingBox3D = BoundingBox3D()
    id: str = ""
    hidden_sides: int = 0
    """How many sides of its top something nearer hides: its size along them is a lower
    bound (0 to 4)."""
    height_seen: bool = True
    """False when the level it stands on is not seen beside it, on the support or on a top
    that reaches under it (a carton in a full layer, or among lower neighbours): the height
    is then measured to the level found beside it, or is the catalogue's."""


class Detection3DArray(Message, frozen=True, kw_only=True):
    """Everything found in one capture; empty when nothing was found."""

    header: Header = Header()
    detections: list[Detection3D] = []


class SupportPlane(Message, frozen=True, kw_only=True):
    """The surface the boxes stand on, as the locator found it: the plane n . p + offset_m = 0.

    ``header.frame_id`` is the world frame, or the camera's optical frame when no pose is known.
    ``normal`` is a unit vector pointing up, away from the surface (towards the camera).
    """

    header: Header = Header()
    normal: Vector3 = Vector3(z=1.0)
    offset_m: float = 0.0
    """n . p + offset_m = 0 for every point p on the plane: -offset_m is its height along n."""
    inlier_share: float = 0.0
    """The share of the readings the plane was fitted to that lie on it, 0 to 1."""
    tilt_deg: float | None = None
    """How far the normal is from the world's up, degrees; None in the camera's frame."""
