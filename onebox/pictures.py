"""Pictures and point clouds as NumPy arrays, both ways: the job cv_bridge did in the seed.

Every decoder honours ``step`` (bytes a row, which may be more than width x bytes a pixel)
and the byte order, so a padded or big-endian picture comes out right instead of sheared.
"No reading" is NaN in a 32FC1 picture (metres) and 0 in a 16UC1 picture (millimetres);
:func:`depth_metres` turns both into float32 metres with NaN, and zero, negative or infinite
readings never become a point. No Zenoh and no Rerun here: every command and the tests use it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from onebox.geometry import Float32Array, Intrinsics
from schemas import FLOAT32, UINT32, Header, Image, PointCloud

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


class ImageError(ValueError):
    """Bytes that cannot be the picture their header describes; the message says why.

    ``kind`` names what is wrong (``encoding``, ``size`` or ``step``), so a caller reporting
    problems once per kind reports each of them.
    """

    def __init__(self, message: str, kind: str) -> None:
        super().__init__(message)
        self.kind = kind


# --- bytes to arrays ------------------------------------------------------------------------


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


def rgb(image: Image) -> npt.NDArray[np.uint8]:
    """A colour picture (rgb8, bgr8, rgba8, bgra8 or mono8) as (height, width, 3), red first."""
    return colour_rgb(
        image.data, width=image.width, height=image.height, step=image.step, encoding=image.encoding
    )


def depth_m(image: Image) -> npt.NDArray[np.float32]:
    """A depth picture (32FC1 metres or 16UC1 millimetres) as float32 metres, NaN = no reading.

    16UC1 uses 0 for "no reading"; it becomes NaN here, so a hole never turns into a point
    inside the lens.
    """
    return depth_metres(
        image.data,
        width=image.width,
        height=image.height,
        step=image.step,
        encoding=image.encoding,
        is_bigendian=image.is_bigendian,
    )


# --- arrays to messages --------------------------------------------------------------------------


def rgb8_image(rgb: npt.NDArray[np.uint8], header: Header) -> Image:
    """A (height, width, 3) red-first array as an rgb8 Image."""
    height, width = rgb.shape[:2]
    return Image(
        header=header,
        height=height,
        width=width,
        encoding="rgb8",
        step=width * 3,
        data=np.ascontiguousarray(rgb, dtype=np.uint8).tobytes(),
    )


def depth_image(depth_m: Float32Array, header: Header, encoding: str = "32FC1") -> Image:
    """Depth in metres (NaN = no reading) as a 32FC1 Image, or a 16UC1 one in whole
    millimetres with 0 for no reading (and for anything beyond 65.535 m)."""
    height, width = depth_m.shape
    if encoding == "32FC1":
        return Image(
            header=header,
            height=height,
            width=width,
            encoding="32FC1",
            is_bigendian=int(not np.little_endian),
            step=width * 4,
            data=np.ascontiguousarray(depth_m, dtype=np.float32).tobytes(),
        )
    if encoding == "16UC1":
        with np.errstate(invalid="ignore"):
            mm = np.rint(depth_m * np.float32(1.0 / MILLIMETRE_M))
            mm[~((mm > 0) & (mm <= 65535))] = 0
        return Image(
            header=header,
            height=height,
            width=width,
            encoding="16UC1",
            step=width * 2,
            data=mm.astype("<u2").tobytes(),
        )
    raise ImageError(f"cannot write depth as {encoding!r}; expected 32FC1 or 16UC1", "encoding")


class Cloud(NamedTuple):
    """The points of a PointCloud with a reading: (n, 3) metres and (n, 3) colours."""

    xyz: npt.NDArray[np.float32]
    rgb: npt.NDArray[np.uint8]


def cloud(message: PointCloud) -> Cloud:
    """x, y, z (and rgb when present) of every point that is not NaN."""
    offsets = {f.name: (f.offset, f.datatype) for f in message.fields}
    missing = {"x", "y", "z"} - offsets.keys()
    if missing:
        raise ImageError(f"point cloud has no field {sorted(missing)}", "fields")
    if any(offsets[name][1] != FLOAT32 for name in "xyz"):
        raise ImageError("point cloud x, y, z must be FLOAT32", "fields")
    count = message.width * message.height
    if message.point_step <= 0 or len(message.data) < count * message.point_step:
        raise ImageError(
            f"{len(message.data)} bytes of data for {count} points of {message.point_step} bytes",
            "size",
        )
    order = ">" if message.is_bigendian else "<"
    names, formats, where = ["x", "y", "z"], [f"{order}f4"] * 3, [offsets[n][0] for n in "xyz"]
    if "rgb" in offsets:
        if offsets["rgb"][1] != UINT32:
            raise ImageError("point cloud rgb must be UINT32 0x00RRGGBB", "fields")
        names.append("rgb")
        formats.append(f"{order}u4")
        where.append(offsets["rgb"][0])
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": where, "itemsize": message.point_step}
    )
    points = np.frombuffer(message.data, dtype, count=count)
    xyz = np.stack([points["x"], points["y"], points["z"]], axis=1).astype(np.float32)
    keep = np.isfinite(xyz).all(axis=1)
    if "rgb" in names:
        packed = points["rgb"][keep]
        colours = np.stack([packed >> 16, packed >> 8, packed], axis=1) & 0xFF
    else:
        colours = np.full((int(keep.sum()), 3), 255)
    return Cloud(xyz[keep], colours.astype(np.uint8))


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
    across, down = lens.rays(width, height)
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
