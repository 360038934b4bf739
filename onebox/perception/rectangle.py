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
    hidden_normals: tuple[tuple[float, float], ...] = ()
    """Outward unit normals of the sides that something standing on or in front of the top
    hides: the top may go on under it that way."""

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
    """The direction of one side of the smallest-area rectangle around the points: every
    degree tried, then every twentieth of a degree around the best."""
    if len(points) < 3 or float(np.ptp(points, axis=0).min()) <= 0.0:
        return None
    centred = points - points.mean(axis=0)
    best = 0.0
    for step, span in ((1.0, 90.0), (0.05, 1.0)):
        angles = np.radians(
            best + np.arange(-span / 2, span / 2, step) if span < 90 else np.arange(0.0, 90.0, step)
        )
        directions = np.stack([np.cos(angles), np.sin(angles)])
        along = centred @ directions
        across = centred @ np.stack([-directions[1], directions[0]])
        area = np.ptp(along, axis=0) * np.ptp(across, axis=0)
        best = float(np.degrees(angles[int(area.argmin())]))
    angle = math.radians(best)
    return np.array([math.cos(angle), math.sin(angle)])


def _sides(
    points: Float64Array, axis: Float64Array, band_m: float
) -> tuple[Float64Array, Float64Array, npt.NDArray[np.intp], BoolArray, tuple[float, ...]]:
    """Each point's coordinates along the axis and across it, the nearest of the four sides
    (+x, +y, -x, -y), whether it lies within ``band_m`` of that side (outline pixels around a
    hole lie deeper inside and are no side's), and the middle and half sizes."""
    normal = np.array([-axis[1], axis[0]])
    x = points @ axis
    y = points @ normal
    mx, my = 0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())
    hx, hy = 0.5 * np.ptp(x), 0.5 * np.ptp(y)
    x0, y0 = x - mx, y - my
    gaps = np.stack([hx - x0, hy - y0, hx + x0, hy + y0], axis=1)
    side = gaps.argmin(axis=1)
    near = gaps[np.arange(len(side)), side] < band_m
    return x, y, side, near, (mx, my, hx, hy)


def _refine_axis(
    edge: Float64Array,
    hidden: BoolArray,
    axis: Float64Array,
    footprint_m: float,
    iterations: int = 1,
) -> tuple[Float64Array, list[Float64Array], list[float]]:
    """Refine the axis with a joint fit of the four sides to the visible outline; returns the
    axis, per side (+x, +y, -x, -y) the visible outline points' perpendicular coordinates, and
    per side the share of its outline points that are hidden."""
    band = 4.0 * footprint_m
    use = ~hidden if int(np.count_nonzero(~hidden)) >= 6 else np.ones(len(edge), dtype=bool)
    for _ in range(iterations):
        x, y, side, near, (mx, my, _, _) = _sides(edge, axis, band)
        pick = near & use
        x0, y0, side = x[pick] - mx, y[pick] - my, side[pick]
        # Small-angle model: on the +-x sides x = c_k - theta * y, on the +-y sides
        # y = c_k + theta * x. Unknowns: theta, c_0..c_3.
        counts = np.bincount(side, minlength=4)
        if np.count_nonzero(counts[[0, 2]]) + np.count_nonzero(counts[[1, 3]]) < 3:
            break
        on_x = (side == 0) | (side == 2)
        u = np.where(on_x, -y0, x0)
        target = np.where(on_x, x0, y0)
        # Normal equations of [u, one-hot(side)] by sums per side: no design matrix.
        used = np.flatnonzero(counts)
        su = np.bincount(side, weights=u, minlength=4)[used]
        st = np.bincount(side, weights=target, minlength=4)[used]
        normal_eq = np.zeros((len(used) + 1, len(used) + 1))
        normal_eq[0, 0] = float(u @ u)
        normal_eq[0, 1:] = normal_eq[1:, 0] = su
        normal_eq[1:, 1:] = np.diag(counts[used].astype(np.float64))
        rhs = np.r_[float(u @ target), st]
        try:
            theta = float(np.linalg.solve(normal_eq, rhs)[0])
        except np.linalg.LinAlgError:
            break
        if not math.isfinite(theta) or abs(theta) > 0.2:
            break
        c, s = math.cos(theta), math.sin(theta)
        axis = np.array([c * axis[0] - s * axis[1], s * axis[0] + c * axis[1]])
        if abs(theta) < 1e-7:
            break
    x, y, side, near, _ = _sides(edge, axis, band)
    coords = (x, y, x, y)
    sides = []
    hidden_share = []
    for k in range(4):
        on_k = near & (side == k)
        sides.append(coords[k][on_k & use])
        total = int(np.count_nonzero(on_k))
        hidden_share.append(float(np.count_nonzero(hidden[on_k])) / total if total else 1.0)
    return axis, sides, hidden_share


def fit_rectangle(
    edge: Float64Array,
    hidden: BoolArray,
    footprint_m: float,
    area_m2: float,
    hull_points: BoolArray | None = None,
) -> Rectangle | None:
    """The top's rectangle (see the module docstring) from its outline points alone;
    ``hull_points`` marks a subset holding the outline's convex hull (each row's ends)."""
    if len(edge) < 4:
        return None
    axis = min_area_axis(edge if hull_points is None else edge[hull_points])
    if axis is None:
        return None
    axis, sides, hidden_share = _refine_axis(edge, hidden, axis, footprint_m)
    normal = np.array([-axis[1], axis[0]])
    x_all, y_all = edge @ axis, edge @ normal
    extremes = (x_all.max(), y_all.max(), x_all.min(), y_all.min())
    # A side is fitted from its own visible outline pixels when it has enough of them;
    # otherwise (hidden, or dropped out) the top's farthest pixel along it bounds it.
    expected = (np.ptp(y_all), np.ptp(x_all), np.ptp(y_all), np.ptp(x_all))
    position = []
    hidden_k = []
    for k in range(4):
        values = sides[k]
        enough = len(values) >= 3 and len(values) * footprint_m >= 0.3 * expected[k]
        if enough and hidden_share[k] < 0.5:
            # Trim the few outline points that noise put far inside the edge.
            position.append(float(np.median(values)) if len(values) < 8 else _trimmed(values, k))
        else:
            position.append(float(extremes[k]))
            hidden_k.append(k)
    length0 = position[0] - position[2]
    width0 = position[1] - position[3]
    if not hidden_k and length0 > 0 and width0 > 0:
        total = length0 + width0
        margin = 0.5 * (
            -total + math.sqrt(max(total * total - 4 * (length0 * width0 - area_m2), 0))
        )
        margin = min(max(margin, 0.0), 2.0 * footprint_m)
    else:
        margin = footprint_m
    length, width = length0 + margin, width0 + margin
    mx, my = 0.5 * (position[0] + position[2]), 0.5 * (position[1] + position[3])
    middle = mx * axis + my * normal
    outward = (axis, normal, -axis, -normal)
    hidden_normals = tuple((float(outward[k][0]), float(outward[k][1])) for k in hidden_k)
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
        hidden_sides=len(hidden_k),
        area_m2=area_m2,
        hidden_normals=hidden_normals,
    )


def _trimmed(values: Float64Array, side: int) -> float:
    """The mean of a side's outline coordinates, leaving out the innermost fifth (noise and
    pixels at the corners that belong to the next side)."""
    ordered = np.sort(values)
    cut = len(ordered) // 5
    kept = ordered[cut:] if side < 2 else ordered[: len(ordered) - cut]
    return float(kept.mean())


def _group_extent(
    values: Float64Array, starts: npt.NDArray[np.intp]
) -> tuple[Float64Array, Float64Array]:
    """Per group (contiguous runs starting at ``starts``, none empty) the least and greatest
    value, along the first axis."""
    low: Float64Array = np.minimum.reduceat(values, starts, axis=0)
    high: Float64Array = np.maximum.reduceat(values, starts, axis=0)
    return low, high


def fit_rectangles(
    edge: Float64Array,
    group: npt.NDArray[np.intp],
    hidden: BoolArray,
    hull_points: BoolArray,
    footprint_m: Float64Array,
    area_m2: Float64Array,
) -> list[Rectangle | None]:
    """:func:`fit_rectangle` for many tops at once: ``edge`` holds every top's outline points,
    grouped (``group`` ascending, 0..G-1, each top's points together), ``hull_points`` marks
    each top's row ends; one rectangle (or None, too few points) per group."""
    count = len(footprint_m)
    sizes = np.bincount(group, minlength=count)
    hull_sizes = np.bincount(group[hull_points], minlength=count)
    result: list[Rectangle | None] = [None] * count
    ok = (sizes >= 4) & (hull_sizes >= 3)
    if not ok.any():
        return result
    keep = ok[group]
    edge, group, hidden, hull_points = edge[keep], group[keep], hidden[keep], hull_points[keep]
    ids = np.flatnonzero(ok)
    remap = np.full(count, -1)
    remap[ids] = np.arange(len(ids))
    g = remap[group]
    n_groups = len(ids)
    footprint, area = footprint_m[ids], area_m2[ids]
    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    centre = (
        np.stack([np.bincount(g, weights=edge[:, k], minlength=n_groups) for k in range(2)], axis=1)
        / np.bincount(g, minlength=n_groups)[:, np.newaxis]
    )
    local = edge - centre[g]
    # The smallest-area rectangle around each hull: every degree, then every 20th of one.
    hull, hull_g = local[hull_points], g[hull_points]
    hull_starts = np.flatnonzero(np.r_[True, hull_g[1:] != hull_g[:-1]])
    best = np.zeros(n_groups)
    for steps in (np.arange(0.0, 90.0, 2.0), np.arange(-1.0, 1.0, 0.1)):
        angles = np.radians(best[:, np.newaxis] + steps[np.newaxis, :])  # groups x angles
        cos, sin = np.cos(angles)[hull_g], np.sin(angles)[hull_g]
        along = hull[:, :1] * cos + hull[:, 1:] * sin
        across = hull[:, 1:] * cos - hull[:, :1] * sin
        lo_a, hi_a = _group_extent(along, hull_starts)
        lo_c, hi_c = _group_extent(across, hull_starts)
        pick = ((hi_a - lo_a) * (hi_c - lo_c)).argmin(axis=1)
        best = np.degrees(angles[np.arange(n_groups), pick])
    theta = np.radians(best)
    band = 4.0 * footprint
    visible = ~hidden
    few_visible = np.bincount(g[visible], minlength=n_groups) < 6
    use = visible | few_visible[g]
    # One joint least-squares step of the four sides (small angle, offsets eliminated).
    x, y, side, near, mid = _all_sides(local, g, starts, theta, band)
    pick = near & use
    on_x = (side == 0) | (side == 2)
    x0, y0 = x - mid[0][g], y - mid[1][g]
    u = np.where(on_x, -y0, x0)
    t = np.where(on_x, x0, y0)
    key = g * 4 + side
    n_k = np.bincount(key[pick], minlength=4 * n_groups).reshape(n_groups, 4)
    su = np.bincount(key[pick], weights=u[pick], minlength=4 * n_groups).reshape(n_groups, 4)
    st = np.bincount(key[pick], weights=t[pick], minlength=4 * n_groups).reshape(n_groups, 4)
    suu = np.bincount(g[pick], weights=u[pick] * u[pick], minlength=n_groups)
    sut = np.bincount(g[pick], weights=u[pick] * t[pick], minlength=n_groups)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(n_k > 0, 1.0 / np.maximum(n_k, 1), 0.0)
        denominator = suu - (su * su * inv).sum(axis=1)
        step = (sut - (su * st * inv).sum(axis=1)) / denominator
    sides_seen = (n_k[:, [0, 2]] > 0).sum(axis=1) + (n_k[:, [1, 3]] > 0).sum(axis=1)
    good = np.isfinite(step) & (np.abs(step) <= 0.2) & (sides_seen >= 3) & (denominator > 0)
    theta = theta + np.where(good, step, 0.0)
    x, y, side, near, mid = _all_sides(local, g, starts, theta, band)
    # Each side's position: the trimmed mean of its visible outline points, outermost 80 %.
    sign = np.where(side < 2, 1.0, -1.0)
    coord = np.where((side == 0) | (side == 2), x, y)
    pick = near & use
    key_all = g * 4 + side
    seen_n = np.bincount(key_all[pick], minlength=4 * n_groups)
    near_n = np.bincount(key_all[near], minlength=4 * n_groups)
    hidden_n = np.bincount(key_all[near & hidden], minlength=4 * n_groups)
    order = np.lexsort(((sign * coord)[pick], key_all[pick]))
    keys_sorted = key_all[pick][order]
    values_sorted = coord[pick][order]
    first = np.searchsorted(keys_sorted, np.arange(4 * n_groups))
    rank = np.arange(len(keys_sorted)) - first[keys_sorted]
    total = seen_n[keys_sorted]
    trimmed = (rank >= total // 5) | (total < 8)
    position = np.bincount(
        keys_sorted[trimmed], weights=values_sorted[trimmed], minlength=4 * n_groups
    ) / np.maximum(np.bincount(keys_sorted[trimmed], minlength=4 * n_groups), 1)
    lo_x, hi_x = _group_extent(x, starts)
    lo_y, hi_y = _group_extent(y, starts)
    extremes = np.stack([hi_x, hi_y, lo_x, lo_y], axis=1).reshape(-1)
    expected = np.stack([hi_y - lo_y, hi_x - lo_x] * 2, axis=1).reshape(-1)
    share = hidden_n / np.maximum(near_n, 1)
    share[near_n == 0] = 1.0
    enough = (seen_n >= 3) & (seen_n * np.repeat(footprint, 4) >= 0.3 * expected)
    fitted = enough & (share < 0.5)
    position = np.where(fitted, position, extremes).reshape(n_groups, 4)
    hidden_side = ~fitted.reshape(n_groups, 4)
    for i, top in enumerate(ids):
        result[top] = _rectangle(
            position[i],
            hidden_side[i],
            float(theta[i]),
            centre[i],
            float(footprint[i]),
            float(area[i]),
        )
    return result


def _all_sides(
    local: Float64Array,
    g: npt.NDArray[np.intp],
    starts: npt.NDArray[np.intp],
    theta: Float64Array,
    band: Float64Array,
) -> tuple[
    Float64Array, Float64Array, npt.NDArray[np.intp], BoolArray, tuple[Float64Array, Float64Array]
]:
    """:func:`_sides` for every group at once, each along its own angle."""
    cos, sin = np.cos(theta)[g], np.sin(theta)[g]
    x = local[:, 0] * cos + local[:, 1] * sin
    y = local[:, 1] * cos - local[:, 0] * sin
    lo_x, hi_x = _group_extent(x, starts)
    lo_y, hi_y = _group_extent(y, starts)
    mx, my = 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y)
    hx, hy = 0.5 * (hi_x - lo_x), 0.5 * (hi_y - lo_y)
    x0, y0 = x - mx[g], y - my[g]
    gaps = np.stack([hx[g] - x0, hy[g] - y0, hx[g] + x0, hy[g] + y0], axis=1)
    side = gaps.argmin(axis=1)
    near = gaps[np.arange(len(side)), side] < band[g]
    return x, y, side, near, (mx, my)


def _rectangle(
    position: Float64Array,
    hidden_side: BoolArray,
    theta: float,
    centre: Float64Array,
    footprint_m: float,
    area_m2: float,
) -> Rectangle | None:
    """The rectangle from its four side positions (+x, +y, -x, -y along the angle)."""
    axis = np.array([math.cos(theta), math.sin(theta)])
    normal = np.array([-axis[1], axis[0]])
    length0 = float(position[0] - position[2])
    width0 = float(position[1] - position[3])
    if length0 <= 0 or width0 <= 0:
        return None
    hidden_k = [k for k in range(4) if hidden_side[k]]
    if not hidden_k:
        total = length0 + width0
        margin = 0.5 * (
            -total + math.sqrt(max(total * total - 4 * (length0 * width0 - area_m2), 0))
        )
        margin = min(max(margin, 0.0), 2.0 * footprint_m)
    else:
        margin = footprint_m
    length, width = length0 + margin, width0 + margin
    middle = centre + 0.5 * (position[0] + position[2]) * axis
    middle = middle + 0.5 * (position[1] + position[3]) * normal
    outward = (axis, normal, -axis, -normal)
    hidden_normals = tuple((float(outward[k][0]), float(outward[k][1])) for k in hidden_k)
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
        hidden_sides=len(hidden_k),
        area_m2=area_m2,
        hidden_normals=hidden_normals,
    )
