"""Seams seen only in colour: where two touching cartons of one height meet.

At a metre or two a depth camera cannot see the gap between two cartons packed side by side at
one height: their tops read as one surface. The colour picture still shows the gap, as a thin
dark line (the shadow between the two lids) or as an edge (two different prints meeting). Print,
labels and tape show lines and edges too, but those stop inside the top; a seam runs straight
from one side of the region to the other, parallel to a side (packed cartons are aligned).

Contract: :func:`seam_map` marks the pixels of thin dark lines and strong colour edges, with
tolerances from the picture's own noise; :func:`split_at_seams` cuts every top that such a
line crosses from side to side (``SEAM_SHARE`` of the cross-section's pixels, clearly more
than the top's print elsewhere and beside the line; not an edge of tape; not running beside
something standing on the top for most of its length, which is that thing's edge) into two,
returning the new labels or None when nothing is cut. Every top's cross-sections are counted
at once, in one pass over the pixels (:func:`onebox.perception.kernels.seam_cuts`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import kernels
from onebox.perception.support import median

if TYPE_CHECKING:
    from onebox.perception.tops import Tops

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int32]
Float64Array = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]

SEAM_WIDTH_M = 0.006
"""The widest gap between two touching cartons that reads as a thin line (wider is a gap the
depth sees)..."""
SEAM_MIN_PX = 5
"""...looked for across this many pixels at least: however thin, a line slanting across the
pixel grid darkens two or three pixels side by side, none of them fully."""
DARK_STEP = 20.0
"""A line this many grey levels darker than both sides is dark; never less than 4 x the
picture's own noise."""
EDGE_STEP = 30.0
"""A grey-level step this large between neighbours is a colour edge (two prints meeting);
never less than 6 x the picture's noise."""
SEAM_SHARE = 0.8
"""A seam crosses this share of a top's cross-section..."""
SEAM_OVER_PRINT = 0.35
"""...and this much more than the top's cross-sections do on average, and than those a few
pixels either side of it (print, texture: a busy print's lines stand out from neither)."""
MIN_SEAM_M = 0.1
"""A seam is at least this long (the side two cartons share): a printed line across a narrow
top is not one."""
END_SHARE = 0.5
"""A seam reaches the top's outline at both ends (this share of its last sixth on each side):
printed lines stop at a margin."""
SHADE_STEP = 12.0
"""Two parts of a top whose mean grey levels differ by this much are in shades of their own."""
NARROWEST_STRIP_M = 0.02
WIDEST_STRIP_M = 0.08
"""A strip of its own shade between two lines, wider than this first (a seam's dark line has
two sides too) and no wider than this, with alike flaps either side, is tape or a printed
band (packing tape is 48 or 75 mm wide), not two seams..."""
MIN_PART_M = 0.05
"""A seam leaves at least this much of the top either side: the narrowest carton, and wider
than packing tape (48 mm). Where a stereo camera's dropout along a top's far side takes the
flap past the tape's far edge, the tape's near edge alone then cuts no strip of it off."""
RISE_M = 0.02
"""A cut whose line runs beside something standing this much higher than the top (4 sigma(z)
at least; the lowest box), within ``BESIDE_PX`` pixels (a box's face seen rising from its
foot stays under this rise for a pixel or two, for three or four where the camera looks
at that face more squarely)..."""
BESIDE_PX = 4
EDGE_BESIDE = 0.75
"""...over this share of its length or more follows that thing's edge: no seam (a carton
standing across a seam, as in a cross-stacked layer, hides less of it)."""
_BESIDE = np.ones((2 * BESIDE_PX + 1, 2 * BESIDE_PX + 1), np.uint8)


def seam_map(
    colour: npt.NDArray[np.uint8], depth_m: npt.NDArray[np.float32], lens: Intrinsics
) -> tuple[BoolArray, npt.NDArray[np.uint8]]:
    """Pixels on thin dark lines or strong colour edges (dilated a pixel, so a line is
    solid), and the grey picture they were found in."""
    grey = np.asarray(cv2.cvtColor(np.ascontiguousarray(colour), cv2.COLOR_RGB2GRAY), np.uint8)
    sample = depth_m[:: max(1, depth_m.shape[0] // 32), :: max(1, depth_m.shape[1] // 32)]
    finite = sample[np.isfinite(sample)]
    distance = median(finite) if finite.size else 1.0
    size = min(max(round(SEAM_WIDTH_M * lens.fx / max(distance, 0.1)), SEAM_MIN_PX), 9) | 1
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))
    dark = np.asarray(cv2.morphologyEx(grey, cv2.MORPH_BLACKHAT, kernel), dtype=np.uint8)
    # The picture's own noise: the median absolute Laplacian (mostly flat regions), at every
    # second pixel each way.
    if min(grey.shape) >= 2:
        noise = _median_of_counts(kernels.laplacian_counts(grey)) / 4.0
    else:
        laplacian = np.abs(cv2.Laplacian(grey, cv2.CV_16S)[::2, ::2]).ravel()
        noise = _median_of_counts(np.bincount(laplacian)) / 4.0
    # A Sobel response is 4 x the step between neighbours.
    dark_step, edge_step = max(DARK_STEP, 4.0 * noise), 4.0 * max(EDGE_STEP, 6.0 * noise)
    if min(grey.shape) >= 2:
        seam = kernels.seam_pixels(dark, grey, dark_step, edge_step)
    else:  # a line of pixels: OpenCV's gradient, the same test
        gx = np.asarray(cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3), dtype=np.float32)
        gy = np.asarray(cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3), dtype=np.float32)
        edge = gx * gx + gy * gy > np.float32(edge_step * edge_step)
        seam = ((dark > dark_step) | edge).astype(np.uint8)
    result: BoolArray = np.asarray(cv2.dilate(seam, np.ones((3, 3), np.uint8)), dtype=bool)
    return result, grey


def _median_of_counts(counts: npt.NDArray[np.int64]) -> float:
    """``np.median`` of small non-negative whole numbers, from how many there are of each
    (``counts[v]`` of value v; no sort)."""
    running = np.cumsum(counts)
    total = int(running[-1])
    below = int(np.searchsorted(running, (total - 1) // 2, side="right"))
    above = int(np.searchsorted(running, total // 2, side="right"))
    return 0.5 * (below + above)


def split_at_seams(
    tops: Tops, seam: BoolArray, grey: npt.NDArray[np.uint8], height_m: Float32Array
) -> IntArray | None:
    """New labels with every top cut at the seam that crosses it best, or None. A line that
    runs beside something standing on the top (higher than it, by ``height_m``: each pixel's
    height) for most of its length is that thing's edge, not a seam: a box lying across a
    carton, whose top's pieces either side of it are one top."""
    index, top = tops.points.index, tops.points.top
    if index.size == 0:
        return None
    limits = np.array(
        [
            MIN_PART_M,
            MIN_SEAM_M,
            SEAM_SHARE,
            SEAM_OVER_PRINT,
            END_SHARE,
            SHADE_STEP,
            NARROWEST_STRIP_M,
            WIDEST_STRIP_M,
        ]
    )
    cut_top, cut_along, cut_at = kernels.seam_cuts(
        index,
        top,
        tops.points.a,
        tops.points.b,
        seam.ravel(),
        grey.ravel(),
        tops.middle_ab,
        tops.axis_ab,
        tops.length_m,
        tops.width_m,
        tops.area_m2,
        tops.pixels,
        limits,
    )
    if not cut_top.any():
        return None
    rise = np.concatenate([[np.inf], tops.height_m + np.maximum(4.0 * tops.sigma_m, RISE_M)])
    highest = cv2.dilate(np.nan_to_num(height_m, nan=-np.inf), _BESIDE)
    beside = (highest > rise[tops.labels]).ravel()[index]
    pixel = tops.pixel_m
    coordinate = _cut_coordinate(tops, cut_along)
    on_line = cut_top[top] & (np.abs(coordinate - cut_at[top]) <= pixel[top])
    line = np.bincount(top[on_line], minlength=len(tops))
    cut_top &= np.bincount(top[on_line & beside], minlength=len(tops)) < EDGE_BESIDE * line
    if not cut_top.any():
        return None
    return cut_labels(tops, cut_top, cut_along, cut_at, coordinate)


def cut_labels(
    tops: Tops,
    cut_top: BoolArray,
    cut_along: BoolArray,
    cut_at: Float64Array,
    coordinate: Float64Array | None = None,
) -> IntArray:
    """New labels with each ``cut_top`` cut in two by a line across its rectangle's length
    (``cut_along``) or its width, ``cut_at`` from its middle: the pixels past it a new top.
    ``coordinate`` is each pixel's offset across the cut (:func:`_cut_coordinate`), if known."""
    labels = tops.labels
    index, top = tops.points.index, tops.points.top
    n = len(tops)
    if coordinate is None:
        coordinate = _cut_coordinate(tops, cut_along)
    moved = cut_top[top] & (coordinate > cut_at[top])
    new_label = np.zeros(n, dtype=np.int32)
    new_label[cut_top] = n + 1 + np.arange(int(cut_top.sum()), dtype=np.int32)
    result = labels.copy()
    flat = result.ravel()
    flat[index[moved]] = new_label[top[moved]]
    return result


def _cut_coordinate(tops: Tops, cut_along: BoolArray) -> Float64Array:
    """Each top pixel's offset from its top's middle along the axis its cut would cross: the
    length where ``cut_along``, else the width."""
    top = tops.points.top
    a = tops.points.a - tops.middle_ab[top, 0]
    b = tops.points.b - tops.middle_ab[top, 1]
    ax = tops.axis_ab[top]
    along = a * ax[:, 0] + b * ax[:, 1]
    across = b * ax[:, 0] - a * ax[:, 1]
    result: Float64Array = np.where(cut_along[top], along, across)
    return result
