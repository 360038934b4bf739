"""Tops: the flat, upward-facing surfaces standing on the support, each measured as an oriented
rectangle.

Contract: :func:`find_tops` takes the depth picture, its :class:`~onebox.perception.surface.
Surface` reading, the lens, the support, optionally the colour picture (registered with the
depth) and the finder's settings, and returns :class:`Tops`: one row per top, every top measured
at once. No I/O, no loop over pixels or over tops in Python (the pairs of pieces joined are
unioned in a short loop over the pairs).

How:

1. **Standing pixels facing up**: higher than ``min_height_m`` and 4 sigma(z) above the
   support, facing up (:mod:`onebox.perception.surface`), not on a depth step. An opening
   (3 x 3) takes off single pixels and spurs two pixels wide (flying pixels, stereo streaks);
   where the depth is quiet, only spurs a pixel wide (2 x 2): a narrow top seen from far,
   slanting across the rows, is two or three pixels wide.
2. **Connected regions** of them (4-connected, OpenCV), the pixels cut at steps or whose
   normals the smoothing turned grown back into the region beside them when at its height
   (:func:`onebox.perception.kernels.grow`, a few pixels).
3. **Pieces of one top joined** (:func:`join_hidden`) where something nearer cut them apart,
   their planes meet and nothing lower shows where the top between them would be.
4. **Seams seen only in colour**: two touching cartons of one height are one region in depth;
   the thin dark line between them (or a colour edge) runs straight across the region from
   side to side, which print and labels do not. Every region is split where such a line
   crosses it (:mod:`onebox.perception.seams`) and measured again.
5. **Two tops side by side at one height**, with no seam seen between them: one region whose
   outline turns inward where they meet (an L, a T). A region that fills its rectangle poorly
   is cut parallel to a side where both parts fill theirs, if what they leave of it is seen
   lower, past it (nearer, it is one top partly hidden) (:func:`split_at_corners`).
6. **Each top measured**: its plane (least squares on its points, in the support's
   coordinates), its oriented rectangle (the angle whose rectangle round the region's outline
   is smallest; the extent along each axis taken over the pixels whose cross-section is at
   least ``PROFILE_SHARE`` of a typical one, so a ragged or smeared edge's stray pixels do not
   stretch it), its area (each pixel's footprint on the plane), how full its rectangle and its
   corners are, how flat it is and how its middle half and its middle 80 % curve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import kernels, seams
from onebox.perception.support import Support
from onebox.perception.surface import Surface, _rays

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int32]
BoolArray = npt.NDArray[np.bool_]

ANGLES = np.radians(np.arange(0.0, 90.0, 5.0))
"""The rectangle's angles tried first (a rectangle repeats every quarter turn)..."""
FINE_ANGLES = np.radians(np.arange(-4.5, 4.6, 0.5))
"""...then about the best of them."""
PROFILE_SHARE = 0.25
"""A cross-section holding less than this share of the top's typical one (its pixels over its
cross-sections) is a stray (a spur, a smear), not the top's extent."""
MIN_PIXELS = 12
"""Fewer pixels than this are no top (speckles), whatever their footprint."""
JOIN_SAMPLES = 24
"""Points looked at between two pieces of a top that something nearer may have cut apart..."""
JOIN_ACROSS = 0.15
"""...on the line between their middles and on two beside it, this share of the narrower
piece's width to either side: a top is hidden across its width, not along one line (two tops
that meet at a corner have something lower in one of the corners between them)."""
JOIN_STEP = 2.5
"""Lower than the pieces' height by this many times their tolerance, beside the middles' line,
is a step down between two tops."""
PINCHED_PX = 8.0
"""A top narrower than this many pixels is pinched in two where its edges' steps narrow it."""
BORDER_PX = 3
"""A top this close to the picture's edge may go on past it (its edge pixels smeared or cut at
a step)..."""
ALONG_BORDER_PX = 12
"""...when it runs along the edge for this many pixels or more: cut off, its extent unknown. A
corner that only grazes the edge spans fewer: both sides beside it are still seen, and the
rectangle placed on them keeps its size."""
CORNERED_FILL = 0.9
"""A top filling less of its rectangle than this may be two tops side by side at one height
(no step, no seam between them: their outline turns inward where they meet)..."""
PART_FILL = 0.9
"""...cut in two where each part fills its own rectangle this well at least..."""
FILL_GAINED = 0.05
"""...and by this much more than the whole fills its own..."""
MIN_PART_M = 0.015
"""...each part this wide at least each way (the narrowest box)..."""
NOTCH_LOWER = 0.8
"""...when what the parts leave of the whole's rectangle is seen lower than the top, past it,
at this share of the points looked at there (nearer, it is a top partly hidden; no reading,
nothing is known)."""
NOTCH_GRID = 12
"""Points looked at across the whole's rectangle each way, for what the parts leave of it."""
CORNER_ROUNDS = 2
"""Cutting at inward corners and measuring again, at most this often."""


@dataclass(frozen=True)
class Tops:
    """Every top of a picture; row k of each array is top k (``labels`` holds k + 1)."""

    labels: IntArray
    """H x W: 0 for no top, k + 1 for top k's pixels."""
    height_m: Float64Array
    """The top plane's height above the support at the rectangle's middle."""
    middle_ab: Float64Array
    """(n, 2): the rectangle's middle in the support plane's coordinates (basis e1, e2)."""
    axis_ab: Float64Array
    """(n, 2): unit vector along the rectangle's length, in the same coordinates."""
    length_m: Float64Array
    width_m: Float64Array
    area_m2: Float64Array
    """The top's area seen, laid on the support plane (each pixel's footprint, summed)."""
    fill: Float64Array
    """Area seen over the rectangle's."""
    corners: Float64Array
    """How full the rectangle's four corner squares are (a fifth of the width on a side, three
    pixels at least, a pixel in; on a top under two squares wide, as far across as they reach)."""
    turned: Float64Array
    """The rectangle's area over that of the rectangle round the same pixels turned 45
    degrees, strays left out of both: about 1 for a round top, as wide at every turn; two
    thirds for a square (the turned one's thin tips are strays), less for a longer one."""
    rms_m: Float64Array
    """How far the top's points lie off its plane (root mean square)."""
    sag_m: Float64Array
    """(n, 2): how far the top curves from its middle to the edges of a window round it, along
    the axis it curves more: the middle half, the middle 80 % (less three pixels each side)..."""
    sag_share: Float64Array
    """...and that over half its extent along that axis."""
    tilt_deg: Float64Array
    """The top plane's angle to the support."""
    slope_ab: Float64Array
    """(n, 2): the top plane's rise along e1 and e2 (height = height_m + slope . offset)."""
    centroid_abh: Float64Array
    """(n, 3): the mean of the top's points' a, b and height."""
    depth_m: Float64Array
    """The top's mean distance along the optical axis."""
    sigma_m: Float64Array
    """The depth noise at that distance."""
    pixels: IntArray
    on_border: BoolArray
    """Runs along the picture's edge (``ALONG_BORDER_PX`` within ``BORDER_PX`` of it): cut off,
    its extent unknown."""
    basis: Float64Array
    """(3, 3): e1, e2 and the support normal, rows, in the optical frame."""
    points: Points
    """The pixels the tops were measured from, in the support plane's coordinates."""

    def __len__(self) -> int:
        return len(self.height_m)

    @property
    def pixel_m(self) -> Float64Array:
        """(n,): a pixel's side on each top's plane, on average (its area over its pixels)."""
        result: Float64Array = np.sqrt(self.area_m2 / np.maximum(self.pixels, 1))
        return result


def plane_basis(support: Support) -> Float64Array:
    """Two unit vectors in the support plane and its normal (rows), in the optical frame: e1
    is the optical x axis laid onto the plane."""
    n = np.asarray(support.normal_camera, dtype=np.float64)
    e1 = np.array([1.0, 0.0, 0.0]) - n[0] * n
    if math.sqrt(e1.dot(e1)) < 1e-6:
        e1 = np.array([0.0, 1.0, 0.0]) - n[1] * n
    e1 /= math.sqrt(e1.dot(e1))
    return np.stack([e1, cross(n, e1), n])


def cross(a: Float64Array, b: Float64Array) -> Float64Array:
    """``np.cross`` of two 3-vectors, the same products and differences written out (np.cross
    costs tens of microseconds in its generality)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def standing_regions(surface: Surface, min_height_m: float, max_height_m: float | None) -> IntArray:
    """Steps 1 and 2 of the module docstring: the labels of connected upward-facing regions."""
    height = surface.height_m
    core, open_, tolerance = kernels.standing(
        height,
        surface.sigma_m,
        surface.up,
        surface.step,
        min_height_m,
        np.inf if max_height_m is None else max_height_m,
    )
    opened = np.asarray(cv2.morphologyEx(core, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)), np.uint8)
    if surface.quiet.any():
        # Where the depth is quiet a pixel-wide spur is still a stray, but a top two or three
        # pixels wide (a narrow box seen from far, slanting across the rows) is no streak.
        # (An even square has no middle: erode from the pixel down and right, dilate back up
        # and left, so the opening keeps every pixel where it is. OpenCV's own opening with
        # a 2 x 2 square shifts the result a pixel down and right, across a step's pixels.)
        square = np.ones((2, 2), np.uint8)
        thin = cv2.dilate(cv2.erode(core, square, anchor=(0, 0)), square, anchor=(1, 1))
        opened |= thin & surface.quiet.view(np.uint8)
    _, found = cv2.connectedComponents(opened, connectivity=4, ltype=cv2.CV_32S)
    labels: IntArray = np.asarray(found, dtype=np.int32)
    # Grow the regions back over the pixels cut at steps and the edge pixels whose normal the
    # smoothing turned, where at the height of the region beside them.
    kernels.grow(labels, height, open_, tolerance, surface.reach_px + 2)
    return labels


def find_tops(
    depth_m: Float32Array,
    surface: Surface,
    lens: Intrinsics,
    support: Support,
    colour: npt.NDArray[np.uint8] | None,
    min_height_m: float,
    max_height_m: float | None = None,
) -> Tops:
    """Every top in the picture (see the module docstring)."""
    labels = kernels.drop_small(standing_regions(surface, min_height_m, max_height_m), MIN_PIXELS)
    seam = None if colour is None else seams.seam_map(colour, depth_m, lens)
    basis = plane_basis(support)
    tops = _measure(labels, depth_m, surface, lens, basis)
    joined = join_hidden(tops, depth_m, lens, support)
    if joined is not None:
        tops = _measure(joined, depth_m, surface, lens, basis, tops)
    # Split at seams and measured again until no seam crosses a top: a round cuts each top
    # once, and a seam that crosses one part only shows once the other is split off. (Each
    # cut leaves a part at least seams.MIN_PART_M wide either side, so this ends.)
    while seam is not None:
        split = seams.split_at_seams(tops, seam[0], seam[1], surface.height_m)
        if split is None:
            break
        tops = _measure(split, depth_m, surface, lens, basis, tops)
    for _ in range(CORNER_ROUNDS):
        split = split_at_corners(tops, depth_m, lens, support)
        if split is None:
            break
        tops = _measure(split, depth_m, surface, lens, basis, tops)
    return tops


def split_at_corners(
    tops: Tops, depth_m: Float32Array, lens: Intrinsics, support: Support
) -> IntArray | None:
    """New labels with every top that is two rectangles side by side cut in two, or None.

    Two boxes of one height touching, with no seam seen between them, are one region whose
    outline turns inward where they meet (an L, a T, two ends offset). A top filling less than
    ``CORNERED_FILL`` of its rectangle is cut, parallel to a side, where both parts fill their
    own rectangles (:func:`kernels.corner_cuts`), if what the parts leave of the whole's
    rectangle is seen lower than the top: past it, not hidden by something nearer."""
    wanted = tops.fill < CORNERED_FILL
    if not wanted.any():
        return None
    cut, cut_along, cut_at, parts = kernels.corner_cuts(
        tops.points.top,
        tops.points.a,
        tops.points.b,
        tops.middle_ab,
        tops.axis_ab,
        tops.length_m,
        tops.width_m,
        tops.area_m2,
        tops.pixels,
        wanted,
        np.array([MIN_PART_M, PART_FILL, FILL_GAINED]),
    )
    if not cut.any():
        return None
    k = np.flatnonzero(cut)
    # Points across each cut top's rectangle, in (along the cut's axis, across it).
    share = (np.arange(NOTCH_GRID) + 0.5) / NOTCH_GRID - 0.5
    grid_u, grid_v = np.meshgrid(share, share, indexing="ij")
    u = grid_u * np.where(cut_along[k], tops.length_m[k], tops.width_m[k])[:, None, None]
    v = grid_v * np.where(cut_along[k], tops.width_m[k], tops.length_m[k])[:, None, None]
    step = tops.pixel_m[k][:, None, None]
    p = parts[k][:, None, None, :]
    inside = (
        (u >= p[..., 0] - step) & (u <= p[..., 1] + step)
        & (v >= p[..., 2] - step) & (v <= p[..., 3] + step)
    ) | (
        (u >= p[..., 4] - step) & (u <= p[..., 5] + step)
        & (v >= p[..., 6] - step) & (v <= p[..., 7] + step)
    )  # fmt: skip
    # Back to the rectangle's own axes (along its length, across it), then the plane's.
    along = np.where(cut_along[k, None, None], u, v)
    across = np.where(cut_along[k, None, None], v, u)
    axis = tops.axis_ab[k][:, None, None, :]
    ab = tops.middle_ab[k][:, None, None, :] + (
        along[..., None] * axis + across[..., None] * np.stack([-axis[..., 1], axis[..., 0]], -1)
    )
    height = np.broadcast_to(tops.height_m[k][:, None, None], u.shape)
    z, seen, in_picture, _ = sight(ab, height, tops.basis, depth_m, lens, support)
    tolerance = np.maximum(3.0 * tops.sigma_m[k], 0.003)[:, None, None]
    notch = ~inside & in_picture
    with np.errstate(invalid="ignore"):
        lower = notch & (seen > z + tolerance)
    looked = notch.sum(axis=(1, 2))
    cut[k] = (looked >= 3) & (lower.sum(axis=(1, 2)) >= NOTCH_LOWER * looked)
    if not cut.any():
        return None
    return seams.cut_labels(tops, cut, cut_along, cut_at)


def join_hidden(
    tops: Tops, depth_m: Float32Array, lens: Intrinsics, support: Support
) -> IntArray | None:
    """New labels with the pieces of one top that something nearer cuts apart made one (a
    carton seen either side of a box standing on it, a lid behind a bottle), or None.

    Two pieces are one top when they lie at one height and everything seen on the line between
    their middles, at that height, is one of them, that height left out of every top, or
    something nearer hiding it (at least one point of it: pieces that meet without anything in
    front were cut apart for a reason), and nothing seen on two lines beside it steps down."""
    n = len(tops)
    if n < 2:
        return None
    tolerance = np.maximum(3.0 * tops.sigma_m, 0.003)
    i, j = np.triu_indices(n, 1)
    # One plane: the larger piece's plane, carried on to the smaller's points, meets them
    # there on average (a small piece's own plane leans with its smeared edges; a lid that
    # leans or bulges is at two heights in two places).
    centroid = tops.centroid_abh
    large = np.where(tops.pixels[i] >= tops.pixels[j], i, j)
    small = i + j - large
    carried = tops.height_m[large] + (
        tops.slope_ab[large] * (centroid[small, :2] - tops.middle_ab[large])
    ).sum(axis=1)
    misfit = np.minimum(
        np.abs(carried - centroid[small, 2]), np.abs(tops.height_m[i] - tops.height_m[j])
    )
    level = misfit < np.maximum(tolerance[i], tolerance[j])
    i, j = i[level], j[level]
    if i.size == 0:
        return None
    # Lines (pair, line, sample): the middles' and two beside it.
    between = tops.middle_ab[j] - tops.middle_ab[i]
    across = between[:, ::-1] * np.array([-1.0, 1.0])
    across *= (
        JOIN_ACROSS
        * np.minimum(tops.width_m[i], tops.width_m[j])
        / np.maximum(np.hypot(*between.T), 1e-9)
    )[:, None]
    start = tops.middle_ab[i, None, :] + np.array([0.0, -1.0, 1.0])[None, :, None] * across[:, None]
    share = np.linspace(0.0, 1.0, JOIN_SAMPLES)
    ab = start[:, :, None, :] + share[None, None, :, None] * between[:, None, None, :]
    height = 0.5 * (tops.height_m[i] + tops.height_m[j])
    z, seen, inside, (vi, ui) = sight(ab, height[:, None, None], tops.basis, depth_m, lens, support)
    label = tops.labels[vi, ui] - 1
    slack = np.maximum(tolerance[i], tolerance[j])[:, None, None]
    with np.errstate(invalid="ignore"):
        nearer = seen < z - slack
    own = (label == i[:, None, None]) | (label == j[:, None, None])
    # ... or the same surface left out of every top (an edge pixel beside the thing nearer).
    with np.errstate(invalid="ignore"):
        own |= (label < 0) & (np.abs(seen - z) <= slack)
    unread = np.isnan(seen)  # no reading says nothing against
    # ... or, a few pixels wide, they touch all the way (pinched in two by the opening).
    narrow = tops.width_m * lens.fx / tops.depth_m < PINCHED_PX
    # Beside that line, only a step down (something lower seen where the top would be) says
    # against: a top that bends or leans a little is still one.
    with np.errstate(invalid="ignore"):
        below = seen[:, 1:] > z[:, 1:] + JOIN_STEP * slack
    middle = (own | nearer | unread)[:, 0]
    one = (
        inside[:, 0].all(axis=1)
        & middle.all(axis=1)
        & ~below.any(axis=(1, 2))
        & (nearer[:, 0].any(axis=1) | (own[:, 0].all(axis=1) & narrow[i] & narrow[j]))
    )
    if not one.any():
        return None
    # Union the joined pairs (a few: a short loop over pairs, not pixels).
    parent = np.arange(n)
    for a, b in zip(i[one], j[one], strict=True):
        ra, rb = a, b
        while parent[ra] != ra:
            ra = parent[ra]
        while parent[rb] != rb:
            rb = parent[rb]
        parent[max(ra, rb)] = min(ra, rb)
    while (parent[parent] != parent).any():
        parent = parent[parent]
    _, compact = np.unique(parent, return_inverse=True)
    lookup = np.concatenate([[0], compact + 1]).astype(np.int32)
    result: IntArray = np.take(lookup, tops.labels)
    return result


def sight(
    ab: Float64Array,
    height_m: Float64Array,
    basis: Float64Array,
    depth_m: Float32Array,
    lens: Intrinsics,
    support: Support,
) -> tuple[Float64Array, Float64Array, BoolArray, tuple[npt.NDArray[np.intp], ...]]:
    """Points at (a, b) in the support plane's coordinates and ``height_m`` above it: the
    depth each would read if seen, the depth seen at its pixel (NaN outside the picture or no
    reading), whether it is in the picture, and its pixel (row, column)."""
    shape = np.broadcast_shapes(ab.shape[:-1], np.shape(height_m))
    z, seen, inside, vi, ui = kernels.sight(
        np.broadcast_to(ab[..., 0], shape).ravel(),
        np.broadcast_to(ab[..., 1], shape).ravel(),
        np.broadcast_to(height_m, shape).ravel(),
        basis,
        support.offset_camera_m,
        depth_m,
        np.array([lens.fx, lens.fy, lens.cx, lens.cy]),
    )
    return (
        z.reshape(shape),
        seen.reshape(shape),
        inside.reshape(shape),
        (vi.reshape(shape), ui.reshape(shape)),
    )


@dataclass(frozen=True)
class Points:
    """The pixels of every top, flat: index into the picture, top, plane coordinates."""

    index: npt.NDArray[np.intp]
    top: IntArray
    a: Float64Array
    b: Float64Array
    h: Float64Array
    z: Float64Array


def _measure(
    labels: IntArray,
    depth_m: Float32Array,
    surface: Surface,
    lens: Intrinsics,
    basis: Float64Array,
    before: Tops | None = None,
) -> Tops:
    """Step 5 of the module docstring for every top (:func:`kernels.top_points`, then
    :func:`kernels.measure_tops`); a top with the same pixels as one of ``before`` (labels
    joined or split elsewhere) keeps its measures: a top's measures are its pixels' alone."""
    rows, cols = labels.shape
    across, down = _rays(lens, cols, rows)
    start, index, top, a, b, h, z, sigma_px, edge, ray_x, ray_y = kernels.top_points(
        labels, depth_m, surface.height_m, surface.sigma_m, across, down, basis
    )
    n = len(start) - 1
    pts = Points(index, top, a, b, h, z)
    kept = np.full(n, -1, dtype=np.intp) if before is None else _kept(before, labels, start)
    todo = np.flatnonzero(kept < 0)
    per_pixel = (a, b, h, z, sigma_px, edge, ray_x, ray_y)
    todo_start = start
    if len(todo) < n:
        # Only the changed tops' pixels are measured (each top's in its order).
        todo_start = np.zeros(len(todo) + 1, dtype=np.intp)
        np.cumsum(start[todo + 1] - start[todo], out=todo_start[1:])
        offset = np.repeat(start[todo] - todo_start[:-1], np.diff(todo_start))
        picked = offset + np.arange(todo_start[-1])
        per_pixel = tuple(values[picked] for values in per_pixel)
    measured = kernels.measure_tops(
        todo_start,
        *per_pixel,
        basis,
        lens.fx * lens.fy,
        ANGLES,
        FINE_ANGLES,
        PROFILE_SHARE,
    )
    if before is not None:
        same = np.flatnonzero(kept >= 0)
        known = (
            before.pixels.astype(np.float64),
            before.depth_m,
            before.sigma_m,
            before.height_m,
            before.middle_ab,
            before.axis_ab,
            before.length_m,
            before.width_m,
            before.area_m2,
            before.fill,
            before.corners,
            before.rms_m,
            before.sag_m,
            before.sag_share,
            before.tilt_deg,
            before.slope_ab,
            before.centroid_abh,
            before.turned,
        )
        merged = []
        for new, old in zip(measured, known, strict=True):
            full = np.empty((n, *new.shape[1:]), dtype=new.dtype)
            full[todo] = new
            full[same] = old[kept[same]]
            merged.append(full)
        measured = tuple(merged)
    (
        pixels,
        mean_z,
        sigma,
        height,
        middle,
        axis,
        length,
        width,
        area,
        fill,
        corners,
        rms,
        sag,
        sag_share,
        tilt,
        slope,
        centroid,
        turned,
    ) = measured
    # Runs along the picture's edge: its extent past it is unknown.
    on_border = kernels.border_spans(labels, BORDER_PX, n) >= ALONG_BORDER_PX
    return Tops(
        labels=labels,
        height_m=height,
        middle_ab=middle,
        axis_ab=axis,
        length_m=length,
        width_m=width,
        area_m2=area,
        fill=fill,
        corners=corners,
        turned=turned,
        rms_m=rms,
        sag_m=sag,
        sag_share=sag_share,
        tilt_deg=tilt,
        slope_ab=slope,
        centroid_abh=centroid,
        depth_m=mean_z,
        sigma_m=sigma,
        pixels=pixels.astype(np.int32),
        on_border=on_border,
        basis=basis,
        points=pts,
    )


def _kept(before: Tops, labels: IntArray, start: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
    """For each top of ``labels`` (pixels from ``start``, as :func:`kernels.top_points` gives
    them), the top of ``before`` with exactly its pixels, or -1. Joining and splitting only
    regroup ``before``'s pixels: a top of ``before`` whose pixels all went to one new top with
    as many pixels is that top."""
    kept = np.full(len(start) - 1, -1, dtype=np.intp)
    count = before.pixels.astype(np.intp)
    seen = np.flatnonzero(count > 0)
    if seen.size == 0:
        return kept
    first = (np.cumsum(count) - count)[seen]
    now = labels.ravel()[before.points.index]
    low = np.minimum.reduceat(now, first)
    high = np.maximum.reduceat(now, first)
    new = low.astype(np.intp) - 1
    whole = (low == high) & (low > 0)
    whole[whole] &= start[new[whole] + 1] - start[new[whole]] == count[seen[whole]]
    kept[new[whole]] = seen[whole]
    return kept
