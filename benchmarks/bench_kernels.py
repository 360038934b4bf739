"""What OpenCV and numba buy the box finder: each operation it uses, side by side with the same
operation in SciPy or NumPy, on a 640 x 480 picture.

    python benchmarks/bench_kernels.py [--repeats 50]

Prints, per operation, the median ms of each way and the ratio (other / ours). The picture is a
height map of twelve cartons in a 4 x 3 grid with 2 mm of noise; the regions grown back have
every seventh row cut, a harder case than the finder meets (a ring a pixel or two wide round
each top).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox.perception import kernels


def median_ms(call: Callable[[], object], repeats: int) -> float:
    call()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        call()
        times.append(1000 * (time.perf_counter() - started))
    return float(np.median(times))


def numpy_top_points(
    labels: np.ndarray, depth: np.ndarray, across: np.ndarray, down: np.ndarray, basis: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The core of kernels.top_points the NumPy way: every top pixel, top by top (a stable
    sort), its point's plane coordinates, and whether it is on its top's outline (another
    label among its 8 neighbours in the picture)."""
    flat = labels.ravel()
    index = np.flatnonzero(flat > 0)
    index = index[np.argsort(flat[index], kind="stable")]
    rows, cols = np.divmod(index, labels.shape[1])
    z = depth.ravel()[index].astype(np.float64)
    x, y = across[cols] * z, down[rows] * z
    a = basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * z
    b = basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * z
    padded = np.pad(labels, 1, mode="edge")  # past the picture's edge: its own row or column
    own = flat[index]
    edge = np.zeros(index.size, bool)
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            edge |= padded[rows + dr, cols + dc] != own
    return index, a, b, edge


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False)
    parser.add_argument("--repeats", type=int, default=50, help="timed runs of each (50)")
    args = parser.parse_args()
    rng = np.random.default_rng(1)
    height = np.zeros((480, 640), np.float32)
    labels = np.zeros((480, 640), np.int32)
    for k in range(12):  # twelve cartons in a 4 x 3 grid, some taller
        r, c = divmod(k, 4)
        top = np.float32(0.2 + 0.1 * (k % 3))
        height[40 + r * 140 : 160 + r * 140, 30 + c * 150 : 160 + c * 150] = top
        labels[40 + r * 140 : 160 + r * 140, 30 + c * 150 : 160 + c * 150] = k + 1
    height += rng.normal(0, 0.002, height.shape).astype(np.float32)
    standing = (height > 0.05).astype(np.uint8)
    square = np.ones((3, 3), np.uint8)
    depth = (1.0 - height).astype(np.float32)  # a camera 1 m above the floor, looking down
    sigma = np.full_like(height, 0.002)
    across = ((np.arange(640) - 319.5) / 600.0).astype(np.float32)
    down = ((np.arange(480) - 239.5) / 600.0).astype(np.float32)
    basis = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    kernels.warm_up()

    def grow_numba() -> None:
        grown = labels.copy()
        grown[::7, :] = 0  # cut rows to grow back
        kernels.grow(grown, height, standing.astype(bool), np.full_like(height, 0.006), 4)

    def grow_opencv() -> None:
        grown = labels.copy()
        grown[::7, :] = 0
        for _ in range(4):
            near = cv2.dilate(grown.astype(np.float32), square).astype(np.int32)
            take = (grown == 0) & standing.astype(bool) & (near > 0)
            grown[take] = near[take]

    rows = [
        ("3 x 3 dilate, float32", lambda: cv2.dilate(height, square),
         lambda: ndimage.grey_dilation(height, size=(3, 3))),
        ("5 x 5 box filter, float32", lambda: cv2.boxFilter(height, -1, (5, 5)),
         lambda: ndimage.uniform_filter(height, 5)),
        ("connected regions", lambda: cv2.connectedComponents(standing, connectivity=4),
         lambda: ndimage.label(standing)),
        ("3 x 3 opening", lambda: cv2.morphologyEx(standing, cv2.MORPH_OPEN, square),
         lambda: ndimage.binary_opening(standing, square)),
        ("5 x 5 median, float32", lambda: cv2.medianBlur(height, 5),
         lambda: ndimage.median_filter(height, 5)),
        ("every top's pixels, top by top (numba / NumPy)",
         lambda: kernels.top_points(labels, depth, height, sigma, across, down, basis),
         lambda: numpy_top_points(labels, depth, across, down, basis)),
        ("grow regions back 4 px (numba / OpenCV)", grow_numba, grow_opencv),
    ]  # fmt: skip
    print(f"{'operation, 640 x 480':48} {'ours ms':>9} {'other ms':>9} {'ratio':>7}")
    for name, ours, other in rows:
        a, b = median_ms(ours, args.repeats), median_ms(other, args.repeats)
        print(f"{name:48} {a:9.3f} {b:9.3f} {b / a:6.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
