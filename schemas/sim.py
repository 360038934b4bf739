"""Simulated time and the simulator's ground truth."""

from __future__ import annotations

from schemas.base import Header, Message
from schemas.geometry import Pose, Vector3


class Clock(Message, frozen=True, kw_only=True):
    """The simulation's clock, as rosgraph_msgs/Clock."""

    clock_ns: int = 0
    """Simulated time, nanoseconds since the simulation started."""


class GroundTruth(Message, frozen=True, kw_only=True):
    """What the simulator knows to be true, for tests and benchmarks; the locator never reads it.

    ``header.frame_id`` is the world frame. ``box_pose`` is the box's middle; ``box_size`` its
    three edges. Both are None when the scene has no box. ``camera_pose`` is
    camera_optical_frame in the world, read from MuJoCo's own camera.
    """

    header: Header = Header()
    box_pose: Pose | None = None
    box_size: Vector3 | None = None
    camera_pose: Pose = Pose()
