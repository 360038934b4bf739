"""The maths of finding one box: depth picture -> points -> the room -> the box's middle and height.

The seed's ``measure.py``, on plain NumPy arrays, so a test can run it on a recorded capture in
milliseconds. Nothing here talks to Zenoh, MuJoCo or MCAP.

- Pixels are measured from their top-left corner: the middle of pixel ``u`` is ``u + 0.5``.
- Points are in the optical frame (X right, Y down, Z forward) until :func:`to_world` moves them.
- "No reading" is NaN in a 32FC1 picture (metres) and 0 in a 16UC1 picture (millimetres);
  :func:`depth_metres` turns both into float32 metres with NaN, and zero, negative or infinite
  readings never count as a point.
- ``step`` is the length of one row in bytes, not in pixels.

Two ways to measure the box, giving the same counts and the same answer:

- the seed's, step by step: :func:`depth_to_points`, :func:`to_world`, :func:`measure_box`;
- :func:`locate_box`, the one the locator runs on every picture. It finds the pixels standing
  above the table with one comparison against a per-pixel limit cached by picture size, lens
  and camera pose, and turns only those pixels into points.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]

DEPTH_ENCODINGS: dict[str, str] = {"32FC1": "f4", "16UC1": "u2"}
"""Depth encodings understood, and the NumPy type of one pixel (byte order from is_bigendian)."""
COLOUR_ENCODINGS: dict[str, tuple[int, tuple[int, int, int]]] = {
    "rgb8": (3, (0, 1, 2)),
    "bgr8": (3, (2, 1, 0)),
    "rgba8": (4, (0, 1, 2)),
    "bgra8": (4, (2, 1, 0)),
    "mono8": (1, (0, 0, 0)),
}
"""Colour encodings understood: bytes a pixel, and which bytes are red, green and blue."""
MILLIMETRE_M = 0.001
TOP_TOLERANCE_M = 0.001
"""The seed's "within a millimetre of the highest point": the top of the box."""


class ImageError(ValueError):
    """Bytes that cannot be the picture their header describes; the message says why.

    ``kind`` names what is wrong (``encoding``, ``size`` or ``step``), so a caller reporting
    problems once per kind reports each of them.
    """

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class Intrinsics:
    """The four lens numbers, in pixels: K = [fx 0 cx; 0 fy cy; 0 0 1]."""

    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_k(cls, k: Sequence[float]) -> Intrinsics:
        """Read a row-major 3 x 3 K; raises ValueError when it cannot be a pinhole lens."""
        if len(k) != 9:
            raise ValueError(f"K has {len(k)} numbers, expected 9 (3 x 3, row-major)")
        fx, fy, cx, cy = float(k[0]), float(k[4]), float(k[2]), float(k[5])
        if not all(np.isfinite([fx, fy, cx, cy])) or fx <= 0.0 or fy <= 0.0:
            raise ValueError(f"K has fx={fx}, fy={fy}, cx={cx}, cy={cy}; fx and fy must be > 0")
        return cls(fx, fy, cx, cy)


@dataclass(frozen=True)
class BoxMeasurement:
    """The box, as the seed measures it: the middle and height of its top, in the world frame."""

    x: float
    """Middle of the top along world x, metres."""
    y: float
    """Middle of the top along world y, metres."""
    top_z: float
    """World z of the highest point, metres."""
    height: float
    """How far the top stands above the table (top_z - table_z), metres."""
    standing_count: int
    """Points more than min_height above the table."""
    top_count: int
    """Points within a millimetre of the highest one: the top, which gives the middle."""
    extent_x: float
    """How far the top's points spread along world x (max - min), metres."""
    extent_y: float
    """How far the top's points spread along world y (max - min), metres."""
    pixel_m: float = 0.0
    """How much one pixel covers on the top, metres (0 when unknown): one pixel wider than
    the spread of the pixel middles is the top's edge to edge."""

    @property
    def score(self) -> float:
        """How much of what stands above the table is one flat top, 0 to 1."""
        return self.top_count / self.standing_count if self.standing_count else 0.0


# --- pictures ------------------------------------------------------------------------------------


def _pixels(
    data: bytes, width: int, height: int, step: int, itemsize: int, dtype: np.dtype[np.generic]
) -> npt.NDArray[np.generic]:
    """A height x width x channels view of ``data`` (no copy), after checking every length."""
    if width <= 0 or height <= 0:
        raise ImageError(f"the picture is {width} x {height}; both must be at least 1", "size")
    row_bytes = width * itemsize
    if step < row_bytes:
        raise ImageError(
            f"step is {step} bytes but one row of {width} pixels needs {row_bytes}; "
            "step counts bytes, not pixels",
            "step",
        )
    if len(data) != step * height:
        raise ImageError(
            f"data is {len(data):,} bytes but step x height = {step} x {height} = "
            f"{step * height:,}",
            "size",
        )
    channels = itemsize // dtype.itemsize
    return np.ndarray(
        (height, width, channels),
        dtype=dtype,
        buffer=data,
        strides=(step, itemsize, dtype.itemsize),
    )


def depth_metres(
    data: bytes, *, width: int, height: int, step: int, encoding: str, is_bigendian: int = 0
) -> Float32Array:
    """A depth picture's bytes as float32 metres, NaN where there is no reading.

    32FC1 little-endian with no row padding is returned without a copy (read-only). 16UC1
    millimetres are scaled, and their 0 ("no reading") becomes NaN, so it can never turn into
    a point inside the lens. Raises :class:`ImageError` when the header does not fit the bytes.
    """
    if encoding not in DEPTH_ENCODINGS:
        raise ImageError(
            f"encoding {encoding!r} is not a depth picture; expected one of "
            f"{', '.join(DEPTH_ENCODINGS)}",
            "encoding",
        )
    dtype = np.dtype(("<", ">")[bool(is_bigendian)] + DEPTH_ENCODINGS[encoding])
    raw = _pixels(data, width, height, step, dtype.itemsize, dtype)[:, :, 0]
    if encoding == "16UC1":
        metres = raw.astype(np.float32)
        metres *= np.float32(MILLIMETRE_M)
        metres[raw == 0] = np.nan
        return metres
    if dtype.byteorder == ">" or not raw.flags.c_contiguous:
        return np.ascontiguousarray(raw, dtype=np.float32)
    return raw.view(np.float32)


def colour_rgb(
    data: bytes, *, width: int, height: int, step: int, encoding: str
) -> npt.NDArray[np.uint8]:
    """A colour picture's bytes as height x width x 3 red, green, blue (a view when possible)."""
    if encoding not in COLOUR_ENCODINGS:
        raise ImageError(
            f"encoding {encoding!r} is not a colour picture; expected one of "
            f"{', '.join(COLOUR_ENCODINGS)}",
            "encoding",
        )
    itemsize, order = COLOUR_ENCODINGS[encoding]
    pixels = _pixels(data, width, height, step, itemsize, np.dtype(np.uint8))
    if order == (0, 1, 2):
        return pixels[:, :, :3]  # type: ignore[return-value]
    return pixels[:, :, list(order)]  # type: ignore[return-value]


# --- the seed's steps ----------------------------------------------------------------------------


def depth_to_points(
    depth_m: npt.NDArray[np.floating], fx: float, fy: float, cx: float, cy: float
) -> Float64Array:
    """Every pixel becomes a point in the optical frame, one row of (x, y, z) each (seed 3.4).

    Pixels with no reading give a row of NaN in z (and x, y), which no comparison selects.
    """
    rows, cols = depth_m.shape
    v, u = np.mgrid[0:rows, 0:cols] + 0.5
    x = (u - cx) * depth_m / fx
    y = (v - cy) * depth_m / fy
    return np.stack([x, y, depth_m.astype(np.float64)], axis=-1).reshape(-1, 3)


def transform_matrix(
    translation: Sequence[float], quaternion_xyzw: Sequence[float]
) -> Float64Array:
    """A shift and a turn as a 4 x 4 matrix moving a child frame's points into its parent.

    Raises ValueError for a quaternion of length zero or any number that is not finite.
    """
    numbers = [*translation, *quaternion_xyzw]
    if len(numbers) != 7 or not np.all(np.isfinite(numbers)):
        raise ValueError(f"a transform needs 3 finite numbers and 4 finite numbers, got {numbers}")
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(quaternion_xyzw).as_matrix()
    matrix[:3, 3] = translation
    return matrix


def to_world(points: npt.NDArray[np.floating], matrix: Float64Array) -> Float64Array:
    """Move (N, 3) points with a 4 x 4 matrix: start at its position, walk its three columns."""
    result: Float64Array = points @ matrix[:3, :3].T + matrix[:3, 3]
    return result


def measure_box(
    points_world: npt.NDArray[np.floating],
    table_z: float = 0.0,
    min_height: float = 0.01,
) -> BoxMeasurement | None:
    """Seed steps 2 to 4 on world points: what stands, its top, the top's middle and height.

    None when nothing stands more than ``min_height`` above the table (no box in view).
    """
    z = points_world[:, 2]
    standing = points_world[z > table_z + min_height]
    if len(standing) == 0:
        return None
    top_z = float(standing[:, 2].max())
    top = standing[standing[:, 2] > top_z - TOP_TOLERANCE_M]
    return BoxMeasurement(
        x=float(top[:, 0].mean()),
        y=float(top[:, 1].mean()),
        top_z=top_z,
        height=top_z - table_z,
        standing_count=len(standing),
        top_count=len(top),
        extent_x=float(np.ptp(top[:, 0])),
        extent_y=float(np.ptp(top[:, 1])),
    )


# --- the fast way, for every picture -------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _rays(width: int, height: int, lens: Intrinsics) -> tuple[Float64Array, Float64Array]:
    """Each column's (u + 0.5 - cx) / fx and each row's (v + 0.5 - cy) / fy."""
    across: Float64Array = (np.arange(width, dtype=np.float64) + 0.5 - lens.cx) / lens.fx
    down: Float64Array = (np.arange(height, dtype=np.float64) + 0.5 - lens.cy) / lens.fy
    return across, down


@functools.lru_cache(maxsize=8)
def _standing_limit(
    width: int, height: int, lens: Intrinsics, row_z: tuple[float, float, float], gap_m: float
) -> tuple[Float32Array, bool]:
    """Per pixel, the depth at which that pixel's point is exactly at the standing threshold.

    A point's world z is ``depth * slope + camera_z`` with ``slope`` the third row of the
    rotation applied to the pixel's ray, so "more than ``gap_m`` above the camera's z" is
    ``depth * slope > gap_m``. When every ray points down (slope < 0, any camera that looks at
    the table) that is ``depth < gap_m / slope``: one comparison per pixel, and NaN never
    passes it. Otherwise the limit is returned as ``slope`` itself and the flag is False.
    The limit is loosened by a millionth so float32 rounding never loses a pixel; the
    candidates are checked again exactly in float64.
    """
    across, down = _rays(width, height, lens)
    slope = row_z[0] * across[np.newaxis, :] + row_z[1] * down[:, np.newaxis] + row_z[2]
    if np.all(slope < 0.0):
        limit = (gap_m / slope) * (1.0 + 1e-6) + 1e-9
        return limit.astype(np.float32), True
    return slope.astype(np.float32), False


def locate_box(
    depth_m: Float32Array,
    lens: Intrinsics,
    camera_to_world: Float64Array,
    table_z: float = 0.0,
    min_height: float = 0.01,
) -> BoxMeasurement | None:
    """The seed's measurement, computing points only for the pixels standing above the table.

    Gives the same standing and top counts as :func:`measure_box` on every point. None when
    nothing stands above the table (no box, or no reading at all).
    """
    height, width = depth_m.shape
    rotation = camera_to_world[:3, :3]
    camera = camera_to_world[:3, 3]
    row_z = (float(rotation[2, 0]), float(rotation[2, 1]), float(rotation[2, 2]))
    gap_m = float(table_z + min_height - camera[2])
    limit, downward = _standing_limit(width, height, lens, row_z, gap_m)
    flat = depth_m.reshape(-1)
    if downward:
        candidates = np.flatnonzero(flat < limit.reshape(-1))
    else:
        loose_gap_m = np.float32(gap_m - 1e-6 * abs(gap_m) - 1e-9)
        candidates = np.flatnonzero(flat * limit.reshape(-1) > loose_gap_m)
    if len(candidates) == 0:
        return None
    # The exact seed arithmetic, in float64, on the few candidates only; a zero, negative or
    # infinite reading is no reading, whatever the comparison said.
    d = flat[candidates].astype(np.float64)
    real = (d > 0.0) & (d < np.inf)
    candidates, d = candidates[real], d[real]
    across, down = _rays(width, height, lens)
    rows, cols = np.divmod(candidates, width)
    ray_x, ray_y = across[cols], down[rows]
    z = camera[2] + rotation[2, 0] * (ray_x * d) + rotation[2, 1] * (ray_y * d) + rotation[2, 2] * d
    keep = z > table_z + min_height
    if not keep.any():
        return None
    d, z, ray_x, ray_y = d[keep], z[keep], ray_x[keep], ray_y[keep]
    top_z = float(z.max())
    top = z > top_z - TOP_TOLERANCE_M
    d_top, x_cam, y_cam = d[top], ray_x[top] * d[top], ray_y[top] * d[top]
    x = camera[0] + rotation[0, 0] * x_cam + rotation[0, 1] * y_cam + rotation[0, 2] * d_top
    y = camera[1] + rotation[1, 0] * x_cam + rotation[1, 1] * y_cam + rotation[1, 2] * d_top
    return BoxMeasurement(
        x=float(x.mean()),
        y=float(y.mean()),
        top_z=top_z,
        height=top_z - table_z,
        standing_count=len(z),
        top_count=len(d_top),
        extent_x=float(np.ptp(x)),
        extent_y=float(np.ptp(y)),
        pixel_m=float(d_top.mean()) / lens.fx,
    )


def has_reading(depth_m: Float32Array) -> bool:
    """Whether any pixel has a reading (a finite depth above zero)."""
    return bool(np.any((depth_m > 0.0) & (depth_m < np.inf)))


# --- the point cloud -----------------------------------------------------------------------------

CLOUD_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
"""One point of camera/points: x, y, z in metres (optical frame), rgb as 0x00RRGGBB."""


def cloud_points(
    depth_m: Float32Array, lens: Intrinsics, colour: npt.NDArray[np.uint8] | None = None
) -> npt.NDArray[np.void]:
    """One point a pixel with a reading, in the optical frame, with its colour (depth_image_proc).

    Pixels with no reading (NaN, zero, negative, infinite) are skipped, so every point is real.
    """
    height, width = depth_m.shape
    flat = depth_m.reshape(-1)
    with np.errstate(invalid="ignore"):
        valid = np.flatnonzero(np.isfinite(flat) & (flat > 0.0))
    across, down = _rays(width, height, lens)
    rows, cols = np.divmod(valid, width)
    d = flat[valid]
    points = np.empty(len(valid), dtype=CLOUD_DTYPE)
    points["x"] = across[cols] * d
    points["y"] = down[rows] * d
    points["z"] = d
    if colour is None:
        points["rgb"] = 0
    else:
        rgb = colour.reshape(-1, 3)[valid].astype(np.uint32)
        points["rgb"] = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    return points
