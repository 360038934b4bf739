"""The few per-region loops no library does, compiled with numba (cached on disk where the
install allows; :func:`warm_up` compiles them before the first picture).

Each takes flat arrays of the pixels of every top at once, with each pixel's top index, and
fills one row per top: one pass over the pixels, whatever the number of tops.
"""

from __future__ import annotations

import numba
import numpy as np
import numpy.typing as npt

Float64Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int32]


@numba.njit(cache=True, nogil=True)
def extents_at_angles(
    label: IntArray, a: Float64Array, b: Float64Array, angles: Float64Array
) -> Float64Array:
    """For each top and each of its angles (``angles`` is (count, m): each top's own), the
    extents of its points along the two axes turned by that angle: shape (count, m, 4) = (min
    along, max along, min across, max across)."""
    count, n_angles = angles.shape
    out = np.empty((count, n_angles, 4))
    out[:, :, 0] = np.inf
    out[:, :, 1] = -np.inf
    out[:, :, 2] = np.inf
    out[:, :, 3] = -np.inf
    cos = np.cos(angles)
    sin = np.sin(angles)
    for i in range(label.shape[0]):
        k = label[i]
        for j in range(n_angles):
            p = a[i] * cos[k, j] + b[i] * sin[k, j]
            q = b[i] * cos[k, j] - a[i] * sin[k, j]
            row = out[k, j]
            if p < row[0]:
                row[0] = p
            if p > row[1]:
                row[1] = p
            if q < row[2]:
                row[2] = q
            if q > row[3]:
                row[3] = q
    return out


@numba.njit(cache=True, nogil=True)
def extents(label: IntArray, p: Float64Array, q: Float64Array, count: int) -> Float64Array:
    """For each top, (min p, max p, min q, max q) of its points: shape (count, 4)."""
    out = np.empty((count, 4))
    out[:, 0] = np.inf
    out[:, 1] = -np.inf
    out[:, 2] = np.inf
    out[:, 3] = -np.inf
    for i in range(label.shape[0]):
        k = label[i]
        if k < 0:
            continue
        if p[i] < out[k, 0]:
            out[k, 0] = p[i]
        if p[i] > out[k, 1]:
            out[k, 1] = p[i]
        if q[i] < out[k, 2]:
            out[k, 2] = q[i]
        if q[i] > out[k, 3]:
            out[k, 3] = q[i]
    return out


@numba.njit(cache=True, nogil=True)
def grow(
    labels: npt.NDArray[np.int32],
    height: npt.NDArray[np.float32],
    open_: npt.NDArray[np.bool_],
    tolerance: npt.NDArray[np.float32],
    steps: int,
) -> None:
    """Grow every labelled region, in place, over the open pixels next to it whose height is
    within ``tolerance`` (the open pixel's) of the neighbour's it is reached from, at most
    ``steps`` pixels (8-connected, breadth first)."""
    rows, cols = labels.shape
    frontier = np.empty(rows * cols, dtype=np.int64)
    count = 0
    for r in range(rows):
        for c in range(cols):
            if labels[r, c] == 0:
                continue
            edge = False
            for rr in range(max(r - 1, 0), min(r + 2, rows)):
                for cc in range(max(c - 1, 0), min(c + 2, cols)):
                    if labels[rr, cc] == 0 and open_[rr, cc]:
                        edge = True
            if edge:
                frontier[count] = r * cols + c
                count += 1
    following = np.empty(rows * cols, dtype=np.int64)
    for _ in range(steps):
        added = 0
        for i in range(count):
            r, c = divmod(frontier[i], cols)
            label = labels[r, c]
            h = height[r, c]
            for rr in range(max(r - 1, 0), min(r + 2, rows)):
                for cc in range(max(c - 1, 0), min(c + 2, cols)):
                    if labels[rr, cc] != 0 or not open_[rr, cc]:
                        continue
                    if abs(height[rr, cc] - h) < tolerance[rr, cc]:
                        labels[rr, cc] = label
                        following[added] = rr * cols + cc
                        added += 1
        if added == 0:
            break
        frontier, following = following, frontier
        count = added


def warm_up() -> None:
    """Compile (or load from the cache) every kernel on a tiny input."""
    label = np.zeros(2, dtype=np.int32)
    a = np.array([0.0, 1.0])
    extents_at_angles(label, a, a, np.array([[0.0, 0.5]]))
    extents(label, a, a, 1)
    grid = np.zeros((2, 2), dtype=np.int32)
    grid[0, 0] = 1
    flat = np.zeros((2, 2), dtype=np.float32)
    grow(grid, flat, np.ones((2, 2), dtype=np.bool_), flat + 1.0, 1)
