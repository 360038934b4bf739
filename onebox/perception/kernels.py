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
    label: IntArray, a: Float64Array, b: Float64Array, count: int, angles: Float64Array
) -> Float64Array:
    """For each top and each angle, the extents of its points along the two axes turned by
    that angle: shape (count, len(angles), 4) = (min along, max along, min across, max
    across)."""
    n_angles = angles.shape[0]
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
            p = a[i] * cos[j] + b[i] * sin[j]
            q = b[i] * cos[j] - a[i] * sin[j]
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


def warm_up() -> None:
    """Compile (or load from the cache) every kernel on a tiny input."""
    label = np.zeros(2, dtype=np.int32)
    a = np.array([0.0, 1.0])
    extents_at_angles(label, a, a, 1, np.array([0.0, 0.5]))
    extents(label, a, a, 1)
