"""The tops of what stands on the support, measured: steps 2 to 5 of
:mod:`onebox.perception.boxes`.

:func:`plateaus` takes a depth picture, its lens, the colour picture (or None) and the support,
and returns every flat top as a :class:`Plateau` (its level, tolerance, rectangle, score and
whether it is a box's top), the height above the support of every pixel, and the picture of
which top each pixel belongs to. What each box stands on is :mod:`onebox.perception.bases`.
No I/O here.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage, spatial

from onebox.geometry import Intrinsics
from onebox.perception import segment
from onebox.perception.rectangle import Rectangle, fit_rectangles
from onebox.perception.support import SIGMA_FLOOR_M, Support

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

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
"""The widest band, in pixels on either side of its middle line."""

MIN_WIDTH_M = 0.01
"""A top seen narrower than this is a sliver (the strip of a box showing past a taller one's
foot, a line of flying pixels), not a box: its rectangle says nothing of a box's size."""

NOISY_TOP_AREA_M2 = 0.0009
"""Where depth is noisy (sigma 1 cm and more: a D435 past 1.5 m), a top must be 3 x 3 cm: a
smaller one's plane is a noise clump's, and taken as a box's base it cut tall boxes short."""

RISING_SHARE = 0.02
"""A top narrower than its noise is read along the rays only if less than this share of its
outline sees the surface rise past a band with no reading (a pallet's margin, cartons on it)."""

MAX_PIXELS = 848 * 480
"""The most pixels a picture is read at: a D435's own depth picture (848 x 480) and an Azure
Kinect's (640 x 576) whole. Read at every second pixel, pallets seen through a D435's own
picture and lens (87 degrees) lost one carton in twelve; read whole, one in forty."""


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
    max_pixels: int | None = MAX_PIXELS
    """Larger pictures are read at every k-th pixel (k = 2 for 1280 x 720) to keep camera rate;
    sizes are then good to that coarser footprint. None reads every pixel."""
    colour_shift: tuple[int, int] | None = None
    """BoxFinder: the colour picture's shift against the depth, (dy, dx) whole pixels (see
    :mod:`onebox.perception.register`); None measures it from the pictures."""
    register_every: int = 30
    """BoxFinder: measure the colour's shift on the first picture and every this many after."""


PAD = 12
"""Empty pixels around the working crop, so looking twelve pixels past a top never wraps."""
NEIGHBOURS = 4


@dataclass
class Plateau:
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
    stands_on: Plateau | None = None
    """The top it stands on (None: the support, or a ledge of its own with no top)."""
    platform: bool = False
    """A level others stand on whose own extent is hidden (a pallet's top): never a box."""
    on_platform: bool = False
    """Stands on a platform (a pallet's top), where cartons stand packed side by side."""
    ledge_m: float | None = None
    """The highest flat level seen just past the top's outline (see :func:`_ledges`)."""
    upright: bool = False
    """Its plane fitted along the rays stands more than UPRIGHT_DEG from the support: a side
    face seen nearly edge-on through noise (its readings' spread within the tolerance), no
    level anything stands on."""
    rounded: bool = False
    """Its readings curve down toward its sides as a can's lying down, or a ball's (see
    :func:`_rounded`): nothing stands on it."""
    hidden_band_m: float = 0.0
    """How far, along the support, what rises past the top's hidden outline stands off it
    (median over the hidden outline): a wall rising at the top's edge stands at it, a taller
    object in front of the top hides a band this wide of it."""


@functools.lru_cache(maxsize=8)
def height_slope(
    width: int, height: int, lens: Intrinsics, normal: tuple[float, float, float]
) -> Float32Array:
    """Per pixel, normal . ray (ray = (across, down, 1)): height = depth * slope + offset."""
    across, down = lens.rays(width, height)
    slope = normal[0] * across[np.newaxis, :] + normal[1] * down[:, np.newaxis] + normal[2]
    result: Float32Array = slope.astype(np.float32)
    result.flags.writeable = False
    return result


def plane_basis(support: Support, camera_to_world: Float64Array | None) -> Float64Array:
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
    e2 = cross(n, e1)
    return np.stack([e1, e2, n])


def least_top_area(sigma_m: npt.ArrayLike, settings: FinderSettings) -> Float64Array:
    """The smallest top kept where the noise is ``sigma_m``: ``min_top_area_m2`` where depth is
    clean, (3 sigma)^2 where that is more, up to ``NOISY_TOP_AREA_M2``."""
    low = settings.min_top_area_m2
    noisy = (3.0 * np.asarray(sigma_m, dtype=np.float64)) ** 2
    result: Float64Array = np.clip(noisy, low, max(low, NOISY_TOP_AREA_M2))
    return result


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


def plateaus(
    depth: Float32Array,
    lens: Intrinsics,
    colour: npt.NDArray[np.uint8] | None,
    settings: FinderSettings,
    support: Support,
) -> tuple[list[Plateau], Float32Array, npt.NDArray[np.int32]]:
    """Every flat top, measured together: whole-array work on the crop, then one short
    rectangle fit per top."""
    rows_n, cols_n = depth.shape
    slope = height_slope(cols_n, rows_n, lens, support.normal_camera)
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
    depth_cut = segment.breaks(h, step)
    cut = depth_cut
    colour_cut: BoolArray | None = None
    grey = None
    edge_step = settings.colour_step
    if colour is not None:
        grey = segment.grey(colour[crop])
        edge_step = segment.edge_step(grey, settings.colour_step)
        colour_cut = np.pad(segment.colour_breaks(grey, edge_step), pad)
        cut = depth_cut | colour_cut
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
    p_area = dd * dd * area_scale / np.abs(s_flat[idx])
    areas = np.bincount(lab, weights=p_area, minlength=count + 1)
    areas[0] = 0.0
    # Pieces too small to be a top (a carton's rim cut off by a colour edge, a clump, the cut
    # pixels themselves) may be taken over by the top beside them at the same height.
    least = 0.5 * float(least_top_area(support.sigma_m, settings))
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
    tol = _tolerance(mean_d, noise_k)
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
            _extents(p_idx, p_top, tops_n, width_p),
            pixels,
            float(np.nanmin(d)) / lens.fx,
            lens,
            support,
            (r0 - PAD, c0 - PAD),
        )
    # Without colour nothing cuts a side face off the tops at its ends.
    peeled = None
    if colour is None:
        peeled = _peel(
            p_idx, p_top, p_h, p_d, p_area[mine], level, tol, noise_k, h.shape, 0.5 * least
        )
    if peeled is not None:
        level, tol, on_level = peeled
        reach = np.maximum(tol, FLAT_REACH_M)
        added = len(level) - tops_n
        band = np.concatenate([band, np.zeros(added, dtype=bool)])
        ring = np.concatenate([ring, np.zeros(added, dtype=bool)])
        tops_n = len(level)
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

    def measured(
        count: int, only: BoolArray | None = None, kept: list[Plateau] | None = None
    ) -> tuple[_Tops, list[Plateau], list[Plateau]]:
        """The tops gathered; those ``only`` flags measured (every one without it); those
        measured, and them with ``kept`` in label order."""
        tops = _Tops.gather(top_lab, count, PAD, (r0, c0))
        fresh = _measure_all(
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
            only,
        )
        return tops, fresh, sorted([*(kept or []), *fresh], key=lambda p: p.label)

    # Measured, then looked over for seams between cartons of one shade (colour lines, or a gap
    # seen through at every few pixels along it), split and measured again; then the pieces of
    # one carton's top joined (colour only), and measured again. A top is measured again only
    # if it changed: each is measured on its own pixels and level.
    tops, fresh, plateaus = measured(tops_n)
    for _ in range(SEAM_ROUNDS):
        cells = _seams(
            fresh,
            tops,
            s_flat,
            top_flat,
            h_flat,
            level,
            tol,
            depth_cut.reshape(-1),
            None if colour_cut is None else colour_cut.reshape(-1),
            None if grey is None else grey.reshape(-1),
            settings.colour_step,
            edge_step,
            lens,
            support,
            depth.shape,
        )
        if not cells:
            break
        before = tops_n
        level, tol, tops_n = _split_tops(top_flat, tops, cells, level, tol, h_flat, p_idx, p_top)
        changed = np.zeros(tops_n, dtype=bool)
        changed[[t for t, _ in cells]] = True
        changed[before:] = True
        kept = [p for p in plateaus if not changed[p.label]]
        tops, fresh, plateaus = measured(tops_n, changed, kept)
    if colour_cut is not None and grey is not None:
        across, down = lens.rays(cols_n, rows_n)
        basis = plane_basis(support, None)
        # Twice: a label across the tape lies inside the flaps and tape joined.
        for _ in range(2):
            shades = _Shades(tops, d_flat, grey.reshape(-1), across, down, basis)
            groups = _one_carton(plateaus, top_lab, lens, support, shades, settings.colour_step)
            if not groups:
                break
            level, tol, tops_n, new, joined = _merge_tops(
                top_flat, groups, level, tol, h_flat, p_idx, p_top
            )
            changed = np.zeros(tops_n, dtype=bool)
            changed[joined] = True
            kept = [p for p in plateaus if not changed[new[p.label]]]
            for p in kept:
                p.label = int(new[p.label])
            tops, _, plateaus = measured(tops_n, changed, kept)
    if colour_cut is not None:
        for strip in _print_strips(plateaus):
            strip.is_box = False
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


def _window_mean(
    w: _Windows,
    peak: npt.NDArray[np.intp],
    values: npt.NDArray[np.floating],
    group: npt.NDArray[np.int32],
    count: int,
) -> Float64Array:
    """Per group, the mean of its readings in the window round its ``peak`` bin (0: none)."""
    near = np.abs(w.at - peak[group]) <= w.reach[group, 0]
    total = np.bincount(group[near], weights=values[near], minlength=count)
    result: Float64Array = total / np.maximum(np.bincount(group[near], minlength=count), 1)
    return result


def _levels(
    values: Float32Array, which: npt.NDArray[np.int32], count: int, tol: Float64Array
) -> Float64Array:
    """Per piece, its top's height: the most common height (the most readings within the
    tolerance), then the mean of the readings within the tolerance of it, twice."""
    w = _windows(values, which, count, tol, float(values.min()))
    # The mean of the readings in the fullest window, then within the tolerance of it.
    level = _window_mean(w, w.counts.argmax(axis=1), values, which, count)
    for _ in range(2):
        near = np.abs(values - level[which]) < tol[which]
        total = np.bincount(which[near], weights=values[near], minlength=count)
        number = np.bincount(which[near], minlength=count)
        level = np.where(number > 0, total / np.maximum(number, 1), level)
    result: Float64Array = level
    return result


def _tolerance(mean_d: Float64Array, noise_k: np.float32) -> Float64Array:
    """Each top's tolerance: three sigma of the noise at its mean depth, at least the floor."""
    result: Float64Array = np.maximum(
        3.0 * np.maximum(noise_k * mean_d * mean_d, SIGMA_FLOOR_M), TOP_TOLERANCE_FLOOR_M
    )
    return result


PEEL_ROUNDS = 3
"""How many more tops one piece may hold, found one under another (see :func:`_peel`)."""
PEEL_APART = 3.0
"""A level found in what is left of a piece is a top only if it lies this many of its or the
piece's level's reaches (the larger) from that level."""


def _peel(
    p_idx: npt.NDArray[np.intp],
    p_top: npt.NDArray[np.int32],
    p_h: Float32Array,
    p_d: Float32Array,
    p_area: Float64Array,
    level: Float64Array,
    tol: Float64Array,
    noise_k: np.float32,
    shape: tuple[int, int],
    least_m2: float,
) -> tuple[Float64Array, Float64Array, BoolArray] | None:
    """More tops in one piece: where a side face seen at a slant falls by less than a break
    from pixel to pixel (a camera looking across, or noise that raises the break), it joins the
    top above it to the tops it rises from, and the piece's level is only the largest of them.
    Of each piece's pixels on its level only the largest connected part stays on it; what is
    left of the piece, as connected parts as large as a top, gets a level of its own if that
    lies well apart from the piece's, and so on. ``p_top`` is relabelled in place (new tops
    after the others); returns the levels, tolerances and which pixels lie on their top's
    level, or None if nothing changed."""
    count = len(level)
    on_level = np.abs(p_h - level[p_top]) < np.maximum(tol, FLAT_REACH_M)[p_top]
    found = _largest_part(np.flatnonzero(on_level), on_level, p_idx, p_top, p_area, shape)
    spent = np.zeros(len(p_h), dtype=bool)
    for _ in range(PEEL_ROUNDS):
        rest = np.flatnonzero(~on_level & ~spent)
        if len(rest) == 0 or p_area[rest].sum() < least_m2:
            break
        mask = np.zeros(shape, dtype=bool)
        mask.reshape(-1)[p_idx[rest]] = True
        parts, n = ndimage.label(mask)
        which = parts.reshape(-1)[p_idx[rest]]
        area = np.bincount(which, weights=p_area[rest], minlength=n + 1)
        area[0] = 0.0
        big = np.flatnonzero(area >= least_m2)
        if len(big) == 0:
            break
        lut = np.full(n + 1, -1, dtype=np.int32)
        lut[big] = np.arange(len(big), dtype=np.int32)
        new = lut[which]
        spent[rest[new < 0]] = True
        rest, new = rest[new >= 0], new[new >= 0]
        mean_d = np.bincount(new, weights=p_d[rest], minlength=len(big)) / np.bincount(
            new, minlength=len(big)
        )
        new_tol = _tolerance(mean_d, noise_k)
        new_level = _levels(p_h[rest], new, len(big), new_tol)
        new_reach = np.maximum(new_tol, FLAT_REACH_M)
        near = np.abs(p_h[rest] - new_level[new]) < new_reach[new]
        # A top stands well apart from the level it was left under: the band just under (or
        # over) a level is where a face or a rounded thing goes on falling (or rising).
        first = np.zeros(len(big), dtype=np.intp)
        first[new] = rest
        parent = p_top[first]
        apart = PEEL_APART * np.maximum(new_reach, np.maximum(tol, FLAT_REACH_M)[parent])
        ok = np.abs(new_level - level[parent]) >= apart
        spent[rest[~ok[new]]] = True
        if not ok.any():
            break
        taken = ok[new]
        rest, new, near = rest[taken], (np.cumsum(ok) - 1)[new[taken]], near[taken]
        p_top[rest] = count + new
        level = np.concatenate([level, new_level[ok]])
        tol = np.concatenate([tol, new_tol[ok]])
        count += int(ok.sum())
        on_level[rest] = near
        _largest_part(rest[near], on_level, p_idx, p_top, p_area, shape)
        found = True
    return (level, tol, on_level) if found else None


def _largest_part(
    sel: npt.NDArray[np.intp],
    on_level: BoolArray,
    p_idx: npt.NDArray[np.intp],
    p_top: npt.NDArray[np.int32],
    p_area: Float64Array,
    shape: tuple[int, int],
) -> bool:
    """Of each piece's pixels on its level (``sel``), only the largest connected part stays
    on it (the others, bands across side faces at the top's height, are taken off in place);
    whether any was."""
    if len(sel) == 0:
        return False
    mask = np.zeros(shape, dtype=bool)
    mask.reshape(-1)[p_idx[sel]] = True
    parts, n = ndimage.label(mask)
    which = parts.reshape(-1)[p_idx[sel]]
    pieces = np.unique(p_top[sel])
    if n == len(pieces):
        return False
    area = np.bincount(which, weights=p_area[sel], minlength=n + 1)
    piece_of = np.zeros(n + 1, dtype=np.int64)
    piece_of[which] = p_top[sel]
    order = np.argsort(-area[1:], kind="stable") + 1
    _, first = np.unique(piece_of[order], return_index=True)
    kept = np.zeros(n + 1, dtype=bool)
    kept[order[first]] = True
    on_level[sel[~kept[which]]] = False
    return True


def _bands(
    labels: npt.NDArray[np.int32],
    h: Float32Array,
    d: Float32Array,
    big: npt.NDArray[np.intp],
    extents: npt.NDArray[np.intp],
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
    (three of its four neighbours are the piece). ``extents``: each piece's first and last
    row and column, each past the end (:func:`_extents`); ``origin``: the picture's row and
    column of ``labels``' first."""
    k = min(max(math.ceil(BAND_M / max(footprint_m, 1e-6)), 2), BAND_MAX_PX)
    band = np.zeros(len(big), dtype=bool)
    ring = np.zeros(len(big), dtype=bool)
    is_big = np.zeros(len(counts), dtype=bool)
    is_big[big] = True
    rows_n, cols_n = labels.shape
    normal = np.asarray(support.normal_camera, dtype=np.float64)
    for t, piece in enumerate(big):
        r0, r1, c0, c1 = (int(v) for v in extents[t])
        where = slice(r0, r1), slice(c0, c1)
        tall, wide = r1 - r0, c1 - c0
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


def _extents(
    flat: npt.NDArray[np.intp], group: npt.NDArray[np.int32], count: int, width: int
) -> npt.NDArray[np.intp]:
    """Per group, the bounding box of its pixels (flat indices into rows ``width`` long):
    first row, last row + 1, first column, last column + 1 (what ``ndimage.find_objects``
    gives, for the groups asked about only)."""
    rows, cols = np.divmod(flat, width)
    out = np.empty((count, 4), dtype=np.intp)
    out[:, 0], out[:, 2] = rows.max() + 1, cols.max() + 1
    out[:, 1] = out[:, 3] = -1
    np.minimum.at(out[:, 0], group, rows)
    np.maximum.at(out[:, 1], group, rows)
    np.minimum.at(out[:, 2], group, cols)
    np.maximum.at(out[:, 3], group, cols)
    out[:, 1] += 1
    out[:, 3] += 1
    return out


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

    def subset(self, chosen: BoolArray) -> tuple[_Tops, npt.NDArray[np.intp]]:
        """Only the tops ``chosen`` (one flag a label), their labels unchanged; with each
        kept pixel's place in this one's grouping."""
        at = np.flatnonzero(chosen[self.top])
        counts = np.where(chosen, self.counts, 0)
        starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
        kept = _Tops(
            self.flat[at],
            self.top[at],
            starts,
            counts,
            self.width,
            self.rows[at],
            self.cols[at],
            np.where(chosen, self.row_fill, 0.0),
            np.where(chosen, self.col_fill, 0.0),
            self.shift,
        )
        return kept, at


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


def _correlation(n: int, lump_px: float) -> Float64Array:
    """Correlation at 0 .. n - 1 pixels of errors smoothed by a Gaussian of ``lump_px``."""
    lags = np.arange(n, dtype=np.float64)
    result: Float64Array = (
        np.exp(-lags * lags / (4.0 * lump_px * lump_px))
        if lump_px > 0
        else (lags == 0).astype(np.float64)
    )
    return result


@functools.lru_cache(maxsize=4096)
def _slope_variance(n: int, lump_px: float) -> float:
    """The variance of the least-squares slope (per pixel) through n >= 2 pixels in a row
    whose errors, sigma 1, correlate as :func:`_correlation` says: 12 / (n^3 - n) for
    independent errors; for lumps wider than the row, the slope of one lump."""
    rho = _correlation(n, lump_px)
    x = np.arange(n) - 0.5 * (n - 1)
    auto = np.correlate(x, x, "full")[n - 1 :]
    spread = float(auto[0])
    return (spread + 2.0 * float(rho[1:] @ auto[1:])) / (spread * spread)


@functools.lru_cache(maxsize=4096)
def _mean_variance(n: int, lump_px: float) -> float:
    """The variance of the mean of n pixels in a row (errors as in :func:`_slope_variance`):
    1 / n for independent errors; for lumps wider than the row, 1."""
    rho = _correlation(n, lump_px)
    return (n + 2.0 * float(rho[1:] @ (n - np.arange(1, n)))) / (n * n)


def noise_tilt_deg(
    length_px: float, width_px: float, sigma_m: float, footprint_m: float, lump_px: float
) -> float:
    """How far, degrees, depth noise of ``sigma_m`` may tilt the plane fitted to a flat top of
    ``length_px`` x ``width_px`` pixels (``footprint_m`` apart): ``TILT_NOISE_SIGMAS``
    standard deviations of the tilt it gives. The slope along each side is the slope of a row
    of readings, averaged over the rows. Lumps (:attr:`Support.lump_px`) tilt a top narrower
    than them as a whole, and leave a wider one fewer independent readings to average."""
    variance = 0.0
    lump = round(lump_px, 1)
    for along, across in ((length_px, width_px), (width_px, length_px)):
        slope = _slope_variance(max(2, min(round(along), MAX_NOISE_ROW_PX)), lump)
        variance += slope * _mean_variance(max(1, min(round(across), MAX_NOISE_ROW_PX)), lump)
    spread = TILT_NOISE_SIGMAS * sigma_m * math.sqrt(variance) / max(footprint_m, 1e-9)
    return math.degrees(math.atan(spread))


def _level(
    tilt: float,
    ray_tilt: float,
    rising: float,
    rect: Rectangle,
    settings: FinderSettings,
    noise_deg: float = 0.0,
) -> bool:
    """Whether a top lies parallel to the support: by its moments' least axis, or, for a top
    narrower than its depth noise (whose least axis turns across it), by its plane fitted
    along the rays when at least three of its sides are seen falling away (edges, or the
    dropout a stereo camera leaves at them): a box standing free, not the strip of a lower top
    seen past a box on it, nor a pallet's margin, which a rising face bounds.

    A long top seen whole, nothing rising past it, may be tilted by either as much as the
    depth noise tilts a flat top of its size (``noise_deg``, :func:`noise_tilt_deg`): a stereo
    camera's lumps tilt a narrow top far off 2 m away. Not a squarish one: a ball's or a
    standing can's round top is cut unevenly by the tolerance and tilts as far, its dome
    hidden in the lumps."""
    limit = settings.max_top_tilt_deg
    if tilt <= limit:
        return True
    falling = set(rect.edge_normals) | set(rect.dropout_normals)
    if ray_tilt <= limit and len(falling) >= 3 and rising < RISING_SHARE:
        return True
    return (
        rect.hidden_sides == 0
        and rising < RISING_SHARE
        and rect.length_m >= LONG_ASPECT * rect.width_m
        and min(tilt, ray_tilt) <= noise_deg
    )


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
    only: BoolArray | None = None,
) -> list[Plateau]:
    """Every top's plane, outline, rectangle and score; which of them are boxes. With
    ``only`` (one flag a label), only those tops, measured as they are among all of them."""
    rows_n, cols_n = shape
    count = len(level)
    # The top's plane from its moments, all tops at once, on a sample of at most ~6k pixels
    # (every k-th of the grouped pixels: each top keeps its share).
    k = max(1, len(tops.top) // 6_000)
    sample: slice | BoolArray = slice(k // 2, None, k)
    if only is not None:
        tops, at = tops.subset(only)
        sample = at % k == k // 2
    top = tops.top
    across, down = lens.rays(cols_n, rows_n)
    basis = plane_basis(support, None)
    d = d_flat[tops.flat]
    pixel_area = d * d
    pixel_area /= np.abs(s_flat[tops.flat])
    pixel_area *= np.float32(1.0 / (lens.fx * lens.fy))
    n = np.maximum(tops.counts, 1).astype(np.float64)
    area = np.bincount(top, weights=pixel_area, minlength=count)
    mean_area = area / n
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
    a, b = _in_plane(basis, across[tops.cols[edge]], down[tops.rows[edge]], d[edge])
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
    near_steps, far_steps = np.arange(1, 4), np.arange(4, PAD + 1)
    for offset in offsets:
        off = label_at[e_flat + offset] != e_top + 1
        beyond = h_flat[e_flat + offset]
        rise = np.fmax(np.fmax(beyond, h_flat[e_flat + 2 * offset]), h_flat[e_flat + 3 * offset])
        with np.errstate(invalid="ignore"):
            risen = off & (rise > e_level)
            hidden |= risen
            at = np.flatnonzero(risen)
            # The rising points 1 to 3 pixels past: the nearest of them sets the stand-off.
            f = e_flat[at, np.newaxis] + near_steps * offset
            up = h_flat[f] > e_level[at, np.newaxis]
            f, on = f[up], np.broadcast_to(at[:, np.newaxis], up.shape)[up]
            r, c = np.divmod(f, tops.width)
            pa, pb = _in_plane(basis, across[c + tops.shift[1]], down[r + tops.shift[0]], d_flat[f])
            np.fmin.at(stand_off, on, np.hypot(pa - a[on], pb - b[on]))
            unsure |= off & np.isnan(beyond)
            # Past a band with no reading (a stereo camera's at a depth edge, as wide as a
            # steep face seen past it and the band each side of that), the first reading says
            # whether the surface rises there.
            gap = np.flatnonzero(off & np.isnan(rise))
            beyond_far = h_flat[e_flat[gap, np.newaxis] + far_steps * offset]
            read = ~np.isnan(beyond_far)
            first = beyond_far[np.arange(len(gap)), read.argmax(axis=1)]
            risen_far[gap[read.any(axis=1) & (first > e_level[gap])]] = True
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
    eligible = (tops.counts >= 6) & (whole_area >= least_top_area(sigma, settings))
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
    loose = _loose_groups(p_idx, p_top, p_h, level, reach, count, only)
    plateaus: list[Plateau] = []
    # The tops that are boxes unless they are round, and their rectangles' axes.
    candidates: list[Plateau] = []
    axes: list[Float64Array] = []
    for t in range(count):
        if tops.counts[t] < 6:
            continue
        p = Plateau(
            t,
            float(level[t]),
            float(tol[t]),
            int(tops.counts[t]),
            float(footprint[t]),
            float(area[t]),
        )
        p.ledge_m = None if np.isnan(ledge[t]) else float(ledge[t])
        p.upright = bool(tilt[t] > settings.max_top_tilt_deg and ray_tilt[t] > UPRIGHT_DEG)
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
        # sides: a disc's sides fitted by medians would hug it. Where the noise leaves the
        # outline clean, a stray pixel or two at each end (a noise spike, a side face's first
        # reading within the tolerance) is left out: a narrow top's fill fell by a tenth.
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        part = slice(int(edge_starts[t]), int(edge_stops[t]))
        points = np.stack([fill_a[part], fill_b[part]], axis=1)
        on_axis, on_perp = points @ ax, points @ perp
        rect_area = (np.ptp(on_axis) + footprint[t]) * (np.ptp(on_perp) + footprint[t])
        clean = tol[t] <= RAGGED_TOLERANCE_M
        # Across a long narrow top whose long sides both drop away or end in the camera's
        # dropout (a box's, not a scrap of a carton's top cut off by colour), by its long
        # sides' many outline points.
        thin = rect.hidden_sides == 0 and rect.length_m >= THIN_ASPECT * rect.width_m
        thin = thin and _falls_both_ways(rect, perp)
        fill_area = _extent(on_axis, float(footprint[t]), clean, False) * _extent(
            on_perp, float(footprint[t]), clean, thin
        )
        fill = min(float(whole_area[t]) / fill_area, 1.0)
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
            # and stays what it is). The hull holds every stray pixel: so does its rectangle.
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
        if (
            tol[t] <= LATTICE_TOLERANCE_M
            and fill * flatness < settings.min_score
            and rect.hidden_sides == 0
            and not hidden[part].any()
            and rect.length_m >= LATTICE_ASPECT * rect.width_m
        ):
            # A small oblong top seen whole, turned on the pixel grid: its outermost outline
            # points stand in of its sides by far less than a footprint (a 10 x 10 pixel
            # rectangle turned 5-40 degrees fills 0.84 by the footprint's measure). Measured
            # as a straight side is, by how many points lie near the outermost, a rectangle of
            # any size and turn fills 0.93 or more on the pixel grid. So may a small round
            # top (a ball's or a tin's, 6-10 pixels across, filled 0.93-0.96): a squarish
            # top is measured by the footprint alone. (A top partly hidden has its own
            # measure above: the part of its rectangle seen.)
            lattice_area = _extent(on_axis, float(footprint[t]), clean, True) * _extent(
                on_perp, float(footprint[t]), clean, True
            )
            lattice_fill = min(float(whole_area[t]) / lattice_area, 1.0)
            if lattice_fill >= LATTICE_MIN_FILL:
                fill = lattice_fill
        p.score = fill * flatness
        rising = float(risen_far[part].mean()) if part.stop > part.start else 0.0
        if p.score < settings.min_score:
            continue
        noise_deg = 0.0
        if tilt[t] > settings.max_top_tilt_deg:
            noise_deg = noise_tilt_deg(
                rect.length_m / footprint[t],
                rect.width_m / footprint[t],
                float(sigma[t]),
                float(footprint[t]),
                support.lump_px,
            )
        if not _level(tilt[t], ray_tilt[t], rising, rect, settings, noise_deg):
            continue
        # Curved tops widen when the tolerance is loosened; a box's sides drop straight down.
        wide = loose[t]
        if len(wide) > tops.counts[t] and _growth(wide, tops, d_flat, lens, basis, points, ax) > (
            settings.max_curvature_growth
        ):
            continue
        candidates.append(p)
        axes.append(ax)
    # A can lying down or a bottle's rounded top: its top is the part of its curve within
    # the tolerance, flat enough for the moments' plane; the readings curve down.
    if candidates:
        labels = [p.label for p in candidates]
        # Every k-th of each top's pixels, at most ~3000 a top.
        picks = [
            np.arange(int(tops.starts[t]), int(tops.starts[t] + tops.counts[t]))[
                :: max(1, int(tops.counts[t]) // 3_000)
            ]
            for t in labels
        ]
        mine = np.concatenate(picks)
        group = np.repeat(np.arange(len(picks)), [len(pick) for pick in picks])
        mine_a, mine_b = _in_plane(basis, across[tops.cols[mine]], down[tops.rows[mine]], d[mine])
        rounded = _rounded(
            mine_a, mine_b, h_flat[tops.flat[mine]], group, np.array(axes), tol[labels]
        )
        for p, is_round in zip(candidates, rounded, strict=True):
            p.rounded = bool(is_round)
            p.is_box = not is_round
    return plateaus


def _in_plane(
    basis: Float64Array, ray_x: npt.ArrayLike, ray_y: npt.ArrayLike, depth: npt.ArrayLike
) -> tuple[Float64Array, Float64Array]:
    """The support plane's coordinates (``basis`` rows 0 and 1) of the points ``depth`` along
    the rays (ray_x, ray_y, 1) of the camera's frame."""
    d = np.asarray(depth, dtype=np.float64)
    x, y = np.asarray(ray_x) * d, np.asarray(ray_y) * d
    a: Float64Array = basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * d
    b: Float64Array = basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * d
    return a, b


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
GAP_TOLERANCES = 2.0
"""A pixel seen down the gap between two cartons lies this many of their top's tolerances under
it (noise alone leaves holes in a top no deeper than about one)."""
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


TAPE_WIDTHS_M = (0.03, 0.08)
"""Packing tape is 48 or 72 mm wide (narrower on small cartons)."""


@dataclass
class _Shades:
    """The tops' pixels' places on the support plane and their brightness, on demand."""

    tops: _Tops
    d_flat: Float32Array
    grey_flat: npt.NDArray[np.int16]
    across: Float64Array
    """Each picture column's ray's x (and ``down``, each row's y), at depth 1."""
    down: Float64Array
    basis: Float64Array

    def tape_edge(self, wide: Plateau, narrow: Plateau, colour_step: float) -> bool:
        """Whether ``wide`` is a flap and the tape beside it, ``narrow`` the other flap (colour
        cut the tape's far edge only; its near one is a soft step, two small ones): along
        the side that meets ``narrow``, a band as wide as the tape (the wide one's width less
        the narrow one's) of another shade than the rest, and the rest of ``narrow``'s."""
        assert wide.rect is not None and narrow.rect is not None
        tape = wide.rect.width_m - narrow.rect.width_m
        if not TAPE_WIDTHS_M[0] <= tape <= TAPE_WIDTHS_M[1]:
            return False
        ax = np.asarray(wide.rect.axis)
        perp = np.array([-ax[1], ax[0]])
        if (np.asarray(narrow.rect.middle) - np.asarray(wide.rect.middle)) @ perp < 0:
            perp = -perp
        a, b, g = self._pixels(wide.label)
        out = (a - wide.rect.middle[0]) * perp[0] + (b - wide.rect.middle[1]) * perp[1]
        edge = wide.rect.width_m / 2 - tape
        margin = max(0.005, 2.0 * wide.footprint_m)
        band, rest = g[out > edge + margin], g[out < edge - margin]
        if len(band) < 6 or len(rest) < 6:
            return False
        shade_band, shade_rest = float(np.median(band)), float(np.median(rest))
        return (
            abs(shade_band - shade_rest) >= colour_step / 2
            and abs(shade_rest - self._shade(narrow.label)) < colour_step / 2
        )

    def banded(self, a: Plateau, band: Plateau, b: Plateau, colour_step: float) -> bool:
        """Whether ``band`` (between ``a`` and ``b``) is print across one top: ``a`` and
        ``b`` of one shade, ``band`` of another."""
        shade_a, shade_band, shade_b = (self._shade(p.label) for p in (a, band, b))
        return (
            abs(shade_a - shade_b) < colour_step / 2
            and abs(shade_band - (shade_a + shade_b) / 2) >= colour_step / 2
        )

    def _shade(self, label: int) -> float:
        tops = self.tops
        part = slice(int(tops.starts[label]), int(tops.starts[label] + tops.counts[label]))
        return float(np.median(self.grey_flat[tops.flat[part]]))

    def _pixels(self, label: int) -> tuple[Float64Array, Float64Array, npt.NDArray[np.int16]]:
        tops = self.tops
        part = slice(int(tops.starts[label]), int(tops.starts[label] + tops.counts[label]))
        flat = tops.flat[part]
        a, b = _in_plane(
            self.basis,
            self.across[tops.cols[part]],
            self.down[tops.rows[part]],
            self.d_flat[flat],
        )
        return a, b, self.grey_flat[flat]


PARALLEL_SIN = math.sin(math.radians(4.0))
"""Two pieces of one carton's top lie parallel within this angle (4 degrees)."""


def _one_carton(
    plateaus: list[Plateau],
    top_lab: npt.NDArray[np.int32],
    lens: Intrinsics,
    support: Support,
    shades: _Shades,
    colour_step: float,
) -> list[list[int]]:
    """Pieces of one carton's top that its own print cut apart by colour, as groups of top
    labels to join: a label or a print (a piece at the top's level with the top all round
    it), and a taped carton's flaps and tape (pieces side by side along their length, of one
    length, their widths symmetric about the middle line of the whole, which runs along its
    length: a carton's flaps meet on the middle line along its length, and the tape covers
    it; or two pieces, one a flap and the other the tape and a flap of the first one's shade,
    where colour cut only one of the tape's edges). Touching cartons of one height stay apart:
    a row end to end meets across its length, and two side by side make one top only if each
    is under half as wide as long and they are of one width."""
    placed = [p for p in plateaus if p.rect is not None]
    joined = {p.label: p.label for p in placed}

    def root(label: int) -> int:
        while joined[label] != label:
            label = joined[label]
        return label

    def level_with(a: Plateau, b: Plateau) -> bool:
        return abs(a.height_m - b.height_m) < max(
            math.hypot(a.tolerance_m, b.tolerance_m), FLAT_REACH_M
        )

    cam = plane_basis(support, None)
    for inner in placed:
        for outer in placed:
            if (
                outer is not inner
                and _rect_area(outer) > _rect_area(inner)
                and level_with(outer, inner)
                and _within(inner, outer)
                and _surrounded(inner, outer, top_lab, lens, support, cam, shades.tops.shift)
            ):
                joined[inner.label] = outer.label
                break
    hosts = [p for p in placed if joined[p.label] == p.label]
    row_of = {p.label: p.label for p in hosts}

    def row_root(label: int) -> int:
        while row_of[label] != label:
            label = row_of[label]
        return label

    for i, a in enumerate(hosts):
        for b in hosts[i + 1 :]:
            if level_with(a, b) and _side_by_side(a, b):
                row_of[row_root(b.label)] = row_root(a.label)
    rows: dict[int, list[int]] = {}
    for p in hosts:
        rows.setdefault(row_root(p.label), []).append(p.label)
    by_label = {p.label: p for p in hosts}
    for row in rows.values():
        if len(row) < 2:
            continue
        pieces = [by_label[t] for t in row]
        for group in _flaps_and_tape(pieces, shades, colour_step):
            for t in group[1:]:
                joined[t] = group[0]
    groups: dict[int, list[int]] = {}
    for label in joined:
        groups.setdefault(root(label), []).append(label)
    return [sorted(g) for g in groups.values() if len(g) > 1]


def _rect_area(top: Plateau) -> float:
    return top.rect.length_m * top.rect.width_m if top.rect is not None else 0.0


def _within(inner: Plateau, outer: Plateau) -> bool:
    """Whether ``inner``'s rectangle lies inside ``outer``'s, give or take 2 cm."""
    assert inner.rect is not None and outer.rect is not None
    a, b = inner.rect, outer.rect
    cos, sin = b.axis
    mx, my = a.middle[0] - b.middle[0], a.middle[1] - b.middle[1]
    along, across = mx * cos + my * sin, my * cos - mx * sin
    return (
        abs(along) + a.half_extent(cos, sin) <= b.length_m / 2 + 0.02
        and abs(across) + a.half_extent(-sin, cos) <= b.width_m / 2 + 0.02
    )


def _surrounded(
    inner: Plateau,
    outer: Plateau,
    top_lab: npt.NDArray[np.int32],
    lens: Intrinsics,
    support: Support,
    cam: Float64Array,
    shift: tuple[int, int],
) -> bool:
    """Whether ``outer``'s pixels lie just past each side of ``inner``'s rectangle (on at least
    three of five points along the side), or past three sides, the fourth on ``outer``'s own
    edge (a flap of a carton taped round its ends as well, an H of tape round it)."""
    assert inner.rect is not None and outer.rect is not None
    rect = inner.rect
    ax = np.asarray(rect.axis)
    perp = np.array([-ax[1], ax[0]])
    out = max(0.006, 4.0 * inner.footprint_m)
    along = np.linspace(-0.35, 0.35, 5)
    points = []
    for normal, side, half, half_side in (
        (ax, perp, rect.length_m / 2, rect.width_m / 2),
        (-ax, perp, rect.length_m / 2, rect.width_m / 2),
        (perp, ax, rect.width_m / 2, rect.length_m / 2),
        (-perp, ax, rect.width_m / 2, rect.length_m / 2),
    ):
        points.append(
            np.asarray(rect.middle)
            + (half + out) * normal
            + (2.0 * half_side * along)[:, np.newaxis] * side
        )
    flat = np.concatenate(points)  # 20 x 2
    pts = (
        flat[:, :1] * cam[0]
        + flat[:, 1:] * cam[1]
        + (inner.height_m - support.offset_camera_m) * cam[2]
    )
    z = pts[:, 2]
    if np.any(z <= 0):
        return False
    col = np.rint(lens.fx * pts[:, 0] / z + lens.cx).astype(np.intp) - shift[1]
    row = np.rint(lens.fy * pts[:, 1] / z + lens.cy).astype(np.intp) - shift[0]
    inside = (row >= 0) & (row < top_lab.shape[0]) & (col >= 0) & (col < top_lab.shape[1])
    hit = np.zeros(len(z), dtype=bool)
    hit[inside] = top_lab[row[inside], col[inside]] == outer.label + 1
    bordered = hit.reshape(4, -1).sum(axis=1) >= 3
    if bordered.all():
        return True
    if bordered.sum() < 3:
        return False
    k = int(np.argmin(bordered))
    normal = (ax, -ax, perp, -perp)[k]
    own = float(np.asarray(rect.middle) @ normal) + (rect.length_m if k < 2 else rect.width_m) / 2
    o = outer.rect
    reach = float(np.asarray(o.middle) @ normal) + o.half_extent(*normal)
    return abs(reach - own) < max(0.015, 3.0 * outer.footprint_m)


def _side_by_side(a: Plateau, b: Plateau) -> bool:
    """Two tops lying parallel, of one length, ends level, their long sides touching. Through
    noise an end reads up to a tolerance long (a side face's first readings within it of the
    top), so the lengths and ends may differ by half the larger tolerance as well."""
    assert a.rect is not None and b.rect is not None
    (a0, a1), (b0, b1) = a.rect.axis, b.rect.axis
    if abs(a0 * b1 - a1 * b0) > PARALLEL_SIN:
        return False
    length = max(a.rect.length_m, b.rect.length_m)
    slack = max(0.012, 0.05 * length, 0.5 * max(a.tolerance_m, b.tolerance_m))
    if abs(a.rect.length_m - b.rect.length_m) > slack:
        return False
    dx, dy = b.rect.middle[0] - a.rect.middle[0], b.rect.middle[1] - a.rect.middle[1]
    if abs(dx * a0 + dy * a1) > slack:
        return False
    gap = abs(dy * a0 - dx * a1) - (a.rect.width_m + b.rect.width_m) / 2
    return -0.01 < gap < max(0.015, 4.0 * max(a.footprint_m, b.footprint_m))


def _flaps_and_tape(row: list[Plateau], shades: _Shades, colour_step: float) -> list[list[int]]:
    """A row of pieces side by side (:func:`_side_by_side`), split into cartons' tops: up to
    four pieces, no wider together than long, whose widths mirror about their middle, the
    inner ones no wider together than tape (flaps and the tape, or its halves); two that
    mirror, or that :meth:`_Shades.tape_edge` says are a flap and a flap with the tape; or
    three, the middle one a strip of print between two of one shade (a band printed across
    a carton, a strap), no wider together than twice their length."""
    assert row[0].rect is not None
    ax = np.asarray(row[0].rect.axis)
    perp = np.array([-ax[1], ax[0]])
    row = sorted(row, key=lambda p: float(np.asarray(p.rect.middle) @ perp) if p.rect else 0.0)
    across = [float(np.asarray(p.rect.middle) @ perp) for p in row if p.rect is not None]
    widths = [p.rect.width_m for p in row if p.rect is not None]
    lengths = [p.rect.length_m for p in row if p.rect is not None]

    def group_score(start: int, end: int) -> int:
        """3 for flaps and tape, 1 for two halves (or a flap and a flap with the tape), 0 for
        no carton's top."""
        size = end - start
        w = widths[start:end]
        whole = across[end - 1] + w[-1] / 2 - (across[start] - w[0] / 2)
        length = max(lengths[start:end])
        if (
            size == 3
            and w[1] <= PRINT_STRIP_M
            and whole <= 2.0 * length
            and shades.banded(row[start], row[start + 1], row[start + 2], colour_step)
        ):
            return 3
        if whole > 1.05 * length:
            return 0
        slack = max(0.012, 0.12 * whole)
        mirrored = all(abs(w[k] - w[-1 - k]) < slack for k in range(size // 2))
        if size == 2:
            wide, narrow = sorted(row[start:end], key=lambda p: -(p.rect.width_m if p.rect else 0))
            return 1 if mirrored or shades.tape_edge(wide, narrow, colour_step) else 0
        # The inner pieces are the tape (or its halves, with the flaps' line between).
        return 3 if mirrored and whole - w[0] - w[-1] <= TAPE_WIDTHS_M[1] + 0.01 else 0

    # The partition of the row that finds the most (flaps and tape first): a row that starts
    # with another carton's flap pairs no flap with its neighbour's.
    best = [0] * (len(row) + 1)
    cut: list[int] = [0] * (len(row) + 1)
    for end in range(1, len(row) + 1):
        best[end], cut[end] = best[end - 1], end - 1
        for size in (2, 3, 4):
            start = end - size
            if start >= 0:
                score = group_score(start, end)
                if score and best[start] + score > best[end]:
                    best[end], cut[end] = best[start] + score, start
    groups = []
    end = len(row)
    while end > 0:
        start = cut[end]
        if end - start > 1:
            groups.append([p.label for p in row[start:end]])
        end = start
    return groups


PRINT_STRIP_M = 0.08
"""The widest strip of print (packing tape is 48 or 72 mm) taken for part of a top."""


def _print_strips(plateaus: list[Plateau]) -> list[Plateau]:
    """Boxes' tops with a top at their level touching two opposite sides, across which they
    span no more than ``PRINT_STRIP_M``: a strip or a patch of tape or print that colour cut
    out of a top and that could not be joined back (the tape of a carton that a box on it
    hides in part), not a box. A narrow carton packed between two of its height is one too,
    and is lost."""
    tops = [p for p in plateaus if p.rect is not None]
    strips = []
    for strip in tops:
        rect = strip.rect
        if not strip.is_box or rect is None or rect.width_m > PRINT_STRIP_M:
            continue
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        level = [
            other
            for other in tops
            if other is not strip
            and abs(other.height_m - strip.height_m)
            < max(math.hypot(other.tolerance_m, strip.tolerance_m), FLAT_REACH_M)
        ]
        for out, side, span, extent in (
            (perp, ax, rect.width_m, rect.length_m),
            (ax, perp, rect.length_m, rect.width_m),
        ):
            if span <= PRINT_STRIP_M and len(_touching(strip, level, out, side, extent)) == 2:
                strips.append(strip)
                break
    return strips


def scraps(
    candidates: list[Plateau], plateaus: list[Plateau], standing: bool = False
) -> list[Plateau]:
    """Of ``candidates``, the tops no more than ``PRINT_STRIP_M`` across with a top at their
    level touching one side and a box standing at their level touching another (the opposite
    side, or, if the top is no longer than that either, any): what shows of a carton's flaps
    and tape round a smaller carton on it, cut apart by colour, not boxes of their own. Before
    the bases are known (``standing`` False) any higher top counts as standing at their level.
    A narrow box packed against a carton of its height and a box on that carton is lost."""
    tops = [p for p in plateaus if p.rect is not None]
    found = []
    for scrap in candidates:
        rect = scrap.rect
        if rect is None or rect.width_m > PRINT_STRIP_M:
            continue
        level, above = [], []
        for other in tops:
            if other is scrap:
                continue
            # Level within the tolerances alone: flaps and tape are one sheet.
            reach = math.hypot(other.tolerance_m, scrap.tolerance_m)
            if abs(other.height_m - scrap.height_m) < reach:
                level.append(other)
            elif other.height_m > scrap.height_m and (
                not standing or (other.is_box and abs(other.base_m - scrap.height_m) < reach)
            ):
                above.append(other)
        if not level or not above:
            continue
        ax = np.asarray(rect.axis)
        perp = np.array([-ax[1], ax[0]])
        beside_any = on_any = False
        for out, side, span, extent in (
            (perp, ax, rect.width_m, rect.length_m),
            (ax, perp, rect.length_m, rect.width_m),
        ):
            if span > PRINT_STRIP_M:
                continue
            beside = _touching(scrap, level, out, side, extent)
            on = _touching(scrap, above, out, side, extent)
            if beside and on and len(beside | on) == 2:
                found.append(scrap)
                break
            beside_any |= bool(beside)
            on_any |= bool(on)
        else:
            if beside_any and on_any and rect.length_m <= PRINT_STRIP_M:
                found.append(scrap)
    return found


def flaps(
    candidates: list[Plateau], plateaus: list[Plateau], standing: bool = False
) -> list[Plateau]:
    """Of ``candidates``, the flaps of a taped carton seen round a smaller box standing on it:
    tops beside a strip of tape at their level (no more than ``PRINT_STRIP_M`` across, with
    a top at its level along most of its length on both sides, one of them the flap) that
    runs under a higher box (:func:`_is_tape`). The carton's top, cut apart by its tape and
    by the box on it, is a level, not boxes of their own. Before the bases are known
    (``standing`` False) any higher box counts; after, only one standing at their level. A
    carton packed between a narrow one of its height and another, under a box across the
    narrow one's end, is lost."""
    placed = [p for p in plateaus if p.rect is not None]
    found = []
    for flap in candidates:
        if flap.rect is None:
            continue
        reach = [max(math.hypot(o.tolerance_m, flap.tolerance_m), FLAT_REACH_M) for o in placed]
        level = [
            o for o, r in zip(placed, reach, strict=True) if abs(o.height_m - flap.height_m) < r
        ]
        above = [
            o
            for o, r in zip(placed, reach, strict=True)
            if o.is_box
            and o.height_m > flap.height_m + r
            and (not standing or abs(o.base_m - flap.height_m) < r)
        ]
        if any(_is_tape(tape, flap, level, above) for tape in level if tape is not flap):
            found.append(flap)
    return found


def _is_tape(tape: Plateau, flap: Plateau, level: list[Plateau], above: list[Plateau]) -> bool:
    """Whether ``tape`` is a strip of tape beside ``flap``: no more than ``PRINT_STRIP_M``
    across, with tops of ``level`` along most of its length on both sides, ``flap`` one of
    them, and a box of ``above`` across its end (:func:`_across_end`). A strip no longer than
    that either (a stub of tape past a box's end) may run either way."""
    rect = tape.rect
    if rect is None or rect.width_m > PRINT_STRIP_M:
        return False
    ax = np.asarray(rect.axis)
    perp = np.array([-ax[1], ax[0]])
    others = [o for o in level if o is not tape]
    for out, side, span, extent in (
        (perp, ax, rect.width_m, rect.length_m),
        (ax, perp, rect.length_m, rect.width_m),
    ):
        if (
            span <= PRINT_STRIP_M
            and _touching(tape, [flap], out, side, extent)
            and any(_across_end(tape, box, side, extent, span) for box in above)
            and len(_touching(tape, others, out, side, extent)) == 2
            # A stub run across its rectangle's length: the tops either side are one
            # carton's flaps, of one width across it (not the next carton packed against one).
            and (side is ax or _one_width(tape, others, out, side, extent))
        ):
            return True
    return False


def _one_width(
    strip: Plateau, others: list[Plateau], out: Float64Array, side: Float64Array, extent: float
) -> bool:
    """Whether the tops of ``others`` touching ``strip``'s two sides along ``side`` are as
    wide across it, within a quarter."""
    widths: dict[int, list[float]] = {}
    for other in others:
        ends = _touching(strip, [other], out, side, extent)
        if len(ends) == 1:
            assert other.rect is not None
            widths.setdefault(ends.pop(), []).append(2.0 * other.rect.half_extent(*out))
    if len(widths) < 2:
        return False
    near, far = max(widths[1]), max(widths[-1])
    return bool(min(near, far) >= 0.75 * max(near, far))


def _across_end(
    strip: Plateau, box: Plateau, along: Float64Array, length_m: float, width_m: float
) -> bool:
    """Whether ``box`` stands across an end of ``strip`` (``length_m`` along ``along``,
    ``width_m`` across), along most of its width and at least twice as wide: touching it (its
    rectangle may overlap the strip's by a couple of centimetres), or, where the strip's end
    is hidden (the box's face in front of it), as far off as what hides it stands."""
    assert strip.rect is not None and box.rect is not None
    across = np.array([-along[1], along[0]])
    offset = np.asarray(box.rect.middle) - np.asarray(strip.rect.middle)
    away = float(offset @ along)
    gap = abs(away) - box.rect.half_extent(*along) - length_m / 2
    end = np.sign(away) * along
    hidden = any(float(end @ np.asarray(n)) > 0.7 for n in strip.rect.hidden_normals)
    limit = max(0.015, 4.0 * strip.footprint_m) + (strip.hidden_band_m if hidden else 0.0)
    middle = float(offset @ across)
    half = box.rect.half_extent(*across)
    overlap = min(width_m / 2, middle + half) - max(-width_m / 2, middle - half)
    # ... and at least twice as wide across it: a box on a taped carton stands on its flaps
    # either side of the tape too.
    return -0.02 < gap < limit and overlap > 0.5 * width_m and half >= width_m


def _touching(
    strip: Plateau, others: list[Plateau], out: Float64Array, side: Float64Array, extent: float
) -> set[int]:
    """Which ends of ``out`` (+1, -1) tops of ``others`` touch along most of the strip's
    side there (``extent`` long, along ``side``)."""
    assert strip.rect is not None
    rect = strip.rect
    span = 2.0 * rect.half_extent(*out)
    ends = set()
    for other in others:
        o = other.rect
        assert o is not None
        offset = np.asarray(o.middle) - np.asarray(rect.middle)
        half_out, half_side = o.half_extent(*out), o.half_extent(*side)
        away = float(offset @ out)
        gap = abs(away) - half_out - span / 2
        along = float(offset @ side)
        overlap = min(extent / 2, along + half_side) - max(-extent / 2, along - half_side)
        if -0.01 < gap < max(0.015, 4.0 * strip.footprint_m) and overlap > 0.5 * extent:
            ends.add(1 if away > 0 else -1)
    return ends


def _merge_tops(
    top_flat: npt.NDArray[np.int32],
    groups: list[list[int]],
    level: Float64Array,
    tol: Float64Array,
    h_flat: Float32Array,
    p_idx: npt.NDArray[np.intp],
    p_top: npt.NDArray[np.int32],
) -> tuple[Float64Array, Float64Array, int, npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Each group of tops becomes one (the labels renumbered from 0 without gaps);
    ``top_flat`` and ``p_top`` are relabelled in place; returns the levels and tolerances, one
    per top, the number of tops, each old label's new one and the new labels of the joined."""
    target = np.arange(len(level))
    for group in groups:
        target[group] = group[0]
    kept = np.unique(target)
    new = np.searchsorted(kept, target)
    lut = np.concatenate([[0], new + 1]).astype(np.int32)
    labelled = np.flatnonzero(top_flat)
    top_flat[labelled] = lut[top_flat[labelled]]
    p_top[:] = new[p_top]
    count = len(kept)
    merged_tol = np.zeros(count)
    np.maximum.at(merged_tol, new, tol)
    merged_level = level[kept]
    joined = np.unique(new[[g[0] for g in groups]])
    is_joined = np.zeros(count + 1, dtype=bool)
    is_joined[joined + 1] = True
    on = labelled[is_joined[top_flat[labelled]]]
    own = _levels(h_flat[on], top_flat[on] - 1, count, merged_tol)
    merged_level[joined] = own[joined]
    return merged_level, merged_tol, count, new, joined


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
    plateaus: list[Plateau],
    tops: _Tops,
    s_flat: Float32Array,
    top_flat: npt.NDArray[np.int32],
    h_flat: Float32Array,
    level: Float64Array,
    tol: Float64Array,
    depth_cut_flat: BoolArray,
    cut_flat: BoolArray | None,
    grey_flat: npt.NDArray[np.int16] | None,
    colour_step: float,
    edge_step: float,
    lens: Intrinsics,
    support: Support,
    shape: tuple[int, int],
) -> list[tuple[int, npt.NDArray[np.intp]]]:
    """Tops that straight lines of colour edges or dark valleys, or of pixels beside ones seen
    far down a gap, cross from side to side, parallel to a side of their rectangle, with the
    top going on past them on both sides (the seams between cartons of one shade, along and
    across; cartons a pixel or less apart, whose gap the pixels see down at every few along
    it): per such top, its label and each of its pixels' cell between the lines (0, 1, ...).
    A dark line is one darker than ``edge_step`` (the colour's noise allowing); the shades
    either side of a seam, means of many pixels, are alike within ``colour_step``."""
    rows_n, cols_n = shape
    across, down = lens.rays(cols_n, rows_n)
    basis = plane_basis(support, None)
    found: list[tuple[int, npt.NDArray[np.intp]]] = []
    long = [
        (p, p.rect)
        for p in plateaus
        if p.rect is not None and p.rect.length_m >= 2.0 * segment.SEAM_MIN_M
    ]
    if not long:
        return found
    # Every long top's pixels at once, then top by top.
    sizes = [int(tops.counts[p.label]) for p, _ in long]
    at = np.concatenate(
        [
            np.arange(tops.starts[p.label], tops.starts[p.label] + n)
            for (p, _), n in zip(long, sizes, strict=True)
        ]
    )
    flat = tops.flat[at]
    w = tops.width
    # Top pixels beside a lower one cut off by a depth step: cartons a few millimetres apart,
    # seen down the gap between them at every pixel or two along it.
    label = top_flat[flat]
    deep = (level - GAP_TOLERANCES * tol)[label - 1]
    lines = np.zeros(len(flat), dtype=bool)
    for offset in (-1, 1, -w, w):
        beside = flat + offset
        lines |= depth_cut_flat[beside] & (top_flat[beside] != label) & (h_flat[beside] < deep)
    if grey_flat is not None and cut_flat is not None:
        lines |= cut_flat[flat] | segment.valleys(grey_flat, flat, w, edge_step)
    # Each pixel's ray met with the top's plane, not its reading: a stereo camera's noise
    # along the ray would smear the line over several footprints.
    top_height = np.repeat([p.height_m for p, _ in long], sizes)
    d = (top_height - support.offset_camera_m) / s_flat[flat].astype(np.float64)
    pa_all, pb_all = _in_plane(basis, across[tops.cols[at]], down[tops.rows[at]], d)
    for (p, rect), end, n in zip(long, np.cumsum(sizes), sizes, strict=True):
        mine = slice(end - n, end)
        shade = np.zeros(n, dtype=np.int16) if grey_flat is None else grey_flat[flat[mine]]
        cut = lines[mine]
        if np.count_nonzero(cut) * p.footprint_m < segment.SEAM_MIN_M:
            continue
        pa, pb = pa_all[mine], pb_all[mine]
        ax, ay = rect.axis
        u, v = pa * ax + pb * ay, pb * ax - pa * ay
        bin_m = SEAM_BIN * p.footprint_m
        at_u = segment.seam_lines(u, v, cut, shade, colour_step, bin_m)
        at_v = segment.seam_lines(v, u, cut, shade, colour_step, bin_m)
        if at_u or at_v:
            cell = np.searchsorted(at_u, u) * (len(at_v) + 1) + np.searchsorted(at_v, v)
            found.append((p.label, cell))
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
    pa, pb = _in_plane(basis, ray_x[np.newaxis, :], ray_y[:, np.newaxis], depth)
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


TILT_NOISE_SIGMAS = 3.0
"""A top is level while tilted less than three standard deviations of what the depth noise
alone tilts a flat top of its size (:func:`noise_tilt_deg`)."""
LONG_ASPECT = 1.5
"""A top this many times as long as wide is no ball's nor standing can's (:func:`_level`)."""
MAX_NOISE_ROW_PX = 400
"""Rows longer than this count as this long in :func:`noise_tilt_deg` (the tilt is then far
under any limit)."""
UPRIGHT_DEG = 60.0
"""A piece whose plane along the rays stands this far from the support is a face, no level
(:attr:`Plateau.upright`)."""
THIN_ASPECT = 2.0
"""A top this many times as long as it is wide, its long sides dropping away, is measured
across by their many outline points (:func:`_extent`)."""
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


def on_level_surface(
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
    level_surface = on_level_surface(h_flat, np.concatenate(where)[keep], width, limit)
    values, group = values[level_surface], group[level_surface]
    if len(values) == 0:
        return result
    # Per top a histogram in bins of a third of the tolerance; a window of +-tol around each
    # bin; the highest window holding enough readings is the ledge.
    w = _windows(values, group, count, tol, lowest)
    window, half = w.counts, w.reach
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
    # The mean of the readings in that window, then of those within the tolerance of it (the
    # window's middle bin may lie a tolerance and half a bin off readings all in one bin).
    centre = _window_mean(w, peak, values, group, count)
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
    only: BoolArray | None = None,
) -> list[npt.NDArray[np.intp]]:
    """Per top (of those ``only`` flags, if given), its piece's pixels within four tolerances
    below its height (the curvature test's footprint)."""
    keep = p_h > level[p_top] - 4.0 * tol[p_top]
    if only is not None:
        keep &= only[p_top]
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
    perp = np.array([-axis[1], axis[0]])
    flat_a, flat_b = _in_plane(
        basis,
        (cols + tops.shift[1] - lens.cx) / lens.fx,
        (rows + tops.shift[0] - lens.cy) / lens.fy,
        d_flat[wide],
    )
    along = flat_a * axis[0] + flat_b * axis[1]
    side = flat_a * perp[0] + flat_b * perp[1]
    before = max(float(np.ptp(outline @ axis)) * float(np.ptp(outline @ perp)), 1e-12)
    return _spread(along) * _spread(side) / before


ROUND_DROP_SHARE = 0.85
"""A top is rounded where its readings fall toward two opposite sides by this share of the
plane's tolerance or more (a flat top seen through a stereo camera's blur at its edges: up to
0.77 on the benchmark's 3,458 tops)..."""

ROUND_MIN_SLOPE = 0.25
"""...leaving its sides at this slope or more (14 degrees: a carton's lid bulging a few
millimetres over its width stays a box)..."""

ROUND_MIN_T = 15.0
"""...with a curve this many standard errors clear of the readings' noise (the flat tops'
curves: up to 11)..."""

ROUND_LEVEL_SHARE = 0.7
"""...and level the other way: falling or rising by under this share of the tolerance, or of
the fall across, whichever is more (a cylinder lying down: depth noise correlated over a
dozen pixels, as a stereo camera's or filtered depth's, bows a can's top 0.9 tolerances
along while it falls 2.2 across). A top that falls a whole tolerance both ways at
:data:`DOME_MIN_SLOPE` is a ball's or a capsule's end; a carton's bulging lid falls both ways
alike, gently."""

DOME_MIN_SLOPE = 0.45
"""The slope (24 degrees) at which a top falling a whole tolerance both ways is round."""


def _rounded(
    a: Float64Array,
    b: Float64Array,
    height: Float32Array,
    group: npt.NDArray[np.intp],
    axis: Float64Array,
    tol: Float64Array,
) -> BoolArray:
    """Per top, whether its readings (plane coordinates ``a``, ``b`` and heights, top
    ``group``, ascending) curve down toward its sides as a cylinder lying down does, or a ball
    (see :data:`ROUND_DROP_SHARE` and the settings after it); ``axis`` (tops x 2) is each
    rectangle's length. The top of a can on its side is the strip of its curve within the
    tolerance: flat enough for the moments' plane, and filling its rectangle.

    Fitted as height = c0 + c1 u + c2 v + c3 u^2 + c4 v^2 (u across the rectangle, v along it;
    the curves c3 and c4 are the same wherever u and v start), all tops at once by their
    normal equations: the drop below the middle at a side is -c (half the extent)^2, the slope
    there -2 c (half the extent). A can's top, seen from 0.45-1.5 m through any of the noises,
    drops 0.9 to 2.5 tolerances across at 19 to 75 standard errors, under 0.1 along."""
    count = len(axis)
    h = height.astype(np.float64)
    ok = np.isfinite(h)
    n = np.bincount(group[ok], minlength=count)
    fit = n >= 12
    ok &= fit[group]
    if not fit.any():
        return fit
    g, h = group[ok], h[ok]
    filled = np.flatnonzero(fit)
    ax0, ax1 = np.repeat(axis[:, 0], n * fit), np.repeat(axis[:, 1], n * fit)
    # Readings x (1, u, v, u^2, v^2, h): the curves need no centring across or along; the
    # heights are taken from their mean, for their sum of squares below.
    m = np.empty((len(g), 6))
    m[:, 0] = 1.0
    u, v = m[:, 1], m[:, 2]
    np.multiply(a[ok], -ax1, out=u)
    u += b[ok] * ax0
    np.multiply(a[ok], ax0, out=v)
    v += b[ok] * ax1
    np.multiply(u, u, out=m[:, 3])
    np.multiply(v, v, out=m[:, 4])
    m[:, 5] = h - (np.bincount(g, weights=h, minlength=count) / np.maximum(n, 1))[g]
    # Per top M'M: the normal equations (and the heights' sum of squares) by one small
    # product each.
    bounds = np.searchsorted(g, np.arange(count + 1))
    gram = np.zeros((count, 6, 6))
    for t in filled:
        rows = m[bounds[t] : bounds[t + 1]]
        gram[t] = rows.T @ rows
    normal, moment = gram[:, :5, :5], gram[:, :5, 5]
    normal[~fit] = np.eye(5)
    try:
        inverse = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        inverse = np.zeros_like(normal)
        for k in range(count):
            try:
                inverse[k] = np.linalg.inv(normal[k])
            except np.linalg.LinAlgError:
                fit[k] = False
    coef = np.einsum("gij,gj->gi", inverse, moment)
    # The residuals' sum of squares: h'h - c'X'h (heights taken from their mean).
    squares = np.maximum(gram[:, 5, 5] - np.einsum("gi,gi->g", coef, moment), 0.0)
    variance = squares / np.maximum(n - 5, 1)
    starts = bounds[filled]
    drop, slope = np.zeros((count, 2)), np.zeros((count, 2))
    sure = np.zeros((count, 2), dtype=bool)
    for k, w in enumerate((u, v)):
        half = np.zeros(count)
        half[filled] = 0.5 * (np.maximum.reduceat(w, starts) - np.minimum.reduceat(w, starts))
        curve = -coef[:, 3 + k]
        drop[:, k] = curve * half * half / tol
        slope[:, k] = 2.0 * curve * half
        error = np.sqrt(np.maximum(inverse[:, 3 + k, 3 + k] * variance, 0.0))
        sure[:, k] = curve >= ROUND_MIN_T * error
    lying = np.zeros(count, dtype=bool)
    for k in (0, 1):
        lying |= (
            (drop[:, k] >= ROUND_DROP_SHARE)
            & (slope[:, k] >= ROUND_MIN_SLOPE)
            & sure[:, k]
            & (np.abs(drop[:, 1 - k]) < ROUND_LEVEL_SHARE * np.maximum(drop[:, k], 1.0))
        )
    dome = np.all((drop >= 1.0) & (slope >= DOME_MIN_SLOPE) & sure, axis=1)
    result: BoolArray = fit & (lying | dome)
    return result


def _extent(values: Float64Array, footprint: float, trim: bool, straight: bool) -> float:
    """A top's extent along one axis from its outline points' positions on it: their span
    (:func:`_spread` where ``trim``), plus a footprint for the pixels' own size. Across
    ``straight`` sides (a long narrow top's long sides, each hundreds of outline points along
    the pixel grid or at a slant to it) the outermost point stands in of its side by a
    footprint over one more than the points within a footprint of it: a whole footprint made
    a box's top four pixels wide fill 0.8 of its rectangle. A disc's extremes are few points,
    and keep the footprint."""
    low, high = _ends(values, trim)
    if not straight:
        return high - low + footprint
    near_low = int(np.count_nonzero(values < low + footprint))
    near_high = int(np.count_nonzero(values > high - footprint))
    return high - low + footprint * (1.0 / (near_low + 1) + 1.0 / (near_high + 1))


def _falls_both_ways(rect: Rectangle, across: Float64Array) -> bool:
    """Whether the surface is seen dropping away (or the camera's dropout) past both of the
    rectangle's sides whose outward normals are +-``across``."""
    ends = np.asarray((*rect.edge_normals, *rect.dropout_normals)).reshape(-1, 2) @ across
    return bool(len(ends)) and float(ends.max()) > 0.99 and float(ends.min()) < -0.99


LATTICE_MIN_FILL = 0.92
"""An oblong top filling this much of its rectangle measured with its sides straight
(see :func:`_extent`) is a rectangle, whatever the footprint's measure says ..."""
LATTICE_ASPECT = 1.3
"""... if it is at least this many times as long as wide (no disc is) ..."""
LATTICE_TOLERANCE_M = 0.004
"""... and its height tolerance is this or less (depth good to a millimetre or so: through
lumpy noise of 3 mm, round things lying down filled as much, and two were boxes on
bench_locator's tables of round things)."""


STRAY_POINTS = 2
"""At most this many outline points are left out at each end of a top's extent as strays."""


def _ends(values: Float64Array, trim: bool) -> tuple[float, float]:
    """The least and the greatest value; where ``trim``, one value in a hundred left out at
    each end, up to :data:`STRAY_POINTS` (under a hundred values, none). Noise that leaves
    holes in a top adds outline points round each hole, far more than round the top: one in
    a hundred of those cut into a disc's few extreme points, and a can's lid through
    sigma 3-4 mm filled 0.86 of its square."""
    return _kth_ends(values, min(len(values) // 100, STRAY_POINTS) if trim else 0)


def _spread(values: Float64Array) -> float:
    """From the 1st to the 99th percentile."""
    low, high = _kth_ends(values, len(values) // 100)
    return high - low


def _kth_ends(values: Float64Array, k: int) -> tuple[float, float]:
    """The k-th least and k-th greatest value (from 0)."""
    low, high = np.partition(values, (k, len(values) - 1 - k))[[k, len(values) - 1 - k]]
    return float(low), float(high)


def cross(a: Float64Array, b: Float64Array) -> Float64Array:
    """a x b of two 3-vectors (np.cross costs tens of microseconds a call)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )
