"""Every box in a depth picture: oriented, full size, topmost first, with stable ids in a stream.

Contract: :func:`find_boxes` takes a depth picture (H x W float32 metres; NaN, 0, negative and
inf are no reading), the lens (CameraInfo convention: the middle of pixel u is at u), the
camera's pose (optical frame -> world, 4 x 4) or None, optionally the colour picture of the
same size (H x W x 3 uint8) and how many whole pixels it lies off the depth, and
:class:`FinderSettings`. It returns :class:`Found`: the support plane and the boxes, highest top
first, in the world frame with a pose and in the optical frame without one ("up" is then the
support normal, toward the camera). :class:`BoxFinder` does the same for a stream, keeping the
support while it still fits, measuring how far the colour lies off the depth
(:mod:`onebox.perception.register`) on its first picture and every ``register_every`` after,
and giving each box an id that stays while the box does not move. No I/O here.

How a picture is read (whole-array work; Python loops only over tops, a few scalars each).
Steps 2 to 5 are :mod:`onebox.perception.tops`, step 6 :mod:`onebox.perception.bases`; this
module reads the picture at its size, fits the support and reports:

0. Pictures larger than ``max_pixels`` (default 848 x 480: a D435's depth picture and an
   Azure Kinect's 640 x 576 are read whole) are read at every k-th pixel, the lens scaled
   exactly (1280 x 720 is read as 640 x 360).
1. The support (:mod:`onebox.perception.support`): the lowest large plane facing up, its noise
   and how wide the noise's lumps are measured on it. Where the depth noise there is 15 mm or
   more (a D435 past 2 m), steps 2 to 7 run twice: on the picture, then on its 3 x 3 median
   (:func:`onebox.perception.segment.median3`, its noise and lumps measured again against the
   plane), whose boxes are added where they share no room with one found already; the two
   readings run side by side, the median's in a thread of its own. Four sigma, the least
   step the finder trusts, was taller there than many a box; the median keeps edges and
   steps and cuts the noise about 2.4-fold, but read alone it lost bases and seams that the
   picture's own readings give.
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
   support (a top narrower than its noise: by its plane along the rays, if it stands free;
   a long top seen whole, within what the noise's lumps tilt a flat top of its size),
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

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import bases, register, segment, tops
from onebox.perception.support import (
    Support,
    fit_support,
    lump_width,
    noise_against,
    support_holds,
)
from onebox.perception.tops import FinderSettings, Plateau

__all__ = ["Box", "BoxFinder", "FinderSettings", "Found", "find_boxes"]

SMOOTH_SIGMA_M = 0.015
"""Depth noise (sigma at the support's distance) from which the picture's 3 x 3 median is read
too: there 4 sigma, the least step the finder trusts, is as tall as many a box."""

SHARED_HEIGHT_M = 0.01
"""Two boxes whose heights overlap by more than this (and whose footprints overlap) share
room: one is not standing on the other."""
SHARED_FOOTPRINT = 0.25
"""...and whose footprints overlap by more than this share of the smaller one's: one box
found in both pictures, not two neighbours, one of them misread in one picture."""

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
Vec3 = tuple[float, float, float]


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
    depth = np.asarray(depth_m, dtype=np.float32)
    frame = "world" if camera_to_world is not None else "camera"
    if colour is not None:
        colour = register.in_register(colour, colour_shift)
    stride = read_stride(depth.shape, settings.max_pixels)
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
    from_median = None
    if settings.noise_sigma_m is None and support.sigma_m > SMOOTH_SIGMA_M:
        # The two readings share nothing but their inputs: the median's runs in a thread
        # beside this one (NumPy's array work lets go of the interpreter).
        from_median = _median_reader().submit(
            _read, depth, lens, camera_to_world, colour, settings, support, median=True
        )
    boxes = _read(depth, lens, camera_to_world, colour, settings, support)
    if from_median is not None:
        boxes = _together(boxes, from_median.result(), support)
    return Found(support, boxes, frame)


_median_readers: dict[int, ThreadPoolExecutor] = {}


def _median_reader() -> ThreadPoolExecutor:
    """This process's thread for the median's reading (a forked child makes its own: its
    parent's thread is not in it)."""
    pid = os.getpid()
    if pid not in _median_readers:
        _median_readers[pid] = ThreadPoolExecutor(1, thread_name_prefix="onebox-median")
    return _median_readers[pid]


def _read(
    depth: Float32Array,
    lens: Intrinsics,
    camera_to_world: Float64Array | None,
    colour: npt.NDArray[np.uint8] | None,
    settings: FinderSettings,
    support: Support,
    median: bool = False,
) -> list[Box]:
    """Steps 2 to 7 on one picture, or on its 3 x 3 median (its noise and lumps measured
    again against the plane)."""
    if median:
        depth = segment.median3(depth)
        support = replace(support, sigma_m=noise_against(depth, lens, support))
        support = replace(support, lump_px=lump_width(depth, lens, support))
    plateaus, height_m, labels_top = tops.plateaus(depth, lens, colour, settings, support)
    if not plateaus:
        return []
    basis = tops.plane_basis(support, camera_to_world)
    # Scraps of a carton's top round a box on it (strips, and a taped carton's flaps) are
    # levels, not boxes, if that box is found to stand at their level; if it is not, the bases
    # are found again with them as boxes.
    candidates = [p for p in plateaus if p.is_box]
    scraps = tops.scraps(candidates, plateaus)
    scraps += [p for p in tops.flaps(candidates, plateaus) if p not in scraps]
    fresh = [dict(vars(p)) for p in plateaus] if scraps else []
    for scrap in scraps:
        scrap.is_box = False
    boxes = [p for p in plateaus if p.is_box]
    bases.find_bases(boxes, plateaus, height_m, labels_top, lens, support, settings)
    confirmed = {id(p) for p in tops.scraps(scraps, plateaus, standing=True)}
    confirmed |= {id(p) for p in tops.flaps(scraps, plateaus, standing=True)}
    if len(confirmed) < len(scraps):
        for p, state in zip(plateaus, fresh, strict=True):
            vars(p).update(state)
            p.is_box = p.is_box and id(p) not in confirmed
        boxes = [p for p in plateaus if p.is_box]
        bases.find_bases(boxes, plateaus, height_m, labels_top, lens, support, settings)
    bases.raise_to_faces(boxes, plateaus, depth, colour, lens, support, settings)
    bases.shadowed_sides(boxes, support.offset_camera_m, settings)
    afloat = bases.seen_under(boxes, depth, lens, support)
    afloat |= bases.open_under(boxes, depth, lens, support)
    reported = [
        b
        for b, floats in zip(boxes, afloat, strict=True)
        if not floats
        and not b.platform
        and not bases.extent_unknown(b)
        and b.rect is not None
        and b.rect.width_m >= tops.MIN_WIDTH_M
    ]
    return _report(reported, support, basis, camera_to_world, settings)


def _together(boxes: list[Box], more: list[Box], support: Support) -> list[Box]:
    """``boxes`` and those of ``more`` that share no room with any of them (a box standing on
    another shares none), highest top first, ``on`` pointing into the joined list."""
    normal = np.asarray(support.normal)
    added = [m for m in more if not any(_share_room(m, b, normal) for b in boxes)]
    if not added:
        return boxes
    joined = boxes + added
    # Where each box of ``more`` went: itself if added, else the box it shares room with.
    where = {
        id(m): next((i for i, b in enumerate(joined) if b is m or _share_room(m, b, normal)), -1)
        for m in more
    }
    for k in range(len(boxes), len(joined)):
        under = joined[k].on
        if under is not None:
            target = where[id(more[under])]
            joined[k] = replace(joined[k], on=target if target >= 0 else None)
    order = sorted(
        range(len(joined)), key=lambda i: -float(normal @ np.asarray(joined[i].top_middle))
    )
    rank = {old: new for new, old in enumerate(order)}
    result = []
    for i in order:
        under = joined[i].on
        result.append(joined[i] if under is None else replace(joined[i], on=rank[under]))
    return result


def _share_room(a: Box, b: Box, normal: Float64Array) -> bool:
    """Whether two boxes are one box seen twice: their heights along ``normal`` overlap by more
    than a centimetre, and their footprints (rectangles across ``normal``) by more than
    :data:`SHARED_FOOTPRINT` of the smaller one. Neighbours, or a box one picture merged with
    its neighbour, overlap by a sliver at most."""
    half = []
    for box in (a, b):
        top = float(normal @ np.asarray(box.top_middle))
        half.append((top - box.size[2], top))
    if min(half[0][1], half[1][1]) - max(half[0][0], half[1][0]) <= SHARED_HEIGHT_M:
        return False
    apart = np.asarray(a.top_middle) - np.asarray(b.top_middle)
    apart -= (apart @ normal) * normal
    if np.linalg.norm(apart) >= 0.5 * (math.hypot(*a.size[:2]) + math.hypot(*b.size[:2])):
        return False  # the circles round their footprints do not meet
    across = tops.cross(normal, np.array([1.0, 0.0, 0.0]))
    if np.linalg.norm(across) < 0.5:
        across = tops.cross(normal, np.array([0.0, 1.0, 0.0]))
    plane = np.stack([across / np.linalg.norm(across), tops.cross(normal, across)])
    outlines = []
    for box in (a, b):
        x, y, z, w = box.quaternion_xyzw
        length = np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])
        width = tops.cross(normal, length)
        middle = np.asarray(box.top_middle)
        corners = [
            middle + sx * box.size[0] / 2 * length + sy * box.size[1] / 2 * width
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
        outlines.append(np.array(corners) @ plane.T)
    smaller = min(box.size[0] * box.size[1] for box in (a, b))
    return _overlap_area(outlines[0], outlines[1]) > SHARED_FOOTPRINT * smaller


def _overlap_area(p: Float64Array, q: Float64Array) -> float:
    """The area two convex polygons (corners in order, n x 2) share: ``p`` clipped by each of
    ``q``'s sides in turn (Sutherland-Hodgman)."""
    orient = 1.0 if _signed_area(q) >= 0 else -1.0
    poly = list(p)
    for k in range(len(q)):
        if not poly:
            return 0.0
        s, e = q[k], q[(k + 1) % len(q)]
        edge = e - s

        def side(pt: Float64Array, s: Float64Array = s, edge: Float64Array = edge) -> float:
            return orient * float(edge[0] * (pt[1] - s[1]) - edge[1] * (pt[0] - s[0]))

        clipped = []
        for i, cur in enumerate(poly):
            prev = poly[i - 1]
            sc, sp = side(cur), side(prev)
            if sc >= 0:
                if sp < 0:
                    clipped.append(prev + (cur - prev) * (sp / (sp - sc)))
                clipped.append(cur)
            elif sp >= 0:
                clipped.append(prev + (cur - prev) * (sp / (sp - sc)))
        poly = clipped
    return abs(_signed_area(np.array(poly))) if len(poly) >= 3 else 0.0


def _signed_area(poly: Float64Array) -> float:
    """A polygon's area, positive when its corners run anticlockwise (shoelace)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(x @ np.roll(y, -1) - y @ np.roll(x, -1))


def read_stride(shape: tuple[int, ...], max_pixels: int | None) -> int:
    """Every how many pixels a picture is read (1: all)."""
    if max_pixels is None or shape[0] * shape[1] <= max_pixels:
        return 1
    return math.ceil(math.sqrt(shape[0] * shape[1] / max_pixels))


def _report(
    boxes: list[Plateau],
    support: Support,
    basis: Float64Array,
    camera_to_world: Float64Array | None,
    settings: FinderSettings,
) -> list[Box]:
    cam_basis = tops.plane_basis(support, None)
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
        y_axis = tops.cross(z_axis, x_axis)
        top = rotation @ top_c + shift
        centre = rotation @ centre_c + shift
        if settings.workspace is not None and not all(
            lo <= value <= hi for value, (lo, hi) in zip(top, settings.workspace, strict=True)
        ):
            continue
        reference = basis[0]
        yaw = math.degrees(
            math.atan2(float(length_c @ tops.cross(n_c, reference)), float(length_c @ reference))
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
    still fits (checked on the grid sample), measures how far the colour lies off the depth
    now and then, and gives each box a stable ``id``."""

    def __init__(self, settings: FinderSettings = FinderSettings()) -> None:
        self.settings = settings
        self._support: Support | None = None
        self._pose: Float64Array | None = None
        self._lens: Intrinsics | None = None
        self._last: list[Box] = []
        self._next_id = 0
        self.refits = 0
        self.registration = register.Registration(settings.colour_shift or (0, 0))
        """The colour's shift against the depth, as last measured (or as set)."""
        self._coloured = 0
        """Pictures with colour read since the lens last changed."""

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
        if lens != self._lens:
            self._coloured = 0
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
        if colour is not None and self.settings.colour_shift is None:
            self._register(depth, colour, support)
        found = find_boxes(
            depth,
            lens,
            camera_to_world,
            colour,
            self.settings,
            support,
            self.registration.shift,
        )
        boxes = self._identify(found.boxes)
        return Found(found.support, boxes, found.frame)

    def _register(
        self, depth: Float32Array, colour: npt.NDArray[np.uint8], support: Support
    ) -> None:
        """Measure the colour's shift on the first picture and every ``register_every`` after;
        a later measurement replaces the shift kept only if it is sure."""
        if self._coloured % max(self.settings.register_every, 1) == 0:
            measured = register.colour_offset(depth, colour, support.sigma_m)
            if measured.sure or self._coloured == 0:
                self.registration = measured
        self._coloured += 1

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
