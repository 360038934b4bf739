"""The key table: every key the pipeline uses, and the message type each carries.

Keys keep the ROS topic names without the leading slash; a ``--namespace`` prefix is put in
front by :class:`onebox.bus.Bus`, never here. Name keys through this module instead of writing
the strings, so a key can be found, renamed and typed in one place.
"""

from __future__ import annotations

from dataclasses import dataclass

from schemas import (
    CameraInfo,
    Clock,
    Detection3DArray,
    GroundTruth,
    Image,
    Message,
    PointCloud,
    SupportPlane,
    TFMessage,
    TransformStamped,
)


@dataclass(frozen=True)
class CameraKeys:
    """The keys of one camera, under its name (``camera`` or ``basic_camera``)."""

    name: str

    @property
    def colour(self) -> str:
        """Image, rgb8."""
        return f"{self.name}/image_raw"

    @property
    def depth(self) -> str:
        """Image, 32FC1 metres (NaN = no reading) or 16UC1 millimetres (0 = no reading)."""
        return f"{self.name}/depth/image_raw"

    @property
    def info(self) -> str:
        """CameraInfo: the lens."""
        return f"{self.name}/camera_info"

    @property
    def pose(self) -> str:
        """TransformStamped world -> the optical frame, stamped with each capture."""
        return f"{self.name}/pose"

    @property
    def points(self) -> str:
        """PointCloud in the optical frame."""
        return f"{self.name}/points"


CAMERA = CameraKeys("camera")
BASIC_CAMERA = CameraKeys("basic_camera")
DEPTH_KEYS = frozenset({CAMERA.depth, BASIC_CAMERA.depth})
"""The keys that carry depth pictures (16UC1 or 32FC1), not colour."""
TF_STATIC = "tf_static"
CLOCK = "clock"
DETECTIONS = "detections"
SUPPORT = "support"
GROUND_TRUTH = "sim/ground_truth"

TYPES: dict[str, type[Message]] = {
    CAMERA.colour: Image,
    CAMERA.depth: Image,
    CAMERA.info: CameraInfo,
    CAMERA.pose: TransformStamped,
    CAMERA.points: PointCloud,
    BASIC_CAMERA.colour: Image,
    BASIC_CAMERA.depth: Image,
    BASIC_CAMERA.info: CameraInfo,
    BASIC_CAMERA.pose: TransformStamped,
    TF_STATIC: TFMessage,
    CLOCK: Clock,
    DETECTIONS: Detection3DArray,
    SUPPORT: SupportPlane,
    GROUND_TRUTH: GroundTruth,
}
"""The pipeline's keys, without namespace, and the type each carries."""


def type_for_key(key: str, namespace: str = "") -> type[Message] | None:
    """The type a key carries, or None for a key that is not the pipeline's."""
    prefix = f"{namespace.strip('/')}/" if namespace else ""
    return TYPES.get(key.removeprefix(prefix))
