"""Every box in a depth picture: oriented, full size, topmost first, with stable ids in a stream.

Contract: :func:`find_boxes` takes a depth picture (H x W float32 metres; NaN, 0, negative and
inf are no reading), the lens (CameraInfo convention: the middle of pixel u is at u), the
camera's pose (optical frame -> world, 4 x 4) or None, optionally the colour picture aligned
with the depth pixel for pixel (H x W x 3 uint8), and :class:`FinderSettings`. It returns
:class:`Found`: the support plane and the boxes, highest top first, in the world frame with a
pose and in the optical frame without one ("up" is then the support normal, toward the camera).
:class:`BoxFinder` does the same for a stream, keeping the support while it still fits and
giving each box an id that stays while the box does not move. No I/O here.

How a picture is read (whole-array work; Python loops only over tops, a few scalars each):

0. Pictures larger than ``max_pixels`` (default 640 x 480) are read at every k-th pixel, the
   lens scaled exactly (1280 x 720 is read as 640 x 360).
1. The support (:mod:`onebox.perception.support`): the lowest large plane facing up.
2. Heights above it for every pixel, one multiply-add (``depth * slope + offset``, the slope
   cached per lens and plane); only the rows and columns holding standing pixels go further.
3. Standing pixels split into pieces at height steps and colour edges
   (:mod:`onebox.perception.segment`). Every piece's top height at once: the fullest window of
   a per-piece height histogram (window = the tolerance, 3 sigma(z), at least 1.5 mm), then the
   mean of the readings within the tolerance. The top is the readings within 4 mm of that
   (``FLAT_REACH_M``, or the tolerance if more: a carton's lid bulges or sags). Tops grow back
   into cut pixels and small pieces at their height (3 pixels, the larger top first), and
   across bands (a seam's line cut out by colour edges on both sides, under ~1 cm wide) until
   they meet in the band's middle.
4. All tops measured together from their grouped pixels: area (holes filled by each row's and
   column's span), the top's plane (moments on a sample), the outline and, for each outline
   pixel, what lies past it: rising (hidden by something standing on or in front of the top,
   also when first seen past a band of no reading), dropping (a real edge) or no reading
   (dropout). Every rectangle is fitted in one batched
   pass (:func:`onebox.perception.rectangle.fit_rectangles`). A top that straight lines of
   colour edges or of dark valleys a few pixels wide (a seam's shadow, with no step between
   neighbours as large as an edge's) cross from side to side, parallel to its rectangle's
   sides and at least 3 cm from either end, with the top going on past them in one shade on
   both sides along 80 % of them, is cartons of one shade: it splits at every such line at
   once (rows and columns), each connected part at its own height, and the tops are measured
   again (a second look finds a seam that crosses one part only).
5. Not a box: a top touching the picture's border (cut off), smaller than ``min_top_area_m2``
   (or (3 sigma)^2 where the depth is noisy), seen narrower than 1 cm, not parallel to the
   support (a top narrower than its noise: by its plane along the rays, if it stands free),
   not flat, filling less than ``min_score`` of its rectangle (a disc fills pi/4;
   under noise of 3 mm or more, a top seen whole by its hull; where a taller object in front
   hides part of the rectangle, of the part seen, if every side is seen along part of it and
   the outline seen hugs the sides), or curved:
   loosening the height tolerance four-fold widens a curved top (cylinder, ball) but not a
   box's, whose sides drop straight down.
6. What each box stands on. Lines of probe points go out from each side at the height of each
   lower level (the support and every lower top); along each line the first surface seen (not
   the box itself, nothing higher in front) says whether the level is there or lower. A level
   counts when seen on two probes with hardly anything lower seen, or on two opposite sides;
   the box's own ledge (a rim just past its outline) counts with less, and when seen on every
   line of one side with no top at its height (a box underneath, overhung on the other sides);
   a lower top counts only if it reaches under the box (its rectangle holds the box's middle,
   it is no box, or the box lies past one of its hidden sides), unless the box meets one of
   its sides end to end, the top goes out from it as far as a carton and the box would be a
   slab on it: the next carton of a row, a little lower (a carton's top that the box on it
   keeps from being a box too); a piece that is no box and
   lies largely inside the box's rectangle is the box's own side face seen at a slant (nothing
   under a box's top is seen), never its base. The highest such level is the base (of tops
   at its height, the one whose rectangle holds the box's middle); a box that sees none takes
   the base most of its touching neighbours have. A box left on the support seen past one
   side only (or by its neighbours) takes the higher base of a touching box of its height,
   when a level there that is no box's top may reach under it: past a load's edge the floor
   is seen, the pallet's rim there out of sight or lost in the dropout. A box still without
   a base stands on the platform it stands over, else the support. A top that boxes stand on
   past its hidden side,
   or that is mostly covered, is a platform (a pallet's top): a level, never reported as a
   box; so is a top walled in on two sides or more at the height two touching boxes stand
   at (the pallet seen where a carton is missing). On a platform, a side in the shadow of a
   taller carton between it and the camera runs halfway into the shadow (packed cartons
   touch; the shadow's middle is never off by more than half of it).
   A top with a hidden side that something standing well off it (a taller object in front)
   may hide by more than half its seen extent is left out: its size is unknown.
   Then each box's side faces (:mod:`onebox.perception.faces`): faces that end well above
   the base raise it to the level between where they are last seen and where the camera sees
   under the box (or to their bottom, when no level is there: a box over one it hides), and a
   top that box hides a side of becomes a level. Faces running flush down onto a box of
   nearly the same footprint end where their colour changes, level across the face, unless a
   top at that height reaches out past that side (a box beside, whose top meets the face).
   A box taken to stand on a box's top whose face is seen going on down past that top, on a
   side the lower box has no face in the plane of (and the lower top cannot go on under the
   box that way), stands beside it, lower: on the highest level under where the face is seen.
7. The height is the top's distance from its base; the centre is the rectangle's middle less
   half the height along the normal.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy import ndimage, spatial

from onebox.geometry import Intrinsics
from onebox.perception import faces, segment
from onebox.perception.rectangle import Rectangle, fit_rectangles
from onebox.perception.support import SIGMA_FLOOR_M, Support, fit_support, support_holds

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Vec3 = tuple[float, float, float]

TOP_TOLERANCE_FLOOR_M = 0.0015
"""The least height tolerance of a top: a renderer's depth is good to a few tenths of a mm."""
FLAT_REACH_M = 0.004
"""How far from its level a reading still belongs to a top (at least the tolerance): a real
carton's lid bulges or sags by several millimetres, smoothly (steps between neighbours still
split objects), and the top is all of it; its level is still measured within the tolerance."""
GROW_PX = 3
"""How far a top grows back into cut pixels and fragments: a colour edge cuts ~2 pixels."""
BAND_M = 0.005
"""A piece between colour edges narrower than about twice this is a band (a seam's line),
not a top: the tops beside it at its height grow across it and meet in its middle."""
BAND_MAX_PX = 6
MIN_WIDTH_M = 0.01
"""A top seen narrower than this is a sliver (the strip of a box showing past a taller one's
foot, a line of flying pixels), not a box: its rectangle says nothing of a box's size."""
NOISY_TOP_AREA_M2 = 0.0009
"""Where depth is noisy (sigma 1 cm and more: a D435 past 1.5 m), a top must be 3 x 3 cm: a
smaller one's plane is a noise clump's, and taken as a box's base it cut tall boxes short."""
"""The widest band, in pixels on either side of its middle line."""
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
RISING_SHARE = 0.02
"""A top narrower than its noise is read along the rays only if less than this share of its
outline sees the surface rise past a band with no reading (a pallet's margin, cartons on it)."""
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
    min_top_area_m2: float = 0.0004
    """Tops smaller than this (2 x 2 cm) are dropped: speckles, clumps, flying pixels; where the
    depth is noisy, smaller than (3 sigma)^2 too, up to ``NOISY_TOP_AREA_M2``."""
    min_score: float = 0.85
    """A top must fill this share of its rectangle (a disc fills 0.785)."""
    max_top_tilt_deg: float = 8.0
    """A box's top is parallel to the surface under it within this angle."""
    max_curvature_growth: float = 1.3
    """A top whose footprint grows more than this when the tolerance is loosened is curved."""
    colour_step: float = 12.0
    """A brightness step (0..255) between neighbours that separates two touching tops."""
    keep_cut_off: bool = False
    """Report tops cut off by the picture's border (their size is then a lower bound)."""
    match_distance_m: float = 0.02
    """BoxFinder: a box within this of last picture's box (and of a similar size) keeps its id."""
    max_pixels: int | None = 640 * 480
    """Larger pictures are read at every k-th pixel (k = 2 for 1280 x 720) to keep camera rate;
    sizes are then good to that coarser footprint. None reads every pixel."""


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


PAD = 12
"""Empty pixels around the working crop, so looking twelve pixels past a top never wraps."""
NEIGHBOURS = 4


@dataclass
class _Plateau:
    label: int
    """Index among the picture's tops; ``labels_top`` holds label + 1."""
    height_m: float
    tolerance_m: float
    pixels: int
    footprint_m: float
    visible_m2: float
    rect: Rectangle | None = None
    is_box: bool = False
    score: float = 0.0
    base_m: float = 0.0
    on_plateau: int | None = None
    stands_on: _Plateau | None = None
    """The top it stands on (None: the support, or a ledge of its own with no top)."""
    platform: bool = False
    """A level others stand on whose own extent is hidden (a pallet's top): never a box."""
    on_platform: bool = False
    """Stands on a platform (a pallet's top), where cartons stand packed side by side."""
    ledge_m: float | None = None
    """The highest flat level seen just past the top's outline (see :func:`_ledges`)."""
    hidden_band_m: float = 0.0
    """How far, along the support, what rises past the top's hidden outline stands off it
    (median over the hidden outline): a wall rising at the top's edge stands at it, a taller
    object in front of the top hides a band this wide of it."""


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
    e2 = _cross(n, e1)
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
    stride = _stride(depth.shape, settings.max_pixels)
    if stride > 1:
        # Pixel k * u' is pixel u' of the coarse picture: its ray is unchanged, so the lens
        # scales exactly (middle of pixel u at u: cx / k, not (cx + 0.5) / k - 0.5).
        depth = depth[::stride, ::stride]
        colour = None if colour is None else colour[::stride, ::stride]
        lens = Intrinsics(lens.fx / stride, lens.fy / stride, lens.cx / stride, lens.cy / stride)
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
    _bases(boxes, plateaus, height_m, labels_top, lens, support, settings)
    _raise_to_faces(boxes, plateaus, depth, colour, lens, support, settings)
    _shadowed_sides(boxes, support.offset_camera_m, settings)
    reported = [
        b
        for b in boxes
        if not b.platform
        and not _extent_unknown(b)
        and b.rect is not None
        and b.rect.width_m >= MIN_WIDTH_M
    ]
    return Found(support, _report(reported, support, basis, camera_to_world, settings), frame)


def _least_top_area(sigma_m: npt.ArrayLike, settings: FinderSettings) -> Float64Array:
    """The smallest top kept where the noise is ``sigma_m``: ``min_top_area_m2`` where depth is
    clean, (3 sigma)^2 where that is more, up to ``NOISY_TOP_AREA_M2``."""
    low = settings.min_top_area_m2
    noisy = (3.0 * np.asarray(sigma_m, dtype=np.float64)) ** 2
    result: Float64Array = np.clip(noisy, low, max(low, NOISY_TOP_AREA_M2))
    return result


def _stride(shape: tuple[int, ...], max_pixels: int | None) -> int:
    """Every how many pixels a picture is read (1: all)."""
    if max_pixels is None or shape[0] * shape[1] <= max_pixels:
        return 1
    return math.ceil(math.sqrt(shape[0] * shape[1] / max_pixels))


def _crop(standing: BoolArray) -> tuple[slice, slice] | None:
    """The rows and columns holding standing pixels, one pixel wider for the steps."""
    row_any = np.flatnonzero(standing.any(axis=1))
    if len(row_any) == 0:
        return None
    col_any = np.flatnonzero(standing.any(axis=0))
    rows_n, cols_n = standing.shape
    r0, r1 = max(int(row_any[0]) - 1, 0), min(int(row_any[-1]) + 2, rows_n)
    c0, c1 = max(int(col_any[0]) - 1, 0), min(int(col_any[-1]) + 2, cols_n)
    return slice(r0, r1), slice(c0, c1)


def _plateaus(
    depth: Float32Array,
    lens: Intrinsics,
    colour: npt.NDArray[np.uint8] | None,
    settings: FinderSettings,
    support: Support,
) -> tuple[list[_Plateau], Float32Array, npt.NDArray[np.int32]]:
    """Every flat top, measured together: whole-array work on the crop, then one short
    rectangle fit per top."""
    rows_n, cols_n = depth.shape
    slope = _slope(cols_n, rows_n, lens, support.normal_camera)
    height = depth * slope
    height += np.float32(support.offset_camera_m)
    with np.errstate(invalid="ignore"):
        standing = (height > np.float32(settings.min_height_m)) & (depth > 0)
    labels_top = np.zeros(depth.shape, dtype=np.int32)
    crop = _crop(standing)
    if crop is None:
        return [], height, labels_top
    r0, c0 = crop[0].start, crop[1].start
    pad = ((PAD, PAD), (PAD, PAD))
    h = np.pad(height[crop], pad, constant_values=np.nan)
    d = np.pad(depth[crop], pad, constant_values=np.nan)
    width_p = h.shape[1]
    # Noise grows as distance squared from the support's figure at its distance; while it
    # stays small everywhere the thresholds are single figures (no noise picture at all).
    noise_k = np.float32(support.sigma_m / support.distance_m**2)
    far = float(np.nanmax(d))
    if 4.0 * max(float(noise_k) * far * far, SIGMA_FLOOR_M) <= min(
        settings.min_height_m, segment.STEP_FLOOR_M
    ):
        stand = np.pad(standing[crop], pad)
        step: Float32Array | np.float32 = np.float32(segment.STEP_FLOOR_M)
    else:
        with np.errstate(invalid="ignore"):
            sigma4 = np.maximum(d * d * noise_k, np.float32(SIGMA_FLOOR_M)) * np.float32(4.0)
            stand = h > np.maximum(sigma4, np.float32(settings.min_height_m))
        step = np.maximum(sigma4, np.float32(segment.STEP_FLOOR_M))
    if settings.max_height_m is not None:
        with np.errstate(invalid="ignore"):
            stand &= h < np.float32(settings.max_height_m)
    cut = segment.breaks(h, step)
    colour_cut: BoolArray | None = None
    grey = None
    if colour is not None:
        grey = segment.grey(colour[crop])
        colour_cut = np.pad(segment.colour_breaks(grey, settings.colour_step), pad)
        cut |= colour_cut
        grey = np.pad(grey, pad, mode="edge")
    labels, count = ndimage.label(stand & ~cut)
    if count == 0:
        return [], height, labels_top
    h_flat, d_flat, s_flat = h.reshape(-1), d.reshape(-1), np.pad(slope[crop], pad, "edge")
    s_flat = s_flat.reshape(-1)
    flat = labels.reshape(-1)
    idx = np.flatnonzero(flat)
    lab = flat[idx]
    dd = d_flat[idx]
    area_scale = np.float32(1.0 / (lens.fx * lens.fy))
    areas = np.bincount(
        lab, weights=dd * dd * area_scale / np.abs(s_flat[idx]), minlength=count + 1
    )
    areas[0] = 0.0
    # Pieces too small to be a top (a carton's rim cut off by a colour edge, a clump, the cut
    # pixels themselves) may be taken over by the top beside them at the same height.
    least = 0.5 * float(_least_top_area(support.sigma_m, settings))
    big = np.flatnonzero(areas >= least)
    if len(big) == 0:
        return [], height, labels_top
    big = big[np.argsort(-areas[big], kind="stable")]
    tops_n = len(big)
    lut = np.zeros(count + 1, dtype=np.int32)
    lut[big] = np.arange(1, tops_n + 1, dtype=np.int32)
    compact = lut[lab]
    mine = compact > 0
    p_idx, p_top = idx[mine], compact[mine] - 1
    p_h, p_d = h_flat[p_idx], dd[mine]
    counts = np.bincount(p_top, minlength=tops_n)
    mean_d = np.bincount(p_top, weights=p_d, minlength=tops_n) / counts
    tol = np.maximum(
        3.0 * np.maximum(noise_k * mean_d * mean_d, SIGMA_FLOOR_M), TOP_TOLERANCE_FLOOR_M
    )
    level = _levels(p_h, p_top, tops_n, tol)
    reach = np.maximum(tol, FLAT_REACH_M)
    on_level = np.abs(p_h - level[p_top]) < reach[p_top]
    top_lab = np.zeros(h.shape, dtype=np.int32)
    top_flat = top_lab.reshape(-1)
    small = np.zeros(count + 1, dtype=bool)
    small[1:] = areas[1:] < least
    candidates = np.concatenate([np.flatnonzero(stand.reshape(-1) & (flat == 0)), idx[small[lab]]])
    band = np.zeros(tops_n, dtype=bool)
    ring = np.zeros(tops_n, dtype=bool)
    if colour_cut is not None:
        pixels = np.bincount(lab, minlength=count + 1)
        band, ring = _bands(
            labels,
            h,
            d,
            big,
            pixels,
            float(np.nanmin(d)) / lens.fx,
            lens,
            support,
            (r0 - PAD, c0 - PAD),
        )
    in_band = band[p_top]
    seated = on_level & ~in_band
    top_flat[p_idx[seated]] = p_top[seated] + 1
    # Cut pixels just under a top are its side faces' first pixels: in clean depth the top
    # grows into none of them (its outline would widen by a pixel); under noise they cannot be
    # told from a lid's rim dipping under the level, and the lid wins.
    below = np.where(tol > TOP_TOLERANCE_FLOOR_M, reach, tol)
    _grow(top_flat, candidates, h_flat, level, below, width_p, p_idx[in_band], reach)
    if band.any():
        # A band no top at its height reaches is an object of its own (a narrow box).
        taken = np.bincount(p_top[in_band], weights=top_flat[p_idx[in_band]] > 0, minlength=tops_n)
        alone = band & (taken == 0)
        back = alone[p_top] & on_level
        top_flat[p_idx[back]] = p_top[back] + 1
        if (alone & ~ring).any():
            # ... and one that runs round no other top grows back into its own cut pixels
            # (those of a narrow top seen at a slant, a few pixels high between the colour
            # edges of its rims; a ring of seams round cartons would fill in); no other top
            # grows again.
            own_level = np.where(alone & ~ring, level, np.nan)
            rest = candidates[top_flat[candidates] == 0]
            _grow(top_flat, rest, h_flat, own_level, below, width_p, None, reach)
    # Measured, then looked over for seams between cartons of one shade (colour only), split
    # and measured again.
    for look in range(SEAM_ROUNDS + 1):
        tops = _Tops.gather(top_lab, tops_n, PAD, (r0, c0))
        plateaus = _measure_all(
            tops,
            top_flat,
            h_flat,
            d_flat,
            s_flat,
            level,
            tol,
            p_idx,
            p_top,
            p_h,
            lens,
            support,
            settings,
            depth.shape,
        )
        if look == SEAM_ROUNDS or colour_cut is None or grey is None:
            break
        cells = _seams(
            plateaus,
            tops,
            s_flat,
            colour_cut.reshape(-1),
            grey.reshape(-1),
            settings.colour_step,
            lens,
            support,
            depth.shape,
        )
        if not cells:
            break
        level, tol, tops_n = _split_tops(top_flat, tops, cells, level, tol, h_flat, p_idx, p_top)
    labels_top[crop] = top_lab[PAD:-PAD, PAD:-PAD]
    return plateaus, height, labels_top


@dataclass(frozen=True)
class _Windows:
    """Per group a histogram of heights, in bins of a third of the least tolerance, summed over
    a window of +-tol (the group's) around each bin."""

    counts: Float64Array
    """(groups, bins): readings within each bin's window."""
    at: npt.NDArray[np.intp]
    """Each reading's bin."""
    reach: npt.NDArray[np.intp]
    """(groups, 1): a window's half-width in bins."""
    bin_m: float


def _windows(
    values: npt.NDArray[np.floating],
    group: npt.NDArray[np.int32],
    count: int,
    tol: Float64Array,
    low: float,
) -> _Windows:
    bin_m = max(float(tol.min()) / 3.0, 1e-4)
    bins = int((float(values.max()) - low) / bin_m) + 2
    if bins * count > 4_000_000:
        bin_m *= bins * count / 4_000_000
        bins = int((float(values.max()) - low) / bin_m) + 2
    at = ((values - low) / bin_m).astype(np.intp)
    hist = np.bincount(group * bins + at, minlength=count * bins).reshape(count, bins)
    cumulative = np.zeros((count, bins + 1))
    np.cumsum(hist, axis=1, out=cumulative[:, 1:])
    reach = np.ceil(tol / bin_m).astype(np.intp)[:, np.newaxis]
    columns = np.arange(bins)[np.newaxis, :]
    counts = np.take_along_axis(cumulative, np.minimum(columns + reach + 1, bins), 1)
    counts -= np.take_along_axis(cumulative, np.maximum(columns - reach, 0), 1)
    return _Windows(counts, at, reach, bin_m)


def _levels(
    values: Float32Array, which: npt.NDArray[np.int32], count: int, tol: Float64Array
) -> Float64Array:
    """Per piece, its top's height: the most common height (the most readings within the
    tolerance), then the mean of the readings within the tolerance of it, twice."""
    w = _windows(values, which, count, tol, float(values.min()))
    # The mean of the readings in the fullest window, then within the tolerance of it.
    peak = w.counts.argmax(axis=1)
    near = np.abs(w.at - peak[which]) <= w.reach[which, 0]
    total = np.bincount(which[near], weights=values[near], minlength=count)
    level = total / np.maximum(np.bincount(which[near], minlength=count), 1)
    for _ in range(2):
        near = np.abs(values - level[which]) < tol[which]
        total = np.bincount(which[near], weights=values[near], minlength=count)
        number = np.bincount(which[near], minlength=count)
        level = np.where(number > 0, total / np.maximum(number, 1), level)
    result: Float64Array = level
    return result


def _bands(
    labels: npt.NDArray[np.int32],
    h: Float32Array,
    d: Float32Array,
    big: npt.NDArray[np.intp],
    counts: npt.NDArray[np.intp],
    footprint_m: float,
    lens: Intrinsics,
    support: Support,
    origin: tuple[int, int],
) -> tuple[BoolArray, BoolArray]:
    """Which tops (pieces ``big``, in order) are only bands, and which of those bands run
    round another top (their bounding box holds some of it): a seam's dark line between two
    cartons, cut out along both sides by colour edges. Nothing of a band is left once it
    shrinks by a few pixels (BAND_M at ``footprint_m``; fewer along the line of sight where a
    camera sees the piece at a slant: its pixels are longer that way), and it runs along a
    carton's side, many times longer than it is wide (a short thin piece is a strip of
    something else, such as a box mostly hidden under another). A pixel with no reading is
    no edge: dropout does not thin a top; nor is a lone pixel cut out of the piece by noise
    (three of its four neighbours are the piece). ``origin``: the picture's row and column of
    ``labels``' first."""
    k = min(max(math.ceil(BAND_M / max(footprint_m, 1e-6)), 2), BAND_MAX_PX)
    band = np.zeros(len(big), dtype=bool)
    ring = np.zeros(len(big), dtype=bool)
    is_big = np.zeros(len(counts), dtype=bool)
    is_big[big] = True
    slices = ndimage.find_objects(labels)
    rows_n, cols_n = labels.shape
    normal = np.asarray(support.normal_camera, dtype=np.float64)
    for t, piece in enumerate(big):
        where = slices[piece - 1]
        if where is None:
            continue
        tall, wide = where[0].stop - where[0].start, where[1].stop - where[1].start
        # Neither count is under 2 or over k: most pieces are plainly no band whatever they are.
        if max(tall, wide) < 16 or counts[piece] > 3 * k * (tall + wide):
            continue
        k_rows, k_cols = _band_pixels(
            (where[0].start + where[0].stop - 1) / 2 + origin[0],
            (where[1].start + where[1].stop - 1) / 2 + origin[1],
            d[where][labels[where] == piece],
            normal,
            lens,
            k,
        )
        # A band holds at most 2k pixels across its length; seams round and between cartons
        # join in rings and grids, up to about twice round their bounding box.
        if max(tall / k_rows, wide / k_cols) < 8 or counts[piece] > 3 * (
            k_cols * tall + k_rows * wide
        ):
            continue
        rs = slice(max(where[0].start - 1, 0), min(where[0].stop + 1, rows_n))
        cs = slice(max(where[1].start - 1, 0), min(where[1].stop + 1, cols_n))
        mine = labels[rs, cs] == piece
        around = np.zeros(mine.shape, dtype=np.int8)
        around[1:] += mine[:-1]
        around[:-1] += mine[1:]
        around[:, 1:] += mine[:, :-1]
        around[:, :-1] += mine[:, 1:]
        alive = mine | np.isnan(h[rs, cs]) | (around >= 3)
        for step in range(max(k_rows, k_cols)):
            core = alive.copy()
            if step < k_cols:
                core[:, :-1] &= alive[:, 1:]
                core[:, 1:] &= alive[:, :-1]
            if step < k_rows:
                core[:-1] &= alive[1:]
                core[1:] &= alive[:-1]
            core[[0, -1], :] = False
            core[:, [0, -1]] = False
            alive = core
        band[t] = not (alive & mine).any()
        inside = labels[where]
        ring[t] = band[t] and bool((is_big[inside] & (inside != piece)).any())
    return band, ring


def _band_pixels(
    row: float,
    col: float,
    depths: Float32Array,
    normal: Float64Array,
    lens: Intrinsics,
    pixels: int,
) -> tuple[int, int]:
    """How many pixels down and across a band's shrinking takes: ``pixels`` along the
    picture's shorter step on a plane parallel to the support at the pixel (row, col) and the
    median of ``depths``, fewer along the longer (a top seen at a slant: its rows are longer
    along the line of sight than its columns across it), at least 2."""
    depth = float(np.nanmedian(depths)) if len(depths) else math.nan
    if not math.isfinite(depth) or depth <= 0:
        return pixels, pixels

    def ray(r: float, c: float) -> Float64Array:
        return np.array([(c - lens.cx) / lens.fx, (r - lens.cy) / lens.fy, 1.0])

    here = ray(row, col) * depth
    level = float(normal @ here)
    metres = []
    for r, c in ((row + 1.0, col), (row, col + 1.0)):
        other = ray(r, c)
        along = float(normal @ other)
        metres.append(float(np.linalg.norm(other * (level / along) - here)) if along else 0.0)
    shortest = min(metres)
    if not shortest > 0:
        return pixels, pixels
    down, across = (max(math.ceil(pixels * shortest / m), 2) for m in metres)
    return down, across


def _grow(
    top_flat: npt.NDArray[np.int32],
    candidates: npt.NDArray[np.intp],
    h_flat: Float32Array,
    level: Float64Array,
    tol: Float64Array,
    width: int,
    bands: npt.NDArray[np.intp] | None = None,
    above: Float64Array | None = None,
) -> None:
    """Tops grow back into cut pixels and small pieces at their height (from ``tol`` under
    their level to ``above`` over it, ``tol`` when None), GROW_PX pixels, and on across
    ``bands`` (a seam's line between colour edges) until they meet; where two tops reach one
    pixel the larger (lower index) takes it, so a band splits down its middle."""
    reach = GROW_PX
    if bands is not None and len(bands):
        candidates = np.concatenate([candidates, bands])
        reach = 4 * BAND_MAX_PX
    heights = h_flat[candidates]
    free = np.zeros(len(candidates), dtype=bool)
    free[len(candidates) - (0 if bands is None else len(bands)) :] = True
    none = np.int32(np.iinfo(np.int32).max)
    for step in range(reach):
        if step == GROW_PX:
            candidates, heights, free = candidates[free], heights[free], free[free]
        if len(candidates) == 0:
            return
        best = np.full(len(candidates), none, dtype=np.int32)
        for offset in (1, -1, width, -width):
            seen = top_flat[candidates + offset]
            np.minimum(best, np.where(seen > 0, seen, none), out=best)
        take = np.flatnonzero(best < none)
        which = best[take] - 1
        rise = heights[take] - level[which]
        fits = (rise > -tol[which]) & (rise < (tol if above is None else above)[which])
        take, which = take[fits], which[fits]
        top_flat[candidates[take]] = which + 1
        if len(take) == 0:
            return
        keep = np.ones(len(candidates), dtype=bool)
        keep[take] = False
        candidates, heights, free = candidates[keep], heights[keep], free[keep]


@dataclass
class _Tops:
    """Every top's pixels in the padded crop, grouped by top (row-major within a top)."""

    flat: npt.NDArray[np.intp]
    top: npt.NDArray[np.int32]
    starts: npt.NDArray[np.intp]
    counts: npt.NDArray[np.intp]
    width: int
    rows: npt.NDArray[np.intp]
    cols: npt.NDArray[np.intp]
    row_fill: Float64Array
    col_fill: Float64Array
    shift: tuple[int, int]
    """Picture row and column of the padded crop's first pixel."""

    @classmethod
    def gather(
        cls, top_lab: npt.NDArray[np.int32], count: int, pad: int, origin: tuple[int, int]
    ) -> _Tops:
        width = top_lab.shape[1]
        flat, top = _grouped(top_lab.reshape(-1), count)
        counts = np.bincount(top, minlength=count)
        starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
        rows, cols = np.divmod(flat, width)
        row_fill = _spans(top, rows, cols, count, top_lab.shape[0])
        col_fill = _spans(top, cols, rows, count, width)
        shift = (origin[0] - pad, origin[1] - pad)
        return cls(
            flat,
            top,
            starts,
            counts,
            width,
            rows + shift[0],
            cols + shift[1],
            row_fill,
            col_fill,
            shift,
        )


def _grouped(
    labels: npt.NDArray[np.int32], count: int
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.int32]]:
    """Flat indices of labelled pixels, grouped by label, in picture order within a group."""
    flat = np.flatnonzero(labels)
    top = labels[flat] - 1
    kind = np.int16 if count < 32_000 else np.int32
    order = np.argsort(top.astype(kind), kind="stable")
    return flat[order], top[order]


def _spans(
    top: npt.NDArray[np.int32],
    lines: npt.NDArray[np.intp],
    along: npt.NDArray[np.intp],
    count: int,
    lines_n: int,
) -> Float64Array:
    """Per top, the pixels from the first to the last of each line (row or column, of
    ``lines_n``), summed: the top's area with the holes in it (noise, a box standing on it)
    filled. One pass over the pixels, whatever their order."""
    key = top.astype(np.intp) * lines_n + lines
    first = np.full(count * lines_n, np.iinfo(np.intp).max, dtype=np.intp)
    last = np.full(count * lines_n, -1, dtype=np.intp)
    np.minimum.at(first, key, along)
    np.maximum.at(last, key, along)
    spans = np.maximum(last - first + 1, 0).reshape(count, lines_n)
    result: Float64Array = spans.sum(axis=1).astype(np.float64)
    return result


def _tilts(
    top: npt.NDArray[np.int32],
    n: Float64Array,
    cols: npt.NDArray[np.intp],
    rows: npt.NDArray[np.intp],
    d: Float64Array,
    across: Float64Array,
    down: Float64Array,
    normal: Float64Array,
    count: int,
) -> Float64Array:
    """Each top's tilt from the support, degrees, from its plane fitted along the rays.

    A plane n·p = c seen along the rays (x, y, 1) has 1 / depth = n·(x, y, 1) / c: linear in
    the ray, which has no error, so least squares on 1 / depth leaves the error where it is,
    in the depth. The least axis of the points' moments puts it everywhere: once the noise is
    wider than a narrow top (sigma above its width / sqrt 12: a box 12 pixels wide 2 m from a
    stereo camera), that axis turns across the top, and a slanted ray tips it further.
    """
    x, y, w = across[cols], down[rows], 1.0 / d
    centred = []
    for values in (x, y, w):
        mean = np.bincount(top, weights=values, minlength=count) / n
        centred.append((values - mean[top], mean))
    cov = np.empty((count, 2, 3))
    for i in range(2):
        for j in range(3):
            cov[:, i, j] = (
                np.bincount(top, weights=centred[i][0] * centred[j][0], minlength=count) / n
            )
    spread = cov[:, :, :2] + np.eye(2) * 1e-18
    alpha, beta = np.linalg.solve(spread, cov[:, :, 2:3])[:, :, 0].T
    gamma = centred[2][1] - alpha * centred[0][1] - beta * centred[1][1]
    plane = np.stack([alpha, beta, gamma], axis=1)
    cos = np.abs(plane @ normal) / np.maximum(np.linalg.norm(plane, axis=1), 1e-300)
    result: Float64Array = np.degrees(np.arccos(np.minimum(cos, 1.0)))
    return result


def _level(
    tilt: float, ray_tilt: float, rising: float, rect: Rectangle, settings: FinderSettings
) -> bool:
    """Whether a top lies parallel to the support: by its moments' least axis, or, for a top
    narrower than its depth noise (whose least axis turns across it), by its plane fitted
    along the rays when at least three of its sides are seen falling away (edges, or the
    dropout a stereo camera leaves at them): a box standing free, not the strip of a lower top
    seen past a box on it, nor a pallet's margin, which a rising face bounds."""
    limit = settings.max_top_tilt_deg
    if tilt <= limit:
        return True
    falling = set(rect.edge_normals) | set(rect.dropout_normals)
    return ray_tilt <= limit and len(falling) >= 3 and rising < RISING_SHARE


def _measure_all(
    tops: _Tops,
    top_flat: npt.NDArray[np.int32],
    h_flat: Float32Array,
    d_flat: Float32Array,
    s_flat: Float32Array,
    level: Float64Array,
    tol: Float64Array,
    p_idx: npt.NDArray[np.intp],
    p_top: npt.NDArray[np.int32],
    p_h: Float32Array,
    lens: Intrinsics,
    support: Support,
    settings: FinderSettings,
    shape: tuple[int, int],
) -> list[_Plateau]:
    """Every top's plane, outline, rectangle and score; which of them are boxes."""
    rows_n, cols_n = shape
    count = len(level)
    top = tops.top
    across, down = lens.rays(cols_n, rows_n)
    basis = _plane_basis(support, None)
    d = d_flat[tops.flat]
    pixel_area = d * d
    pixel_area /= np.abs(s_flat[tops.flat])
    pixel_area *= np.float32(1.0 / (lens.fx * lens.fy))
    n = np.maximum(tops.counts, 1).astype(np.float64)
    area = np.bincount(top, weights=pixel_area, minlength=count)
    mean_area = area / n
    # The top's plane from its moments, all tops at once, on a sample of at most ~6k pixels
    # (every k-th of the grouped pixels: each top keeps its share).
    k = max(1, len(top) // 6_000)
    sample = slice(k // 2, None, k)
    ds = d[sample].astype(np.float64)
    xyz = (across[tops.cols[sample]] * ds, down[tops.rows[sample]] * ds, ds)
    st = top[sample]
    ns = np.maximum(np.bincount(st, minlength=count), 1).astype(np.float64)
    centred = []
    for row in basis:
        values = row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2]
        mean = np.bincount(st, weights=values, minlength=count) / ns
        centred.append(values - mean[st])
    moments = np.empty((count, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            m = np.bincount(st, weights=centred[i] * centred[j], minlength=count) / ns
            moments[:, i, j] = m
            moments[:, j, i] = m
    values_e, vectors = np.linalg.eigh(moments)
    rms = np.sqrt(np.maximum(values_e[:, 0], 0.0))
    tilt = np.degrees(np.arccos(np.minimum(np.abs(vectors[:, 2, 0]), 1.0)))
    # Along the rays only where the least axis finds a top tilted (noise may have turned it).
    ray_tilt = np.full(count, np.inf)
    steep = (tilt > settings.max_top_tilt_deg)[st]
    if steep.any():
        ray_tilt = _tilts(
            st[steep],
            ns,
            tops.cols[sample][steep],
            tops.rows[sample][steep],
            ds[steep],
            across,
            down,
            basis[2],
            count,
        )
    # Outline: top pixels with a 4-neighbour off the top. Hidden: within two pixels past it the
    # surface rises above the top (something stands on it, or is in front of it).
    label_at = top_flat
    own = top + 1
    outline = np.zeros(len(top), dtype=bool)
    offsets = (1, -1, tops.width, -tops.width)
    for offset in offsets:
        outline |= label_at[tops.flat + offset] != own
    edge = np.flatnonzero(outline)
    e_flat, e_top = tops.flat[edge], top[edge]
    # The outline's points in the support plane (the rectangle needs no others).
    de = d[edge].astype(np.float64)
    xe, ye = across[tops.cols[edge]] * de, down[tops.rows[edge]] * de
    a = basis[0, 0] * xe + basis[0, 1] * ye + basis[0, 2] * de
    b = basis[1, 0] * xe + basis[1, 1] * ye + basis[1, 2] * de
    fill_a, fill_b = _nearer_on_level(
        a, b, h_flat[e_flat], level[e_top], e_top, support.offset_camera_m, count
    )
    # Each row's first and last outline pixel: their hull is the top's hull.
    row_key = e_top.astype(np.int64) * (rows_n + 1) + tops.rows[edge]
    change = np.flatnonzero(row_key[1:] != row_key[:-1])
    extreme = np.zeros(len(edge), dtype=bool)
    extreme[0] = extreme[-1] = True
    extreme[change] = True
    extreme[change + 1] = True
    # Above this a surface rises over a top (something stands on or in front of it).
    over = level + np.maximum(1.5 * tol, 0.005)
    e_level = over[e_top]
    hidden = np.zeros(len(edge), dtype=bool)
    unsure = np.zeros(len(edge), dtype=bool)
    # Drop: past the pixel the surface is seen well below the top: a real edge, not a shadow.
    drop = np.zeros(len(edge), dtype=bool)
    e_low = level[e_top] - np.maximum(1.5 * tol[e_top], 0.005)
    # For hidden outline points, how far along the support the nearest rising point past it
    # lies from it.
    stand_off = np.full(len(edge), np.inf)
    risen_far = np.zeros(len(edge), dtype=bool)
    for offset in offsets:
        off = label_at[e_flat + offset] != e_top + 1
        beyond = h_flat[e_flat + offset]
        rise = np.fmax(np.fmax(beyond, h_flat[e_flat + 2 * offset]), h_flat[e_flat + 3 * offset])
        with np.errstate(invalid="ignore"):
            risen = off & (rise > e_level)
        hidden |= risen
        at = np.flatnonzero(risen)
        for k in (1, 2, 3):
            f = e_flat[at] + k * offset
            with np.errstate(invalid="ignore"):
                up = h_flat[f] > e_level[at]
            f, on = f[up], at[up]
            r, c = np.divmod(f, tops.width)
            df = d_flat[f].astype(np.float64)
            xf = across[c + tops.shift[1]] * df
            yf = down[r + tops.shift[0]] * df
            pa = basis[0, 0] * xf + basis[0, 1] * yf + basis[0, 2] * df
            pb = basis[1, 0] * xf + basis[1, 1] * yf + basis[1, 2] * df
            stand_off[on] = np.fmin(stand_off[on], np.hypot(pa - a[on], pb - b[on]))
        unsure |= off & np.isnan(beyond)
        # Past a band with no reading (a stereo camera's at a depth edge, as wide as a steep
        # face seen past it and the band each side of that), the first reading says whether
        # the surface rises there.
        gap = np.flatnonzero(off & np.isnan(rise))
        far, undecided = e_flat[gap], np.ones(len(gap), dtype=bool)
        for k in range(4, PAD + 1):
            beyond_k = h_flat[far + k * offset]
            with np.errstate(invalid="ignore"):
                up = undecided & (beyond_k > e_level[gap])
                undecided &= np.isnan(beyond_k)
            risen_far[gap[up]] = True
        with np.errstate(invalid="ignore"):
            drop |= off & (np.fmin(beyond, h_flat[e_flat + 2 * offset]) < e_low)
    # Past a dropout band something rises: hidden as much as by a rise right past the top.
    rise_near = hidden.copy()
    hidden |= risen_far
    border = (tops.rows == 0) | (tops.rows == rows_n - 1) | (tops.cols == 0)
    border |= tops.cols == cols_n - 1
    cut_off = np.bincount(top[border], minlength=count) > 0
    filled = np.minimum(tops.row_fill, tops.col_fill)
    whole_area = area + np.maximum(filled - tops.counts, 0) * mean_area
    mean_depth = np.bincount(top, weights=d, minlength=count) / n
    sigma = np.asarray(support.sigma_at(mean_depth), dtype=np.float64)
    eligible = (tops.counts >= 6) & (whole_area >= _least_top_area(sigma, settings))
    if not settings.keep_cut_off:
        eligible &= ~cut_off
    footprint = np.sqrt(mean_area)
    chosen = eligible[e_top]
    rects = fit_rectangles(
        np.stack([a[chosen], b[chosen]], axis=1),
        e_top[chosen],
        hidden[chosen],
        extreme[chosen],
        unsure[chosen],
        drop[chosen],
        footprint,
        whole_area,
    )
    # A rim of a lower top a few pixels wide is told from noise only while the noise is well
    # under a footprint (3 sigma within two): a close camera, a clean picture.
    # Only for the tops that may be boxes, and while the noise lets a rim be told.
    rim = eligible & (3.0 * sigma <= 2.0 * footprint)
    at_rim = rim[e_top]
    ledge = _ledges(
        e_flat[at_rim],
        e_top[at_rim],
        label_at,
        h_flat,
        tops.width,
        level,
        tol,
        footprint,
        settings,
        count,
    )
    edge_starts = np.searchsorted(e_top, np.arange(count))
    edge_stops = np.searchsorted(e_top, np.arange(count), side="right")
    reach = np.maximum(tol, FLAT_REACH_M)
    loose = _loose_groups(p_idx, p_top, p_h, level, reach, count)
    plateaus: list[_Plateau] = []
    for t in range(count):
        if tops.counts[t] < 6:
            continue
        p = _Plateau(
            t,
            float(level[t]),
            float(tol[t]),
            int(tops.counts[t]),
            float(footprint[t]),
            float(area[t]),
        )
        p.ledge_m = None if np.isnan(ledge[t]) else float(ledge[t])
        part = slice(int(edge_starts[t]), int(edge_stops[t]))
        bands = stand_off[part][hidden[part]]
        bands = bands[np.isfinite(bands)]
        p.hidden_band_m = float(np.median(bands)) if len(bands) else 0.0
        plateaus.append(p)
        rect = rects[t]
        if not eligible[t] or rect is None:
            continue
        p.rect = rect
        # The fill is taken against the extreme pixels (plus a footprint), not the fitted
        # sides: a disc's sides fitted by medians would hug it.
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        part = slice(int(edge_starts[t]), int(edge_stops[t]))
        points = np.stack([fill_a[part], fill_b[part]], axis=1)
        rect_area = (np.ptp(points @ ax) + footprint[t]) * (np.ptp(points @ perp) + footprint[t])
        fill = min(float(whole_area[t]) / rect_area, 1.0)
        # A side hidden by what rises past a dropout band is ragged like a seen one.
        through_dropout = rect.hidden_sides == 1 and risen_far[part].sum() > rise_near[part].sum()
        if (
            tol[t] > RAGGED_TOLERANCE_M
            and fill >= RAGGED_MIN_FILL
            and (rect.hidden_sides == 0 or through_dropout)
            and len(points) >= 3
        ):
            # Noise this large makes a top's outline ragged (readings near its edge fall in and
            # out of the tolerance): its hull, grown by half a footprint, measures the shape of
            # a top seen whole that already nearly fills its rectangle (a narrow strip, such as
            # a pallet's margin under the cartons, loses more of its area to the ragged edge
            # and stays what it is).
            fill = max(fill, min(_hull_area(points, float(footprint[t])) / rect_area, 1.0))
        flatness = max(0.0, 1.0 - max(rms[t] - 0.5 * reach[t], 0.0) / reach[t])
        if fill * flatness < settings.min_score and hidden[part].any():
            # Something in front hides part of the top (a taller box nearer the camera): the
            # fill is taken over the part of the rectangle that can be seen, when the outline
            # seen hugs the rectangle's sides (a disc's does not, whatever hides its corners).
            seen = _seen_fill(
                t,
                points,
                extreme[part] & ~hidden[part] & ~unsure[part],
                (hidden[part] & ~(stand_off[part] <= 3.0 * footprint[t])) | unsure[part],
                rect,
                float(footprint[t]),
                float(whole_area[t]),
                float(level[t]),
                float(over[t]),
                top_flat,
                h_flat,
                tops,
                across,
                down,
                basis,
                lens,
                support,
            )
            fill = max(fill, seen)
        p.score = fill * flatness
        rising = float(risen_far[part].mean()) if part.stop > part.start else 0.0
        if p.score < settings.min_score or not _level(tilt[t], ray_tilt[t], rising, rect, settings):
            continue
        # Curved tops widen when the tolerance is loosened; a box's sides drop straight down.
        wide = loose[t]
        if len(wide) > tops.counts[t] and _growth(wide, tops, d_flat, lens, basis, points, ax) > (
            settings.max_curvature_growth
        ):
            continue
        p.is_box = True
    return plateaus


def _nearer_on_level(
    a: Float64Array,
    b: Float64Array,
    height: Float32Array,
    level: Float64Array,
    top: npt.NDArray[np.int32],
    offset_m: float,
    count: int,
) -> tuple[Float64Array, Float64Array]:
    """Outline points ``a``, ``b`` (the readings in the support plane's coordinates) for the
    fill: each one where its ray meets its top's level, or where its reading puts it, whichever
    is nearer the top's middle.

    A reading's error along its ray moves it across the top too, by the error times the ray's
    slant (12 mm for sigma 21 mm seen 30 degrees off straight down: a D435 at 2.5 m), so the
    outline's extreme readings stand past the top's edge and a box seen through such noise
    fills too little of the span they give. Placed on its level, a pixel of the top is where
    it is; a pixel of a side face within the tolerance would be placed out past the edge, and
    its reading, at the edge, is the nearer. The rectangle itself is fitted to the readings,
    whose errors its medians average out."""
    # Along the ray the height is linear in depth (height = depth * slope + offset): the depth
    # at which the ray meets the level scales the reading's coordinates.
    scale = (level - offset_m) / (height.astype(np.float64) - offset_m)
    on_a, on_b = a * scale, b * scale
    n = np.maximum(np.bincount(top, minlength=count), 1)
    mid_a = (np.bincount(top, weights=on_a, minlength=count) / n)[top]
    mid_b = (np.bincount(top, weights=on_b, minlength=count) / n)[top]
    nearer = np.hypot(on_a - mid_a, on_b - mid_b) < np.hypot(a - mid_a, b - mid_b)
    return np.where(nearer, on_a, a), np.where(nearer, on_b, b)


SEAM_ROUNDS = 2
"""Tops are looked over for seams at most this many times (every seam across a top is split at
once; a seam that only runs across one of the parts shows after)."""
SEAM_BIN = 1.5
"""A seam's bins, footprints: a tilted camera's pixels lie farther apart one way."""


def _split_tops(
    top_flat: npt.NDArray[np.int32],
    tops: _Tops,
    cells: list[tuple[int, npt.NDArray[np.intp]]],
    level: Float64Array,
    tol: Float64Array,
    h_flat: Float32Array,
    p_idx: npt.NDArray[np.intp],
    p_top: npt.NDArray[np.int32],
) -> tuple[Float64Array, Float64Array, int]:
    """Cartons of one shade whose seams' colour lines break for a pixel or two grew into one
    top: each cell between the seams (from :func:`_seams`: per top, each of its pixels' cell)
    becomes a top of its own, and so does each connected part of a cell (a load's cartons round
    a missing one); the largest part keeps the top's label. ``top_flat`` and ``p_top`` are
    relabelled in place; returns the levels and tolerances, one per top, and the number of
    tops."""
    before = len(level)
    count = before
    parents = []
    for t, cell in cells:
        flat = tops.flat[int(tops.starts[t]) : int(tops.starts[t] + tops.counts[t])]
        pieces = [
            piece for c in np.unique(cell) for piece in _connected(flat[cell == c], tops.width)
        ]
        biggest = max(range(len(pieces)), key=lambda k: len(pieces[k]))
        for k, piece in enumerate(pieces):
            if k == biggest or len(piece) < 6:
                continue
            top_flat[piece] = count + 1
            parents.append(t)
            count += 1
    moved = top_flat[p_idx] > before
    p_top[moved] = top_flat[p_idx[moved]] - 1
    level = np.concatenate([level, level[parents]])
    tol = np.concatenate([tol, tol[parents]])
    # Each part at its own height: under a stereo camera's noise a step of a centimetre or two
    # between two cartons may be what the depth could not see.
    split = np.unique(np.concatenate([[t for t, _ in cells], np.arange(before, count)]))
    on = np.flatnonzero(np.isin(top_flat, (split + 1).astype(np.int32)))
    own = _levels(h_flat[on], top_flat[on] - 1, count, tol)
    level[split] = own[split]
    return level, tol, count


def _connected(flat: npt.NDArray[np.intp], width: int) -> list[npt.NDArray[np.intp]]:
    """The 4-connected parts of a set of pixels (flat indices in a picture ``width`` wide)."""
    if len(flat) == 0:
        return []
    r, c = np.divmod(flat, width)
    r0, c0 = int(r.min()), int(c.min())
    mask = np.zeros((int(r.max()) - r0 + 1, int(c.max()) - c0 + 1), dtype=bool)
    mask[r - r0, c - c0] = True
    labels, n = ndimage.label(mask)
    if n <= 1:
        return [flat]
    which = labels[r - r0, c - c0]
    return [flat[which == k] for k in range(1, n + 1)]


def _seams(
    plateaus: list[_Plateau],
    tops: _Tops,
    s_flat: Float32Array,
    cut_flat: BoolArray,
    grey_flat: npt.NDArray[np.int16],
    colour_step: float,
    lens: Intrinsics,
    support: Support,
    shape: tuple[int, int],
) -> list[tuple[int, npt.NDArray[np.intp]]]:
    """Tops that straight lines of colour edges or dark valleys cross from side to side,
    parallel to a side of their rectangle, with the top going on past them on both sides (the
    seams between cartons of one shade, along and across): per such top, its label and each of
    its pixels' cell between the lines (0, 1, ...)."""
    rows_n, cols_n = shape
    across, down = lens.rays(cols_n, rows_n)
    basis = _plane_basis(support, None)
    found: list[tuple[int, npt.NDArray[np.intp]]] = []
    for p in plateaus:
        if p.rect is None or p.rect.length_m < 2.0 * segment.SEAM_MIN_M:
            continue
        t = p.label
        part = slice(int(tops.starts[t]), int(tops.starts[t] + tops.counts[t]))
        flat = tops.flat[part]
        shade = grey_flat[flat]
        cut = cut_flat[flat] | segment.valleys(grey_flat, flat, tops.width, colour_step)
        if np.count_nonzero(cut) * p.footprint_m < segment.SEAM_MIN_M:
            continue
        # Each pixel's ray met with the top's plane, not its reading: a stereo camera's noise
        # along the ray would smear the line over several footprints.
        d = (p.height_m - support.offset_camera_m) / s_flat[flat].astype(np.float64)
        x, y = across[tops.cols[part]] * d, down[tops.rows[part]] * d
        pa = basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * d
        pb = basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * d
        ax, ay = p.rect.axis
        u, v = pa * ax + pb * ay, pb * ax - pa * ay
        bin_m = SEAM_BIN * p.footprint_m
        at_u = segment.seam_lines(u, v, cut, shade, colour_step, bin_m)
        at_v = segment.seam_lines(v, u, cut, shade, colour_step, bin_m)
        if at_u or at_v:
            cell = np.searchsorted(at_u, u) * (len(at_v) + 1) + np.searchsorted(at_v, v)
            found.append((t, cell))
    return found


HUG_SHARE = 0.85
"""A partly hidden top counts as a rectangle only if this share of its row ends seen (not
hidden, not next to dropout) lies within ``HUG_FOOTPRINTS`` of its rectangle's sides ..."""
HUG_FOOTPRINTS = 2.5
SIDE_SEEN_SHARE = 0.05
"""... and each of its four sides is seen (outline points within that band of it, not hidden)
along at least this share of its length."""


def _seen_fill(
    t: int,
    points: Float64Array,
    ends: BoolArray,
    hidden_points: BoolArray,
    rect: Rectangle,
    footprint_m: float,
    whole_area_m2: float,
    level_m: float,
    rise_m: float,
    top_flat: npt.NDArray[np.int32],
    h_flat: Float32Array,
    tops: _Tops,
    across: Float64Array,
    down: Float64Array,
    basis: Float64Array,
    lens: Intrinsics,
    support: Support,
) -> float:
    """The share of the part of the top's rectangle not hidden by something in front that the
    top fills; 0 when the outline seen does not hug the rectangle (not a rectangle).

    The rectangle is the extreme outline points' (plus a footprint), as for the plain fill.
    Each crop pixel whose ray meets the top's plane inside it counts with its area there;
    those whose reading rises above the top (``rise_m``) are hidden and left out."""
    if rect.hidden_sides or ends.sum() < 8:
        return 0.0
    ax = np.asarray(rect.axis)
    perp = np.array([-ax[1], ax[0]])
    # The outline seen must lie on the fitted rectangle's sides ...
    local = points - np.asarray(rect.middle)
    u, w = local @ ax, local @ perp
    off_u = np.abs(np.abs(u) - rect.length_m / 2)
    off_w = np.abs(np.abs(w) - rect.width_m / 2)
    band = HUG_FOOTPRINTS * footprint_m
    hug = float(np.mean(np.minimum(off_u, off_w)[ends] <= band))
    if hug < HUG_SHARE:
        return 0.0
    # ... and every side be seen along a good part of it (or be met by a taller neighbour's
    # wall: what rises past it stands at it): where something in front hides a whole side,
    # the line it is cut along passes for one and the size is unknown.
    # (Points within the band of a side's ends belong to the sides across it as well.)
    seen = ~hidden_points
    along_w = np.abs(w) < rect.width_m / 2 - band
    along_u = np.abs(u) < rect.length_m / 2 - band
    for on_side, length in (
        (seen & (off_u <= band) & (u > 0) & along_w, rect.width_m),
        (seen & (off_u <= band) & (u < 0) & along_w, rect.width_m),
        (seen & (off_w <= band) & (w > 0) & along_u, rect.length_m),
        (seen & (off_w <= band) & (w < 0) & along_u, rect.length_m),
    ):
        count = int(on_side.sum())
        if count < 2 or count * footprint_m < SIDE_SEEN_SHARE * length:
            return 0.0
    along, side = points @ ax, points @ perp
    half = 0.5 * footprint_m
    lo_a, hi_a = float(along.min()) - half, float(along.max()) + half
    lo_b, hi_b = float(side.min()) - half, float(side.max()) + half
    # The rectangle's corners on the top's plane, into the (padded) crop's pixels.
    n = basis[2]
    lift = level_m - support.offset_camera_m
    corners = np.array(
        [
            (a * ax[0] - b * ax[1]) * basis[0] + (a * ax[1] + b * ax[0]) * basis[1] + lift * n
            for a in (lo_a, hi_a)
            for b in (lo_b, hi_b)
        ]
    )
    if (corners[:, 2] <= 0).any():
        return 0.0
    u = lens.fx * corners[:, 0] / corners[:, 2] + lens.cx - tops.shift[1]
    v = lens.fy * corners[:, 1] / corners[:, 2] + lens.cy - tops.shift[0]
    rows_n = len(h_flat) // tops.width
    r0, r1 = max(int(v.min()), 0), min(math.ceil(v.max()) + 1, rows_n)
    c0, c1 = max(int(u.min()), 0), min(math.ceil(u.max()) + 1, tops.width)
    if r1 <= r0 or c1 <= c0:
        return 0.0
    ray_x = across[np.clip(np.arange(c0, c1) + tops.shift[1], 0, len(across) - 1)]
    ray_y = down[np.clip(np.arange(r0, r1) + tops.shift[0], 0, len(down) - 1)]
    slope = n[0] * ray_x[np.newaxis, :] + n[1] * ray_y[:, np.newaxis] + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = lift / slope
    x, y = ray_x[np.newaxis, :] * depth, ray_y[:, np.newaxis] * depth
    pa = basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * depth
    pb = basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * depth
    pa, pb = pa * ax[0] + pb * ax[1], pb * ax[0] - pa * ax[1]
    inside = (depth > 0) & (pa >= lo_a) & (pa <= hi_a) & (pb >= lo_b) & (pb <= hi_b)
    window = (slice(r0, r1), slice(c0, c1))
    heights = h_flat.reshape(rows_n, tops.width)[window]
    mine = top_flat.reshape(rows_n, tops.width)[window] == t + 1
    with np.errstate(invalid="ignore"):
        hidden = inside & ~mine & (heights > rise_m)
    area = depth * depth / (np.abs(slope) * lens.fx * lens.fy)
    seen_m2 = float(area[inside].sum() - area[hidden].sum())
    if seen_m2 <= 0.0:
        return 0.0
    return min(whole_area_m2 / seen_m2, 1.0)


RAGGED_TOLERANCE_M = 0.01
"""A top whose height tolerance is wider than this (noise of 3 mm or more) is measured by its
hull: a disc still fills pi/4 of its rectangle, a ragged rectangle nearly all of it ..."""
RAGGED_MIN_FILL = 0.72
"""... when its own readings fill at least this share of its rectangle."""


def _hull_area(points: Float64Array, footprint_m: float) -> float:
    """The area of the points' convex hull grown by half a footprint all round (outline pixel
    middles lie half a footprint inside the edge)."""
    try:
        hull = spatial.ConvexHull(points)
    except spatial.QhullError:  # all on a line: no area
        return 0.0
    half = 0.5 * footprint_m
    # In 2-D, ConvexHull's "volume" is the area and its "area" the perimeter.
    return float(hull.volume + hull.area * half + math.pi * half * half)


LEDGE_REACH_PX = 12
"""How far past a top's outline (pixels, along each off-top direction) the level just under
it is looked for: a few pixels past a side seen edge-on, past the side face seen from the front."""


def _flat(
    h_flat: Float32Array, flat: npt.NDArray[np.intp], width: int, limit: Float64Array | float
) -> BoolArray:
    """Whether the readings at these flat indices lie on a level surface: a neighbour across
    and a neighbour down agree with each one within ``limit`` (a side face's level lines run
    one way only; a rim of a lower top two pixels wide still has both)."""
    size = len(h_flat)
    here = h_flat[flat]
    with np.errstate(invalid="ignore"):
        across = (np.abs(h_flat[np.minimum(flat + 1, size - 1)] - here) < limit) | (
            np.abs(h_flat[np.maximum(flat - 1, 0)] - here) < limit
        )
        down = (np.abs(h_flat[np.minimum(flat + width, size - 1)] - here) < limit) | (
            np.abs(h_flat[np.maximum(flat - width, 0)] - here) < limit
        )
    result: BoolArray = across & down
    return result


def _ledges(
    e_flat: npt.NDArray[np.intp],
    e_top: npt.NDArray[np.int32],
    label_at: npt.NDArray[np.int32],
    h_flat: Float32Array,
    width: int,
    level: Float64Array,
    tol: Float64Array,
    footprint: Float64Array,
    settings: FinderSettings,
    count: int,
) -> Float64Array:
    """Per top, the highest flat level seen just past its outline, below it and above the
    support (NaN: none). A box standing on a box that it nearly covers leaves only a rim of the
    lower top, a few pixels wide and cut up by its edges: never a top of its own, yet a level
    the box stands on. The candidate is checked by the probes (:func:`_bases`)."""
    result = np.full(count, np.nan)
    if len(e_flat) == 0:
        return result
    size = len(h_flat)
    rows_all = size // width
    rows, cols = np.divmod(e_flat, width)
    own = e_top + 1
    heights = []
    which = []
    where = []
    reach = np.arange(1, LEDGE_REACH_PX + 1)
    for dr, dc in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        off = label_at[e_flat + dr * width + dc] != own
        r = rows[off, np.newaxis] + dr * reach
        c = cols[off, np.newaxis] + dc * reach
        inside = (r >= 0) & (r < rows_all) & (c >= 0) & (c < width)
        flat = np.where(inside, r * width + c, 0)
        seen = np.where(inside & (label_at[flat] != own[off, np.newaxis]), h_flat[flat], np.nan)
        heights.append(seen.reshape(-1))
        which.append(np.repeat(e_top[off], LEDGE_REACH_PX))
        where.append(flat.reshape(-1))
    values = np.concatenate(heights).astype(np.float64)
    group = np.concatenate(which)
    lowest = settings.min_height_m
    with np.errstate(invalid="ignore"):
        keep = (values > lowest) & (values < level[group] - np.maximum(2.0 * tol[group], lowest))
    keep = np.flatnonzero(keep)
    values, group = values[keep], group[keep]
    # ... on a level surface (not a side face seen at a slant).
    limit = np.minimum(tol, 0.5 * footprint)[group]
    level_surface = _flat(h_flat, np.concatenate(where)[keep], width, limit)
    values, group = values[level_surface], group[level_surface]
    if len(values) == 0:
        return result
    # Per top a histogram in bins of a third of the tolerance; a window of +-tol around each
    # bin; the highest window holding enough readings is the ledge.
    w = _windows(values, group, count, tol, lowest)
    window, half, bin_m = w.counts, w.reach, w.bin_m
    bins = window.shape[1]
    columns = np.arange(bins)[np.newaxis, :]
    total = np.bincount(group, minlength=count)[:, np.newaxis]
    enough = window >= np.maximum(8, 0.05 * total)
    has = enough.any(axis=1)
    if not has.any():
        return result
    # The highest window holding enough is the top edge of the level's readings: the level is
    # the fullest window within two tolerances below it.
    top_bin = bins - 1 - np.argmax(enough[:, ::-1], axis=1)
    span = (columns <= top_bin[:, np.newaxis]) & (columns >= top_bin[:, np.newaxis] - 2 * half)
    peak = np.where(span, window, -1.0).argmax(axis=1)
    centre = lowest + (peak + 0.5) * bin_m
    near = np.abs(values - centre[group]) < tol[group]
    sums = np.bincount(group[near], weights=values[near], minlength=count)
    number = np.bincount(group[near], minlength=count)
    found = has & (number > 0)
    result[found] = sums[found] / number[found]
    return result


def _loose_groups(
    p_idx: npt.NDArray[np.intp],
    p_top: npt.NDArray[np.int32],
    p_h: Float32Array,
    level: Float64Array,
    tol: Float64Array,
    count: int,
) -> list[npt.NDArray[np.intp]]:
    """Per top, its piece's pixels within four tolerances below its height (the curvature
    test's footprint)."""
    keep = p_h > level[p_top] - 4.0 * tol[p_top]
    which = p_top[keep]
    order = np.argsort(which.astype(np.int16 if count < 32_000 else np.int32), kind="stable")
    flat = p_idx[keep][order]
    stops = np.cumsum(np.bincount(which, minlength=count))
    return np.split(flat, stops[:-1])


def _growth(
    wide: npt.NDArray[np.intp],
    tops: _Tops,
    d_flat: Float32Array,
    lens: Intrinsics,
    basis: Float64Array,
    outline: Float64Array,
    axis: Float64Array,
) -> float:
    """How much a top's extent (along and across its axis) grows with the loose tolerance."""
    rows, cols = np.divmod(wide, tops.width)
    d = d_flat[wide].astype(np.float64)
    x = (cols + tops.shift[1] - lens.cx) / lens.fx * d
    y = (rows + tops.shift[0] - lens.cy) / lens.fy * d
    perp = np.array([-axis[1], axis[0]])
    flat_a = basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * d
    flat_b = basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * d
    along = flat_a * axis[0] + flat_b * axis[1]
    side = flat_a * perp[0] + flat_b * perp[1]
    before = max(float(np.ptp(outline @ axis)) * float(np.ptp(outline @ perp)), 1e-12)
    return _spread(along) * _spread(side) / before


def _spread(values: Float64Array) -> float:
    """From the 1st to the 99th percentile."""
    k = len(values) // 100
    low, high = np.partition(values, (k, len(values) - 1 - k))[[k, len(values) - 1 - k]]
    return float(high - low)


PROBE_FRACTIONS = np.linspace(-0.4, 0.4, 5)
PROBE_REACH = np.array([1.0, 2.0, 4.0, 7.0])
"""Each probe line's points past the first (the foot), in steps of max(8 mm, 3 footprints)
out from the side: the box itself hides the nearest when the camera looks down past that side."""


def _probes(box: _Plateau) -> Float64Array:
    """Lines of points in the support plane going out from each side of a box's rectangle,
    5 lines a side (lines x reaches x 2). The first point is the side's foot, 1.5 footprints
    and 1 mm out (a rim of a lower top a few pixels wide); then PROBE_REACH steps."""
    assert box.rect is not None
    rect = box.rect
    ax = np.asarray(rect.axis)
    perp = np.array([-ax[1], ax[0]])
    step = max(0.008, 3.0 * box.footprint_m)
    out = np.stack([ax, -ax, perp, -perp])  # sides x 2
    along = np.stack([perp, perp, ax, ax])
    half = np.array([rect.length_m, rect.length_m, rect.width_m, rect.width_m]) / 2
    half_along = np.array([rect.width_m, rect.width_m, rect.length_m, rect.length_m]) / 2
    start = (
        np.asarray(rect.middle)
        + (out * half[:, np.newaxis])[:, np.newaxis, :]
        + (2 * PROBE_FRACTIONS[np.newaxis, :, np.newaxis] * half_along[:, np.newaxis, np.newaxis])
        * along[:, np.newaxis, :]
    )  # sides x fractions x 2
    reach = np.concatenate([[1.5 * box.footprint_m + 0.001], PROBE_REACH * step])
    points = start[:, :, np.newaxis, :] + reach[:, np.newaxis] * out[:, np.newaxis, np.newaxis, :]
    result: Float64Array = points.reshape(-1, len(reach), 2)
    return result


def _shadowed_sides(
    boxes: list[_Plateau], camera_height_m: float, settings: FinderSettings
) -> None:
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


def _extent_unknown(box: _Plateau) -> bool:
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
        seen = _half_extent(rect, n0, n1) * 2.0
        if band > HIDDEN_SHARE * seen:
            return True
    return False


def _reaches_under(
    lower: _Plateau,
    upper: _Plateau,
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
        reach = _half_extent(upper.rect, -o1, o0)
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
                and half_out < 0.6 * _half_extent(upper.rect, o0, o1)
            )
        ):
            return True
    return False


def _next_in_row(lower: _Plateau, upper: _Plateau, side: tuple[float, float], slack: float) -> bool:
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
    reach = _half_extent(upper.rect, -o1, o0)
    fit = max(slack, 0.1 * reach)
    return (
        rx * o0 + ry * o1 >= half_out - slack
        and upper.height_m - lower.height_m < SLAB * upper.rect.width_m
        and abs(ry * o0 - rx * o1) <= fit
        and abs(reach - half_side) <= fit
        and half_out >= 0.6 * _half_extent(upper.rect, o0, o1)
    )


def _half_extent(rect: Rectangle, d0: float, d1: float) -> float:
    """Half a rectangle's extent along the unit direction (d0, d1)."""
    a0, a1 = rect.axis
    return 0.5 * (
        abs(rect.length_m * (a0 * d0 + a1 * d1)) + abs(rect.width_m * (a1 * d0 - a0 * d1))
    )


def _bases(
    boxes: list[_Plateau],
    plateaus: list[_Plateau],
    height_m: Float32Array,
    labels_top: npt.NDArray[np.int32],
    lens: Intrinsics,
    support: Support,
    settings: FinderSettings,
) -> None:
    """What each box stands on (see the module docstring, step 6)."""
    if not boxes:
        return
    rows_n, cols_n = height_m.shape
    cam = _plane_basis(support, None)
    # Levels: the support, every top, and each box's ledge (a level of its own box only).
    ledged = [i for i, b in enumerate(boxes) if b.ledge_m is not None]
    levels: list[_Plateau | None] = [None, *plateaus, *(None for _ in ledged)]
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
    label_height = np.full(max(p.label for p in plateaus) + 1, np.nan)
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
        for i, box in enumerate(boxes):
            if allowed[j, i]:
                allowed[j, i] = _reaches_under(level, box, rows=True)
    _own_faces(allowed, levels, boxes, height_m, labels_top, lens, support, cam)
    # Only the pairs (level, box) that may be the box's base are probed.
    pair_l, pair_b = np.nonzero(allowed)
    probes = np.stack([_probes(box) for box in boxes])  # boxes x lines x reaches x 2
    # Camera-frame probe points at each pair's level: a e1 + b e2 + (level - offset) n.
    shape = (-1, 1, 1, 1)
    pair_probes = probes[pair_b]
    pts = (
        pair_probes[..., :1] * cam[0]
        + pair_probes[..., 1:] * cam[1]
        + (level_h[pair_l].reshape(shape) - support.offset_camera_m) * cam[2]
    )
    z = pts[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.rint(lens.fx * pts[..., 0] / z + lens.cx)
        v = np.rint(lens.fy * pts[..., 1] / z + lens.cy)
        inside = (z > 0) & (u >= 0) & (u < cols_n) & (v >= 0) & (v < rows_n)
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
        match = any_known & (np.abs(h_first - lh[..., 0]) < lt[..., 0])
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
        match[ledge_rows] &= _flat(height_m.reshape(-1), at, cols_n, limit)
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
    side_match = match.reshape(len(pair_l), 4, -1).sum(axis=2)
    side_lower = lower.reshape(len(pair_l), 4, -1).sum(axis=2)
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
    platforms = {
        j
        for i, j in base.items()
        if levels[j] is not None and _is_platform(levels[j], boxes[i])  # type: ignore[arg-type]
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
    # that surface seen through a gap in a load (a carton missing): a level, not a box.
    for i, box in enumerate(boxes):
        assert box.rect is not None
        if (
            box.rect.hidden_sides >= 2
            and sum(
                k != i
                and other.stands_on is not box
                and other.base_m > 0
                and abs(other.base_m - box.height_m) < max(box.tolerance_m, LEVEL_TOLERANCE_FLOOR_M)
                and _touch(box, other)
                for k, other in enumerate(boxes)
            )
            >= 2
        ):
            box.platform = True


def _raise_to_faces(
    boxes: list[_Plateau],
    plateaus: list[_Plateau],
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
        _plane_basis(support, None),
        support.offset_camera_m,
        colour,
    )
    tops: list[tuple[float, _Plateau | None]] = [(p.height_m, p) for p in plateaus]
    for box, bottom, tol in zip(boxes, seen.bottoms, tolerance, strict=True):
        # The support, every top, and the box's own ledge.
        levels = [(0.0, None), *tops, *([] if box.ledge_m is None else [(box.ledge_m, None)])]
        slack = faces.resolution_m(box.height_m) + tol
        if (
            bottom is not None
            and bottom.seam
            and any(
                p is not None and p is not box and _beside(p, box, bottom.seam_sides)
                for h, p in levels
                if bottom.low_m - slack <= h <= bottom.high_m + slack
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
    boxes: list[_Plateau],
    plateaus: list[_Plateau],
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


def _flush(lower: _Plateau, box: _Plateau, side: int, tolerance_m: float) -> bool:
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


def _beside(lower: _Plateau, upper: _Plateau, sides: tuple[tuple[float, float], ...]) -> bool:
    """Whether the lower top stands beside the upper box past one of ``sides`` (outward
    normals): a top with BESIDE_MIN_M2 or more of it seen (not the rim of a box under it),
    touching the box, whose rectangle reaches out past that side by more than SEAM_REACH_M."""
    if lower.visible_m2 < BESIDE_MIN_M2 or lower.rect is None or upper.rect is None:
        return False
    if not _touch(lower, upper):
        return False
    rel = lower.rect.corners - np.asarray(upper.rect.middle)
    return any(
        float(np.max(rel @ np.array(o))) - _half_extent(upper.rect, *o) > SEAM_REACH_M
        for o in sides
    )


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
    levels: list[_Plateau | None],
    boxes: list[_Plateau],
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
    slope = _slope(cols_n, rows_n, lens, support.normal_camera)
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


def _is_platform(lower: _Plateau, upper: _Plateau) -> bool:
    """A box's base that is no box of its own: a top that goes on under the box past a hidden
    side (the box hides it), or one mostly covered by what stands on it."""
    if not lower.is_box or lower.rect is None:
        return True
    rect = lower.rect
    if lower.visible_m2 < 0.5 * rect.length_m * rect.width_m:
        return True
    return rect.hidden_sides > 0 and (
        (_reaches_under(lower, upper, slack=-0.0) and not _inside(lower, upper))
        # The box on it hides one of its sides: the top goes on under the box, how far is
        # unknown (seen as a strip beside the box).
        or (_past_hidden_side(lower, upper) and _touch(lower, upper))
    )


def _past_hidden_side(lower: _Plateau, upper: _Plateau) -> bool:
    """Whether the upper box's middle lies out past one of the lower top's hidden sides."""
    if lower.rect is None or upper.rect is None:
        return False
    rect = lower.rect
    rx = upper.rect.middle[0] - rect.middle[0]
    ry = upper.rect.middle[1] - rect.middle[1]
    return any(rx * o0 + ry * o1 > _half_extent(rect, o0, o1) for o0, o1 in rect.hidden_normals)


def _base_rank(level: _Plateau | None, box: _Plateau, matches: int) -> tuple[bool, bool, int]:
    """How a level ranks as a box's base among levels at one height (see :func:`_bases`)."""
    if level is None:
        return (False, False, matches)
    holds = level.rect is not None and _inside(level, box)
    return (holds, level.is_box, matches)


def _inside(lower: _Plateau, upper: _Plateau) -> bool:
    assert lower.rect is not None and upper.rect is not None
    ax0, ax1 = lower.rect.axis
    rx = upper.rect.middle[0] - lower.rect.middle[0]
    ry = upper.rect.middle[1] - lower.rect.middle[1]
    return (
        abs(rx * ax0 + ry * ax1) <= lower.rect.length_m / 2
        and abs(ry * ax0 - rx * ax1) <= lower.rect.width_m / 2
    )


def _touch(a: _Plateau, b: _Plateau) -> bool:
    """Whether two tops' rectangles (grown by 2 cm) overlap: side by side, touching."""
    assert a.rect is not None and b.rect is not None
    gap = 0.02
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
        y_axis = _cross(z_axis, x_axis)
        top = rotation @ top_c + shift
        centre = rotation @ centre_c + shift
        if settings.workspace is not None and not all(
            lo <= value <= hi for value, (lo, hi) in zip(top, settings.workspace, strict=True)
        ):
            continue
        reference = basis[0]
        yaw = math.degrees(
            math.atan2(float(length_c @ _cross(n_c, reference)), float(length_c @ reference))
        )
        if camera_to_world is not None:
            yaw = math.degrees(math.atan2(float(x_axis[1]), float(x_axis[0])))
        yaw = (yaw + 90.0) % 180.0 - 90.0
        if yaw == -90.0:
            yaw = 90.0
        quaternion = _quaternion(np.stack([x_axis, y_axis, z_axis], axis=1))
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
                top_pixels=b.pixels,
                top_middle=_vec(top),
                on=index.get(b.on_plateau) if b.on_plateau is not None else None,
                hidden_sides=rect.hidden_sides,
            )
        )
    if len(result) != len(ordered):
        # The workspace dropped some: "on" must index the list as reported.
        result = [replace(r, on=None) for r in result]
    return result


def _cross(a: Float64Array, b: Float64Array) -> Float64Array:
    """a x b of two 3-vectors (np.cross costs tens of microseconds a call)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _quaternion(m: Float64Array) -> Float64Array:
    """x, y, z, w of a rotation matrix (Shepperd's method: the largest of the four first)."""
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2], trace]))
    if i == 3:
        w = math.sqrt(1.0 + trace) / 2
        q = [
            (m[2, 1] - m[1, 2]) / (4 * w),
            (m[0, 2] - m[2, 0]) / (4 * w),
            (m[1, 0] - m[0, 1]) / (4 * w),
            w,
        ]
    else:
        j, k = (i + 1) % 3, (i + 2) % 3
        big = math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) / 2
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / (4 * big)]
        q[i] = big
        q[j] = (m[j, i] + m[i, j]) / (4 * big)
        q[k] = (m[k, i] + m[i, k]) / (4 * big)
    result: Float64Array = np.asarray(q, dtype=np.float64)
    if result[3] < 0:
        result = -result
    return result / float(np.linalg.norm(result))


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
