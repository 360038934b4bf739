"""The seed's way of finding one box: depth picture -> points -> the room -> its middle and height.

The seed's ``measure.py``, on plain NumPy arrays, kept as the reference the tests check exactly
on the committed capture. Nothing here talks to Zenoh, MuJoCo or MCAP.

- :func:`depth_to_points` is the seed's step 3.4 as written: the middle of pixel ``u`` at
  ``u + 0.5``, so it takes the seed's cx (``lens.cx + 0.5`` of a real camera's CameraInfo).
- Points are in the optical frame (X right, Y down, Z forward) until ``to_world`` moves them.

Two ways to measure the box, giving the same counts and the same answer:

- the seed's, step by step: :func:`depth_to_points`, :func:`~onebox.geometry.to_world`,
  :func:`measure_box`;
- :func:`locate_box`, which finds the pixels standing above the table with one comparison
  against a per-pixel limit cached by picture size, lens and camera pose, and turns only those
  pixels into points.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onebox.geometry import Float32Array, Float64Array, Intrinsics

TOP_TOLERANCE_M = 0.001
"""The seed's "within a millimetre of the highest point": the top of the box."""


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


# --- the seed's steps -------------------------------------------------------------------------


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
    across, down = lens.rays(width, height)
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
    across, down = lens.rays(width, height)
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
