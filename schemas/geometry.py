"""Positions, turns and transforms: geometry_msgs and tf2_msgs, as msgspec structs."""

from __future__ import annotations

from schemas.base import Header, Message


class Vector3(Message, frozen=True, kw_only=True):
    """A vector, metres unless a field says otherwise."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class Quaternion(Message, frozen=True, kw_only=True):
    """A turn as a unit quaternion (x, y, z, w), the order ROS and SciPy use."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


class Pose(Message, frozen=True, kw_only=True):
    """Where something is (metres) and which way it faces."""

    position: Vector3 = Vector3()
    orientation: Quaternion = Quaternion()


class Transform(Message, frozen=True, kw_only=True):
    """The shift and the turn that move a point from a child frame into its parent frame."""

    translation: Vector3 = Vector3()
    rotation: Quaternion = Quaternion()


class TransformStamped(Message, frozen=True, kw_only=True):
    """``header.frame_id`` is the parent frame, ``child_frame_id`` the child."""

    header: Header = Header()
    child_frame_id: str = ""
    transform: Transform = Transform()


class TFMessage(Message, frozen=True, kw_only=True):
    """A batch of transforms, as published on ``tf_static``."""

    transforms: list[TransformStamped] = []
