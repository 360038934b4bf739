"""Pictures and point clouds as NumPy arrays: the job cv_bridge did in the seed.

Every decoder honours ``step`` (bytes a row, which may be more than width x bytes a pixel)
and the byte order, so a padded or big-endian picture comes out right instead of sheared.
No Zenoh and no Rerun here: the viewer, ``onebox pixels`` and the tests all use it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from schemas import FLOAT32, UINT32, Image, PointCloud

# encoding: (bytes per channel, channels, NumPy kind); the byte order comes from is_bigendian.
_ENCODINGS: dict[str, tuple[int, int, str]] = {
    "rgb8": (1, 3, "u"),
    "bgr8": (1, 3, "u"),
    "mono8": (1, 1, "u"),
    "16UC1": (2, 1, "u"),
    "32FC1": (4, 1, "f"),
}


class ImageError(ValueError):
    """A picture whose encoding, size or data do not agree."""


def _pixels(image: Image) -> npt.NDArray[np.generic]:
    """The picture as (height, width) or (height, width, channels), rows top first."""
    if image.encoding not in _ENCODINGS:
        raise ImageError(f"encoding {image.encoding!r} is not one of {sorted(_ENCODINGS)}")
    size, channels, kind = _ENCODINGS[image.encoding]
    row_bytes = image.width * size * channels
    if image.step < row_bytes:
        raise ImageError(
            f"step {image.step} is shorter than a row of {image.width} {image.encoding} pixels "
            f"({row_bytes} bytes)"
        )
    if len(image.data) < image.step * image.height:
        raise ImageError(
            f"{len(image.data)} bytes of data, but {image.height} rows of step {image.step} need "
            f"{image.step * image.height}"
        )
    rows = np.frombuffer(image.data, np.uint8, count=image.step * image.height)
    rows = rows.reshape(image.height, image.step)[:, :row_bytes]
    dtype = np.dtype(f"{'>' if image.is_bigendian else '<'}{kind}{size}")
    shape = (image.height, image.width, channels) if channels > 1 else (image.height, image.width)
    return np.ascontiguousarray(rows).view(dtype).reshape(shape)


def rgb(image: Image) -> npt.NDArray[np.uint8]:
    """A colour picture (rgb8, bgr8 or mono8) as (height, width, 3) uint8, red first."""
    pixels = _pixels(image)
    if image.encoding == "bgr8":
        return np.ascontiguousarray(pixels[:, :, ::-1]).astype(np.uint8)
    if image.encoding == "mono8":
        return np.repeat(pixels[:, :, None], 3, axis=2).astype(np.uint8)
    if image.encoding != "rgb8":
        raise ImageError(f"encoding {image.encoding!r} is not a colour picture")
    return pixels.astype(np.uint8)


def depth_m(image: Image) -> npt.NDArray[np.float32]:
    """A depth picture (32FC1 metres or 16UC1 millimetres) as float32 metres, NaN = no reading.

    16UC1 uses 0 for "no reading"; it becomes NaN here, so a hole never turns into a point
    inside the lens.
    """
    pixels = _pixels(image)
    if image.encoding == "32FC1":
        return pixels.astype(np.float32)
    if image.encoding == "16UC1":
        metres = pixels.astype(np.float32) / 1000.0
        metres[pixels == 0] = np.nan
        return metres
    raise ImageError(f"encoding {image.encoding!r} is not a depth picture")


class Cloud(NamedTuple):
    """The points of a PointCloud with a reading: (n, 3) metres and (n, 3) colours."""

    xyz: npt.NDArray[np.float32]
    rgb: npt.NDArray[np.uint8]


def cloud(message: PointCloud) -> Cloud:
    """x, y, z (and rgb when present) of every point that is not NaN."""
    offsets = {f.name: (f.offset, f.datatype) for f in message.fields}
    missing = {"x", "y", "z"} - offsets.keys()
    if missing:
        raise ImageError(f"point cloud has no field {sorted(missing)}")
    if any(offsets[name][1] != FLOAT32 for name in "xyz"):
        raise ImageError("point cloud x, y, z must be FLOAT32")
    count = message.width * message.height
    if message.point_step <= 0 or len(message.data) < count * message.point_step:
        raise ImageError(
            f"{len(message.data)} bytes of data for {count} points of {message.point_step} bytes"
        )
    order = ">" if message.is_bigendian else "<"
    names, formats, where = ["x", "y", "z"], [f"{order}f4"] * 3, [offsets[n][0] for n in "xyz"]
    if "rgb" in offsets:
        if offsets["rgb"][1] != UINT32:
            raise ImageError("point cloud rgb must be UINT32 0x00RRGGBB")
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
