"""Pictures, lenses and point clouds: sensor_msgs, as msgspec structs."""

from __future__ import annotations

from schemas.base import Header, Message


class Image(Message, frozen=True, kw_only=True):
    """One picture, row after row, top row first.

    ``encoding`` is ``rgb8`` (3 bytes a pixel), ``32FC1`` (float32 metres, NaN = no reading)
    or ``16UC1`` (uint16 millimetres, 0 = no reading). ``step`` is the length of one row in
    bytes, not in pixels.
    """

    header: Header = Header()
    height: int = 0
    width: int = 0
    encoding: str = ""
    is_bigendian: int = 0
    step: int = 0
    data: bytes = b""


class CameraInfo(Message, frozen=True, kw_only=True):
    """The lens: K = [fx 0 cx; 0 fy cy; 0 0 1] in pixels, row-major.

    As real cameras' drivers, OpenCV and depth_image_proc write it: the middle of pixel u is
    at u, so cx of a centred 320-wide lens is 159.5.
    """

    header: Header = Header()
    height: int = 0
    width: int = 0
    distortion_model: str = "plumb_bob"
    d: list[float] = []
    """Distortion coefficients; all zero for the simulated camera."""
    k: list[float] = []
    """3 x 3 intrinsic matrix, row-major."""
    r: list[float] = []
    """3 x 3 rectification matrix, row-major."""
    p: list[float] = []
    """3 x 4 projection matrix, row-major."""


class PointField(Message, frozen=True, kw_only=True):
    """One field of each point in a PointCloud: its name, byte offset and type."""

    name: str
    offset: int
    datatype: int
    """As sensor_msgs/PointField: 7 = FLOAT32, 6 = UINT32."""
    count: int = 1


FLOAT32 = 7
UINT32 = 6


class PointCloud(Message, frozen=True, kw_only=True):
    """Points packed one after another, as sensor_msgs/PointCloud2 with height 1.

    onebox's clouds have x, y, z (float32 metres) and rgb (uint32, 0x00RRGGBB), 16 bytes a point.
    """

    header: Header = Header()
    height: int = 1
    width: int = 0
    fields: list[PointField] = []
    is_bigendian: bool = False
    point_step: int = 0
    row_step: int = 0
    data: bytes = b""
    is_dense: bool = True


class ImageView(Message, frozen=True, kw_only=True, tag="Image"):
    """An :class:`Image` whose ``data`` is a view, not a copy: the same message on the wire.

    Decoding into it leaves the pixels where they are, in the received payload; encoding one
    writes the bytes an :class:`Image` would, reading the pixels from wherever ``data`` points
    (a ROS message's buffer, a NumPy array). A bridge moves a picture with one copy this way.
    The fields are :class:`Image`'s, in its order (a test keeps them so).
    """

    header: Header = Header()
    height: int = 0
    width: int = 0
    encoding: str = ""
    is_bigendian: int = 0
    step: int = 0
    data: memoryview = memoryview(b"")


class PointCloudView(Message, frozen=True, kw_only=True, tag="PointCloud"):
    """A :class:`PointCloud` whose ``data`` is a view, as :class:`ImageView` is an Image's."""

    header: Header = Header()
    height: int = 1
    width: int = 0
    fields: list[PointField] = []
    is_bigendian: bool = False
    point_step: int = 0
    row_step: int = 0
    data: memoryview = memoryview(b"")
    is_dense: bool = True
