"""What each box stands on, and how tall it is: step 6 of :mod:`onebox.perception.boxes`.

:func:`find_bases` gives every box's top (a :class:`onebox.perception.tops.Plateau`) its base:
the support, a lower top, a platform or its own ledge, from probe lines out past its sides;
:func:`raise_to_faces` checks the bases against the side faces the camera sees;
:func:`shadowed_sides` lets a box on a platform run into a taller neighbour's shadow; and
:func:`extent_unknown` says whether a box's size cannot be known. No I/O here.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from onebox.geometry import Intrinsics
from onebox.perception import faces
from onebox.perception.rectangle import Rectangle
from onebox.perception.support import Support
from onebox.perception.tops import (
    TOP_TOLERANCE_FLOOR_M,
    FinderSettings,
    Plateau,
    height_slope,
    on_level_surface,
    plane_basis,
)

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

HIDDEN_BAND_M = 0.01
"""A box whose hidden side is hidden by something standing off it by more than this (and
three footprints) has an unknown extent: it is left out."""
HIDDEN_SHARE = 0.5
"""... and by more than this share of the top's seen extent across the hidden side."""
LEVEL_TOLERANCE_FLOOR_M = 0.004
"""Two heights within this of each other are one level (a lid bulges or sags this much)."""
SLAB = 0.5
"""A box standing less tall over a top than this share of its width would be a slab on it:
few cartons are (a carton 25 cm wide, less than 12.5 cm over the next one of its row, stands
beside it, on what that one stands on)."""


PROBE_FRACTIONS = np.linspace(-0.4, 0.4, 5)
PROBE_REACH = np.array([1.0, 2.0, 4.0, 7.0])
"""Each probe line's points past the first (the foot), in steps of max(8 mm, 3 footprints)
out from the side: the box itself hides the nearest when the camera looks down past that side."""


def _frames(boxes: list[Plateau]) -> tuple[Float64Array, Float64Array, Float64Array, Float64Array]:
    """Per box its rectangle's middle (boxes x 2), its sides' outward normals (ax, -ax, perp,
    -perp: boxes x 4 x 2), the directions along those sides (perp, perp, ax, ax) and its
    length and width (boxes x 2)."""
    rects = [box.rect for box in boxes if box.rect is not None]
    assert len(rects) == len(boxes)
    mid = np.array([rect.middle for rect in rects], dtype=np.float64).reshape(-1, 2)
    ax = np.array([rect.axis for rect in rects], dtype=np.float64).reshape(-1, 2)
    size = np.array([(r.length_m, r.width_m) for r in rects], dtype=np.float64).reshape(-1, 2)
    perp = np.stack([-ax[:, 1], ax[:, 0]], axis=1)
    out = np.stack([ax, -ax, perp, -perp], axis=1)
    along = np.stack([perp, perp, ax, ax], axis=1)
    return mid, out, along, size


def _probes(boxes: list[Plateau]) -> Float64Array:
    """Lines of points in the support plane going out from each side of each box's rectangle,
    5 lines a side (boxes x lines x reaches x 2). The first point is the side's foot, 1.5
    footprints and 1 mm out (a rim of a lower top a few pixels wide); then PROBE_REACH
    steps."""
    mid, out, along, size = _frames(boxes)
    half = size[:, [0, 0, 1, 1], np.newaxis, np.newaxis] / 2  # out past each side
    half_along = size[:, [1, 1, 0, 0], np.newaxis, np.newaxis] / 2
    fractions = PROBE_FRACTIONS[np.newaxis, np.newaxis, :, np.newaxis]
    start = (
        mid[:, np.newaxis, np.newaxis, :]
        + out[:, :, np.newaxis, :] * half
        + (2 * fractions * half_along) * along[:, :, np.newaxis, :]
    )  # boxes x sides x fractions x 2
    footprint = np.array([box.footprint_m for box in boxes], dtype=np.float64)[:, np.newaxis]
    step = np.maximum(0.008, 3.0 * footprint)
    reach = np.concatenate([1.5 * footprint + 0.001, PROBE_REACH * step], axis=1)
    points = (
        start[:, :, :, np.newaxis, :]
        + reach[:, np.newaxis, np.newaxis, :, np.newaxis] * out[:, :, np.newaxis, np.newaxis, :]
    )
    result: Float64Array = points.reshape(len(boxes), -1, reach.shape[1], 2)
    return result


def _camera_out_m(rect: Rectangle, outward: npt.ArrayLike) -> float:
    """How far the camera stands out past the rectangle's side whose outward unit normal is
    ``outward`` (positive: it sees that side's face); it stands over the support's origin."""
    o = np.asarray(outward, dtype=np.float64)
    return -float(np.asarray(rect.middle) @ o) - rect.half_extent(float(o[0]), float(o[1]))


def _face_slant(boxes: list[Plateau], probes: Float64Array) -> Float64Array:
    """Per box, line and point of :func:`_probes`: how far under a point's level (per metre
    of the camera's height over it) the ray through it meets the box's side behind it, where
    the camera sees that side's face (inf where it does not)."""
    mid, out, _, size = _frames(boxes)
    ox, oy = out[..., 0], out[..., 1]  # boxes x sides
    ax, ay = ox[:, :1], oy[:, :1]
    # Each side's half extent along its outward normal (as Rectangle.half_extent), and the
    # camera's distance out past it: the camera stands over the support's origin.
    half = 0.5 * (
        np.abs(size[:, :1] * (ax * ox + ay * oy)) + np.abs(size[:, 1:] * (ay * ox - ax * oy))
    )
    camera_out = -(mid[:, :1] * ox + mid[:, 1:] * oy) - half
    lines = probes.reshape(len(boxes), 4, len(PROBE_FRACTIONS), -1, 2)
    rel = lines - mid[:, np.newaxis, np.newaxis, np.newaxis, :]
    o = out[:, :, np.newaxis, np.newaxis, :]
    point_out = rel[..., 0] * o[..., 0] + rel[..., 1] * o[..., 1]
    point_out -= half[..., np.newaxis, np.newaxis]
    camera = camera_out[..., np.newaxis, np.newaxis]
    with np.errstate(divide="ignore", invalid="ignore"):
        slant = point_out / (camera - point_out)
    result: Float64Array = np.where((camera > point_out) & (point_out > 0), slant, np.inf)
    return result.reshape(probes.shape[:3])


def shadowed_sides(boxes: list[Plateau], camera_height_m: float, settings: FinderSettings) -> None:
    """A taller box beside a box, between it and the camera, hides a band of its top along
    that side (band = height difference x how far the camera looks past the taller top). On
    a platform (cartons on a pallet stand packed) the side runs on into the shadow, halfway
    to the taller box's side; elsewhere (boxes strewn on a table) the seen extent stays."""
    for box in boxes:
        if not box.on_platform:
            continue
        assert box.rect is not None
        rect = box.rect
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        mid = np.asarray(rect.middle)
        half = {0: rect.length_m / 2, 1: rect.width_m / 2}
        sides = [(ax, 0, 1.0), (perp, 1, 1.0), (-ax, 0, -1.0), (-perp, 1, -1.0)]
        extent = [half[0], half[1], half[0], half[1]]
        real = {(round(x, 6), round(y, 6)) for x, y in rect.edge_normals}
        eaten = {(round(x, 6), round(y, 6)) for x, y in rect.dropout_normals}
        for k, (normal, along_k, _) in enumerate(sides):
            key = (round(float(normal[0]), 6), round(float(normal[1]), 6))
            if key in real:
                continue
            # The seen edge may stop a footprint short of the shadow (noise), two more where
            # the camera drops the readings along depth edges.
            slack = max((3.0 if key in eaten else 2.0) * box.footprint_m, 0.005)
            edge_mid = mid + normal * half[along_k]
            toward = float(-edge_mid @ normal)  # the camera is above the plane's origin
            if toward <= 0:
                continue
            side_dir = perp if along_k == 0 else ax
            other_half = half[1 - along_k]
            best = None
            for other in boxes:
                if other is box or other.height_m < box.height_m + settings.min_height_m:
                    continue
                assert other.rect is not None
                corners = other.rect.corners - mid
                near_edge = float((corners @ normal).min())
                lateral = corners @ side_dir
                if lateral.max() < -other_half + 0.01 or lateral.min() > other_half - 0.01:
                    continue
                rise = other.height_m - box.height_m
                gap = near_edge - half[along_k]
                band = rise * (toward - gap) / max(camera_height_m - other.height_m, 0.05)
                # The top's seen edge ends where the shadow begins (within the noise):
                # otherwise the floor between them was seen and the edge is the top's own.
                if -slack <= gap <= band + slack and (best is None or near_edge < best):
                    best = near_edge
            if best is not None:
                # Touching cartons end at the taller one's side, a gap in the shadow ends
                # sooner: the middle of the shadow is never off by more than half of it.
                extent[k] = 0.5 * (half[along_k] + best)
        if extent != [half[0], half[1], half[0], half[1]]:
            length = extent[0] + extent[2]
            width = extent[1] + extent[3]
            middle = mid + ax * (extent[0] - extent[2]) / 2 + perp * (extent[1] - extent[3]) / 2
            axis = ax
            if width > length:
                length, width, axis = width, length, perp
                if axis[0] < 0 or (axis[0] == 0 and axis[1] < 0):
                    axis = -axis
            box.rect = replace(
                rect,
                middle=(float(middle[0]), float(middle[1])),
                axis=(float(axis[0]), float(axis[1])),
                length_m=float(length),
                width_m=float(width),
            )


UNDER_FRACTIONS = np.linspace(-0.25, 0.25, 5)
"""Where a top's footprint is looked under: a grid over its middle half each way. A far,
narrow top's rectangle may be off by a centimetre, and its middle is still over the box."""
SEEN_UNDER_SHARE = 0.9
"""A top under which the camera sees through, on one level, at this share of the grid,
floats: no box stands there. A real box's rarely passes 0.5 (a box across a narrower one, its
base not found); a floating clump's is 1 on some level."""


def _pixels(
    pts: Float64Array, lens: Intrinsics, shape: tuple[int, ...]
) -> tuple[Float64Array, Float64Array, BoolArray]:
    """The column and row of the pixel each optical-frame point falls in, and whether that is
    in a picture of ``shape`` (rows, columns), in front of the camera."""
    z = pts[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.rint(lens.fx * pts[..., 0] / z + lens.cx)
        v = np.rint(lens.fy * pts[..., 1] / z + lens.cy)
        inside = (z > 0) & (u >= 0) & (u < shape[1]) & (v >= 0) & (v < shape[0])
    return u, v, inside


def seen_under(
    boxes: list[Plateau], depth_m: Float32Array, lens: Intrinsics, support: Support
) -> BoolArray:
    """Per box, whether the camera sees through it: the box it would be does not stand there.
    A solid box hides every point inside it and under it, so the ray to one meets the box's
    surface first, nearer. A top afloat (a clump of a stereo camera's mismatched readings, or
    flying pixels) shows the table under it, from the side; looking straight down on it,
    nothing shows and this cannot tell. Looked at on a grid over the footprint's middle, at
    three levels: the base's and the support's (through: a reading at the level, within the
    noise or half the way back to where the ray enters the box), and halfway up the box (a
    reading clearly past the point)."""
    result: BoolArray = np.zeros(len(boxes), dtype=bool)
    measured = [i for i, b in enumerate(boxes) if b.rect is not None]
    boxes = [boxes[i] for i in measured]
    rects = [b.rect for b in boxes if b.rect is not None]
    if not rects:
        return result
    cam = plane_basis(support, None)
    middle = np.array([r.middle for r in rects])  # boxes x 2
    ax = np.array([r.axis for r in rects])
    across = np.stack([-ax[:, 1], ax[:, 0]], axis=1)
    f_len, f_wid = (f.reshape(-1) for f in np.meshgrid(UNDER_FRACTIONS, UNDER_FRACTIONS))
    length = np.array([r.length_m for r in rects])[:, np.newaxis, np.newaxis]
    width = np.array([r.width_m for r in rects])[:, np.newaxis, np.newaxis]
    flat = (
        middle[:, np.newaxis]
        + f_len[:, np.newaxis] * length * ax[:, np.newaxis]
        + f_wid[:, np.newaxis] * width * across[:, np.newaxis]
    )  # boxes x samples x 2
    # Its base's level and the support's (under a box on another box, or on a ledge of its
    # own, the support is hidden too; an overhang hides less than half of it), where a reading
    # at the level is seen through the box; and halfway up, inside the box, where only one
    # clearly past the point is.
    base = np.array([b.base_m for b in boxes])
    top = np.array([b.height_m for b in boxes])
    level = np.stack([base, np.zeros_like(base), 0.5 * (base + top)], axis=1)  # boxes x 3
    pts = (
        flat[:, np.newaxis, :, :1] * cam[0]
        + flat[:, np.newaxis, :, 1:] * cam[1]
        + (level - support.offset_camera_m)[:, :, np.newaxis, np.newaxis] * cam[2]
    )  # boxes x levels x samples x 3
    z = pts[..., 2]
    u, v, inside = _pixels(pts, lens, depth_m.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        # Where the ray to the point enters the box, as a share of the way from the camera
        # (at (0, 0) on the plane, at height offset): the slabs' entries, the latest of them.
        camera = -middle[:, np.newaxis]  # boxes x 1 x 2, from the rectangle's middle
        enter = np.zeros(z.shape)
        for axis, half in ((ax, length), (across, width)):
            c0 = (camera * axis[:, np.newaxis]).sum(-1)
            d0 = (flat * axis[:, np.newaxis]).sum(-1)  # boxes x samples
            near = np.minimum((-half[..., 0] - c0) / d0, (half[..., 0] - c0) / d0)
            enter = np.maximum(enter, np.where(d0 != 0, near, 0.0)[:, np.newaxis])
        down = level - support.offset_camera_m  # the camera is at height offset
        near_h = np.minimum(
            (base - support.offset_camera_m)[:, np.newaxis] / down,
            (top - support.offset_camera_m)[:, np.newaxis] / down,
        )
        enter = np.maximum(enter, near_h[..., np.newaxis])
        gap = (1.0 - np.clip(enter, 0.0, 1.0)) * z
    seen = np.where(
        inside,
        depth_m[np.where(inside, v, 0).astype(np.intp), np.where(inside, u, 0).astype(np.intp)],
        np.nan,
    )
    noise = np.maximum(3.0 * support.sigma_at(z), LEVEL_TOLERANCE_FLOOR_M)
    margin = np.minimum(noise, 0.5 * gap)
    margin[:, 2] = -noise[:, 2]
    with np.errstate(invalid="ignore"):
        through = (seen > z - margin).sum(axis=-1)  # boxes x levels
    looked = inside.sum(axis=-1)
    share = through / np.maximum(looked, 1)
    # Under a box standing on a wide top, the support is hidden only where that top is solid
    # down to it: under a table's top, or a pallet's, the camera sees the floor past its edge.
    # (A clump on a clump is still looked through to the support.)
    on_wide = np.array([_wide(b.stands_on) for b in boxes], dtype=bool)
    share[on_wide, 1] = 0.0
    result[measured] = ((looked >= 0.5 * inside.shape[-1]) & (share >= SEEN_UNDER_SHARE)).any(
        axis=1
    )
    return result


OPEN_UNDER_MIN_M = 0.3
"""Only tops at least this wide are looked under: a clump afloat is :func:`seen_under`'s, and
a narrower top's rectangle may be a centimetre off against the strip of floor seen under a
table."""
OPEN_UNDER_SIDE_RAYS = 20
"""A top is looked under along the rays that pass down past its sides into its footprint (a
solid box's side face stops each of them): at least this many readings of them..."""
OPEN_UNDER_SHARE = 0.5
"""...of which this share lands inside its footprint, well under its top: a table's or a
pallet's top on legs or blocks, not a box. Speckles on a box's face land so one in a hundred."""
OPEN_UNDER_INSET_M = 0.01
"""How far inside the top's rectangle such a ray must reach the support, and such a reading
land (a far top's rectangle is a centimetre off at most; a face's readings blur at its edges).
Under a table seen from just past its edge the strip of floor seen is 3-7 cm deep."""
OPEN_UNDER_DROP = 0.2
"""...and how far under its top, as a share of its height over the support (a table's top
is a slab a few centimetres thick)."""
OPEN_UNDER_PIXELS = 40_000
"""At most this many readings are looked at per top (every k-th row and column)."""
TABLE_MIN_M = 0.35
"""A wide top on the support and at least this high that the camera sees from over its
footprint (no ray passes down past its sides) is a table's if it carries boxes: from there a
table and a crate look the same, and a crate on a pallet stands on the pallet..."""
BARE_TABLE_MIN_M = 0.4
"""...and, carrying nothing, if it is at least this wide too."""


def _wide(top: Plateau | None) -> bool:
    """Whether a box stands on a top at least :data:`OPEN_UNDER_MIN_M` wide."""
    return top is not None and top.rect is not None and top.rect.width_m >= OPEN_UNDER_MIN_M


def open_under(
    boxes: list[Plateau], depth_m: Float32Array, lens: Intrinsics, support: Support
) -> BoolArray:
    """Per box, whether it is no solid box but a table's top: the camera sees under it past
    its sides (the floor round it and under it), or sees it from over its footprint, wide, on
    the support and as high as a table."""
    result: BoolArray = np.zeros(len(boxes), dtype=bool)
    carrying = {id(b.stands_on) for b in boxes if b.stands_on is not None}
    for i, box in enumerate(boxes):
        if box.platform or box.rect is None or not _wide(box):
            continue
        if not 0.0 < box.height_m < support.offset_camera_m:
            continue
        looked, under = _looked_under(box, box.rect, depth_m, lens, support)
        if looked >= OPEN_UNDER_SIDE_RAYS:
            result[i] = under >= OPEN_UNDER_SHARE * looked
        else:
            result[i] = (
                box.stands_on is None
                and box.height_m >= TABLE_MIN_M
                and (id(box) in carrying or box.rect.width_m >= BARE_TABLE_MIN_M)
            )
    return result


def _looked_under(
    box: Plateau, rect: Rectangle, depth_m: Float32Array, lens: Intrinsics, support: Support
) -> tuple[int, int]:
    """How many readings (of every k-th pixel) lie along rays that pass down past the top's
    sides and reach the support inside its footprint, and how many of those land inside the
    footprint, under the top by :data:`OPEN_UNDER_DROP` of its height or more."""
    cam = plane_basis(support, None)
    height = support.offset_camera_m  # the camera's, over the support, at (0, 0) in the plane
    top = box.height_m
    rows_n, cols_n = depth_m.shape
    axes = np.array([rect.axis, (-rect.axis[1], rect.axis[0])])  # along, across
    middle = np.asarray(rect.middle)
    half = np.array([rect.length_m, rect.width_m]) / 2
    # The part of the picture the box would fill, from its top down to the support.
    corners = middle + (np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]]) * half) @ axes
    pts = np.concatenate([corners @ cam[:2] + (level - height) * cam[2] for level in (top, 0.0)])
    r0, r1, c0, c1 = 0, rows_n, 0, cols_n
    if (pts[:, 2] > 0).all():
        u = lens.fx * pts[:, 0] / pts[:, 2] + lens.cx
        v = lens.fy * pts[:, 1] / pts[:, 2] + lens.cy
        c0, c1 = max(int(u.min()), 0), min(int(u.max()) + 2, cols_n)
        r0, r1 = max(int(v.min()), 0), min(int(v.max()) + 2, rows_n)
        if c0 >= c1 or r0 >= r1:
            return 0, 0
    step = max(1, math.ceil(math.sqrt((r1 - r0) * (c1 - c0) / OPEN_UNDER_PIXELS)))
    d = depth_m[r0:r1:step, c0:c1:step].astype(np.float64)
    x = ((np.arange(c0, c1, step) - lens.cx) / lens.fx)[np.newaxis, :] * d
    y = ((np.arange(r0, r1, step) - lens.cy) / lens.fy)[:, np.newaxis] * d
    point = np.stack([x, y, d], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        flat = (point @ cam[:2].T - middle) @ axes.T  # along and across, from the middle
        h = point @ cam[2] + height
        # Readings at the top's level are the top's own (its rectangle a little short of it
        # where the edges drop out), not what the ray meets under or past it.
        valid = (d > 0) & (h < top - box.tolerance_m)
        # Where each ray crosses the top's level and the support's: from the camera, a share
        # of the way to its reading.
        camera = -middle @ axes.T
        past = ~_in_rect(camera, flat, (height - top) / (height - h), half)
        reach = _in_rect(camera, flat, height / (height - h), half - OPEN_UNDER_INSET_M)
        rays = valid & past & reach
        lands = _in_rect(camera, flat, np.ones_like(d), half - OPEN_UNDER_INSET_M)
        under = rays & lands & (h < (1.0 - OPEN_UNDER_DROP) * top)
    return int(np.count_nonzero(rays)), int(np.count_nonzero(under))


def _in_rect(
    camera: Float64Array, flat: Float64Array, share: Float64Array, half: Float64Array
) -> BoolArray:
    """Whether the point ``share`` of the way from ``camera`` to each of ``flat`` (along and
    across a rectangle, from its middle) lies inside it (half sides ``half``)."""
    at = camera + (flat - camera) * share[..., np.newaxis]
    inside: BoolArray = (np.abs(at[..., 0]) < half[0]) & (np.abs(at[..., 1]) < half[1])
    return inside


def extent_unknown(box: Plateau) -> bool:
    """Whether a box's top may go on far past what is seen: a side is hidden, and what hides
    it stands well off the top's edge (a taller object between the top and the camera hides
    a band of the top, which may go on under it by as much), by more than half the top's seen
    extent across that side. Such a top's size says little (a carton 13 % seen is reported a
    quarter of its length), so it is not reported as a box. A wall rising at the edge (a
    taller box beside, touching) hides nothing; a band narrow beside the seen extent leaves
    the size a close lower bound (``Box.hidden_sides``); on a platform, cartons stand packed
    and the side runs halfway into the shadow (:func:`_shadowed_sides`)."""
    rect = box.rect
    assert rect is not None
    band = box.hidden_band_m
    if rect.hidden_sides == 0 or box.on_platform:
        return False
    if band <= max(3.0 * box.footprint_m, HIDDEN_BAND_M):
        return False
    for n0, n1 in rect.hidden_normals:
        seen = rect.half_extent(n0, n1) * 2.0
        if band > HIDDEN_SHARE * seen:
            return True
    return False


def _reaches_under(
    lower: Plateau,
    upper: Plateau,
    slack: float = 0.01,
    exact: bool = False,
    rows: bool = False,
) -> bool:
    """Whether the lower top may go on under the upper box: its extent is unknown (no
    rectangle), its rectangle holds the upper's middle, or the upper lies past one of its
    hidden sides and within that side's span (a strip of a box's top beside the box across
    it; a pallet's top seen as a strip in front of the cartons on it). A top that a box
    overhangs along the side (the next carton of a row, seen past its neighbour) does not
    reach under it: a top standing beside is no base. A top that is no box may go on past any
    side. ``exact``: only a box's top, past a hidden side whose span the upper's matches (the
    upper hides the lower's top right across). ``rows``: nor the top of the next carton of a
    row, a little lower (:func:`_next_in_row`), a box's or one that a box on it keeps from
    being a box (for choosing a base; a base already chosen is not asked again)."""
    if lower.rect is None or (exact and not lower.is_box):
        return not exact
    assert upper.rect is not None
    rect = lower.rect
    ax0, ax1 = rect.axis
    rx = upper.rect.middle[0] - rect.middle[0]
    ry = upper.rect.middle[1] - rect.middle[1]
    along, across = rx * ax0 + ry * ax1, ry * ax0 - rx * ax1
    hl, hw = rect.length_m / 2, rect.width_m / 2
    if not exact and abs(along) <= hl + slack and abs(across) <= hw + slack:
        return True
    all_sides = ((ax0, ax1), (-ax0, -ax1), (-ax1, ax0), (ax1, -ax0))
    if not exact and not lower.is_box and _touch(lower, upper):
        # A top that is no box is seen only in part (the box on it hides the rest, and the
        # box's own side face seen at a slant): touching is enough; the probes decide. But
        # not a carton's top that a box on it keeps from being a box of its own, beside the
        # next carton of its row.
        return not rows or not any(_next_in_row(lower, upper, o, slack) for o in all_sides)
    # A top that is no box may have any of its sides hidden (noise hides the rise).
    for o0, o1 in rect.hidden_normals if lower.is_box else all_sides:
        half_out, half_side = (hl, hw) if abs(o0 * ax0 + o1 * ax1) > 0.7 else (hw, hl)
        if rx * o0 + ry * o1 < half_out - slack:
            continue
        # The upper's half extent along the side, which must lie within the side's span.
        reach = upper.rect.half_extent(-o1, o0)
        room = half_side + max(slack, 0.1 * reach)
        offset = abs(ry * o0 - rx * o1)
        if rows and lower.is_box and _next_in_row(lower, upper, (o0, o1), slack):
            continue
        if offset + reach <= room and (
            not exact
            or (
                half_side <= reach + max(slack, 0.1 * reach)
                # ... and the strip is narrower than the box across it (the next carton of
                # a row of the same depth is a whole top of its own).
                and half_out < 0.6 * upper.rect.half_extent(o0, o1)
            )
        ):
            return True
    return False


def _next_in_row(lower: Plateau, upper: Plateau, side: tuple[float, float], slack: float) -> bool:
    """Whether the upper box stands past the lower top's ``side`` as the next carton of a row:
    it meets the whole side, end to end, and the lower top goes out from it as far as a
    carton, not a strip, and the upper would be a slab standing on it (a tall box's faces show
    where it stands). Two cartons of a row side by side, the lower's side hidden by the taller
    one's rise. A gap in a load (the surface under it seen where a carton is missing) is as
    deep as the cartons round it are tall, no slab's step, and stays their base."""
    assert lower.rect is not None and upper.rect is not None
    rect = lower.rect
    ax0, ax1 = rect.axis
    o0, o1 = side
    rx = upper.rect.middle[0] - rect.middle[0]
    ry = upper.rect.middle[1] - rect.middle[1]
    half_out, half_side = (
        (rect.length_m / 2, rect.width_m / 2)
        if abs(o0 * ax0 + o1 * ax1) > 0.7
        else (rect.width_m / 2, rect.length_m / 2)
    )
    reach = upper.rect.half_extent(-o1, o0)
    fit = max(slack, 0.1 * reach)
    return (
        rx * o0 + ry * o1 >= half_out - slack
        and upper.height_m - lower.height_m < SLAB * upper.rect.width_m
        and abs(ry * o0 - rx * o1) <= fit
        and abs(reach - half_side) <= fit
        and half_out >= 0.6 * upper.rect.half_extent(o0, o1)
    )


def find_bases(
    boxes: list[Plateau],
    plateaus: list[Plateau],
    height_m: Float32Array,
    labels_top: npt.NDArray[np.int32],
    lens: Intrinsics,
    support: Support,
    settings: FinderSettings,
) -> None:
    """What each box stands on (see the module docstring, step 6)."""
    if not boxes:
        return
    cols_n = height_m.shape[1]
    cam = plane_basis(support, None)
    # Levels: the support, every top, and each box's ledge (a level of its own box only).
    ledged = [i for i, b in enumerate(boxes) if b.ledge_m is not None]
    levels: list[Plateau | None] = [None, *plateaus, *(None for _ in ledged)]
    owner = np.array([-1] * (1 + len(plateaus)) + ledged, dtype=np.intp)
    level_h = np.array(
        [0.0] + [p.height_m for p in plateaus] + [boxes[i].ledge_m or 0.0 for i in ledged]
    )
    support_tol = 3.0 * float(support.sigma_at(support.distance_m))
    level_tol = np.maximum(
        np.array(
            [support_tol]
            + [p.tolerance_m for p in plateaus]
            + [boxes[i].tolerance_m for i in ledged]
        ),
        LEVEL_TOLERANCE_FLOOR_M,
    )
    # Every label the picture holds (a top dropped before it was measured keeps its label
    # there, with no height: no level is seen on it).
    labels_n = max(max(p.label for p in plateaus), int(labels_top.max()) - 1) + 1
    label_height = np.full(labels_n, np.nan)
    label_height[[p.label for p in plateaus]] = [p.height_m for p in plateaus]
    box_h = np.array([b.height_m for b in boxes])
    # A level within the noise of the box's own top is that top, not one under it (each
    # tolerance is three sigma of one reading: the two add in quadrature).
    box_tol = np.array([b.tolerance_m for b in boxes])
    gap = np.maximum(
        settings.min_height_m, np.hypot(box_tol[np.newaxis, :], level_tol[:, np.newaxis])
    )
    allowed = level_h[:, np.newaxis] < box_h[np.newaxis, :] - gap
    mine = owner[:, np.newaxis] == np.arange(len(boxes))[np.newaxis, :]
    allowed &= (owner[:, np.newaxis] < 0) | mine
    for j, level in enumerate(levels):
        if level is None:
            continue
        if level.upright or level.rounded:
            allowed[j] = False
            continue
        for i, box in enumerate(boxes):
            if allowed[j, i]:
                allowed[j, i] = _reaches_under(level, box, rows=True)
    _own_faces(allowed, levels, boxes, height_m, labels_top, lens, support, cam)
    # Only the pairs (level, box) that may be the box's base are probed.
    pair_l, pair_b = np.nonzero(allowed)
    probes = _probes(boxes)  # boxes x lines x reaches x 2
    # Camera-frame probe points at each pair's level: a e1 + b e2 + (level - offset) n.
    shape = (-1, 1, 1, 1)
    pair_probes = probes[pair_b]
    pts = (
        pair_probes[..., :1] * cam[0]
        + pair_probes[..., 1:] * cam[1]
        + (level_h[pair_l].reshape(shape) - support.offset_camera_m) * cam[2]
    )
    u, v, inside = _pixels(pts, lens, height_m.shape)
    ui = np.where(inside, u, 0).astype(np.intp)
    vi = np.where(inside, v, 0).astype(np.intp)
    seen_h = np.where(inside, height_m[vi, ui], np.nan)
    seen_label = np.where(inside, labels_top[vi, ui] - 1, -2)
    own = np.array([b.label for b in boxes])[pair_b].reshape(-1, 1, 1)
    lh = level_h[pair_l].reshape(shape[:-1])
    lt = level_tol[pair_l].reshape(shape[:-1])
    # Along each line the first point whose surface is seen (a reading, not the box itself,
    # nothing higher in front of it) tells whether the level is there or lower.
    with np.errstate(invalid="ignore"):
        known = np.isfinite(seen_h) & (seen_label != own) & (seen_h < lh + lt)
        first = np.argmax(known, axis=-1)[..., np.newaxis]
        any_known = known.any(axis=-1)
        h_first = np.take_along_axis(seen_h, first, -1)[..., 0]
        label_first = np.take_along_axis(seen_label, first, -1)[..., 0]
        # Past a side whose face the camera sees, a reading on no top just under the level
        # may be that face, right behind the probe point: a point tells the level from the
        # face only by half the drop the ray makes between them.
        drop = (support.offset_camera_m - lh) * _face_slant(boxes, probes)[pair_b]
        face_tol = np.minimum(lt, 0.5 * np.take_along_axis(drop, first, -1))[..., 0]
        near_tol = np.where((label_first < 0) & (pair_l > 0)[:, np.newaxis], face_tol, lt[..., 0])
        match = any_known & (np.abs(h_first - lh[..., 0]) < near_tol)
        # The level's own top, or any top at its height (one carton's top seen on both
        # sides of the box across it is two pieces), or no top (the support, a fragment).
        top_h = np.append(label_height, np.nan)[np.where(label_first >= 0, label_first, -1)]
        match &= (label_first < 0) | (np.abs(top_h - lh[..., 0]) < lt[..., 0])
        lower = any_known & (h_first < lh[..., 0] - lt[..., 0])
    # A level is seen on pixels of no top, or of a top that may reach under the box (not a
    # box of its own standing beside it: the top of the next carton along a row is no sign
    # of what the box stands on).
    under = np.ones((len(label_height) + 1, len(boxes)), dtype=bool)
    by_label = {p.label: p for p in plateaus if p.is_box}
    for t in np.unique(label_first[match & (label_first >= 0)]):
        if int(t) in by_label:
            under[t] = [_reaches_under(by_label[int(t)], box, rows=True) for box in boxes]
    match &= (label_first < 0) | under[
        np.where(label_first >= 0, label_first, -1), pair_b[:, np.newaxis]
    ]
    ledge_rows = np.flatnonzero(owner[pair_l] >= 0)
    if len(ledge_rows):
        # ... and on a level surface, not on the box's own side face seen at a slant.
        at = np.take_along_axis((vi * cols_n + ui)[ledge_rows], first[ledge_rows], -1)[..., 0]
        fp = np.array([b.footprint_m for b in boxes])[pair_b[ledge_rows]].reshape(-1, 1)
        limit = np.minimum(lt[ledge_rows, ..., 0], 0.5 * fp)
        match[ledge_rows] &= on_level_surface(height_m.reshape(-1), at, cols_n, limit)
    # Past a side the camera cannot see the foot of (the box hides it), a lower reading
    # farther out says only that the level is narrower than the box's shadow: against a
    # box's own ledge only a lower reading at the foot itself counts.
    grid = allowed.shape
    matches = np.zeros(grid, dtype=np.intp)
    lowers = np.zeros(grid, dtype=np.intp)
    foot_lowers = np.zeros(grid, dtype=np.intp)
    across = np.zeros(grid, dtype=bool)
    matches[pair_l, pair_b] = match.sum(axis=1)
    lowers[pair_l, pair_b] = lower.sum(axis=1)
    foot_lowers[pair_l, pair_b] = (lower & (first[..., 0] == 0)).sum(axis=1)
    # A level counts when it is seen on at least two probes and hardly anything lower is, or
    # on two opposite sides (a box across a narrower one: past its other sides lies lower).
    probes = match.shape[1] // 4  # (no pair at all: -1 cannot be inferred from size 0)
    side_match = match.reshape(len(pair_l), 4, probes).sum(axis=2)
    side_lower = lower.reshape(len(pair_l), 4, probes).sum(axis=2)
    per_side = side_match >= 2
    across[pair_l, pair_b] = (per_side[:, 0] & per_side[:, 1]) | (per_side[:, 2] & per_side[:, 3])
    # ... or, a level that is no whole box's top, on two sides or more, more often than
    # anything lower there: the rim of the box under it, a few pixels wide, or a strip of it
    # seen past the box's side face (the box overhangs it, or stands off its middle, past the
    # other sides). A whole box's top beside the box is no sign of what it stands on.
    sides_seen = ((side_match >= 1) & (side_match >= side_lower)).sum(axis=1)
    # A box's ledge at the height of a box standing beside it (touching, not reaching under
    # it) is that box's top seen past the seam between them: no more a sign than the top.
    beside = np.zeros(len(levels), dtype=bool)
    for row in np.flatnonzero(owner >= 0):
        box = boxes[owner[row]]
        beside[row] = any(
            p.is_box
            and p is not box
            and abs(p.height_m - level_h[row]) < level_tol[row]
            and _touch(p, box)
            and not _reaches_under(p, box, rows=True)
            for p in plateaus
        )
    partial = np.array([level is None or not level.is_box for level in levels]) & ~beside
    partial = partial[pair_l]
    across[pair_l, pair_b] |= (sides_seen >= 2) & (side_match.sum(axis=1) >= 3) & partial
    # ... or a top seen on every line of two sides that meet, whose rectangle holds the box's
    # middle: the box overhangs its corner, and past its other two sides lies lower.
    whole = side_match >= len(PROBE_FRACTIONS)
    corner = (whole[:, 0] | whole[:, 1]) & (whole[:, 2] | whole[:, 3])
    for k in np.flatnonzero(corner):
        level = levels[pair_l[k]]
        if level is not None and level.rect is not None and _inside(level, boxes[pair_b[k]]):
            across[pair_l[k], pair_b[k]] = True
    seen_ok = allowed & (matches >= 2) & ((matches >= 0.75 * (matches + lowers)) | across)
    # A top seen as a strip beside the box, the box right across the strip's hidden side
    # (a small carton turned across a larger one): past the box's other sides lies lower.
    for j, i in zip(*np.nonzero(allowed & (matches >= 2) & ~seen_ok), strict=True):
        level = levels[j]
        if level is not None and _reaches_under(level, boxes[i], exact=True):
            seen_ok[j, i] = True
    # A ledge found right past the box's own outline needs less: a rim of the box under it is
    # often narrower than the foot's probe along some sides (the upper box turned on it).
    own_ok = (owner[:, np.newaxis] >= 0) & ~beside[:, np.newaxis] & (matches >= 3)
    own_ok &= matches >= 0.5 * (matches + foot_lowers)
    # ... or seen on every line of one side, when no top beside is at its height: the rim of
    # a box underneath that the upper one overhangs on its other sides.
    whole_side = np.zeros(grid, dtype=bool)
    whole_side[pair_l, pair_b] = (side_match >= len(PROBE_FRACTIONS)).any(axis=1)
    top_hs = np.array([p.height_m for p in plateaus])
    alone = np.array(
        [
            owner[j] >= 0 and not np.any(np.abs(top_hs - level_h[j]) < level_tol[j])
            for j in range(len(levels))
        ]
    )
    own_ok |= alone[:, np.newaxis] & whole_side
    seen_ok |= allowed & own_ok
    base: dict[int, int] = {}
    for i in range(len(boxes)):
        ok = np.flatnonzero(seen_ok[:, i])
        if len(ok):
            j = int(ok[np.argmax(level_h[ok])])
            # Of the levels at that height, the top whose rectangle holds the box's middle
            # (not the next carton of its row, at the same height), then a box's top (the
            # strip of a carton across which the box lies, not the sliver of a seam beside
            # it), then the most seen.
            near = ok[np.abs(level_h[ok] - level_h[j]) < level_tol[j]]
            if len(near) > 1:
                j = int(max(near, key=lambda k: _base_rank(levels[k], boxes[i], matches[k, i])))
            if owner[j] >= 0:
                # The ledge is the top of a box the box stands on, when one is at its height.
                same = np.flatnonzero(
                    allowed[:, i]
                    & (owner < 0)
                    & (np.abs(level_h - level_h[j]) < level_tol[j])
                    & (level_h > 0)
                )
                if len(same):
                    j = int(same[np.argmax(matches[same, i])])
            base[i] = j
    # The support seen past one side only is weak: it may be the floor past a load's edge,
    # the platform's rim there lost in the camera's dropout or in the box's shadow.
    pair_at = {(int(j), int(i)): k for k, (j, i) in enumerate(zip(pair_l, pair_b, strict=True))}
    weak = {
        i
        for i, j in base.items()
        if j == 0 and (i_k := pair_at.get((j, i))) is not None and (side_match[i_k] > 0).sum() <= 1
    }
    # A box hemmed in by touching boxes stands where most of them stand.
    for _ in range(3):
        changed = False
        for i, box in enumerate(boxes):
            if i in base:
                continue
            votes = [
                base[k]
                for k, other in enumerate(boxes)
                if k in base and allowed[base[k], i] and _touch(box, other)
            ]
            if votes:
                base[i] = max(set(votes), key=lambda j: (votes.count(j), level_h[j]))
                if base[i] == 0:
                    weak.add(i)
                changed = True
        if not changed:
            break
    # Touching boxes of one height stand on one level: a box whose base is weak (or still
    # undecided) takes the higher base of a touching box of its height, when a level there
    # that is no box's top (a platform's) may reach under it.
    is_box_top = np.array([level is not None and level.is_box for level in levels])
    level_index = np.arange(len(levels))
    weak |= {i for i in range(len(boxes)) if i not in base}
    for _ in range(3):
        changed = False
        for low in sorted(weak):
            current = base.get(low, 0)  # still undecided: the support, for now
            for near_k, other in enumerate(boxes):
                theirs = base.get(near_k)
                if (
                    theirs is None
                    or near_k == low
                    or level_h[theirs] <= level_h[current] + level_tol[current]
                    or abs(other.height_m - box_h[low]) >= max(other.tolerance_m, box_tol[low])
                    or not _touch(boxes[low], other)
                ):
                    continue
                # Their base, or a level at its height that may be this box's (their base
                # may be their own ledge).
                same = np.flatnonzero(
                    allowed[:, low]
                    & (np.abs(level_h - level_h[theirs]) < level_tol[theirs])
                    & (~is_box_top | (level_index == theirs))
                )
                if len(same):
                    current = base[low] = int(same[np.argmax(matches[same, low])])
                    changed = True
        if not changed:
            break
    carried = Counter(base.values())
    platforms = {
        j
        for i, j in base.items()
        if levels[j] is not None and _is_platform(levels[j], boxes[i], carried[j])  # type: ignore[arg-type]
    }
    for i, box in enumerate(boxes):
        if i not in base:
            # Still undecided: the highest platform it stands over, else the support.
            over = [j for j in platforms if allowed[j, i]]
            base[i] = int(max(over, key=lambda j: level_h[j])) if over else 0
        box.base_m = float(level_h[base[i]])
        level = levels[base[i]]
        box.stands_on = level
        if level is not None and base[i] in platforms:
            level.platform = True
            box.on_platform = True
        elif level is not None and level.is_box:
            box.on_plateau = level.label
    # A top walled in on two sides or more, at the height two touching boxes stand at, is
    # that surface seen through a gap in a load (a carton missing): a level, not a box. The
    # walls' tops stand off the part seen by what the walls hide of it (and any dropout band
    # at their feet): that far more they still touch it.
    for i, box in enumerate(boxes):
        assert box.rect is not None
        if (
            box.rect.hidden_sides >= 2
            and sum(
                k != i
                and other.stands_on is not box
                and other.base_m > 0
                and abs(other.base_m - box.height_m) < max(box.tolerance_m, LEVEL_TOLERANCE_FLOOR_M)
                and _touch(box, other, 0.02 + box.hidden_band_m)
                for k, other in enumerate(boxes)
            )
            >= 2
        ):
            box.platform = True


def raise_to_faces(
    boxes: list[Plateau],
    plateaus: list[Plateau],
    depth: Float32Array,
    colour: npt.NDArray[np.uint8] | None,
    lens: Intrinsics,
    support: Support,
    settings: FinderSettings,
) -> None:
    """A box whose side faces end well above its base stands higher (a box standing on a
    narrower one, which it overhangs, with the lower top's rim out of the probes' reach or
    unseen): its base is the level (the support, a top or a box's ledge) between where its
    faces are last seen and where the camera sees past them, or the faces' bottom itself when
    no level is there (a box on one hidden under it)."""
    if not boxes:
        return
    rects = [b.rect for b in boxes if b.rect is not None]
    assert len(rects) == len(boxes)  # every box has its rectangle
    tolerance = np.array(
        [max(FACE_FOOTPRINTS * b.footprint_m, FACE_TOLERANCE_M, b.tolerance_m) for b in boxes]
    )
    seen = faces.face_bottoms(
        np.array([r.middle for r in rects]),
        np.array([r.axis for r in rects]),
        np.array([[r.length_m / 2, r.width_m / 2] for r in rects]),
        np.array([b.height_m for b in boxes]),
        tolerance,
        depth,
        lens,
        plane_basis(support, None),
        support.offset_camera_m,
        colour,
    )
    tops: list[tuple[float, Plateau | None]] = [(p.height_m, p) for p in plateaus]
    for box, bottom, tol in zip(boxes, seen.bottoms, tolerance, strict=True):
        # The support, every top, and the box's own ledge.
        levels = [(0.0, None), *tops, *([] if box.ledge_m is None else [(box.ledge_m, None)])]
        slack = faces.resolution_m(box.height_m) + tol
        # Seen at a slant, a pixel's step down the face is long: the seam where a top beside
        # meets the face is read up to a pixel's step under that top.
        step = 0.0 if bottom is None else _face_step_m(box, bottom.seam_sides, support)
        if (
            bottom is not None
            and bottom.seam
            and any(
                p is not None and p is not box and _beside(p, box, bottom.seam_sides)
                for h, p in levels
                if bottom.low_m - slack <= h <= bottom.high_m + slack + step
            )
        ):
            # A seam in the colour where a top beside the box meets its face (the face goes on
            # down past that top, in one plane with it), not a box under it, of which only a
            # rim round the box's outline is seen.
            bottom = bottom.unseamed
        if bottom is None:
            continue
        if (
            bottom.middle_m <= box.base_m + max(settings.min_height_m, 2.0 * slack)
            or bottom.middle_m >= box.height_m - settings.min_height_m
        ):
            continue
        # A level between where the face is last seen and where the camera sees past it,
        # the nearest the face's last point (the rim of a box underneath hides the rest), of
        # those that may reach under the box.
        near = [
            (bottom.high_m - h, h, p)
            for h, p in levels
            if bottom.low_m - slack <= h <= bottom.high_m + slack
            and p is not box
            and (p is None or _reaches_under(p, box, rows=True) or _past_hidden_side(p, box))
        ]
        if near:
            _, box.base_m, level = min(near, key=lambda n: abs(n[0]))
            box.on_plateau = level.label if level is not None and level.is_box else None
            box.stands_on = level
            for p in plateaus:
                if (
                    abs(p.height_m - box.base_m) <= max(p.tolerance_m, box.tolerance_m)
                    and _past_hidden_side(p, box)
                    and _touch(p, box)
                ):
                    # The box hides that top's side: the top goes on under it, how far is
                    # unknown (a box with one standing on it, seen as a strip): a level.
                    p.platform = True
        else:
            box.base_m, box.on_plateau, box.stands_on = bottom.middle_m, None, None
    _lower_to_faces(boxes, plateaus, seen.reach_m, tolerance, settings)


FLUSH_DEG = 20.0
"""The most two sides may turn from each other and still run as one face where it is read."""


def _lower_to_faces(
    boxes: list[Plateau],
    plateaus: list[Plateau],
    reach_m: Float64Array,
    tolerance: Float64Array,
    settings: FinderSettings,
) -> None:
    """A box taken to stand on the top of a box beside it (that top's rim seen along one
    side, its far side hidden by the taller box rising there) whose own face is seen going on
    down well below that top, on a side that top has no side flush with, stands lower: a box
    is solid down to its bottom, and only a box under it flush with that side could go on in
    the face's plane. Its base is the highest level the face goes down to that may reach under
    it, else the support."""
    for box, sides, tol in zip(boxes, reach_m, tolerance, strict=True):
        lower = box.stands_on
        if lower is None or not lower.is_box or lower.rect is None or box.rect is None:
            continue
        slack = faces.resolution_m(box.height_m) + float(tol)
        # Past a hidden side the lower top goes on under the box, how far is unknown: it may
        # end flush with the box's side facing that way. The side facing the lower top says
        # nothing either (its foot is the lower top's edge, or hidden by it).
        ax = np.asarray(box.rect.axis)
        perp = np.array([-ax[1], ax[0]])
        toward = np.asarray(lower.rect.middle) - np.asarray(box.rect.middle)
        toward /= max(float(np.linalg.norm(toward)), 1e-9)
        open_ways = [np.asarray(h) for h in lower.rect.hidden_normals] + [toward]
        deep = [
            float(sides[k])
            for k, normal in enumerate((ax, -ax, perp, -perp))
            if sides[k] < box.base_m - max(settings.min_height_m, 2.0 * slack)
            and not any(float(normal @ h) > 0.7 for h in open_ways)
            and not _flush(lower, box, k, float(tol))
        ]
        if not deep:
            continue
        floor = min(deep) + slack
        levels = [
            p
            for p in plateaus
            if p is not box
            and p is not lower
            and p.height_m <= floor
            and p.height_m < box.height_m - settings.min_height_m
            and _reaches_under(p, box, rows=True)
        ]
        level = max(levels, key=lambda p: p.height_m, default=None)
        box.stands_on = level
        box.base_m = 0.0 if level is None else level.height_m
        box.on_plateau = level.label if level is not None and level.is_box else None
        box.on_platform = level is not None and level.platform
        if lower.platform and not any(
            other.stands_on is lower for other in boxes if other is not box
        ):
            lower.platform = False


def _flush(lower: Plateau, box: Plateau, side: int, tolerance_m: float) -> bool:
    """Whether the lower top's rectangle has a side in the plane of the box's ``side``
    (+length, -length, +width, -width), turned FLUSH_DEG from it at most: within
    ``tolerance_m`` of the plane where the box's faces are read, or at the side's own middle
    (a small top's turn is poorly known; the middle of its side is sure), and a footprint
    more through noise. The box under the top may go on down that face."""
    assert lower.rect is not None and box.rect is not None

    def sides(rect: Rectangle) -> list[tuple[Float64Array, Float64Array, float]]:
        """Each side's outward normal, middle and half length."""
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        middle = np.asarray(rect.middle)
        hl, hw = rect.length_m / 2, rect.width_m / 2
        return [
            (n, middle + n * out, along)
            for n, out, along in ((ax, hl, hw), (-ax, hl, hw), (perp, hw, hl), (-perp, hw, hl))
        ]

    normal, middle, half = sides(box.rect)[side]
    if lower.tolerance_m > TOP_TOLERANCE_FLOOR_M:
        # Through noise a top's sides are good to a footprint.
        tolerance_m += lower.footprint_m
    run = np.array([-normal[1], normal[0]])
    feet = [middle + share * 2.0 * half * run for share in (faces.LINES[0], faces.LINES[-1])]
    return any(
        float(n @ normal) >= math.cos(math.radians(FLUSH_DEG))
        and (
            all(abs(float(n @ (foot - m))) <= tolerance_m for foot in feet)
            or abs(float(normal @ (m - middle))) <= tolerance_m
        )
        for n, m, _ in sides(lower.rect)
    )


SEAM_REACH_M = 0.015
"""A top at a colour seam's height that reaches out past a box's rectangle by more than this
stands beside the box; a box under it, flush, shows at most a rim round its outline."""
BESIDE_MIN_M2 = 0.0008
"""... if that much of it is seen (a rim is less)."""


def _beside(lower: Plateau, upper: Plateau, sides: tuple[tuple[float, float], ...]) -> bool:
    """Whether the lower top stands beside the upper box past one of ``sides`` (outward
    normals): a top with BESIDE_MIN_M2 or more of it seen (not the rim of a box under it),
    touching the box, whose rectangle reaches out past that side by more than SEAM_REACH_M,
    and lies against the side where the face's lines run down it (a top past a side's line
    but off to one end of it, beside another side, meets none of them)."""
    if lower.visible_m2 < BESIDE_MIN_M2 or lower.rect is None or upper.rect is None:
        return False
    if not _touch(lower, upper):
        return False
    rel = lower.rect.corners - np.asarray(upper.rect.middle)
    return any(
        float(np.max(rel @ np.array(o))) - upper.rect.half_extent(*o) > SEAM_REACH_M
        and _against(lower.rect, upper.rect, np.array(o))
        for o in sides
    )


def _against(lower: Rectangle, upper: Rectangle, normal: Float64Array) -> bool:
    """Whether ``lower`` covers a point within TOUCH_GAP_M past ``upper``'s side facing
    ``normal`` (outward), on one of the face's lines (faces.LINES along the side)."""
    run = np.array([-normal[1], normal[0]])
    middle = np.asarray(upper.middle) + normal * upper.half_extent(*normal)
    length = 2.0 * upper.half_extent(*run)
    out = np.array([0.25, 0.5, 1.0]) * TOUCH_GAP_M
    points = (
        middle
        + out[:, np.newaxis, np.newaxis] * normal
        + (faces.LINES * length)[np.newaxis, :, np.newaxis] * run
    ).reshape(-1, 2) - np.asarray(lower.middle)
    ax = np.asarray(lower.axis)
    along = np.abs(points @ ax) <= lower.length_m / 2
    across = np.abs(points @ np.array([-ax[1], ax[0]])) <= lower.width_m / 2
    return bool(np.any(along & across))


def _face_step_m(box: Plateau, sides: tuple[tuple[float, float], ...], support: Support) -> float:
    """How far down a side face of ``box`` one pixel's footprint steps, at the most over
    ``sides`` (outward normals): a footprint times the camera's height over the top by how far
    the camera stands out past the side."""
    assert box.rect is not None
    steps = [0.0]
    for o in sides:
        out = _camera_out_m(box.rect, o)
        if out > 0:
            steps.append(box.footprint_m * (support.offset_camera_m - box.height_m) / out)
    return max(steps)


FACE_TOLERANCE_M = 0.003
FACE_FOOTPRINTS = 1.5
"""How far across a side face's plane a reading may lie and still be on it: this many pixel
footprints (the rectangle's sides are good to about one), the top's height tolerance (the
noise), and at least FACE_TOLERANCE_M."""


OWN_FACE_SHARE = 1.0 / 3.0
"""A piece below a box with more than this share of its readings inside the box's rectangle is
the box's own side face: nothing under a box's top can be seen."""


def _own_faces(
    allowed: BoolArray,
    levels: list[Plateau | None],
    boxes: list[Plateau],
    height_m: Float32Array,
    labels_top: npt.NDArray[np.int32],
    lens: Intrinsics,
    support: Support,
    cam: Float64Array,
) -> None:
    """A lower piece that is no box (a strip cut out between tops) is no base of a box when
    much of it lies inside the box's rectangle: it is the box's own side face seen at a slant,
    its readings between the box's top and what stands in front (or its edge's flying pixels),
    not a level the box stands on, whose part under the box is hidden by the box itself."""
    pieces = [
        j
        for j, level in enumerate(levels)
        if level is not None and not level.is_box and allowed[j].any()
    ]
    if not pieces:
        return
    rows_n, cols_n = height_m.shape
    slope = height_slope(cols_n, rows_n, lens, support.normal_camera)
    across, down = lens.rays(cols_n, rows_n)
    where = ndimage.find_objects(labels_top)
    for j in pieces:
        level = levels[j]
        assert level is not None
        if level.label >= len(where) or where[level.label] is None:
            continue
        rs, cs = where[level.label]
        v, u = np.nonzero(labels_top[rs, cs] == level.label + 1)
        if len(v) == 0:
            continue
        v += rs.start
        u += cs.start
        d = (height_m[v, u] - support.offset_camera_m) / slope[v, u]
        xyz = np.stack([across[u] * d, down[v] * d, d])
        a, b = cam[0] @ xyz, cam[1] @ xyz
        for i in np.flatnonzero(allowed[j]):
            rect = boxes[i].rect
            assert rect is not None
            ax0, ax1 = rect.axis
            ra, rb = a - rect.middle[0], b - rect.middle[1]
            out = np.maximum(
                np.abs(ra * ax0 + rb * ax1) - rect.length_m / 2,
                np.abs(rb * ax0 - ra * ax1) - rect.width_m / 2,
            )
            if np.count_nonzero(out <= 0.0) > OWN_FACE_SHARE * len(v):
                allowed[j, i] = False


def _is_platform(lower: Plateau, upper: Plateau, carried: int) -> bool:
    """A box's base that is no box of its own: a top that goes on under the box past a hidden
    side (the box hides it), or one mostly covered by the ``carried`` boxes standing on it,
    two or more (a pallet's). A carton mostly covered by the one carton on it is a box."""
    if not lower.is_box or lower.rect is None:
        return True
    rect = lower.rect
    if carried >= 2 and lower.visible_m2 < 0.5 * rect.length_m * rect.width_m:
        return True
    return rect.hidden_sides > 0 and (
        (_reaches_under(lower, upper, slack=-0.0) and not _inside(lower, upper))
        # The box on it hides one of its sides: the top goes on under the box, how far is
        # unknown (seen as a strip beside the box).
        or (_past_hidden_side(lower, upper) and _touch(lower, upper))
    )


def _past_hidden_side(lower: Plateau, upper: Plateau) -> bool:
    """Whether the upper box's middle lies out past one of the lower top's hidden sides."""
    if lower.rect is None or upper.rect is None:
        return False
    rect = lower.rect
    rx = upper.rect.middle[0] - rect.middle[0]
    ry = upper.rect.middle[1] - rect.middle[1]
    return any(rx * o0 + ry * o1 > rect.half_extent(o0, o1) for o0, o1 in rect.hidden_normals)


def _base_rank(level: Plateau | None, box: Plateau, matches: int) -> tuple[bool, bool, int]:
    """How a level ranks as a box's base among levels at one height (see :func:`_bases`)."""
    if level is None:
        return (False, False, matches)
    holds = level.rect is not None and _inside(level, box)
    return (holds, level.is_box, matches)


def _inside(lower: Plateau, upper: Plateau) -> bool:
    assert lower.rect is not None and upper.rect is not None
    ax0, ax1 = lower.rect.axis
    rx = upper.rect.middle[0] - lower.rect.middle[0]
    ry = upper.rect.middle[1] - lower.rect.middle[1]
    return (
        abs(rx * ax0 + ry * ax1) <= lower.rect.length_m / 2
        and abs(ry * ax0 - rx * ax1) <= lower.rect.width_m / 2
    )


TOUCH_GAP_M = 0.02
"""How far apart two tops' rectangles may be and still touch (side by side)."""


def _touch(a: Plateau, b: Plateau, gap: float = TOUCH_GAP_M) -> bool:
    """Whether two tops' rectangles (grown by ``gap``) overlap: side by side, touching."""
    assert a.rect is not None and b.rect is not None
    for r, s in ((a.rect, b.rect), (b.rect, a.rect)):
        ax0, ax1 = r.axis
        for u0, u1 in ((ax0, ax1), (-ax1, ax0)):
            # Projections of the two rectangles on the axis: middle +- half extent.
            ra = abs(r.length_m * (u0 * ax0 + u1 * ax1)) + abs(r.width_m * (u1 * ax0 - u0 * ax1))
            s0, s1 = s.axis
            rb = abs(s.length_m * (u0 * s0 + u1 * s1)) + abs(s.width_m * (u1 * s0 - u0 * s1))
            dist = abs((s.middle[0] - r.middle[0]) * u0 + (s.middle[1] - r.middle[1]) * u1)
            if dist > (ra + rb) / 2 + gap:
                return False
    return True
