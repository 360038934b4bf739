"""The box finder (onebox.perception) on pictures whose answers are known: the seed's capture,
ray-cast scenes, bad input, and each mechanism of the pipeline on its own."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
import pytest
from scipy import ndimage

from onebox import pictures
from onebox.geometry import FrameTree, Intrinsics
from onebox.perception import kernels, register
from onebox.perception.boxes import FinderSettings, find_boxes
from onebox.perception.stream import BoxFinder
from onebox.perception.support import depth_quantum, fit_support
from onebox.perception.surface import Surface, read_surface
from onebox.perception.tops import find_tops, standing_regions
from onebox.testing import synthetic
from onebox.testing.capture import load_capture
from onebox.testing.judged import yaw_error
from onebox.testing.raycast import (
    Box,
    Camera,
    Cylinder,
    Mark,
    Noise,
    Plane,
    Scene,
    Sphere,
    add_noise,
    box_on,
    loaded_pallet,
    lying,
    render,
    table_on_legs,
    taped,
)
from onebox.world.noise import PRESETS, DepthNoise

TAN = ((200, 150, 90), (140, 100, 60))
"""Two carton colours, alternating so touching cartons part by colour."""
BROWN = (150, 110, 70)
P = Plane()
"""The table, z = 0."""


def random_boxes(seed: int, count: int, spread_m: float) -> tuple[Box, ...]:
    """Up to ``count`` boxes scattered without overlap inside +-spread_m of the origin."""
    rng, boxes = np.random.default_rng(seed), []
    for _ in range(count * 20):
        size = tuple(float(rng.uniform(*r)) for r in ((0.05, 0.14), (0.04, 0.1), (0.02, 0.1)))
        x, y = rng.uniform(-spread_m, spread_m, 2)
        radius = math.hypot(size[0], size[1]) / 2
        if len(boxes) < count and all(
            math.hypot(x - b.centre[0], y - b.centre[1]) >= radius + math.hypot(*b.size[:2]) / 2
            + 0.01 for b in boxes
        ):  # fmt: skip
            colour = tuple(int(v) for v in rng.integers(60, 230, 3))
            boxes.append(box_on(Plane(), x, y, size, float(rng.uniform(-90, 90)), colour))  # type: ignore[arg-type]
    return tuple(boxes)


def match(found, truth):
    """Pairs of (found box, true box), the found box whose top middle is nearest."""
    return [(min(found, key=lambda f: math.dist(f.top_middle, t.top_middle)), t) for t in truth]


def noisy(depth, noise, seed: int):
    """``depth`` through ``noise``: a raycast Noise, or a preset's name (onebox.world.noise)."""
    if noise is None:
        return depth
    if isinstance(noise, str):
        return DepthNoise(dataclasses.replace(PRESETS[noise], seed=seed), depth.shape).apply(depth)
    return add_noise(depth, noise, np.random.default_rng(seed))


XFAIL: dict[str, str] = {
    "noise-free, 4 boxes at 2 m": "all 4 found, but one's yaw is 2.3 deg off (bound 1 deg)",
    "cans lying down, lumpy sigma 3 mm": "all 4 cans are boxes in each of 3 pictures (6 found "
    "for 2: 0.08 x 0.07, 0.16 x 0.06, 0.10 x 0.05 and 0.13 x 0.04 m)",
    "a box nearly covering the one under it": "measured from the table: 0.220 m for 0.125",
    "a box flush on one of its footprint": "measured from the table: 0.200 m for 0.130",
    "a box between lower ones touching it": "measured 0.011 m tall for 0.0718, standing on the "
    "0.0607 m boxes beside it",
    "tops joined by side faces, d435, depth only": "the 0.15 m box measured 0.070 m (80.5 mm "
    "short: standing on the low box beside it); the tall one right",
    "cartons in rows, some 14 mm lower": "the two taller cartons measured 0.014 m tall, standing "
    "on their lower neighbours (0.150 true)",
    "two touching cartons of two browns": "one box 0.201 x 0.081 x 0.060 m for the two 0.10 x "
    "0.08 cartons (the side they share, 8 cm, is shorter than seams.MIN_SEAM_M, 10 cm)",
    "three cartons, 5 mm dark rims": "one box 0.201 x 0.161 x 0.060 m for the three cartons "
    "(seams of 8 and 20 cm)",
    "cartons 2 mm apart at 2 m, depth only": "one box 0.504 x 0.204 x 0.149 m for the two "
    "0.25 x 0.2 cartons",
    "cartons end to end, a shadow between": "one box 0.601 x 0.206 x 0.200 m for the two 0.3 x "
    "0.2 cartons",
    "two cartons of one brown, 12 and 9 cm wide": "both found, heights right; widths 124.3 and "
    "85.8 mm for 120 and 90 (bound 4 mm)",
    "low boxes 2.5 m from a d435": "both found, one centre 10.3 mm off (bound 10)",
    "narrow boxes through an azure kinect": "all 3 found, one centre 4.8 mm off (bound 4), "
    "height 2.0 mm off (bound 1)",
    "a small box where the depth is clean": "both found, the small box 26.4 x 25.2 mm for 25 x "
    "23 (bound 2 mm)",
    "narrow boxes under a tilted camera": "1 of the 4 boxes 1.5-2 cm wide found (the 0.200 x "
    "0.018 m one, 0.203 x 0.021 m)",
    "cartons on a pallet, d435": "8 boxes for 12: the four 0.2 m cartons missed, the 8 others "
    "measured 0.05-0.1 m tall, from their lower neighbours' tops",
    "cartons on a pallet, azure kinect": "10 boxes for 12: the two 0.2 m cartons at the ends of "
    "a row missed (one top seen either side of the taller ones between them), 7 of the others "
    "measured 0.05-0.1 m tall from their neighbours' tops",
    "a pallet's margin under rows of two heights": "the 4 middle cartons 14-15 mm off (bound "
    "10), 0.180-0.186 m wide for 0.200; the far row of three one box 1.079 m long, 0.099 m tall",
    "taped cartons of one brown, d435": "21 boxes for 12: cartons split at their tape into "
    "halves 0.12-0.15 m wide (one row of them a strip 1.13 m long), measured 0.05-0.35 m tall",
    "labelled cartons of one brown": "10 boxes for 12, 8 of them measured 0.05-0.1 m tall from "
    "their neighbours' tops",
}
"""What the finder does wrong, by case, as measured (python -m pytest tests/test_perception.py
-rx lists them; a case it gets right again fails as XPASS until it leaves this table)."""


def xfail(reason: str) -> pytest.MarkDecorator:
    return pytest.mark.xfail(strict=True, reason=reason)


# --- the seed's world --------------------------------------------------------------------------
def test_committed_capture_gives_the_seed_answer():
    """tests/data/one_box.mcap: one box, middle (+0.064, +0.040), 0.060 tall, as the seed says."""
    capture = load_capture()
    depth = pictures.depth_m(capture["camera/depth/image_raw"])
    lens = Intrinsics.from_k(capture["camera/camera_info"].k)
    pose = FrameTree(capture["tf_static"].transforms).lookup("world", "camera_optical_frame")
    for colour in (None, pictures.rgb(capture["camera/image_raw"])):
        (box,) = find_boxes(depth, lens, pose, colour).boxes
        assert f"({box.centre[0]:+.3f}, {box.centre[1]:+.3f}) {box.size[2]:.3f}" == (
            "(+0.064, +0.040) 0.060"
        )
        assert box.size[:2] == pytest.approx((0.06, 0.06), abs=0.002) and box.id == -1
        assert box.height_seen and box.hidden_sides == 0 and box.on is None


def seed_depth(how: str) -> np.ndarray:
    """The seed's scene (a 6 cm cube at (0.065, 0.0405)) with a fiftieth of its pixels and a
    10 x 10 block read as nothing, written ``how``."""
    depth = synthetic.depth_picture(synthetic.Scene())
    gone = np.random.default_rng(0).random(depth.shape) < 0.02
    gone[100:110, 10:20] = True
    if how in ("16UC1", "32FC1"):  # through the message's bytes, as the locator reads them
        if how == "16UC1":
            depth = np.where(gone, 0, np.round(depth * 1000)).astype("<u2")
        data = depth.tobytes() if how == "16UC1" else np.where(gone, np.nan, depth).tobytes()
        return pictures.depth_metres(data, width=320, height=240, step=depth.shape[1] *
                                     depth.dtype.itemsize, encoding=how)  # fmt: skip
    return np.where(gone, {"nan": np.nan, "0": 0.0, "inf": np.inf, "-1": -1.0}[how], depth)


@pytest.mark.parametrize("pose", [True, False], ids=["pose", "no pose"])
@pytest.mark.parametrize("how", ["nan", "0", "inf", "-1", "16UC1", "32FC1"])
def test_seed_scene_through_every_kind_of_no_reading(how, pose):
    """NaN, 0, inf, negative, 16UC1's 0 and 32FC1's NaN are no reading: the cube is found, its
    middle within 1 mm, 6 cm tall; without a pose in the optical frame, 0.34 m away."""
    scene = synthetic.Scene()
    camera_to_world = scene.camera_to_world() if pose else None
    found = find_boxes(seed_depth(how), Intrinsics.from_k(scene.k), camera_to_world)
    (box,) = found.boxes
    assert found.frame == ("world" if pose else "camera")
    want = (0.065, 0.0405, 0.06) if pose else (0.065, -0.0405, 0.34)
    assert box.top_middle == pytest.approx(want, abs=0.001)
    assert box.size == pytest.approx((0.06, 0.06, 0.06), abs=0.002)


SEED_SCENES = {
    "320x240": synthetic.Scene(),
    "320x240, 4 cm": synthetic.Scene(box_x=-0.1, box_y=0.05, box_size=0.04),
    "320x240, 8 cm, 30 deg": synthetic.Scene(box_x=0.02, box_y=-0.08, box_size=0.08,
                                             box_yaw_deg=30.0),
    "640x480": synthetic.Scene(width=640, height=480),
    "640x480, 45 deg": synthetic.Scene(width=640, height=480, box_yaw_deg=45.0),
    "1280x720, hfov 90": synthetic.Scene(width=1280, height=720, hfov_deg=90.0, box_x=0.15,
                                         box_y=-0.1),
    "80x60": synthetic.Scene(width=80, height=60),
}  # fmt: skip
"""The seed's world at the sizes tests/test_measure.py checks the seed's own method on."""


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=xfail(XFAIL[n])) if n in XFAIL else n for n in SEED_SCENES]
)
def test_the_seed_scene_at_every_picture_size(name):
    """The seed's cube, any size, turned or not, at any picture size: its top's middle within
    1 mm (80 x 60: 1.5 mm), its sides within 2 mm, its height within 0.5 mm."""
    scene = SEED_SCENES[name]
    depth = synthetic.depth_picture(scene)
    (box,) = find_boxes(depth, Intrinsics.from_k(scene.k), scene.camera_to_world()).boxes
    top = (scene.box_x, scene.box_y, scene.box_size)
    assert box.top_middle == pytest.approx(top, abs=0.0015 if scene.width < 100 else 0.001)
    assert box.size == pytest.approx((scene.box_size,) * 3, abs=0.002)
    assert box.size[2] == pytest.approx(scene.box_size, abs=0.0005)


@pytest.mark.parametrize(
    "depth",
    [np.full((240, 320), np.nan), np.zeros((240, 320)), np.full((240, 320), np.inf),
     np.full((1, 1), 0.4), np.full((2, 3), 0.4), np.full((5, 5), 0.4),
     np.random.default_rng(0).uniform(0.3, 3.0, (240, 320))],
    ids=["nan", "zeros", "inf", "1x1", "2x3", "5x5", "no plane"],
)  # fmt: skip
@pytest.mark.parametrize("pose", [True, False], ids=["pose", "no pose"])
def test_no_surface_to_stand_on_is_found_none(depth, pose):
    """No reading, too few pixels or no plane among them: no support and no box, no error."""
    camera_to_world = synthetic.Scene().camera_to_world() if pose else None
    lens = Intrinsics(277.1, 277.1, depth.shape[1] / 2, depth.shape[0] / 2)
    found = find_boxes(depth.astype(np.float32), lens, camera_to_world)
    assert (found.support, found.boxes) == (None, [])
    assert found.frame == ("world" if pose else "camera")


def test_a_picture_half_without_readings_raises_no_warning():
    """A 200 x 200 block with no reading beside the seed's table: the table is still found."""
    scene = synthetic.Scene(has_box=False)
    depth = synthetic.depth_picture(scene)
    depth[:200, :200] = np.nan
    found = find_boxes(depth, Intrinsics.from_k(scene.k), scene.camera_to_world())
    assert found.support is not None and found.boxes == []


# --- scenes: each rendered, the boxes found and judged one way -----------------------------------
@dataclass(frozen=True)
class Case:
    """A scene (shapes, camera, the boxes to find), how it is seen and what is asked of it."""

    build: Callable[[], tuple[tuple, Camera, tuple[Box, ...]]]
    noise: Noise | str | None = None
    seeds: tuple[int, ...] = (0,)
    colour: bool = True
    centre_m: float | None = 0.003
    size_m: float | None = 0.004
    height_m: float | None = 0.002
    yaw_deg: float | None = None
    exact: bool = True
    """Nothing but the boxes to find (else: they are found, whatever else is)."""
    plane: Plane = P
    scene: dict = dataclasses.field(default_factory=dict)
    colour_shift: tuple[int, int] = (0, 0)


def tilted(d: float, tilt: float, **kw) -> Camera:
    """A camera ``d`` over its target, ``tilt`` from straight down, 640 x 480 unless told."""
    return Camera.tilted(d, tilt, width=kw.pop("width", 640), height=kw.pop("height", 480), **kw)


def spread(seed: int, count: int, d: float, tilt: float) -> Callable:
    """Random boxes spread over what a camera ``d`` away sees."""
    return lambda: ((b := random_boxes(seed, count, 0.18 * d)), tilted(d, tilt), b)


def one(*shapes, camera: Camera, find: tuple[int, ...] | None = None) -> Callable:
    """``shapes`` seen by ``camera``; the boxes to find are those at ``find`` (default: all)."""
    boxes = [i for i, s in enumerate(shapes) if isinstance(s, Box)] if find is None else find
    return lambda: (shapes, camera, tuple(shapes[i] for i in boxes))


def pallet(marked: Callable[[Box], Box] | None = None) -> Callable:
    """The loaded pallet (its cartons of one brown and ``marked`` when that is given)."""

    def build() -> tuple:
        base, cartons, camera = loaded_pallet(np.random.default_rng(0 if marked else 1))
        if marked:
            cartons = [marked(dataclasses.replace(c, colour=BROWN)) for c in cartons]
        return (base, *cartons), camera, tuple(cartons)

    return build


def end_to_end(size: tuple[float, float, float], turn: float, gap: float = 0.0) -> list[Box]:
    """Two cartons of one colour end to end, ``gap`` apart, turned ``turn`` degrees."""
    along = np.array([math.cos(math.radians(turn)), math.sin(math.radians(turn))])
    middles = [s * (size[0] + gap) / 2 * along for s in (-1.0, 1.0)]
    return [box_on(P, x, y, size, turn, (170, 130, 80)) for x, y in middles]


def turned(u: float, v: float, deg: float) -> tuple[float, float]:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return u * c - v * s, u * s + v * c


HIGH, TABLE_TOP = Plane((0.0, 0.0, 0.75)), Plane((0.0, 0.0, 0.6))
LOWER = box_on(P, 0.0, 0.0, (0.2, 0.15, 0.08), 10.0)
NEAR = box_on(P, 0.02, 0.01, (0.168, 0.069, 0.095), 15.0, (40, 90, 200))
HIDDEN = box_on(P, 0.05, 0.03, (0.08, 0.06, 0.09), 30.0, (40, 90, 200))
NARROW = box_on(P, 0.05, 0.03, (0.15, 0.06, 0.11), 30.0, (40, 90, 200))
FLUSH = box_on(P, 0.04, 0.02, (0.06, 0.02, 0.07), 20.0, (60, 90, 190))
CRATE = box_on(P, 0.0, 0.0, (0.5, 0.4, 0.6), 15.0, (170, 130, 90))
CARTONS = (
    box_on(P, -0.15, -0.12, (0.16, 0.1, 0.08), 25.0, (170, 130, 90)),
    box_on(P, 0.17, 0.12, (0.12, 0.09, 0.06), -40.0, (160, 125, 85)),
)
LIDDED = tuple(
    dataclasses.replace(box_on(P, x, y, size, yaw, colour), lid_m=0.008)
    for x, y, size, yaw, colour in (
        (0.0, 0.0, (0.3, 0.2, 0.15), 20.0, TAN[0]),
        (0.22, 0.15, (0.2, 0.15, 0.1), -15.0, TAN[1]),
        (-0.2, 0.18, (0.12, 0.1, 0.08), 5.0, BROWN),
    )
)
ROWS = tuple(
    box_on(P, *turned((j - 0.5) * 0.25, (i - 0.5) * 0.25, 20.0), (0.25, 0.25, h), 20.0,
           TAN[(i + j) % 2])
    for i, row in enumerate(((0.15, 0.136), (0.136, 0.15))) for j, h in enumerate(row)
)  # fmt: skip
"""Cartons 25 cm square in two rows of two, turned 20 degrees, each 14 mm off its neighbours."""
PALLET = box_on(P, 0.0, 0.0, (1.2, 0.8, 0.144), 0.0, (120, 90, 60))
MARGIN = (PALLET, *(
    box_on(PALLET, (col - (n - 1) / 2) * size[0], y, size, 0.0, TAN[col % 2])
    for y, size, n in ((-0.2125, (0.36, 0.275, 0.3), 3), (0.025, (0.275, 0.2, 0.2), 4),
                       (0.2625, (0.36, 0.275, 0.3), 3))
    for col in range(n)
))  # fmt: skip
"""Rows of tall, low and tall cartons inset 5 cm on a pallet: the far row's foot is hidden."""
LABEL = Mark((0.0, 0.1), (-0.075, -0.005), (240, 240, 235))


# fmt: off
CASES = {
    "noise-free, 1 box at 0.4 m": Case(
        spread(1, 1, 0.4, 0.0), centre_m=0.0015, size_m=0.002, height_m=0.001, yaw_deg=1.0),
    "noise-free, 5 boxes at 0.8 m": Case(
        spread(3, 5, 0.8, 30.0), centre_m=0.003, size_m=0.004, height_m=0.001, yaw_deg=1.0),
    "noise-free, 4 boxes at 2 m": Case(
        spread(5, 4, 2.0, 10.0), centre_m=0.0075, size_m=0.01, height_m=0.001, yaw_deg=1.0),
    "sigma 1 mm, 5 boxes at 0.5 m": Case(
        lambda: ((b := random_boxes(7, 5, 0.12)), tilted(0.5, 20.0), b),
        Noise(sigma_m=0.001), yaw_deg=2.0),
    "1280 x 720, read at every 2nd pixel": Case(
        lambda: ((b := random_boxes(3, 4, 0.15)), tilted(0.8, 20.0, width=1280, height=720), b),
        centre_m=0.002, height_m=0.001),
    **{f"a box and {name}": Case(
        one(box_on(P, 0.12, 0.05, (0.08, 0.06, 0.05), 30.0), thing, camera=tilted(0.5, 15.0)),
        centre_m=0.002)
       for name, thing in (
           ("an upright cylinder", Cylinder((0.0, 0.0, 0.06), 0.04, 0.12)),
           ("a ball", Sphere((0.0, 0.0, 0.05), 0.05)),
           ("a lying cylinder",
            Cylinder((0.0, 0.0, 0.035), 0.035, 0.2, ((1, 0, 0), (0, 0, -1), (0, 1, 0)))))},
    "bottles with round tops": Case(
        one(*(s for x in (-0.2, 0.0, 0.2)
              for s in (Cylinder((x, 0.1, 0.15), 0.02, 0.3), Sphere((x, 0.1, 0.3), 0.02))),
            camera=tilted(0.8, 20.0)),
        Noise(sigma_m=0.001), (1,)),
    "cans lying down, d435": Case(
        one(*CARTONS, lying(0.12, -0.1, 0.033, 0.12, 20.0), lying(-0.15, 0.13, 0.035, 0.22, -30.0),
            lying(0.02, 0.02, 0.05, 0.2, 80.0), camera=tilted(0.6, 17.0, hfov_deg=70)),
        Noise.d435(), (0, 1), centre_m=0.01, size_m=None, height_m=None),
    "cans lying down, lumpy sigma 3 mm": Case(
        one(CARTONS[0], box_on(P, 0.17, 0.14, (0.12, 0.09, 0.06), -40.0, (160, 125, 85)),
            lying(0.15, -0.1, 0.021, 0.13, 20.0), lying(-0.18, 0.12, 0.025, 0.1, -30.0),
            lying(0.0, 0.02, 0.03, 0.16, 80.0), lying(-0.02, -0.2, 0.042, 0.09, 10.0),
            camera=tilted(1.4, 5.0)),
        Noise(sigma_m=0.003, correlation_px=5.0), (0, 1, 2), centre_m=0.01, size_m=None,
        height_m=None),
    "an empty noisy table": Case(
        one(camera=tilted(1.0, 20.0, width=320, height=240)),
        Noise(sigma_m=0.003, quantum_m=0.001, speckle_share=0.003, speckle_clump_px=3), (0, 1, 2)),
    "an empty table through a far d435": Case(
        one(camera=tilted(1.8, 20.0, width=320, height=240)), Noise.d435(), (0, 1, 2, 3)),
    "boxes on a table, the floor round it": Case(
        one(*table_on_legs((0.8, 0.6), 0.6, 10.0),
            box_on(TABLE_TOP, -0.2, -0.1, (0.17, 0.13, 0.04), 30.0, (200, 80, 60)),
            box_on(TABLE_TOP, 0.15, 0.1, (0.19, 0.1, 0.056), -20.0, (60, 90, 200)),
            box_on(TABLE_TOP, 0.15, -0.15, (0.11, 0.09, 0.034), 70.0, (220, 200, 80)),
            camera=tilted(1.2, 25.0, target=(0.0, 0.0, 0.6)), find=(5, 6, 7)),
        Noise.d435(), centre_m=0.01, size_m=None, height_m=0.005),
    "an empty table, the floor round it": Case(
        one(*table_on_legs((0.8, 0.6), 0.6, 10.0), camera=tilted(1.0, 25.0, target=(0, 0, 0.6)),
            find=())),
    "a crate carrying a box": Case(
        one(CRATE, box_on(CRATE, 0.05, 0.03, (0.16, 0.1, 0.08), 40.0, (60, 90, 200)),
            camera=tilted(1.0, 30.0, target=(0.0, 0.0, 0.6))),
        centre_m=0.01, size_m=None, height_m=0.005),
    "a top afloat": Case(
        one(Box((-0.25, 0.0, 0.25), (0.06, 0.05, 0.004)), camera=tilted(1.0, 20.0, width=320,
            height=240), find=())),
    "the same top on a box": Case(
        one(box_on(P, -0.25, 0.0, (0.06, 0.05, 0.252)), camera=tilted(1.0, 20.0, width=320,
            height=240))),
    "a box on a box": Case(
        one(LOWER, box_on(LOWER, 0.02, -0.01, (0.1, 0.07, 0.05), 25.0, (40, 90, 200)),
            camera=tilted(0.7, 20.0)),
        height_m=0.001),
    "a box nearly covering the one under it": Case(
        one(NEAR, box_on(NEAR, 0.001, -0.0005, (0.158, 0.06, 0.125), 0.0, (190, 150, 100)),
            camera=tilted(1.0, 20.0), find=(1,)),
        exact=False, centre_m=0.0025, size_m=None, height_m=0.001),
    "a box over a smaller one it hides": Case(
        one(HIDDEN, box_on(HIDDEN, 0.0, 0.0, (0.14, 0.1, 0.07), 10.0, (190, 150, 100)),
            camera=tilted(0.8, 25.0), find=(1,)),
        centre_m=None, size_m=None, height_m=0.003),
    "a box across a narrower one": Case(
        one(NARROW, box_on(NARROW, 0.02, 0.0, (0.07, 0.09, 0.12), 15.0, (190, 150, 100)),
            camera=tilted(0.8, 25.0), find=(1,)),
        exact=False, centre_m=0.002, size_m=None, height_m=0.001),
    "a box flush on one of its footprint": Case(
        one(FLUSH, box_on(FLUSH, 0.0, 0.0, (0.06, 0.02, 0.13), 20.0, (190, 150, 100)),
            camera=tilted(0.9, 25.0), find=(1,)),
        centre_m=None, size_m=None, height_m=0.003),
    "the same from depth alone: one box from the table": Case(
        one(FLUSH, box_on(FLUSH, 0.0, 0.0, (0.06, 0.02, 0.13), 20.0, (190, 150, 100)),
            box_on(P, 0.04, 0.02, (0.06, 0.02, 0.2), 20.0), camera=tilted(0.9, 25.0), find=(2,)),
        colour=False, centre_m=None, size_m=None, height_m=0.003),
    "a box overhanging a corner of one": Case(
        one(box_on(P, 0.0, 0.14, (0.2241, 0.1226, 0.0778), 52.77, (184, 103, 195)),
            box_on(Plane((0.0, 0.0, 0.0778)), 0.0048, 0.1659, (0.0862, 0.07, 0.0681), -36.53,
                   (64, 121, 208)),
            camera=tilted(0.9, 26.4), find=(1,)),
        exact=False, centre_m=None, size_m=None, height_m=0.003),
    "a box between lower ones touching it": Case(
        one(*(box_on(P, (k - 1) * 0.1414, 0.0, (0.1, 0.1, 0.0607), 45.0, TAN[k % 2])
              for k in range(3)),
            box_on(P, -0.0707, 0.0707, (0.1, 0.1, 0.0718), 45.0, (78, 212, 202)),
            box_on(P, 0.0707, 0.0707, (0.1, 0.1, 0.0599), 45.0, (153, 111, 63)),
            camera=tilted(0.8, 6.36), find=(3,)),
        exact=False, centre_m=None, size_m=None),
    "a tall box touching a lower one": Case(
        one(box_on(P, -0.0436, -0.5542, (0.183, 0.279, 0.308), -82.0, (179, 125, 94)),
            box_on(P, 0.233, -0.5648, (0.266, 0.103, 0.353), 8.0, (43, 87, 204)),
            camera=Camera.looking_at((-0.084, -0.062, 1.69), (-0.084, -0.2, 0.0), 640, 480)),
        Noise(sigma_m=0.001), (1,), centre_m=None, size_m=None, height_m=0.006),
    "tops joined by side faces, d435, depth only": Case(
        one(box_on(P, -0.1, 0.0, (0.2, 0.2, 0.08), 25.0, (170, 130, 80)),
            box_on(P, *np.add((-0.1, 0.0), turned(0.16, 0.0, 25.0)), (0.12, 0.12, 0.22), 25.0),
            box_on(P, *np.add((-0.1, 0.0), turned(0.0, 0.16, 25.0)), (0.1, 0.12, 0.15), 25.0),
            camera=tilted(1.0, 30.0), find=(1, 2)),
        Noise.d435(), (2,), colour=False, exact=False, centre_m=0.006, size_m=None,
        height_m=0.004),
    "a face seen nearly edge-on": Case(
        lambda: ((b := random_boxes(111, 6, 0.2)), Camera.looking_at(
            (0.3, -0.5, 0.6), (0.0, 0.0, 0.0), 640, 480, roll_deg=35.0), b),
        size_m=None),
    "a flat box's corner hidden by a taller one": Case(
        one(box_on(HIGH, 0.2, 0.15, (0.3, 0.1, 0.05), 70.0, (60, 60, 200)),
            box_on(HIGH, 0.05, 0.02, (0.2, 0.15, 0.1), 20.0, (200, 60, 50)),
            camera=tilted(0.9, 20.0, target=(0.0, 0.0, 0.75))),
        Noise(sigma_m=0.001), (3,), yaw_deg=1.0, plane=HIGH),
    "bulging lids": Case(
        lambda: ((c := LIDDED), tilted(0.7, 20.0, hfov_deg=70), tuple(dataclasses.replace(
            b, size=(*b.size[:2], b.size[2] + 0.004)) for b in c)),
        centre_m=None, size_m=0.007, height_m=0.006),
    "cartons in rows, some 14 mm lower": Case(
        lambda: ((c := ROWS), tilted(2.2, 8.0), c), centre_m=None, size_m=None),
    "a lower box of another colour against a face": Case(
        one(box_on(P, 0.0, 0.0, (0.08, 0.05, 0.2), 0.0, (190, 150, 100)),
            box_on(P, 0.0, -0.065, (0.08, 0.08, 0.07), 0.0, (60, 90, 190)),
            camera=tilted(0.9, 20.0)),
        centre_m=None, size_m=None),
    "colour 2 px off, a tall box 2 m away": Case(
        one(box_on(P, 0.5, 0.4, (0.3, 0.05, 0.3), 30.0, (190, 150, 100)), camera=tilted(2.0, 5.0)),
        colour_shift=(2, 1), centre_m=None, size_m=None),
    "two touching cartons of two browns": Case(
        one(box_on(P, -0.05, 0.0, (0.1, 0.08, 0.06), 0.0, (180, 140, 90)),
            box_on(P, 0.05, 0.0, (0.1, 0.08, 0.06), 0.0, (150, 115, 70)),
            camera=tilted(0.6, 10.0))),
    "three cartons, 5 mm dark rims": Case(
        one(box_on(P, -0.05, 0.0, (0.1, 0.08, 0.06), 0.0, (180, 140, 90)),
            box_on(P, 0.05, 0.0, (0.1, 0.08, 0.06), 0.0, (150, 115, 70)),
            box_on(P, 0.0, 0.08, (0.2, 0.08, 0.06), 0.0, (170, 130, 80)),
            camera=tilted(0.6, 10.0)),
        scene={"seam_m": 0.005}),
    "cartons 2 mm apart, depth only": Case(
        one(*end_to_end((0.25, 0.2, 0.15), 35.0, 0.002), camera=tilted(1.2, 15.0)),
        Noise(sigma_m=0.001), (1,), colour=False, centre_m=0.004, size_m=0.005),
    "cartons 2 mm apart at 2 m, depth only": Case(
        one(*end_to_end((0.25, 0.2, 0.15), 35.0, 0.002), camera=tilted(2.0, 15.0)),
        colour=False, centre_m=0.004, size_m=0.005),
    "cartons end to end, a shadow between": Case(
        one(*end_to_end((0.3, 0.2, 0.2), 10.0), camera=tilted(1.5, 20.0)),
        Noise.d435(), (3,), centre_m=0.012, size_m=0.012, height_m=0.005,
        scene={"seam_m": 0.012, "seam_shade": 0.7, "seam_fades": True}),
    "two cartons of one brown, 12 and 9 cm wide": Case(
        one(box_on(P, 0.0, -0.06, (0.3, 0.12, 0.1), 0.0, BROWN),
            box_on(P, 0.0, 0.045, (0.3, 0.09, 0.1), 0.0, BROWN), camera=tilted(0.9, 15.0)),
        scene={"seam_m": 0.003}),
    "a tall box at the side, far d435": Case(
        one(box_on(P, 0.9, 0.3, (0.27, 0.13, 0.32), 25.0, (170, 130, 80)),
            camera=tilted(2.5, 15.0)),
        Noise.d435(), (0, 1), centre_m=0.015, size_m=0.02, height_m=0.005),
    "boxes and round things through a d435 at 2.3 m": Case(
        one(box_on(P, -0.25, 0.0, (0.2, 0.11, 0.3), 20.0),
            box_on(P, 0.2, 0.1, (0.3, 0.15, 0.12), -35.0, (60, 140, 200)),
            Cylinder((0.1, -0.25, 0.1), 0.08, 0.2), Sphere((-0.1, 0.3, 0.08), 0.08),
            camera=tilted(2.3, 10.0)),
        "d435", centre_m=0.01, size_m=0.025, height_m=0.003),
    "low boxes 2.5 m from a d435": Case(
        one(box_on(P, -0.25, 0.05, (0.3, 0.2, 0.07), 25.0, (180, 130, 80)),
            box_on(P, 0.25, -0.1, (0.25, 0.15, 0.05), -40.0, (60, 140, 200)),
            camera=tilted(2.5, 15.0)),
        "d435", centre_m=0.01, size_m=0.03, height_m=0.005),
    "narrow boxes through an azure kinect": Case(
        one(*(box_on(P, x, y, (0.35, w, 0.1), yaw, (r, 90, 60)) for x, y, w, r, yaw in (
            (-0.35, -0.3, 0.05, 150, 40.0), (0.3, 0.25, 0.045, 200, -70.0),
            (0.0, 0.1, 0.06, 90, 10.0))), camera=tilted(1.8, 20.0)),
        "azure_kinect", centre_m=0.004, size_m=0.008, height_m=0.001),
    "narrow boxes under a tilted camera": Case(
        one(*(box_on(P, x, y, s, yaw + 25.0, (160, 110, 70)) for x, y, s, yaw in (
            (-0.25, -0.15, (0.30, 0.015, 0.10), 25.0), (0.2, 0.1, (0.20, 0.018, 0.06), 50.0),
            (0.0, 0.25, (0.25, 0.02, 0.15), 70.0), (0.05, -0.2, (0.12, 0.016, 0.04), 115.0))),
            camera=tilted(1.8, 20.0)),
        centre_m=0.002, size_m=0.002, height_m=0.001),
    "a small box where the depth is clean": Case(
        one(box_on(P, 0.05, 0.03, (0.025, 0.023, 0.04), 15.0, (200, 60, 40)),
            box_on(P, -0.08, -0.02, (0.12, 0.08, 0.06), -20.0, (60, 90, 200)),
            camera=tilted(0.6, 20.0)),
        Noise(sigma_m=0.001), (1,), centre_m=0.002, size_m=0.002),
    "a narrow top seen at 65 degrees": Case(
        one(box_on(P, 0.0, 0.0, (0.08, 0.04, 0.06), 0.0, (100, 180, 200)),
            camera=tilted(0.5, 65.0)),
        centre_m=None, height_m=0.001),
    "cartons on a pallet, d435": Case(
        pallet(), Noise.d435(), centre_m=0.01, size_m=0.015, height_m=0.005),
    "cartons on a pallet, azure kinect": Case(
        pallet(), Noise.kinect(), (2,), centre_m=None, size_m=None, height_m=0.01),
    "a pallet's margin under rows of two heights": Case(
        lambda: ((c := MARGIN), tilted(1.86, 10.0, target=(0.0, -0.12, 0.144), hfov_deg=56.0),
                 c[1:]),
        Noise.d435(), (4,), exact=False, centre_m=0.01, size_m=None, height_m=0.01),
    "taped cartons of one brown, d435": Case(
        pallet(lambda c: taped(c, (160, 118, 76), flap_line=(96, 70, 45))), Noise.d435(), (1,),
        centre_m=0.01, size_m=0.02, height_m=0.01),
    "labelled cartons of one brown": Case(
        pallet(lambda c: dataclasses.replace(c, marks=(LABEL,))), centre_m=0.003, size_m=0.005),
}
# fmt: on


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=xfail(XFAIL[n])) if n in XFAIL else n for n in CASES]
)
def test_scene(name):
    """Every box to find is found (and nothing else where asked), its centre, sides, height and
    yaw within the case's bounds; the support is the scene's lowest plane."""
    case = CASES[name]
    shapes, camera, wanted = case.build()
    depth, colour = render(Scene(camera, case.plane, tuple(shapes), **case.scene))
    colour = np.roll(colour, case.colour_shift, axis=(0, 1))
    for seed in case.seeds:
        found = find_boxes(noisy(depth, case.noise, seed), camera.lens, camera.camera_to_world,
                           colour if case.colour else None)  # fmt: skip
        assert found.support is not None
        assert found.support.offset_m == pytest.approx(-case.plane.point[2], abs=0.01)
        sizes = [tuple(round(v, 3) for v in b.size) for b in found.boxes]
        if case.exact:
            assert len(found.boxes) == len(wanted), (seed, sizes)
        assert found.boxes or not wanted, seed
        for box, true in match(found.boxes, wanted):
            if case.centre_m is not None:
                assert math.dist(box.centre, true.centre) <= case.centre_m, (seed, sizes)
            if case.size_m is not None:
                sides = sorted(true.size[:2], reverse=True)
                assert box.size[:2] == pytest.approx(sides, abs=case.size_m), (seed, sizes)
            if case.height_m is not None:
                assert box.size[2] == pytest.approx(true.size[2], abs=case.height_m), (seed, sizes)
            if case.yaw_deg is not None:
                square = abs(true.size[0] - true.size[1]) < 0.01
                assert yaw_error(box.yaw_deg, true.yaw_deg(), square) <= case.yaw_deg


def test_a_box_on_a_box_says_what_it_stands_on():
    """The upper box of two is `on` the lower (an index into the boxes), the lower on nothing."""
    upper = box_on(LOWER, 0.02, -0.01, (0.1, 0.07, 0.05), 25.0, (40, 90, 200))
    camera = tilted(0.7, 20.0)
    depth, colour = render(Scene(camera, P, (LOWER, upper)))
    top, bottom = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
    assert (top.on, bottom.on) == (1, None)
    assert math.dist(top.centre, upper.centre) < 0.002
    assert top.height_seen and bottom.height_seen


def tote(floor_m: float, wall_m: float) -> tuple[tuple[Box, ...], tuple[Box, ...]]:
    """A tote 0.6 x 0.4 m, 0.22 m walls ``wall_m`` thick on a floor ``floor_m`` thick, and the
    three cartons in it: (the tote's parts, the cartons)."""
    blue = (50, 75, 150)
    bottom = box_on(P, 0.0, 0.0, (0.6, 0.4, floor_m), 0.0, blue)
    inside = (0.6 - 2 * wall_m, 0.4 - 2 * wall_m)
    walls = [box_on(bottom, 0.0, s * (0.2 - wall_m / 2), (0.6, wall_m, 0.22), 0.0, blue)
             for s in (-1, 1)]  # fmt: skip
    walls += [box_on(bottom, s * (0.3 - wall_m / 2), 0.0, (wall_m, inside[1], 0.22), 0.0, blue)
              for s in (-1, 1)]  # fmt: skip
    cartons = (
        box_on(bottom, -0.15, -0.05, (0.2, 0.15, 0.12), 20.0, TAN[0]),
        box_on(bottom, 0.12, 0.05, (0.22, 0.16, 0.18), 0.0, (200, 190, 150)),
        box_on(bottom, 0.14, -0.12, (0.18, 0.08, 0.1), 0.0, TAN[1]),
    )
    return (bottom, *walls), cartons


def test_a_bins_rim_is_no_box():
    """A tote with walls 15 mm thick, three cartons in it, a metre away through a D435's
    noise: the rim falls apart into pieces where its normals come and go, each going on at its
    height past its ends. Every carton is found and nothing at the rim's height."""
    parts, cartons = tote(0.015, 0.015)
    camera = tilted(0.9, 20.0)
    depth, colour = render(Scene(camera, P, (*parts, *cartons)))
    for seed in (0, 1):
        found = find_boxes(noisy(depth, "d435", seed), camera.lens, camera.camera_to_world,
                           colour).boxes  # fmt: skip
        for box, true in match(found, cartons):
            assert math.dist(box.top_middle, true.top_middle) < 0.01, seed
        rim = [tuple(round(v, 3) for v in b.size) for b in found if b.top_middle[2] > 0.2]
        assert rim == [], seed


def test_a_tins_lid_is_no_box():
    """Upright tins 0.8-1.1 m from a camera tilted 30 degrees, through a D435's noise
    correlated over 5 pixels: the side under the lid's near edge reads at the lid's height, and
    the lid's top fills a square round it. Its outline is as wide at every turn, a carton's is
    not: the carton beside each is found, the lid is no box."""
    lumpy = dataclasses.replace(Noise.d435(), correlation_px=5.0)
    carton = box_on(P, -0.15, 0.05, (0.16, 0.12, 0.1), 20.0, TAN[0])
    for radius, tall, d in ((0.04, 0.15, 0.8), (0.05, 0.09, 1.1)):
        camera = tilted(d, 30.0)
        depth, colour = render(Scene(camera, P, (carton, Cylinder((0.1, 0.0, tall / 2), radius,
                                                                  tall))))  # fmt: skip
        for seed in (0, 1, 2):
            found = find_boxes(noisy(depth, lumpy, seed), camera.lens, camera.camera_to_world,
                               colour).boxes  # fmt: skip
            sizes = [tuple(round(v, 3) for v in b.size) for b in found]
            assert [math.dist(b.top_middle, carton.top_middle) < 0.01 for b in found] == [True], (
                radius, seed, sizes)  # fmt: skip


def test_two_cartons_meeting_at_a_corner_are_two_boxes():
    """Two cartons of one height meet at a corner, a taller one and a lower one in the other
    two corners, 1.7 m from a D435 (15 degrees tilted) and an Azure Kinect (straight down).
    The taller one hides the line between the two cartons' middles, but beside it the lower
    one shows where a single top would be: two boxes, each its own size, not one joined
    across the corner (which these two pictures gave before)."""
    heights = ((0.25, 0.3), (0.2, 0.25))
    cartons = [box_on(P, (i - 0.5) * 0.28, (j - 0.5) * 0.25, (0.28, 0.25, heights[i][j]), 0.0,
                      TAN[(i + j) % 2]) for i in range(2) for j in range(2)]  # fmt: skip
    pair = (cartons[0], cartons[3])
    for camera, noise in ((tilted(1.7, 15.0), "d435"), (tilted(1.7, 0.0), "azure_kinect")):
        depth, colour = render(Scene(camera, P, tuple(cartons)))
        found = find_boxes(noisy(depth, noise, 2), camera.lens, camera.camera_to_world,
                           colour).boxes  # fmt: skip
        sizes = [tuple(round(v, 3) for v in b.size) for b in found]
        for box, true in match(found, pair):
            assert math.dist(box.top_middle, true.top_middle) < 0.01, (noise, sizes)
            assert box.size[:2] == pytest.approx(true.size[:2], abs=0.015), (noise, sizes)


def test_a_bin_seen_from_close_over_it_stands_on_the_floor_round_it():
    """A tote with a 4 cm floor and three cartons in it, 0.8 m straight down, through a D435's
    noise: the floor round the tote is a sixth of the picture, and no plane through three
    readings anywhere held a tenth of them, so nothing was found. The support is about level:
    the lowest height a tenth of the readings share is the floor, along the pose's up, or
    without a pose along the way most small patches face. Every carton is found, its height
    over the tote's floor."""
    parts, cartons = tote(0.04, 0.025)
    camera = tilted(0.8, 0.0)
    depth, colour = render(Scene(camera, P, (*parts, *cartons)))
    for pose in (camera.camera_to_world, None):
        found = find_boxes(noisy(depth, "d435", 0), camera.lens, pose, colour)
        assert found.support is not None
        assert found.support.distance_m == pytest.approx(0.8, abs=0.01)  # the floor's
        sizes = [tuple(round(v, 3) for v in b.size) for b in found.boxes]
        for true in cartons:
            assert any(
                b.size[:2] == pytest.approx(sorted(true.size[:2], reverse=True), abs=0.015)
                and b.size[2] == pytest.approx(true.size[2], abs=0.005)
                for b in found.boxes
            ), (pose is not None, true.size, sizes)


def test_a_carton_among_lower_ones_does_not_say_its_height_is_seen():
    """A carton with lower ones against its four sides, each of its own height: the level
    found beside it is a neighbour's, whose top does not reach under it, so its height (taken
    to that level) is not said to be seen."""
    centre = box_on(P, 0.0, 0.0, (0.25, 0.25, 0.3), 0.0, TAN[0])
    around = [box_on(P, 0.25 * dx, 0.25 * dy, (0.25, 0.25, tall), 0.0, TAN[1])
              for (dx, dy), tall in zip(((-1, 0), (1, 0), (0, -1), (0, 1)),
                                        (0.15, 0.2, 0.25, 0.22), strict=True)]  # fmt: skip
    camera = tilted(1.5, 0.0)
    depth, colour = render(Scene(camera, P, (centre, *around), seam_m=0.003))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
    ((box, _),) = match(found, (centre,))
    assert box.size[2] < 0.3 - 0.02
    assert not box.height_seen


def test_what_is_seen_round_a_top():
    """A box alone: every side and its foot seen. A carton ringed by taller ones: four sides
    hidden and its foot not seen, its height taken to its neighbours' level. A flat box two
    thirds behind a taller one: that side hidden, its width a lower bound."""
    ring = [box_on(P, (i - 1) * 0.25, (j - 1) * 0.25, (0.25, 0.25, 0.2 if i == j == 1 else 0.3),
                   0.0, TAN[(i + j) % 2]) for i in range(3) for j in range(3)]  # fmt: skip
    behind = box_on(P, 0.0, 0.145, (0.10, 0.30, 0.05), 0.0, (40, 90, 200))
    front = box_on(P, 0.0, -0.04, (0.16, 0.06, 0.25), 0.0, (190, 150, 100))
    for shapes, camera, true, hidden, seen in (
        (ring[4:5], tilted(1.5, 0.0), ring[4], 0, True),
        (ring, tilted(1.5, 0.0), ring[4], 4, False),
        ((behind, front), tilted(1.0, 30.0), behind, 1, True),
        ((behind, front), tilted(1.0, 30.0), front, 0, True),
    ):
        depth, colour = render(Scene(camera, P, tuple(shapes), seam_m=0.003))
        found = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
        ((box, _),) = match(found, (true,))
        assert (box.hidden_sides, box.height_seen) == (hidden, seen)
        assert math.dist(box.top_middle[:2], true.top_middle[:2]) < (
            max(true.size[:2]) / 2 if hidden else 0.003
        )
        assert box.size[2] == pytest.approx(true.size[2], abs=0.003)
        assert box.size[1] <= min(true.size[:2]) + 0.003


# --- the support ---------------------------------------------------------------------------------
def test_a_slanted_floor_is_the_support():
    """A floor 5 degrees off level: fitted, its tilt said, the plane through its point."""
    plane = Plane((0.0, 0.0, 0.1), (math.sin(math.radians(5)), 0.0, math.cos(math.radians(5))))
    camera = Camera.tilted(0.6, 10.0, target=(0, 0, 0.1))
    depth, _ = render(Scene(camera, plane))
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    assert support is not None and support.tilt_deg == pytest.approx(5.0, abs=0.05)
    assert support.normal[2] * 0.1 + support.offset_m == pytest.approx(0.0, abs=1e-4)
    with pytest.raises(ValueError, match="table_z_m needs the camera's pose"):
        fit_support(depth, camera.lens, None, table_z_m=0.1)
    given = fit_support(depth, camera.lens, camera.camera_to_world, table_z_m=0.1)
    assert given is not None and given.normal == pytest.approx((0.0, 0.0, 1.0), abs=1e-9)
    assert given.offset_m == pytest.approx(-0.1, abs=1e-9)


@pytest.mark.parametrize("lump_px", [0.0, 1.0, 3.0])
def test_the_support_measures_how_wide_the_noise_lumps_are(lump_px):
    """Noise smoothed over 0, 1 or 3 pixels, one sigma: the support says how wide, +-0.2 px."""
    camera = tilted(1.5, 15.0)
    depth, _ = render(Scene(camera, P))
    depth = add_noise(depth, Noise(sigma_m=0.004, correlation_px=lump_px), np.random.default_rng(1))
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    assert support is not None and support.lump_px == pytest.approx(lump_px, abs=0.2)


def test_a_quantised_depth_gives_its_step():
    """A stereo camera's depth in eighths of a disparity step: the step over z^2 is measured
    (the noise floor and the RANSAC band follow it); a renderer's smooth depth has none."""
    camera = tilted(1.0, 20.0, azimuth_deg=0.0)  # the table slopes along the rows
    depth, _ = render(Scene(camera, P))
    assert depth_quantum(depth) == 0.0
    focal_baseline = camera.lens.fx * 0.05  # px m: disparity = fb / z
    rough = add_noise(depth, Noise(sigma_m=0.003), np.random.default_rng(0))
    disparity = np.round(focal_baseline / rough * 8.0) / 8.0
    stepped = (focal_baseline / disparity).astype(np.float32)
    assert depth_quantum(stepped) == pytest.approx(0.125 / focal_baseline, rel=0.1)
    support = fit_support(stepped, camera.lens, camera.camera_to_world)
    assert support is not None and support.sigma_m >= 0.5 * 0.125 / focal_baseline


@pytest.mark.parametrize("turn", [20.0, 40.0, 65.0])
def test_a_smooth_depth_seen_at_a_slant_has_no_step_and_hides_no_small_step(turn):
    """A renderer's depth of boxes turned on a table, seen from 1.2 m at 30 degrees: their
    side faces slope along the rows, which is no step the depth comes in (the noise floor
    stays under a tenth of a millimetre). So two boxes touching along their length, one
    6 mm taller, are two tops: both found, each its own size."""
    camera = tilted(1.2, 30.0)
    lower = box_on(P, 0.0, 0.0, (0.15, 0.05, 0.161), turn, (170, 130, 80))
    x, y = turned(0.0, 0.04, turn)
    higher = box_on(P, x, y, (0.2, 0.03, 0.167), turn, (40, 60, 160))
    depth, colour = render(Scene(camera, P, (lower, higher)))
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    assert support is not None
    assert 0.5 * depth_quantum(depth) * support.distance_m**2 < 1e-4
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
    assert len(found) == 2
    for box, true in match(found, (lower, higher)):
        assert box.size == pytest.approx(true.size, abs=0.004)


# --- the pipeline's mechanisms, one by one -----------------------------------------------------
def test_a_step_a_pixel_wide_parts_two_tops_where_the_depth_is_quiet():
    """Two tops 6 mm apart in height, quiet depth, the step between them a staircase of
    pixels slanting across the rows (two along for one down): two regions. Keeping thin tops
    where the depth is quiet opens the cores with a 2 x 2 square, which must keep every pixel
    where it is (shifted a pixel, the cores cross the staircase and the tops are one)."""
    rows, cols = np.mgrid[0:60, 0:80]
    line = cols + 2 * rows - 100
    step = (line >= -2) & (line < 0)
    surface = Surface(
        height_m=np.where(line < 0, 0.167, 0.161).astype(np.float32),
        sigma_m=np.full(line.shape, 0.0002, np.float32),
        up=~step,
        step=step,
        slope=np.ones(line.shape, np.float32),
        reach_px=2,
        quiet=np.ones(line.shape, bool),
    )
    labels = standing_regions(surface, 0.01, None)
    assert len(np.unique(labels[labels > 0])) == 2


def test_a_tops_surface_faces_up_its_sides_do_not_and_its_outline_steps():
    """Every pixel's height above the support; a box's top faces up (farther from its outline
    than twice the normals' reach), its side faces do not; the depth steps all round it and
    nowhere on its top."""
    camera = tilted(0.8, 30.0)
    box = box_on(P, 0.0, 0.0, (0.16, 0.1, 0.08), 20.0)
    depth, _ = render(Scene(camera, P, (box,)))
    surface = read_surface(depth, camera.lens, fit_support(depth, camera.lens,
                                                           camera.camera_to_world))  # fmt: skip
    across, down = camera.lens.rays(640, 480)
    up, height = camera.camera_to_world[2, :3], camera.camera_to_world[2, 3]
    z = depth * (up[0] * across[None, :] + up[1] * down[:, None] + up[2]) + height
    top = (np.abs(z - 0.08) < 1e-4).astype(np.uint8)
    inner = cv2.erode(top, np.ones((4 * surface.reach_px + 3,) * 2, np.uint8)).astype(bool)
    side, table = (z > 0.005) & (z < 0.075), z < 1e-4
    assert surface.height_m[top > 0] == pytest.approx(0.08, abs=1e-4)
    assert inner.sum() > 2000 and surface.up[inner].all() and not surface.step[inner].any()
    assert side.sum() > 1000 and not surface.up[side].any()
    standing = (z > 0.005).astype(np.uint8)
    outline = cv2.dilate(standing, None) != cv2.erode(standing, None)
    assert surface.step[outline].all() and surface.step[table].mean() < 0.005


def test_a_turned_boxs_top_is_measured_as_its_rectangle():
    """Straight down from 0.8 m, a box turned 33 degrees: one top, length and width within
    2 mm, its axis within 1 degree, its height within 0.1 mm."""
    camera = Camera.looking_at((0, 0, 0.8), (0, 0, 0), 640, 480)
    depth, _ = render(Scene(camera, P, (box_on(P, 0.05, -0.03, (0.16, 0.1, 0.07), 33.0),)))
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    surface = read_surface(depth, camera.lens, support)
    tops = find_tops(depth, surface, camera.lens, support, None, 0.01)
    assert len(tops) == 1
    assert (tops.length_m[0], tops.width_m[0]) == pytest.approx((0.16, 0.1), abs=0.002)
    angle = math.degrees(math.atan2(tops.axis_ab[0, 1], tops.axis_ab[0, 0]))  # e1, e2: x, y
    assert yaw_error(angle, 33.0, square=False) <= 1.0
    assert tops.height_m[0] == pytest.approx(0.07, abs=1e-4) and tops.fill[0] > 0.95


def test_tops_a_few_pixels_wide_are_found():
    """Forty tall boxes 19-24 mm wide, 1.6-2.3 m away, 10-40 degrees from straight down: their
    tops five to seven pixels across, so that the normals' windows take in an edge almost
    everywhere on them. At least 30 are found, each within 8 mm of its width."""
    rng = np.random.default_rng(1)
    found = 0
    for _ in range(40):
        d, tilt, yaw = rng.uniform(1.6, 2.3), rng.uniform(10.0, 40.0), rng.uniform(0.0, 90.0)
        size = (rng.uniform(0.05, 0.12), rng.uniform(0.019, 0.024), rng.uniform(0.2, 0.4))
        camera = tilted(d, tilt)
        box = box_on(P, rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), size, yaw)
        depth, colour = render(Scene(camera, P, (box,)))
        boxes = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
        found += len(boxes) == 1 and abs(min(boxes[0].size[:2]) - size[1]) < 0.008
    assert found >= 30


def test_a_round_tops_rectangle_is_as_small_turned_45_degrees_a_rectangles_is_not():
    """Straight down from 0.8 m: a tin's lid fits the rectangle round its pixels turned 45
    degrees as well as its own (Tops.turned 1.02); a square box's fits two thirds of it (0.67:
    the turned square's thin tips are left out as strays), a box four times as long as wide
    less (0.39)."""
    camera = Camera.looking_at((0, 0, 0.8), (0, 0, 0), 640, 480)
    for shape, low, high in (
        (Cylinder((0.0, 0.0, 0.05), 0.05, 0.1), 0.9, 1.1),
        (box_on(P, 0.0, 0.0, (0.1, 0.1, 0.1), 20.0), 0.55, 0.7),
        (box_on(P, 0.0, 0.0, (0.2, 0.05, 0.1), 20.0), 0.25, 0.45),
    ):
        depth, _ = render(Scene(camera, P, (shape,)))
        support = fit_support(depth, camera.lens, camera.camera_to_world)
        tops = find_tops(depth, read_surface(depth, camera.lens, support), camera.lens, support,
                         None, 0.01)  # fmt: skip
        assert len(tops) == 1
        assert low <= tops.turned[0] <= high, (shape, tops.turned[0])


@pytest.mark.parametrize(("distance_m", "tilt"), [(1.2, 0.0), (1.5, 0.0), (1.5, 20.0)])
def test_a_tin_lying_down_is_no_box_through_a_stereo_cameras_noise(distance_m, tilt):
    """A tin 10 cm across lying down, 1.2-1.5 m away through a D435's noise (sigma 3.6-5.1 mm
    there), five pictures: no box. Its top (7 cm of it) sags 7-9 mm over its middle 80 %,
    clear of that window's noise, and only 3 mm over its middle half, within it. A carton of
    its size in the same place: a box in each."""
    camera = tilted(distance_m, tilt)
    tin = lying(0.0, 0.0, 0.05, 0.16, 30.0)
    carton = box_on(P, 0.0, 0.0, (0.16, 0.08, 0.1), 30.0, (170, 130, 80))
    for shape, count in ((tin, 0), (carton, 1)):
        depth, colour = render(Scene(camera, P, (shape,)))
        for seed in range(5):
            noisy = add_noise(depth, Noise.d435(), np.random.default_rng(seed))
            found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour).boxes
            assert len(found) == count


@pytest.mark.parametrize(("past_px", "reported"), [(3.0, True), (8.0, False)])
def test_a_top_the_pictures_edge_runs_along_is_cut_off(past_px, reported):
    """Straight down, a box turned 40 degrees with a corner past the picture's left edge: 3
    pixels past, the edge only grazes a corner of the top (its sides still seen), and the box
    is reported, its size within 3 mm; 8 pixels past, the edge runs along the top, cut off,
    and it is not (but is with ``keep_cut_off``, its size a lower bound)."""
    camera = Camera.looking_at((0, 0, 0.8), (0, 0, 0), 640, 480)
    lens, pose = camera.lens, camera.camera_to_world
    size, yaw = (0.16, 0.1, 0.07), 40.0
    corners = np.array([[sx * size[0] / 2, sy * size[1] / 2] for sx in (1, -1) for sy in (1, -1)])
    turn = np.radians(yaw)
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    xy = corners @ rotation.T
    top = np.c_[xy, np.full(4, size[2]), np.ones(4)] @ np.linalg.inv(pose).T
    u = lens.fx * top[:, 0] / top[:, 2] + lens.cx
    shift_px = -past_px - u.min()  # the leftmost corner at column -past_px
    x = shift_px * float(np.mean(top[:, 2])) / lens.fx * float(np.sign(pose[0, 0]))
    box = box_on(P, x, 0.0, size, yaw)
    depth, _ = render(Scene(camera, P, (box,)))
    found = find_boxes(depth, lens, pose).boxes
    assert len(found) == int(reported)
    if reported:
        assert found[0].size[:2] == pytest.approx(size[:2], abs=0.003)
    kept = find_boxes(depth, lens, pose, settings=FinderSettings(keep_cut_off=True)).boxes
    assert len(kept) == 1 and kept[0].size[0] <= size[0] + 0.003


@pytest.mark.parametrize("turn", [0.0, 35.0])
def test_two_boxes_of_one_height_and_colour_touching_are_told_by_their_outline(turn):
    """A narrow carton against the side of a wide one, one height, one brown, no seam: one
    region in depth and colour, an L whose outline turns inward where they meet. Cut there, it
    is two boxes, each its own size. A carton with a taller box in front hiding the same
    corner is one box: what its outline leaves out is nearer, not lower."""
    camera = tilted(0.9, 20.0)
    brown = (170, 130, 80)
    wide = box_on(P, 0.0, 0.0, (0.2, 0.12, 0.08), turn, brown)
    x, y = turned(0.1 + 0.04, 0.06 - 0.02, turn)
    narrow = box_on(P, x, y, (0.08, 0.04, 0.08), turn, brown)
    depth, colour = render(Scene(camera, P, (wide, narrow)))
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    surface = read_surface(depth, camera.lens, support)
    tops = find_tops(depth, surface, camera.lens, support, colour, 0.01)
    assert len(tops) == 2
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
    for box, true in match(found, (wide, narrow)):
        assert box.size == pytest.approx(true.size, abs=0.004)
    x, y = turned(0.1 - 0.02, 0.06 + 0.05, turn)
    front = box_on(P, x, y, (0.08, 0.06, 0.2), turn, (40, 90, 200))
    camera = tilted(0.9, 35.0, azimuth_deg=90.0)
    depth, colour = render(Scene(camera, P, (wide, front)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
    ((box, _),) = match(found, (wide,))
    assert len(found) == 2 and box.hidden_sides == 1
    assert box.size[:2] == pytest.approx(wide.size[:2], abs=0.004)


@pytest.mark.parametrize("distance_m", [0.8, 1.5])
def test_a_thin_dark_line_parts_two_cartons_of_one_height(distance_m):
    """Two cartons of one brown touching end to end: one top in depth; with colour, a dark line
    between them 2 x 2 mm wide parts them into two, each its own length; no line, one top."""
    cartons = end_to_end((0.2, 0.15, 0.1), 0.0)
    camera = tilted(distance_m, 10.0)
    for seam_m, count in ((0.002, 2), (0.0, 1)):
        depth, colour = render(Scene(camera, P, tuple(cartons), seam_m=seam_m))
        support = fit_support(depth, camera.lens, camera.camera_to_world)
        surface = read_surface(depth, camera.lens, support)
        assert len(find_tops(depth, surface, camera.lens, support, None, 0.01)) == 1
        tops = find_tops(depth, surface, camera.lens, support, colour, 0.01)
        assert len(tops) == count
        assert tops.length_m == pytest.approx([0.2 * (3 - count)] * count, abs=0.008)


def test_the_kernels_grow_as_scipy_dilates():
    """kernels.grow: a region grows breadth first, 8-connected, ``steps`` pixels at most, over
    open pixels whose height is within tolerance of the one it comes from (not over a step)."""
    labels = np.zeros((40, 50), np.int32)
    labels[20, 10] = 3
    seed = labels > 0
    height = np.zeros((40, 50), np.float32)
    height[:, 16:] = 0.05  # a step the region must not climb
    open_ = np.ones((40, 50), bool)
    open_[25:, :] = False
    kernels.grow(labels, height, open_, np.full((40, 50), 0.01, np.float32), 8)
    want = ndimage.binary_dilation(seed, np.ones((3, 3), bool), 8, open_ & (height == 0))
    assert np.array_equal(labels == 3, want) and set(np.unique(labels)) == {0, 3}


def test_the_kernels_measure_what_numpy_does():
    """kernels.rectangle_angles: the angle (of those tried, then the fine ones about the best)
    whose rectangle round a top's points is smallest, as NumPy finds it, and the rectangle's
    own turn."""
    rng = np.random.default_rng(0)
    kernels.warm_up()
    turns = (10.0, 37.0, 71.0)
    along, across = rng.uniform(-0.2, 0.2, (3, 300)), rng.uniform(-0.05, 0.05, (3, 300))
    t = np.radians(turns)[:, None]
    pa = along * np.cos(t) - across * np.sin(t)
    pb = along * np.sin(t) + across * np.cos(t)
    coarse, fine = np.radians(np.arange(0.0, 90.0, 5.0)), np.radians(np.arange(-4.5, 4.6, 0.5))
    found = kernels.rectangle_angles(np.arange(0, 901, 300), pa.ravel(), pb.ravel(), coarse, fine)
    for k, turn in enumerate(turns):

        def area(angle: float, k: int = k) -> float:
            p = pa[k] * np.cos(angle) + pb[k] * np.sin(angle)
            q = pb[k] * np.cos(angle) - pa[k] * np.sin(angle)
            return float(np.ptp(p) * np.ptp(q))

        tried = coarse[np.argmin([area(x) for x in coarse])] + fine
        assert found[k] == tried[np.argmin([area(x) for x in tried])]
        assert abs((np.degrees(found[k]) - turn + 45.0) % 90.0 - 45.0) < 1.5


def test_the_kernels_take_a_planes_moments_as_numpy_does():
    """kernels.plane_moments: the mean and covariance (np.cov's) of the points marked inliers,
    without gathering them."""
    rng = np.random.default_rng(4)
    points = rng.normal(size=(400, 3)) * (0.3, 0.2, 0.01) + (0.1, -0.2, 1.5)
    inliers = rng.random(400) < 0.7
    centre, moments = kernels.plane_moments(points, inliers)
    chosen = points[inliers]
    assert centre == pytest.approx(chosen.mean(axis=0), abs=1e-12)
    assert np.allclose(moments, np.cov(chosen.T), rtol=1e-10, atol=1e-14)
    assert np.array_equal(moments, moments.T)


@pytest.mark.parametrize("shape", [(2, 2), (3, 2), (2, 7), (5, 6), (31, 44)])
def test_the_kernels_read_the_colour_as_opencv_does(shape: tuple[int, int]):
    """kernels.laplacian_counts and seam_pixels: the Laplacian's absolute values at every
    second pixel, and the Sobel gradient's test, exactly as OpenCV's filters (and their
    reflected border) give them, down to a picture two pixels a side."""
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    grey = rng.integers(0, 256, shape).astype(np.uint8)
    grey[:, : shape[1] // 2] //= 8  # a strong edge as well as noise
    dark = rng.integers(0, 60, shape).astype(np.uint8)
    laplacian = np.abs(cv2.Laplacian(grey, cv2.CV_16S)[::2, ::2]).ravel()
    counts = kernels.laplacian_counts(grey)
    assert np.array_equal(counts[: laplacian.max() + 1], np.bincount(laplacian))
    assert counts[laplacian.max() + 1 :].sum() == 0
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    for dark_step, edge_step in ((25.0, 120.0), (40.0, 400.0)):
        want = (dark > dark_step) | (gx * gx + gy * gy > np.float32(edge_step * edge_step))
        found = kernels.seam_pixels(dark, grey, dark_step, edge_step)
        assert found.dtype == np.uint8 and np.array_equal(found, want.astype(np.uint8))


def test_the_kernels_find_settled_steps_as_numpy_does():
    """kernels.settled_steps: a crack a pixel wide along a row or a column (the picture
    wrapping round at its edges, as np.roll does) or a 3 x 3 spread beyond the step, as the
    NumPy it stands in for finds them, in float32."""
    rng = np.random.default_rng(3)
    height = rng.normal(0.05, 0.004, (23, 31)).astype(np.float32)
    height[5, :] -= 0.02  # a crack along a row
    height[:, 0] -= 0.02  # the first column low, but as low as the last, its neighbour
    height[:, -1] -= 0.02  # round the picture's edge: no crack either
    sigma = rng.uniform(0.0005, 0.0015, height.shape).astype(np.float32)
    high = height + rng.uniform(0.0, 0.0025, height.shape).astype(np.float32)
    low = height - rng.uniform(0.0, 0.0025, height.shape).astype(np.float32)
    limits = np.array([0.0005, 0.9, 5.0, 0.004, 0.25, 500.0], dtype=np.float32)
    threshold = np.maximum(limits[2] * sigma, limits[3])
    lower = [height < np.roll(height, shift, axis) - threshold for shift, axis in
             ((1, 1), (-1, 1), (1, 0), (-1, 0))]  # fmt: skip
    want = (lower[0] & lower[1]) | (lower[2] & lower[3]) | (high - low > threshold)
    found = kernels.settled_steps(height, sigma, high, low, limits)
    assert want[5].all() and not (high - low > threshold).all()
    assert np.array_equal(found, want.astype(np.uint8))


# --- a stream of pictures ------------------------------------------------------------------------
def test_a_stream_keeps_the_support_the_ids_and_still_boxes_still():
    """Sixteen noisy pictures of two still boxes: one plane fit, the same two ids throughout,
    and each box's top middle steadier than found picture by picture (running means)."""
    camera = tilted(0.7, 15.0)
    boxes = (box_on(P, 0.05, 0.02, (0.12, 0.08, 0.06), 25.0),
             box_on(P, -0.1, -0.05, (0.1, 0.07, 0.05), -30.0, (60, 90, 200)))  # fmt: skip
    depth, _ = render(Scene(camera, P, boxes))
    rng, finder = np.random.default_rng(5), BoxFinder()
    alone, held = [], []
    for _ in range(16):
        picture = add_noise(depth, Noise(sigma_m=0.002), rng)
        each = find_boxes(picture, camera.lens, camera.camera_to_world).boxes
        kept = finder(picture, camera.lens, camera.camera_to_world).boxes
        assert len(each) == 2 and [b.id for b, _ in match(kept, boxes)] == [0, 1]
        alone.append([b.top_middle for b, _ in match(each, boxes)])
        held.append([b.top_middle for b, _ in match(kept, boxes)])
    assert finder.refits == 1
    spread_alone = np.std(np.array(alone)[4:, :, :2], axis=0)
    spread_held = np.std(np.array(held)[4:, :, :2], axis=0)
    assert (spread_held < 0.6 * spread_alone).all(), (spread_held, spread_alone)


def test_a_stream_measures_how_far_the_colour_lies_off():
    """A tall box 2 m away, its colour 2 px up and 2 right of the depth: the stream measures the
    shift on its first picture and finds one box 30 cm long; told the pictures are in
    register, it keeps (0, 0)."""
    camera = tilted(2.0, 5.0)
    depth, colour = render(Scene(camera, P, (box_on(P, 0.5, 0.0, (0.3, 0.05, 0.3), 30.0),)))
    off = np.roll(colour, (-2, 2), axis=(0, 1))
    aligned = BoxFinder(FinderSettings(colour_shift=(0, 0)))
    aligned(depth, camera.lens, camera.camera_to_world, off)
    assert aligned.registration.shift == (0, 0)
    finder = BoxFinder()
    found = [finder(depth, camera.lens, camera.camera_to_world, off) for _ in range(2)]
    assert finder.registration.shift == (-2, 2) and finder.registration.sure
    assert [[round(b.size[0], 2) for b in f.boxes] for f in found] == [[0.3], [0.3]]


# --- colour registration -------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("noise", "shift"), [(None, (0, 0)), (None, (2, 1)), ("d435", (-2, 2)), ("d435", (1, -3))]
)
def test_how_far_the_colour_lies_off_the_depth_is_measured(noise, shift):
    """Three boxes seen at a slant, the colour moved up to 3 px: the shift is measured exactly,
    noise-free and through a D435; moved back, the colour is in register pixel for pixel."""
    camera = tilted(1.0, 20.0)
    boxes = (box_on(P, -0.15, 0.05, (0.2, 0.12, 0.15), 20.0),
             box_on(P, 0.12, -0.08, (0.25, 0.15, 0.08), -35.0, (60, 140, 200)),
             box_on(P, 0.1, 0.15, (0.1, 0.1, 0.2), 50.0, (90, 190, 80)))  # fmt: skip
    depth, colour = render(Scene(camera, P, boxes))
    depth = noisy(depth, noise, 0)
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    off = np.roll(colour, shift, axis=(0, 1))
    measured = register.colour_offset(depth, off, support.sigma_m)
    assert (measured.shift, measured.sure) == (shift, shift != (0, 0))
    back = register.in_register(off, measured.shift)
    assert np.array_equal(back[3:-3, 3:-3], colour[3:-3, 3:-3])


def test_pictures_that_show_no_jump_leave_the_colour_where_it_is():
    """An empty table, no reading at all (NaN or 0), a colour picture of another view: nothing
    to be sure of, so the colour is taken as it comes."""
    camera = tilted(1.0, 20.0, width=320, height=240)
    box = (box_on(P, 0.0, 0.0, (0.2, 0.12, 0.15), 20.0),)
    depth, colour = render(Scene(camera, P, box))
    empty_depth, empty_colour = render(Scene(camera, P))
    _, other = render(Scene(tilted(1.0, 0.0, width=320, height=240), P, box))
    for d, c in ((empty_depth, empty_colour), (np.full_like(depth, np.nan), colour),
                 (np.zeros_like(depth), colour), (depth, other)):  # fmt: skip
        measured = register.colour_offset(d, c, 0.0005)
        assert (measured.shift, measured.sure) == ((0, 0), False)
    assert register.colour_offset(np.zeros_like(depth), colour, 0.0005).jumps == 0
