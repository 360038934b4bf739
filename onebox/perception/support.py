"""The surface the boxes stand on: a robust plane fit to a depth picture.

Contract: :func:`fit_support` takes a depth picture (float32 metres; NaN, 0, negative and inf
are no reading), the lens and, when known, the camera's pose (optical frame -> world, 4 x 4),
and returns the :class:`Support` plane or None when no plane holds enough readings.

How:

- A grid sample of at most ``SAMPLE_POINTS`` readings becomes optical-frame points.
- RANSAC (every hypothesis's votes counted in one compiled pass) with an inlier threshold
  that grows with distance like stereo noise (sigma ~ z^2); then least squares on the
  inliers, the noise estimated from their residuals (MAD), the inliers taken again at 3
  sigma(z) and refitted; how wide the noise's lumps are, from how alike neighbours' residuals
  are (:func:`lump_width`).
- With a pose only planes within ``max_tilt_deg`` of world up count; without one the largest
  plane sets "up". Up to three planes are found in turn; among those holding at least
  ``MIN_SHARE`` of the readings and facing the same way the LOWEST is the support (the floor
  under a pallet, the table under the boxes; carton tops are never the support even when they
  are the largest plane). When no plane through three readings holds that share (the floor
  round a bin seen from close over it, which few triples fall on), the support is about level:
  the lowest height that share of the readings holds, along the pose's up or, without a pose,
  the way most small patches of the picture face, is fitted instead. What stands on a higher
  plateau (a pallet, a table seen with the floor around it) is measured from that plateau by
  the box finder, not from the support.
- ``table_z_m`` skips the fit: the support is the world plane z = table_z.

The plane is ``normal . p + offset_m = 0`` with the normal pointing up, toward the camera, so
``normal . p + offset_m`` is a point's height above the surface.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import kernels

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

SAMPLE_POINTS = 2400
"""Readings the plane is fitted on: enough for a 0.1 % share to hold a couple of points."""
HYPOTHESES = 64
"""RANSAC planes tried per round; with half the readings on the plane, P(miss) ~ 1e-4."""
FAR_SHARE = 4.0
"""Readings farther than this many times the median distance are strays, not the support."""
MIN_SHARE = 0.10
"""A plane holding less than this share of the readings is not a support candidate."""
LEVEL_WIDEN = 4.0
"""When no plane through three readings holds that share, the lowest level height is looked
for in a band this many times theirs first ("up" may lean by a degree or two)..."""
FACING_PATCHES = 600
"""...and without a pose "up" is the way most of this many small patches face..."""
PATCH_CELLS = 3
"""...each three readings within this many cells of the sample's grid of one another..."""
FACING_DEG = 10.0
"""...averaged over the patches within this angle of the most common way."""
MAX_LUMP_PX = 8.0
"""The widest lumps measured: past this a plane's residuals tell little more (a wave, a
quantisation step held flat over many pixels)."""
SIGMA_FLOOR_M = 0.0002
"""The least noise assumed (float32 depth at a metre is good to ~0.1 micrometre; a renderer's
depth to ~0.1 mm): thresholds never shrink below a few tenths of a millimetre."""


@dataclass(frozen=True)
class Support:
    """The plane the boxes stand on: ``normal . p + offset_m = 0`` in ``frame``.

    ``normal`` is unit length and points up, toward the camera; ``normal . p + offset_m`` is a
    point's height above the plane. ``tilt_deg`` is the angle between the normal and world up
    (None without a pose). ``sigma_m`` is the depth noise at ``distance_m`` (the median
    distance of the plane's readings); noise elsewhere is taken to grow as distance squared.
    ``normal_camera`` and ``offset_camera_m`` are the same plane in the optical frame.
    ``lump_px`` says how far apart readings still err together.
    """

    normal: tuple[float, float, float]
    offset_m: float
    inlier_share: float
    tilt_deg: float | None
    frame: str
    sigma_m: float = SIGMA_FLOOR_M
    distance_m: float = 1.0
    normal_camera: tuple[float, float, float] = (0.0, 0.0, -1.0)
    offset_camera_m: float = 1.0
    lump_px: float = 0.0
    """How many pixels wide the depth errors' lumps are (0: every pixel errs on its own): the
    width of the Gaussian that makes the plane's residuals as alike between neighbours as they
    are (:func:`lump_width`). A stereo camera's matching window and depth filters make lumps."""

    def sigma_at(self, depth_m: npt.NDArray[np.floating] | float) -> npt.NDArray[np.float32]:
        """The depth noise expected at these distances, metres (never below the floor)."""
        ratio = np.asarray(depth_m, dtype=np.float32) * np.float32(1.0 / self.distance_m)
        result: npt.NDArray[np.float32] = np.maximum(
            np.float32(self.sigma_m) * ratio * ratio, np.float32(SIGMA_FLOOR_M)
        )
        return result


def median(values: npt.NDArray[np.floating]) -> float:
    """``np.median`` of values with no NaN among them, without its generality's overhead (the
    mean of the middle two in the values' own precision, as ``np.median`` gives it)."""
    half = values.size // 2
    if values.size % 2:
        return float(np.partition(values, half)[half])
    part = np.partition(values, (half - 1, half))
    return float((part[half - 1] + part[half]) / 2)


def _sample(depth_m: Float32Array, lens: Intrinsics) -> tuple[Float64Array, IntArray]:
    """Optical-frame points of a grid sample of readings, and their flat pixel indices."""
    height, width = depth_m.shape
    stride = max(1, int(math.sqrt(height * width / SAMPLE_POINTS)))
    across, down = lens.rays(width, height)
    return kernels.grid_sample(
        np.ascontiguousarray(depth_m, dtype=np.float32), stride, across, down
    )


def _initial_threshold(
    d: Float64Array, sigma_m: float | None, quantum_m2: float = 0.0
) -> Float64Array:
    if sigma_m is not None:
        return np.full(d.shape, max(3.0 * sigma_m, 0.001))
    # Unknown noise: generous enough for a stereo camera at 2 m, tight enough at 0.4 m that a
    # 1 cm box is not on the plane; never less than one and a half depth steps.
    result: Float64Array = np.maximum(0.0015 + 0.004 * d * d, 1.5 * quantum_m2 * d * d)
    return result


def depth_quantum(depth_m: Float32Array) -> float:
    """The step in which the camera reports depth, over distance squared (1/m): a stereo or
    structured-light camera reports whole (or eighth) disparities, so its depth comes in steps
    that grow as z^2. Measured as a low percentile of the non-zero second differences along
    a grid of rows (:func:`kernels.depth_steps`: a surface seen at a slant has first
    differences of its own; 0 for a renderer's continuous depth)."""
    steps = kernels.depth_steps(
        np.ascontiguousarray(depth_m, dtype=np.float32), max(1, depth_m.shape[0] // 48)
    )
    if len(steps) < 100:
        return 0.0
    return float(np.percentile(steps, 20))


def _ransac(
    points: Float64Array,
    threshold: Float64Array,
    up: Float64Array | None,
    min_cos: float,
    rng: np.random.Generator,
) -> tuple[Float64Array, float] | None:
    count = len(points)
    if count < 3:
        return None
    picks = rng.integers(0, count, size=(HYPOTHESES, 3))
    a, b, c = points[picks[:, 0]], points[picks[:, 1]], points[picks[:, 2]]
    u, v = b - a, c - a
    # np.cross's products, written out (np.cross costs more than the rest of the round).
    normals = np.stack(
        [
            u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1],
            u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
            u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0],
        ],
        axis=1,
    )
    length = np.linalg.norm(normals, axis=1)
    good = length > 1e-12
    normals = normals[good] / length[good, np.newaxis]
    offsets = -np.einsum("ij,ij->i", normals, a[good])
    flip = offsets < 0  # toward the camera: the camera (origin) is on the positive side
    normals[flip] *= -1
    offsets[flip] *= -1
    if up is not None:
        keep = normals @ up >= min_cos
        normals, offsets = normals[keep], offsets[keep]
    if len(normals) == 0:
        return None
    votes = kernels.plane_votes(
        points, threshold, np.ascontiguousarray(normals), np.ascontiguousarray(offsets)
    )
    best = int(votes.argmax())
    return normals[best], float(offsets[best])


def _lowest_level(
    points: Float64Array, up: Float64Array, band: Float64Array
) -> npt.NDArray[np.bool_] | None:
    """The readings at the lowest height along ``up`` that ``MIN_SHARE`` of them share within
    their band (its median), or None."""
    height = points @ up
    order = np.argsort(height)
    ordered = height[order]
    width = median(band)
    low = np.searchsorted(ordered, ordered - width)
    high = np.searchsorted(ordered, ordered + width, side="right")
    enough = high - low >= MIN_SHARE * len(points)
    if not enough.any():
        return None
    first = int(np.argmax(enough))
    densest = first + int(np.argmax((high - low)[first : high[first]]))
    result: npt.NDArray[np.bool_] = np.abs(height - ordered[densest]) < width
    return result


def _level(
    points: Float64Array,
    up: Float64Array,
    band: Float64Array,
    sigma_m: float | None,
    quantum_m2: float,
) -> tuple[Float64Array, float, float, float, float] | None:
    """The plane at the lowest height along ``up`` that ``MIN_SHARE`` of the readings share:
    found in a band ``LEVEL_WIDEN`` times theirs (``up`` may lean a little), fitted (see
    :func:`_refine`), then found again along the fitted normal in their band and fitted.
    (normal, offset, share, sigma, distance), or None."""
    widen = LEVEL_WIDEN
    for _ in range(2):
        level = _lowest_level(points, up, widen * band)
        if level is None:
            return None
        up, offset, sigma, distance, inliers = _refine(points, level, sigma_m, quantum_m2)
        widen = 1.0
    share = float(inliers.sum()) / len(points)
    return (up, offset, share, sigma, distance) if share >= MIN_SHARE else None


def _most_faced(
    points: Float64Array, index: IntArray, shape: tuple[int, int], rng: np.random.Generator
) -> Float64Array | None:
    """The way most small patches of the picture face, toward the camera: the normals of
    ``FACING_PATCHES`` triples of readings within ``PATCH_CELLS`` of one another on the
    sample's grid, averaged over those within ``FACING_DEG`` of the one with the most such
    neighbours; None when no three such readings make a plane."""
    rows, width = shape
    stride = max(1, int(math.sqrt(rows * width / SAMPLE_POINTS)))  # as _sample takes it
    grid = np.stack([index // width // stride, index % width // stride], axis=1)
    cells_shape = grid.max(axis=0) + 1
    cells = np.full(cells_shape, -1, dtype=np.intp)
    cells[grid[:, 0], grid[:, 1]] = np.arange(len(points))
    first = rng.integers(0, len(points), FACING_PATCHES)
    at = grid[first][:, None, :] + rng.integers(-PATCH_CELLS, PATCH_CELLS + 1, (len(first), 2, 2))
    inside = ((at >= 0) & (at < cells_shape)).all(axis=-1)
    row = np.clip(at[..., 0], 0, cells_shape[0] - 1)
    column = np.clip(at[..., 1], 0, cells_shape[1] - 1)
    other = np.where(inside, cells[row, column], -1)
    whole = (other >= 0).all(axis=1)
    a, b, c = points[first[whole]], points[other[whole, 0]], points[other[whole, 1]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    normals = normals[length > 1e-12] / length[length > 1e-12, None]
    if len(normals) == 0:
        return None
    normals[normals[:, 2] > 0] *= -1  # toward the camera, which looks along +z
    near = normals @ normals.T > math.cos(math.radians(FACING_DEG))
    mean = normals[near[int(near.sum(axis=1).argmax())]].mean(axis=0)
    result: Float64Array = mean / np.linalg.norm(mean)
    return result


def _least_squares(
    points: Float64Array, inliers: npt.NDArray[np.bool_]
) -> tuple[Float64Array, float, float]:
    """The plane through the inliers by least squares: normal toward the origin, offset, rms."""
    centre, moments = kernels.plane_moments(points, inliers)
    values, vectors = np.linalg.eigh(moments)
    normal = vectors[:, 0]
    offset = -float(normal @ centre)
    if offset < 0:
        normal, offset = -normal, -offset
    return normal, offset, math.sqrt(max(float(values[0]), 0.0))


def _refine(
    points: Float64Array,
    inliers: npt.NDArray[np.bool_],
    sigma_m: float | None,
    quantum_m2: float = 0.0,
) -> tuple[Float64Array, float, float, float, npt.NDArray[np.bool_]]:
    """Least squares, noise from the residuals (never under half a depth step), inliers again
    at 3 sigma(z), least squares."""
    normal, offset, _ = _least_squares(points, inliers)
    d = points[:, 2]
    distance = median(d[inliers])
    for _ in range(2):
        residual = points @ normal + offset
        if sigma_m is None:
            scaled = residual[inliers] / (d[inliers] / distance) ** 2
            sigma = 1.4826 * median(np.abs(scaled - median(scaled)))
            sigma = max(sigma, SIGMA_FLOOR_M, 0.5 * quantum_m2 * distance * distance)
        else:
            sigma = sigma_m
        threshold = np.maximum(3.0 * sigma * (d / distance) ** 2, 3.0 * SIGMA_FLOOR_M)
        if sigma_m is not None:
            threshold = np.full(d.shape, max(3.0 * sigma_m, 3.0 * SIGMA_FLOOR_M))
        new = np.abs(residual) < threshold
        if new.sum() < 3:
            break
        inliers = new
        normal, offset, _ = _least_squares(points, inliers)
    return normal, offset, sigma, distance, inliers


def _to_frame(
    normal_c: Float64Array, offset_c: float, camera_to_world: Float64Array | None
) -> tuple[tuple[float, float, float], float, float | None, str]:
    if camera_to_world is None:
        n = normal_c
        return (float(n[0]), float(n[1]), float(n[2])), offset_c, None, "camera"
    rotation = camera_to_world[:3, :3]
    n_w = rotation @ normal_c
    offset_w = offset_c - float(n_w @ camera_to_world[:3, 3])
    tilt = math.degrees(math.acos(min(1.0, max(-1.0, float(n_w[2])))))
    return (float(n_w[0]), float(n_w[1]), float(n_w[2])), offset_w, tilt, "world"


def support_from_plane(
    normal_c: Float64Array,
    offset_c: float,
    camera_to_world: Float64Array | None,
    inlier_share: float,
    sigma_m: float,
    distance_m: float,
) -> Support:
    """A :class:`Support` from an optical-frame plane (normal toward the camera)."""
    normal, offset, tilt, frame = _to_frame(normal_c, offset_c, camera_to_world)
    return Support(
        normal=normal,
        offset_m=offset,
        inlier_share=inlier_share,
        tilt_deg=tilt,
        frame=frame,
        sigma_m=sigma_m,
        distance_m=distance_m,
        normal_camera=(float(normal_c[0]), float(normal_c[1]), float(normal_c[2])),
        offset_camera_m=offset_c,
    )


def fit_support(
    depth_m: Float32Array,
    lens: Intrinsics,
    camera_to_world: Float64Array | None,
    *,
    max_tilt_deg: float = 15.0,
    noise_sigma_m: float | None = None,
    table_z_m: float | None = None,
    seed: int = 0,
) -> Support | None:
    """The support plane (see the module docstring), or None when no plane is found."""
    points, index = _sample(depth_m, lens)
    if table_z_m is not None:
        if camera_to_world is None:
            raise ValueError("table_z_m needs the camera's pose (camera_to_world), got None")
        rotation = camera_to_world[:3, :3]
        normal_c = rotation.T @ np.array([0.0, 0.0, 1.0])
        offset_c = float(camera_to_world[2, 3] - table_z_m)
        if len(points) >= 3:
            residual = points @ normal_c + offset_c
            near = np.abs(residual) < _initial_threshold(points[:, 2], noise_sigma_m)
            share = float(near.mean())
            if near.sum() >= 3 and noise_sigma_m is None:
                distance = median(points[near, 2])
                mad = median(np.abs(residual[near] - median(residual[near])))
                sigma = max(1.4826 * mad, SIGMA_FLOOR_M)
            else:
                distance, sigma = median(points[:, 2]), noise_sigma_m or SIGMA_FLOOR_M
        else:
            share, distance, sigma = 0.0, 1.0, noise_sigma_m or SIGMA_FLOOR_M
        support = support_from_plane(normal_c, offset_c, camera_to_world, share, sigma, distance)
        return replace(support, lump_px=lump_width(depth_m, lens, support))
    if len(points) < 30:
        return None
    # Stray readings far beyond the scene (a stereo camera's mismatches at tens of metres)
    # would be within any plane's band there, the band growing as z^2: leave them out.
    near = points[:, 2] < FAR_SHARE * median(points[:, 2])
    points, index = points[near], index[near]
    if len(points) < 30:
        return None
    rng = np.random.default_rng(seed)
    quantum = depth_quantum(depth_m) if noise_sigma_m is None else 0.0
    min_cos = math.cos(math.radians(max_tilt_deg))
    up: Float64Array | None = None
    if camera_to_world is not None:
        up = camera_to_world[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    remaining = np.ones(len(points), dtype=bool)
    candidates: list[tuple[Float64Array, float, float, float, float]] = []
    for _ in range(3):
        left = np.flatnonzero(remaining)
        if len(left) < MIN_SHARE * len(points):
            break
        sub = points[left]
        band = _initial_threshold(sub[:, 2], noise_sigma_m, quantum)
        found = _ransac(sub, band, up, min_cos, rng)
        if found is None:
            break
        normal, offset = found
        first = np.abs(sub @ normal + offset) < band
        if first.sum() < MIN_SHARE * len(points):
            break
        normal, offset, sigma, distance, inliers = _refine(sub, first, noise_sigma_m, quantum)
        share = float(inliers.sum()) / len(points)
        if up is None:
            up = normal  # without a pose the first (largest) plane says which way is up
        if share >= MIN_SHARE and float(normal @ up) >= min_cos:
            candidates.append((normal, offset, share, sigma, distance))
        # Take out a wider band than the inliers, so the next round finds another plane.
        wide = np.abs(sub @ normal + offset) < 2.0 * band
        remaining[left[wide | inliers]] = False
    if not candidates:
        # No plane through three readings held enough (the floor round a bin seen from close
        # over it: a tenth of the readings or so, which few triples fall on). The support is
        # about level: the lowest height enough readings share, along the pose's up, or without
        # one along the way most small patches of the picture face (floor, tops and rims).
        band = _initial_threshold(points[:, 2], noise_sigma_m, quantum)
        if camera_to_world is None:
            up = _most_faced(points, index, (depth_m.shape[0], depth_m.shape[1]), rng)
        level = None if up is None else _level(points, up, band, noise_sigma_m, quantum)
        if level is not None and up is not None and float(level[0] @ up) >= min_cos:
            candidates.append(level)
    if not candidates:
        return None
    assert up is not None
    # The lowest: the plane farthest below the camera along "up".
    normal, offset, share, sigma, distance = max(candidates, key=lambda c: c[1] * float(c[0] @ up))
    support = support_from_plane(normal, offset, camera_to_world, share, sigma, distance)
    return replace(support, lump_px=lump_width(depth_m, lens, support))


def noise_against(depth_m: Float32Array, lens: Intrinsics, support: Support) -> float:
    """The depth noise of a picture at ``support.distance_m``, measured against a plane known
    to fit it (the readings within 3 sigma(z) of it, on the grid sample): how much a filter
    cut the noise the support was fitted under."""
    points, _ = _sample(depth_m, lens)
    d = points[:, 2]
    residual = points @ np.asarray(support.normal_camera) + support.offset_camera_m
    near = np.abs(residual) < np.maximum(3.0 * support.sigma_at(d), 3.0 * SIGMA_FLOOR_M)
    if near.sum() < 30:
        return support.sigma_m
    scaled = residual[near] / (d[near] / support.distance_m) ** 2
    return max(1.4826 * median(np.abs(scaled - median(scaled))), SIGMA_FLOOR_M)


def lump_width(depth_m: Float32Array, lens: Intrinsics, support: Support) -> float:
    """How many pixels wide the depth errors' lumps are on the support: the sigma of a
    Gaussian that, smoothing independent errors, makes neighbours one pixel apart correlate as
    the plane's residuals do. Neighbours' differences and the residuals are measured on the
    same readings (grid-sample pixels near the plane and the pixel right of and below each),
    by their medians, so speckles and boxes do not count; 0 when neighbours hardly correlate.

    Correlation rho at one pixel, for errors smoothed by a Gaussian of sigma s, is
    exp(-1 / (4 s^2)); the differences' variance is 2 sigma^2 (1 - rho)."""
    height, width = depth_m.shape
    points, flat = _sample(depth_m, lens)
    if len(points) < 30:
        return 0.0
    normal = np.asarray(support.normal_camera)
    d = points[:, 2]
    residual = points @ normal + support.offset_camera_m
    reach = np.maximum(3.0 * support.sigma_at(d), 3.0 * SIGMA_FLOOR_M)
    rows, cols = np.divmod(flat, width)
    near = (np.abs(residual) < reach) & (rows < height - 1) & (cols < width - 1)
    rows, cols = rows[near], cols[near]
    # Residuals scaled to the noise at distance_m, as sigma_m is (noise grows as z^2).
    scale = (support.distance_m / d[near]) ** 2
    own_all = residual[near] * scale
    across, down = lens.rays(width, height)
    own, apart = [], []
    for dr, dc in ((0, 1), (1, 0)):
        r, c = rows + dr, cols + dc
        nd = depth_m[r, c].astype(np.float64)
        with np.errstate(invalid="ignore"):
            ok = (nd > 0) & (nd < np.inf)
        other = normal[0] * across[c] * nd + normal[1] * down[r] * nd + normal[2] * nd
        other += support.offset_camera_m
        own.append(own_all[ok])
        apart.append((other * scale - own_all)[ok])
    res_all, diff = np.concatenate(own), np.concatenate(apart)
    if len(diff) < 30:
        return 0.0
    spread = median(np.abs(res_all - median(res_all)))
    step = median(np.abs(diff - median(diff)))
    if spread <= 0.0:
        return 0.0
    rho = 1.0 - 0.5 * (step / spread) ** 2
    if rho <= 0.05:
        return 0.0
    if rho >= 1.0:
        return MAX_LUMP_PX
    return min(0.5 / math.sqrt(-math.log(rho)), MAX_LUMP_PX)


def support_holds(
    depth_m: Float32Array, lens: Intrinsics, support: Support, min_share_ratio: float = 0.6
) -> bool:
    """Whether a kept support still fits a new picture, checked on the grid sample (cheap)."""
    points, _ = _sample(depth_m, lens)
    if len(points) < 30:
        return False
    normal = np.asarray(support.normal_camera)
    residual = np.abs(points @ normal + support.offset_camera_m)
    sigma = support.sigma_at(points[:, 2]).astype(np.float64)
    share = float((residual < np.maximum(3.0 * sigma, 3.0 * SIGMA_FLOOR_M)).mean())
    return share >= min_share_ratio * support.inlier_share
