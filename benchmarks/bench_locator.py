"""Milliseconds per picture of the box finder beside the seed's one-box method, and the
finder's accuracy on a noisy pallet and a cluttered table (ray-cast, answers known).

    python benchmarks/bench_locator.py [--repeats 30] [--scaling]

Timed in one process, on the same pictures (ray-cast, answers known, 0.5 mm noise):

- seed, as written: the seed's steps 3.4 and 3.5 in NumPy, every pixel a point moved into the
  world, then standing, top and middle (``seed.depth_to_points``, ``to_world``,
  ``seed.measure_box``); it finds one box only;
- seed, fast: the same answer from ``seed.locate_box`` (``onebox locator --method seed``);
- boxes, plane kept: what ``onebox locator`` runs on each picture while the camera stays put
  (the support plane checked, not fitted again);
- boxes, fresh: the same with the support plane fitted from scratch;
- one labelling of the standing pixels the finder reads (``ndimage.label``): a floor under any
  finder that splits a picture into objects with these libraries;
- the first picture of a fresh process: the imports, ``kernels.warm_up()`` (numba compiling
  the kernels into an empty cache, then loading them from it) and the first two pictures.

Then, on ray-cast pictures with known answers: a noisy pallet, a cluttered desk, empty tables,
a stream of still pictures (the ids), tables with only round things on them (tins upright
and lying, balls, bottles), where every box is a false one, desks of boxes among round
things, boxes on tables on legs with the floor round them, and such tables empty; then the
round things and the desks again through noise correlated over 5 pixels ("lumpy").

Figures: median and p90 over the repeats; the ratio is the finder (plane kept) over the seed as
written.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from onebox import memory
from onebox.geometry import to_world
from onebox.perception import seed as seed_method
from onebox.perception.boxes import FinderSettings, find_boxes, read_stride
from onebox.perception.register import colour_offset
from onebox.perception.stream import BoxFinder
from onebox.perception.support import fit_support, support_holds
from onebox.perception.surface import height_slope
from onebox.rectify import lens_of
from onebox.testing.raycast import (
    Box,
    Camera,
    Cylinder,
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
)
from schemas import CameraInfo


def timed(call, repeats: int) -> tuple[float, float]:
    call()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append((time.perf_counter() - start) * 1e3)
    return float(np.median(times)), float(np.percentile(times, 90))


def grid_boxes(count: int, spread: float, rng: np.random.Generator):
    side = math.ceil(math.sqrt(count))
    boxes = []
    for k in range(count):
        x = (k % side - (side - 1) / 2) * spread / side * 2
        y = (k // side - (side - 1) / 2) * spread / side * 2
        size = (float(rng.uniform(0.08, 0.12)), float(rng.uniform(0.05, 0.08)), 0.05 + 0.02 * k % 3)
        colour = tuple(int(v) for v in rng.integers(60, 230, 3))
        boxes.append(box_on(Plane(), x, y, size, float(rng.uniform(-60, 60)), colour))
    return tuple(boxes)


def speed(repeats: int) -> None:
    rng = np.random.default_rng(0)
    cases = [
        ("320x240, 1 box", Camera.tilted(0.4, 0.0, width=320, height=240), 1, 0.1),
        ("640x480, 12 boxes", Camera.tilted(0.9, 15.0, width=640, height=480), 12, 0.3),
        ("1280x720, 6 boxes", Camera.tilted(0.8, 15.0, width=1280, height=720), 6, 0.25),
    ]
    print(
        f"{'picture':<20} {'seed, as written':>17} {'seed, fast':>15} {'boxes, plane kept':>18} "
        f"{'boxes, fresh':>15} {'ratio':>6}"
    )
    for name, camera, count, spread in cases:
        boxes = grid_boxes(count, spread, rng)
        depth, colour = render(Scene(camera, Plane(), boxes))
        depth = add_noise(depth, Noise(sigma_m=0.0005), rng)
        lens = camera.lens
        pose = camera.camera_to_world
        support = fit_support(depth, lens, pose)

        def as_written(depth=depth, lens=lens, pose=pose) -> object:
            points = seed_method.depth_to_points(
                depth, lens.fx, lens.fy, lens.cx + 0.5, lens.cy + 0.5
            )
            return seed_method.measure_box(to_world(points, pose))

        written = timed(as_written, repeats)
        seed = timed(lambda: seed_method.locate_box(depth, lens, pose), repeats)  # noqa: B023
        kept = timed(
            lambda: find_boxes(depth, lens, pose, colour, support=support),  # noqa: B023
            repeats,
        )
        fresh = timed(lambda: find_boxes(depth, lens, pose, colour), repeats)  # noqa: B023
        found = len(find_boxes(depth, lens, pose, colour).boxes)
        print(
            f"{name:<20} {written[0]:8.2f}/{written[1]:6.2f}  {seed[0]:7.2f}/{seed[1]:6.2f}  "
            f"{kept[0]:9.2f}/{kept[1]:6.2f}  {fresh[0]:7.2f}/{fresh[1]:6.2f} "
            f"{kept[0] / written[0]:6.2f}x  ({found}/{count} found)"
        )
        # The least any finder that splits the picture into objects does: label it once (the
        # pixels the finder reads: every k-th of a picture over max_pixels).
        slope = height_slope(lens, camera.width, camera.height, support.normal_camera)
        standing = depth * slope + np.float32(support.offset_camera_m) > np.float32(0.01)
        k = read_stride(depth.shape, FinderSettings().max_pixels)
        label = timed(lambda: ndimage.label(standing[::k, ::k]), repeats)  # noqa: B023
        print(
            f"{'':<20} one labelling of the standing pixels it reads (ndimage.label"
            f"{f', one pixel in {k} each way' if k > 1 else ''}): {label[0]:.2f}/{label[1]:.2f} ms"
        )
        fit = timed(lambda: fit_support(depth, lens, pose), repeats)  # noqa: B023
        check = timed(lambda: support_holds(depth, lens, support), repeats)  # noqa: B023
        print(
            f"{'':<20} support plane: fit {fit[0]:.2f}/{fit[1]:.2f} ms, "
            f"check kept {check[0]:.2f}/{check[1]:.2f} ms ({fit[0] / check[0]:.0f}x cheaper)"
        )
        off = np.roll(colour, (2, -1), axis=(0, 1))
        shift = timed(
            lambda: colour_offset(depth, off, support.sigma_m),  # noqa: B023
            repeats,
        )
        every = FinderSettings().register_every
        print(
            f"{'':<20} the colour's shift against the depth: measured "
            f"{shift[0]:.2f}/{shift[1]:.2f} ms ({colour_offset(depth, off, support.sigma_m)}; "
            f"a BoxFinder measures it every {every} pictures: {shift[0] / every:.2f} ms a picture)"
        )


FIRST_PICTURE = """
import json, time
start = time.perf_counter()
from onebox.geometry import Intrinsics
from onebox.perception import kernels
from onebox.perception.boxes import find_boxes
from onebox.testing import synthetic
imported = time.perf_counter()
kernels.warm_up()
warmed = time.perf_counter()
scene = synthetic.Scene(width=640, height=480)
depth, lens = synthetic.depth_picture(scene), Intrinsics.from_k(scene.k)
times = []
for _ in range(2):
    begin = time.perf_counter()
    found = find_boxes(depth, lens, scene.camera_to_world()).boxes
    times.append(time.perf_counter() - begin)
print(json.dumps([imported - start, warmed - imported, *times, len(found)]))
"""
"""A fresh process: the finder's imports, ``kernels.warm_up()``, then the seed's scene at
640 x 480 read twice (seconds each), and the boxes found."""


def first_picture_cost() -> None:
    """What a fresh process pays before its first picture: numba compiling the kernels (an
    empty cache directory), or loading them from the cache it wrote (the same directory)."""
    root = str(Path(__file__).resolve().parent.parent)
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": root}
        for label in ("compiled (empty cache)", "loaded from the cache"):
            done = subprocess.run(
                [sys.executable, "-c", FIRST_PICTURE],
                env=env,
                capture_output=True,
                text=True,
                check=True,
                timeout=300,
            )
            *seconds, found = json.loads(done.stdout)
            imports, warm, first, second = (1e3 * t for t in seconds)
            print(
                f"first picture, kernels {label}: imports {imports:.0f} ms, "
                f"kernels.warm_up() {warm:.0f} ms, then the seed's scene at 640x480 "
                f"{first:.1f} ms, again {second:.1f} ms ({found} box found)"
            )


def scaling(repeats: int) -> None:
    """Where the time goes: the finder (plane kept, every pixel read) on grids of 0, 1, 4 and
    12 boxes at three picture sizes, the camera 0.9 m away, 15 degrees off straight down."""
    counts = (0, 1, 4, 12)
    print(f"{'every pixel, plane kept':<24}" + "".join(f"{f'{n} boxes':>12}" for n in counts))
    settings = FinderSettings(max_pixels=None)
    for width, height in ((320, 240), (640, 480), (1280, 960)):
        camera = Camera.tilted(0.9, 15.0, width=width, height=height)
        row = []
        for count in counts:
            rng = np.random.default_rng(0)
            boxes = grid_boxes(max(count, 1), 0.3, rng)[:count]
            depth, colour = render(Scene(camera, Plane(), boxes))
            depth = add_noise(depth, Noise(sigma_m=0.0005), rng)
            support = fit_support(depth, camera.lens, camera.camera_to_world)
            call = functools.partial(
                find_boxes, depth, camera.lens, camera.camera_to_world, colour, settings, support
            )
            found = len(call().boxes)
            ms = timed(call, repeats)[0]
            row.append(f"{ms:7.2f} ms" + ("" if found == count else f" ({found})"))
        print(f"{f'{width}x{height}':<24}" + "".join(f"{cell:>12}" for cell in row))


def rectify_cost(repeats: int) -> None:
    """What a lens that distorts adds: an Azure Kinect's raw depth (640 x 576,
    rational_polynomial) rectified before the finder reads it."""
    pinhole = Camera.tilted(0.9, 20.0, width=640, height=576, hfov_deg=2 * math.degrees(0.5653))
    camera = pinhole.distorted(
        "rational_polynomial", (5.06, 3.26, -6e-5, 8e-5, 0.165, 5.39, 4.95, 0.86)
    )
    boxes = grid_boxes(6, 0.3, np.random.default_rng(2))
    depth, colour = render(Scene(camera, Plane(), boxes))
    lens = camera.lens
    info = CameraInfo(
        width=640,
        height=576,
        distortion_model="rational_polynomial",
        d=list(camera.distortion[1]) if camera.distortion else [],
        k=[lens.fx, 0.0, lens.cx, 0.0, lens.fy, lens.cy, 0.0, 0.0, 1.0],
    )
    start = time.perf_counter()
    _, rectifier = lens_of(info)
    built = (time.perf_counter() - start) * 1e3
    assert rectifier is not None
    depth_ms = timed(lambda: rectifier.depth(depth), repeats)
    colour_ms = timed(lambda: rectifier.colour(colour), repeats)
    finder = timed(
        lambda: find_boxes(rectifier.depth(depth), lens, camera.camera_to_world, colour), repeats
    )
    print(
        f"640x576 Kinect lens: rectify depth {depth_ms[0]:.2f}/{depth_ms[1]:.2f} ms, colour "
        f"{colour_ms[0]:.2f}/{colour_ms[1]:.2f} ms (map built once: {built:.1f} ms); the finder "
        f"on it {finder[0]:.2f}/{finder[1]:.2f} ms"
    )


def report(name: str, found, truth) -> None:
    errors_c, errors_s = [], []
    missing = 0
    for box in truth:
        best = min(found.boxes, key=lambda f: math.dist(f.top_middle, box.top_middle), default=None)
        if best is None or math.dist(best.top_middle, box.top_middle) > 0.05:
            missing += 1
            continue
        errors_c.append(math.dist(best.centre, box.centre))
        true_size = (*sorted(box.size[:2], reverse=True), box.size[2])
        errors_s.append(max(abs(a - b) for a, b in zip(best.size, true_size, strict=True)))
    extra = len(found.boxes) - (len(truth) - missing)
    print(
        f"{name:<34} found {len(truth) - missing}/{len(truth)}, extra {extra}, centre worst "
        f"{1e3 * max(errors_c, default=0):.1f} mm, "
        f"size worst {1e3 * max(errors_s, default=0):.1f} mm"
    )


def accuracy() -> None:
    rng = np.random.default_rng(1)
    # Pallet: camera 2 m up, 10 degrees, 640x480 fx ~600, a pallet 0.15 m high with twelve
    # touching cartons of two sizes at three heights, a tall machine at one edge.
    pallet, cartons, camera = loaded_pallet(rng)
    machine = box_on(Plane(), 1.2, 0.0, (0.4, 0.4, 1.2), 0.0, (80, 80, 90))
    depth, colour = render(Scene(camera, Plane(), (pallet, *cartons, machine)))
    for noise_name, noise in (("D435", Noise.d435()), ("Kinect", Noise.kinect())):
        noisy = add_noise(depth, noise, rng)
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
        report(f"pallet, {noise_name} noise", found, tuple(cartons))
    # Clutter: 1280x720 fx ~630, camera 0.45 m above a table, 17 degrees, boxes among round
    # things and a tall arm at the edge.
    boxes = (
        box_on(Plane(), 0.05, 0.05, (0.1, 0.07, 0.05), 20.0, (200, 80, 60)),
        box_on(Plane(), -0.12, -0.02, (0.08, 0.08, 0.08), -40.0, (60, 90, 200)),
        box_on(Plane(), 0.1, -0.1, (0.15, 0.05, 0.04), 75.0, (220, 200, 80)),
    )
    others = (
        Cylinder((-0.05, 0.12, 0.06), 0.035, 0.12),
        Sphere((0.2, 0.08, 0.04), 0.04),
        Cylinder((-0.2, 0.1, 0.03), 0.03, 0.15, ((1, 0, 0), (0, 0, -1), (0, 1, 0))),
        Cylinder((0.45, 0.0, 0.3), 0.05, 0.6),
    )
    camera = Camera.tilted(0.45, 17.0, width=1280, height=720, hfov_deg=90.8)
    depth, colour = render(Scene(camera, Plane(), (*boxes, *others)))
    for noise_name, noise in (("sigma 3 mm", Noise(sigma_m=0.003)), ("Kinect", Noise.kinect())):
        found = find_boxes(
            add_noise(depth, noise, rng), camera.lens, camera.camera_to_world, colour
        )
        report(f"clutter, {noise_name}", found, boxes)
    false = 0
    for k in range(50):
        camera = Camera.tilted(float(rng.uniform(0.4, 2.0)), float(rng.uniform(0, 30)), width=320)
        depth, _ = render(Scene(camera, Plane()))
        noise = Noise.d435() if k % 2 else Noise(sigma_m=0.003, speckle_share=0.003)
        false += len(
            find_boxes(add_noise(depth, noise, rng), camera.lens, camera.camera_to_world).boxes
        )
    print(f"{'50 empty tables, noisy':<34} false boxes {false}")
    finder = BoxFinder()
    camera = Camera.tilted(0.6, 15.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), grid_boxes(6, 0.2, rng)))
    ids = [
        tuple(sorted(b.id for b in finder(depth, camera.lens, camera.camera_to_world).boxes))
        for _ in range(5)
    ]
    print(f"{'stream of 5 still pictures':<34} refits {finder.refits}, ids {ids[0]} .. {ids[-1]}")


NOISES: dict[str, Noise | None] = {
    "noise-free": None,
    "sigma 1 mm": Noise(sigma_m=0.001),
    "sigma 3 mm": Noise(sigma_m=0.003),
    "D435": Noise.d435(),
    "Kinect": Noise.kinect(),
}
"""The noises the ray-cast desks and tables are seen through."""

LUMPY: dict[str, Noise | None] = {
    "sigma 1 mm": Noise(sigma_m=0.001, correlation_px=5.0),
    "sigma 3 mm": Noise(sigma_m=0.003, correlation_px=5.0),
    "D435": dataclasses.replace(Noise.d435(), correlation_px=5.0),
}
"""The same noises correlated over 5 pixels (a stereo camera's matching window, a depth
filter): neighbours err together, in lumps."""


def round_things(tables: int = 30, noises: dict[str, Noise | None] = NOISES, how: str = "") -> None:
    """Tables with only round things on them (tins upright and lying, balls, bottles with
    rounded tops: 2-5 of them, 2-8 cm in radius), a camera 0.5-1.5 m up tilted up to 30
    degrees, under each of ``noises`` (the five of NOISES unless told): every box found is a
    false one. ``how`` is added to the line's title."""
    rng = np.random.default_rng(5)
    false = dict.fromkeys(noises, 0)
    for _ in range(tables):
        things: list[Cylinder | Sphere] = []
        for _ in range(int(rng.integers(2, 6))):
            x, y = (float(v) for v in rng.uniform(-0.25, 0.25, 2))
            radius = float(rng.uniform(0.02, 0.08))
            kind = int(rng.integers(0, 4))
            if kind == 0:
                height = float(rng.uniform(0.06, 0.24))
                things.append(Cylinder((x, y, height / 2), radius, height))
            elif kind == 1:
                things.append(Sphere((x, y, radius), radius))
            elif kind == 2:
                length = float(rng.uniform(0.08, 0.3))
                things.append(lying(x, y, radius, length, float(rng.uniform(0, 180))))
            else:
                height = float(rng.uniform(0.1, 0.3))
                things.append(Cylinder((x, y, height / 2), radius / 2, height))
                things.append(Sphere((x, y, height), radius / 2))
        height_m, tilt = float(rng.uniform(0.5, 1.5)), float(rng.uniform(0, 30))
        camera = Camera.tilted(height_m, tilt, width=640, height=480)
        depth, colour = render(Scene(camera, Plane(), tuple(things)))
        for name, noise in noises.items():
            noisy = depth if noise is None else add_noise(depth, noise, rng)
            found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour)
            false[name] += len(found.boxes)
    shown = ", ".join(f"{name} {count}" for name, count in false.items())
    print(f"{f'{tables} tables of round things{how}':<34} false boxes: {shown}")


def _top_in_view(box: Box, camera: Camera) -> bool:
    """Whether the four corners of the box's top fall in the picture (3 pixels in)."""
    to_camera = np.linalg.inv(camera.camera_to_world)
    half = np.asarray(box.size) / 2
    lens = camera.lens
    for sx in (-1, 1):
        for sy in (-1, 1):
            corner = np.asarray(box.centre) + box.matrix @ (half * (sx, sy, 1))
            x, y, z = to_camera[:3, :3] @ corner + to_camera[:3, 3]
            u, v = lens.fx * x / z + lens.cx, lens.fy * y / z + lens.cy
            if not (3 <= u <= camera.width - 4 and 3 <= v <= camera.height - 4):
                return False
    return True


def _place(
    rng: np.random.Generator, taken: list[tuple[float, float, float]], reach: float
) -> tuple[float, float] | None:
    """A spot on the desk whose circle of ``reach`` clears every one ``taken`` by 1 cm."""
    for _ in range(100):
        x, y = (float(v) for v in rng.uniform(-0.3, 0.3, 2))
        if all(math.hypot(x - px, y - py) > reach + pr + 0.01 for px, py, pr in taken):
            taken.append((x, y, reach))
            return x, y
    return None


def desks(tables: int = 30, noises: dict[str, Noise | None] = NOISES, how: str = "") -> None:
    """Desks of 2-5 boxes (4-20 cm, 3-15 cm tall, any turn) among 2-4 round things (tins
    upright and lying, balls), none touching, a camera 0.6-1.5 m up tilted up to 30 degrees,
    under each of ``noises`` (as :func:`round_things`). Found and missed count the boxes whose
    top is all in the picture; false, the boxes found where there is none (a box partly out of
    the picture is neither)."""
    rng = np.random.default_rng(3)
    counts = {name: [0, 0, 0] for name in noises}
    for _ in range(tables):
        taken: list[tuple[float, float, float]] = []

        boxes: list[Box] = []
        things: list[Cylinder | Sphere] = []
        for _ in range(int(rng.integers(2, 6))):
            length, width = sorted((float(v) for v in rng.uniform(0.04, 0.2, 2)), reverse=True)
            height = float(rng.uniform(0.03, 0.15))
            spot = _place(rng, taken, math.hypot(length, width) / 2)
            if spot is not None:
                colour = tuple(int(v) for v in rng.integers(60, 230, 3))
                yaw = float(rng.uniform(0, 180))
                boxes.append(box_on(Plane(), *spot, (length, width, height), yaw, colour))
        for _ in range(int(rng.integers(2, 5))):
            radius, kind = float(rng.uniform(0.02, 0.06)), int(rng.integers(0, 3))
            length = float(rng.uniform(0.08, 0.25))
            spot = _place(rng, taken, length / 2 if kind == 2 else radius)
            if spot is None:
                continue
            x, y = spot
            if kind == 0:
                height = float(rng.uniform(0.05, 0.2))
                things.append(Cylinder((x, y, height / 2), radius, height))
            elif kind == 1:
                things.append(Sphere((x, y, radius), radius))
            else:
                things.append(lying(x, y, radius, length, float(rng.uniform(0, 180))))
        height_m, tilt = float(rng.uniform(0.6, 1.5)), float(rng.uniform(0, 30))
        camera = Camera.tilted(height_m, tilt, width=640, height=480)
        depth, colour = render(Scene(camera, Plane(), (*boxes, *things)))
        _judge(depth, colour, camera, boxes, noises, rng, counts)
    shown = ", ".join(f"{name} {'/'.join(map(str, c))}" for name, c in counts.items())
    print(f"{f'{tables} desks, boxes among round things{how}':<34} found/missed/false: {shown}")


def _judge(
    depth: np.ndarray,
    colour: np.ndarray,
    camera: Camera,
    boxes: list[Box],
    noises: dict[str, Noise | None],
    rng: np.random.Generator,
    counts: dict[str, list[int]],
) -> None:
    """Adds each noise's found, missed and false boxes to ``counts``: a box is found where one
    is reported within 2 cm of its middle and of its height; found and missed count the boxes
    whose top is all in the picture, false the boxes reported where there is none."""
    seen = [box for box in boxes if _top_in_view(box, camera)]
    for name, noise in noises.items():
        noisy = depth if noise is None else add_noise(depth, noise, rng)
        found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour).boxes
        matched = set()
        for box in boxes:
            near = [
                i
                for i, f in enumerate(found)
                if i not in matched
                and math.dist(f.centre[:2], box.centre[:2]) < 0.02
                and abs(f.size[2] - box.size[2]) < 0.02
            ]
            if near:
                matched.add(near[0])
                counts[name][0] += box in seen
            elif box in seen:
                counts[name][1] += 1
        counts[name][2] += len(found) - len(matched)


def _legged_table(
    rng: np.random.Generator,
) -> tuple[float, tuple[float, float], tuple[Box, ...]]:
    """A table on legs 0.4-0.8 m high, 0.5-0.9 x 0.4-0.7 m, turned up to 20 degrees: its
    height, its size and its top and legs."""
    height_m = float(rng.uniform(0.4, 0.8))
    size = (float(rng.uniform(0.5, 0.9)), float(rng.uniform(0.4, 0.7)))
    return height_m, size, table_on_legs(size, height_m, float(rng.uniform(-20, 20)))


def _over_table(rng: np.random.Generator, height_m: float) -> Camera:
    """A 640 x 480 camera 0.6-1.4 m over a table's middle, tilted up to 35 degrees."""
    over, tilt = float(rng.uniform(0.6, 1.4)), float(rng.uniform(0, 35))
    return Camera.tilted(over, tilt, target=(0.0, 0.0, height_m), width=640, height=480)


def tables_on_legs(tables: int = 20) -> None:
    """Tables on legs 0.4-0.8 m high, 0.5-0.9 x 0.4-0.7 m, the floor round them, 2-5 boxes on
    each, a camera 0.6-1.4 m over the table tilted up to 35 degrees: found / missed / false as
    :func:`_judge` counts them (the table itself, reported, is a false box). Not through a
    flat sigma 3 mm: noise that does not grow with distance is read on the floor, farther than
    the table by its height, and taken to shrink toward the table as a real camera's does."""
    rng = np.random.default_rng(1)
    noises = {name: noise for name, noise in NOISES.items() if name != "sigma 3 mm"}
    counts = {name: [0, 0, 0] for name in noises}
    for _ in range(tables):
        height_m, size, table = _legged_table(rng)
        top = Plane((0.0, 0.0, height_m))
        boxes: list[Box] = []
        for _ in range(int(rng.integers(2, 6))):
            length, width = sorted((float(v) for v in rng.uniform(0.04, 0.2, 2)), reverse=True)
            x = float(rng.uniform(-size[0] / 2 + 0.1, size[0] / 2 - 0.1))
            y = float(rng.uniform(-size[1] / 2 + 0.1, size[1] / 2 - 0.1))
            colour = tuple(int(v) for v in rng.integers(60, 230, 3))
            box = box_on(
                top,
                x,
                y,
                (length, width, float(rng.uniform(0.03, 0.15))),
                float(rng.uniform(0, 180)),
                colour,
            )
            reach = (math.hypot(length, width) + 0.01) / 2
            if all(
                math.dist(box.centre[:2], o.centre[:2]) > reach + math.hypot(*o.size[:2]) / 2
                for o in boxes
            ):
                boxes.append(box)
        camera = _over_table(rng, height_m)
        depth, colour = render(Scene(camera, Plane(), (*table, *boxes)))
        _judge(depth, colour, camera, boxes, noises, rng, counts)
    shown = ", ".join(f"{name} {'/'.join(map(str, c))}" for name, c in counts.items())
    print(f"{f'{tables} tables on legs, the floor round':<34} found/missed/false: {shown}")


def empty_tables_on_legs(tables: int = 20) -> None:
    """Tables on legs as :func:`tables_on_legs` draws them, with nothing on them: every box
    reported is false (the table's top, as a box as high as the table, before it was looked
    under)."""
    rng = np.random.default_rng(5)
    noises = {name: noise for name, noise in NOISES.items() if name != "sigma 3 mm"}
    false = dict.fromkeys(noises, 0)
    for _ in range(tables):
        height_m, _, table = _legged_table(rng)
        camera = _over_table(rng, height_m)
        depth, colour = render(Scene(camera, Plane(), table))
        for name, noise in noises.items():
            noisy = depth if noise is None else add_noise(depth, noise, rng)
            found = find_boxes(noisy, camera.lens, camera.camera_to_world, colour).boxes
            false[name] += len(found)
    shown = ", ".join(f"{name} {count}" for name, count in false.items())
    print(f"{f'{tables} empty tables on legs':<34} false boxes: {shown}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument(
        "--scaling",
        action="store_true",
        help="also time the finder on 0, 1, 4 and 12 boxes at three picture sizes",
    )
    args = parser.parse_args()
    memory.bound_heap()  # malloc as the locator sets it
    speed(args.repeats)
    first_picture_cost()
    if args.scaling:
        scaling(args.repeats)
    rectify_cost(args.repeats)
    print()
    accuracy()
    round_things()
    desks()
    tables_on_legs()
    empty_tables_on_legs()
    round_things(noises=LUMPY, how=", lumpy")
    desks(noises=LUMPY, how=", lumpy")


if __name__ == "__main__":
    main()
