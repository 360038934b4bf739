"""The rectangle around a box's top: orientation, sides and a footprint-corrected size.

Contract: :func:`fit_rectangles` takes every top's outline points as 2-D points in the
support plane (metres), grouped by top, with what lies past each point (hidden: the surface
rises; drop: it falls; unsure: no reading), each top's row ends (a superset of its hull), its
pixel footprint and its area (holes filled), and returns one :class:`Rectangle` (or None)
per top. All tops are fitted together, whole-array.

- The smallest-area rectangle around each top's row ends: every 2 degrees, then every 0.1
  around the best; one joint least-squares step of the four sides (one shared small angle,
  the four offsets eliminated in closed form) refines it below the pixel grid's staircase.
- Each side's position is the trimmed mean (outermost 80 %) of its visible outline points
  within four footprints of the side. A side mostly hidden, or with too few points, is
  bounded by the farthest pixel instead.
- Outline pixel centres lie inside the true edge by between 0 and one pixel footprint. When
  all four sides are fitted, the margin that makes the rectangle's area equal the top's
  area (an unbiased estimate) is added (clamped to 0..2 footprints); otherwise one footprint.
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
    edge_normals: tuple[tuple[float, float], ...] = ()
    """Outward unit normals of the sides past which the surface is seen dropping: real edges."""
    dropout_normals: tuple[tuple[float, float], ...] = ()
    """Outward unit normals of the sides with no readings past many of their pixels (an
    edge's dropout, which may eat a pixel or two of the top)."""

    def half_extent(self, d0: float, d1: float) -> float:
        """Half the rectangle's extent along the unit direction (d0, d1)."""
        a0, a1 = self.axis
        return 0.5 * (
            abs(self.length_m * (a0 * d0 + a1 * d1)) + abs(self.width_m * (a1 * d0 - a0 * d1))
        )

    @property
    def corners(self) -> Float64Array:
        ax = np.asarray(self.axis)
        across = np.array([-ax[1], ax[0]])
        m = np.asarray(self.middle)
        hl, hw = self.length_m / 2, self.width_m / 2
        return np.array(
            [m + s * hl * ax + t * hw * across for s, t in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        )


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
    group: npt.NDArray[np.integer],
    hidden: BoolArray,
    hull_points: BoolArray,
    unsure: BoolArray,
    drop: BoolArray,
    footprint_m: Float64Array,
    area_m2: Float64Array,
) -> list[Rectangle | None]:
    """:func:`fit_rectangle` for many tops at once: ``edge`` holds every top's outline points,
        grouped (``group`` ascending, 0..G-1, each top's points together), ``hull_points`` marks
        each top's row ends, ``unsure`` the outline points with no reading past them (the edge
    lies farther: left out of the sides' fit); one rectangle (or None, too few points) per
    group."""
    count = len(footprint_m)
    sizes = np.bincount(group, minlength=count)
    hull_sizes = np.bincount(group[hull_points], minlength=count)
    result: list[Rectangle | None] = [None] * count
    ok = (sizes >= 4) & (hull_sizes >= 3)
    if not ok.any():
        return result
    keep = ok[group]
    edge, group, hidden, hull_points = edge[keep], group[keep], hidden[keep], hull_points[keep]
    unsure, drop = unsure[keep], drop[keep]
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
    best = np.zeros(n_groups)
    # Every 2 degrees, then every 0.1 around the best (a stride > 1 thins the points).
    for stride, steps in ((1, np.arange(0.0, 90.0, 2.0)), (1, np.arange(-1.0, 1.0, 0.1))):
        pts, pts_g = hull[::stride], hull_g[::stride]
        present = np.bincount(pts_g, minlength=n_groups) > 0
        if not present.all():
            pts, pts_g = hull, hull_g
        starts_h = np.flatnonzero(np.r_[True, pts_g[1:] != pts_g[:-1]])
        angles = np.radians(best[:, np.newaxis] + steps[np.newaxis, :])  # groups x angles
        cos, sin = np.cos(angles)[pts_g], np.sin(angles)[pts_g]
        along = pts[:, :1] * cos + pts[:, 1:] * sin
        across = pts[:, 1:] * cos - pts[:, :1] * sin
        lo_a, hi_a = _group_extent(along, starts_h)
        lo_c, hi_c = _group_extent(across, starts_h)
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
    drop_n = np.bincount(key_all[near & drop], minlength=4 * n_groups)
    unsure_n = np.bincount(key_all[near & unsure], minlength=4 * n_groups)
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
    hidden_side = share >= 0.5
    fitted = enough & ~hidden_side
    position = np.where(fitted, position, extremes).reshape(n_groups, 4)
    hidden_side = hidden_side.reshape(n_groups, 4)
    fitted = fitted.reshape(n_groups, 4)
    real = (drop_n >= 0.25 * np.maximum(near_n, 1)).reshape(n_groups, 4)
    eaten = (unsure_n >= 0.3 * np.maximum(near_n, 1)).reshape(n_groups, 4)
    for i, top in enumerate(ids):
        result[top] = _rectangle(
            position[i],
            hidden_side[i],
            fitted[i],
            real[i],
            eaten[i],
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
    fitted: BoolArray,
    real: BoolArray,
    eaten: BoolArray,
    theta: float,
    centre: Float64Array,
    footprint_m: float,
    area_m2: float,
) -> Rectangle | None:
    """The rectangle from its four side positions (+x, +y, -x, -y along the angle): fitted
    sides, or the farthest pixel centres (then half a footprint lies beyond each)."""
    axis = np.array([math.cos(theta), math.sin(theta)])
    normal = np.array([-axis[1], axis[0]])
    length0 = float(position[0] - position[2])
    width0 = float(position[1] - position[3])
    if length0 <= 0 or width0 <= 0:
        return None
    hidden_k = [k for k in range(4) if hidden_side[k]]
    if fitted.all():
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

    def normals(pick: list[int]) -> tuple[tuple[float, float], ...]:
        return tuple((float(outward[k][0]), float(outward[k][1])) for k in pick)

    hidden_normals = normals(hidden_k)
    edge_normals = normals([k for k in range(4) if real[k]])
    dropout_normals = normals([k for k in range(4) if eaten[k]])
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
        edge_normals=edge_normals,
        dropout_normals=dropout_normals,
    )
