"""The rectangle around a box's top: orientation, sides and a footprint-corrected size.

Contract: :func:`fit_rectangle` takes the top's pixel centres as 2-D points in the support
plane (metres), which of them lie on the top's outline (and which of those are hidden edges,
where something nearer occludes the top), each pixel's footprint area on the top (and
optionally the top's whole area, when something standing on it hides part) and returns a
:class:`Rectangle`, or None for fewer than three distinct points.

- The smallest-area rectangle around the outline's convex hull (rotating calipers) gives a
  first orientation; a joint least-squares fit of the four sides (two directions at right
  angles, one shared angle) to the visible outline pixels refines it well below the pixel
  grid's staircase.
- Outline pixel centres lie inside the true edge by between 0 and one pixel footprint,
  depending on the edge's angle to the pixel grid and on noise eating the edge. The summed
  pixel footprints are an unbiased estimate of the top's true area, so the margin that makes
  the rectangle's area equal it is added to both sides (clamped to 0..2 footprints). When a
  side is hidden the area says nothing and one footprint is added instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial import ConvexHull, QhullError

Float64Array = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Rectangle:
    """A rectangle in the plane: middle, unit axis of the length, length >= width, metres."""

    middle: tuple[float, float]
    axis: tuple[float, float]
    length_m: float
    width_m: float
    hidden_sides: int
    area_m2: float

    @property
    def corners(self) -> Float64Array:
        ax = np.asarray(self.axis)
        across = np.array([-ax[1], ax[0]])
        m = np.asarray(self.middle)
        hl, hw = self.length_m / 2, self.width_m / 2
        return np.array(
            [m + s * hl * ax + t * hw * across for s, t in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        )


def min_area_axis(points: Float64Array) -> Float64Array | None:
    """The direction of one side of the smallest-area rectangle around the points."""
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return None
    ring = points[hull.vertices]
    edges = np.roll(ring, -1, axis=0) - ring
    length = np.linalg.norm(edges, axis=1)
    keep = length > 1e-12
    axes = edges[keep] / length[keep, np.newaxis]
    normals = np.stack([-axes[:, 1], axes[:, 0]], axis=1)
    along = ring @ axes.T
    across = ring @ normals.T
    area = np.ptp(along, axis=0) * np.ptp(across, axis=0)
    result: Float64Array = axes[int(area.argmin())]
    return result


def _refine_axis(
    points: Float64Array, axis: Float64Array, iterations: int = 2
) -> tuple[Float64Array, list[Float64Array]]:
    """Refine the axis with a joint fit of the four sides; returns the axis and, per side (+x,
    +y, -x, -y), the outline points' perpendicular coordinates."""
    for _ in range(iterations):
        normal = np.array([-axis[1], axis[0]])
        x = points @ axis
        y = points @ normal
        mx, my = 0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())
        hx, hy = 0.5 * np.ptp(x), 0.5 * np.ptp(y)
        x0, y0 = x - mx, y - my
        # Which side each outline point belongs to: the nearest of the four.
        gaps = np.stack([hx - x0, hy - y0, hx + x0, hy + y0], axis=1)
        side = gaps.argmin(axis=1)
        # Small-angle model: on the +-x sides x = c_k - theta * y, on the +-y sides
        # y = c_k + theta * x. Unknowns: theta, c_0..c_3.
        rows = len(points)
        design = np.zeros((rows, 5))
        target = np.empty(rows)
        on_x = (side == 0) | (side == 2)
        design[on_x, 0] = -y0[on_x]
        target[on_x] = x0[on_x]
        design[~on_x, 0] = x0[~on_x]
        target[~on_x] = y0[~on_x]
        design[np.arange(rows), 1 + side] = 1.0
        counts = np.bincount(side, minlength=4)
        if np.count_nonzero(counts[[0, 2]]) + np.count_nonzero(counts[[1, 3]]) < 3:
            break
        used = counts > 0
        solution, *_ = np.linalg.lstsq(design[:, np.r_[True, used]], target, rcond=None)
        theta = float(solution[0])
        if not math.isfinite(theta) or abs(theta) > 0.2:
            break
        c, s = math.cos(theta), math.sin(theta)
        axis = np.array([c * axis[0] - s * axis[1], s * axis[0] + c * axis[1]])
        if abs(theta) < 1e-7:
            break
    normal = np.array([-axis[1], axis[0]])
    x, y = points @ axis, points @ normal
    mx, my = 0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())
    hx, hy = 0.5 * np.ptp(x), 0.5 * np.ptp(y)
    gaps = np.stack([hx - (x - mx), hy - (y - my), hx + (x - mx), hy + (y - my)], axis=1)
    side = gaps.argmin(axis=1)
    coords = [x, y, x, y]
    return axis, [coords[k][side == k] for k in range(4)]


def fit_rectangle(
    points: Float64Array,
    outline: BoolArray,
    hidden: BoolArray,
    pixel_area_m2: Float64Array,
    area_m2: float | None = None,
) -> Rectangle | None:
    """The top's rectangle (see the module docstring)."""
    edge = points[outline]
    if len(edge) < 4:
        return None
    axis = min_area_axis(edge)
    if axis is None:
        return None
    seen = outline & ~hidden
    fit_points = points[seen] if seen.sum() >= 6 else edge
    axis, sides = _refine_axis(fit_points, axis)
    normal = np.array([-axis[1], axis[0]])
    x_all, y_all = points @ axis, points @ normal
    extremes = (x_all.max(), y_all.max(), x_all.min(), y_all.min())
    # A side is fitted from its own visible outline pixels when it has enough of them;
    # otherwise (hidden, or dropped out) the top's farthest pixel along it bounds it.
    expected = (np.ptp(y_all), np.ptp(x_all), np.ptp(y_all), np.ptp(x_all))
    footprint = math.sqrt(float(np.median(pixel_area_m2)))
    position = []
    hidden_sides = 0
    for k in range(4):
        values = sides[k]
        enough = len(values) >= 3 and len(values) * footprint >= 0.3 * expected[k]
        if enough:
            # Trim the few outline points that noise put far inside the edge.
            position.append(float(np.median(values)) if len(values) < 8 else _trimmed(values, k))
        else:
            position.append(float(extremes[k]))
            hidden_sides += 1
    length0 = position[0] - position[2]
    width0 = position[1] - position[3]
    area = float(pixel_area_m2.sum()) if area_m2 is None else area_m2
    if hidden_sides == 0 and length0 > 0 and width0 > 0:
        total = length0 + width0
        margin = 0.5 * (-total + math.sqrt(max(total * total - 4 * (length0 * width0 - area), 0)))
        margin = min(max(margin, 0.0), 2.0 * footprint)
    else:
        margin = footprint
    length, width = length0 + margin, width0 + margin
    mx, my = 0.5 * (position[0] + position[2]), 0.5 * (position[1] + position[3])
    middle = mx * axis + my * normal
    if width > length:
        length, width = width, length
        axis = normal
    if axis[0] < 0 or (axis[0] == 0 and axis[1] < 0):
        axis = -axis
    return Rectangle(
        middle=(float(middle[0]), float(middle[1])),
        axis=(float(axis[0]), float(axis[1])),
        length_m=float(length),
        width_m=float(width),
        hidden_sides=hidden_sides,
        area_m2=area,
    )


def _trimmed(values: Float64Array, side: int) -> float:
    """The mean of a side's outline coordinates, leaving out the innermost fifth (noise and
    pixels at the corners that belong to the next side)."""
    ordered = np.sort(values)
    cut = len(ordered) // 5
    kept = ordered[cut:] if side < 2 else ordered[: len(ordered) - cut]
    return float(kept.mean())
