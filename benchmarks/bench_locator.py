"""The locator's compute per picture, against the seed's pseudo code transcribed into NumPy.

    python benchmarks/bench_locator.py [--repeats N]

For 320 x 240, 640 x 480 and 1280 x 720 depth pictures of the default scene (a 6 cm box at
(0.065, 0.040) under the camera 0.40 m up, hfov 60, worked out exactly by casting a ray per
pixel) it times, in the same run and interleaved so both see the same machine load:

- reference: the seed's section 3.4 and 3.5 as written: every pixel's middle from
  ``np.mgrid + 0.5``, x, y, z for all of them, all moved into the world with the 4 x 4 matrix,
  then standing, top and middle;
- locator: ``pictures.depth_metres`` + ``seed.locate_box``, what ``onebox locator`` runs per
  picture (the per-lens limit grid cached, as in the running locator).

Both start from the message's bytes. It prints the median milliseconds of each, the ratio, and
checks both found the same standing and top points and the same middle.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np

from onebox import geometry, pictures
from onebox.perception import seed
from onebox.testing.synthetic import Scene, depth_picture

SIZES = [(320, 240), (640, 480), (1280, 720)]


def reference(
    data: bytes, width: int, height: int, k: list[float], camera_to_world: np.ndarray
) -> tuple[float, float, float, int, int]:
    """The seed's pseudo code, every pixel, in NumPy (sections 3.4 and 3.5)."""
    depth = np.frombuffer(data, np.float32).reshape(height, width)
    fx, fy, cx, cy = k[0], k[4], k[2], k[5]
    v, u = np.mgrid[0:height, 0:width] + 0.5
    x = (u - cx) * depth / fx
    y = (v - cy) * depth / fy
    z = depth
    points = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    points = points @ camera_to_world[:3, :3].T + camera_to_world[:3, 3]
    standing = points[points[:, 2] > 0.01]
    top_z = float(standing[:, 2].max())
    top = standing[standing[:, 2] > top_z - 0.001]
    return float(top[:, 0].mean()), float(top[:, 1].mean()), top_z, len(standing), len(top)


def locator(
    data: bytes, width: int, height: int, lens: geometry.Intrinsics, camera_to_world: np.ndarray
) -> seed.BoxMeasurement | None:
    depth = pictures.depth_metres(
        data, width=width, height=height, step=width * 4, encoding="32FC1"
    )
    return seed.locate_box(depth, lens, camera_to_world)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=60, help="timed runs of each (default 60)")
    args = parser.parse_args()
    print(f"{'size':>10}  {'reference ms':>12}  {'locator ms':>10}  {'ratio':>6}  points")
    for width, height in SIZES:
        scene = Scene(width=width, height=height)
        data = depth_picture(scene).tobytes()
        lens = geometry.Intrinsics.from_k(scene.k)
        matrix = scene.camera_to_world()
        ref = reference(data, width, height, scene.k, matrix)
        box = locator(data, width, height, lens, matrix)
        assert box is not None
        assert (box.standing_count, box.top_count) == ref[3:], (box, ref)
        assert abs(box.x - ref[0]) < 1e-12 and abs(box.y - ref[1]) < 1e-12
        ref_s: list[float] = []
        ours_s: list[float] = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            reference(data, width, height, scene.k, matrix)
            ref_s.append(time.perf_counter() - start)
            # The locator is fast enough that one run is close to the timer's resolution.
            start = time.perf_counter()
            for _ in range(10):
                locator(data, width, height, lens, matrix)
            ours_s.append((time.perf_counter() - start) / 10)
        ref_ms = statistics.median(ref_s) * 1e3
        ours_ms = statistics.median(ours_s) * 1e3
        print(
            f"{width:>4} x {height:<4}  {ref_ms:>12.3f}  {ours_ms:>10.3f}  "
            f"{ref_ms / ours_ms:>5.1f}x  {width * height:,} / {box.standing_count:,} standing"
            f" / {box.top_count:,} top"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
