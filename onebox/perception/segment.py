"""Splitting what stands above the support into objects, and finding each object's flat top.

Contract: :func:`plateaus` takes the height map (metres above the support, NaN where no
reading), the depth, the per-pixel noise and, optionally, the colour picture (aligned with the
depth, pixel for pixel) and returns a label picture of separate standing pieces plus their
slices. Whole-array work only; the caller loops over the (few) pieces.

- A pixel stands when it is more than ``max(min_height, 4 sigma(z))`` above the support.
- Between two neighbouring pixels a height step larger than ``max(3 mm, 4 sigma(z))`` is a
  break: the LOWER pixel of the pair is cut, so a top keeps its outline pixels and the side
  below it is cut away. A speckle (much nearer) cuts its neighbours out and then stands alone,
  too small to count.
- Touching cartons of one height leave no step that noisy depth can see; where a colour picture
  is given, a brightness change larger than ``colour_step`` between neighbours is a break too
  (both pixels cut); the top regrows into the cut pixels afterwards, from both sides.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

Float32Array = npt.NDArray[np.float32]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int32]

STEP_FLOOR_M = 0.003
"""The smallest height step between neighbours that separates two objects."""


def breaks(height_m: Float32Array, step_m: Float32Array | np.float32) -> BoolArray:
    """Pixels that are the lower side of a height step larger than ``step_m`` (one figure, or
    one per pixel) to a neighbour."""
    cut = np.zeros(height_m.shape, dtype=bool)
    scalar = np.ndim(step_m) == 0
    with np.errstate(invalid="ignore"):
        across = height_m[:, 1:] - height_m[:, :-1]
        limit = step_m if scalar else step_m[:, 1:]  # type: ignore[index]
        cut[:, :-1] |= across > limit  # the right pixel is higher: the left one is cut
        cut[:, 1:] |= across < -limit
        down = height_m[1:, :] - height_m[:-1, :]
        limit = step_m if scalar else step_m[1:, :]  # type: ignore[index]
        cut[:-1, :] |= down > limit
        cut[1:, :] |= down < -limit
    return cut


def colour_breaks(colour: npt.NDArray[np.uint8], step: float) -> BoolArray:
    """Pixels on either side of a brightness change larger than ``step`` (0..255 levels)."""
    # Integer luma (weights 77, 150, 29 over 256): one pass in 16 bits, no float picture.
    grey16 = colour[..., 0].astype(np.uint16) * np.uint16(77)
    grey16 += colour[..., 1].astype(np.uint16) * np.uint16(150)
    grey16 += colour[..., 2].astype(np.uint16) * np.uint16(29)
    grey = (grey16 >> 8).astype(np.int16)
    limit = np.int16(int(step))
    cut = np.zeros(grey.shape, dtype=bool)
    across = np.abs(grey[:, 1:] - grey[:, :-1]) > limit
    cut[:, :-1] |= across
    cut[:, 1:] |= across
    down = np.abs(grey[1:, :] - grey[:-1, :]) > limit
    cut[:-1, :] |= down
    cut[1:, :] |= down
    return cut


def pieces(
    standing: BoolArray, cut: BoolArray
) -> tuple[IntArray, int, list[tuple[slice, slice] | None]]:
    """Connected standing pixels (4-neighbours) once the cut pixels are removed."""
    labels, count = ndimage.label(standing & ~cut)
    return labels.astype(np.int32, copy=False), int(count), ndimage.find_objects(labels)
