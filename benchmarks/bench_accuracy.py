"""How right the boxes come out: the locator's finder on MuJoCo renders against the ground truth.

    python benchmarks/bench_accuracy.py [--scenes 30] [--empty 50] [--pallets 30] [--seed 1]
        [--only NAME] [--max-pixels N]

Builds each world the way ``onebox sim`` does (random scenes from seeds, 640 x 480 with an hfov
of 60 degrees unless told otherwise; random loaded pallets from seeds
(:func:`onebox.world.random_scene.random_pallet`), the same pallets taped; the random scenes
looked at across, 45 degrees from straight down
(:func:`onebox.world.random_scene.looking_across`); scene/pallet.toml, scene/clutter.toml, the
seed's world), renders colour and depth with MuJoCo, adds the depth noise (the presets, and a
D435 whose errors come in lumps 3 pixels wide), and runs the box finder the locator runs
(``onebox.perception.boxes.BoxFinder``) on the picture, the lens the sim publishes and the
camera's pose (on the depth alone, in the cases saying "depth only": a camera with no
colour; with the colour a pixel or two off the depth, or through a colour sensor's noise,
where the case says so), and judges
what it finds against the ground truth (:mod:`onebox.testing.judged` says how: found,
missed, false; a box partly hidden under another is judged on its height only).

Prints, per case, median / p90 / worst of: the centre's error (mm, and as a share of the
camera's distance), the yaw's (degrees, modulo the box's symmetry), length and width (mm,
scaled to a camera 0.4 m away), height (mm), the height of boxes partly hidden under another;
and the counts of found, missed and false boxes. ``--max-pixels`` reads the pictures the way the
locator's ``max_pixels`` setting does (at every k-th pixel when larger: faster, coarser).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox.perception.boxes import MAX_PIXELS, FinderSettings
from onebox.perception.stream import BoxFinder
from onebox.testing.judged import Judged, judge, render_scene
from onebox.world import spec
from onebox.world.noise import PRESETS, NoiseSpec
from onebox.world.random_scene import looking_across, random_pallet, random_scene
from onebox.world.scene import seed_scene
from onebox.world.spec import SceneDesc

SCENES = Path(__file__).resolve().parent.parent / "scene"
ACROSS_TILT_DEG = 45.0
"""The random scenes once more, seen this far from straight down (a robot's head)."""
COLOUR_OFF = {
    "2 px down and 1 px right of the depth": (2, 1),
    "1 px up and 2 px left of the depth": (-1, -2),
    "1 px down and 1 px right of the depth": (1, 1),
}
"""The colour picture rolled (rows, columns) against the depth: a real camera's colour is
registered with its depth to a pixel or two."""
COLOUR_NOISE = 8.0
"""A colour camera's sensor noise in dim light, sigma in levels of 0..255 a channel."""
LUMPY_D435 = replace(PRESETS["d435"], correlation_px=3.0)
"""A D435 whose errors come in lumps 3 pixels wide (its matching window, a depth filter)."""


@dataclass
class Errors(Judged):
    """One case's errors, and the finder's time a picture."""

    ms: list[float] = field(default_factory=list)


def run_case(
    scenes: list[SceneDesc],
    noise: NoiseSpec | None,
    errors: Errors,
    colour: bool = True,
    colour_off: tuple[int, int] = (0, 0),
    settings: FinderSettings | None = None,
) -> None:
    for scene in scenes:
        rendered = render_scene(scene, noise if noise is not None else scene.noise)
        finder = BoxFinder(settings or FinderSettings())
        rgb = np.roll(rendered.rgb, colour_off, axis=(0, 1)) if colour else None
        started = time.perf_counter()
        found = finder(rendered.depth_m, rendered.lens, rendered.camera_to_world, rgb)
        errors.ms.append(1000 * (time.perf_counter() - started))
        judge(found, rendered, errors)


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
        f"missed, {errors.false} false ({errors.hidden_found} of {errors.hidden} partly hidden "
        "also found); "
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
    print(row("length/width, p. hidden", errors.hidden_size_mm))
    if verbose:
        for note in errors.notes[:30]:
            print(f"    {note}")
    sys.stdout.flush()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False)
    parser.add_argument("--scenes", type=int, default=30, help="random scenes per case (30)")
    parser.add_argument("--empty", type=int, default=50, help="empty tables per noise (50)")
    parser.add_argument("--pallets", type=int, default=30, help="random pallets per noise (30)")
    parser.add_argument("--seed", type=int, default=1, help="the first random scene's seed")
    parser.add_argument("--only", help="run only the cases whose title contains this")
    parser.add_argument("--width", type=int, default=640, help="random scenes' pictures (640)")
    parser.add_argument("--height", type=int, default=480, help="random scenes' pictures (480)")
    parser.add_argument("--verbose", action="store_true", help="list missed and false boxes")
    parser.add_argument(
        "--max-pixels",
        type=int,
        default=MAX_PIXELS,
        metavar="N",
        help="read pictures larger than N pixels at every k-th pixel, as the locator's "
        f"max_pixels does (default {MAX_PIXELS:,}; 0: every pixel)",
    )
    args = parser.parse_args()
    if args.max_pixels < 0:
        parser.error(f"--max-pixels {args.max_pixels}: must be 0 (every pixel) or more")
    settings = FinderSettings(max_pixels=args.max_pixels or None)
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

    def pallets(taped: bool = False) -> list[SceneDesc]:
        return [random_pallet(s, taped=taped) for s in range(args.seed, args.seed + args.pallets)]

    cases: list[tuple[str, list[SceneDesc] | None, NoiseSpec | None]] = [
        ("seed's world, noise-free", [seed_scene()], PRESETS["none"]),
        ("random, noise-free", None, PRESETS["none"]),
        ("random, sigma 1 mm", None, NoiseSpec(model="gaussian", sigma_m=0.001)),
        ("random, d435", None, PRESETS["d435"]),
        ("random, azure_kinect", None, PRESETS["azure_kinect"]),
        ("random, d435 lumpy (3 px)", None, LUMPY_D435),
        ("random looked at across, 45 degrees, noise-free", None, PRESETS["none"]),
        ("random looked at across, 45 degrees, d435", None, PRESETS["d435"]),
        ("random looked at across, 45 degrees, azure_kinect", None, PRESETS["azure_kinect"]),
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
        ("empty tables, d435 lumpy (3 px)", None, LUMPY_D435),
        ("random pallets, noise-free", None, PRESETS["none"]),
        ("random pallets, d435", None, PRESETS["d435"]),
        ("random pallets, d435 lumpy (3 px)", None, LUMPY_D435),
        ("random pallets taped, noise-free", None, PRESETS["none"]),
        ("random pallets taped, d435", None, PRESETS["d435"]),
        ("pallet, d435", [spec.load(SCENES / "pallet.toml")], PRESETS["d435"]),
        ("pallet, azure_kinect", [spec.load(SCENES / "pallet.toml")], PRESETS["azure_kinect"]),
        ("clutter, d435", [spec.load(SCENES / "clutter.toml")], PRESETS["d435"]),
        ("clutter, azure_kinect", [spec.load(SCENES / "clutter.toml")], PRESETS["azure_kinect"]),
        ("random, noise-free, colour 2 px down and 1 px right of the depth", None, PRESETS["none"]),
        ("random, d435, colour 1 px up and 2 px left of the depth", None, PRESETS["d435"]),
        (
            "random, azure_kinect, colour 1 px down and 1 px right of the depth",
            None,
            PRESETS["azure_kinect"],
        ),
        (
            "random, d435, the colour's noise 8 levels",
            None,
            replace(PRESETS["d435"], colour_sigma=COLOUR_NOISE),
        ),
        (
            "random pallets, noise-free, the colour's noise 8 levels",
            None,
            replace(PRESETS["none"], colour_sigma=COLOUR_NOISE),
        ),
        (
            "random pallets, d435, the colour's noise 8 levels",
            None,
            replace(PRESETS["d435"], colour_sigma=COLOUR_NOISE),
        ),
        ("random, noise-free, depth only", None, PRESETS["none"]),
        ("random, d435, depth only", None, PRESETS["d435"]),
        ("random looked at across, 45 degrees, noise-free, depth only", None, PRESETS["none"]),
        ("empty tables, d435, depth only", None, PRESETS["d435"]),
        ("random pallets, noise-free, depth only", None, PRESETS["none"]),
        (
            "random pallets, sigma 2 mm, depth only",
            None,
            NoiseSpec(model="gaussian", sigma_m=0.002),
        ),
    ]
    for title, scenes, noise in cases:
        if args.only and args.only not in title:
            continue
        if scenes is None:
            if title.startswith("empty"):
                scenes = empty()
            elif title.startswith("random pallets"):
                scenes = pallets(taped="taped" in title)
            elif title.startswith("random looked at across"):
                scenes = [looking_across(scene, ACROSS_TILT_DEG) for scene in randoms(8, 3)]
            else:
                scenes = randoms(8, 3)
        if not scenes:  # --scenes, --empty or --pallets 0: the case is left out
            continue
        errors = Errors()
        off = COLOUR_OFF.get(title.split(", colour ")[-1], (0, 0))
        run_case(
            scenes,
            noise,
            errors,
            colour="depth only" not in title,
            colour_off=off,
            settings=settings,
        )
        report(title, errors, args.verbose)


if __name__ == "__main__":
    main()
