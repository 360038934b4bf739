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
from services import measure

ImageError = measure.ImageError


def rgb(image: Image) -> npt.NDArray[np.uint8]:
    """A colour picture (rgb8, bgr8, rgba8, bgra8 or mono8) as (height, width, 3), red first."""
    return measure.colour_rgb(
        image.data, width=image.width, height=image.height, step=image.step, encoding=image.encoding
    )


def depth_m(image: Image) -> npt.NDArray[np.float32]:
    """A depth picture (32FC1 metres or 16UC1 millimetres) as float32 metres, NaN = no reading.

    16UC1 uses 0 for "no reading"; it becomes NaN here, so a hole never turns into a point
    inside the lens.
    """
    return measure.depth_metres(
        image.data,
        width=image.width,
        height=image.height,
        step=image.step,
        encoding=image.encoding,
        is_bigendian=image.is_bigendian,
    )


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
