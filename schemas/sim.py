"""Simulated time and the simulator's ground truth."""

from __future__ import annotations

from schemas.base import Header, Message
from schemas.geometry import Pose, Vector3


class Clock(Message, frozen=True, kw_only=True):
    """The simulation's clock, as rosgraph_msgs/Clock."""

    clock_ns: int = 0
    """Simulated time, nanoseconds since the simulation started."""


class BoxTruth(Message, frozen=True, kw_only=True):
    """One box as it truly is, in the world frame."""

    pose: Pose = Pose()
    """The box's middle; the orientation's x axis runs along its length, z up."""
    size: Vector3 = Vector3()
    """Length (x, >= width), width (y) and height (z), metres."""
    on: int | None = None
    """The index (in ``GroundTruth.boxes``) of the box it stands on; None: on the table."""
    top_in_view: bool = False
    """Whether the whole top lies inside the main camera's picture."""
    top_pixels: int = 0
    """How many of the main camera's pixels see the top (not hidden by anything nearer)."""


class ObjectTruth(Message, frozen=True, kw_only=True):
    """One object that is not a box (for the locator to ignore), in the world frame."""

    shape: str = ""
    """``cylinder``, ``sphere`` or ``capsule``."""
    pose: Pose = Pose()
    """Its middle; the shape's axis is the world's z."""
    size: list[float] = []
    """MuJoCo's numbers for the shape: radius, and half the length of a cylinder or capsule."""


class TablePlane(Message, frozen=True, kw_only=True):
    """The table's top: the plane n . p + offset_m = 0 (n points up), and its extent."""

    normal: Vector3 = Vector3(z=1.0)
    offset_m: float = 0.0
    """-offset_m is the table top's height, metres."""
    size_x_m: float = 0.0
    size_y_m: float = 0.0


class GroundTruth(Message, frozen=True, kw_only=True):
    """What the simulator knows to be true, for tests and benchmarks; the locator never reads it.

    ``header`` carries the stamp of the capture it belongs to; ``frame_id`` is the world frame.
    ``box_pose`` and ``box_size`` are the first box's middle and edges (kept for readers of one
    box), None when the scene has no box. ``camera_pose`` is camera_optical_frame in the world,
    read from MuJoCo's own camera. ``boxes``, ``objects`` and ``table`` describe everything.
    """

    header: Header = Header()
    box_pose: Pose | None = None
    box_size: Vector3 | None = None
    camera_pose: Pose = Pose()
    boxes: list[BoxTruth] = []
    objects: list[ObjectTruth] = []
    table: TablePlane = TablePlane()
