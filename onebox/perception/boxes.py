"""Every box in a depth picture: oriented, full size, topmost first, with stable ids in a stream.

Contract: :func:`find_boxes` takes a depth picture (H x W float32 metres; NaN, 0, negative and
inf are no reading), the lens (CameraInfo convention: the middle of pixel u is at u), the
camera's pose (optical frame -> world, 4 x 4) or None, optionally the colour picture aligned
with the depth pixel for pixel (H x W x 3 uint8), and :class:`FinderSettings`. It returns
:class:`Found`: the support plane and the boxes, highest top first, in the world frame with a
pose and in the optical frame without one ("up" is then the support normal, toward the camera).
:class:`BoxFinder` does the same for a stream, keeping the support while it still fits and
giving each box an id that stays while the box does not move. No I/O here.

How a picture is read:

1. The support (:mod:`onebox.perception.support`): the lowest large plane facing up.
2. Heights above it for every pixel, one multiply-add (``depth * slope + offset``, the slope
   cached per lens and plane); only the rows and columns holding standing pixels go further.
3. Standing pixels split into pieces at height steps and colour edges
   (:mod:`onebox.perception.segment`); each piece's flat top is the pixels within 3 sigma(z)
   (at least 1.5 mm) of its highest common height, grown back into the cut pixels.
4. Each top becomes a rectangle in the support plane (:mod:`onebox.perception.rectangle`),
   edges that something nearer hides are left out of the fit.
5. Not a box: a top touching the picture's border (cut off), smaller than ``min_top_area_m2``,
   not parallel to the support, not flat, filling less than ``min_score`` of its rectangle
   (a disc fills pi/4), or curved: loosening the height tolerance four-fold widens a curved
   top (cylinder, ball) but not a box's, whose sides drop straight down.
6. What each box stands on: the surface directly under it. Points just outside each side of
   its rectangle, at the height of each lower plateau (and of the support), are looked up in
   the picture; the highest level seen there on at least 40 % of the visible sides is what it
   stands on (another box: ``on`` is its index; a pallet or table top: that plateau). A box
   hemmed in by touching boxes takes the level of its touching neighbours; otherwise the
   highest plateau that is not a box top seen around it, else the support. The height is the
   distance from its top to that level, so cartons on a pallet are carton-sized.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.spatial.transform import Rotation

from onebox.geometry import Intrinsics
from onebox.perception import segment
from onebox.perception.rectangle import Rectangle, fit_rectangle
from onebox.perception.support import Support, fit_support, support_holds

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Vec3 = tuple[float, float, float]

TOP_TOLERANCE_FLOOR_M = 0.0015
"""The least height tolerance of a top: a renderer's depth is good to a few tenths of a mm."""
GROW_PX = 3
"""How far a top grows back into cut pixels and fragments: a colour edge cuts ~2 pixels."""
CROSS = ndimage.generate_binary_structure(2, 1)


@dataclass(frozen=True)
class FinderSettings:
    """Tolerances; those left None follow the noise measured on the support plane."""

    min_height_m: float = 0.01
    """Less than this above the surface is the surface."""
    noise_sigma_m: float | None = None
    """Depth noise; None estimates it from the support plane's residuals (growing as z^2)."""
    table_z_m: float | None = None
    """Skip the fit: the surface is the world plane z = table_z (needs a pose)."""
    max_tilt_deg: float = 15.0
    """A support plane may be this far from world up (with a pose)."""
    workspace: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] | None = None
    """World (or optical-frame) x, y, z limits of a box's top middle; nothing reported outside."""
    max_height_m: float | None = None
    """A ceiling above the surface; anything higher is ignored."""
    min_top_area_m2: float = 0.0009
    """Tops smaller than this (3 x 3 cm) are dropped: speckles, clumps, flying pixels."""
    min_score: float = 0.85
    """A top must fill this share of its rectangle (a disc fills 0.785)."""
    max_top_tilt_deg: float = 8.0
    """A box's top is parallel to the surface under it within this angle."""
    max_curvature_growth: float = 1.3
    """A top whose footprint grows more than this when the tolerance is loosened is curved."""
    colour_step: float = 28.0
    """A brightness step (0..255) between neighbours that separates two touching tops."""
    keep_cut_off: bool = False
    """Report tops cut off by the picture's border (their size is then a lower bound)."""
    match_distance_m: float = 0.02
    """BoxFinder: a box within this of last picture's box (and of a similar size) keeps its id."""


@dataclass(frozen=True)
class Box:
    """One box, in the frame of :class:`Found`."""

    centre: Vec3
    """The middle of the whole box: the top's middle less half the height along the normal."""
    quaternion_xyzw: tuple[float, float, float, float]
    """The box's axes: x along its length, z along the support normal (up)."""
    size: Vec3
    """Length, width (length >= width) and height, metres."""
    yaw_deg: float
    """The length axis's angle about world z (about the support normal without a pose), from
    the frame's x axis (the support plane's projection of it), in (-90, 90]."""
    score: float
    """0..1: the top's area over its rectangle's, times how flat the top is."""
    top_pixels: int
    top_middle: Vec3
    on: int | None = None
    """The index (in Found.boxes) of the box it stands on, if any."""
    id: int = -1
    """Stable across a stream (BoxFinder); -1 from find_boxes."""
    hidden_sides: int = 0
    """Sides of the top another object hides: the size along them is a lower bound."""


@dataclass(frozen=True)
class Found:
    """The support plane and the boxes, highest top first, all in ``frame``."""

    support: Support | None
    boxes: list[Box] = field(default_factory=list)
    frame: str = "camera"


@dataclass
class _Plateau:
    label: int
    height_m: float
    tolerance_m: float
    rows: npt.NDArray[np.intp]
    cols: npt.NDArray[np.intp]
    rect: Rectangle | None = None
    is_box: bool = False
    score: float = 0.0
    normal_c: Float64Array | None = None
    base_m: float = 0.0
    on_plateau: int | None = None
    window: tuple[slice, slice] = (slice(0, 0), slice(0, 0))
    """The piece's rows and columns in the crop (for the curvature test)."""


@functools.lru_cache(maxsize=8)
def _slope(
    width: int, height: int, lens: Intrinsics, normal: tuple[float, float, float]
) -> Float32Array:
    """Per pixel, normal . ray (ray = (across, down, 1)): height = depth * slope + offset."""
    across, down = lens.rays(width, height)
    slope = normal[0] * across[np.newaxis, :] + normal[1] * down[:, np.newaxis] + normal[2]
    result: Float32Array = slope.astype(np.float32)
    result.flags.writeable = False
    return result


def _plane_basis(support: Support, camera_to_world: Float64Array | None) -> Float64Array:
    """Rows e1, e2, n in the optical frame: e1 is the frame's x axis laid onto the plane."""
    n = np.asarray(support.normal_camera, dtype=np.float64)
    if camera_to_world is not None:
        ref = camera_to_world[:3, :3].T @ np.array([1.0, 0.0, 0.0])
        if abs(ref @ n) > 0.95:
            ref = camera_to_world[:3, :3].T @ np.array([0.0, 1.0, 0.0])
    else:
        ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.95 else np.array([0.0, 1.0, 0.0])
    e1 = ref - n * (ref @ n)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    return np.stack([e1, e2, n])


def find_boxes(
    depth_m: npt.NDArray[np.floating],
    lens: Intrinsics,
    camera_to_world: Float64Array | None,
    colour: npt.NDArray[np.uint8] | None = None,
    settings: FinderSettings = FinderSettings(),
    support: Support | None = None,
) -> Found:
    """Every box in the picture (see the module docstring); ``support`` skips the plane fit."""
    depth = np.asarray(depth_m, dtype=np.float32)
    frame = "world" if camera_to_world is not None else "camera"
    if support is None:
        support = fit_support(
            depth,
            lens,
            camera_to_world,
            max_tilt_deg=settings.max_tilt_deg,
            noise_sigma_m=settings.noise_sigma_m,
            table_z_m=settings.table_z_m,
        )
    if support is None:
        return Found(None, [], frame)
    plateaus, height_m, labels_top = _plateaus(depth, lens, colour, settings, support)
    if not plateaus:
        return Found(support, [], frame)
    basis = _plane_basis(support, camera_to_world)
    boxes = [p for p in plateaus if p.is_box]
    _bases(boxes, plateaus, height_m, labels_top, lens, support, basis, settings)
    return Found(support, _report(boxes, support, basis, camera_to_world, settings), frame)


def _plateaus(
    depth: Float32Array,
    lens: Intrinsics,
    colour: npt.NDArray[np.uint8] | None,
    settings: FinderSettings,
    support: Support,
) -> tuple[list[_Plateau], Float32Array, npt.NDArray[np.int32]]:
    rows_n, cols_n = depth.shape
    slope = _slope(cols_n, rows_n, lens, support.normal_camera)
    height = depth * slope
    height += np.float32(support.offset_camera_m)
    with np.errstate(invalid="ignore"):
        standing = (height > np.float32(settings.min_height_m)) & (depth > 0)
    labels_top = np.zeros(depth.shape, dtype=np.int32)
    row_any = np.flatnonzero(standing.any(axis=1))
    if len(row_any) == 0:
        return [], height, labels_top
    col_any = np.flatnonzero(standing.any(axis=0))
    r0, r1 = int(row_any[0]), int(row_any[-1]) + 1
    c0, c1 = int(col_any[0]), int(col_any[-1]) + 1
    # Work on the rows and columns that hold standing pixels, one pixel wider for the steps.
    r0, c0 = max(r0 - 1, 0), max(c0 - 1, 0)
    r1, c1 = min(r1 + 1, rows_n), min(c1 + 1, cols_n)
    crop = (slice(r0, r1), slice(c0, c1))
    h = height[crop]
    d = depth[crop]
    sigma = support.sigma_at(d)
    stand = standing[crop] & (h > 4.0 * sigma)
    if settings.max_height_m is not None:
        stand &= h < np.float32(settings.max_height_m)
    step = np.maximum(np.float32(4.0) * sigma, np.float32(segment.STEP_FLOOR_M))
    cut = segment.breaks(h, step)
    if colour is not None:
        cut |= segment.colour_breaks(colour[crop], settings.colour_step)
    labels, count, slices = segment.pieces(stand, cut)
    if count == 0:
        return [], height, labels_top
    across, down = lens.rays(cols_n, rows_n)
    area_scale = 1.0 / (lens.fx * lens.fy)
    # Per piece, the summed footprint area (d^2 / (fx fy |slope|)) decides which are big enough.
    flat_labels = labels.ravel()
    idx = np.flatnonzero(flat_labels)
    d_l = d.ravel()[idx]
    pixel_area = d_l * d_l * np.float32(area_scale) / np.abs(slope[crop].ravel()[idx])
    areas = np.bincount(flat_labels[idx], weights=pixel_area, minlength=count + 1)
    plateaus: list[_Plateau] = []
    lab_top = labels_top[crop]
    # Small pieces (a carton's darker rim cut off by a colour edge, a clump) may be taken over
    # by the large top beside them at the same height; large pieces go first.
    fragment = areas < settings.min_top_area_m2
    fragment[0] = True
    big = np.flatnonzero(areas >= 0.5 * settings.min_top_area_m2)
    for label in big[np.argsort(-areas[big])]:
        sl = slices[label - 1]
        if sl is None:
            continue
        plateau = _top(int(label), sl, labels, h, stand, sigma, lab_top, fragment, (r0, c0))
        if plateau is None:
            continue
        _measure(plateau, depth, slope, across, down, lens, support, settings, labels, h, crop)
        plateaus.append(plateau)
    return plateaus, height, labels_top


def _top(
    label: int,
    sl: tuple[slice, slice],
    labels: npt.NDArray[np.int32],
    h: Float32Array,
    stand: BoolArray,
    sigma: Float32Array,
    lab_top: npt.NDArray[np.int32],
    fragment: BoolArray,
    place: tuple[int, int],
) -> _Plateau | None:
    """The flat top of one piece: pixels near its highest common height, grown into cuts."""
    pad = GROW_PX
    rows, cols = labels.shape
    a0, a1 = max(sl[0].start - pad, 0), min(sl[0].stop + pad, rows)
    b0, b1 = max(sl[1].start - pad, 0), min(sl[1].stop + pad, cols)
    win = (slice(a0, a1), slice(b0, b1))
    mine = labels[win] == label
    hh = h[win]
    values = hh[mine]
    sig = float(np.median(sigma[win][mine]))
    tol = max(3.0 * sig, TOP_TOLERANCE_FLOOR_M)
    ref = float(np.quantile(values, 0.9))
    near = np.abs(values - ref) < tol
    top_height = float(np.median(values[near]))
    with np.errstate(invalid="ignore"):
        level = np.abs(hh - np.float32(top_height)) < np.float32(tol)
    top = mine & level
    free = stand[win] & level & (fragment[labels[win]] | mine) & (lab_top[win] == 0)
    top = ndimage.binary_dilation(top, CROSS, iterations=GROW_PX, mask=free | top)
    # The largest connected part is the top; noise may leave a few specks apart from it.
    parts, n_parts = ndimage.label(top)
    if n_parts > 1:
        sizes = np.bincount(parts.ravel())
        sizes[0] = 0
        top = parts == int(sizes.argmax())
    r, c = np.nonzero(top)
    if len(r) < 6:
        return None
    lab_top[win][top] = label
    r0, c0 = place
    return _Plateau(label, top_height, tol, r + a0 + r0, c + b0 + c0, window=win)


def _measure(
    p: _Plateau,
    depth: Float32Array,
    slope: Float32Array,
    across: Float64Array,
    down: Float64Array,
    lens: Intrinsics,
    support: Support,
    settings: FinderSettings,
    labels: npt.NDArray[np.int32],
    h: Float32Array,
    crop: tuple[slice, slice],
) -> None:
    """Fit the top's plane and rectangle and decide whether it is a box."""
    rows_n, cols_n = depth.shape
    d = depth[p.rows, p.cols].astype(np.float64)
    pts = np.stack([across[p.cols] * d, down[p.rows] * d, d], axis=1)
    pixel_area = d * d / (lens.fx * lens.fy * np.abs(slope[p.rows, p.cols].astype(np.float64)))
    area = float(pixel_area.sum())
    if area < settings.min_top_area_m2:
        return
    centre = pts.mean(axis=0)
    values, vectors = np.linalg.eigh(np.cov((pts - centre).T))
    normal_c = vectors[:, 0] * (1.0 if vectors[2, 0] < 0 else -1.0)
    rms = math.sqrt(max(float(values[0]), 0.0))
    p.normal_c = normal_c
    n = np.asarray(support.normal_camera)
    # Outline: top pixels with a 4-neighbour off the top. Hidden: that neighbour is nearer.
    r0 = int(p.rows.min())
    c0 = int(p.cols.min())
    mask = np.zeros((int(p.rows.max()) - r0 + 3, int(p.cols.max()) - c0 + 3), dtype=bool)
    mask[p.rows - r0 + 1, p.cols - c0 + 1] = True
    # Holes inside a top (noise, or a box standing on it) are not its outline, and a box
    # standing on it hides part of its area.
    filled = ndimage.binary_fill_holes(mask)
    inner = ndimage.binary_erosion(filled, CROSS)
    area += float(np.count_nonzero(filled & ~mask)) * float(np.median(pixel_area))
    outline = mask[p.rows - r0 + 1, p.cols - c0 + 1] & ~inner[p.rows - r0 + 1, p.cols - c0 + 1]
    hidden = np.zeros(len(d), dtype=bool)
    cut_off = False
    occluder_m = max(3.0 * p.tolerance_m, 0.005)
    for dr, dc in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        nr, nc = p.rows + dr, p.cols + dc
        inside = (nr >= 0) & (nr < rows_n) & (nc >= 0) & (nc < cols_n)
        cut_off |= bool((~inside).any())
        nr, nc = np.clip(nr, 0, rows_n - 1), np.clip(nc, 0, cols_n - 1)
        off_top = ~mask[nr - r0 + 1, nc - c0 + 1]
        with np.errstate(invalid="ignore"):
            nearer = depth[nr, nc] < d - occluder_m
        hidden |= outline & inside & off_top & nearer
    if cut_off and not settings.keep_cut_off:
        return
    basis = _plane_basis(support, None)
    flat = np.stack([pts @ basis[0], pts @ basis[1]], axis=1)
    rect = fit_rectangle(flat, outline, hidden, pixel_area, area)
    if rect is None or rect.length_m <= 0 or rect.width_m <= 0:
        return
    p.rect = rect
    # The fill is taken against the extreme pixels (plus a footprint), not the fitted sides: a
    # disc's sides fitted by medians would hug it.
    footprint = math.sqrt(float(np.median(pixel_area)))
    ax = np.asarray(rect.axis)
    perp = np.array([-ax[1], ax[0]])
    rect_area = (np.ptp(flat @ ax) + footprint) * (np.ptp(flat @ perp) + footprint)
    fill = min(area / rect_area, 1.0)
    flatness = max(0.0, 1.0 - max(rms - 1.5 * p.tolerance_m / 3.0, 0.0) / p.tolerance_m)
    p.score = fill * flatness
    tilt = math.degrees(math.acos(min(1.0, abs(float(normal_c @ n)))))
    if tilt > settings.max_top_tilt_deg or p.score < settings.min_score:
        return
    # Curved tops widen when the tolerance is loosened; a box's sides drop straight down.
    win_r, win_c = p.window
    with np.errstate(invalid="ignore"):
        loose = (labels[p.window] == p.label) & (
            h[p.window] > np.float32(p.height_m - 4.0 * p.tolerance_m)
        )
    lr, lc = np.nonzero(loose)
    lr = lr + win_r.start + crop[0].start
    lc = lc + win_c.start + crop[1].start
    if len(lr) > len(d):
        dl = depth[lr, lc].astype(np.float64)
        lp = np.stack([across[lc] * dl, down[lr] * dl, dl], axis=1)
        loose_flat = np.stack([lp @ basis[0], lp @ basis[1]], axis=1)
        growth = (_spread(loose_flat @ ax) * _spread(loose_flat @ perp)) / max(
            _spread(flat @ ax) * _spread(flat @ perp), 1e-12
        )
        if growth > settings.max_curvature_growth:
            return
    p.is_box = True


def _spread(values: Float64Array) -> float:
    low, high = np.percentile(values, [1.0, 99.0])
    return float(high - low)


def _bases(
    boxes: list[_Plateau],
    plateaus: list[_Plateau],
    height_m: Float32Array,
    labels_top: npt.NDArray[np.int32],
    lens: Intrinsics,
    support: Support,
    basis: Float64Array,
    settings: FinderSettings,
) -> None:
    """What each box stands on (see the module docstring, step 6)."""
    rows_n, cols_n = height_m.shape
    n = basis[2]
    camera_basis = _plane_basis(support, None)
    levels = sorted({0.0, *(p.height_m for p in plateaus)})
    box_levels = {round(b.height_m, 4) for b in boxes}
    undecided: list[_Plateau] = []
    seen_other: dict[int, float] = {}
    for box in boxes:
        assert box.rect is not None
        rect = box.rect
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        mid = np.asarray(rect.middle)
        reach = max(0.008, 3.0 * math.sqrt(rect.area_m2 / max(len(box.rows), 1)))
        fractions = np.linspace(-0.4, 0.4, 5)
        samples = []
        for direction, half, along, half_along in (
            (ax, rect.length_m / 2, perp, rect.width_m / 2),
            (-ax, rect.length_m / 2, perp, rect.width_m / 2),
            (perp, rect.width_m / 2, ax, rect.length_m / 2),
            (-perp, rect.width_m / 2, ax, rect.length_m / 2),
        ):
            for f in fractions:
                samples.append(mid + direction * (half + reach) + along * (2 * f * half_along))
        flat = np.asarray(samples)
        best: float | None = None
        other_best: float | None = None
        for level in levels:
            if level > box.height_m - settings.min_height_m:
                break
            # Camera-frame points at this level: a e1 + b e2 + (level - offset) n.
            pts = (
                flat[:, :1] * camera_basis[0]
                + flat[:, 1:] * camera_basis[1]
                + (level - support.offset_camera_m) * n
            )
            z = pts[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                u = np.rint(lens.fx * pts[:, 0] / z + lens.cx)
                v = np.rint(lens.fy * pts[:, 1] / z + lens.cy)
            inside = (z > 0) & (u >= 0) & (u < cols_n) & (v >= 0) & (v < rows_n)
            ui, vi = u[inside].astype(np.intp), v[inside].astype(np.intp)
            seen_h = height_m[vi, ui]
            known = np.isfinite(seen_h) & (labels_top[vi, ui] != box.label)
            if known.sum() < 3:
                continue
            tol = max(3.0 * box.tolerance_m, 0.004)
            share = float((np.abs(seen_h[known] - level) < tol).mean())
            if share >= 0.4:
                best = level
            if share >= 0.1 and round(level, 4) not in box_levels and level > 0:
                other_best = level
        if best is not None:
            box.base_m = best
        else:
            undecided.append(box)
            if other_best is not None:
                seen_other[box.label] = other_best
    # A box hemmed in by touching boxes stands where they stand.
    decided = [b for b in boxes if b not in undecided]
    for _ in range(3):
        still = []
        for box in undecided:
            assert box.rect is not None
            neighbour = next(
                (
                    o
                    for o in decided
                    if o.base_m < box.height_m - settings.min_height_m and _touch(box, o)
                ),
                None,
            )
            if neighbour is None:
                still.append(box)
            else:
                box.base_m = neighbour.base_m
                decided.append(box)
        if len(still) == len(undecided):
            break
        undecided = still
    for box in undecided:
        box.base_m = seen_other.get(box.label, 0.0)
    for box in boxes:
        if box.base_m <= 0.0:
            continue
        under = [
            o
            for o in boxes
            if o is not box and abs(o.height_m - box.base_m) < 1e-9 and _contains(o, box)
        ]
        if under:
            box.on_plateau = under[0].label


def _touch(a: _Plateau, b: _Plateau) -> bool:
    """Whether two tops' rectangles (grown by 2 cm) overlap: side by side, touching."""
    assert a.rect is not None and b.rect is not None
    gap = 0.02
    for r, s in ((a.rect, b.rect), (b.rect, a.rect)):
        ax = np.asarray(r.axis)
        for axis in (ax, np.array([-ax[1], ax[0]])):
            pa = r.corners @ axis
            pb = s.corners @ axis
            if pa.max() + gap < pb.min() or pb.max() + gap < pa.min():
                return False
    return True


def _contains(lower: _Plateau, upper: _Plateau) -> bool:
    """Whether the upper top's middle is over the lower top's rectangle (1 cm slack)."""
    assert lower.rect is not None and upper.rect is not None
    ax = np.asarray(lower.rect.axis)
    rel = np.asarray(upper.rect.middle) - np.asarray(lower.rect.middle)
    return bool(
        abs(rel @ ax) <= lower.rect.length_m / 2 + 0.01
        and abs(rel @ np.array([-ax[1], ax[0]])) <= lower.rect.width_m / 2 + 0.01
    )


def _report(
    boxes: list[_Plateau],
    support: Support,
    basis: Float64Array,
    camera_to_world: Float64Array | None,
    settings: FinderSettings,
) -> list[Box]:
    cam_basis = _plane_basis(support, None)
    n_c = cam_basis[2]
    rotation = camera_to_world[:3, :3] if camera_to_world is not None else np.eye(3)
    shift = camera_to_world[:3, 3] if camera_to_world is not None else np.zeros(3)
    ordered = sorted(boxes, key=lambda b: -b.height_m)
    index = {b.label: i for i, b in enumerate(ordered)}
    result: list[Box] = []
    for b in ordered:
        assert b.rect is not None
        rect = b.rect
        top_c = (
            rect.middle[0] * cam_basis[0]
            + rect.middle[1] * cam_basis[1]
            + (b.height_m - support.offset_camera_m) * n_c
        )
        height = b.height_m - b.base_m
        centre_c = top_c - 0.5 * height * n_c
        length_c = rect.axis[0] * cam_basis[0] + rect.axis[1] * cam_basis[1]
        x_axis = rotation @ length_c
        z_axis = rotation @ n_c
        y_axis = np.cross(z_axis, x_axis)
        top = rotation @ top_c + shift
        centre = rotation @ centre_c + shift
        if settings.workspace is not None and not all(
            lo <= value <= hi for value, (lo, hi) in zip(top, settings.workspace, strict=True)
        ):
            continue
        reference = basis[0]
        yaw = math.degrees(
            math.atan2(float(length_c @ np.cross(n_c, reference)), float(length_c @ reference))
        )
        if camera_to_world is not None:
            yaw = math.degrees(math.atan2(float(x_axis[1]), float(x_axis[0])))
        yaw = (yaw + 90.0) % 180.0 - 90.0
        if yaw == -90.0:
            yaw = 90.0
        quaternion = Rotation.from_matrix(np.stack([x_axis, y_axis, z_axis], axis=1)).as_quat()
        result.append(
            Box(
                centre=_vec(centre),
                quaternion_xyzw=(
                    float(quaternion[0]),
                    float(quaternion[1]),
                    float(quaternion[2]),
                    float(quaternion[3]),
                ),
                size=(rect.length_m, rect.width_m, height),
                yaw_deg=yaw,
                score=b.score,
                top_pixels=len(b.rows),
                top_middle=_vec(top),
                on=index.get(b.on_plateau) if b.on_plateau is not None else None,
                hidden_sides=rect.hidden_sides,
            )
        )
    if len(result) != len(ordered):
        # The workspace dropped some: "on" must index the list as reported.
        kept = {id(r) for r in result}
        del kept
        result = [replace(r, on=None) for r in result]
    return result


def _vec(v: Float64Array) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


class BoxFinder:
    """:func:`find_boxes` for a stream: keeps the support while the camera does not move and it
    still fits (checked on the grid sample), and gives each box a stable ``id``."""

    def __init__(self, settings: FinderSettings = FinderSettings()) -> None:
        self.settings = settings
        self._support: Support | None = None
        self._pose: Float64Array | None = None
        self._lens: Intrinsics | None = None
        self._last: list[Box] = []
        self._next_id = 0
        self.refits = 0

    def __call__(
        self,
        depth_m: npt.NDArray[np.floating],
        lens: Intrinsics,
        camera_to_world: Float64Array | None,
        colour: npt.NDArray[np.uint8] | None = None,
    ) -> Found:
        depth = np.asarray(depth_m, dtype=np.float32)
        same_pose = (self._pose is None and camera_to_world is None) or (
            self._pose is not None
            and camera_to_world is not None
            and np.allclose(self._pose, camera_to_world, atol=1e-6)
        )
        support = self._support
        if (
            support is None
            or not same_pose
            or lens != self._lens
            or not support_holds(depth, lens, support)
        ):
            support = fit_support(
                depth,
                lens,
                camera_to_world,
                max_tilt_deg=self.settings.max_tilt_deg,
                noise_sigma_m=self.settings.noise_sigma_m,
                table_z_m=self.settings.table_z_m,
            )
            self.refits += 1
        self._support, self._lens = support, lens
        self._pose = None if camera_to_world is None else np.array(camera_to_world, copy=True)
        if support is None:
            self._last = []
            return Found(None, [], "world" if camera_to_world is not None else "camera")
        found = find_boxes(depth, lens, camera_to_world, colour, self.settings, support)
        boxes = self._identify(found.boxes)
        return Found(found.support, boxes, found.frame)

    def _identify(self, boxes: list[Box]) -> list[Box]:
        taken: set[int] = set()
        result = []
        for box in boxes:
            best, best_distance = None, self.settings.match_distance_m
            for old in self._last:
                if old.id in taken:
                    continue
                distance = math.dist(old.centre, box.centre)
                similar = all(
                    abs(a - b) < max(0.02, 0.2 * b) for a, b in zip(old.size, box.size, strict=True)
                )
                if similar and distance <= best_distance:
                    best, best_distance = old, distance
            if best is None:
                ident = self._next_id
                self._next_id += 1
            else:
                ident = best.id
            taken.add(ident)
            result.append(replace(box, id=ident))
        self._last = result
        return result
