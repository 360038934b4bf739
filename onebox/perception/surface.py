"""What the camera sees of the surfaces over the support: heights, which way they face, where
the depth steps.

Contract: :func:`read_surface` takes a depth picture (float32 metres, NaN = no reading), the
lens and the :class:`~onebox.perception.support.Support`, and returns a :class:`Surface`: every
pixel's height above the support, whether it faces up (a top, not a side face), its noise
sigma(z) and the pixels where the height steps between neighbours by more than the noise
allows. OpenCV's box filter, then one pass over the pixels (numba).

The physical effects, one line each:

- **Height.** A pixel's point is ``z * ray``; its height is ``normal . point + offset``, so the
  height of every pixel is one multiply-add, ``z * slope + offset`` with ``slope`` the rays'
  dot product with the normal (cached per lens and plane).
- **Noise grows with distance.** sigma(z) = sigma_support * (z / z_support)^2 (stereo and
  structured light alike), floored; every tolerance below is a multiple of it.
- **Which way a surface faces.** The normal of the surface through a pixel follows from the
  depth's gradient alone: for ``P = z * ray``, ``n ~ (-fx z_u, -fy z_v, z + (u - cx) z_u +
  (v - cy) z_v)``. The gradient is taken across a few pixels of box-filtered depth (wider where
  the noise is larger), so a top's noise does not turn it into a side; where the noise is
  small against a pixel's footprint, also across one pixel: either side, and on the side where
  the surface goes on (the smaller step to a neighbour, each way), so a top a few pixels wide,
  an edge within every window on it, keeps its facing. A top faces up within
  ``MAX_TOP_TILT_DEG``; a side face, a can's flank or a smeared edge does not.
- **Depth steps.** Where the height spread of a pixel's 3 x 3 neighbourhood passes
  ``STEP_SIGMAS`` sigma(z) (and ``MIN_STEP_M``), two surfaces meet: the pixel is a boundary.
  With independent errors, only where the heights through a 3 x 3 median step too (a pixel
  away at most) or at a crack a pixel wide: a noise tail is no edge.
- **No reading.** NaN is nowhere: it faces no way and belongs to no top.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import kernels
from onebox.perception.support import SIGMA_FLOOR_M, Support

Float32Array = npt.NDArray[np.float32]
BoolArray = npt.NDArray[np.bool_]

MAX_TOP_TILT_DEG = 30.0
"""A pixel whose surface turns further than this from the support's normal is no top's (a lid
that bulges or leans tilts up to ~12 degrees; the per-pixel normal adds its noise)."""
STEP_SIGMAS = 5.0
"""A height spread across 3 x 3 pixels beyond this many sigma(z) is a step between surfaces."""
MIN_STEP_M = 0.004
"""...and beyond this, whatever the noise: print and renderer precision make no step."""
LUMPY_NOISE_M = 0.001
"""Below this noise at the support, lumps tilt a top too little to matter."""
NORMAL_REACH_PX = 2
"""The depth's gradient is taken this many pixels either side (more when noisy, see below)."""

QUIET_SHARE = 0.25
"""Noise under this share of a pixel's footprint leaves the gradient across one pixel either
side within a few degrees (1 sigma about 3.5): narrow tops keep their facing."""


@dataclass(frozen=True)
class Surface:
    """Per-pixel readings of one depth picture against its support (all H x W)."""

    height_m: Float32Array
    """Height above the support; NaN where there is no reading."""
    sigma_m: Float32Array
    """The depth noise expected at each pixel's distance."""
    up: BoolArray
    """The surface through the pixel faces up (within MAX_TOP_TILT_DEG of the normal)."""
    step: BoolArray
    """The height steps across the pixel's 3 x 3 neighbourhood: two surfaces meet here."""
    slope: Float32Array
    """Height per metre of depth along each pixel's ray (height = depth * slope + offset)."""
    reach_px: int
    """How many pixels either side the normals were taken across (edges blur this far)."""
    quiet: BoolArray
    """The noise is under ``QUIET_SHARE`` of the pixel's footprint: a surface a few pixels
    wide is still seen for what it is."""


@functools.lru_cache(maxsize=8)
def _rays(lens: Intrinsics, width: int, height: int) -> tuple[Float32Array, Float32Array]:
    """Every pixel's ray x/z and y/z (middle of pixel u at u)."""
    across = ((np.arange(width, dtype=np.float32) - lens.cx) / lens.fx).astype(np.float32)
    down = ((np.arange(height, dtype=np.float32) - lens.cy) / lens.fy).astype(np.float32)
    return across, down


@functools.lru_cache(maxsize=8)
def height_slope(
    lens: Intrinsics, width: int, height: int, normal: tuple[float, float, float]
) -> Float32Array:
    """``normal . ray`` for every pixel: height = depth * slope + offset."""
    across, down = _rays(lens, width, height)
    slope = (
        np.float32(normal[0]) * across[None, :]
        + np.float32(normal[1]) * down[:, None]
        + np.float32(normal[2])
    )
    result: Float32Array = np.ascontiguousarray(slope, dtype=np.float32)
    return result


def read_surface(depth_m: Float32Array, lens: Intrinsics, support: Support) -> Surface:
    """Heights, noise, facing and steps for every pixel (see the module docstring): the box
    filters and the 3 x 3 spread by OpenCV, the rest in numba passes
    (:func:`onebox.perception.kernels.surface_heights`, :func:`~onebox.perception.kernels.
    faces_up`, :func:`~onebox.perception.kernels.surface_steps`)."""
    rows, cols = depth_m.shape
    slope = height_slope(lens, cols, rows, support.normal_camera)
    depth = np.ascontiguousarray(depth_m, dtype=np.float32)
    reach = normal_reach(support)
    lens_f = np.array([lens.fx, lens.fy, lens.cx, lens.cy], dtype=np.float32)
    plane = np.array(
        [
            *support.normal_camera,
            support.offset_camera_m,
            support.sigma_m,
            1.0 / support.distance_m,
        ],
        dtype=np.float32,
    )
    limits = np.array(
        [
            SIGMA_FLOOR_M,
            math.cos(math.radians(MAX_TOP_TILT_DEG)),
            STEP_SIGMAS,
            MIN_STEP_M,
            QUIET_SHARE,
            lens.fx,
        ],
        dtype=np.float32,
    )
    height, sigma, for_high, for_low, quiet, counted, filled = kernels.surface_heights(
        depth, slope, plane, limits
    )

    def facing(reach: int) -> BoolArray:
        window = (2 * reach + 1, 2 * reach + 1)
        weight = cv2.boxFilter(counted, -1, window, normalize=False)
        total = cv2.boxFilter(filled, -1, window, normalize=False)
        up: BoolArray = kernels.faces_up(
            depth,
            np.asarray(weight, dtype=np.float32),
            np.asarray(total, dtype=np.float32),
            reach,
            lens_f,
            plane,
            limits,
        )
        return up

    up = facing(reach)
    # A top a few pixels wide has no pixel whose wide window misses its edges: where the noise
    # is small against a pixel's footprint, the gradient across one pixel is steady enough to
    # say which way it faces, taken either side or on the side away from an edge beside it.
    if quiet.any():
        sided = kernels.faces_up_sided(depth, lens_f, plane, limits)
        kernels.merge_flags(up, facing(1) | sided, quiet)
    # The 3 x 3 spread of heights; no reading counts as neither high nor low.
    square = np.ones((3, 3), np.uint8)
    high = np.asarray(cv2.dilate(for_high, square), dtype=np.float32)
    low = np.asarray(cv2.erode(for_low, square), dtype=np.float32)
    step = kernels.surface_steps(depth, sigma, high, low, limits)
    if not lumpy(support):
        # Independent errors' tails make steps here and there on a flat top and shatter it: a
        # step counts where the heights through a 3 x 3 median step too, a pixel away at most
        # (the median rounds a corner off), or at a crack a pixel wide (which it wipes out).
        settled = np.asarray(cv2.medianBlur(kernels.read_or(height, counted, 0.0), 3), np.float32)
        settled_high = kernels.read_or(settled, counted, -np.inf)
        settled_low = kernels.read_or(settled, counted, np.inf)
        near = kernels.settled_steps(
            height,
            sigma,
            np.asarray(cv2.dilate(settled_high, square), np.float32),
            np.asarray(cv2.erode(settled_low, square), np.float32),
            limits,
        )
        kernels.keep_flags(step, np.asarray(cv2.dilate(near, square), np.uint8))
    return Surface(height, sigma, up, step, slope, reach, quiet)


def lumpy(support: Support) -> bool:
    """Whether the depth's errors come in lumps wider than a pixel, large enough to matter."""
    return support.lump_px > 1.0 and support.sigma_m > LUMPY_NOISE_M


def normal_reach(support: Support) -> int:
    """How many pixels either side the depth's gradient is taken: errors that come in lumps
    tilt a flat top over the lump's width, so look wider (when there is noise to speak of: a
    wider window also blurs a narrow top's normals into its neighbours')."""
    if lumpy(support):
        return min(math.ceil(support.lump_px) + 1, 6)
    return NORMAL_REACH_PX
