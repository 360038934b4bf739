"""Where a box's side faces end: how high a box's bottom is, seen from the side.

Contract: :func:`face_bottoms` takes each box's top (its rectangle in the support plane and
its height), the depth picture (H x W metres; NaN, 0 and below are no reading), the lens,
the plane's basis in the optical frame (rows e1, e2, n) and the camera's height above the
plane, and returns for each box the height above the plane at which its side faces end, or
None where the picture cannot say. No I/O.

A box's top says nothing of what it stands on; its sides do. A box standing on the surface
shows a face from its top down to the surface on every side that faces the camera. A box
standing on a narrower box overhangs it: below the box's bottom the camera looks past the
face's plane, under the box. Along lines down each face that the camera sees, each point of
the face is looked up in the picture and the surface seen there sorted by where it lies
across the face's plane: on it (the face is there), beyond it (the face has ended: the camera
sees under the box) or before it (something in front hides the face: no answer). A line's
bottom is where, going down, the first two points beyond come after at least two on the face.
A box is solid down to its bottom, so its bottom is the highest one that two lines agree on,
on any side: where a side runs flush with the box under it, the face goes on down, seen as
one, and says nothing. None when no two lines see the face end above the surface.
"""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics

Float64Array = npt.NDArray[np.float64]

LINES = np.linspace(-0.35, 0.35, 5)
"""Where the lines run down each side, as shares of the side's length from its middle."""
SAMPLES = 48
"""Points down each line, from just under the top to the surface."""
MIN_FACE_PX = 6.0
"""A face that spans fewer pixels from top to bottom than this (seen edge-on) says nothing."""


def face_bottoms(
    middles: Float64Array,
    axes: Float64Array,
    halves: Float64Array,
    tops_m: Float64Array,
    tolerances_m: Float64Array,
    depth_m: npt.NDArray[np.floating],
    lens: Intrinsics,
    basis: Float64Array,
    camera_height_m: float,
) -> list[float | None]:
    """Each box's bottom as its faces show it (see the module docstring).

    ``middles`` (N x 2), ``axes`` (N x 2, unit, the length's) and ``halves`` (N x 2: half the
    length and half the width) are the tops' rectangles in plane coordinates (a = e1 . p,
    b = e2 . p); ``tops_m`` their heights; ``tolerances_m`` (N) how far across a face's plane
    a reading may lie and still be on it.
    """
    n_boxes = len(tops_m)
    if n_boxes == 0:
        return []
    rows_n, cols_n = depth_m.shape
    ax = axes
    perp = np.stack([-ax[:, 1], ax[:, 0]], axis=1)
    # Sides: outward normal, direction along the side, half extent out and along.
    out = np.stack([ax, -ax, perp, -perp], axis=1)  # N x 4 x 2
    along = np.stack([perp, perp, ax, ax], axis=1)
    half_out = np.stack([halves[:, 0], halves[:, 0], halves[:, 1], halves[:, 1]], axis=1)
    half_along = np.stack([halves[:, 1], halves[:, 1], halves[:, 0], halves[:, 0]], axis=1)
    edge_mid = middles[:, np.newaxis, :] + out * half_out[..., np.newaxis]  # N x 4 x 2
    # The camera stands over the plane's origin: a side faces it when the origin lies out past
    # the side's line.
    facing = np.einsum("nsk,nsk->ns", -edge_mid, out) > 0.0
    # Points on each face: N x 4 sides x lines x samples, in plane coordinates and height.
    feet = (
        edge_mid[:, :, np.newaxis, :]
        + LINES[np.newaxis, np.newaxis, :, np.newaxis]
        * (2 * half_along[..., np.newaxis, np.newaxis])
        * along[:, :, np.newaxis, :]
    )  # N x 4 x L x 2
    share = np.linspace(0.97, 0.0, SAMPLES)  # just under the top, down to the surface
    heights = tops_m[:, np.newaxis] * share[np.newaxis, :]  # N x S
    e1, e2, normal = basis
    xyz = (
        feet[..., np.newaxis, 0:1] * e1
        + feet[..., np.newaxis, 1:2] * e2
        + (heights[:, np.newaxis, np.newaxis, :, np.newaxis] - camera_height_m) * normal
    )  # N x 4 x L x S x 3
    z = xyz[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = lens.fx * xyz[..., 0] / z + lens.cx
        v = lens.fy * xyz[..., 1] / z + lens.cy
    ui, vi = np.rint(u), np.rint(v)
    inside = (z > 0) & (ui >= 0) & (ui < cols_n) & (vi >= 0) & (vi < rows_n)
    # The face's extent in pixels, top to bottom, along each line.
    span_px = np.hypot(u[..., 0] - u[..., -1], v[..., 0] - v[..., -1])
    ui = np.where(inside, ui, 0).astype(np.intp)
    vi = np.where(inside, vi, 0).astype(np.intp)
    d = np.asarray(depth_m, dtype=np.float64)[vi, ui]
    with np.errstate(invalid="ignore"):
        seen = inside & np.isfinite(d) & (d > 0)
    across_r, down_r = lens.rays(cols_n, rows_n)
    seen_xyz = np.stack([across_r[ui] * d, down_r[vi] * d, d], axis=-1)
    seen_a = seen_xyz @ e1
    seen_b = seen_xyz @ e2
    # How far out past the face's plane the surface seen at each point lies.
    offset = (seen_a - edge_mid[:, :, np.newaxis, np.newaxis, 0]) * out[
        :, :, np.newaxis, np.newaxis, 0
    ] + (seen_b - edge_mid[:, :, np.newaxis, np.newaxis, 1]) * out[:, :, np.newaxis, np.newaxis, 1]
    tol = tolerances_m[:, np.newaxis, np.newaxis, np.newaxis]
    on = seen & (np.abs(offset) <= tol)
    beyond = seen & (offset < -tol)
    step = np.array([resolution_m(float(t)) for t in tops_m])
    result: list[float | None] = []
    for i in range(n_boxes):
        ends: list[tuple[float, float]] = []
        for k in np.flatnonzero(facing[i]):
            for line in np.flatnonzero(span_px[i, k] >= MIN_FACE_PX):
                bottom = _line_bottom(on[i, k, line], beyond[i, k, line], heights[i])
                if bottom is not None:
                    ends.append((bottom, float(span_px[i, k, line])))
        result.append(_agreed(ends, 2.0 * step[i] + float(tolerances_m[i])))
    return result


def resolution_m(top_m: float) -> float:
    """How far apart the points down a face of a top this high lie."""
    return top_m * 0.97 / (SAMPLES - 1)


def _agreed(ends: list[tuple[float, float]], within_m: float) -> float | None:
    """The highest bottom two lines agree on (None when no two do): the lines within
    ``within_m`` of that pair, weighted by how many pixels their face spans (a face seen at a
    slant puts more of its height in each pixel)."""
    ends = sorted(ends, reverse=True)
    for (first, _), (second, _) in itertools.pairwise(ends):
        if first - second <= within_m:
            middle = 0.5 * (first + second)
            near = np.array([(e, px) for e, px in ends if abs(e - middle) <= within_m])
            weights = near[:, 1] ** 2
            return float(near[:, 0] @ weights / weights.sum())
    return None


def _line_bottom(
    on: npt.NDArray[np.bool_], beyond: npt.NDArray[np.bool_], heights: Float64Array
) -> float | None:
    """Going down one line: the height between the last point on the face and the first of
    two beyond it, after two on it; None when the face does not end so (or is not seen)."""
    pair = beyond[:-1] & beyond[1:]
    starts = np.flatnonzero(pair & (np.cumsum(on)[:-1] >= 2))
    if not len(starts):
        return None
    k = int(starts[0])
    last_on = np.flatnonzero(on[:k])
    return float(0.5 * (heights[last_on[-1]] + heights[k]))
