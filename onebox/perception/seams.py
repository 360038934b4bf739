"""Seams seen only in colour: where two touching cartons of one height meet.

At a metre or two a depth camera cannot see the gap between two cartons packed side by side at
one height: their tops read as one surface. The colour picture still shows the gap, as a thin
dark line (the shadow between the two lids) or as an edge (two different prints meeting). Print,
labels and tape show lines and edges too, but those stop inside the top; a seam runs straight
from one side of the region to the other, parallel to a side (packed cartons are aligned).

Contract: :func:`seam_map` marks the pixels of thin dark lines and strong colour edges, with
tolerances from the picture's own noise; :func:`split_at_seams` cuts every top that such a
line crosses from side to side (``SEAM_SHARE`` of the cross-section's pixels, clearly more
than the top's print elsewhere) into two, returning the new labels or None when nothing is
cut. Whole-array work: every top's cross-sections are counted at once (``np.bincount``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics

if TYPE_CHECKING:
    from onebox.perception.tops import Tops

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int32]
Float64Array = npt.NDArray[np.float64]

SEAM_WIDTH_M = 0.006
"""The widest gap between two touching cartons that reads as a thin line (wider is a gap the
depth sees)."""
DARK_STEP = 25.0
"""A line this many grey levels darker than both sides is dark; never less than 4 x the
picture's own noise."""
EDGE_STEP = 30.0
"""A grey-level step this large between neighbours is a colour edge (two prints meeting);
never less than 6 x the picture's noise."""
SEAM_SHARE = 0.8
"""A seam crosses this share of a top's cross-section..."""
SEAM_OVER_PRINT = 0.35
"""...and this much more than the top's cross-sections do on average (print, texture)."""
MIN_SEAM_M = 0.1
"""A seam is at least this long (the side two cartons share): a printed line across a narrow
top is not one."""
END_SHARE = 0.5
"""A seam reaches the top's outline at both ends (this share of its last sixth on each side):
printed lines stop at a margin."""
SHADE_STEP = 12.0
"""Two parts of a top whose mean grey levels differ by this much are in shades of their own."""
MIN_PART_M = 0.04
"""A seam leaves at least this much of the top either side: the narrowest carton."""


def seam_map(
    colour: npt.NDArray[np.uint8], depth_m: npt.NDArray[np.float32], lens: Intrinsics
) -> tuple[BoolArray, npt.NDArray[np.uint8]]:
    """Pixels on thin dark lines or strong colour edges (dilated a pixel, so a line is
    solid), and the grey picture they were found in."""
    grey = cv2.cvtColor(np.ascontiguousarray(colour), cv2.COLOR_RGB2GRAY)
    sample = depth_m[:: max(1, depth_m.shape[0] // 32), :: max(1, depth_m.shape[1] // 32)]
    finite = sample[np.isfinite(sample)]
    distance = float(np.median(finite)) if finite.size else 1.0
    size = int(np.clip(round(SEAM_WIDTH_M * lens.fx / max(distance, 0.1)), 3, 9)) | 1
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))
    dark = cv2.morphologyEx(grey, cv2.MORPH_BLACKHAT, kernel)
    # The picture's own noise: the median absolute Laplacian (mostly flat regions).
    laplacian = cv2.Laplacian(grey, cv2.CV_16S)
    noise = float(np.median(np.abs(laplacian[::2, ::2]))) / 4.0
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    # A Sobel response is 4 x the step between neighbours.
    edge = (gx * gx + gy * gy) > (4.0 * max(EDGE_STEP, 6.0 * noise)) ** 2
    seam = (dark > max(DARK_STEP, 4.0 * noise)) | edge
    result: BoolArray = np.asarray(
        cv2.dilate(seam.astype(np.uint8), np.ones((3, 3), np.uint8)), dtype=bool
    )
    return result, np.asarray(grey, dtype=np.uint8)


def _tape(
    strong: BoolArray,
    position: Float64Array,
    owner: npt.NDArray[np.intp],
    offset: npt.NDArray[np.int64],
    nbins: npt.NDArray[np.int64],
    slot: npt.NDArray[np.int64],
    shade: Float64Array,
    bin_m: Float64Array,
) -> BoolArray:
    """Which strong lines are the edges of tape along a lid: a pair mirrored about the top's
    middle, the strip between them in a shade of its own, the flaps either side in one shade
    (three cartons side by side, one of them as wide as the strip, are not alike so)."""
    total = int(nbins.sum())
    count = np.bincount(slot, minlength=total).astype(np.float64)
    summed = np.bincount(slot, weights=shade, minlength=total)
    # Running sums within each top: the shade of any run of its cross-sections.
    run_count = np.cumsum(count) - np.repeat(np.cumsum(count)[offset] - count[offset], nbins)
    run_sum = np.cumsum(summed) - np.repeat(np.cumsum(summed)[offset] - summed[offset], nbins)
    last = offset + nbins - 1
    local = np.arange(total) - offset[owner]
    twin = offset[owner] + np.clip(nbins[owner] - 1 - local, 0, nbins[owner] - 1)
    mirrored = strong & (
        strong[twin]
        | strong[np.clip(twin - 1, 0, total - 1)]
        | strong[np.clip(twin + 1, 0, total - 1)]
    )
    high = np.maximum(np.arange(total), twin)
    low = np.minimum(np.arange(total), twin)

    def mean(upto: npt.NDArray[np.intp], start: npt.NDArray[np.intp]) -> Float64Array:
        before_count = np.where(start > offset[owner], run_count[np.maximum(start - 1, 0)], 0.0)
        before_sum = np.where(start > offset[owner], run_sum[np.maximum(start - 1, 0)], 0.0)
        n = run_count[upto] - before_count
        result: Float64Array = (run_sum[upto] - before_sum) / np.maximum(n, 1.0)
        return result

    middle = mean(high, low)
    below = mean(np.maximum(low - 1, offset[owner]), offset[owner])
    above = mean(last[owner], np.minimum(high + 1, last[owner]))
    flaps_alike = np.abs(above - below) < SHADE_STEP
    strip_apart = np.abs(middle - 0.5 * (above + below)) >= SHADE_STEP
    # A line down the middle is its own mirror: one seam, not a pair.
    apart = np.abs(position) > 2.0 * bin_m
    result: BoolArray = mirrored & apart & flaps_alike & strip_apart
    return result


def split_at_seams(tops: Tops, seam: BoolArray, grey: npt.NDArray[np.uint8]) -> IntArray | None:
    """New labels with every top cut at the seam that crosses it best, or None."""
    labels = tops.labels
    index, top = tops.points.index, tops.points.top
    if index.size == 0:
        return None
    n = len(tops)
    a = tops.points.a - tops.middle_ab[top, 0]
    b = tops.points.b - tops.middle_ab[top, 1]
    ax = tops.axis_ab[top]
    along = a * ax[:, 0] + b * ax[:, 1]
    across = b * ax[:, 0] - a * ax[:, 1]
    on_seam = seam.ravel()[index].astype(np.float64)
    shade = grey.ravel()[index].astype(np.float64)
    step = np.sqrt(np.maximum(tops.area_m2 / np.maximum(tops.pixels, 1), 1e-12))
    cut_top = np.full(n, False)
    cut_along = np.full(n, False)
    cut_at = np.zeros(n)
    best = np.zeros(n)
    for is_along, coordinate, extent, other, span in (
        (True, along, tops.length_m, across, tops.width_m),
        (False, across, tops.width_m, along, tops.length_m),
    ):
        nbins = np.maximum(np.ceil(extent / step).astype(np.int64) + 2, 1)
        offset = np.concatenate([[0], np.cumsum(nbins)[:-1]])
        bins = np.clip(
            np.floor((coordinate + 0.5 * extent[top]) / step[top]).astype(np.int64) + 1,
            0,
            nbins[top] - 1,
        )
        slot = offset[top] + bins
        total = np.bincount(slot, minlength=int(nbins.sum()))
        lined = np.bincount(slot, weights=on_seam, minlength=int(nbins.sum()))
        share = lined / np.maximum(total, 1)
        ends = []
        for sign in (1.0, -1.0):
            end = sign * other > span[top] / 3.0
            ends.append(
                np.bincount(slot, weights=on_seam * end, minlength=int(nbins.sum()))
                / np.maximum(np.bincount(slot, weights=end, minlength=int(nbins.sum())), 1)
            )
        print_share = np.bincount(top, weights=on_seam, minlength=n) / np.maximum(tops.pixels, 1)
        owner = np.repeat(np.arange(n), nbins)
        position = (np.arange(int(nbins.sum())) - offset[owner] - 0.5) * step[owner]
        position -= 0.5 * extent[owner]
        margin = np.maximum(MIN_PART_M, 3.0 * step[owner])
        inside = (np.abs(position) < 0.5 * extent[owner] - margin) & (total >= 3)
        strong = (
            inside
            & (span[owner] >= MIN_SEAM_M)
            & (share >= SEAM_SHARE)
            & (share - print_share[owner] >= SEAM_OVER_PRINT)
            & (ends[0] >= END_SHARE)
            & (ends[1] >= END_SHARE)
        )
        score = np.where(
            strong & ~_tape(strong, position, owner, offset, nbins, slot, shade, step[owner]),
            share,
            0.0,
        )
        peak = np.maximum.reduceat(score, offset)
        where = np.zeros(n, dtype=np.int64)
        hit = np.flatnonzero(score > 0)
        # The strongest slot of each top (the last written wins among equals: any will do).
        at_peak = hit[score[hit] >= peak[owner[hit]]]
        where[owner[at_peak]] = at_peak
        better = (peak > 0) & (peak > best)
        best = np.where(better, peak, best)
        cut_top |= better
        cut_along = np.where(better, is_along, cut_along)
        cut_at = np.where(better, position[where], cut_at)
    if not cut_top.any():
        return None
    coordinate = np.where(cut_along[top], along, across)
    moved = cut_top[top] & (coordinate > cut_at[top])
    new_label = np.zeros(n, dtype=np.int32)
    new_label[cut_top] = n + 1 + np.arange(int(cut_top.sum()), dtype=np.int32)
    result = labels.copy()
    flat = result.ravel()
    flat[index[moved]] = new_label[top[moved]]
    return result
