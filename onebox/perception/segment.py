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
  (both pixels cut); the top regrows into the cut pixels afterwards, from both sides. A real
  camera's colour is noisy (its sensor, a carton's grain): :func:`edge_step` raises the step
  to what the picture's own neighbour differences make rare.
- Where such a line breaks for a pixel, or the seam is only a shadow darkening over a few
  pixels, two cartons are one top: :func:`seam_lines` finds the straight lines of colour edges
  and dark valleys (:func:`valleys`) that cross a top, for the caller to split it there. So
  it does, from depth alone, for the dotted line of pixels that see down a gap narrower than
  a pixel between two cartons (the caller marks the top's pixels beside them).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy import ndimage

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int32]

STEP_FLOOR_M = 0.003
"""The smallest height step between neighbours that separates two objects."""


MEDIAN_NETWORK = (
    (1, 2), (4, 5), (7, 8), (0, 1), (3, 4), (6, 7), (1, 2), (4, 5), (7, 8),
    (0, 3), (5, 8), (4, 7), (3, 6), (1, 4), (2, 5), (4, 7), (4, 2), (6, 4), (4, 2),
)  # fmt: skip
"""Compare-exchanges that leave the median of nine values in the fifth (Paeth's network)."""


def median3(depth_m: Float32Array) -> Float32Array:
    """The depth picture's 3 x 3 median, NaN where there is no reading: a pixel with no reading
    keeps none, and one with five or more of its nine without a reading has none. A median keeps
    a straight edge where it is and a step's height, while it cuts independent noise about
    2.4-fold."""
    rows, cols = depth_m.shape
    with np.errstate(invalid="ignore"):
        missing = ~((depth_m > 0) & (depth_m < np.inf))
    padded = np.pad(np.where(missing, np.float32(np.inf), depth_m), 1, mode="edge")
    v = [padded[i : i + rows, j : j + cols].copy() for i in range(3) for j in range(3)]
    for a, b in MEDIAN_NETWORK:
        low = np.minimum(v[a], v[b])
        np.maximum(v[a], v[b], out=v[b])
        v[a] = low
    result = v[4]
    result[missing | np.isinf(result)] = np.nan
    return result


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


def grey(colour: npt.NDArray[np.uint8]) -> npt.NDArray[np.int16]:
    """Integer luma (weights 77, 150, 29 over 256): one pass in 16 bits, no float picture."""
    grey16 = colour[..., 0].astype(np.uint16) * np.uint16(77)
    grey16 += colour[..., 1].astype(np.uint16) * np.uint16(150)
    grey16 += colour[..., 2].astype(np.uint16) * np.uint16(29)
    return (grey16 >> 8).astype(np.int16)


EDGE_NOISE_SPREADS = 2.5
"""A brightness step between neighbours is an edge only if it is this many times the spread
(sigma) of the picture's neighbour differences. Gaussian noise then cuts about one pair in 80,
specks the tops grow back over. At 2 spreads the specks joined into false tops on pallets; at
3 and more the edges between cartons of like shades were lost (random pallets through colour
noise of 4-12 levels)."""


def edge_step(grey: npt.NDArray[np.int16], step: float) -> float:
    """The least brightness step between neighbours that is an edge in ``grey``: ``step``, or
    ``EDGE_NOISE_SPREADS`` times the spread of neighbour differences where the picture's own
    noise is larger (a camera's sensor noise, the grain of a carton, read robustly: the
    median absolute difference along every other row, over 0.6745; edges are too few to move
    it). A rendered picture's flat shades differ by nothing and keep ``step``."""
    if grey.shape[1] < 2:
        return step
    diff = np.abs(grey[::2, 1:] - grey[::2, :-1]).reshape(-1)
    counts = np.cumsum(np.bincount(diff, minlength=1))
    half = 0.5 * counts[-1]
    k = int(np.searchsorted(counts, half))
    if k == 0:
        return step
    # Whole levels: |d| = k stands for k - 0.5 .. k + 0.5; the median where half is reached.
    within = counts[k] - counts[k - 1]
    median = k - 0.5 + float(half - counts[k - 1]) / float(within)
    return max(step, EDGE_NOISE_SPREADS * median / 0.6745)


def colour_breaks(grey: npt.NDArray[np.int16], step: float) -> BoolArray:
    """Pixels on either side of a brightness change larger than ``step`` (0..255 levels)
    between neighbours, in a picture from :func:`grey`."""
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


SEAM_COVER = 0.8
"""A colour line is a seam where it runs along this share of the top seen on both its sides."""
SEAM_MIN_M = 0.03
"""The shortest seam, and the least a top goes on past it on each side, metres."""
SEAM_SIDE_BINS = 5
"""How far past a seam (bins) the top must go on, on both sides."""
SEAM_VALLEY_PX = (2, 3, 4)
"""How far each side of a pixel a dark line's shoulders are looked for: a seam's shadow is a
valley a few pixels wide, with no neighbour-to-neighbour step as large as a colour edge's."""


def valleys(
    grey_flat: npt.NDArray[np.int16], flat: npt.NDArray[np.intp], width: int, step: float
) -> BoolArray:
    """Pixels darker by more than ``step`` than the pixels a few either side of them, across or
    down: on a dark line."""
    here = grey_flat[flat]
    dark = np.zeros(len(flat), dtype=bool)
    for k in SEAM_VALLEY_PX:
        for offset in (k, k * width):
            shoulders = np.minimum(grey_flat[flat - offset], grey_flat[flat + offset])
            dark |= shoulders - here > step
    return dark


def seam_lines(
    u: Float64Array,
    v: Float64Array,
    cut: BoolArray,
    shade: npt.NDArray[np.int16],
    step: float,
    bin_m: float,
) -> list[float]:
    """Where along ``u`` lines of ``cut`` points (a top's pixels at (u, v) in its plane, on
    colour edges or dark lines) cross the top at right angles, with the top going on past
    it on both sides in one ``shade`` (within two ``step``: two cartons of one kind, not a top
    and something darker beside it within the depth's noise): each line's middle, ascending,
    a carton's worth apart. Counted in square bins ``bin_m`` wide."""
    iu = ((u - u.min()) / bin_m).astype(np.intp)
    nu = int(iu.max()) + 1
    side = SEAM_SIDE_BINS
    if nu <= 2 * side + 1:
        return []
    # A quick look first: a line must hold, within a bin either side, as many points as run
    # across the top (half as many, for the bins' staircase), somewhere away from the ends.
    across = np.bincount(iu, minlength=nu)
    on_line = np.bincount(iu[cut], minlength=nu)
    near = on_line.copy()
    near[1:] += on_line[:-1]
    near[:-1] += on_line[1:]
    if not (near[side:-side] >= 0.5 * SEAM_COVER * across[side:-side]).any():
        return []
    iv = ((v - v.min()) / bin_m).astype(np.intp)
    nv = int(iv.max()) + 1
    seen = np.zeros((nu + 2 * side + 2, nv), dtype=bool)
    seen[iu[~cut] + side + 1, iv[~cut]] = True
    lines = np.zeros((nu + 2, nv), dtype=bool)
    lines[iu[cut] + 1, iv[cut]] = True
    line = lines[:-2] | lines[1:-1] | lines[2:]  # the cut within one bin of each u
    i = np.arange(nu)

    def sides(padded: npt.NDArray[np.float64]) -> tuple[Float64Array, Float64Array]:
        """Per bin i, ``padded`` (bin i at row i + side + 1) summed over bins i - side .. i - 2
        and over bins i + 2 .. i + side."""
        total = np.cumsum(padded, axis=0)
        return total[i + side - 1] - total[i], total[i + 2 * side + 1] - total[i + side + 2]

    before, after = sides(seen.astype(np.float64))
    both = (before > 0) & (after > 0)
    n_both = both.sum(axis=1)
    n_line = (line & both).sum(axis=1)
    # The mean shade of the points on each side, over the same bins.
    at = iu[~cut] + side + 1
    size = nu + 2 * side + 2
    sums = np.stack(
        [
            np.bincount(at, weights=shade[~cut], minlength=size),
            np.bincount(at, minlength=size).astype(np.float64),
        ],
        axis=1,
    )
    low, high = sides(sums)
    gap = np.abs(low[:, 0] / np.maximum(low[:, 1], 1.0) - high[:, 0] / np.maximum(high[:, 1], 1.0))
    ok = (n_both * bin_m >= SEAM_MIN_M) & (n_line >= SEAM_COVER * n_both) & (gap <= 2.0 * step)
    # Each side a carton's worth, not a rim's band (a carton's edge printed darker).
    ok &= (np.minimum(i + 0.5, nu - i - 0.5) * bin_m) >= SEAM_MIN_M
    if not ok.any():
        return []
    share = np.where(ok, n_line / np.maximum(n_both, 1), -1.0)
    # Each run of good bins is one line, a few bins wide (a shadow's valley, both pixels of a
    # colour edge): its middle is the middle of its points in the bins as good as its best.
    lines_at: list[float] = []
    starts = np.flatnonzero(ok & ~np.concatenate([[False], ok[:-1]]))
    stops = np.flatnonzero(ok & ~np.concatenate([ok[1:], [False]]))
    for first, last in zip(starts, stops, strict=True):
        run = share[first : last + 1]
        good = np.flatnonzero(run >= run.max() - 0.1) + first
        on = cut & (iu >= good[0] - 1) & (iu <= good[-1] + 1)
        middle = float(np.median(u[on]))
        if lines_at and middle - lines_at[-1] < SEAM_MIN_M:
            continue  # a carton's worth from the last line, or none (two edges of one band)
        lines_at.append(middle)
    return lines_at
