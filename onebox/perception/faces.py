"""Where a box's side faces end: how high a box's bottom is, seen from the side.

Contract: :func:`face_bottoms` takes each box's top (its rectangle in the support plane and
its height), the depth picture (H x W metres; NaN, 0 and below are no reading), the lens,
the plane's basis in the optical frame (rows e1, e2, n) and the camera's height above the
plane, and returns for each box a :class:`Bottom` (the heights between which its side faces
end) or None where the picture cannot say. No I/O.

A box's top says nothing of what it stands on; its sides do. A box standing on the surface
shows a face from its top down to the surface on every side that faces the camera. A box
standing on a narrower box overhangs it: below the box's bottom the camera looks past the
face's plane, under the box. Along lines down each face that the camera sees, each point of
the face is looked up in the picture and the surface seen there sorted by where it lies
across the face's plane: on it (the face is there), beyond it (the face has ended: the camera
sees under the box) or before it (something in front hides the face, such as the rim of the
box underneath: no answer). Going down a line, past the points that give no answer, the face
ends where points mostly beyond it first follow points mostly on it: between the last point
on it and the first beyond. A box is solid down to its bottom, so its bottom is the highest
one that two lines agree on, on any side: where a side runs flush with the box under it, the
face goes on down, seen as one, and says nothing. None when no two lines see the face end
above the surface.

Where the sides run flush (a box on one of nearly its footprint) depth says nothing, but the
colour may: with the colour picture, a line whose points on the face are all of one even shade
above a point and of another below it (a step of SEAM_STEP levels or more), at the same height
as another line of the same side, ends there too (a ``seam``; the caller tells it from a top
beside the box that meets the face there). A real camera's colour lies a pixel or two off its
depth, and paints a face's first or last pixels in the shade of the top's rim above it or of
the surface seen past its foot: a shade that spans less than SEAM_UNDER_PX across the side's
edges at the face's end is no box's face (under the seam, only where the picture past the
face's end shows a lower surface of that shade).

The other way round, each side's ``reach``: how far down its face is seen unbroken from the
top, on points where the surface seen lies both in the face's plane and at the point's height
(not the rim of a top in front, nor the surface at its foot). A box's bottom is no higher
than where its face is still seen, unless a box under it runs flush with that side.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics

Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

LINES = np.linspace(-0.35, 0.35, 5)
"""Where the lines run down each side, as shares of the side's length from its middle."""
SAMPLES = 48
"""Points down each line, from just under the top (FIRST_SHARE of its height) to the surface."""
FIRST_SHARE = 0.97
RUN = 4
RUN_OF = 3
"""A face ends where RUN_OF of RUN points in a row are on it, and of the next RUN beyond it."""
MIN_FACE_PX = 6.0
"""A face that spans fewer pixels from top to bottom than this (seen edge-on) says nothing."""
SEAM_STEP = 8.0
"""The least brightness step (0..255) down a face between two boxes' faces."""
SEAM_GAP = 2
"""Points skipped between the shades above and below a seam (pixels blended across it)."""
SEAM_MIN_PX = 16.0
"""A line that spans fewer pixels from the top to the surface shows no seam: each pixel of a
face seen that steeply spans too much of its height (a box on another measured 12-23 mm short
from a rim's step on a face 10-13 pixels long)."""
SEAM_UNDER_PX = 3.0
"""The least a shade either side of a seam spans from the face's end, across the side's edges,
in pixels: more than a real camera's colour picture lies off its depth."""


@dataclass(frozen=True)
class Bottom:
    """Where a box's faces end: at most ``high_m`` (a face is seen there), at least ``low_m``
    (the camera sees past the face there); ``middle_m`` is the best single figure."""

    low_m: float
    high_m: float
    middle_m: float
    seam: bool = False
    """Seen as a seam in the colour (a face going on down in one plane), not as a face's end:
    the level under it may also be a top beside the box, which meets the face there."""
    unseamed: Bottom | None = None
    """For a seam: the bottom the faces' ends alone show."""
    seam_sides: tuple[tuple[float, float], ...] = ()
    """For a seam: the outward normals (plane coordinates) of the sides it is seen on."""


@dataclass(frozen=True)
class Faces:
    """What the side faces of each box show."""

    bottoms: list[Bottom | None]
    """Where each box's faces end (see :func:`face_bottoms`)."""
    reach_m: Float64Array
    """N x 4 (sides +length, -length, +width, -width): how far down the face is seen on the
    side, at the height of the face's own points and from its top on (the lowest point two of
    its lines agree on); NaN where fewer than two lines see it."""


def face_bottoms(
    middles: Float64Array,
    axes: Float64Array,
    halves: Float64Array,
    tops_m: Float64Array,
    tolerances_m: Float64Array,
    depth_m: npt.NDArray[np.floating],
    lens: Intrinsics,
    basis: Float64Array,
    camera_height_m: float,
    colour: npt.NDArray[np.uint8] | None = None,
) -> Faces:
    """Each box's bottom as its faces show it (see the module docstring), and how far down
    each side's face is seen.

    ``middles`` (N x 2), ``axes`` (N x 2, unit, the length's) and ``halves`` (N x 2: half the
    length and half the width) are the tops' rectangles in plane coordinates (a = e1 . p,
    b = e2 . p); ``tops_m`` their heights; ``tolerances_m`` (N) how far across a face's plane
    a reading may lie and still be on it; ``colour`` (H x W x 3, registered with the depth)
    shows seams between boxes stacked flush.
    """
    n_boxes = len(tops_m)
    if n_boxes == 0:
        return Faces([], np.zeros((0, 4)))
    ax = axes
    perp = np.stack([-ax[:, 1], ax[:, 0]], axis=1)
    # Sides: outward normal, direction along the side, half extent out and along.
    out = np.stack([ax, -ax, perp, -perp], axis=1)  # N x 4 x 2
    along = np.stack([perp, perp, ax, ax], axis=1)
    half_out = np.stack([halves[:, 0], halves[:, 0], halves[:, 1], halves[:, 1]], axis=1)
    half_along = np.stack([halves[:, 1], halves[:, 1], halves[:, 0], halves[:, 0]], axis=1)
    edge_mid = middles[:, np.newaxis, :] + out * half_out[..., np.newaxis]  # N x 4 x 2
    # The camera stands over the plane's origin: a side faces it when the origin lies out past
    # the side's line.
    facing = np.einsum("nsk,nsk->ns", -edge_mid, out) > 0.0
    share = np.linspace(FIRST_SHARE, 0.0, SAMPLES)
    heights = tops_m[:, np.newaxis] * share[np.newaxis, :]  # N x S
    tol = tolerances_m[:, np.newaxis, np.newaxis, np.newaxis]
    reading = _Reading(depth_m, lens, basis, camera_height_m, heights, out, along, half_along)
    offset, seen, span_px = reading(edge_mid)
    # The rectangle's side may lie a little off the face (a footprint or so, which a face seen
    # steeply turns into a centimetre of height): each face is moved to where its readings
    # say it stands (their median offset), then read again.
    with np.errstate(invalid="ignore"):
        near = np.where(seen & (np.abs(offset) <= tol), offset, np.nan)
    shift = np.zeros(facing.shape)
    counts = np.sum(np.isfinite(near), axis=(2, 3))
    enough = counts >= SAMPLES // 2
    if enough.any():
        shift[enough] = _row_medians(near[enough].reshape(int(enough.sum()), -1))
        offset, seen, span_px = reading(edge_mid + out * shift[..., np.newaxis])
    on = seen & (np.abs(offset) <= tol)
    beyond = seen & (offset < -tol)
    # Every line of a side facing the camera that spans pixels enough, all at once.
    use = facing[:, :, np.newaxis] & (span_px >= MIN_FACE_PX)
    box_of, side_of, line_of = np.nonzero(use)
    low, high, ended = _line_ends(
        on[box_of, side_of, line_of], beyond[box_of, side_of, line_of], heights[box_of]
    )
    # Each point is read at the pixel it falls in, whose ray meets the face up to half a
    # pixel's height away.
    px = span_px[box_of, side_of, line_of]
    half_px = 0.5 * heights[box_of, 0] / px
    # A point is the face's own where the surface seen there lies at the point's height too
    # (the top of a rim in front lies within the plane's tolerance near the face, higher),
    # and is not the surface at the face's foot.
    seen_height = reading.seen_height[box_of, side_of, line_of]
    line_tol = tol[box_of, 0, 0]
    own = on[box_of, side_of, line_of] & (seen_height > line_tol)
    own &= np.abs(seen_height - heights[box_of]) <= line_tol + half_px[:, np.newaxis]
    deepest = _line_reach(own, beyond[box_of, side_of, line_of], heights[box_of], ended, high)
    reach = np.full((n_boxes, 4), np.nan)
    for key in np.unique(box_of * 4 + side_of):
        depths = np.sort(deepest[(box_of * 4 + side_of) == key])
        depths = depths[np.isfinite(depths)]
        if len(depths) >= 2:
            reach[key // 4, key % 4] = depths[1]
    if colour is not None:
        rows_at, cols_at = reading.pixels
        grey = _grey(colour[rows_at, cols_at])[box_of, side_of, line_of]
        # The surface at the face's foot lies within the tolerance of its plane too, for a
        # face seen steeply: it is no face, and its colour no seam.
        face = (on & (reading.seen_height > tol))[box_of, side_of, line_of]
        s_low, s_high, seam = _seams(face, grey, heights[box_of])
        # A real camera's colour lies a pixel or two off its depth: a band that thin at
        # either end of the face may be the top's rim or the surface past its foot.
        seam &= ~_bled(
            reading,
            colour,
            face,
            grey,
            heights[box_of],
            (s_low, s_high),
            tol[box_of, 0, 0, 0],
            (box_of, side_of, line_of),
        )
    else:
        s_low = s_high = np.zeros(len(low))
        seam = np.zeros(len(low), dtype=bool)
    # Each pixel of a face seen steeply spans much of its height: a shade's step there is no
    # sure height (the face's plane a pixel off moves it by a pixel's height).
    seam &= px >= SEAM_MIN_PX
    if seam.any():
        # A seam between two boxes runs level across the side: another line of the same side
        # sees it within a point's spacing (an edge across the face at a slant is no seam).
        spacing = 1.5 * heights[box_of, 0] / (SAMPLES - 1)
        side_key = box_of * 4 + side_of
        for j in np.flatnonzero(seam):
            twins = seam & (side_key == side_key[j]) & (np.abs(s_high - s_high[j]) <= spacing[j])
            seam[j] = np.count_nonzero(twins) >= 2
    result: list[Bottom | None] = []
    for i in range(n_boxes):
        slack = float(tolerances_m[i])
        mine = np.flatnonzero(ended & (box_of == i))
        ends = [(low[j] - half_px[j], high[j] + half_px[j], px[j]) for j in mine]
        seams = np.flatnonzero(seam & (box_of == i))
        seam_ends = [(s_low[j] - half_px[j], s_high[j] + half_px[j], px[j]) for j in seams]
        bottom = _agreed(ends, slack)
        # A seam above where the faces are seen to end is the higher bottom of the two.
        by_seam = _agreed(ends + seam_ends, slack) if seam_ends else None
        if by_seam is not None and (bottom is None or by_seam.high_m > bottom.high_m):
            sides = sorted({int(side_of[j]) for j in seams})
            normals = tuple((float(out[i, k, 0]), float(out[i, k, 1])) for k in sides)
            bottom = replace(by_seam, seam=True, unseamed=bottom, seam_sides=normals)
        result.append(bottom)
    return Faces(result, reach)


def _bled(
    reading: _Reading,
    colour: npt.NDArray[np.uint8],
    face: BoolArray,
    grey: Float64Array,
    heights: Float64Array,
    seam: tuple[Float64Array, Float64Array],
    tol: Float64Array,
    line: tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.intp]],
) -> BoolArray:
    """For each line (rows of ``face``, ``grey`` and ``heights``; ``line`` its box, side and
    line), whether a shade either side of its seam (heights ``seam``: low, high) may be what
    the picture shows past that end of the face, seen a little off. The colour picture is
    registered with the depth to a pixel or so (a real camera's depth aligned to its colour)
    and paints a face's first or last pixels in the shade of the top's rim above it or of the
    surface seen past its foot. Such a band lies within SEAM_UNDER_PX of the face's end,
    across the side's edges as the picture shows them (a face seen at a slant shows its lines
    down it nearly along those edges). Under the seam, it is a band only if a pixel a few on
    past the face's last point shows a lower surface of its shade: a box under another, turned
    a little, leaves the face's plane a pixel or two under the seam, of its own shade."""
    u, v = reading.uv
    box_of, side_of, _ = line
    samples = face.shape[1]
    at = np.arange(len(face))
    # Across the side's edges (from the foot of its first line to that of its last), the way
    # the lines run down the face.
    eu = u[box_of, side_of, -1, -1] - u[box_of, side_of, 0, -1]
    ev = v[box_of, side_of, -1, -1] - v[box_of, side_of, 0, -1]
    with np.errstate(invalid="ignore", divide="ignore"):
        nu, nv = ev / np.hypot(eu, ev), -eu / np.hypot(eu, ev)
    down = nu * (u[(*line, -1)] - u[(*line, 0)]) + nv * (v[(*line, -1)] - v[(*line, 0)])
    nu, nv = np.where(down < 0, -nu, nu), np.where(down < 0, -nv, nv)

    def across(end: npt.NDArray[np.intp], inner: npt.NDArray[np.intp]) -> Float64Array:
        du = u[(*line, inner)] - u[(*line, end)]
        dv = v[(*line, inner)] - v[(*line, end)]
        result: Float64Array = np.abs(du * nu + dv * nv)
        return result

    first = np.argmax(face, axis=1)
    under = np.argmin(np.abs(heights - seam[0][:, np.newaxis]), axis=1)
    over = np.argmin(np.abs(heights - seam[1][:, np.newaxis]), axis=1)
    # The shade under the seam (its first RUN points).
    index = np.arange(samples)[np.newaxis, :]
    head = face & (index >= under[:, np.newaxis]) & (index < under[:, np.newaxis] + RUN)
    with np.errstate(invalid="ignore", divide="ignore"):
        shade = np.sum(np.where(head, grey, 0.0), axis=1) / np.sum(head, axis=1)
    last = samples - 1 - np.argmax(face[:, ::-1], axis=1)
    # The pixels a few on past the face's last point, the surface seen there lower.
    steps = np.arange(1.0, 1.0 + RUN)
    inside, pv, pu = reading.pixel_of(
        u[(*line, last)][:, np.newaxis] + nu[:, np.newaxis] * steps,
        v[(*line, last)][:, np.newaxis] + nv[:, np.newaxis] * steps,
    )
    with np.errstate(invalid="ignore"):
        inside &= (
            reading.height_at(pv, pu) < (reading.seen_height[line][at, last] - tol)[:, np.newaxis]
        )
        alike = inside & (np.abs(_grey(colour[pv, pu]) - shade[:, np.newaxis]) < SEAM_STEP / 2)
    bled: BoolArray = (across(first, over) < SEAM_UNDER_PX) | (
        (across(last, under) < SEAM_UNDER_PX) & alike.any(axis=1)
    )
    return bled


def resolution_m(top_m: float) -> float:
    """How far apart the points down a face of a top this high lie."""
    return top_m * FIRST_SHARE / (SAMPLES - 1)


def _agreed(ends: list[tuple[float, float, float]], slack_m: float) -> Bottom | None:
    """The highest end two lines agree on (their spans overlap, within ``slack_m``), None
    when no two do. The lines that overlap that pair's give the span; the middle is their
    middles' mean weighted by how many pixels their face spans (a face seen at a slant puts
    more of its height in each pixel)."""
    ends = sorted(ends, key=lambda e: -e[1])
    for a, b in itertools.combinations(ends, 2):
        if max(a[0], b[0]) > min(a[1], b[1]) + slack_m:
            continue
        low, high = max(a[0], b[0]), min(a[1], b[1])
        near = np.array([e for e in ends if e[0] <= high + slack_m and e[1] >= low - slack_m])
        weights = near[:, 2] ** 2
        middle = float((0.5 * (near[:, 0] + near[:, 1])) @ weights / weights.sum())
        low, high = float(near[:, 0].max()), float(near[:, 1].min())
        if low > high:
            low = high = middle
        return Bottom(low, high, min(max(middle, low), high))
    return None


def _line_ends(
    on: BoolArray, beyond: BoolArray, heights: Float64Array
) -> tuple[Float64Array, Float64Array, BoolArray]:
    """Going down each line (rows of ``on``, ``beyond`` and ``heights``), past the points that
    say nothing: the heights of the first point beyond the face and the last on it, where
    RUN_OF of RUN points on it are followed by RUN_OF of RUN beyond it (a noisy reading is
    outvoted), and whether the line ends so. Points that flip between on and beyond are a
    face seen nearly edge-on, not its end."""
    rows, samples = on.shape
    said = on | beyond
    # Each row's points that say something, first, in order.
    order = np.argsort(~said, axis=1, kind="stable")
    s_on = np.take_along_axis(on, order, 1)
    s_beyond = np.take_along_axis(beyond, order, 1)
    n_said = said.sum(axis=1)
    zero = np.zeros((rows, 1), dtype=np.int64)
    c_on = np.concatenate([zero, np.cumsum(s_on, axis=1)], axis=1)
    c_beyond = np.concatenate([zero, np.cumsum(s_beyond, axis=1)], axis=1)
    # k: the first point of a window mostly beyond, right after a window mostly on.
    k = np.arange(RUN, samples - RUN + 1)
    on_before = c_on[:, k] - c_on[:, k - RUN]
    beyond_after = c_beyond[:, k + RUN] - c_beyond[:, k]
    is_end = (on_before >= RUN_OF) & (beyond_after >= RUN_OF) & s_beyond[:, k]
    is_end &= (k + RUN)[np.newaxis, :] <= n_said[:, np.newaxis]
    ended = is_end.any(axis=1)
    first = k[np.argmax(is_end, axis=1)]
    # The last point on the face before it: the highest index on among those before k.
    before = np.arange(samples)[np.newaxis, :] < first[:, np.newaxis]
    last_on = np.max(np.where(s_on & before, np.arange(samples), -1), axis=1)
    at = np.arange(rows)
    low = heights[at, order[at, first]]
    high = heights[at, order[at, np.maximum(last_on, 0)]]
    return low, high, ended


def _line_reach(
    own: BoolArray,
    beyond: BoolArray,
    heights: Float64Array,
    ended: BoolArray,
    end_high: Float64Array,
) -> Float64Array:
    """Going down each line (rows), past the points that say nothing, the lowest point of the
    face's own before the first RUN points that say something hold fewer than RUN_OF of its
    own (the face is seen unbroken from its top to there), and above where the line ends
    (``ended``, its last point on the face at ``end_high``); NaN where there is none."""
    rows, samples = own.shape
    said = own | beyond
    order = np.argsort(~said, axis=1, kind="stable")
    s_own = np.take_along_axis(own, order, 1)
    s_heights = np.take_along_axis(heights, order, 1)
    n_said = said.sum(axis=1)[:, np.newaxis]
    c_own = np.concatenate([np.zeros((rows, 1), dtype=np.int64), np.cumsum(s_own, axis=1)], 1)
    m = np.arange(samples)[np.newaxis, :]
    window = c_own[:, m[0] + 1] - c_own[:, np.maximum(m[0] + 1 - RUN, 0)]
    broken = (window < RUN_OF) & (m >= RUN - 1) & (m < n_said)
    first_break = np.where(broken.any(axis=1), np.argmax(broken, axis=1), samples)
    good = s_own & (m < first_break[:, np.newaxis]) & (m < n_said)
    with np.errstate(invalid="ignore"):
        good &= ~ended[:, np.newaxis] | (s_heights >= end_high[:, np.newaxis])
    result: Float64Array = np.where(good, s_heights, np.inf).min(axis=1)
    result[~np.isfinite(result)] = np.nan
    return result


def _row_medians(values: Float64Array) -> Float64Array:
    """Each row's median of its finite values (every row has one): ``np.nanmedian`` takes a
    masked array's slow path for arrays this small."""
    ordered = np.sort(values, axis=1)  # NaN sorts last
    finite = np.count_nonzero(np.isfinite(values), axis=1)
    rows = np.arange(len(values))
    middle: Float64Array = 0.5 * (ordered[rows, (finite - 1) // 2] + ordered[rows, finite // 2])
    return middle


def _grey(colour: npt.NDArray[np.uint8]) -> Float64Array:
    """Brightness, 0..255 (Rec. 601 luma)."""
    rgb = np.asarray(colour, dtype=np.float64)
    result: Float64Array = rgb @ np.array([0.299, 0.587, 0.114])
    return result


def _seams(
    on: BoolArray, grey: Float64Array, heights: Float64Array
) -> tuple[Float64Array, Float64Array, BoolArray]:
    """Going down each line (rows): the first point where the face's points above (all of
    them) are of one even shade and the RUN below of another, SEAM_STEP or more apart (RUN_OF
    of RUN points on the face on either side, SEAM_GAP points between them left out), and at
    most one of the 2 RUN below is of the shade above again; the heights just below and just
    above it, and whether the line has one."""
    rows, samples = on.shape
    shade = np.where(on, grey, np.nan)
    # Means by running sums, spreads by fmax/fmin (no warnings on windows with no point).
    # A box's face above the seam as long as two runs at least (a dark rim under a top's
    # edge is no box); below it, the face does not come back to the shade above within two
    # runs (a face seen nearly edge-on catches a few pixels of another shade, then its own).
    k = np.arange(2 * RUN, samples - 2 * RUN - SEAM_GAP + 1)
    if rows == 0 or len(k) == 0:
        empty = np.zeros(rows)
        return empty, empty, np.zeros(rows, dtype=bool)
    windows = np.lib.stride_tricks.sliding_window_view(shade, RUN, axis=1)
    longer = np.lib.stride_tricks.sliding_window_view(shade, 2 * RUN, axis=1)
    zero = np.zeros((rows, 1))
    c_valid = np.concatenate([zero, np.cumsum(on, axis=1)], axis=1)
    c_shade = np.concatenate([zero, np.cumsum(np.where(on, grey, 0.0), axis=1)], axis=1)

    def window(start: npt.NDArray[np.intp]) -> tuple[Float64Array, Float64Array]:
        """Per row and start: points on the face and their mean shade."""
        n = c_valid[:, start + RUN] - c_valid[:, start]
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (c_shade[:, start + RUN] - c_shade[:, start]) / n
        return n, mean

    n_above, a_mid = window(k - RUN)
    n_below, b_mid = window(k + SEAM_GAP)
    below = windows[:, k + SEAM_GAP]
    b_span = np.fmax.reduce(below, axis=2) - np.fmin.reduce(below, axis=2)
    with np.errstate(invalid="ignore"):
        back = np.abs(longer[:, k + SEAM_GAP] - a_mid[..., np.newaxis]) < SEAM_STEP / 2
    # The whole face above, from just under the top's edge (whose pixels blend with the top),
    # is one shade: a face shaded from light to dark has no seam to tell.
    lit = shade[:, SEAM_GAP:]
    spread = np.fmax.accumulate(lit, axis=1) - np.fmin.accumulate(lit, axis=1)
    with np.errstate(invalid="ignore"):
        even = (spread[:, k - 1 - SEAM_GAP] < SEAM_STEP / 2) & (b_span < SEAM_STEP / 2)
        is_seam = (
            (n_above >= RUN_OF)
            & (n_below >= RUN_OF)
            & even
            & (np.abs(a_mid - b_mid) >= SEAM_STEP)
            & (back.sum(axis=2) <= 1)
        )
    seam: BoolArray = np.any(is_seam, axis=1)
    pick = np.argmax(is_seam, axis=1)
    first = k[pick]
    at = np.arange(rows)
    # The points left out between the two shades: those nearer the upper shade are above
    # the seam.
    gap = first[:, np.newaxis] + np.arange(SEAM_GAP)[np.newaxis, :]
    values = shade[at[:, np.newaxis], gap]
    upper = np.abs(values - a_mid[at, pick, np.newaxis]) < np.abs(
        values - b_mid[at, pick, np.newaxis]
    )
    last = first - 1 + np.sum(np.cumprod(upper, axis=1), axis=1)
    return heights[at, last + 1], heights[at, last], seam


class _Reading:
    """Points down the lines of every face, looked up in the picture."""

    def __init__(
        self,
        depth_m: npt.NDArray[np.floating],
        lens: Intrinsics,
        basis: Float64Array,
        camera_height_m: float,
        heights: Float64Array,
        out: Float64Array,
        along: Float64Array,
        half_along: Float64Array,
    ) -> None:
        self.depth = depth_m
        self.lens = lens
        self.basis = basis
        self.camera_height_m = camera_height_m
        self.heights = heights
        self.out = out
        self.pixels: tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]] = (
            np.zeros(0, dtype=np.intp),
            np.zeros(0, dtype=np.intp),
        )
        """Each point's pixel (rows, columns) at the last reading."""
        self.seen_height: Float64Array = np.zeros(0)
        """Each point's surface's height above the plane at the last reading."""
        self.uv: tuple[Float64Array, Float64Array] = (np.zeros(0), np.zeros(0))
        """Where each point falls in the picture (columns, rows; not rounded)."""
        # Where each line runs along its side, from the side's middle: N x 4 x L x 2.
        self.along = (
            LINES[np.newaxis, np.newaxis, :, np.newaxis]
            * (2 * half_along[..., np.newaxis, np.newaxis])
            * along[:, :, np.newaxis, :]
        )

    def pixel_of(
        self, u: Float64Array, v: Float64Array, also: BoolArray | None = None
    ) -> tuple[BoolArray, npt.NDArray[np.intp], npt.NDArray[np.intp]]:
        """Whether the points at (u, v) (columns, rows) fall in the picture (and ``also``
        holds), and the pixel each falls in (rows, columns; 0, 0 where not)."""
        rows_n, cols_n = self.depth.shape
        ui, vi = np.rint(u), np.rint(v)
        inside = (ui >= 0) & (ui < cols_n) & (vi >= 0) & (vi < rows_n)
        if also is not None:
            inside &= also
        return (
            inside,
            np.where(inside, vi, 0).astype(np.intp),
            np.where(inside, ui, 0).astype(np.intp),
        )

    def _seen(
        self, rows: npt.NDArray[np.intp], cols: npt.NDArray[np.intp]
    ) -> tuple[Float64Array, Float64Array]:
        """The depth at these pixels, and the points seen there (optical frame, ... x 3)."""
        d = self.depth[rows, cols].astype(np.float64)
        across_r, down_r = self.lens.rays(self.depth.shape[1], self.depth.shape[0])
        return d, np.stack([across_r[cols] * d, down_r[rows] * d, d], axis=-1)

    def height_at(self, rows: npt.NDArray[np.intp], cols: npt.NDArray[np.intp]) -> Float64Array:
        """The height above the plane of the surface seen at these pixels (NaN: no reading)."""
        d, xyz = self._seen(rows, cols)
        height: Float64Array = xyz @ self.basis[2] + self.camera_height_m
        height[~(d > 0)] = np.nan
        return height

    def __call__(self, edge_mid: Float64Array) -> tuple[Float64Array, BoolArray, Float64Array]:
        """For faces through ``edge_mid`` (N x 4 x 2): how far out past the face's plane the
        surface seen at each point lies (N x 4 x L x S), whether it is seen, and each line's
        extent in pixels, top to bottom (N x 4 x L)."""
        lens = self.lens
        e1, e2, normal = self.basis
        feet = edge_mid[:, :, np.newaxis, :] + self.along  # N x 4 x L x 2
        xyz = (
            feet[..., np.newaxis, 0:1] * e1
            + feet[..., np.newaxis, 1:2] * e2
            + (self.heights[:, np.newaxis, np.newaxis, :, np.newaxis] - self.camera_height_m)
            * normal
        )  # N x 4 x L x S x 3
        z = xyz[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = lens.fx * xyz[..., 0] / z + lens.cx
            v = lens.fy * xyz[..., 1] / z + lens.cy
        inside, vi, ui = self.pixel_of(u, v, z > 0)
        span_px = np.hypot(u[..., 0] - u[..., -1], v[..., 0] - v[..., -1])
        self.pixels = (vi, ui)
        self.uv = (u, v)
        d, seen_xyz = self._seen(vi, ui)
        with np.errstate(invalid="ignore"):
            seen = inside & np.isfinite(d) & (d > 0)
        a = seen_xyz @ e1 - edge_mid[:, :, np.newaxis, np.newaxis, 0]
        b = seen_xyz @ e2 - edge_mid[:, :, np.newaxis, np.newaxis, 1]
        self.seen_height = seen_xyz @ normal + self.camera_height_m
        out = self.out[:, :, np.newaxis, np.newaxis, :]
        offset: Float64Array = a * out[..., 0] + b * out[..., 1]
        return offset, seen, span_px
