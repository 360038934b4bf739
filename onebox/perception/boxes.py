"""Every box in a depth picture: oriented, measured, topmost first, with stable ids in a stream.

Contract: :func:`find_boxes` takes a depth picture (H x W float32 metres; NaN, 0, negative and
inf are no reading), the lens (CameraInfo convention: the middle of pixel u is at u), the
camera's pose (optical frame -> world, 4 x 4) or None, optionally the colour picture of the
same size (H x W x 3 uint8, RGB) and how many whole pixels it lies off the depth, and
:class:`FinderSettings`. It returns :class:`Found`: the support plane and the boxes, highest
top first, in the world frame with a pose and in the optical frame without one ("up" is then
the support normal, toward the camera). :class:`BoxFinder` does the same for a stream (see
:mod:`onebox.perception.stream`). No I/O here.

The pipeline, one module a physical effect:

1. :mod:`~onebox.perception.support`: the surface the boxes stand on (RANSAC, then least
   squares) and the depth noise measured on it, growing with distance (sigma(z)).
2. :mod:`~onebox.perception.surface`: every pixel's height above it, which way it faces, where
   the depth steps.
3. :mod:`~onebox.perception.tops`: connected flat regions facing up, split where a seam seen
   only in colour crosses them (:mod:`~onebox.perception.seams`) or where their outline turns
   inward round something lower (two tops side by side), each measured as an oriented
   rectangle on its own plane.
4. Here:

   - what lies round each top (:func:`_look_round`): something nearer hiding a side (the
     extent along that side is then a lower bound), a lower level, the picture's edge, and how
     much of its rectangle is not seen;
   - which tops are boxes (:func:`_boxes`): large enough, level (a long narrow one along its
     length: its edges' smear leans it across), flat, not curved over their
     middle half or their middle 80 % beyond each fitted sag's noise, filling their rectangle
     and its corners (of what is not hidden, nor covered by a top standing over it
     (:func:`_under_carried`), nor missing along what hides it: no reading, or its own
     pixels lost in the edge's smear; and a fifth of the rectangle at least; where the depth is
     quiet, nor the band past its pixel-exact outline that its rectangle takes in along a
     slanted side), not round (its outline as wide at every turn: a tin's lid), not cut off,
     not a narrow piece of a longer top (its surface going on at its height past two sides: a
     bin's rim);
   - what each top stands on (:func:`_bases`, before the test above): the support or a lower
     top, looked for at its own height just past the top's sides, within where the top's faces
     are seen to end (:func:`_face_bottom`), or where they end on a box sticking out under
     them;
   - what is no box after all: a top with nothing under its edges (:func:`_hollow`, a table on
     legs) and a platform (a top two boxes or more stand on that they mostly hide, or that
     they stand on past one side of it that something hides or no reading shows: a pallet's
     top and rim);
   - the report, with a catalogue's height and name where a top fits an entry.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import kernels, register
from onebox.perception.catalogue import Entry, match
from onebox.perception.support import (
    Support,
    fit_support,
    lump_width,
    noise_against,
)
from onebox.perception.surface import QUIET_SHARE, height_slope, read_surface
from onebox.perception.tops import Tops, cross, find_tops, sight

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Vec3 = tuple[float, float, float]

MAX_PIXELS = 848 * 480
"""Larger pictures are read at every k-th pixel (a D435's depth and an Azure Kinect's 640 x 576
are read whole; 1280 x 720 as 640 x 360)."""
PROBES_PER_SIDE = 9
"""Points looked at just past each side of a top."""
PROBE_REACH_M = 0.012
"""...this far past it (and at least two pixels): past a smeared edge, within a gap."""
FACE_LEVELS = 12
"""Heights a top's faces are looked at, from its edge down to the support."""
FINE_LEVELS = 8
"""Where a face is seen to end, it is looked at again this many times finer."""
RECESS_M = 0.1
"""A face seen ending over a surface less than this behind it overhangs a box..."""
STICKING_OUT_M = 0.1
"""...over one less than this in front of it stands on a wider box; farther off it is
something else in front (a bottle before a carton)."""
WALL_FACING = 0.1
"""A side faces the camera when its outward normal is this far (cosine) toward it."""
WALL_TOLERANCE_M = 0.012
"""A point on a side seen this much farther than it lies (or 4 sigma(z)) has nothing there."""
HOLLOW_INSET_PX = 2.0
"""Under a top's edges is looked at this many pixels in from its rectangle: a smeared edge
stretches the rectangle past the faces under it."""
PLATFORM_CARRIES = 2
"""A platform carries at least this many boxes..."""
PLATFORM_COVERED = 0.5
"""...and has more than this share of it hidden, or has them outside its rectangle."""
SMOOTH_SIGMA_M = 0.01
"""Depth noisier than this at the support is read through a median first (a camera
reporting depth in steps of a centimetre, at 0.7 m, is left as it is)..."""
MEDIAN_PX = 5
"""...of this many pixels a side."""
CROP_MARGIN_PX = 16
"""Pixels kept round everything standing, for what is looked at just past a top's sides."""
CANDIDATES = 4
"""Lower levels looked for round a top (the highest first), beside the support."""
HIDDEN_SHARE = 0.3
"""A side is hidden when this share of its probes see something nearer than the top."""
COVER_GRID = 9
"""Points across each side of a top's rectangle looked at for what hides it."""
CURVED_SHARE = np.array([0.06, 0.154])
"""A top whose middle half sags from its middle to that half's edges by more than this share
of their distance is curved (a can lying down: about 0.06 and more; a carton's lid, bowed by
a stereo camera, up to 0.05; its edges smeared by the camera, it stays flat in its middle);
so is one whose middle 80 % sags by the second (the same curve over a window 1.6 times as
wide, whose sag rises 2.56-fold, above its noise more surely)..."""
CURVE_WINDOW_SHARE = np.array([0.5, 0.8])
"""The share of a top's pixels in each window."""
CURVED_SIGMAS = np.array([3.0, 5.0])
"""...when the sag is also more than this many times its own noise (the middle half's, the
middle 80 %'s): no curve is read into noise. Nearer a top's edges a stereo camera's errors
are less like noise (lumps, steps, smear), so the wider window asks more."""
SAG_SPREAD = 3.35
"""A quadratic fitted to N points spread evenly over [-a, a] has its rise over a known to
sigma * 3.35 / sqrt(N)..."""
SAG_FLOOR = 0.35
"""...but a top's fitted sag is never taken as surer than this share of sigma(z)."""
MAX_FILL = 1.5
"""A flat top's pixels, laid on its plane, fit in its rectangle (a small one seen at a slant
overfills it by up to a sixth: each pixel's footprint is taken at its middle); half as much
again is a surface seen edge-on, its pixels' footprints blowing up as its plane turns along
the rays (a strip of a drill's flank, 9 times its rectangle)."""
OUTLINE_PX = 0.25
"""A rectangle placed half a pixel past the middles of a top's outermost pixels lies, along a
side slanted across the pixels, up to half a pixel past the true side: this much on average."""
ROUND_TURNED = 0.8
"""A top whose rectangle is more than this share of the one round its pixels turned 45 degrees
(a disc's is all of it, a square's two thirds, a longer rectangle's less) is round..."""
ROUND_SEEN_COVERED = 0.1
"""...judged where less than this share of it is covered: the part of a top seen round a box
standing on it has no outline of its own."""
MIN_SEEN = 0.2
"""A top fills this share of its rectangle at least, however much of it is hidden: a sliver
seen between nearer things says too little of the rectangle round it."""
CORNER_FILL = 0.6
"""A box's top reaches into its rectangle's corners; a disc, a rounded tin or a bowl's bottom
does not."""
NARROW_PX = 15.0
"""A top narrower than this many pixels (three of the normals' 5 x 5 windows: most of its
pixels' windows take in its edges) falls apart along its length where its normals come and
go..."""
PIECE_LEVEL_SIDES = 2
"""...so one whose surface goes on at its height past this many of its sides or more (a bin's
rim, the corner where two rims meet) is a piece of a longer top, not a box's."""
LONG_NARROW = 3.0
"""A narrow top at least this many times as long as wide is judged level by its slope along
it alone: along a shorter one that slope is read over too few pixels to say more than its
tilt across (a real capture read at half size: a 44 x 18 mm piece of something, 2.4 times as
long as wide and leaning 25 degrees, came through at 2)."""
MIN_WIDTH_M = 0.015
"""A top narrower than this is an edge or a rim, not a box."""
FLAT_SIGMAS = 3.0
"""A top lies within this many sigma(z) of its plane (root mean square)..."""
FLAT_M = 0.006
"""...or within this, whatever the noise (a carton's lid bulges and sags by millimetres)."""


@dataclass(frozen=True)
class FinderSettings:
    """Tolerances; the depth noise's are measured on the support plane."""

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
    """Tops smaller than this (2 x 2 cm) are no boxes: speckles, clumps, flying pixels."""
    min_score: float = 0.85
    """A top seen whole must fill this share of its rectangle (a disc fills 0.785)."""
    max_top_tilt_deg: float = 15.0
    """A box's top is parallel to the surface under it within this angle (lids bulge, lean)."""
    keep_cut_off: bool = False
    """Report tops cut off by the picture's border (their size is then a lower bound)."""
    match_distance_m: float = 0.02
    """BoxFinder: a box within this of last picture's box (and of a similar size) keeps its id."""
    max_pixels: int | None = MAX_PIXELS
    """Larger pictures are read at every k-th pixel to keep camera rate; None reads them all."""
    colour_shift: tuple[int, int] | None = None
    """BoxFinder: the colour picture's shift against the depth, (dy, dx) whole pixels (see
    :mod:`onebox.perception.register`); None measures it from the pictures."""
    register_every: int = 30
    """BoxFinder: measure the colour's shift on the first picture and every this many after."""
    catalogue: tuple[Entry, ...] = ()
    """The box sizes a site handles (:mod:`onebox.perception.catalogue`): a top that fits one
    takes its height and name."""


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
    """0..1: how full the top's rectangle is, times how flat the top is."""
    top_pixels: int
    top_middle: Vec3
    on: int | None = None
    """The index (in Found.boxes) of the box it stands on, if any."""
    id: int = -1
    """Stable across a stream (BoxFinder); -1 from find_boxes."""
    hidden_sides: int = 0
    """Sides of the top another object hides: the size along them is a lower bound."""
    height_seen: bool = True
    """Whether the level it stands on is seen beside it, on the support or on a top that
    reaches under it (its rectangle holds the box's middle); when not (a carton in a full
    layer, or among lower neighbours), the height is measured to the level found beside it
    and is only as good as that."""
    name: str = ""
    """The catalogue entry its top matches, if a catalogue is used."""


@dataclass(frozen=True)
class Found:
    """The support plane and the boxes, highest top first, all in ``frame``."""

    support: Support | None
    boxes: list[Box] = field(default_factory=list)
    frame: str = "camera"


def read_stride(shape: tuple[int, ...], max_pixels: int | None) -> int:
    """Every how many pixels a picture is read (1: all)."""
    if max_pixels is None or shape[0] * shape[1] <= max_pixels:
        return 1
    return math.ceil(math.sqrt(shape[0] * shape[1] / max_pixels))


def clean_depth(depth_m: npt.NDArray[np.floating]) -> Float32Array:
    """Float32 metres with every kind of no reading (0, negative, inf) as NaN."""
    return kernels.clean_depth(np.ascontiguousarray(depth_m, dtype=np.float32))


def find_boxes(
    depth_m: npt.NDArray[np.floating],
    lens: Intrinsics,
    camera_to_world: Float64Array | None,
    colour: npt.NDArray[np.uint8] | None = None,
    settings: FinderSettings = FinderSettings(),
    support: Support | None = None,
    colour_shift: tuple[int, int] = (0, 0),
) -> Found:
    """Every box in the picture (see the module docstring); ``support`` skips the plane fit;
    ``colour_shift`` is how far the colour lies off the depth (:mod:`register`)."""
    depth = clean_depth(depth_m)
    frame = "world" if camera_to_world is not None else "camera"
    if colour is not None:
        colour = register.in_register(colour, colour_shift)
    stride = read_stride(depth.shape, settings.max_pixels)
    if stride > 1:
        # Pixel k * u' is pixel u' of the coarse picture: its ray is unchanged, so the lens
        # scales exactly (middle of pixel u at u: cx / k, not (cx + 0.5) / k - 0.5).
        depth = np.ascontiguousarray(depth[::stride, ::stride])
        colour = None if colour is None else np.ascontiguousarray(colour[::stride, ::stride])
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
    lump_px = support.lump_px
    if settings.noise_sigma_m is None and support.sigma_m > SMOOTH_SIGMA_M:
        depth, support = _smoothed(depth, lens, support)
        lump_px = max(support.lump_px, MEDIAN_PX)  # the median's window makes the noise lumpy
    crop, colour_crop, crop_lens, origin = _standing_crop(
        depth, colour, lens, support, settings.min_height_m
    )
    if crop.size == 0:
        return Found(support, [], frame)
    surface = read_surface(crop, crop_lens, support)
    tops = find_tops(
        crop,
        surface,
        crop_lens,
        support,
        colour_crop,
        settings.min_height_m,
        settings.max_height_m,
    )
    if len(tops) == 0:
        return Found(support, [], frame)
    # What lies round the tops is looked at in the whole picture.
    round_ = _look_round(tops, origin, depth, lens, support)
    quiet = support.sigma_at(tops.depth_m) < QUIET_SHARE * tops.depth_m / lens.fx
    looked, slant = _looked_at(tops, round_, lens, support)
    face_bottom, ledge = _face_bottom(tops, looked, slant, quiet, origin, depth, lens, support)
    base, on, held = _bases(tops, round_, face_bottom, ledge, depth, lens, support)
    round_ = _under_carried(tops, round_, on, held)
    is_box = _boxes(tops, round_, settings, lump_px, quiet)
    # A top that several boxes stand on, and that they mostly hide or that they stand on
    # outside its rectangle (past a side of it something hides), is a platform (a pallet's
    # top, its rim seen in front of the load): a level to stand on, not a box to report. A
    # carton with one box on it is still a carton.
    is_box &= ~_hollow(tops, looked, base, depth, lens, support)
    carried = is_box & (on >= 0)
    carries = np.bincount(on[carried], minlength=len(tops)) >= PLATFORM_CARRIES
    # ... boxes standing on it outside its rectangle stand past a side of it that something
    # hides or no reading shows (a stereo camera's hole along the faces rising there), the same
    # side (a pallet's rim before its load; taller neighbours either side of a carton are not)
    under = on[carried]
    d = tops.middle_ab[carried] - tops.middle_ab[under]
    axis = tops.axis_ab[under]
    along = d[:, 0] * axis[:, 0] + d[:, 1] * axis[:, 1]
    across = d[:, 1] * axis[:, 0] - d[:, 0] * axis[:, 1]
    beyond_length = np.abs(along) - tops.length_m[under] / 2
    beyond_width = np.abs(across) - tops.width_m[under] / 2
    side = np.where(
        beyond_length > beyond_width, np.where(along > 0, 0, 1), np.where(across > 0, 2, 3)
    )
    past_side = round_.hidden[under, side] | round_.unread[under, side]
    outside = (np.maximum(beyond_length, beyond_width) > 0) & past_side
    past = np.zeros((len(tops), 4), dtype=np.int64)
    np.add.at(past, (under[outside], side[outside]), 1)
    platform = carries & ((round_.covered >= PLATFORM_COVERED) | (past.max(axis=1) >= 2))
    is_box &= ~platform
    return Found(
        support,
        _report(tops, round_, is_box, base, on, held, support, camera_to_world, settings),
        frame,
    )


def _smoothed(
    depth_m: Float32Array, lens: Intrinsics, support: Support
) -> tuple[Float32Array, Support]:
    """Depth too noisy for a box's step (a stereo camera past two metres) through a 5 x 5
    median, which keeps steps and edges and cuts the noise about 2.5-fold, and the noise
    measured again on the support."""
    valid = np.isfinite(depth_m)
    smooth: Float32Array = np.asarray(
        cv2.medianBlur(np.where(valid, depth_m, 0.0).astype(np.float32), MEDIAN_PX),
        dtype=np.float32,
    )
    smooth[~valid | (smooth <= 0)] = np.nan
    sigma = noise_against(smooth, lens, support)
    lumped = replace(support, sigma_m=sigma)
    return smooth, replace(lumped, lump_px=lump_width(smooth, lens, lumped))


def _standing_crop(
    depth_m: Float32Array,
    colour: npt.NDArray[np.uint8] | None,
    lens: Intrinsics,
    support: Support,
    min_height_m: float,
) -> tuple[Float32Array, npt.NDArray[np.uint8] | None, Intrinsics, tuple[int, int]]:
    """The part of the picture holding everything that stands on the support, with a margin,
    its lens and where its first pixel lies in the picture: the rest is support or nothing,
    and finding tops there would only cost time."""
    rows, cols = depth_m.shape
    first_row, last_row, first_col, last_col = kernels.standing_bounds(
        depth_m,
        height_slope(lens, cols, rows, support.normal_camera),
        support.offset_camera_m,
        min_height_m,
    )
    if first_row < 0:
        return depth_m[:0, :0], None, lens, (0, 0)
    r0, r1 = max(first_row - CROP_MARGIN_PX, 0), min(last_row + CROP_MARGIN_PX + 1, rows)
    c0, c1 = max(first_col - CROP_MARGIN_PX, 0), min(last_col + CROP_MARGIN_PX + 1, cols)
    if (r0, r1, c0, c1) == (0, rows, 0, cols):
        return depth_m, colour, lens, (0, 0)
    crop = np.ascontiguousarray(depth_m[r0:r1, c0:c1])
    colour_crop = None if colour is None else np.ascontiguousarray(colour[r0:r1, c0:c1])
    lens_crop = Intrinsics(lens.fx, lens.fy, lens.cx - c0, lens.cy - r0)
    return crop, colour_crop, lens_crop, (int(r0), int(c0))


@dataclass(frozen=True)
class Round:
    """What is seen just past each side of each top (n, 4 sides)."""

    hidden: BoolArray
    """Something nearer than the top hides the side."""
    unread: BoolArray
    """No reading past the side (a stereo camera's hole along a depth edge): what it does
    there is not seen either."""
    lower_m: Float64Array
    """(n, 4, PROBES_PER_SIDE): the height seen past the side where it is lower than the top
    (NaN where not)."""
    level: BoolArray
    """The top's own surface goes on past the side at its height: no edge there."""
    seen_top: npt.NDArray[np.intp]
    """(n, 4, PROBES_PER_SIDE): the top seen at each probe's pixel (-1: none)."""
    ab: Float64Array
    """(n, 4, PROBES_PER_SIDE, 2): where the probes are, in the support plane's coordinates."""
    cover: BoolArray
    """(n, COVER_GRID ** 2): which points of a grid on the top's rectangle are hidden: seen
    nearer (a box standing on it, an object in front), or under a top standing on it."""
    missing: BoolArray
    """(n, COVER_GRID ** 2): which show nothing of the top: no reading, or a reading at its
    level that no top holds."""

    @property
    def covered(self) -> Float64Array:
        """(n,): the share of the top's rectangle hidden."""
        result: Float64Array = self.cover.mean(axis=1)
        return result

    @functools.cached_property
    def blank(self) -> BoolArray:
        """(n, COVER_GRID ** 2): the points missing along a hidden one (beside it, or beside
        one of these). A stereo camera reads nothing on a surface along a nearer edge (one of
        its two views does not see it there), and the top's own pixels along it are lost in
        the edge's smear (its depth steps, its normals turn), a band wider than the grid's
        step when far."""
        grid = self.cover.reshape(-1, COVER_GRID, COVER_GRID)
        missing = self.missing.reshape(grid.shape)
        # From the hidden points across the missing ones next to them, until none is added.
        reached = grid.copy()
        while True:
            grown = reached.copy()
            grown[:, 1:] |= reached[:, :-1]
            grown[:, :-1] |= reached[:, 1:]
            grown[:, :, 1:] |= reached[:, :, :-1]
            grown[:, :, :-1] |= reached[:, :, 1:]
            grown &= missing | grid
            if (grown == reached).all():
                break
            reached = grown
        result: BoolArray = (reached & missing).reshape(self.cover.shape)
        return result

    @property
    def unseen(self) -> Float64Array:
        """(n,): the share of the top's rectangle hidden or blank."""
        result: Float64Array = (self.cover | self.blank).mean(axis=1)
        return result

    @property
    def corners_unseen(self) -> Float64Array:
        """(n,): the share of its four corners hidden or blank."""
        result: Float64Array = (self.cover | self.blank)[:, _COVER_CORNER].mean(axis=1)
        return result


_PROBE_SPREAD = np.linspace(-0.8, 0.8, PROBES_PER_SIDE)
"""Where the probes past a side are along it: its middle 80 %, in shares of its half."""
_COVER_LINE = np.linspace(-0.45, 0.45, COVER_GRID)
_COVER_S, _COVER_T = (v.ravel() for v in np.meshgrid(_COVER_LINE, _COVER_LINE, indexing="ij"))
"""The grid on a top's rectangle looked at for what hides it: shares of its length and width."""
_COVER_CORNER = (np.abs(_COVER_S) == _COVER_LINE[-1]) & (np.abs(_COVER_T) == _COVER_LINE[-1])
_FACE_SPREAD = np.linspace(-0.6, 0.6, 5)
"""Where the points on a side's plane are along it: its middle 60 %, in shares of its half."""


def _look_round(
    tops: Tops,
    origin: tuple[int, int],
    depth_m: Float32Array,
    lens: Intrinsics,
    support: Support,
) -> Round:
    """Probe points just past each side of every top, on the top's plane extended: what the
    camera sees along the ray to each (see :class:`Round`), in the whole picture (``tops``
    were found in the part of it whose first pixel is ``origin``)."""
    pixel = tops.depth_m / lens.fx
    reach = np.maximum(PROBE_REACH_M, 2.5 * pixel)
    # Sides: +length, -length, +width, -width; probes spread along each side's middle 80 %.
    ab, z_expected, seen, inside, vi, ui = kernels.probe_round(
        tops.middle_ab,
        tops.axis_ab,
        tops.length_m,
        tops.width_m,
        reach,
        _PROBE_SPREAD,
        tops.height_m,
        tops.basis,
        support.offset_camera_m,
        depth_m,
        _lens_array(lens),
    )
    tolerance = np.maximum(3.0 * tops.sigma_m, 0.006)[:, None, None]
    with np.errstate(invalid="ignore"):
        nearer = seen < z_expected - tolerance * 4.0
        seen_height = seen / z_expected * (tops.height_m[:, None, None] - support.offset_camera_m)
        seen_height += support.offset_camera_m  # height along the same ray, by similar triangles
        lower = np.where(seen > z_expected + tolerance, seen_height, np.nan)
    hidden = nearer.mean(axis=2) >= HIDDEN_SHARE
    with np.errstate(invalid="ignore"):
        level = (np.abs(seen - z_expected) <= tolerance).mean(axis=2) >= 0.5
    unread = (np.isnan(seen) & inside).mean(axis=2) >= HIDDEN_SHARE
    seen_top = np.where(inside, _top_at(tops, origin, vi, ui), -1)
    cover, missing = _covered(tops, origin, depth_m, lens, support)
    return Round(hidden, unread, lower, level, seen_top, ab, cover, missing)


def _top_at(
    tops: Tops, origin: tuple[int, int], v: npt.NDArray[np.intp], u: npt.NDArray[np.intp]
) -> npt.NDArray[np.intp]:
    """The top at each pixel (row ``v``, column ``u`` of the picture; -1: none, or outside the
    part of the picture the tops were found in, which starts at ``origin``)."""
    rows, cols = tops.labels.shape
    vc, uc = v - origin[0], u - origin[1]
    in_crop = (vc >= 0) & (vc < rows) & (uc >= 0) & (uc < cols)
    labels = tops.labels[np.clip(vc, 0, rows - 1), np.clip(uc, 0, cols - 1)]
    result: npt.NDArray[np.intp] = np.where(in_crop, labels - 1, -1)
    return result


def _lens_array(lens: Intrinsics) -> Float64Array:
    """fx, fy, cx, cy, as the kernels take them."""
    return np.array([lens.fx, lens.fy, lens.cx, lens.cy])


def _covered(
    tops: Tops, origin: tuple[int, int], depth_m: Float32Array, lens: Intrinsics, support: Support
) -> tuple[BoolArray, BoolArray]:
    """Which points of a grid on each top's rectangle something nearer hides (a box standing
    on it, an object in front), looked at; and which are missing (:attr:`Round.missing`)."""
    s, t = _COVER_S, _COVER_T
    z_expected, seen, vi, ui = kernels.probe_cover(
        tops.middle_ab,
        tops.axis_ab,
        tops.length_m,
        tops.width_m,
        s,
        t,
        tops.height_m,
        tops.basis,
        support.offset_camera_m,
        depth_m,
        _lens_array(lens),
    )
    tolerance = np.maximum(3.0 * tops.sigma_m, 0.006)[:, None]
    with np.errstate(invalid="ignore"):
        nearer: BoolArray = seen < z_expected - 4.0 * tolerance
        level = np.abs(seen - z_expected) <= tolerance
    return nearer, np.isnan(seen) | (level & (_top_at(tops, origin, vi, ui) < 0))


def _under_carried(tops: Tops, round_: Round, on: npt.NDArray[np.intp], held: BoolArray) -> Round:
    """``round_`` with the points of each top's grid under the rectangle of a top standing on
    it, over it (``held``: its middle within the rectangle), hidden too: what stands on a top
    covers it, including the band round its foot whose faces rise too little above the top
    there to be seen nearer."""
    j = np.flatnonzero((on >= 0) & held)
    k = on[j]
    if len(j) == 0:
        return round_
    axis_k, axis_j = tops.axis_ab[k], tops.axis_ab[j]
    along = _COVER_S[None, :] * tops.length_m[k, None]
    across = _COVER_T[None, :] * tops.width_m[k, None]
    d = tops.middle_ab[k, None, :] - tops.middle_ab[j, None, :]  # (m, 1, 2)
    da = d[..., 0] + along * axis_k[:, None, 0] - across * axis_k[:, None, 1]
    db = d[..., 1] + along * axis_k[:, None, 1] + across * axis_k[:, None, 0]
    own_along = np.abs(da * axis_j[:, None, 0] + db * axis_j[:, None, 1])
    own_across = np.abs(db * axis_j[:, None, 0] - da * axis_j[:, None, 1])
    under = (own_along <= 0.5 * tops.length_m[j, None]) & (
        own_across <= 0.5 * tops.width_m[j, None]
    )
    cover = round_.cover.copy()
    np.logical_or.at(cover, k, under)
    return replace(round_, cover=cover)


def _boxes(
    tops: Tops, round_: Round, settings: FinderSettings, lump_px: float, quiet: BoolArray
) -> BoolArray:
    """Which tops are boxes' (see the module docstring); ``quiet``: the noise at the top's
    depth is under a share of a pixel's footprint there (as :attr:`Surface.quiet`)."""
    # Where the depth is quiet, a top's outline is pixel-exact, and its rectangle lies past
    # its sides by the band OUTLINE_PX wide that a slanted side leaves: neither its fill nor
    # its roundness is asked of that band (a share of a top a few pixels across).
    pixel = tops.pixel_m
    band = 2.0 * OUTLINE_PX * pixel * (1.0 / tops.width_m + 1.0 / tops.length_m)
    band = np.where(quiet, band, 0.0)
    # What something nearer hides, or a stereo camera leaves blank beside it, cannot be
    # filled: ask for the rest.
    fill_needed = np.maximum(settings.min_score * (1.0 - round_.unseen) * (1.0 - band), MIN_SEEN)
    corners_needed = CORNER_FILL * (1.0 - round_.corners_unseen)
    flat = tops.rms_m <= np.maximum(FLAT_SIGMAS * tops.sigma_m, FLAT_M)
    # A top seen whole whose outline is about as wide at every turn is round (a tin's lid),
    # however full its rectangle.
    round_top = (tops.turned > ROUND_TURNED * (1.0 - band)) & (round_.covered < ROUND_SEEN_COVERED)
    # A narrow top whose surface goes on at its height past two of its sides is a piece of a
    # longer one that fell apart where its normals came and went (a bin's rim).
    narrow = tops.width_m < NARROW_PX * pixel
    piece = narrow & (round_.level.sum(axis=1) >= PIECE_LEVEL_SIDES)
    # Across a narrow top, its edges' smear (a depth edge's pixels read between the two
    # surfaces) is most of it, and leans its plane: on a long one, its slope along it says
    # whether it is level. (A short one has no such slope to go by: a ball's cap.)
    along = np.abs((tops.slope_ab * tops.axis_ab).sum(axis=1))
    long_narrow = narrow & (tops.length_m >= LONG_NARROW * tops.width_m)
    tilt = np.where(long_narrow, np.degrees(np.arctan(along)), tops.tilt_deg)
    # Each sag is fitted to its window's pixels: its noise falls with the root of how many
    # independent lumps of noise the window holds, down to a share of sigma(z) (depth errors
    # keep some structure across a top that no count of pixels averages out).
    lumps = np.maximum(CURVE_WINDOW_SHARE * tops.pixels[:, None] / max(lump_px, 1.0) ** 2, 1.0)
    sag_noise = np.clip(SAG_SPREAD / np.sqrt(lumps), SAG_FLOOR, 1.0) * tops.sigma_m[:, None]
    curved = (tops.sag_share > CURVED_SHARE) & (tops.sag_m > CURVED_SIGMAS * sag_noise)
    result: BoolArray = (
        (tops.area_m2 >= settings.min_top_area_m2)
        & (tops.width_m >= MIN_WIDTH_M)
        & (tilt <= settings.max_top_tilt_deg)
        & flat
        & ~piece
        & (tops.fill >= fill_needed)
        & (tops.fill <= MAX_FILL)
        & (tops.corners >= corners_needed)
        & ~round_top
        & ~curved.any(axis=1)
    )
    if not settings.keep_cut_off:
        result &= ~tops.on_border
    return result


def _on_sides(
    tops: Tops,
    height_m: Float64Array,
    depth_m: Float32Array,
    lens: Intrinsics,
    support: Support,
    inset_px: float = 1.0,
) -> tuple[Float64Array, Float64Array, BoolArray, tuple[npt.NDArray[np.intp], ...]]:
    """Points on the planes of each top's four sides (``inset_px`` pixels in from the
    rectangle, over the middle 60 % of each side) at the heights ``height_m`` (n, H): the depth
    each would read if seen, the depth seen there, whether it is in the picture, and its pixel
    (row, column); each (n, 4, H, 5)."""
    z_expected, seen, inside, vi, ui = kernels.probe_faces(
        tops.middle_ab,
        tops.axis_ab,
        tops.length_m,
        tops.width_m,
        inset_px * tops.depth_m / lens.fx,
        _FACE_SPREAD,
        np.ascontiguousarray(height_m, dtype=np.float64),
        tops.basis,
        support.offset_camera_m,
        depth_m,
        _lens_array(lens),
    )
    return z_expected, seen, inside, (vi, ui)


def _looked_at(
    tops: Tops, round_: Round, lens: Intrinsics, support: Support
) -> tuple[BoolArray, Float64Array]:
    """(n, 4): the sides whose faces the camera sees: facing it, and not hidden by something
    nearer at the top's height; and for each, how much nearer a point reads along the line of
    sight to the face's middle per metre it lies out from the face's plane (one over the
    cosine between the face's outward normal and that line, scaled to depth: large where the
    face is seen nearly edge-on; 0 for a side facing away)."""
    axis = tops.axis_ab
    perp = np.stack([-axis[:, 1], axis[:, 0]], axis=1)
    outward = np.stack([axis, -axis, perp, -perp], axis=1)
    half = np.stack([tops.length_m, tops.length_m, tops.width_m, tops.width_m], axis=1) / 2
    e1, e2, normal = tops.basis
    out3 = outward[..., :1] * e1 + outward[..., 1:] * e2
    middle_ab = tops.middle_ab[:, None, :] + outward * half[..., None]
    lift = (0.5 * tops.height_m - support.offset_camera_m)[:, None, None]
    middle = middle_ab[..., :1] * e1 + middle_ab[..., 1:] * e2 + lift * normal
    toward = -(out3 * middle).sum(axis=-1)
    facing = toward > WALL_FACING * np.linalg.norm(middle, axis=-1)
    result: BoolArray = facing & ~round_.hidden
    slant: Float64Array = middle[..., 2] / np.where(facing, toward, np.inf)
    return result, slant


def _hollow(
    tops: Tops,
    looked: BoolArray,
    base_m: Float64Array,
    depth_m: Float32Array,
    lens: Intrinsics,
    support: Support,
) -> BoolArray:
    """Whether nothing is under a top's edges where a box's sides would be, as under a table
    on legs or a board on a post: on every side whose face the camera sees, points on the
    side's plane in the upper quarter between the base and the top are seen farther than they
    lie, three in four at least (a stereo camera reads a face it sees at a grazing angle
    through its background, here and there). A top none of whose faces the camera sees is
    not hollow."""
    n = len(tops)
    share = np.array([0.75, 0.9])
    heights = base_m[:, None] + share[None, :] * (tops.height_m - base_m)[:, None]
    z_expected, seen, inside, _ = _on_sides(tops, heights, depth_m, lens, support, HOLLOW_INSET_PX)
    tolerance = np.maximum(4.0 * tops.sigma_m, WALL_TOLERANCE_M)[:, None, None, None]
    with np.errstate(invalid="ignore"):
        farther = (seen > z_expected + tolerance) & inside
    empty = farther.reshape(n, 4, -1).mean(axis=2) >= 0.75
    result: BoolArray = looked.any(axis=1) & (empty | ~looked).all(axis=1)
    return result


def _mean_where(values: Float64Array, where: BoolArray, axis: int) -> Float64Array:
    """The mean of ``values`` where ``where`` along ``axis`` (0 where none)."""
    mean: Float64Array = np.where(where, values, 0.0).sum(axis=axis) / np.maximum(
        where.sum(axis=axis), 1
    )
    return mean


def _face_bottom(
    tops: Tops,
    looked: BoolArray,
    slant: Float64Array,
    quiet: BoolArray,
    origin: tuple[int, int],
    depth_m: Float32Array,
    lens: Intrinsics,
    support: Support,
) -> tuple[Float64Array, BoolArray]:
    """How far down each top's faces are seen going on from its edge without a break (on the
    side that shows them lowest): a box's side ends where it stands. NaN where no face is
    seen. Also whether the face is seen to end there: past it nothing is where the face would
    go on, or the face of a box under it sticks out (not a top in front, which only hides it),
    or a face read steady down its levels steps out (all against what the face reads above);
    where it ends is then looked for again, finer, from its last level down to there."""
    n = len(tops)
    share = 1.0 - np.linspace(0.05, 1.0, FACE_LEVELS)
    heights = share[None, :] * tops.height_m[:, None]  # top down to the support
    z_expected, seen, inside, (vi, ui) = _on_sides(tops, heights, depth_m, lens, support)
    tolerance = np.maximum(4.0 * tops.sigma_m, WALL_TOLERANCE_M)[:, None, None, None]
    with np.errstate(invalid="ignore"):
        on_face = (np.abs(seen - z_expected) < tolerance) & inside
    present = on_face.mean(axis=3) >= 0.5  # (n, 4, levels)
    run = np.cumprod(present, axis=2).sum(axis=2)  # levels seen from the edge down, unbroken
    run = np.where(looked, run, 0)
    side = np.argmax(run, axis=1)
    deepest = run[np.arange(n), side]
    bottom = np.where(
        deepest > 0, share[np.clip(deepest - 1, 0, FACE_LEVELS - 1)] * tops.height_m, np.nan
    )
    # What is seen just under the face's end on that side: something nearer that is no top's
    # (a neighbour's top in front only hides the face; a box's face sticking out carries it).
    rows, cols = tops.labels.shape
    near_top = cv2.dilate((tops.labels > 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    # Past the face's end, against what the face reads above it (its plane may lie a little
    # off the rectangle's side): a box's face a little behind it (it overhangs that box) or
    # sticking out (it stands on a wider one); a top in front only hides where it goes on,
    # and past a wide gap nothing is under it (a table's top on legs). Where the noise is
    # quiet, a face seen nearly edge-on reads the half pixel its side may lie off as that
    # much nearer, over the cosine between its normal and the line of sight: a face under it
    # sticks out only past that. (Through noise the tolerance for it is asked already.)
    per_side = (np.arange(n), side)
    half_pixel = 0.5 * tops.pixel_m * slant[per_side]
    edge_on = np.where(quiet, half_pixel, 0.0)
    # A face read steady down its levels (a box's side, not a face placed a little askew)
    # steps out where a box a little wider stands under it, whose top is too narrow to be
    # seen: nearer than the face reads above, past the noise and the half pixel that a probe
    # and the face's reading each may land off.
    on_side = on_face[per_side]  # (n, levels, probes)
    with np.errstate(invalid="ignore"):
        by_level = _mean_where(seen[per_side] - z_expected[per_side], on_side, 2)  # (n, levels)
    face_levels = np.arange(FACE_LEVELS)[None, :] < deepest[:, None]
    high = np.max(np.where(face_levels, by_level, -np.inf), axis=1)
    low = np.min(np.where(face_levels, by_level, np.inf), axis=1)
    allowed = 4.0 * tops.sigma_m + 2.0 * half_pixel
    steady = (deepest >= 2) & (high - low < allowed)
    face = _mean_where(by_level, face_levels, 1)

    def ends_at(level: npt.NDArray[np.intp]) -> tuple[BoolArray, Float64Array]:
        """Per probe at ``level`` on the side: whether the face is seen to end there, and
        how far behind the side's plane it reads (negative: nearer)."""
        index = (np.arange(n), side, level)
        vc, uc = vi[index] - origin[0], ui[index] - origin[1]
        in_crop = (vc >= 0) & (vc < rows) & (uc >= 0) & (uc < cols)
        on_top = in_crop & near_top[np.clip(vc, 0, rows - 1), np.clip(uc, 0, cols - 1)]
        gap = seen[index] - z_expected[index]
        off = gap - face[:, None]  # off what the face reads
        with np.errstate(invalid="ignore"):
            recessed = (off > tolerance[:, 0, 0]) & (gap < RECESS_M) & inside[index]
            sticking_out = (
                (
                    (off < -(tolerance[:, 0, 0] + edge_on[:, None]))
                    | (steady[:, None] & (off < -allowed[:, None]))
                )
                & inside[index]
                & ~on_top
                & (gap > -STICKING_OUT_M)
            )
        result: BoolArray = recessed | sticking_out
        return result, gap

    # Just under its last level, or where the face reads steady the level after (probes there
    # may straddle the end, and read neither the face nor what is past it).
    below = np.clip(deepest, 0, FACE_LEVELS - 1)
    ends, gap = ends_at(below)
    later, later_gap = ends_at(np.clip(deepest + 1, 0, FACE_LEVELS - 1))
    first = ends.mean(axis=1) >= 0.5
    second = ~first & steady & (later.mean(axis=1) >= 0.5) & (deepest + 1 < FACE_LEVELS)
    ledge = (first | second) & (deepest > 0) & (deepest < FACE_LEVELS)
    if ledge.any():
        # Where between its last level and where it is seen to end the face ends, to a part
        # of a level (the box stands there): the last of finer levels still read as the face,
        # within its tolerance and nearer what it reads above than what is seen past its end.
        ends, gap = (
            np.where(second[:, None], later, ends),
            np.where(second[:, None], later_gap, gap),
        )
        past = _mean_where(gap, ends, 1)
        spacing = share[0] - share[1]
        last_share = share[np.clip(deepest - 1, 0, FACE_LEVELS - 1)]
        finer = np.arange(1, 2 * FINE_LEVELS)[None, :] / FINE_LEVELS
        fine = last_share[:, None] - spacing * finer
        z_fine, seen_fine, inside_fine, _ = _on_sides(
            tops, fine * tops.height_m[:, None], depth_m, lens, support
        )
        reading = seen_fine[per_side] - z_fine[per_side]  # (n, fine levels, probes)
        valid = inside_fine[per_side] & np.isfinite(reading)
        mean = _mean_where(reading, valid, 2)
        on_fine = (np.abs(reading) < tolerance[:, 0]) & valid
        still = (np.abs(mean - face[:, None]) < np.abs(mean - past[:, None])) & (
            on_fine.sum(axis=2) >= 0.5 * np.maximum(valid.sum(axis=2), 1)
        )
        still &= finer < np.where(second, 2, 1)[:, None]
        further = np.cumprod(still, axis=1).sum(axis=1)
        refined = (last_share - spacing * further / FINE_LEVELS) * tops.height_m
        bottom = np.where(ledge, refined, bottom)
    looked_any = looked.any(axis=1)
    return np.where(looked_any, bottom, np.nan), ledge & looked_any


def _bases(
    tops: Tops,
    round_: Round,
    face_bottom_m: Float64Array,
    ledge: BoolArray,
    depth_m: Float32Array,
    lens: Intrinsics,
    support: Support,
) -> tuple[Float64Array, npt.NDArray[np.intp], BoolArray]:
    """The level each top stands on, which top that is (-1: the support), and whether that
    top reaches under it (its rectangle holds the top's middle; always on the support).

    The candidates are the support and the lower tops seen round the top, near it, or whose
    rectangle holds its middle (a lower top seen only in a gap). Each is looked for at its own
    height just past the top's sides: a box stands on the level found there on the most probes
    (a box on a wider box finds it all round; a box beside a lower one finds it on one side
    only, and its own base level on the others). Ties go to the higher level; of tops at
    one level within the noise, the one whose rectangle holds its middle. A level above
    where the top's faces are seen to end is none it stands on: its sides go on down past it
    (a box beside lower ones, seen from the side they do not hide), and a level found where
    the faces end, past two sides or more, wins (a box on one a little wider, whose top shows
    past few probes; a box beside a lower one finds that one past a single side); where
    the faces end on the face of a box sticking out under them, it stands there (on the level
    of the support or of a top reaching under it, if one is found there). Nothing stands
    through a lower top whose rectangle holds its middle: read lower than that, it stands on
    it. A top that finds only a lower neighbour beside it takes the level its layer stands on
    (below)."""
    n = len(tops)
    lower = tops.height_m[None, :] < tops.height_m[:, None] - 0.01  # (k top, j lower)
    seen = round_.seen_top.reshape(n, -1)
    counts = np.zeros((n, n + 1), dtype=np.int64)
    np.add.at(counts, (np.repeat(np.arange(n), seen.shape[1]), seen.ravel() + 1), 1)
    d = tops.middle_ab[:, None, :] - tops.middle_ab[None, :, :]
    along = np.abs(d[..., 0] * tops.axis_ab[None, :, 0] + d[..., 1] * tops.axis_ab[None, :, 1])
    across = np.abs(d[..., 1] * tops.axis_ab[None, :, 0] - d[..., 0] * tops.axis_ab[None, :, 1])
    holds = (along <= 0.5 * tops.length_m[None, :]) & (across <= 0.5 * tops.width_m[None, :])
    reach = 0.5 * np.hypot(tops.length_m, tops.width_m) + PROBE_REACH_M
    near = np.hypot(d[..., 0], d[..., 1]) < reach[:, None] + reach[None, :]
    # How far above where the faces end a level may be that they end on (a level, and the
    # face's tolerance: a top in front may hide their last part), and how far below (where
    # the end was looked for again finer, a finer level and the tolerance).
    wall = np.maximum(4.0 * tops.sigma_m, WALL_TOLERANCE_M)
    step = tops.height_m / FACE_LEVELS + wall
    step_below = np.where(ledge, tops.height_m / (FACE_LEVELS * FINE_LEVELS) + wall, step)
    above_faces = tops.height_m[None, :] > (face_bottom_m + step)[:, None]  # NaN: never
    candidate = lower & ((counts[:, 1:] > 0) | holds | near) & ~above_faces
    candidate[np.arange(n), np.arange(n)] = False
    # The few highest candidates of each top, then the support.
    width = min(CANDIDATES, n)
    ranked = np.argsort(np.where(candidate, -tops.height_m[None, :], np.inf), axis=1)[:, :width]
    real = np.take_along_axis(candidate, ranked, axis=1)
    levels = np.concatenate(
        [np.where(real, tops.height_m[ranked], np.nan), np.zeros((n, 1))], axis=1
    )  # (n, C + 1)
    ab = round_.ab[:, None]  # (n, 1, 4, P, 2)
    z_expected, seen_z, _, _ = sight(
        ab, levels[:, :, None, None], tops.basis, depth_m, lens, support
    )
    tolerance = np.maximum(3.0 * tops.sigma_m, 0.006)[:, None, None, None]
    with np.errstate(invalid="ignore"):
        found = np.abs(seen_z - z_expected) < tolerance
    score = found.reshape(n, width + 1, -1).sum(axis=2).astype(np.float64)
    score[np.isnan(levels)] = -1.0
    # The level its faces are seen to end on, found past two sides or more, is what it stands
    # on (a box beside a lower one finds that one past a single side).
    sides = found.any(axis=3).sum(axis=2)
    off_faces = levels - face_bottom_m[:, None]
    at_face = (off_faces < step[:, None]) & (off_faces > -step_below[:, None]) & (sides >= 2)
    score += 1000.0 * at_face
    score += 1e-3 * np.nan_to_num(levels, nan=0.0)  # ties: the higher
    best = np.argmax(score, axis=1)
    rows = np.arange(n)
    base = np.nan_to_num(levels[rows, best], nan=0.0)
    # Tops at one level within the noise are found on the same probes: of those, it stands on
    # one that reaches under it (not a neighbour of that height beside it).
    holds_ranked = np.take_along_axis(holds, ranked, axis=1)
    under_alike = (
        (np.abs(levels[:, :width] - levels[rows, best, None]) < tolerance[:, 0, 0])
        & (score[:, :width] >= 1000.0 * at_face[rows, best, None])
        & holds_ranked
        & (best < width)[:, None]
    )
    best = np.where(under_alike.any(axis=1), np.argmax(under_alike, axis=1), best)

    def top_of(column: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
        """The top at each row's ``column`` of ``levels`` (-1: the support)."""
        top: npt.NDArray[np.intp] = np.where(
            column < width, ranked[rows, np.minimum(column, width - 1)], -1
        )
        return top

    on = top_of(best)
    # A face seen to end: the box stands there (on a box whose top it hides, or that is too
    # small to be a top), unless a level was found there; or on the level there of the support
    # or a top reaching under it, the highest (a top's level is read more surely than where a
    # face ends).
    off_base = base - face_bottom_m
    unmatched = ledge & ((off_base > step) | (off_base < -step_below))
    reaching = np.concatenate([holds_ranked, np.ones((n, 1), dtype=bool)], axis=1)
    there = (np.abs(off_faces) < step_below[:, None]) & reaching
    nearest = np.argmax(np.where(there, levels, -np.inf), axis=1)
    level_there = there[rows, nearest]
    base = np.where(unmatched, np.where(level_there, levels[rows, nearest], face_bottom_m), base)
    on = np.where(unmatched, np.where(level_there, top_of(nearest), -1), on)
    # Nothing stands through a top under it: a box read lower than a lower top whose
    # rectangle holds its middle (its face running on down flush with that one's, or past it
    # into the floor seen beyond) stands on that top, the highest such.
    under = np.where(lower & holds, tops.height_m[None, :], -np.inf)
    j = np.argmax(under, axis=1)
    through = base < under[rows, j] - tolerance[:, 0, 0, 0]
    base = np.where(through, tops.height_m[j], base)
    on = np.where(through, j, on)
    held = (on < 0) | holds[rows, np.maximum(on, 0)]
    # Cartons packed side by side at one height stand on one level: a top that finds only a
    # lower neighbour beside it (its faces not seen to end on it) takes the level a top of its
    # layer (its height, touching, along the layer) stands on, seen under it (the support, or
    # a top reaching under it): the highest such, where a flush face runs on down past a
    # pallet's edge.
    touching = counts[:, 1:] > 0
    noise = tolerance[:, 0, 0, 0]
    alike = (
        np.abs(tops.height_m[:, None] - tops.height_m[None, :])
        < np.maximum(noise[:, None], noise[None, :])
    ) & (touching | touching.T)
    layer = alike | np.eye(n, dtype=bool)
    while alike.any():  # ... along the layer: the tops reached through one another
        grown = (layer.astype(np.int64) @ layer.astype(np.int64)) > 0
        if (grown == layer).all():
            break
        layer = grown
    given = np.where(layer & held[None, :], base[None, :], -np.inf)
    source = np.argmax(given, axis=1)
    take = ~held & ~(unmatched & ~through) & np.isfinite(given[rows, source])
    base[take], on[take] = base[source[take]], on[source[take]]
    return base, on, held


def _report(
    tops: Tops,
    round_: Round,
    is_box: BoolArray,
    base_m: Float64Array,
    on: npt.NDArray[np.intp],
    held: BoolArray,
    support: Support,
    camera_to_world: Float64Array | None,
    settings: FinderSettings,
) -> list[Box]:
    e1, e2, n_c = tops.basis
    rotation = camera_to_world[:3, :3] if camera_to_world is not None else np.eye(3)
    shift = camera_to_world[:3, 3] if camera_to_world is not None else np.zeros(3)
    order = [int(k) for k in np.argsort(-tops.height_m) if is_box[k]]
    index = {k: i for i, k in enumerate(order)}
    flatness = np.clip(1.0 - tops.rms_m / np.maximum(FLAT_SIGMAS * tops.sigma_m, FLAT_M), 0, 1)
    result: list[Box] = []
    for k in order:
        middle = tops.middle_ab[k]
        top_c = middle[0] * e1 + middle[1] * e2 + (tops.height_m[k] - support.offset_camera_m) * n_c
        height = float(tops.height_m[k] - base_m[k])
        hidden = round_.hidden[k]
        entry = match(
            float(tops.length_m[k]),
            float(tops.width_m[k]),
            height,
            settings.catalogue,
            hidden_length=bool(hidden[0] or hidden[1]),
            hidden_width=bool(hidden[2] or hidden[3]),
        )
        if entry is not None:
            height = entry.height_m
        centre_c = top_c - 0.5 * height * n_c
        length_c = tops.axis_ab[k, 0] * e1 + tops.axis_ab[k, 1] * e2
        x_axis = rotation @ length_c
        z_axis = rotation @ n_c
        y_axis = cross(z_axis, x_axis)
        top = rotation @ top_c + shift
        centre = rotation @ centre_c + shift
        if settings.workspace is not None and not all(
            lo <= value <= hi for value, (lo, hi) in zip(top, settings.workspace, strict=True)
        ):
            continue
        if camera_to_world is not None:
            yaw = math.degrees(math.atan2(float(x_axis[1]), float(x_axis[0])))
        else:
            yaw = math.degrees(math.atan2(float(tops.axis_ab[k, 1]), float(tops.axis_ab[k, 0])))
        yaw = (yaw + 90.0) % 180.0 - 90.0
        if yaw == -90.0:
            yaw = 90.0
        q = quaternion(np.stack([x_axis, y_axis, z_axis], axis=1))
        seen_base = np.abs(round_.lower_m[k] - base_m[k]) < np.maximum(4.0 * tops.sigma_m[k], 0.01)
        result.append(
            Box(
                centre=_vec(centre),
                quaternion_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
                size=(float(tops.length_m[k]), float(tops.width_m[k]), height),
                yaw_deg=yaw,
                score=float(min(tops.fill[k], 1.0) * flatness[k]),
                top_pixels=int(tops.pixels[k]),
                top_middle=_vec(top),
                on=index.get(int(on[k])) if on[k] >= 0 else None,
                hidden_sides=int(hidden.sum()),
                # Seen beside it, on the support or a top reaching under it: a lower
                # neighbour's level, in a layer of cartons, says nothing of what is under it.
                height_seen=bool(seen_base.any() and held[k]),
                name="" if entry is None else entry.name,
            )
        )
    if len(result) != len(order):
        result = [replace(b, on=None) for b in result]
    return result


def quaternion(m: Float64Array) -> Float64Array:
    """x, y, z, w of a rotation matrix (Shepperd's method: the largest of the four first)."""
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    diagonal = [m[0, 0], m[1, 1], m[2, 2], trace]
    i = diagonal.index(max(diagonal))  # the first largest, as np.argmax
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
    return result / math.sqrt(result.dot(result))  # np.linalg.norm's own sum


def _vec(v: Float64Array) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))
