"""How right the boxes come out: the locator's finder on MuJoCo renders against the ground truth.

    python benchmarks/bench_accuracy.py [--scenes 30] [--empty 50] [--seed 1] [--only NAME]

Builds each world the way ``onebox sim`` does (random scenes from seeds, 640 x 480 with an
hfov of 60 degrees unless told otherwise, scene/pallet.toml,
scene/clutter.toml, the seed's world), renders colour and depth with MuJoCo, adds the depth
noise, and runs the box finder the locator runs (``onebox.perception.boxes.BoxFinder``) on the
picture, the lens the sim publishes and the camera's pose. Each detection is paired with the
true box whose top's middle is nearest its top's middle. A box whose whole top is in the
picture and seen (not hidden under another box: at least 95 % of its top's pixels see it) and
that nothing detected is "missed"; a detection near no true top is "false". A box partly hidden
under another, or a platform (a true box that two or more others stand on, such as a pallet),
counts neither way: the camera cannot see its whole top.

Prints, per case, median / p90 / worst of: the centre's error (mm, and as a share of the
camera's distance), the yaw's (degrees, modulo the box's symmetry), length and width (mm,
scaled to a camera 0.4 m away), height (mm); and the counts of found, missed and false boxes.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox.geometry import Intrinsics
from onebox.perception.boxes import BoxFinder, FinderSettings, Found
from onebox.world import spec
from onebox.world.noise import PRESETS, NoiseSpec
from onebox.world.random_scene import random_scene
from onebox.world.render import SceneRenderer
from onebox.world.scene import (
    build_model,
    camera_info,
    cameras,
    ground_truth,
    optical_pose,
    seed_scene,
)
from onebox.world.spec import SceneDesc, place, visible_top_pixels
from schemas import BoxTruth, GroundTruth

SCENES = Path(__file__).resolve().parent.parent / "scene"


@dataclass
class Errors:
    """One case's errors, one entry a matched box."""

    centre_mm: list[float] = field(default_factory=list)
    centre_share: list[float] = field(default_factory=list)
    yaw_deg: list[float] = field(default_factory=list)
    size_mm_at_04: list[float] = field(default_factory=list)
    size_mm: list[float] = field(default_factory=list)
    height_mm: list[float] = field(default_factory=list)
    found: int = 0
    missed: int = 0
    false: int = 0
    pictures: int = 0
    hidden_found: int = 0
    hidden_height_mm: list[float] = field(default_factory=list)
    """Heights of boxes partly hidden under another box: their top is seen in part, but how
    high it stands is as measurable as any top's."""
    ms: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return spec.quat_matrix((w, x, y, z))


def yaw_of(rotation: np.ndarray) -> float:
    """The length axis's angle about world z, degrees."""
    return math.degrees(math.atan2(rotation[1, 0], rotation[0, 0]))


def yaw_error(detected: float, true: float, square: bool) -> float:
    """The smallest turn between two length axes (a box looks the same turned half a turn, and
    a square top a quarter)."""
    period = 90.0 if square else 180.0
    diff = (detected - true) % period
    return min(diff, period - diff)


def render(
    scene: SceneDesc, noise: NoiseSpec
) -> Iterator[tuple[np.ndarray, np.ndarray, Intrinsics, np.ndarray, GroundTruth, list[int]]]:
    """Depth (noisy), colour, lens, camera pose and ground truth of the main camera."""
    import mujoco  # after onebox, which makes MuJoCo render headless

    from onebox.world.noise import DepthNoise

    model = build_model(scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cams = cameras(scene)
    main = cams[0]
    with SceneRenderer(model, cams) as renderer:
        capture = renderer.render(data, main.name)
    clean = capture.depth_m
    depth = DepthNoise(noise, clean.shape).apply(clean)
    pose = optical_pose(model, data, main.name)
    p, q = pose.position, pose.orientation
    matrix = np.eye(4)
    matrix[:3, :3] = quat_matrix(q.x, q.y, q.z, q.w)
    matrix[:3, 3] = (p.x, p.y, p.z)
    lens = Intrinsics.from_k(camera_info(main).k)
    placed = place(scene)
    top_pixels = visible_top_pixels(scene.camera, placed, clean)
    truth = ground_truth(model, data, scene, top_pixels)
    rays = spec.pixel_rays(scene.camera)
    whole = [int(np.isfinite(spec.top_depths(scene.camera, b, rays)).sum()) for b in placed]
    yield depth, capture.rgb, lens, matrix, truth, whole


def score(
    found: Found, truth: GroundTruth, whole: list[int], camera: np.ndarray, errors: Errors
) -> None:
    """Pair detections with true boxes by their tops' middles and add the errors."""
    boxes: list[BoxTruth] = list(truth.boxes)
    tops = np.array(
        [[b.pose.position.x, b.pose.position.y, b.pose.position.z + b.size.z / 2] for b in boxes]
    ).reshape(-1, 3)
    carried = [sum(1 for b in boxes if b.on == i) for i in range(len(boxes))]
    seen = [
        b.top_in_view and b.top_pixels >= 0.95 * max(n, 1)
        for b, n in zip(boxes, whole, strict=True)
    ]
    unjudged = {i for i, n in enumerate(carried) if n >= 2 or not seen[i]}
    used: set[int] = set()
    for box in found.boxes:
        top, centre = np.array(box.top_middle), np.array(box.centre)
        distances = np.linalg.norm(tops - top, axis=1)
        nearest = int(np.argmin(distances)) if len(boxes) else -1
        reach = (
            0.0
            if nearest < 0
            else max(0.02, 0.5 * min(boxes[nearest].size.x, boxes[nearest].size.y))
        )
        if nearest < 0 or distances[nearest] > reach or nearest in used:
            errors.false += 1
            errors.notes.append(
                f"false box, top at ({top[0]:+.3f}, {top[1]:+.3f}, {top[2]:+.3f}), size "
                f"{box.size[0]:.3f} x {box.size[1]:.3f} x {box.size[2]:.3f}"
            )
            continue
        used.add(nearest)
        true = boxes[nearest]
        if nearest in unjudged:
            errors.hidden_found += 1  # its whole top is not to be seen: neither right nor wrong
            if carried[nearest] < 2:  # ... but its height is (not a platform's, under many)
                height_error = abs(box.size[2] - true.size.z)
                errors.hidden_height_mm.append(1000 * height_error)
                if height_error > 0.01:
                    errors.notes.append(
                        f"box {nearest} (partly hidden) height {box.size[2]:.3f}, true "
                        f"{true.size.z:.3f}"
                    )
            continue
        errors.found += 1
        distance_m = float(np.linalg.norm(top - camera))
        p = true.pose.position
        centre_error = float(np.linalg.norm(centre - np.array([p.x, p.y, p.z])))
        errors.centre_mm.append(1000 * centre_error)
        errors.centre_share.append(100 * centre_error / distance_m)
        q = true.pose.orientation
        true_yaw = yaw_of(quat_matrix(q.x, q.y, q.z, q.w))
        square = abs(true.size.x - true.size.y) < 0.005
        errors.yaw_deg.append(yaw_error(box.yaw_deg, true_yaw, square))
        size_err = [abs(box.size[0] - true.size.x), abs(box.size[1] - true.size.y)]
        errors.size_mm.extend(1000 * s for s in size_err)
        errors.size_mm_at_04.extend(1000 * s * 0.4 / distance_m for s in size_err)
        errors.height_mm.append(1000 * abs(box.size[2] - true.size.z))
        if max(size_err) > 0.015 or centre_error > 0.01:
            errors.notes.append(
                f"box {nearest} off by {1000 * centre_error:.0f} mm: measured "
                f"{box.size[0]:.3f} x {box.size[1]:.3f} x {box.size[2]:.3f}, true "
                f"{true.size.x:.3f} x {true.size.y:.3f} x {true.size.z:.3f}"
            )
    for index, true in enumerate(boxes):
        if index not in used and index not in unjudged:
            errors.missed += 1
            p = true.pose.position
            errors.notes.append(
                f"missed box {index} at ({p.x:+.3f}, {p.y:+.3f}, {p.z:+.3f}) size "
                f"{true.size.x:.3f} x {true.size.y:.3f} x {true.size.z:.3f}"
            )


def run_case(scenes: list[SceneDesc], noise: NoiseSpec | None, errors: Errors) -> None:
    for scene in scenes:
        used = noise if noise is not None else scene.noise
        for depth, rgb, lens, pose, truth, whole in render(scene, used):
            finder = BoxFinder(FinderSettings())
            started = time.perf_counter()
            found = finder(depth, lens, pose, rgb)
            errors.ms.append(1000 * (time.perf_counter() - started))
            errors.pictures += 1
            score(found, truth, whole, pose[:3, 3], errors)


def row(name: str, values: list[float], digits: int = 2) -> str:
    if not values:
        return f"  {name:<22} -"
    v = np.asarray(values)
    return (
        f"  {name:<22} {np.median(v):.{digits}f} / {np.percentile(v, 90):.{digits}f} / "
        f"{v.max():.{digits}f}"
    )


def report(title: str, errors: Errors, verbose: bool) -> None:
    print(
        f"{title}: {errors.pictures} pictures, {errors.found} boxes found, {errors.missed} "
        f"missed, {errors.false} false ({errors.hidden_found} partly hidden also found); "
        f"{np.median(errors.ms) if errors.ms else 0:.1f} ms a picture (median)"
    )
    print("  (median / p90 / worst)")
    print(row("centre, mm", errors.centre_mm))
    print(row("centre, % of distance", errors.centre_share, 3))
    print(row("yaw, deg", errors.yaw_deg))
    print(row("length/width, mm", errors.size_mm))
    print(row("length/width at 0.4 m", errors.size_mm_at_04))
    print(row("height, mm", errors.height_mm))
    print(row("height, partly hidden", errors.hidden_height_mm))
    if verbose:
        for note in errors.notes[:30]:
            print(f"    {note}")
    sys.stdout.flush()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False)
    parser.add_argument("--scenes", type=int, default=30, help="random scenes per case (30)")
    parser.add_argument("--empty", type=int, default=50, help="empty tables per noise (50)")
    parser.add_argument("--seed", type=int, default=1, help="the first random scene's seed")
    parser.add_argument("--only", help="run only the cases whose title contains this")
    parser.add_argument("--width", type=int, default=640, help="random scenes' pictures (640)")
    parser.add_argument("--height", type=int, default=480, help="random scenes' pictures (480)")
    parser.add_argument("--verbose", action="store_true", help="list missed and false boxes")
    args = parser.parse_args()
    seeds = range(args.seed, args.seed + args.scenes)

    def randoms(boxes: int, objects: int) -> list[SceneDesc]:
        return [
            random_scene(s, boxes=boxes, objects=objects, width=args.width, height=args.height)
            for s in seeds
        ]

    def empty() -> list[SceneDesc]:
        return [
            replace(
                random_scene(s, boxes=1, objects=0, width=args.width, height=args.height),
                boxes=(),
            )
            for s in range(args.seed, args.seed + args.empty)
        ]

    cases: list[tuple[str, list[SceneDesc] | None, NoiseSpec | None]] = [
        ("seed's world, noise-free", [seed_scene()], PRESETS["none"]),
        ("random, noise-free", None, PRESETS["none"]),
        ("random, sigma 1 mm", None, NoiseSpec(model="gaussian", sigma_m=0.001)),
        (
            "empty tables, sigma 3 mm + speckle + edges",
            None,
            NoiseSpec(
                model="gaussian",
                sigma_m=0.003,
                speckle_share=0.002,
                clump_px=3,
                edge_px=2,
                flying_share=0.2,
            ),
        ),
        ("empty tables, d435", None, PRESETS["d435"]),
        ("empty tables, azure_kinect", None, PRESETS["azure_kinect"]),
        ("pallet, d435", [spec.load(SCENES / "pallet.toml")], PRESETS["d435"]),
        ("pallet, azure_kinect", [spec.load(SCENES / "pallet.toml")], PRESETS["azure_kinect"]),
        ("clutter, d435", [spec.load(SCENES / "clutter.toml")], PRESETS["d435"]),
        ("clutter, azure_kinect", [spec.load(SCENES / "clutter.toml")], PRESETS["azure_kinect"]),
    ]
    for title, scenes, noise in cases:
        if args.only and args.only not in title:
            continue
        if scenes is None:
            scenes = empty() if title.startswith("empty") else randoms(8, 3)
        errors = Errors()
        run_case(scenes, noise, errors)
        report(title, errors, args.verbose)


if __name__ == "__main__":
    main()
