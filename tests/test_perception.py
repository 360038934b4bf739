"""The box finder on ray-cast pictures whose answers are known exactly."""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import warnings

import numpy as np
import pytest
from scipy import ndimage

from onebox.geometry import Intrinsics
from onebox.perception import register, segment, tops
from onebox.perception.boxes import BoxFinder, FinderSettings, find_boxes
from onebox.perception.segment import median3
from onebox.perception.support import Support, fit_support, lump_width, noise_against
from onebox.perception.tops import _bands, _extents, noise_tilt_deg
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
from onebox.world.noise import PRESETS, DepthNoise, NoiseSpec


def random_boxes(rng: np.random.Generator, count: int, spread_m: float) -> tuple[Box, ...]:
    """Up to ``count`` boxes scattered without overlap inside +-spread_m of the origin."""
    boxes: list[Box] = []
    for _ in range(count * 20):
        if len(boxes) == count:
            break
        size = (
            float(rng.uniform(0.05, 0.14)),
            float(rng.uniform(0.04, 0.1)),
            float(rng.uniform(0.02, 0.1)),
        )
        x, y = rng.uniform(-spread_m, spread_m, 2)
        radius = math.hypot(size[0], size[1]) / 2
        if any(
            math.hypot(x - b.centre[0], y - b.centre[1])
            < radius + math.hypot(b.size[0], b.size[1]) / 2 + 0.01
            for b in boxes
        ):
            continue
        colour = tuple(int(v) for v in rng.integers(60, 230, 3))
        boxes.append(
            box_on(Plane(), float(x), float(y), size, float(rng.uniform(-90, 90)), colour)  # type: ignore[arg-type]
        )
    return tuple(boxes)


def match(found, truth: tuple[Box, ...]):
    """Pairs of (found box, true box) by nearest top middle."""
    pairs = []
    for box in truth:
        best = min(found, key=lambda f: math.dist(f.top_middle, box.top_middle))
        pairs.append((best, box))
    return pairs


def test_seed_world_cube_middle_and_height():
    """The seed's 6 cm cube at (0.065, 0.040): middle within 1 mm, height 0.060 m."""
    camera = Camera.looking_at((0, 0, 0.4), (0, 0, 0), 320, 240, 60)
    scene = Scene(camera, Plane(), (box_on(Plane(), 0.065, 0.040, (0.06, 0.06, 0.06)),))
    depth, _ = render(scene)
    found = find_boxes(depth, camera.lens, camera.camera_to_world)
    assert len(found.boxes) == 1
    box = found.boxes[0]
    assert abs(box.top_middle[0] - 0.065) <= 0.001
    assert abs(box.top_middle[1] - 0.040) <= 0.001
    assert box.size[2] == pytest.approx(0.060, abs=0.0005)
    assert box.size[0] == pytest.approx(0.060, abs=0.002)
    assert box.centre[2] == pytest.approx(0.030, abs=0.0005)


@pytest.mark.parametrize(
    ("seed", "count", "distance_m", "tilt_deg"),
    [(1, 1, 0.4, 0.0), (2, 3, 0.5, 15.0), (3, 5, 0.8, 30.0), (4, 8, 1.2, 20.0), (5, 4, 2.0, 10.0)],
)
def test_noise_free_boxes_found_exactly(seed, count, distance_m, tilt_deg):
    """Noise-free: every box found, none extra, centre/yaw/size/height within the targets."""
    rng = np.random.default_rng(seed)
    spread = 0.12 * distance_m / 0.4 * 0.6
    truth = random_boxes(rng, count, spread)
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480, hfov_deg=60)
    depth, colour = render(Scene(camera, Plane(), truth))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(truth)
    scale = distance_m / 0.4
    for box, true in match(found.boxes, truth):
        assert math.dist(box.centre, true.centre) <= 0.0025 * distance_m * 1.5
        square = abs(true.size[0] - true.size[1]) < 0.01
        assert yaw_error(box.yaw_deg, true.yaw_deg(), square) <= 1.0
        assert abs(box.size[0] - max(true.size[:2])) <= 0.002 * scale
        assert abs(box.size[1] - min(true.size[:2])) <= 0.002 * scale
        assert abs(box.size[2] - true.size[2]) <= 0.001


def test_sigma_1mm_accuracy():
    """Gaussian 1 mm noise at 0.5 m: centres within 3 mm, sizes within 4 mm, yaw within 2 deg."""
    rng = np.random.default_rng(7)
    truth = random_boxes(rng, 5, 0.12)
    camera = Camera.tilted(0.5, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), truth))
    noisy = add_noise(depth, Noise(sigma_m=0.001), rng)
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(truth)
    centre_errors = []
    for box, true in match(found.boxes, truth):
        centre_errors.append(math.dist(box.centre, true.centre))
        square = abs(true.size[0] - true.size[1]) < 0.01
        assert yaw_error(box.yaw_deg, true.yaw_deg(), square) <= 2.0
        assert abs(box.size[0] - max(true.size[:2])) <= 0.004
        assert abs(box.size[1] - min(true.size[:2])) <= 0.004
        assert abs(box.size[2] - true.size[2]) <= 0.002
    assert max(centre_errors) <= 0.003
    assert float(np.median(centre_errors)) <= 0.0015


@pytest.mark.parametrize(
    "thing",
    [
        Cylinder((0.0, 0.0, 0.06), 0.04, 0.12),
        Sphere((0.0, 0.0, 0.05), 0.05),
        Cylinder((0.0, 0.0, 0.035), 0.035, 0.2, ((1, 0, 0), (0, 0, -1), (0, 1, 0))),
    ],
    ids=["upright cylinder", "sphere", "lying cylinder"],
)
def test_round_things_are_not_boxes(thing):
    """A cylinder (upright or lying) or a ball next to a box: only the box is reported."""
    box = box_on(Plane(), 0.12, 0.05, (0.08, 0.06, 0.05), 30.0)
    camera = Camera.tilted(0.5, 15.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (box, thing)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 1
    assert math.dist(found.boxes[0].centre, box.centre) < 0.002


def only_cartons(cartons, camera, pictures, noise: Noise, seeds: int) -> None:
    """Through ``noise`` drawn from each of ``seeds`` seeds, the rendered ``pictures`` (depth,
    colour) give the cartons and nothing else (the round things beside them are no boxes),
    each carton's centre within 1 cm."""
    depth, colour = pictures
    for seed in range(seeds):
        noisy = add_noise(depth, noise, np.random.default_rng(seed))
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        assert len(found.boxes) == len(cartons), (seed, [b.size for b in found.boxes])
        for box, true in match(found.boxes, cartons):
            assert math.dist(box.centre, true.centre) < 0.01


@pytest.mark.parametrize("noise", ["sigma 1 mm", "sigma 3 mm", "d435", "azure_kinect"])
def test_cans_and_rolls_lying_down_are_not_boxes_through_noise(noise):
    """A can, a bottle and a roll lying on a table beside two cartons, seen from 0.6 m through
    noisy depth. Each one's top within the tolerance is a long flat-enough strip that fills
    its rectangle, so the finder before reported a box 3.5-5 cm wide on every one under any
    noise; across the strip the readings curve down by more than the tolerance, and along it
    they do not (a carton's bulging lid curves both ways). Only the cartons are boxes."""
    cartons = (
        box_on(Plane(), -0.15, -0.12, (0.16, 0.1, 0.08), 25.0, (170, 130, 90)),
        box_on(Plane(), 0.17, 0.12, (0.12, 0.09, 0.06), -40.0, (160, 125, 85)),
    )
    things = (
        lying(0.12, -0.1, 0.033, 0.12, 20.0),
        lying(-0.15, 0.13, 0.035, 0.22, -30.0),
        lying(0.02, 0.02, 0.05, 0.2, 80.0),
    )
    camera = Camera.tilted(0.6, 17.0, width=640, height=480, hfov_deg=70)
    depth, colour = render(Scene(camera, Plane(), (*cartons, *things)))
    model = (
        Noise.d435()
        if noise == "d435"
        else Noise.kinect()
        if noise == "azure_kinect"
        else Noise(sigma_m=0.001 if noise == "sigma 1 mm" else 0.003)
    )
    only_cartons(cartons, camera, (depth, colour), model, seeds=2)


@pytest.mark.parametrize("sigma_m", [0.001, 0.003])
def test_cans_lying_down_through_lumpy_noise_are_not_boxes(sigma_m):
    """Cans and a roll lying down, 4-8 cm across, beside two cartons, seen from 1.4 m through
    noise correlated over 5 pixels (a stereo camera's matching window, a depth filter): the
    lumps bow a can's top along its length by most of the tolerance while it falls two across,
    and the finder before took 2 of 6 pictures' cans for boxes at sigma 1 mm and 3 mm alike.
    A can falls across by far more than along; a carton's bulging lid falls both ways alike."""
    cartons = (
        box_on(Plane(), -0.15, -0.12, (0.16, 0.1, 0.08), 25.0, (170, 130, 90)),
        box_on(Plane(), 0.17, 0.14, (0.12, 0.09, 0.06), -40.0, (160, 125, 85)),
    )
    things = (
        lying(0.15, -0.1, 0.021, 0.13, 20.0),
        lying(-0.18, 0.12, 0.025, 0.1, -30.0),
        lying(0.0, 0.02, 0.03, 0.16, 80.0),
        lying(-0.02, -0.2, 0.042, 0.09, 10.0),
    )
    camera = Camera.tilted(1.4, 5.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (*cartons, *things)))
    only_cartons(cartons, camera, (depth, colour), Noise(sigma_m=sigma_m, correlation_px=5.0), 6)


@pytest.mark.parametrize("noise", ["d435", "azure_kinect"])
def test_a_box_between_cans_lying_down_does_not_stand_on_them(noise):
    """Three boxes in a row with a can lying down between each two, touching them, seen from
    1.15 m at 25 degrees through a real camera's noise. A can's top within the tolerance is a
    level beside the box, and the middle box, 85 mm tall, once stood on one (35 mm tall, in
    7 of these 12 pictures). A rounded top is no level anything stands on."""
    boxes = (
        box_on(Plane(), -0.18, -0.052, (0.141, 0.135, 0.061), 0.0, (170, 120, 80)),
        box_on(Plane(), 0.012, -0.065, (0.133, 0.129, 0.085), 0.0, (90, 150, 200)),
        box_on(Plane(), 0.215, -0.097, (0.141, 0.064, 0.087), 0.0, (200, 200, 90)),
    )
    cans = (lying(-0.083, -0.052, 0.026, 0.1, 90.0), lying(0.111, -0.065, 0.032, 0.1, 90.0))
    camera = Camera.tilted(1.042, 24.55, target=(0.048, 0.0, 0.0), width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (*cans, *boxes)))
    model = Noise.d435() if noise == "d435" else Noise.kinect()
    for seed in range(6):
        noisy = add_noise(depth, model, np.random.default_rng(seed))
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        assert len(found.boxes) == len(boxes)
        for box, true in match(found.boxes, boxes):
            assert box.size[2] == pytest.approx(true.size[2], abs=0.01)


@pytest.mark.parametrize("sigma_m", [0.003, 0.004])
def test_tins_and_balls_seen_close_through_noise_are_not_boxes(sigma_m):
    """Upright tins 8.6-13 cm across and a ball, 0.55-0.65 m under the camera, through
    sigma 3-4 mm. Noise leaves holes in a lid, and the outline points round them once made
    the one-in-a-hundred trimmed off each end of the extent cut into the few points at a
    disc's extremes: a tin's lid filled 0.86 of its square and was a box (in 5 of these 8
    pictures); at most two points are trimmed now."""
    rng = np.random.default_rng(7)
    for radius, height, camera_m, tilt in (
        (0.062, 0.09, 0.54, 0.5),
        (0.056, 0.193, 0.64, 28.5),
        (0.043, 0.192, 0.69, 5.4),
        (0.065, 0.146, 0.63, 3.4),
    ):
        things = (
            Cylinder((0.0, 0.0, height / 2), radius, height),
            Sphere((0.14, -0.1, 0.045), 0.045),
        )
        box = box_on(Plane(), -0.15, 0.1, (0.1, 0.08, 0.06), 30.0, (170, 130, 90))
        camera = Camera.tilted(camera_m, tilt, width=640, height=480)
        depth, colour = render(Scene(camera, Plane(), (*things, box)))
        noisy = add_noise(depth, Noise(sigma_m=sigma_m), rng)
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        assert [b for b in found.boxes if math.dist(b.centre, box.centre) > 0.01] == []


def test_bottles_round_tops_are_not_boxes():
    """Three bottles 30 cm tall with rounded tops (a cylinder under a half ball, 2 cm across
    them), 0.8 m from a camera tilted 20 degrees, sigma 1 mm: the top within the tolerance is
    a small flat-enough disc that filled its square, and was a box 29 cm tall. Its readings
    fall a whole tolerance both ways, steeply: no box."""
    things: list[Cylinder | Sphere] = []
    for x in (-0.2, 0.0, 0.2):
        things += [Cylinder((x, 0.1, 0.15), 0.02, 0.3), Sphere((x, 0.1, 0.3), 0.02)]
    camera = Camera.tilted(0.8, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), tuple(things)))
    noisy = add_noise(depth, Noise(sigma_m=0.001), np.random.default_rng(1))
    assert find_boxes(noisy, camera.lens, camera.camera_to_world, colour).boxes == []


@pytest.mark.parametrize("noise", ["noise-free", "d435"])
@pytest.mark.parametrize(
    "view",
    [(1.2, 25.0), (1.5, 35.0), (1.0, 20.0), (1.0, 0.0)],
    ids=["1.2 m, 25 deg", "1.5 m, 35 deg", "1.0 m, 20 deg", "1.0 m, straight down"],
)
def test_boxes_on_a_table_with_the_floor_round_it(view, noise):
    """A table 0.6 m high on legs, the floor round it, a camera 1.0-1.5 m over it tilted
    0-35 degrees: the floor is the support, and three boxes stand on the table's top. The
    camera sees the floor under the table past its near edge; the finder before took that for
    seeing through the boxes at the table's side (they floated: 1 of 3 found at 35 degrees)
    and reported the table as a box 0.8 x 0.6 x 0.6 m. The boxes are found, measured from the
    table's top, and the table is no box: seen under past its sides (at 20 degrees only a strip
    a few centimetres deep under its near edge shows, and it was reported), or seen from over
    its top, where no ray passes its sides and a top so high carrying boxes is a table's."""
    height_m, tilt = view
    table = table_on_legs((0.8, 0.6), 0.6, 10.0)
    top = Plane((0.0, 0.0, 0.6))
    boxes = (
        box_on(top, -0.2, -0.1, (0.17, 0.13, 0.04), 30.0, (200, 80, 60)),
        box_on(top, 0.15, 0.1, (0.19, 0.1, 0.056), -20.0, (60, 90, 200)),
        box_on(top, 0.15, -0.15, (0.11, 0.09, 0.034), 70.0, (220, 200, 80)),
    )
    camera = Camera.tilted(height_m, tilt, target=(0.0, 0.0, 0.6), width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (*table, *boxes)))
    model = Noise.d435() if noise == "d435" else Noise()
    noisy = add_noise(depth, model, np.random.default_rng(0))
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert found.support is not None and abs(found.support.offset_m) < 0.01
    assert len(found.boxes) == len(boxes), [b.size for b in found.boxes]
    for box, true in match(found.boxes, boxes):
        assert math.dist(box.centre, true.centre) < 0.01
        assert box.size[2] == pytest.approx(true.size[2], abs=0.005)


@pytest.mark.parametrize("noise", ["noise-free", "d435"])
@pytest.mark.parametrize("tilt_deg", [25.0, 0.0], ids=["from the side", "straight down"])
def test_an_empty_table_with_the_floor_round_it_is_no_box(tilt_deg, noise):
    """The table of :func:`test_boxes_on_a_table_with_the_floor_round_it` with nothing on it:
    its top, 0.8 x 0.6 m and 0.6 m over the floor, was a box that high. Seen from the side the
    camera sees the floor under it; seen from over it, a top so wide and high is a table's."""
    camera = Camera.tilted(1.0, tilt_deg, target=(0.0, 0.0, 0.6), width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), table_on_legs((0.8, 0.6), 0.6, 10.0)))
    model = Noise.d435() if noise == "d435" else Noise()
    noisy = add_noise(depth, model, np.random.default_rng(0))
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert found.support is not None and abs(found.support.offset_m) < 0.01
    assert found.boxes == []


@pytest.mark.parametrize(
    ("crate", "tilt_deg"),
    [((0.5, 0.4, 0.6), 30.0), ((0.5, 0.4, 0.3), 30.0), ((0.5, 0.4, 0.3), 0.0)],
    ids=["tall, from the side", "low, from the side", "low, straight down"],
)
def test_a_crate_carrying_a_box_is_a_box(crate, tilt_deg):
    """A solid crate as wide as a small table, carrying a box: from the side its face stops
    the rays that pass down past its top, and it is a box; straight down, lower than a table,
    it is a box too. Both are found, the box measured from the crate's top."""
    camera = Camera.tilted(1.0, tilt_deg, target=(0.0, 0.0, crate[2]), width=640, height=480)
    under = box_on(Plane(), 0.0, 0.0, crate, 15.0, (170, 130, 90))
    on_it = box_on(under, 0.05, 0.03, (0.16, 0.1, 0.08), 40.0, (60, 90, 200))
    depth, colour = render(Scene(camera, Plane(), (under, on_it)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2, [b.size for b in found.boxes]
    for box, true in match(found.boxes, (under, on_it)):
        assert math.dist(box.centre, true.centre) < 0.01
        assert box.size[2] == pytest.approx(true.size[2], abs=0.005)


@pytest.mark.parametrize("seed", range(6))
def test_no_box_on_an_empty_noisy_table(seed):
    """Empty table, sigma 3 mm plus Kinect-like speckles, holes and mm steps: no box at all."""
    rng = np.random.default_rng(100 + seed)
    camera = Camera.tilted(float(rng.uniform(0.5, 1.5)), float(rng.uniform(0, 30)), width=320)
    depth, _ = render(Scene(camera, Plane()))
    noise = Noise(sigma_m=0.003, quantum_m=0.001, speckle_share=0.003, speckle_clump_px=3)
    found = find_boxes(add_noise(depth, noise, rng), camera.lens, camera.camera_to_world)
    assert found.support is not None
    assert found.boxes == []


@pytest.mark.parametrize(("x_m", "tilt_deg"), [(-0.25, 20.0), (0.25, 20.0), (0.3, 0.0)])
def test_a_top_afloat_over_the_table_is_no_box(x_m, tilt_deg):
    """A stereo camera's mismatch floats a patch of readings above the table. The camera sees
    the table under it, which no box standing there would let it: no box. The same top on a
    box of its own footprint is one."""
    camera = Camera.tilted(1.0, tilt_deg)
    afloat = Box(centre=(x_m, 0.0, 0.25), size=(0.06, 0.05, 0.004))
    standing = box_on(Plane(), x_m, 0.0, (0.06, 0.05, 0.252))
    for shape, count in ((afloat, 0), (standing, 1)):
        depth, _ = render(Scene(camera, Plane(), (shape,)))
        found = find_boxes(depth, camera.lens, camera.camera_to_world)
        assert len(found.boxes) == count, shape


@pytest.mark.parametrize("seed", range(4))
def test_no_box_in_far_d435_speckle_clumps(seed):
    """Empty tables 1.5-2 m under a D435's noise: its speckles are clumps of up to 4 x 4
    pixels 10-70 % nearer than the table, flat, the size of a small box's top there."""
    rng = np.random.default_rng(seed)
    found = []
    for _ in range(12):
        camera = Camera.tilted(float(rng.uniform(1.5, 2.0)), float(rng.uniform(0, 30)))
        depth, _ = render(Scene(camera, Plane()))
        noisy = add_noise(depth, Noise.d435(), rng)
        found += find_boxes(noisy, camera.lens, camera.camera_to_world).boxes
    assert found == []


def test_stacked_box_reports_what_it_stands_on():
    """A box on a box: two boxes, the upper one `on` the lower, its own height."""
    lower = box_on(Plane(), 0.0, 0.0, (0.2, 0.15, 0.08), 10.0)
    upper = box_on(lower, 0.02, -0.01, (0.1, 0.07, 0.05), 25.0, colour=(40, 90, 200))
    camera = Camera.tilted(0.7, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (lower, upper)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    top, bottom = found.boxes
    assert top.on == 1 and bottom.on is None
    assert top.size[2] == pytest.approx(0.05, abs=0.001)
    assert bottom.size[2] == pytest.approx(0.08, abs=0.001)
    assert math.dist(top.centre, upper.centre) < 0.002


def touching_cartons():
    """Two touching cartons of one height and two browns, seen from 0.6 m: the cartons, the
    camera and its depth and colour pictures."""
    plane = Plane()
    a = box_on(plane, -0.05, 0.0, (0.1, 0.08, 0.06), 0.0, colour=(180, 140, 90))
    b = box_on(plane, 0.05, 0.0, (0.1, 0.08, 0.06), 0.0, colour=(150, 115, 70))
    camera = Camera.tilted(0.6, 10.0, width=640, height=480)
    depth, colour = render(Scene(camera, plane, (a, b)))
    return (a, b), camera, depth, colour


def test_touching_cartons_split_by_colour():
    """Two touching cartons of one height: one merged box from depth alone, two with colour."""
    (a, b), camera, depth, colour = touching_cartons()
    assert len(find_boxes(depth, camera.lens, camera.camera_to_world).boxes) == 1
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    for box, true in match(found.boxes, (a, b)):
        assert math.dist(box.centre, true.centre) < 0.003
        assert box.size[0] == pytest.approx(0.1, abs=0.004)


@pytest.mark.parametrize("colour_sigma", [4.0, 8.0, 12.0])
def test_touching_cartons_split_by_colour_through_the_colours_noise(colour_sigma):
    """The same two cartons through a colour camera's sensor noise of a few to twelve levels
    a channel: the noise's own steps between neighbours are no edges, so the tops do not
    crumble into specks, and the cartons' edge still splits them."""
    (a, b), camera, depth, colour = touching_cartons()
    noise = DepthNoise(NoiseSpec(colour_sigma=colour_sigma), depth.shape)
    found = find_boxes(depth, camera.lens, camera.camera_to_world, noise.colour(colour))
    assert len(found.boxes) == 2, [box.size for box in found.boxes]
    for box, true in match(found.boxes, (a, b)):
        assert math.dist(box.centre, true.centre) < 0.003
        assert box.size[0] == pytest.approx(0.1, abs=0.004)


def test_the_edge_step_follows_the_colours_noise():
    """Clean shades keep the colour step; noise raises it to 2.5 spreads of the neighbours'
    differences (sqrt 2 times the grey's sigma), wherever edges are a small share."""
    shades = np.zeros((240, 320), np.int16)
    shades[:, 160:] = 100
    shades[120:] += 40
    assert segment.edge_step(shades, 12.0) == 12.0
    rng = np.random.default_rng(5)
    for sigma in (2.0, 6.0, 10.0):
        noisy = shades + np.rint(rng.normal(0.0, sigma, shades.shape)).astype(np.int16)
        want = max(12.0, segment.EDGE_NOISE_SPREADS * math.sqrt(2.0) * sigma)
        assert segment.edge_step(noisy, 12.0) == pytest.approx(want, rel=0.08)


@pytest.mark.parametrize(
    ("gap_m", "turn_deg", "distance_m", "sigma_m"),
    [
        (0.002, 10.0, 1.2, 0.0),
        (0.002, 35.0, 2.0, 0.0),
        (0.0015, 60.0, 1.2, 0.0),
        (0.002, 35.0, 1.2, 0.001),
    ],
)
def test_cartons_a_gap_apart_split_from_depth_alone(gap_m, turn_deg, distance_m, sigma_m):
    """Two cartons of one height 1.5-2 mm apart, turned on the pixel grid, no colour: pixels
    see down the gap at every few along it only, so the tops join round the dots; the dotted
    line of pixels far under the tops crossing them from side to side splits them."""
    plane = Plane()
    size = (0.25, 0.2, 0.15)
    along = np.array([math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))])
    pair = tuple(
        box_on(plane, *(s * (size[0] + gap_m) / 2 * along), size, turn_deg, colour=(170, 130, 80))
        for s in (-1.0, 1.0)
    )
    camera = Camera.tilted(distance_m, 15.0, width=640, height=480)
    depth, _ = render(Scene(camera, plane, pair))
    if sigma_m:
        depth = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(1))
    found = find_boxes(depth, camera.lens, camera.camera_to_world)
    assert len(found.boxes) == 2, [box.size for box in found.boxes]
    for box, true in match(found.boxes, pair):
        assert math.dist(box.centre, true.centre) < 0.004
        assert box.size[0] == pytest.approx(size[0], abs=0.005)
        assert box.size[1] == pytest.approx(size[1], abs=0.005)


@pytest.mark.parametrize("turn_deg", [0.0, 25.0, 60.0])
def test_tops_joined_by_side_faces_through_noise_are_each_a_box_from_depth_alone(turn_deg):
    """A tall box and a middling one touching a low wide one, seen at 30 degrees through a
    D435's noise with no colour: the break between neighbours is 4 sigma, more than a side
    face falls from pixel to pixel, so the faces join the three tops into one piece whose one
    level was the largest top's. What is left of the piece off that level gets levels of its
    own."""
    plane = Plane()
    c, s = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))
    low = box_on(plane, -0.1, 0.0, (0.2, 0.2, 0.08), turn_deg, colour=(170, 130, 80))
    tall = box_on(plane, -0.1 + 0.16 * c, 0.16 * s, (0.12, 0.12, 0.22), turn_deg)
    middling = box_on(plane, -0.1 - 0.16 * s, 0.16 * c, (0.1, 0.12, 0.15), turn_deg)
    camera = Camera.tilted(1.0, 30.0, width=640, height=480)
    clean, _ = render(Scene(camera, plane, (low, tall, middling)))
    depth = add_noise(clean, Noise.d435(), np.random.default_rng(2))
    found = find_boxes(depth, camera.lens, camera.camera_to_world).boxes
    assert len(found) == 2, [box.size for box in found]
    for box, true in match(found, (tall, middling)):
        assert math.dist(box.centre, true.centre) < 0.006
        assert box.size[2] == pytest.approx(true.size[2], abs=0.004)


@pytest.mark.parametrize("distance_m", [0.6, 1.2])
def test_wide_seam_band_split_down_its_middle(distance_m):
    """Cartons of one height with 5 mm dark lines round their tops (a 10 mm band between two):
    the band is shared between the tops beside it, so each keeps its full size."""
    plane = Plane()
    a = box_on(plane, -0.05, 0.0, (0.1, 0.08, 0.06), 0.0, colour=(180, 140, 90))
    b = box_on(plane, 0.05, 0.0, (0.1, 0.08, 0.06), 0.0, colour=(150, 115, 70))
    c = box_on(plane, 0.0, 0.08, (0.2, 0.08, 0.06), 0.0, colour=(170, 130, 80))
    camera = Camera.tilted(distance_m, 10.0, width=640, height=480)
    depth, colour = render(Scene(camera, plane, (a, b, c), seam_m=0.005))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 3
    for box, true in match(found.boxes, (a, b, c)):
        assert box.size[0] == pytest.approx(true.size[0], abs=0.0025 * distance_m / 0.4)
        assert box.size[1] == pytest.approx(true.size[1], abs=0.0025 * distance_m / 0.4)
        assert math.dist(box.centre, true.centre) < 0.002 * distance_m / 0.4


def shadowed_seam_pair(size, distance_m, tilt_deg, turn_deg, seam_m, noisy):
    """Two cartons of one colour end to end, turned ``turn_deg``, the seam between them a
    shadow that fades in over a few pixels; the cartons and what the finder finds."""
    plane = Plane()
    along = np.array([math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))])
    a, b = (
        box_on(plane, *(s * size[0] / 2 * along), size, turn_deg, colour=(170, 130, 80))
        for s in (-1.0, 1.0)
    )
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480)
    scene = Scene(camera, plane, (a, b), seam_m=seam_m, seam_shade=0.7, seam_fades=True)
    depth, colour = render(scene)
    if noisy:
        depth = add_noise(depth, Noise.d435(), np.random.default_rng(3))
    return (a, b), find_boxes(depth, camera.lens, camera.camera_to_world, colour)


@pytest.mark.parametrize(
    ("distance_m", "tilt_deg", "turn_deg", "seam_m", "noisy"),
    [
        (0.6, 10.0, 0.0, 0.005, False),
        (0.8, 20.0, 60.0, 0.005, False),
        (1.5, 20.0, 10.0, 0.012, True),
    ],
)
def test_cartons_of_one_shade_split_at_the_seams_shadow(
    distance_m, tilt_deg, turn_deg, seam_m, noisy
):
    """Two cartons of one colour end to end, the seam between them a shadow that fades in
    over a few pixels (no step between neighbours is a colour edge): one top until the seam's
    line is seen crossing it, then two cartons of their own size."""
    size = (0.3, 0.2, 0.2) if noisy else (0.12, 0.08, 0.06)
    (a, b), found = shadowed_seam_pair(size, distance_m, tilt_deg, turn_deg, seam_m, noisy)
    assert len(found.boxes) == 2, [box.size for box in found.boxes]
    bound = 0.003 if not noisy else 0.012
    for box, true in match(found.boxes, (a, b)):
        assert math.dist(box.centre[:2], true.centre[:2]) < bound
        assert box.size[0] == pytest.approx(size[0], abs=bound)
        assert box.size[2] == pytest.approx(size[2], abs=0.005)


@pytest.mark.parametrize("x_m, tilt_deg", [(0.9, 15.0), (-0.9, 25.0), (0.6, 30.0)])
def test_tall_box_at_the_view_side_through_far_d435_noise_is_found(x_m, tilt_deg):
    """2.5 m away, a D435's noise (sigma about 2 cm) moves each reading 1 cm or more across the
    top as well, as the rays there are slanted: the outline's extreme readings stand past the
    top and it seemed to fill too little of its rectangle to be a box. Its fill is taken
    placing each outline pixel on the top's level, or at its reading where that is nearer."""
    plane = Plane()
    true = box_on(plane, x_m, 0.3, (0.27, 0.13, 0.32), 25.0, colour=(170, 130, 80))
    camera = Camera.tilted(2.5, tilt_deg, width=640, height=480)
    clean, colour = render(Scene(camera, plane, (true,)))
    for seed in (0, 1):
        depth = add_noise(clean, Noise.d435(), np.random.default_rng(seed))
        (box,) = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes
        assert math.dist(box.centre[:2], true.centre[:2]) < 0.015
        assert box.size[0] == pytest.approx(0.27, abs=0.02)
        assert box.size[2] == pytest.approx(0.32, abs=0.005)


@pytest.mark.parametrize("tilt_deg", [0.0, 25.0])
def test_without_pose_sizes_match(tilt_deg):
    """No pose: the camera-frame answer has the same sizes, and the support faces the camera."""
    box = box_on(Plane(), 0.03, 0.02, (0.1, 0.06, 0.04), 40.0)
    camera = Camera.tilted(0.5, tilt_deg, width=640, height=480)
    depth, _ = render(Scene(camera, Plane(), (box,)))
    found = find_boxes(depth, camera.lens, None)
    assert found.frame == "camera" and found.support is not None
    assert found.support.offset_m == pytest.approx(0.5, abs=0.001)
    (only,) = found.boxes
    assert only.size == pytest.approx((0.1, 0.06, 0.04), abs=0.0015)
    centre_world = camera.camera_to_world[:3, :3] @ only.centre + camera.camera_to_world[:3, 3]
    assert math.dist(centre_world, box.centre) < 0.0015


def test_support_is_the_floor_under_a_raised_table_slant():
    """A slanted floor 5 degrees off: the fit finds it and reports the tilt."""
    plane = Plane((0.0, 0.0, 0.1), (math.sin(math.radians(5)), 0.0, math.cos(math.radians(5))))
    camera = Camera.tilted(0.6, 10.0, target=(0, 0, 0.1), width=320)
    depth, _ = render(Scene(camera, plane))
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    assert support is not None and support.tilt_deg == pytest.approx(5.0, abs=0.05)
    assert support.normal[0] * 0.0 + support.normal[2] * 0.1 + support.offset_m == pytest.approx(
        0.0, abs=1e-4
    )


def test_box_finder_keeps_support_and_ids():
    """A still camera: one plane fit for the stream, the same ids while the boxes stay."""
    rng = np.random.default_rng(11)
    truth = random_boxes(rng, 3, 0.1)
    camera = Camera.tilted(0.5, 15.0, width=320)
    depth, _ = render(Scene(camera, Plane(), truth))
    finder = BoxFinder(FinderSettings())
    first = finder(
        add_noise(depth, Noise(sigma_m=0.0005), rng), camera.lens, camera.camera_to_world
    )
    second = finder(
        add_noise(depth, Noise(sigma_m=0.0005), rng), camera.lens, camera.camera_to_world
    )
    assert finder.refits == 1
    assert len(first.boxes) == 3
    ids = {b.id: b.centre for b in first.boxes}
    assert sorted(ids) == [0, 1, 2]
    for box in second.boxes:
        assert math.dist(ids[box.id], box.centre) < 0.003


def test_pallet_cartons_measured_from_the_pallet():
    """Cartons of three heights on a pallet, D435 noise: each carton's own height and centre,
    the pallet's visible strip never a box."""
    rng = np.random.default_rng(1)
    pallet, cartons, camera = loaded_pallet(rng)
    depth, colour = render(Scene(camera, Plane(), (pallet, *cartons)))
    noisy = add_noise(depth, Noise.d435(), rng)
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(cartons)
    for box, true in match(found.boxes, tuple(cartons)):
        assert math.dist(box.centre, true.centre) <= 0.010
        assert box.size[2] == pytest.approx(true.size[2], abs=0.005)
        assert box.size[0] == pytest.approx(max(true.size[:2]), abs=0.015)
        assert box.size[1] == pytest.approx(min(true.size[:2]), abs=0.015)


@pytest.mark.parametrize("seed", [2, 9])
def test_pallet_carton_not_measured_from_its_own_side_face(seed):
    """The same pallet, Azure Kinect noise: the strip of a tall carton's side face seen at a
    slant in the gap before it (between the lower carton's top and its own) is no level it
    stands on; every carton's height is its own."""
    rng = np.random.default_rng(1)
    pallet, cartons, camera = loaded_pallet(rng)
    depth, colour = render(Scene(camera, Plane(), (pallet, *cartons)))
    noisy = add_noise(depth, Noise.kinect(), np.random.default_rng(seed))
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(cartons)
    for box, true in match(found.boxes, tuple(cartons)):
        assert box.size[2] == pytest.approx(true.size[2], abs=0.01)


def test_large_picture_read_at_every_second_pixel():
    """1280 x 720 is read as 640 x 360 (the lens scaled exactly): noise-free answers hold."""
    rng = np.random.default_rng(3)
    truth = random_boxes(rng, 4, 0.15)
    camera = Camera.tilted(0.8, 20.0, width=1280, height=720)
    depth, colour = render(Scene(camera, Plane(), truth))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(truth)
    for box, true in match(found.boxes, truth):
        assert math.dist(box.centre, true.centre) <= 0.0025 * 0.8
        assert abs(box.size[0] - max(true.size[:2])) <= 0.004
        assert abs(box.size[2] - true.size[2]) <= 0.001


@pytest.mark.parametrize(("distance_m", "tilt_deg"), [(1.0, 20.0), (0.8, 0.0)])
def test_box_nearly_covering_the_box_under_it(distance_m, tilt_deg):
    """A box on a box it nearly covers (a rim of 4-5 mm of the lower top shows): measured from
    that rim, not from the table."""
    lower = box_on(Plane(), 0.02, 0.01, (0.168, 0.069, 0.095), 15.0, colour=(40, 90, 200))
    upper = box_on(lower, 0.001, -0.0005, (0.158, 0.060, 0.125), 0.0, colour=(190, 150, 100))
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480, hfov_deg=60)
    depth, colour = render(Scene(camera, Plane(), (lower, upper)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    top = found.boxes[0]
    assert top.size[2] == pytest.approx(0.125, abs=0.001)
    assert math.dist(top.centre, upper.centre) <= 0.0025 * distance_m


@pytest.mark.parametrize(("distance_m", "tilt_deg"), [(0.8, 25.0), (1.5, 10.0)])
def test_box_overhanging_the_box_under_it_measured_from_its_faces(distance_m, tilt_deg):
    """A box across a narrower one, overhanging its long sides (the lower top's rims lie
    past the upper's ends, out of the probes' reach): its faces end at the lower top, so it
    is measured from there, not from the table."""
    lower = box_on(Plane(), 0.05, 0.03, (0.15, 0.06, 0.11), 30.0, colour=(40, 90, 200))
    upper = box_on(lower, 0.02, 0.0, (0.07, 0.09, 0.12), 15.0, colour=(190, 150, 100))
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (lower, upper)))
    top = find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes[0]
    assert top.size[2] == pytest.approx(0.12, abs=0.001)
    assert math.dist(top.centre, upper.centre) <= 0.0025 * distance_m


@pytest.mark.parametrize(("distance_m", "tilt_deg"), [(0.8, 25.0), (1.5, 10.0)])
def test_box_over_a_box_it_hides_measured_from_its_faces(distance_m, tilt_deg):
    """A box on a smaller one it hides whole: no level under it is seen, but its side faces
    end at its bottom, 9 cm up; the height is good to the faces' pixels (under 3 mm here),
    not the 16 cm from the table."""
    lower = box_on(Plane(), 0.05, 0.03, (0.08, 0.06, 0.09), 30.0, colour=(40, 90, 200))
    upper = box_on(lower, 0.0, 0.0, (0.14, 0.10, 0.07), 10.0, colour=(190, 150, 100))
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (lower, upper)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 1
    assert found.boxes[0].size[2] == pytest.approx(0.07, abs=0.003)


@pytest.mark.parametrize(("distance_m", "tilt_deg"), [(0.9, 25.0), (1.2, 15.0)])
@pytest.mark.parametrize("turn_deg", [0.0, 6.0])
def test_box_flush_on_a_box_of_its_footprint_measured_from_the_seam(distance_m, tilt_deg, turn_deg):
    """A box on one of the same footprint, squarely or turned 6 degrees on it: the faces run
    down to the table in one plane (depth cannot tell where one box ends), but the colour
    changes where they meet, level across each face. With colour it is measured from there;
    from depth alone it is one box from the table."""
    lower = box_on(Plane(), 0.04, 0.02, (0.06, 0.02, 0.07), 20.0, colour=(60, 90, 190))
    # box_on turns a box on a box from the world's axes, not the lower box's.
    upper = box_on(lower, 0.0, 0.0, (0.06, 0.02, 0.13), 20.0 + turn_deg, colour=(190, 150, 100))
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (lower, upper)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 1
    assert found.boxes[0].size[2] == pytest.approx(0.13, abs=0.003)
    depth_only = find_boxes(depth, camera.lens, camera.camera_to_world)
    assert depth_only.boxes[0].size[2] == pytest.approx(0.20, abs=0.003)


def test_colour_step_where_a_lower_box_beside_meets_a_face_is_no_seam():
    """A tall box with a lower one of another colour touching it in front, flush with its
    side: the colour changes down the tall box's face where the lower box's top meets it, but
    the tall box stands on the table."""
    tall = box_on(Plane(), 0.0, 0.0, (0.08, 0.05, 0.2), 0.0, colour=(190, 150, 100))
    low = box_on(Plane(), 0.0, -0.065, (0.08, 0.08, 0.07), 0.0, colour=(60, 90, 190))
    camera = Camera.tilted(0.9, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (tall, low)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    heights = sorted(round(b.size[2], 3) for b in found.boxes)
    assert heights == pytest.approx([0.07, 0.2], abs=0.002)


@pytest.mark.parametrize(
    ("x", "y", "yaw_deg", "shift"),
    [
        (0.5, 0.0, 30.0, (1, 0)),
        (0.5, 0.4, 30.0, (2, 1)),
        (0.8, 0.0, 30.0, (2, 1)),
        (0.5, 0.0, 0.0, (-2, 2)),
    ],
)
def test_colour_a_pixel_or_two_off_the_depth_makes_no_seam_on_a_face(x, y, yaw_deg, shift):
    """A real camera's colour is registered with its depth to a pixel or two: a tall box seen
    steeply 2 m away, its colour picture that far off, paints the top's rim or the table's
    shade on the ends of its faces. That band is no seam between two boxes: the box stands on
    the table (before, 0.06-0.25 m tall)."""
    tall = box_on(Plane(), x, y, (0.3, 0.05, 0.3), yaw_deg, colour=(190, 150, 100))
    camera = Camera.tilted(2.0, 5.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (tall,)))
    off = np.roll(colour, shift, axis=(0, 1))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, off)
    assert [round(b.size[2], 3) for b in found.boxes] == [0.3]


@pytest.mark.parametrize("noise", ["none", "d435"])
@pytest.mark.parametrize("shift", [(0, 0), (2, 1), (-2, 2), (1, -3), (0, -1)])
def test_how_far_the_colour_lies_off_the_depth_is_measured(noise, shift):
    """Three boxes of three colours seen from 1 m at a slant, the colour picture moved by up
    to 3 pixels: the shift is measured exactly, noise-free and through the D435 preset, and
    moving the colour back gives the picture in register pixel for pixel; in register it is
    left alone."""
    boxes = (
        box_on(Plane(), -0.15, 0.05, (0.2, 0.12, 0.15), 20.0),
        box_on(Plane(), 0.12, -0.08, (0.25, 0.15, 0.08), -35.0, colour=(60, 140, 200)),
        box_on(Plane(), 0.1, 0.15, (0.1, 0.1, 0.2), 50.0, colour=(90, 190, 80)),
    )
    camera = Camera.tilted(1.0, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), boxes))
    if noise != "none":
        depth = DepthNoise(PRESETS[noise], depth.shape).apply(depth)
    support = fit_support(depth, camera.lens, camera.camera_to_world)
    off = np.roll(colour, shift, axis=(0, 1))
    measured = register.colour_offset(depth, off, support.sigma_m)
    assert measured.shift == shift
    assert measured.sure == (shift != (0, 0))
    back = register.in_register(off, measured.shift)
    assert back.shape == colour.shape
    assert np.array_equal(back[3:-3, 3:-3], colour[3:-3, 3:-3])


def test_pictures_that_show_no_jump_leave_the_colour_where_it_is():
    """An empty table, no reading at all (NaN or 0), or a colour picture of another view:
    nothing to be sure of, so the colour is taken as it comes."""
    camera = Camera.tilted(1.0, 20.0, width=320, height=240)
    box = box_on(Plane(), 0.0, 0.0, (0.2, 0.12, 0.15), 20.0)
    depth, colour = render(Scene(camera, Plane(), (box,)))
    empty_depth, empty_colour = render(Scene(camera, Plane(), ()))
    _, other_colour = render(Scene(Camera.tilted(1.0, 0.0, width=320, height=240), Plane(), (box,)))
    for d, c in [
        (empty_depth, empty_colour),
        (np.full_like(depth, np.nan), colour),
        (np.zeros_like(depth), colour),
        (depth, other_colour),
    ]:
        measured = register.colour_offset(d, c, 0.0005)
        assert measured.shift == (0, 0)
        assert not measured.sure
    assert register.colour_offset(np.zeros_like(depth), colour, 0.0005).jumps == 0


def test_a_box_whose_colour_lies_off_the_depth_is_one_box_in_a_stream():
    """A tall box 2 m away, its colour 2 pixels up and 2 right of the depth: the top's rim
    line, painted inside the top, read as a seam between two cartons, so the box was two
    boxes. The stream's finder measures the shift on its first picture and reads the colour
    moved back: one box; told the pictures are aligned, it still splits the box."""
    tall = box_on(Plane(), 0.5, 0.0, (0.3, 0.05, 0.3), 30.0, colour=(190, 150, 100))
    camera = Camera.tilted(2.0, 5.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (tall,)))
    off = np.roll(colour, (-2, 2), axis=(0, 1))
    finder = BoxFinder()
    for _ in range(2):
        found = finder(depth, camera.lens, camera.camera_to_world, off)
        assert [round(b.size[0], 2) for b in found.boxes] == [0.3]
    assert finder.registration.shift == (-2, 2)
    aligned = BoxFinder(FinderSettings(colour_shift=(0, 0)))
    found = aligned(depth, camera.lens, camera.camera_to_world, off)
    assert len(found.boxes) == 2
    assert aligned.registration.shift == (0, 0)


@pytest.mark.parametrize("seed", range(3))
def test_boxes_through_d435_noise_at_2_3_m(seed):
    """The D435 preset 2.3 m away (sigma 19 mm, holes, flying pixels, speckle): both boxes
    found, their tops ragged at the edges but measured by their hull (centres within 1 cm,
    sizes within 25 mm, heights within 3 mm); a cylinder and a ball beside them are not."""
    boxes = (
        box_on(Plane(), -0.25, 0.0, (0.2, 0.11, 0.3), 20.0),
        box_on(Plane(), 0.2, 0.1, (0.3, 0.15, 0.12), -35.0, colour=(60, 140, 200)),
    )
    things = (Cylinder((0.1, -0.25, 0.1), 0.08, 0.2), Sphere((-0.1, 0.3, 0.08), 0.08))
    camera = Camera.tilted(2.3, 10.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), boxes + things))
    noisy = DepthNoise(dataclasses.replace(PRESETS["d435"], seed=seed), depth.shape).apply(depth)
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    for box, true in match(found.boxes, boxes):
        assert math.dist(box.centre, true.centre) <= 0.01
        assert abs(box.size[0] - max(true.size[:2])) <= 0.025
        assert abs(box.size[1] - min(true.size[:2])) <= 0.025
        assert abs(box.size[2] - true.size[2]) <= 0.003


def test_the_depth_median_keeps_holes_and_edges():
    """The 3 x 3 median is scipy's inside the picture; a pixel with no reading (NaN or 0)
    keeps none, one with five of its nine missing gets none, and a step stays where it is."""
    rng = np.random.default_rng(0)
    depth = rng.uniform(1.0, 2.0, (40, 50)).astype(np.float32)
    inner = (slice(1, -1), slice(1, -1))
    assert np.array_equal(median3(depth)[inner], ndimage.median_filter(depth, 3)[inner])
    depth[5, 5], depth[20:23, 20:23], depth[30, 30:32] = np.nan, 0.0, np.inf
    depth[10:13, 11], depth[10, 12], depth[12, 12] = 0.0, np.nan, np.nan
    smooth = median3(depth)
    assert np.isnan(smooth[5, 5]) and np.isnan(smooth[21, 21]) and np.isnan(smooth[30, 30])
    assert np.isnan(smooth[11, 12])  # a reading, but five of its nine have none
    assert np.isfinite(smooth[19, 21]) and np.isfinite(smooth[5, 6])
    step = np.where(np.arange(30) < 12, 1.0, 1.1).astype(np.float32)[np.newaxis, :]
    assert np.array_equal(median3(np.repeat(step, 10, axis=0))[1:-1], np.repeat(step, 8, axis=0))


def far_d435_picture(seed: int) -> tuple[np.ndarray, np.ndarray, Camera, tuple[Box, ...]]:
    """Boxes 7 and 5 cm tall 2.5 m from a D435 (noise ``seed``): the picture, its colour, the
    camera and the boxes."""
    boxes = (
        box_on(Plane(), -0.25, 0.05, (0.3, 0.2, 0.07), 25.0, (180, 130, 80)),
        box_on(Plane(), 0.25, -0.1, (0.25, 0.15, 0.05), -40.0, (60, 140, 200)),
    )
    camera = Camera.tilted(2.5, 15.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), boxes))
    noisy = DepthNoise(dataclasses.replace(PRESETS["d435"], seed=seed), depth.shape).apply(depth)
    return noisy, colour, camera, boxes


@pytest.mark.parametrize("seed", range(4))
def test_low_boxes_under_the_noise_of_a_far_d435(seed):
    """Boxes 7 and 5 cm tall 2.5 m from a D435 (sigma 22 mm: four sigma, the least step the
    finder trusts, is 9 cm) were never seen. The picture is read through its 3 x 3 median
    there: both found, centres within 1 cm, heights within 5 mm; their sides come out short by
    up to 3 cm, as the dropout and the noise eat their edges."""
    noisy, colour, camera, boxes = far_d435_picture(seed)
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    for box, true in match(found.boxes, boxes):
        assert math.dist(box.centre, true.centre) <= 0.01
        assert abs(box.size[0] - max(true.size[:2])) <= 0.03
        assert abs(box.size[1] - min(true.size[:2])) <= 0.03
        assert abs(box.size[2] - true.size[2]) <= 0.005


def _centres_of_far_d435_boxes() -> list[tuple[float, float, float]]:
    noisy, colour, camera, _ = far_d435_picture(0)
    return [b.centre for b in find_boxes(noisy, camera.lens, camera.camera_to_world, colour).boxes]


def test_a_forked_process_reads_the_median_beside_the_picture_too():
    """The median's reading runs in a thread of the finder's. A process forked after the
    finder ran (a worker pool) has no such thread, only its parent's executor's state: the
    finder makes the child its own and gives the parent's boxes, instead of waiting forever."""
    here = _centres_of_far_d435_boxes()
    assert len(here) == 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # fork() of a threaded process
        with multiprocessing.get_context("fork").Pool(1) as pool:
            there = pool.apply_async(_centres_of_far_d435_boxes).get(timeout=60)
    assert there == here


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_narrow_boxes_with_stray_outline_pixels_through_an_azure_kinect(seed):
    """Boxes 35 cm long and 4.5-6 cm wide, 1.8 m from an Azure Kinect: a reading or two of
    an outline's hundreds, put a few millimetres out by the noise or a side face, widened the
    rectangle the fill is taken against by up to a tenth, and a box could fill under 0.85 of
    it (seeds 1 and 3 lost one each). The fill now leaves out one outline point in a hundred at
    each end: all found, centres within 4 mm, sides within 8 mm, heights within 1 mm."""
    rng = np.random.default_rng(seed)
    places = ((-0.35, -0.3, 0.05, 150), (0.3, 0.25, 0.045, 200), (0.0, 0.1, 0.06, 90))
    boxes = tuple(
        box_on(Plane(), x, y, (0.35, w, 0.1), float(rng.uniform(-80, 80)), (red, 90, 60))
        for x, y, w, red in places
    )
    camera = Camera.tilted(1.8, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), boxes))
    noise = dataclasses.replace(PRESETS["azure_kinect"], seed=seed)
    found = find_boxes(DepthNoise(noise, depth.shape).apply(depth), camera.lens,
                       camera.camera_to_world, colour)  # fmt: skip
    assert len(found.boxes) == 3
    for box, true in match(found.boxes, boxes):
        assert math.dist(box.centre, true.centre) <= 0.004
        assert abs(box.size[0] - true.size[0]) <= 0.008
        assert abs(box.size[1] - true.size[1]) <= 0.008
        assert abs(box.size[2] - true.size[2]) <= 0.001


def test_boxes_of_the_median_join_those_of_the_picture():
    """A box found in the median picture is added only where it shares no room with one
    found in the picture itself (the same box seen twice), a box standing on a box shares
    none, a neighbour overlapping by a sliver (the picture merged it into the next box) is
    added, and ``on`` points into the joined list, highest top first."""
    from onebox.perception.boxes import Box, _together

    def box(x, top, height, on=None, size=(0.3, 0.2)):
        return Box((x, 0.0, top - height / 2), (0.0, 0.0, 0.0, 1.0), (*size, height), 0.0, 0.9,
                   100, (x, 0.0, top), on)  # fmt: skip

    support = Support((0.0, 0.0, 1.0), 0.0, 0.9, 0.0, "world")
    lower, beside = box(0.0, 0.2, 0.2), box(1.0, 0.1, 0.1)
    seen = [lower, beside]
    # The median saw the lower box (a little off), a box on it, and a new one.
    more = [box(0.3, 0.35, 0.15, on=1), box(0.01, 0.2, 0.19), box(-1.0, 0.05, 0.05)]
    joined = _together(seen, more, support)
    assert [b.top_middle[0] for b in joined] == [0.3, 0.0, 1.0, -1.0]
    assert joined[0].on == 1 and joined[1] is lower
    assert _together(seen, [box(1.02, 0.1, 0.1, size=(0.1, 0.1))], support) == seen
    # 1 cm of a 30 cm box's length under the picture's box beside it: a box of its own.
    sliver = box(0.29, 0.2, 0.2)
    assert _together(seen, [sliver], support) == [lower, sliver, beside]
    assert _together(seen, [box(0.2, 0.2, 0.2)], support) == seen


TAN = ((200, 150, 90), (140, 100, 60))
"""Two carton colours, alternating so touching cartons part by colour."""


def test_pallet_margin_under_rows_of_two_heights():
    """Rows of tall, low and tall cartons inset 5 cm on a pallet, D435 noise at 2 m: the far
    row (its foot hidden, lower cartons in front) is measured from the pallet's margin, not
    from the low cartons' tops."""
    rng = np.random.default_rng(4)
    pallet = box_on(Plane(), 0.0, 0.0, (1.2, 0.8, 0.144), 0.0, (120, 90, 60))
    cartons = []
    for y, size in ((-0.2125, (0.36, 0.275, 0.3)), (0.025, (0.275, 0.2, 0.2))):
        count = 3 if size[0] > 0.3 else 4
        for col in range(count):
            x = (col - (count - 1) / 2) * size[0]
            cartons.append(box_on(pallet, x, y, size, 0.0, TAN[col % 2]))
    for col in range(3):
        far = box_on(pallet, (col - 1) * 0.36, 0.2625, (0.36, 0.275, 0.3), 0.0, TAN[col % 2])
        cartons.append(far)
    camera = Camera.tilted(
        1.86, 10.0, target=(0.0, -0.12, 0.144), width=640, height=480, hfov_deg=56.0
    )
    depth, colour = render(Scene(camera, Plane(), (pallet, *cartons)))
    found = find_boxes(
        add_noise(depth, Noise.d435(), rng), camera.lens, camera.camera_to_world, colour
    )
    for box, true in match(found.boxes, tuple(cartons)):
        assert box.size[2] == pytest.approx(true.size[2], abs=0.01)
        assert math.dist(box.centre, true.centre) <= 0.010


@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_box_on_a_box_beside_one_of_the_same_height(sigma_m):
    """A box standing off the middle of a box of almost its footprint, the lower box touching
    a box of its own height (so no level of its own shows), and a box overhanging a wider box
    whose strip shows only past its side face: both measured from the box under them."""
    rng = np.random.default_rng(13)
    beside = box_on(Plane(), 0.0, -0.19, (0.38, 0.37, 0.35), 0.0, (120, 170, 90))
    lower = box_on(Plane(), 0.027, 0.023, (0.131, 0.046, 0.35), 0.0, (40, 90, 200))
    upper = box_on(lower, 0.035, 0.007, (0.118, 0.041, 0.386), 0.0, (190, 150, 100))
    wide = box_on(Plane(), -0.33, -0.09, (0.292, 0.192, 0.21), 90.0, (200, 80, 60))
    on_wide = box_on(wide, -0.028, 0.002, (0.196, 0.173, 0.192), 90.0, (90, 200, 200))
    camera = Camera.looking_at((-1.1, -0.95, 2.2), (0.0, 0.0, 0.0), 640, 480, 60)
    shapes = (beside, lower, upper, wide, on_wide)
    depth, colour = render(Scene(camera, Plane(), shapes))
    if sigma_m:
        depth = add_noise(depth, Noise(sigma_m=sigma_m), rng)
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    for true in (upper, on_wide):
        box = min(found.boxes, key=lambda f: math.dist(f.top_middle, true.top_middle))
        assert math.dist(box.top_middle, true.top_middle) < 0.01
        assert box.size[2] == pytest.approx(true.size[2], abs=0.003 + 3 * sigma_m)


@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_box_mostly_hidden_behind_a_taller_one_is_left_out(sigma_m):
    """A long flat box, two thirds of it hidden behind a taller box in front: its size is
    unknown, so it is not reported at the size of the part seen; a flat box against a taller
    one behind it (a wall at its edge, hiding nothing) keeps its whole size."""
    camera = Camera.tilted(1.0, 30.0, width=640, height=480)
    hidden = box_on(Plane(), 0.0, 0.07, (0.10, 0.30, 0.05), 0.0, (40, 90, 200))
    front = box_on(Plane(), 0.0, -0.04, (0.16, 0.06, 0.25), 0.0, (190, 150, 100))
    flat = box_on(Plane(), 0.25, 0.1, (0.14, 0.09, 0.04), 0.0, (90, 200, 90))
    wall = box_on(Plane(), 0.25, 0.18, (0.14, 0.07, 0.2), 0.0, (200, 80, 60))
    depth, colour = render(Scene(camera, Plane(), (hidden, front, flat, wall)))
    if sigma_m:
        depth = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(3))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 3
    assert all(math.dist(b.top_middle[:2], hidden.top_middle[:2]) > 0.08 for b in found.boxes)
    for box, true in match(found.boxes, (front, flat, wall)):
        assert abs(box.size[0] - max(true.size[:2])) <= 0.004
        assert abs(box.size[1] - min(true.size[:2])) <= 0.006


def test_a_small_box_is_found_where_the_depth_is_clean():
    """A 2.5 x 2.3 cm box (a top of 5.75 cm^2, under the 3 x 3 cm kept where depth is noisy)
    beside a larger one: found at 0.6 m noise-free and through 1 mm of noise."""
    small = box_on(Plane(), 0.05, 0.03, (0.025, 0.023, 0.04), 15.0, (200, 60, 40))
    large = box_on(Plane(), -0.08, -0.02, (0.12, 0.08, 0.06), -20.0, (60, 90, 200))
    camera = Camera.tilted(0.6, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (small, large)))
    for sigma_m in (0.0, 0.001):
        noisy = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(1))
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        assert len(found.boxes) == 2
        for box, true in match(found.boxes, (small, large)):
            assert math.dist(box.centre, true.centre) < 0.002
            assert box.size[0] == pytest.approx(max(true.size[:2]), abs=0.002)
            assert box.size[1] == pytest.approx(min(true.size[:2]), abs=0.002)


@pytest.mark.parametrize("lid_m", [0.008, -0.008], ids=["bulging", "sagging"])
@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_cartons_whose_lids_bulge_or_sag_are_boxes(lid_m, sigma_m):
    """Real cartons' lids are not flat: overfilled they bulge, soft they sag, by several
    millimetres, smoothly. Seen from 0.7 m through clean depth each is still one box (the
    finder before lost one in three), its outline near the rim's (within 7 mm: a bulging lid's
    rim may fall under the top's level), its height between the rim and the lid's middle."""
    cartons = tuple(
        dataclasses.replace(box_on(Plane(), x, y, size, yaw, colour), lid_m=lid_m)
        for x, y, size, yaw, colour in (
            (0.0, 0.0, (0.30, 0.20, 0.15), 20.0, (170, 130, 90)),
            (0.22, 0.15, (0.20, 0.15, 0.10), -15.0, (160, 125, 85)),
            (-0.2, 0.18, (0.12, 0.10, 0.08), 5.0, (175, 135, 95)),
        )
    )
    camera = Camera.tilted(0.7, 20.0, width=640, height=480, hfov_deg=70)
    depth, colour = render(Scene(camera, Plane(), cartons))
    noisy = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(2))
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(cartons)
    for box, true in match(found.boxes, cartons):
        assert math.dist(box.top_middle[:2], true.top_middle[:2]) < 0.003
        assert box.size[0] == pytest.approx(max(true.size[:2]), abs=0.007)
        assert box.size[1] == pytest.approx(min(true.size[:2]), abs=0.007)
        rim, crest = true.size[2], true.size[2] + lid_m
        assert min(rim, crest) - 0.002 <= box.size[2] <= max(rim, crest) + 0.002


@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_a_box_whose_corner_a_taller_box_in_front_hides_is_found_whole(sigma_m):
    """A camera tilted 20 degrees sees a flat box's near corner behind a taller box in front:
    the part of its rectangle it can see is full, so it is a box, of its whole size (the
    finder before judged its fill over the whole rectangle, 0.83, and left it out). An
    upright cylinder whose rectangle's corners the same box hides is still no box: its outline
    does not hug its rectangle's sides."""
    table = Plane((0.0, 0.0, 0.75))
    flat = box_on(table, 0.2, 0.15, (0.3, 0.1, 0.05), 70.0, (60, 60, 200))
    tall = box_on(table, 0.05, 0.02, (0.2, 0.15, 0.1), 20.0, (200, 60, 50))
    camera = Camera.tilted(0.9, 20.0, target=(0.0, 0.0, 0.75), width=640, height=480)
    depth, colour = render(Scene(camera, table, (flat, tall)))
    noisy = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(3))
    found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    box = min(found.boxes, key=lambda b: math.dist(b.top_middle, flat.top_middle))
    assert math.dist(box.centre, flat.centre) < 0.003
    assert box.size[0] == pytest.approx(0.3, abs=0.004)
    assert box.size[1] == pytest.approx(0.1, abs=0.004)
    assert box.size[2] == pytest.approx(0.05, abs=0.002)
    assert yaw_error(box.yaw_deg, 70.0, square=False) < 1.0

    for dx in (-0.06, 0.0, 0.06):
        can = Cylinder((0.0, 0.0, 0.03), 0.05, 0.06)
        front = box_on(Plane(), dx, -0.08, (0.12, 0.08, 0.12), 15.0, (200, 60, 50))
        camera = Camera.tilted(0.7, 35.0, width=640, height=480)
        depth, colour = render(Scene(camera, Plane(), (can, front)))
        noisy = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(4))
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        assert all(math.hypot(*b.top_middle[:2]) > 0.05 for b in found.boxes), found.boxes


def test_a_face_seen_nearly_edge_on_shows_no_seam():
    """A camera off to one side and rolled 35 degrees sees one face of a flat box nearly
    edge-on: its pixels alternate between the face and what lies past it, and a few of another
    shade (the top's edge) fall on it part way down. That is no seam between two boxes stacked
    flush: every box stands on the table at its full height (the finder before measured that
    one 13 mm tall, its base at a "seam" 22 mm up)."""
    boxes = random_boxes(np.random.default_rng(111), 6, 0.2)
    camera = Camera.looking_at((0.3, -0.5, 0.6), (0.0, 0.0, 0.0), 640, 480, roll_deg=35.0)
    depth, colour = render(Scene(camera, Plane(), boxes))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(boxes)
    for box, true in match(found.boxes, boxes):
        assert box.size[2] == pytest.approx(true.size[2], abs=0.002)
        assert math.dist(box.centre, true.centre) < 0.003


@pytest.mark.parametrize("tilt_deg", [65.0, 70.0])
def test_a_narrow_top_seen_at_a_slant_keeps_its_width(tilt_deg):
    """A robot's head camera looks across a table, 65-70 degrees from straight down: a box's
    4 cm top along the line of sight spans eight pixel rows, two of them its rims' dark edges
    and two more cut beside them by the colour steps. Its few rows left are a band to the
    seam test (pixels along the line of sight are measured in metres on the top's plane now,
    not as across), and a band no other top reaches is a top of its own that grows back into
    its cut rows (the finder before reported it 20 mm and 8 mm narrow)."""
    box = box_on(Plane(), 0.0, 0.0, (0.08, 0.04, 0.06), 0.0, (100, 180, 200))
    camera = Camera.tilted(0.5, tilt_deg, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (box,)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 1
    assert found.boxes[0].size[0] == pytest.approx(0.08, abs=0.004)
    assert found.boxes[0].size[1] == pytest.approx(0.04, abs=0.004)
    assert found.boxes[0].size[2] == pytest.approx(0.06, abs=0.001)


@pytest.mark.parametrize(("distance_m", "tilt_deg"), [(1.5, 30.0), (1.8, 20.0)])
@pytest.mark.parametrize("turn_deg", [0.0, 25.0, 50.0])
def test_narrow_boxes_under_a_tilted_camera(distance_m, tilt_deg, turn_deg):
    """Boxes 1.5-2 cm wide, 4-6 pixels across, turned every way under a tilted camera. The
    long sides of a top at a slant to the pixel grid have outline pixels at every offset from
    the side, so the outermost stand within a fraction of a pixel of it: the rectangle a top's
    fill is taken against, grown by a whole footprint each way, made such tops fill 0.80-0.84
    of it. Finders before found 1 or 2 of the 4; straight down they found all 4, as now."""
    places = (
        (-0.25, -0.15, (0.30, 0.015, 0.10), 25.0),
        (0.2, 0.1, (0.20, 0.018, 0.06), 50.0),
        (0.0, 0.25, (0.25, 0.02, 0.15), 70.0),
        (0.05, -0.2, (0.12, 0.016, 0.04), 115.0),
    )
    boxes = tuple(
        box_on(Plane(), x, y, size, yaw + turn_deg, (160, 110, 70)) for x, y, size, yaw in places
    )
    camera = Camera.tilted(distance_m, tilt_deg, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), boxes))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 4
    for box, true in match(found.boxes, boxes):
        assert math.dist(box.centre, true.centre) <= 0.002
        assert abs(box.size[0] - true.size[0]) <= 0.002
        assert abs(box.size[1] - true.size[1]) <= 0.002
        assert abs(box.size[2] - true.size[2]) <= 0.001


def _standing_at(z: float, x: float, y: float, size, yaw_deg: float, colour) -> Box:
    """A box standing at height ``z`` with its top's middle over (x, y)."""
    return box_on(Plane(point=(0.0, 0.0, z)), x, y, size, yaw_deg, colour)


def _tallest_found(boxes, camera: Camera, sigma_m: float, seed: int):
    """The highest box found in ``boxes``' picture, through noise of ``sigma_m`` if any."""
    depth, colour = render(Scene(camera, Plane(), tuple(boxes)))
    if sigma_m:
        depth = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(seed))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    return max(found.boxes, key=lambda b: b.top_middle[2])


@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_a_box_overhanging_the_corner_of_the_one_under_it_stands_on_it(sigma_m):
    """A small box stands near a corner of a larger one and overhangs it there: past two of
    its sides, meeting at a corner, the camera sees the lower top on every probe line; past
    the other two, the table. Those are two sides of the top whose rectangle holds the box's
    middle, so the box stands on it (the finder before measured it from the table: 146 mm
    for 68)."""
    lower = box_on(Plane(), 0.0, 0.14, (0.2241, 0.1226, 0.0778), 52.77, (184, 103, 195))
    upper = _standing_at(0.0778, 0.0048, 0.1659, (0.0862, 0.07, 0.0681), -36.53, (64, 121, 208))
    top = _tallest_found(
        (lower, upper), Camera.tilted(0.9, 26.4, width=640, height=480), sigma_m, 5
    )
    assert top.top_middle[2] == pytest.approx(0.1459, abs=0.002)
    assert top.size[2] == pytest.approx(0.0681, abs=0.003)


def test_a_face_seen_nearly_edge_on_shows_no_seam_under_a_box_on_another():
    """A camera almost straight down sees a stacked box's faces 10-13 pixels long from its
    top to the table; the dark rim's step on them read as a seam between two boxes flush,
    12-23 mm over the lower top (the box 33 mm tall for 45). A line that short shows no
    seam now: the box is measured from the lower top seen round it."""
    lower = box_on(Plane(), -0.15, -0.1, (0.217, 0.1536, 0.0766), -29.79, (171, 188, 207))
    upper = _standing_at(0.0766, -0.1453, -0.0892, (0.0806, 0.0667, 0.045), -3.88, (201, 209, 214))
    camera = Camera.tilted(0.9, 3.68, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (lower, upper)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    top = max(found.boxes, key=lambda b: b.top_middle[2])
    assert top.size[2] == pytest.approx(0.045, abs=0.002)


def test_a_rim_at_one_height_is_a_ledge_at_that_height():
    """A rim of a lower top all round a top, every reading at one height (clean depth): its
    level is that height wherever the height falls among the histogram's bins (the window's
    middle bin lay up to a tolerance and half a bin off such readings, and 147 of these 300
    heights found no ledge)."""
    n = 40
    height = np.zeros((n, n), dtype=np.float32)
    label = np.zeros((n, n), dtype=np.int32)
    label[10:30, 10:30] = 1
    flat = label.reshape(-1)
    inside = np.flatnonzero(flat == 1)
    outline = np.zeros(len(inside), dtype=bool)
    for step in (1, -1, n, -n):
        outline |= flat[inside + step] != 1
    edge = inside[outline]
    wrong = []
    for rim in np.arange(0.03, 0.06, 0.0001, dtype=np.float32):
        height[7:33, 7:33] = rim
        height[10:30, 10:30] = 0.1
        ledge = tops._ledges(
            edge,
            np.zeros(len(edge), dtype=np.int32),
            flat,
            height.reshape(-1),
            n,
            np.array([0.1]),
            np.array([0.0015]),
            np.array([0.001]),
            FinderSettings(),
            1,
        )
        if not abs(ledge[0] - rim) < 1e-5:
            wrong.append(float(rim))
    assert wrong == []


@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_a_box_between_lower_ones_touching_it_stands_on_the_table(sigma_m):
    """Cartons turned 45 degrees packed edge to edge: one 11 mm taller than the two it
    touches. Their tops seen just past its sides are a ledge at their height, but they stand
    beside it (touching, not reaching under it): no sign of what it stands on (the finder
    before measured it 11 mm tall, standing on them)."""
    d = 0.1 * math.sqrt(2)
    colours = ((208, 130, 141), (197, 106, 106), (192, 198, 229))
    boxes = [
        box_on(Plane(), (k - 1) * d, 0.0, (0.1, 0.1, 0.0607), 45.0, colours[k]) for k in range(3)
    ]
    boxes.append(box_on(Plane(), -d / 2, d / 2, (0.1, 0.1, 0.0718), 45.0, (78, 212, 202)))
    boxes.append(box_on(Plane(), d / 2, d / 2, (0.1, 0.1, 0.0599), 45.0, (153, 111, 63)))
    tall = _tallest_found(boxes, Camera.tilted(0.8, 6.36, width=640, height=480), sigma_m, 3)
    assert tall.top_middle[2] == pytest.approx(0.0718, abs=0.002)
    assert tall.size[2] == pytest.approx(0.0718, abs=0.002)


def test_extents_are_those_of_find_objects():
    """The band test's bounding boxes, from each piece's pixels, are ndimage's."""
    labels, count = ndimage.label(np.random.default_rng(1).random((60, 80)) > 0.5)
    flat = np.flatnonzero(labels)
    group = (labels.reshape(-1)[flat] - 1).astype(np.int32)
    extents = _extents(flat, group, count, labels.shape[1])
    assert count > 100
    for (r0, r1, c0, c1), (rows, cols) in zip(extents, ndimage.find_objects(labels), strict=True):
        assert (r0, r1, c0, c1) == (rows.start, rows.stop, cols.start, cols.stop)


def test_noise_holes_do_not_make_a_narrow_top_a_band():
    """The seam test shrinks a piece between colour edges by 5 mm from each side (5 pixels
    where the nearest reading is 0.6 m away): nothing left, it is a band (a seam's dark
    line). A narrow top 12 pixels wide, pitted by noise (lone pixels cut by a height step of
    a few sigma), shrank from every pit as from an edge and was taken for a band; a pixel
    whose neighbours are three of them the piece is no edge. A band 4 pixels wide, pitted the
    same, is still one."""
    lens = Intrinsics(554.0, 554.0, 319.5, 239.5)
    support = Support((0.0, 0.0, 1.0), 0.0, 1.0, None, "camera", offset_camera_m=1.0)
    rng = np.random.default_rng(3)
    for across, band in ((12, False), (4, True)):
        labels = np.zeros((40, 200), dtype=np.int32)
        labels[10 : 10 + across, 20:180] = 1
        pits = (rng.random(labels.shape) < 0.12) & (labels == 1)
        pits[10] = pits[9 + across] = False  # the outline stays: only lone pixels inside
        labels[pits] = 0
        h = np.full(labels.shape, 0.1, dtype=np.float32)
        d = np.full(labels.shape, 1.0, dtype=np.float32)
        counts = np.bincount(labels.reshape(-1), minlength=2)
        flat = np.flatnonzero(labels)
        extents = _extents(flat, np.zeros(len(flat), dtype=np.int32), 1, labels.shape[1])
        found, _ = _bands(
            labels, h, d, np.array([1]), extents, counts, 0.6 / lens.fx, lens, support, (220, 120)
        )
        assert bool(found[0]) is band


@pytest.mark.parametrize("sigma_m", [0.0, 0.001])
def test_a_tall_box_beside_a_lower_one_stands_on_the_table(sigma_m):
    """A box 35 cm tall touching a 31 cm one at a corner, seen from 1.7 m: the lower top is
    seen right past one of its sides and its own side toward the tall box is hidden by it, so
    it might go on under the tall box. But the tall box's face on another side is seen going
    on down past that top, where the lower box has no face in its plane: the tall box stands
    on the table (the finder before measured it 45 mm tall, standing on the lower box, which
    it then left out as a pallet's top)."""
    lower = box_on(Plane(), -0.0436, -0.5542, (0.183, 0.279, 0.308), -82.0, (179, 125, 94))
    tall = box_on(Plane(), 0.233, -0.5648, (0.266, 0.103, 0.353), 8.0, (43, 87, 204))
    camera = Camera.looking_at((-0.084, -0.062, 1.69), (-0.084, -0.2, 0.0), 640, 480, 60)
    depth, colour = render(Scene(camera, Plane(), (lower, tall)))
    if sigma_m:
        depth = add_noise(depth, Noise(sigma_m=sigma_m), np.random.default_rng(1))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    for box, true in match(found.boxes, (lower, tall)):
        assert box.size[2] == pytest.approx(true.size[2], abs=0.003 + 3 * sigma_m)


@pytest.mark.parametrize("yaw_deg", [0.0, 60.0])
def test_a_narrow_box_through_d435_noise_at_2_2_m(yaw_deg):
    """A box 33 cm tall whose top is 5 cm wide, 2.2 m from a D435 (sigma 17 mm, a third of the
    width): the moments' least axis of its top turns across the strip (its width / sqrt 12
    is less than the noise), so the top looked tilted 70-80 degrees and the box was left out
    in 8 of 8 pictures. Its plane fitted along the rays is level and its sides are seen
    falling away: found in every picture, the only box, its sides within 25 mm (the camera's
    dropout eats a pixel or two at each edge, as in the test above)."""
    true = box_on(Plane(), 0.0, 0.0, (0.34, 0.05, 0.33), yaw_deg, (180, 130, 80))
    camera = Camera.tilted(2.2, 10.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (true,)))
    for seed in range(4):
        noise = DepthNoise(dataclasses.replace(PRESETS["d435"], seed=seed), depth.shape)
        found = find_boxes(noise.apply(depth), camera.lens, camera.camera_to_world, colour)
        assert len(found.boxes) == 1
        box = found.boxes[0]
        assert math.dist(box.centre, true.centre) <= 0.015
        assert abs(box.size[0] - 0.34) <= 0.025
        assert abs(box.size[1] - 0.05) <= 0.025
        assert abs(box.size[2] - 0.33) <= 0.005


@pytest.mark.parametrize("lump_px", [0.0, 1.0, 3.0])
def test_the_support_measures_how_wide_the_noise_lumps_are(lump_px):
    """A table through noise smoothed over 0, 1 and 3 pixels (a stereo camera's matching window
    makes neighbours err together), the same sigma each time: the support says so, from its
    own residuals, within a fifth of a pixel. The picture's 3 x 3 median keeps lumps as wide
    and makes independent errors lumpy over half a pixel or more: measured again on it."""
    camera = Camera.tilted(1.5, 15.0, width=640, height=480)
    depth, _ = render(Scene(camera, Plane(), ()))
    noise = Noise(sigma_m=0.004, correlation_px=lump_px)
    noisy = add_noise(depth, noise, np.random.default_rng(1))
    support = fit_support(noisy, camera.lens, camera.camera_to_world)
    assert support is not None
    assert support.lump_px == pytest.approx(lump_px, abs=0.2)
    smooth = median3(noisy)
    calmer = dataclasses.replace(support, sigma_m=noise_against(smooth, camera.lens, support))
    assert lump_width(smooth, camera.lens, calmer) >= max(lump_px - 0.2, 0.5)


def test_the_tilt_noise_gives_a_flat_top_follows_its_size_and_the_lumps():
    """:func:`noise_tilt_deg` against answers worked by hand: independent errors tilt a top of
    n x m pixels by 3 sigma sqrt(12 / (n^3 - n) / m) per pixel each way; errors in one lump
    far wider than the top tilt it as the lump's slope, sigma / (sqrt 2 lump) per pixel."""
    sigma, footprint = 0.01, 0.005
    each = 12.0 / (20**3 - 20) / 8 + 12.0 / (8**3 - 8) / 20
    alone = math.degrees(math.atan(3.0 * sigma * math.sqrt(each) / footprint))
    assert noise_tilt_deg(20, 8, sigma, footprint, 0.0) == pytest.approx(alone, rel=1e-9)
    slope = math.sqrt(2.0) * sigma / (math.sqrt(2.0) * 8.0)  # both ways, one lump of 8 px
    lumped = math.degrees(math.atan(3.0 * slope / footprint))
    assert noise_tilt_deg(3, 3, sigma, footprint, 8.0) == pytest.approx(lumped, rel=0.05)
    # Lumps tilt a narrow top more than independent errors; a wide top hardly at all.
    assert noise_tilt_deg(40, 5, sigma, footprint, 3.0) > 1.5 * noise_tilt_deg(
        40, 5, sigma, footprint, 0.0
    )
    assert noise_tilt_deg(200, 150, sigma, footprint, 3.0) < 1.0


@pytest.mark.parametrize("height_m", [2.0, 2.5])
def test_narrow_cartons_far_off_through_lumpy_noise(height_m):
    """Four cartons 4.5-7 cm wide, a ball and a standing can, 2-2.5 m under a camera whose
    noise (a D435's, 9-14 mm there) errs in lumps 3 pixels wide. A lump tilts a top that
    narrow as a whole, 10-30 degrees, past the 8 a level top may have: the finder before lost
    6 and 22 of the 32 cartons in eight pictures. A long top seen whole may tilt as far as the
    noise tilts a flat top of its size; a ball's and a can's round tops are squarish and may
    not. Every carton in 7 of 8 pictures or more, within 2 cm; nothing else."""
    cartons = (
        box_on(Plane(), -0.35, -0.2, (0.32, 0.045, 0.12), 20.0, (170, 130, 90)),
        box_on(Plane(), 0.3, -0.15, (0.16, 0.06, 0.1), -35.0, (160, 125, 85)),
        box_on(Plane(), -0.1, 0.25, (0.15, 0.05, 0.2), 70.0, (150, 120, 80)),
        box_on(Plane(), 0.35, 0.3, (0.25, 0.07, 0.08), 5.0, (180, 140, 95)),
    )
    things = (Sphere((0.05, -0.05, 0.045), 0.045), Cylinder((-0.3, 0.05, 0.08), 0.035, 0.16))
    camera = Camera.tilted(height_m, 15.0, width=640, height=480, hfov_deg=70)
    depth, colour = render(Scene(camera, Plane(), (*cartons, *things)))
    noise = Noise(axial_a_m=0.001, axial_b_per_m=0.002, quantum_m=0.001, correlation_px=3.0)
    seen = [0] * len(cartons)
    for seed in range(8):
        noisy = add_noise(depth, noise, np.random.default_rng(seed))
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        hits = [any(math.dist(b.centre, c.centre) < 0.02 for b in found.boxes) for c in cartons]
        assert len(found.boxes) == sum(hits), (seed, [b.size for b in found.boxes])
        seen = [n + hit for n, hit in zip(seen, hits, strict=True)]
    assert min(seen) >= 7, seen


@pytest.mark.parametrize(
    "heights",
    [((0.15, 0.136), (0.136, 0.15)), ((0.15, 0.15, 0.136), (0.15, 0.136, 0.15))],
)
def test_cartons_of_a_row_a_little_taller_than_their_neighbours_stand_on_the_floor(heights):
    """Cartons 25 cm square packed in rows, turned 20 degrees, some 14 mm lower than the
    cartons touching them, seen from 2.2 m: the lower top is seen right past the taller
    carton's side, which hides that top's side, so it might go on under the taller one. But
    the taller carton's side meets the lower top's hidden side end to end and the lower top
    goes out from it as far as a carton: two cartons side by side. Every carton found, each
    its own height (the finder before measured the taller ones 14 mm tall, on their
    neighbours, and left one of those out as their platform)."""
    side, turn = 0.25, math.radians(20.0)
    cartons = []
    for i, row in enumerate(heights):
        for j, tall in enumerate(row):
            u, v = (j - (len(row) - 1) / 2) * side, (i - (len(heights) - 1) / 2) * side
            x, y = u * math.cos(turn) - v * math.sin(turn), u * math.sin(turn) + v * math.cos(turn)
            cartons.append(box_on(Plane(), x, y, (side, side, tall), 20.0, TAN[(i + j) % 2]))
    camera = Camera.tilted(2.2, 8.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), tuple(cartons)))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == len(cartons)
    for box, true in match(found.boxes, tuple(cartons)):
        assert box.size[2] == pytest.approx(true.size[2], abs=0.002)


BROWN = (150, 110, 70)


def one_shade_pallet(noisy: bool, marked=lambda carton: carton):
    """The loaded pallet with every carton one brown (``marked`` adds tape or a label), and
    the boxes found on it."""
    pallet, cartons, camera = loaded_pallet(np.random.default_rng(0))
    cartons = [marked(dataclasses.replace(c, colour=BROWN)) for c in cartons]
    depth, colour = render(Scene(camera, Plane(), (pallet, *cartons)))
    if noisy:
        depth = add_noise(depth, Noise.d435(), np.random.default_rng(1))
    return tuple(cartons), find_boxes(depth, camera.lens, camera.camera_to_world, colour).boxes


@pytest.mark.parametrize(
    ("tape", "flap_line", "noisy"),
    [
        ((185, 140, 90), None, False),
        ((185, 140, 90), None, True),
        ((160, 118, 76), (96, 70, 45), False),
        ((160, 118, 76), (96, 70, 45), True),
        ((230, 230, 225), None, True),
    ],
)
def test_taped_cartons_of_one_shade_are_one_box_each(tape, flap_line, noisy):
    """A pallet of cartons of one brown, each taped along its top's middle (brown tape, clear
    tape showing the line where the flaps meet, white tape): the tape and the flaps are one
    top, and the boxes are those found on the same cartons untaped."""
    cartons, plain = one_shade_pallet(noisy)
    _, found = one_shade_pallet(noisy, lambda c: taped(c, tape, flap_line=flap_line))
    assert len(plain) == 12
    assert len(found) == 12, sorted(b.size[:2] for b in found)
    centre_mm, size_mm = (10.0, 20.0) if noisy else (3.0, 5.0)
    for box, true in match(found, cartons):
        assert math.dist(box.centre[:2], true.centre[:2]) * 1e3 < centre_mm
        assert abs(box.size[0] - max(true.size[:2])) * 1e3 < size_mm
        assert abs(box.size[1] - min(true.size[:2])) * 1e3 < size_mm
        untaped = min(plain, key=lambda b: math.dist(b.centre, box.centre))
        assert math.dist(box.centre, untaped.centre) < 0.001
        assert np.allclose(box.size, untaped.size, atol=0.001)


LABEL = Mark((0.0, 0.1), (-0.075, -0.005), (240, 240, 235))


def labelled(carton: Box) -> Box:
    return dataclasses.replace(carton, marks=(LABEL,))


def labelled_over_tape(carton: Box) -> Box:
    """Taped, and a label over a flap and the tape's edge."""
    carton = taped(carton)
    label = Mark((0.0, 0.1), (-0.09, -0.035), (240, 240, 235))
    return dataclasses.replace(carton, marks=(*carton.marks, label))


def banded(carton: Box) -> Box:
    """A red band 3 cm wide printed across the top near one end."""
    return dataclasses.replace(carton, marks=(Mark((0.08, 0.11), (-0.2, 0.2), (200, 40, 40)),))


@pytest.mark.parametrize(
    ("marked", "noisy"),
    [
        (labelled, False),
        (labelled, True),
        (labelled_over_tape, False),
        (labelled_over_tape, True),
        (banded, False),
    ],
)
def test_print_on_a_carton_is_part_of_its_top(marked, noisy):
    """A white shipping label inside each carton's top, a label across a flap and the tape,
    a band printed across near one end: print, not boxes. The boxes are those found on the
    same cartons unprinted, within 2 mm."""
    _, plain = one_shade_pallet(noisy)
    _, found = one_shade_pallet(noisy, marked)
    assert len(found) == 12, sorted(b.size[:2] for b in found)
    for box in found:
        unmarked = min(plain, key=lambda b: math.dist(b.centre, box.centre))
        assert math.dist(box.centre, unmarked.centre) < 0.002
        assert np.allclose(box.size, unmarked.size, atol=0.002)


def test_side_by_side_cartons_of_two_widths_stay_two():
    """Two cartons of one shade and length side by side, 12 and 9 cm wide: their seam runs
    along the whole's length, but off its middle, so it is no flap line; two boxes."""
    plane = Plane()
    a = box_on(plane, 0.0, -0.06, (0.3, 0.12, 0.1), 0.0, BROWN)
    b = box_on(plane, 0.0, 0.045, (0.3, 0.09, 0.1), 0.0, BROWN)
    camera = Camera.tilted(0.9, 15.0, width=640, height=480)
    depth, colour = render(Scene(camera, plane, (a, b), seam_m=0.003))
    found = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    assert len(found.boxes) == 2
    for box, true in match(found.boxes, (a, b)):
        assert box.size[1] == pytest.approx(true.size[1], abs=0.004)


@pytest.mark.parametrize("noisy", [False, True])
def test_a_top_measured_again_alone_is_measured_as_among_all(monkeypatch, noisy):
    """After a seam split (two cartons of one shade end to end) or a taped carton's pieces
    joined (a pallet of them), only the tops that changed are measured again: each comes out
    as it does measured among every top."""
    measure = tops._measure_all
    alone: list[tuple[int, int]] = []

    def both(*args):
        *every, only = args
        measured = measure(*args)
        if only is not None:
            among = [p for p in measure(*every) if only[p.label]]
            assert [repr(p) for p in measured] == [repr(p) for p in among]
            alone.append((int(only.sum()), len(only)))
        return measured

    monkeypatch.setattr(tops, "_measure_all", both)
    pair = ((0.3, 0.2, 0.2), 1.5, 10.0) if noisy else ((0.12, 0.08, 0.06), 0.8, 60.0)
    size, distance_m, turn_deg = pair
    seam_m = 0.012 if noisy else 0.005
    _, found = shadowed_seam_pair(size, distance_m, 20.0, turn_deg, seam_m, noisy)
    assert len(found.boxes) == 2
    split = len(alone)
    _, boxes = one_shade_pallet(noisy, taped)
    assert len(boxes) == 12
    assert split >= 1 and len(alone) > split, alone
    assert all(0 < changed <= every for changed, every in alone), alone
    assert any(changed < every for changed, every in alone), alone  # some kept as they were
