"""The finder's loops over pixels, tops and probes, compiled with numba (cached on disk where
the install allows; :func:`warm_up` compiles them before the first picture).

Each does in one or a few passes what would otherwise be dozens of NumPy calls, each making a
temporary array: over the picture (the surface reading and its masks, the standing pixels,
cleaning the depth, the colour's Laplacian and gradient and the seam pixels), over the pixels
of every top at once, top by top (measuring them, their cross-sections at seams), or over the
points looked at round every top (the probes). Each computes what the NumPy or OpenCV it
replaced did, in the same order and precision (float32 where the picture is float32; sums
taken in another order only where they are whole numbers, exact in any; a top's sags and
the support plane's moments from plain sums, equal to the last few digits), so the finder's
results do not change with it; the docstrings say what each computes.

The loops run on one thread, written so the compiler vectorises the inner ones where it can
(no branches on the index, a pixel's neighbours read straight inside the picture's frame).
numba's parallel loops were measured and left out: on a two-core machine shared with a
simulator, waiting for the second core at every loop cost a picture up to ten times its time.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int32]


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
    if rows == 0 or cols == 0:
        return
    # The labelled pixels with an open unlabelled one among their 8 neighbours: "free"
    # pixels spread a column either way, then looked for a row either way (loops without
    # branches, which the compiler vectorises, but for the list of those pixels).
    free = np.empty((rows, cols), dtype=np.bool_)
    for r in range(rows):
        for c in range(cols):
            free[r, c] = (labels[r, c] == 0) & open_[r, c]
    free_near = np.empty((rows, cols), dtype=np.bool_)
    for r in range(rows):
        free_near[r, 0] = free[r, 0] | (cols > 1 and free[r, 1])
        for c in range(1, cols - 1):
            free_near[r, c] = free[r, c - 1] | free[r, c] | free[r, c + 1]
        if cols > 1:
            free_near[r, cols - 1] = free[r, cols - 2] | free[r, cols - 1]
    frontier = np.empty(rows * cols, dtype=np.int64)
    edge = np.empty(cols, dtype=np.bool_)
    count = 0
    for r in range(rows):
        above, below = max(r - 1, 0), min(r + 1, rows - 1)
        for c in range(cols):
            edge[c] = (labels[r, c] != 0) & (
                free_near[above, c] | free_near[r, c] | free_near[below, c]
            )
        for c in range(cols):
            if edge[c]:
                frontier[count] = r * cols + c
                count += 1
    following = np.empty(rows * cols, dtype=np.int64)
    for _ in range(steps):
        added = 0
        for i in range(count):
            r, c = divmod(frontier[i], cols)
            label = labels[r, c]
            h = height[r, c]
            if 0 < r < rows - 1 and 0 < c < cols - 1:
                # Inside the picture's frame, the 8 neighbours in the same order, straight.
                for rr, cc in (
                    (r - 1, c - 1),
                    (r - 1, c),
                    (r - 1, c + 1),
                    (r, c - 1),
                    (r, c + 1),
                    (r + 1, c - 1),
                    (r + 1, c),
                    (r + 1, c + 1),
                ):
                    if labels[rr, cc] != 0 or not open_[rr, cc]:
                        continue
                    if abs(height[rr, cc] - h) < tolerance[rr, cc]:
                        labels[rr, cc] = label
                        following[added] = rr * cols + cc
                        added += 1
                continue
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


@numba.njit(cache=True, nogil=True)
def rectangle_angles(
    start: npt.NDArray[np.intp],
    a: Float64Array,
    b: Float64Array,
    angles: Float64Array,
    fine_angles: Float64Array,
) -> Float64Array:
    """Each top's angle whose rectangle round its points (top k's are ``start[k]`` to
    ``start[k + 1]``) is smallest: ``angles`` tried, then ``fine_angles`` about the best of
    them (the first smallest wins; the first tried if none has an area)."""
    n = len(start) - 1
    best = np.zeros(n)
    most = max(len(angles), len(fine_angles))
    cos, sin = np.empty(most), np.empty(most)
    low_p, high_p = np.empty(most), np.empty(most)
    low_q, high_q = np.empty(most), np.empty(most)
    for k in range(n):
        for search in range(2):
            tried = angles if search == 0 else best[k] + fine_angles
            count = len(tried)
            for j in range(count):
                cos[j] = np.cos(tried[j])
                sin[j] = np.sin(tried[j])
                low_p[j], high_p[j], low_q[j], high_q[j] = np.inf, -np.inf, np.inf, -np.inf
            # Every angle's rectangle in one pass over the points (each angle's own min and
            # max still taken over them in order).
            for i in range(start[k], start[k + 1]):
                ai, bi = a[i], b[i]
                for j in range(count):
                    p = ai * cos[j] + bi * sin[j]
                    q = bi * cos[j] - ai * sin[j]
                    low_p[j] = min(low_p[j], p)
                    high_p[j] = max(high_p[j], p)
                    low_q[j] = min(low_q[j], q)
                    high_q[j] = max(high_q[j], q)
            smallest = np.inf
            at = tried[0]
            for j in range(count):
                area = (high_p[j] - low_p[j]) * (high_q[j] - low_q[j])
                if np.isfinite(area) and area < smallest:
                    smallest = area
                    at = tried[j]
            best[k] = at
    return best


@numba.njit(cache=True, nogil=True)
def _kept_extent(
    p: Float64Array,
    q: Float64Array,
    lo: int,
    hi: int,
    step: float,
    share: float,
    start_p: float,
    end_p: float,
    start_q: float,
    end_q: float,
) -> tuple[npt.NDArray[np.bool_], float, float, float, float]:
    """Whether each of one top's pixels (``lo`` to ``hi``) has cross-sections along ``p`` and
    along ``q`` (bins ``step`` wide from the top's least coordinate, ``start_p`` and
    ``start_q``; ``end_p`` and ``end_q`` the greatest, +-inf if none) each holding at least
    ``share`` of the top's typical one along that axis (its pixels over its cross-sections
    that hold any; all of the pixels if none does), and the kept pixels' least and greatest
    ``p`` and ``q``. The two axes are counted in the same passes, each on its own."""
    width_p = int(np.floor((end_p - start_p) / step)) + 1 if np.isfinite(end_p) else 0
    width_q = int(np.floor((end_q - start_q) / step)) + 1 if np.isfinite(end_q) else 0
    counts_p = np.zeros(width_p, dtype=np.int64)
    counts_q = np.zeros(width_q, dtype=np.int64)
    slot_p = np.empty(hi - lo, dtype=np.int64)
    slot_q = np.empty(hi - lo, dtype=np.int64)
    # The slots first (a loop the compiler vectorises), then the counts.
    for i in range(lo, hi):
        slot_p[i - lo] = int(np.floor((p[i] - start_p) / step))
        slot_q[i - lo] = int(np.floor((q[i] - start_q) / step))
    for i in range(hi - lo):
        counts_p[slot_p[i]] += 1
        counts_q[slot_q[i]] += 1
    occupied_p = occupied_q = 0
    for s in range(width_p):
        if counts_p[s] > 0:
            occupied_p += 1
    for s in range(width_q):
        if counts_q[s] > 0:
            occupied_q += 1
    typical_p = (hi - lo) / max(occupied_p, 1)
    typical_q = (hi - lo) / max(occupied_q, 1)
    keep = np.empty(hi - lo, dtype=np.bool_)
    for i in range(hi - lo):
        keep[i] = (counts_p[slot_p[i]] >= share * typical_p) & (
            counts_q[slot_q[i]] >= share * typical_q
        )
    if not keep.any():
        keep[:] = True
    low_p, high_p, low_q, high_q = np.inf, -np.inf, np.inf, -np.inf
    for i in range(lo, hi):
        if keep[i - lo]:
            low_p = min(low_p, p[i])
            high_p = max(high_p, p[i])
            low_q = min(low_q, q[i])
            high_q = max(high_q, q[i])
    return keep, low_p, high_p, low_q, high_q


_HALF_ROOT2 = math.sqrt(0.5)


@numba.njit(cache=True, nogil=True)
def measure_tops(
    start: npt.NDArray[np.intp],
    a: Float64Array,
    b: Float64Array,
    h: Float64Array,
    z: Float64Array,
    sigma: Float64Array,
    on_edge: npt.NDArray[np.bool_],
    ray_x: Float64Array,
    ray_y: Float64Array,
    basis: Float64Array,
    fx_fy: float,
    angles: Float64Array,
    fine_angles: Float64Array,
    profile_share: float,
) -> tuple[Float64Array, ...]:
    """Every top measured from its pixels (step 5 of :mod:`onebox.perception.tops`); top k's
    pixels are ``start[k]`` to ``start[k + 1]`` (as :func:`top_points` orders them).

    Per pixel: its plane coordinates ``a``, ``b``, its height ``h``, depth ``z``, the noise
    ``sigma`` there, whether it is on its top's outline, and its ray's x/z and y/z; ``basis``
    is e1, e2 and the support normal (rows), ``fx_fy`` the lens's fx fy. Each top's sums run
    over its pixels in order, as ``np.bincount`` would add them.

    Returns per top (n): pixels, mean depth, mean sigma, height at the rectangle's middle,
    middle (n, 2), axis (n, 2), length, width, area, fill, corners, rms, sag and sag share
    (n, 2: over the middle half, over the middle 80 %), tilt (degrees), slope (n, 2), the
    points' mean a, b and h (n, 3) and the rectangle's area over the turned one's, as
    :class:`onebox.perception.tops.Tops` holds them."""
    n = len(start) - 1
    # The outline's points, top by top, for the rectangle's angle.
    edges = 0
    for i in range(len(a)):
        if on_edge[i]:
            edges += 1
    edge_a = np.empty(edges)
    edge_b = np.empty(edges)
    edge_start = np.zeros(n + 1, dtype=np.intp)
    e = 0
    for k in range(n):
        for i in range(start[k], start[k + 1]):
            if on_edge[i]:
                edge_a[e] = a[i]
                edge_b[e] = b[i]
                e += 1
        edge_start[k + 1] = e
    angle = rectangle_angles(edge_start, edge_a, edge_b, angles, fine_angles)
    pixels = np.zeros(n)
    mean_z = np.zeros(n)
    mean_sigma = np.zeros(n)
    height = np.zeros(n)
    middle = np.zeros((n, 2))
    axis_ab = np.zeros((n, 2))
    length = np.zeros(n)
    width = np.zeros(n)
    area = np.zeros(n)
    fill = np.zeros(n)
    corners = np.zeros(n)
    rms = np.zeros(n)
    sag = np.zeros((n, 2))
    sag_share = np.zeros((n, 2))
    tilt = np.zeros(n)
    slope = np.zeros((n, 2))
    centroid = np.zeros((n, 3))
    turned = np.zeros(n)
    residual = np.empty(len(a))
    p = np.empty(len(a))
    q = np.empty(len(a))
    p_turned = np.empty(len(a))
    q_turned = np.empty(len(a))
    footprint = np.empty(len(a))
    window = np.empty((2, 2))
    sums = np.empty((2, 2, 5))
    for k in range(n):
        lo, hi = start[k], start[k + 1]
        pixels[k] = hi - lo
        safe = max(hi - lo, 1.0)
        sum_a = sum_b = sum_h = sum_z = sum_sigma = 0.0
        for i in range(lo, hi):
            sum_a += a[i]
            sum_b += b[i]
            sum_h += h[i]
            sum_z += z[i]
            sum_sigma += sigma[i]
        mean_a, mean_b, mean_h = sum_a / safe, sum_b / safe, sum_h / safe
        centroid[k, 0], centroid[k, 1], centroid[k, 2] = mean_a, mean_b, mean_h
        mean_z[k], mean_sigma[k] = sum_z / safe, sum_sigma / safe
        # The top's plane, h = alpha a + beta b + gamma, by least squares about its middle.
        saa = sab = sbb = sah = sbh = 0.0
        for i in range(lo, hi):
            da, db, dh = a[i] - mean_a, b[i] - mean_b, h[i] - mean_h
            saa += da * da
            sab += da * db
            sbb += db * db
            sah += da * dh
            sbh += db * dh
        saa, sab, sbb, sah, sbh = saa / safe, sab / safe, sbb / safe, sah / safe, sbh / safe
        det = saa * sbb - sab * sab
        alpha = beta = 0.0
        if det > 1e-18:
            alpha = (sah * sbb - sbh * sab) / det
            beta = (sbh * saa - sah * sab) / det
        cos, sin = np.cos(angle[k]), np.sin(angle[k])
        # Each pixel's residual off the plane; its coordinates along the rectangle's axes
        # (and their least and greatest); its footprint on the support plane: z^2 / (fx fy
        # |m . ray|) on the top's own plane (normal m ~ n - alpha e1 - beta e2), times m . n
        # to lay it on the support's. One pass, each sum in order.
        squared = summed = 0.0
        start_p, end_p, start_q, end_q = np.inf, -np.inf, np.inf, -np.inf
        start_t, end_t, start_u, end_u = np.inf, -np.inf, np.inf, -np.inf
        for i in range(lo, hi):
            da, db, dh = a[i] - mean_a, b[i] - mean_b, h[i] - mean_h
            residual[i] = dh - alpha * da - beta * db
            squared += residual[i] * residual[i]
            p[i] = a[i] * cos + b[i] * sin
            q[i] = b[i] * cos - a[i] * sin
            along_e1 = ray_x[i] * basis[0, 0] + ray_y[i] * basis[0, 1] + basis[0, 2]
            along_e2 = ray_x[i] * basis[1, 0] + ray_y[i] * basis[1, 1] + basis[1, 2]
            along_n = ray_x[i] * basis[2, 0] + ray_y[i] * basis[2, 1] + basis[2, 2]
            facing = along_n - alpha * along_e1 - beta * along_e2
            footprint[i] = z[i] * z[i] / (fx_fy * max(abs(facing), 0.05))
            summed += footprint[i]
            start_p = min(start_p, p[i])
            end_p = max(end_p, p[i])
            start_q = min(start_q, q[i])
            end_q = max(end_q, q[i])
            # ... and along the rectangle's axes turned 45 degrees.
            p_turned[i] = (p[i] - q[i]) * _HALF_ROOT2
            q_turned[i] = (p[i] + q[i]) * _HALF_ROOT2
            start_t = min(start_t, p_turned[i])
            end_t = max(end_t, p_turned[i])
            start_u = min(start_u, q_turned[i])
            end_u = max(end_u, q_turned[i])
        rms[k] = np.sqrt(squared / safe)
        step = np.sqrt(summed / safe)  # one pixel's side on the plane
        # The extent along each axis over the pixels whose cross-sections are not strays
        # (all of them if none is kept).
        keep, low_p, high_p, low_q, high_q = _kept_extent(
            p, q, lo, hi, step, profile_share, start_p, end_p, start_q, end_q
        )
        for i in range(lo, hi):
            if keep[i - lo]:
                area[k] += footprint[i]
        low_p -= 0.5 * step
        high_p += 0.5 * step
        low_q -= 0.5 * step
        high_q += 0.5 * step
        extent_p, extent_q = high_p - low_p, high_q - low_q
        # The rectangle round the same pixels turned 45 degrees, its strays left out the same
        # way: a round top's is no larger, a square's half as large again, a longer one's more.
        _, low_t, high_t, low_u, high_u = _kept_extent(
            p_turned, q_turned, lo, hi, step, profile_share, start_t, end_t, start_u, end_u
        )
        turned_area = (high_t - low_t + step) * (high_u - low_u + step)
        turned[k] = extent_p * extent_q / max(turned_area, 1e-12)
        mid_p, mid_q = 0.5 * (low_p + high_p), 0.5 * (low_q + high_q)
        # How full the rectangle's corners are: corner squares a fifth of the width on a side
        # (three pixels at least), a pixel in from the rectangle's sides.
        corner = max(0.2 * min(extent_p, extent_q), 3.0 * step)
        in_corners = 0.0
        for i in range(lo, hi):
            if not keep[i - lo]:
                continue
            dp = 0.5 * extent_p - step - abs(p[i] - mid_p)
            dq = 0.5 * extent_q - step - abs(q[i] - mid_q)
            if dp >= 0 and dp < corner and dq >= 0 and dq < corner:
                in_corners += footprint[i]
        # A top under two corners wide has its corner squares overlap across it: each holds
        # what lies between the sides, a pixel in. (Along it they are asked whole: a top small
        # both ways is a disc as well as a square.)
        across = max(min(corner, 0.5 * min(extent_p, extent_q) - step), step)
        corners[k] = min(in_corners / (4.0 * corner * across), 1.0)
        # Lengths on the top's own plane (it may lean): stretch by the slope along each axis.
        stretched_p = extent_p * math.hypot(1.0, alpha * cos + beta * sin)
        stretched_q = extent_q * math.hypot(1.0, beta * cos - alpha * sin)
        # How the top curves off its plane along each axis: the residuals' quadratic part over
        # a window round its middle, as the sag from its middle to the window's edges; two
        # windows, the middle half and the middle 80 % (less three pixels at each edge, which
        # a camera smears, and never narrower than the middle half: a top a few pixels across
        # has no wider window to fit). Both windows and both axes in one pass, by their sums:
        # with o the offset and r the residual over a window's n pixels, the quadratic's
        # covariance sum (o^2 - mean o^2)(r - mean r) is sum o^2 r - n mean(o^2) mean(r), and
        # its variance sum sum o^4 - n mean(o^2)^2.
        window[0, 0], window[0, 1] = stretched_p / 4, stretched_q / 4
        window[1, 0] = max(min(stretched_p * 0.4, stretched_p * 0.5 - 3.0 * step), stretched_p / 4)
        window[1, 1] = max(min(stretched_q * 0.4, stretched_q * 0.5 - 3.0 * step), stretched_q / 4)
        sums[:] = 0.0
        for i in range(lo, hi):
            for direction in range(2):
                offset = (p[i] - mid_p) if direction == 0 else (q[i] - mid_q)
                square = offset * offset
                for w in range(2):
                    if abs(offset) < window[w, direction]:
                        sums[w, direction, 0] += 1.0
                        sums[w, direction, 1] += square
                        sums[w, direction, 2] += residual[i]
                        sums[w, direction, 3] += square * residual[i]
                        sums[w, direction, 4] += square * square
        for w in range(2):
            for direction in range(2):
                extent = stretched_p if direction == 0 else stretched_q
                count = max(sums[w, direction, 0], 1.0)
                mean_square = sums[w, direction, 1] / count
                mean_residual = sums[w, direction, 2] / count
                curved = sums[w, direction, 3] - count * mean_square * mean_residual
                spread = sums[w, direction, 4] - count * mean_square * mean_square
                curve = (curved / count) / max(spread / count, 1e-18)
                # Under two pixels either side, the fit has two or three offsets to go by and
                # its curve is noise (a 25 mm sag across a flat top six pixels wide): no curve.
                this = abs(curve) * max(window[w, direction], 0.0) ** 2
                if window[w, direction] < 2.0 * step:
                    this = 0.0
                share = this / max(extent / 2, 1e-9)
                if share > sag_share[k, w]:
                    sag[k, w] = this
                sag_share[k, w] = max(sag_share[k, w], share)
        middle[k, 0] = mid_p * cos - mid_q * sin
        middle[k, 1] = mid_p * sin + mid_q * cos
        if extent_p >= extent_q:
            axis_ab[k, 0], axis_ab[k, 1] = cos, sin
        else:
            axis_ab[k, 0], axis_ab[k, 1] = -sin, cos
        length[k] = max(stretched_p, stretched_q)
        width[k] = min(stretched_p, stretched_q)
        slope[k, 0], slope[k, 1] = alpha, beta
        height[k] = mean_h + alpha * (middle[k, 0] - mean_a) + beta * (middle[k, 1] - mean_b)
        tilt[k] = math.degrees(math.atan(math.hypot(alpha, beta)))
        fill[k] = area[k] / max(extent_p * extent_q, 1e-12)
    return (
        pixels,
        mean_z,
        mean_sigma,
        height,
        middle,
        axis_ab,
        length,
        width,
        area,
        fill,
        corners,
        rms,
        sag,
        sag_share,
        tilt,
        slope,
        centroid,
        turned,
    )


@numba.njit(cache=True, nogil=True)
def _mean_run(
    run_count: Float64Array,
    run_sum: Float64Array,
    first: int,
    start: int,
    upto: int,
) -> float:
    """The mean of slots ``start`` to ``upto`` of a top whose first slot is ``first``, from the
    running counts and sums within the top."""
    before_count = run_count[start - 1] if start > first else 0.0
    before_sum = run_sum[start - 1] if start > first else 0.0
    return float((run_sum[upto] - before_sum) / max(run_count[upto] - before_count, 1.0))


@numba.njit(cache=True, nogil=True, inline="always")
def _offsets(
    a: Float64Array,
    b: Float64Array,
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    k: int,
    i: int,
    along: Float64Array,
    across: Float64Array,
) -> None:
    """Pixel ``i``'s offset from top ``k``'s middle along its rectangle's length and across."""
    da = a[i] - middle_ab[k, 0]
    db = b[i] - middle_ab[k, 1]
    along[i] = da * axis_ab[k, 0] + db * axis_ab[k, 1]
    across[i] = db * axis_ab[k, 0] - da * axis_ab[k, 1]


@numba.njit(cache=True, nogil=True)
def _rectangle_axes(
    a: Float64Array,
    b: Float64Array,
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    area: Float64Array,
    pixels: IntArray,
    wanted: npt.NDArray[np.bool_],
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """Each ``wanted`` top's pixels' offsets from its middle along its rectangle's length and
    across it (the others' are left unset), and each top's pixel side (the root of its mean
    footprint). The pixels come top by top, ``pixels`` of each."""
    along = np.empty(len(a))
    across = np.empty(len(a))
    first = 0
    for k in range(len(pixels)):
        last = first + pixels[k]
        if wanted[k]:
            for i in range(first, last):
                _offsets(a, b, middle_ab, axis_ab, k, i, along, across)
        first = last
    step = np.empty(len(pixels))
    for k in range(len(pixels)):
        step[k] = math.sqrt(max(area[k] / max(pixels[k], 1), 1e-12))
    return along, across, step


SEAM_AROUND = (4, 10)
"""Slots (pixels) either side of a seam whose print it is compared with: from, to."""
SEAM_FULL = 0.5
"""A seam's cross-section holds at least this share of the top's typical one."""


@numba.njit(cache=True, nogil=True)
def seam_cuts(
    index: npt.NDArray[np.intp],
    top: IntArray,
    a: Float64Array,
    b: Float64Array,
    seam: npt.NDArray[np.bool_],
    grey: npt.NDArray[np.uint8],
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    length: Float64Array,
    width: Float64Array,
    area: Float64Array,
    pixels: IntArray,
    limits: Float64Array,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], Float64Array]:
    """Where a seam crosses each top best (:func:`onebox.perception.seams.split_at_seams`):
    whether it is cut, whether along its length (else across), and where (the cut's offset
    from the rectangle's middle along that axis).

    Each top's cross-sections along each axis, bins a pixel wide, count their pixels on
    ``seam`` (flat, the picture's), overall and in each of the outer thirds across; a
    cross-section is a seam when ``limits`` (min part, min seam length, seam share, over
    print, end share, shade step, narrowest and widest strip) say so: it holds half a typical
    cross-section at least, stands out from the top's print on average and from the
    cross-sections a few pixels either side, and is not one edge of a strip of tape (another
    seam-like cross-section the strip's width away, or its mirror about the middle, the strip
    between them in a shade of ``grey`` its own, the flaps either side alike)."""
    min_part, min_seam, seam_share, over_print, end_share, shade_step = limits[:6]
    narrowest_strip, widest_strip = limits[6], limits[7]
    n = len(length)
    count = len(top)
    on_seam = np.empty(count)
    shade = np.empty(count)
    print_share = np.zeros(n)
    for i in range(count):
        k = top[i]
        on_seam[i] = 1.0 if seam[index[i]] else 0.0
        shade[i] = float(grey[index[i]])
        print_share[k] += on_seam[i]
    every = np.ones(n, dtype=np.bool_)
    along, across, step = _rectangle_axes(a, b, middle_ab, axis_ab, area, pixels, every)
    for k in range(n):
        print_share[k] /= max(pixels[k], 1)
    cut = np.zeros(n, dtype=np.bool_)
    cut_along = np.zeros(n, dtype=np.bool_)
    cut_at = np.zeros(n)
    best = np.zeros(n)
    for direction in range(2):
        coordinate = along if direction == 0 else across
        other = across if direction == 0 else along
        extent = length if direction == 0 else width
        span = width if direction == 0 else length
        offset = np.zeros(n + 1, dtype=np.int64)
        for k in range(n):
            offset[k + 1] = offset[k] + max(math.ceil(extent[k] / step[k]) + 2, 1)
        total = offset[n]
        owner = np.empty(total, dtype=np.int64)
        third = np.empty(n)  # (each top's once, not a division at every pixel)
        for k in range(n):
            owner[offset[k] : offset[k + 1]] = k
            third[k] = span[k] / 3.0
        # Per slot: pixels, pixels on a seam, and in the outer third on either side: all of
        # them and those on a seam; the sum of grey levels.
        sums = np.zeros((total, 7))
        for i in range(count):
            k = top[i]
            bins = int(np.floor((coordinate[i] + 0.5 * extent[k]) / step[k])) + 1
            s = offset[k] + min(max(bins, 0), offset[k + 1] - offset[k] - 1)
            # (Indexed straight: a view of the row would be counted and let go at every pixel.)
            sums[s, 0] += 1.0
            sums[s, 1] += on_seam[i]
            if other[i] > third[k]:
                sums[s, 2] += 1.0
                sums[s, 3] += on_seam[i]
            if -other[i] > third[k]:
                sums[s, 4] += 1.0
                sums[s, 5] += on_seam[i]
            sums[s, 6] += shade[i]
        share = np.zeros(total)
        for s in range(total):
            share[s] = sums[s, 1] / max(sums[s, 0], 1.0)
        strong = np.zeros(total, dtype=np.bool_)
        position = np.empty(total)
        for s in range(total):
            k = owner[s]
            # The print round the line: its share in the slots a few pixels either side (a
            # seam stands out from them; a busy print's lines do not).
            first, last = offset[k], offset[k + 1] - 1
            around = 0.0
            counted = 0
            for near in range(s - SEAM_AROUND[1], s + SEAM_AROUND[1] + 1):
                if first <= near <= last and abs(near - s) >= SEAM_AROUND[0]:
                    around += share[near]
                    counted += 1
            around /= max(counted, 1)
            position[s] = (s - offset[k] - 0.5) * step[k] - 0.5 * extent[k]
            margin = max(min_part, 3.0 * step[k])
            # A seam runs across the whole top: its cross-section is no thinner than half a
            # typical one (a sliver left beside something nearer is edged by its outline).
            typical = pixels[k] * step[k] / max(extent[k], step[k])
            strong[s] = (
                abs(position[s]) < 0.5 * extent[k] - margin
                and sums[s, 0] >= 3
                and sums[s, 0] >= SEAM_FULL * typical
                and span[k] >= min_seam
                and share[s] >= seam_share
                and share[s] - print_share[k] >= over_print
                and share[s] - around >= over_print
                and sums[s, 3] / max(sums[s, 2], 1.0) >= end_share
                and sums[s, 5] / max(sums[s, 4], 1.0) >= end_share
            )
        # Running counts and grey sums within each top: the shade of any run of its slots.
        run_count = np.empty(total)
        run_sum = np.empty(total)
        for s in range(total):
            first = s == offset[owner[s]]
            run_count[s] = sums[s, 0] + (0.0 if first else run_count[s - 1])
            run_sum[s] = sums[s, 6] + (0.0 if first else run_sum[s - 1])
        peak = np.zeros(n)
        where = np.zeros(n, dtype=np.int64)
        for s in range(total):
            if not strong[s]:
                continue
            k = owner[s]
            first, last = offset[k], offset[k + 1] - 1
            twin = first + min(max(last - s, 0), last - first)
            mirrored = strong[twin] or strong[max(twin - 1, 0)] or strong[min(twin + 1, total - 1)]
            high, low = max(s, twin), min(s, twin)
            middle = _mean_run(run_count, run_sum, first, low, high)
            below = _mean_run(run_count, run_sum, first, first, max(low - 1, first))
            above = _mean_run(run_count, run_sum, first, min(high + 1, last), last)
            tape = (
                mirrored
                and abs(position[s]) > 2.0 * step[k]
                and abs(above - below) < shade_step
                and abs(middle - 0.5 * (above + below)) >= shade_step
            )
            # ... or one edge of a strip of its own shade anywhere, no wider than a roll of
            # tape, with alike flaps either side (a band as wide as the strip).
            reach = math.ceil(widest_strip / step[k])
            for mate in range(max(s - reach, first), min(s + reach, last) + 1):
                if tape:
                    break
                if abs(mate - s) * step[k] < narrowest_strip or not strong[mate]:
                    continue
                low, high = min(s, mate), max(s, mate)
                wide = high - low
                if low - wide < first or high + wide > last:
                    continue
                strip = _mean_run(run_count, run_sum, first, low + 1, high - 1)
                before = _mean_run(run_count, run_sum, first, low - wide, low - 1)
                after = _mean_run(run_count, run_sum, first, high + 1, high + wide)
                tape = (
                    abs(after - before) < shade_step
                    and abs(strip - 0.5 * (after + before)) >= shade_step
                )
            # The strongest slot of each top (the last among equals).
            if not tape and share[s] >= peak[k]:
                peak[k] = share[s]
                where[k] = s
        for k in range(n):
            if peak[k] > 0 and peak[k] > best[k]:
                best[k] = peak[k]
                cut[k] = True
                cut_along[k] = direction == 0
                cut_at[k] = position[where[k]]
    return cut, cut_along, cut_at


@numba.njit(cache=True, nogil=True)
def corner_cuts(
    top: IntArray,
    a: Float64Array,
    b: Float64Array,
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    length: Float64Array,
    width: Float64Array,
    area: Float64Array,
    pixels: IntArray,
    wanted: npt.NDArray[np.bool_],
    limits: Float64Array,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], Float64Array, Float64Array]:
    """Where each ``wanted`` top is best cut in two rectangles
    (:func:`onebox.perception.tops.split_at_corners`): whether it is cut, whether along its
    length (else across), where (the cut's offset from its rectangle's middle along that axis),
    and each part's rectangle (from, to along that axis; from, to across it: the part below
    the cut, then the part above).

    Each top's cross-sections along each axis, bins a pixel wide, each spanning from its
    first pixel across to its last; a cut between two bins leaves a part each side, each
    filling the rectangle round it by its cross-sections' spans (a notch shows as shorter
    spans; pixels differ in footprint across a top seen at a slant, spans do not). A cut
    counts when ``limits`` (narrowest part, part fill, fill gained) say so: both parts at
    least the narrowest part each way, each filling its rectangle, both by more than the
    whole fills its own; the best fills the two rectangles most, together."""
    min_part, part_fill, gain = limits[0], limits[1], limits[2]
    n = len(length)
    along, across, step = _rectangle_axes(a, b, middle_ab, axis_ab, area, pixels, wanted)
    begin = np.zeros(n + 1, dtype=np.int64)
    for k in range(n):
        begin[k + 1] = begin[k] + pixels[k]
    cut = np.zeros(n, dtype=np.bool_)
    cut_along = np.zeros(n, dtype=np.bool_)
    cut_at = np.zeros(n)
    parts = np.zeros((n, 8))
    best = np.zeros(n)
    for direction in range(2):
        coordinate = along if direction == 0 else across
        other = across if direction == 0 else along
        extent = length if direction == 0 else width
        offset = np.zeros(n + 1, dtype=np.int64)
        for k in range(n):
            slots = max(math.ceil(extent[k] / step[k]) + 2, 1) if wanted[k] else 0
            offset[k + 1] = offset[k] + slots
        total = offset[n]
        held = np.zeros(total)
        low = np.full(total, np.inf)
        high = np.full(total, -np.inf)
        for k in range(n):
            if not wanted[k]:
                continue
            for i in range(begin[k], begin[k + 1]):
                bins = int(np.floor((coordinate[i] + 0.5 * extent[k]) / step[k])) + 1
                s = offset[k] + min(max(bins, 0), offset[k + 1] - offset[k] - 1)
                held[s] += 1.0
                low[s] = min(low[s], other[i])
                high[s] = max(high[s], other[i])
        # Running from either end of each top: spans, extent across.
        run_span = np.empty(total)
        run_low = np.empty(total)
        run_high = np.empty(total)
        back_span = np.empty(total)
        back_low = np.empty(total)
        back_high = np.empty(total)
        for k in range(n):
            first, last = offset[k], offset[k + 1] - 1
            if last <= first:
                continue
            spans, lo, hi = 0.0, np.inf, -np.inf
            for s in range(first, last + 1):
                spans += high[s] - low[s] + step[k] if held[s] > 0 else 0.0
                lo, hi = min(lo, low[s]), max(hi, high[s])
                run_span[s], run_low[s], run_high[s] = spans, lo, hi
            spans, lo, hi = 0.0, np.inf, -np.inf
            for s in range(last, first - 1, -1):
                spans += high[s] - low[s] + step[k] if held[s] > 0 else 0.0
                lo, hi = min(lo, low[s]), max(hi, high[s])
                back_span[s], back_low[s], back_high[s] = spans, lo, hi
            start, end = first, last
            while start < last and held[start] == 0.0:
                start += 1
            while end > first and held[end] == 0.0:
                end -= 1
            whole = (end - start + 1) * (run_high[last] - run_low[last] + step[k])
            whole_fill = run_span[last] / max(whole, 1e-12)
            for s in range(start, end):
                below_long = (s - start + 1) * step[k]
                above_long = (end - s) * step[k]
                below_wide = run_high[s] - run_low[s] + step[k]
                above_wide = back_high[s + 1] - back_low[s + 1] + step[k]
                if min(below_long, above_long, below_wide, above_wide) < min_part:
                    continue
                below_area = below_long * below_wide
                above_area = above_long * above_wide
                worst = min(
                    run_span[s] * step[k] / below_area, back_span[s + 1] * step[k] / above_area
                )
                # The two rectangles that hold the top best, together.
                fill = (run_span[s] + back_span[s + 1]) * step[k] / (below_area + above_area)
                if worst >= part_fill and worst >= whole_fill + gain and fill > best[k]:
                    best[k] = fill
                    cut[k] = True
                    cut_along[k] = direction == 0
                    from_ = (start - offset[k] - 1) * step[k] - 0.5 * extent[k]
                    at = (s - offset[k]) * step[k] - 0.5 * extent[k]
                    to = (end - offset[k]) * step[k] - 0.5 * extent[k]
                    cut_at[k] = at
                    parts[k, 0], parts[k, 1] = from_, at
                    parts[k, 2], parts[k, 3] = run_low[s], run_high[s]
                    parts[k, 4], parts[k, 5] = at, to
                    parts[k, 6], parts[k, 7] = back_low[s + 1], back_high[s + 1]
    return cut, cut_along, cut_at, parts


@numba.njit(cache=True, nogil=True)
def surface_heights(
    depth: Float32Array,
    slope: Float32Array,
    plane: Float32Array,
    limits: Float32Array,
) -> tuple[
    Float32Array,
    Float32Array,
    Float32Array,
    Float32Array,
    npt.NDArray[np.bool_],
    Float32Array,
    Float32Array,
]:
    """Every pixel's height and noise (:func:`onebox.perception.surface.read_surface`), in
    float32 as NumPy computes them; its height for the 3 x 3 highest and lowest (-inf and inf
    where no reading, which is neither); whether its noise is quiet (under a share of its
    footprint, ``depth / fx``); and, to box-filter, 1 and its depth where it has a reading
    (0 and 0 where not).

    ``plane`` is the support's normal (optical frame), offset, sigma and 1 / its distance;
    ``limits`` the noise floor, the cosine of the steepest top, the step in sigmas, the least
    step, the quiet share and fx."""
    rows, cols = depth.shape
    offset, sigma_support, inverse_distance = plane[3], plane[4], plane[5]
    floor, quiet_share, fx = limits[0], limits[4], limits[5]
    height = np.empty((rows, cols), dtype=np.float32)
    sigma = np.empty((rows, cols), dtype=np.float32)
    for_high = np.empty((rows, cols), dtype=np.float32)
    for_low = np.empty((rows, cols), dtype=np.float32)
    quiet = np.empty((rows, cols), dtype=np.bool_)
    counted = np.empty((rows, cols), dtype=np.float32)
    filled = np.empty((rows, cols), dtype=np.float32)
    for r in range(rows):
        for c in range(cols):
            d = depth[r, c]
            h = d * slope[r, c] + offset
            height[r, c] = h
            ratio = d * inverse_distance
            noise = sigma_support * ratio * ratio
            # np.maximum: NaN wins.
            sigma[r, c] = noise if (noise != noise or noise > floor) else floor
            quiet[r, c] = sigma[r, c] < quiet_share * d / fx
            finite = np.isfinite(d)
            for_high[r, c] = h if finite else -np.inf
            for_low[r, c] = h if finite else np.inf
            counted[r, c] = 1.0 if finite else 0.0
            filled[r, c] = d if finite else 0.0
    return height, sigma, for_high, for_low, quiet, counted, filled


@numba.njit(cache=True, nogil=True, inline="always")
def _faces_up_by(
    z: np.float32,
    dz_u: np.float32,
    dz_v: np.float32,
    u: np.float32,
    v: np.float32,
    fx: np.float32,
    fy: np.float32,
    normal: tuple[np.float32, np.float32, np.float32],
    cos_max: np.float32,
) -> bool:
    """Whether the surface at depth ``z`` (``u``, ``v`` from the principal point), with the
    depth's gradient ``dz_u``, ``dz_v`` a pixel, faces within the steepest top of the support's
    ``normal``: ``n ~ (-fx z_u, -fy z_v, z + u z_u + v z_v)``."""
    nx = -fx * dz_u
    ny = -fy * dz_v
    nz = z + u * dz_u + v * dz_v
    along = -(nx * normal[0] + ny * normal[1] + nz * normal[2])
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    return along > cos_max * norm  # type: ignore[no-any-return]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def faces_up(
    depth: Float32Array,
    weight: Float32Array,
    total: Float32Array,
    reach: int,
    lens: Float32Array,
    plane: Float32Array,
    limits: Float32Array,
) -> npt.NDArray[np.bool_]:
    """Whether each pixel faces up: the normal from the gradient, ``reach`` pixels either
    side, of the depth box-filtered over ``2 reach + 1`` (``total`` over ``weight``; no normal
    where fewer than half the window's readings), within the steepest top of the support's
    normal; float32 as NumPy computes it, False where no reading. ``lens`` is fx, fy, cx, cy;
    ``plane`` and ``limits`` as for :func:`surface_heights`."""
    rows, cols = depth.shape
    fx, fy, cx, cy = lens[0], lens[1], lens[2], lens[3]
    normal, cos_max = (plane[0], plane[1], plane[2]), limits[1]
    window = 2 * reach + 1
    min_weight = np.float32(0.5 * window * window)
    smooth = np.empty((rows, cols), dtype=np.float32)
    nan = np.float32(np.nan)
    for r in range(rows):
        for c in range(cols):
            # Branch-free (a select), so the compiler vectorises the loop.
            mean = total[r, c] / weight[r, c]
            smooth[r, c] = nan if weight[r, c] < min_weight else mean
    up = np.zeros((rows, cols), dtype=np.bool_)
    span = np.float32(2 * reach)
    for r in range(reach, rows - reach):
        v = np.float32(r) - cy
        for c in range(reach, cols - reach):
            dz_u = (smooth[r, c + reach] - smooth[r, c - reach]) / span
            dz_v = (smooth[r + reach, c] - smooth[r - reach, c]) / span
            u = np.float32(c) - cx
            up[r, c] = _faces_up_by(smooth[r, c], dz_u, dz_v, u, v, fx, fy, normal, cos_max)
    for r in range(rows):
        for c in range(cols):
            up[r, c] &= np.isfinite(depth[r, c])
    return up


@numba.njit(cache=True, nogil=True, error_model="numpy")
def faces_up_sided(
    depth: Float32Array,
    lens: Float32Array,
    plane: Float32Array,
    limits: Float32Array,
) -> npt.NDArray[np.bool_]:
    """Whether each pixel faces up by the gradient across one pixel, on the side where its
    surface goes on: of the differences to the neighbour before and after (each way), the
    smaller, so an edge beside the pixel does not turn it. False where no reading or no
    neighbour read either way; arguments as for :func:`faces_up`."""
    rows, cols = depth.shape
    fx, fy, cx, cy = lens[0], lens[1], lens[2], lens[3]
    normal, cos_max = (plane[0], plane[1], plane[2]), limits[1]
    up = np.zeros((rows, cols), dtype=np.bool_)
    for r in range(1, rows - 1):
        v = np.float32(r) - cy
        for c in range(1, cols - 1):
            z = depth[r, c]
            if not np.isfinite(z):
                continue
            dz_u = _nearer_difference(z - depth[r, c - 1], depth[r, c + 1] - z)
            dz_v = _nearer_difference(z - depth[r - 1, c], depth[r + 1, c] - z)
            if not (np.isfinite(dz_u) and np.isfinite(dz_v)):
                continue
            u = np.float32(c) - cx
            up[r, c] = _faces_up_by(z, dz_u, dz_v, u, v, fx, fy, normal, cos_max)
    return up


@numba.njit(cache=True, nogil=True, inline="always")
def _nearer_difference(before: np.float32, after: np.float32) -> np.float32:
    """Of two differences, the smaller (the one that is a number, NaN if neither)."""
    if not np.isfinite(before):
        return after
    if not np.isfinite(after):
        return before
    return before if abs(before) <= abs(after) else after


@numba.njit(cache=True, nogil=True)
def read_or(values: Float32Array, counted: Float32Array, instead: float) -> Float32Array:
    """``values`` where there is a reading (``counted`` > 0, from :func:`surface_heights`),
    ``instead`` (as float32) where not: ``np.where(counted > 0, values, instead)`` in one
    pass."""
    rows, cols = values.shape
    other = np.float32(instead)
    result = np.empty((rows, cols), dtype=np.float32)
    for r in range(rows):
        for c in range(cols):
            result[r, c] = values[r, c] if counted[r, c] > 0 else other
    return result


@numba.njit(cache=True, nogil=True)
def merge_flags(
    into: npt.NDArray[np.bool_], flags: npt.NDArray[np.bool_], where: npt.NDArray[np.bool_]
) -> None:
    """``into |= flags & where``, in place, in one pass."""
    rows, cols = into.shape
    for r in range(rows):
        for c in range(cols):
            into[r, c] |= flags[r, c] & where[r, c]


@numba.njit(cache=True, nogil=True)
def keep_flags(into: npt.NDArray[np.bool_], where: npt.NDArray[np.uint8]) -> None:
    """``into &= where > 0``, in place, in one pass."""
    rows, cols = into.shape
    for r in range(rows):
        for c in range(cols):
            into[r, c] &= where[r, c] > 0


@numba.njit(cache=True, nogil=True)
def surface_steps(
    depth: Float32Array,
    sigma: Float32Array,
    high: Float32Array,
    low: Float32Array,
    limits: Float32Array,
) -> npt.NDArray[np.bool_]:
    """Whether the height steps across each pixel's 3 x 3 neighbourhood: ``high`` less
    ``low`` beyond the step in sigmas (and the least step), float32 as NumPy computes it;
    False where no reading. ``limits`` as for :func:`surface_heights`."""
    rows, cols = depth.shape
    step_sigmas, min_step = limits[2], limits[3]
    step = np.zeros((rows, cols), dtype=np.bool_)
    for r in range(rows):
        for c in range(cols):
            bound = step_sigmas * sigma[r, c]
            step[r, c] = high[r, c] - low[r, c] > (bound if bound > min_step else min_step)
            step[r, c] = step[r, c] and np.isfinite(depth[r, c])
    return step


@numba.njit(cache=True, nogil=True)
def settled_steps(
    height: Float32Array,
    sigma: Float32Array,
    high: Float32Array,
    low: Float32Array,
    limits: Float32Array,
) -> npt.NDArray[np.uint8]:
    """1 where ``high`` less ``low`` (the 3 x 3 spread of the heights a median settled) is
    beyond the step (the step in sigmas, the least step), or where the pixel is a crack: lower
    by the step than both its neighbours either side, along a row or a column (the picture
    wrapping round at its edges, as ``np.roll`` does); float32 as NumPy computes it.
    ``limits`` as for :func:`surface_heights`."""
    rows, cols = height.shape
    near = np.zeros((rows, cols), dtype=np.uint8)
    if cols == 0:
        return near
    for r in range(rows):
        up = r - 1 if r > 0 else rows - 1
        down = r + 1 if r < rows - 1 else 0
        # The first and last columns wrap round; the rest read their neighbours straight (a
        # loop without branches, which the compiler vectorises).
        for c in (0, cols - 1):
            left = c - 1 if c > 0 else cols - 1
            right = c + 1 if c < cols - 1 else 0
            near[r, c] = _settled(height, sigma, high, low, r, c, up, down, left, right, limits)
        for c in range(1, cols - 1):
            near[r, c] = _settled(height, sigma, high, low, r, c, up, down, c - 1, c + 1, limits)
    return near


@numba.njit(cache=True, nogil=True)
def _settled(
    height: Float32Array,
    sigma: Float32Array,
    high: Float32Array,
    low: Float32Array,
    r: int,
    c: int,
    up: int,
    down: int,
    left: int,
    right: int,
    limits: Float32Array,
) -> np.uint8:
    """:func:`settled_steps` at pixel (r, c), its neighbours in rows ``up`` and ``down`` and
    columns ``left`` and ``right``."""
    bound = limits[2] * sigma[r, c]
    min_step = limits[3]
    threshold = bound if (bound != bound or bound > min_step) else min_step
    h = height[r, c]
    across = (h < height[r, left] - threshold) & (h < height[r, right] - threshold)
    along = (h < height[up, c] - threshold) & (h < height[down, c] - threshold)
    return np.uint8(across | along | (high[r, c] - low[r, c] > threshold))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _sight_one(
    a: float,
    b: float,
    height: float,
    basis: Float64Array,
    offset: float,
    depth: Float32Array,
    lens: Float64Array,
) -> tuple[float, float, bool, int, int]:
    """:func:`sight` for one point."""
    rows, cols = depth.shape
    lift = height - offset
    x = a * basis[0, 0] + b * basis[1, 0] + lift * basis[2, 0]
    y = a * basis[0, 1] + b * basis[1, 1] + lift * basis[2, 1]
    z = a * basis[0, 2] + b * basis[1, 2] + lift * basis[2, 2]
    u = np.rint(lens[0] * x / z + lens[2])
    v = np.rint(lens[1] * y / z + lens[3])
    if u >= 0 and u < cols and v >= 0 and v < rows and z > 0:
        return z, np.float64(depth[int(v), int(u)]), True, int(v), int(u)
    return z, np.nan, False, 0, 0


@numba.njit(cache=True, nogil=True)
def sight(
    a: Float64Array,
    b: Float64Array,
    height: Float64Array,
    basis: Float64Array,
    offset: float,
    depth: Float32Array,
    lens: Float64Array,
) -> tuple[
    Float64Array, Float64Array, npt.NDArray[np.bool_], npt.NDArray[np.intp], npt.NDArray[np.intp]
]:
    """Points at (a, b) in the support plane's coordinates (``basis``: e1, e2 and the normal,
    rows, in the optical frame; the plane's ``offset``) and ``height`` above it: the depth each
    would read if seen, the depth seen at its pixel (NaN outside the picture or no reading),
    whether it is in the picture, and its pixel's row and column (0 outside). ``lens`` is fx,
    fy, cx, cy."""
    count = len(a)
    z = np.empty(count)
    seen = np.empty(count)
    inside = np.empty(count, dtype=np.bool_)
    vi = np.zeros(count, dtype=np.intp)
    ui = np.zeros(count, dtype=np.intp)
    for i in range(count):
        z[i], seen[i], inside[i], vi[i], ui[i] = _sight_one(
            a[i], b[i], height[i], basis, offset, depth, lens
        )
    return z, seen, inside, vi, ui


@numba.njit(cache=True, nogil=True)
def _sides(axis_ab: Float64Array, k: int) -> tuple[Float64Array, Float64Array]:
    """Top k's four sides (+length, -length, +width, -width): each one's outward direction
    and the direction along it, (4, 2) each, in the support plane's coordinates."""
    ax, ay = axis_ab[k, 0], axis_ab[k, 1]
    outward = np.array([[ax, ay], [-ax, -ay], [-ay, ax], [ay, -ax]])
    along = np.array([[-ay, ax], [-ay, ax], [ax, ay], [ax, ay]])
    return outward, along


@numba.njit(cache=True, nogil=True)
def probe_round(
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    length: Float64Array,
    width: Float64Array,
    reach: Float64Array,
    spread: Float64Array,
    height: Float64Array,
    basis: Float64Array,
    offset: float,
    depth: Float32Array,
    lens: Float64Array,
) -> tuple[
    Float64Array,
    Float64Array,
    Float64Array,
    npt.NDArray[np.bool_],
    npt.NDArray[np.intp],
    npt.NDArray[np.intp],
]:
    """The probes just past each top's sides (:func:`onebox.perception.boxes._look_round`):
    ``reach`` past the side, at ``spread`` (shares of the half side) along it, at the top's
    height, seen as :func:`sight` sees them. Returns the probes' plane coordinates (n, 4, P, 2)
    and their z expected, depth seen, whether inside, row and column (n, 4, P)."""
    n, probes = len(length), len(spread)
    ab = np.empty((n, 4, probes, 2))
    z = np.empty((n, 4, probes))
    seen = np.empty((n, 4, probes))
    inside = np.empty((n, 4, probes), dtype=np.bool_)
    vi = np.empty((n, 4, probes), dtype=np.intp)
    ui = np.empty((n, 4, probes), dtype=np.intp)
    for k in range(n):
        outward, along = _sides(axis_ab, k)
        half_l, half_w = length[k] * 0.5, width[k] * 0.5
        for side in range(4):
            out_len = (half_l if side < 2 else half_w) + reach[k]
            along_len = half_w if side < 2 else half_l
            for j in range(probes):
                for c in range(2):
                    ab[k, side, j, c] = (middle_ab[k, c] + outward[side, c] * out_len) + along[
                        side, c
                    ] * (along_len * spread[j])
                (
                    z[k, side, j],
                    seen[k, side, j],
                    inside[k, side, j],
                    vi[k, side, j],
                    ui[k, side, j],
                ) = _sight_one(
                    ab[k, side, j, 0], ab[k, side, j, 1], height[k], basis, offset, depth, lens
                )
    return ab, z, seen, inside, vi, ui


@numba.njit(cache=True, nogil=True)
def probe_cover(
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    length: Float64Array,
    width: Float64Array,
    s: Float64Array,
    t: Float64Array,
    height: Float64Array,
    basis: Float64Array,
    offset: float,
    depth: Float32Array,
    lens: Float64Array,
) -> tuple[Float64Array, Float64Array, npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Points on each top's rectangle (:func:`onebox.perception.boxes._covered`): ``s`` of
    its length along its axis and ``t`` of its width across, at its height, seen as
    :func:`sight` sees them: z expected, depth seen and the pixel's row and column (0 outside
    the picture), (n, len(s)) each."""
    n, count = len(length), len(s)
    z = np.empty((n, count))
    seen = np.empty((n, count))
    vi = np.zeros((n, count), dtype=np.intp)
    ui = np.zeros((n, count), dtype=np.intp)
    for k in range(n):
        ax, ay = axis_ab[k, 0], axis_ab[k, 1]
        for i in range(count):
            a = (middle_ab[k, 0] + (s[i] * length[k]) * ax) + (t[i] * width[k]) * -ay
            b = (middle_ab[k, 1] + (s[i] * length[k]) * ay) + (t[i] * width[k]) * ax
            z[k, i], seen[k, i], _, vi[k, i], ui[k, i] = _sight_one(
                a, b, height[k], basis, offset, depth, lens
            )
    return z, seen, vi, ui


@numba.njit(cache=True, nogil=True)
def probe_faces(
    middle_ab: Float64Array,
    axis_ab: Float64Array,
    length: Float64Array,
    width: Float64Array,
    inset: Float64Array,
    spread: Float64Array,
    heights: Float64Array,
    basis: Float64Array,
    offset: float,
    depth: Float32Array,
    lens: Float64Array,
) -> tuple[
    Float64Array, Float64Array, npt.NDArray[np.bool_], npt.NDArray[np.intp], npt.NDArray[np.intp]
]:
    """Points on the planes of each top's four sides (:func:`onebox.perception.boxes.
    _on_sides`): ``inset`` in from the rectangle, at ``spread`` (shares of the half side)
    along it, at each of the top's ``heights`` (n, H), seen as :func:`sight` sees them: z
    expected, depth seen, whether inside, row and column, (n, 4, H, len(spread)) each."""
    n, levels, count = len(length), heights.shape[1], len(spread)
    z = np.empty((n, 4, levels, count))
    seen = np.empty((n, 4, levels, count))
    inside = np.empty((n, 4, levels, count), dtype=np.bool_)
    vi = np.empty((n, 4, levels, count), dtype=np.intp)
    ui = np.empty((n, 4, levels, count), dtype=np.intp)
    for k in range(n):
        outward, along = _sides(axis_ab, k)
        for side in range(4):
            half = (length[k] if side < 2 else width[k]) / 2
            half_along = (width[k] if side < 2 else length[k]) / 2
            for j in range(count):
                a = (middle_ab[k, 0] + outward[side, 0] * (half - inset[k])) + (
                    along[side, 0] * half_along
                ) * spread[j]
                b = (middle_ab[k, 1] + outward[side, 1] * (half - inset[k])) + (
                    along[side, 1] * half_along
                ) * spread[j]
                for level in range(levels):
                    (
                        z[k, side, level, j],
                        seen[k, side, level, j],
                        inside[k, side, level, j],
                        vi[k, side, level, j],
                        ui[k, side, level, j],
                    ) = _sight_one(a, b, heights[k, level], basis, offset, depth, lens)
    return z, seen, inside, vi, ui


@numba.njit(cache=True, nogil=True)
def top_points(
    labels: IntArray,
    depth: Float32Array,
    height: Float32Array,
    sigma: Float32Array,
    across: Float32Array,
    down: Float32Array,
    basis: Float64Array,
) -> tuple[
    npt.NDArray[np.intp],
    npt.NDArray[np.intp],
    IntArray,
    Float64Array,
    Float64Array,
    Float64Array,
    Float64Array,
    Float64Array,
    npt.NDArray[np.bool_],
    Float64Array,
    Float64Array,
]:
    """Every top pixel (``labels`` > 0), top by top and in the picture's order within each:
    where each top's pixels start (n + 1: the last is the count), and per pixel its flat
    index, its top (label - 1), its point's plane coordinates a and b (``basis``: e1, e2,
    normal, rows), its height, depth and noise, whether it is on its top's outline (a pixel of
    another label or none among its 8 neighbours in the picture) and its ray's x/z and y/z
    (``across`` per column, ``down`` per row)."""
    rows, cols = labels.shape
    start = _label_sizes(labels)
    n = len(start) - 1
    start[0] = 0  # the pixels of no top
    for k in range(n):
        start[k + 1] += start[k]
    count = start[n]
    index = np.empty(count, dtype=np.intp)
    top = np.empty(count, dtype=np.int32)
    a = np.empty(count)
    b = np.empty(count)
    h = np.empty(count)
    z = np.empty(count)
    noise = np.empty(count)
    edge = np.zeros(count, dtype=np.bool_)
    ray_x = np.empty(count)
    ray_y = np.empty(count)
    at = start[:n].copy()
    for r in range(rows):
        for c in range(cols):
            label = labels[r, c]
            if label <= 0:
                continue
            i = at[label - 1]
            at[label - 1] += 1
            index[i] = r * cols + c
            top[i] = label - 1
            zi = np.float64(depth[r, c])
            x = across[c] * zi
            y = down[r] * zi
            a[i] = basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * zi
            b[i] = basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * zi
            h[i] = height[r, c]
            z[i] = zi
            noise[i] = sigma[r, c]
            # On the outline: another label (or none) among the 8 neighbours in the picture
            # (inside the picture's frame, the 8 read straight).
            if 0 < r < rows - 1 and 0 < c < cols - 1:
                edge[i] = (
                    (labels[r - 1, c - 1] != label)
                    | (labels[r - 1, c] != label)
                    | (labels[r - 1, c + 1] != label)
                    | (labels[r, c - 1] != label)
                    | (labels[r, c + 1] != label)
                    | (labels[r + 1, c - 1] != label)
                    | (labels[r + 1, c] != label)
                    | (labels[r + 1, c + 1] != label)
                )
            else:
                for nr in range(max(r - 1, 0), min(r + 2, rows)):
                    for nc in range(max(c - 1, 0), min(c + 2, cols)):
                        if labels[nr, nc] != label:
                            edge[i] = True
            ray_x[i] = across[c]
            ray_y[i] = down[r]
    return start, index, top, a, b, h, z, noise, edge, ray_x, ray_y


@numba.njit(cache=True, nogil=True)
def standing(
    height: Float32Array,
    sigma: Float32Array,
    up: npt.NDArray[np.bool_],
    step: npt.NDArray[np.bool_],
    min_height: float,
    max_height: float,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.bool_], Float32Array]:
    """Steps 1 and 2 of :mod:`onebox.perception.tops`, per pixel, in float32 as NumPy
    computes them: which pixels stand (above ``min_height`` and 4 sigma, below
    ``max_height``: "open" to grow over), which of them also face up and are on no step (the
    regions' cores, 1), and how far in height a region grows to its neighbours (3 sigma,
    2 mm at least)."""
    rows, cols = height.shape
    low = np.float32(min_height)
    high = np.float32(max_height)
    core = np.zeros((rows, cols), dtype=np.uint8)
    open_ = np.zeros((rows, cols), dtype=np.bool_)
    tolerance = np.empty((rows, cols), dtype=np.float32)
    least = np.float32(0.002)
    for r in range(rows):
        for c in range(cols):
            noise = sigma[r, c]
            four = np.float32(4.0) * noise
            bound = four if (four != four or four > low) else low
            h = height[r, c]
            stands = (h > bound) & (h < high)
            open_[r, c] = stands
            core[r, c] = stands & up[r, c] & (not step[r, c])
            three = np.float32(3.0) * noise
            tolerance[r, c] = three if (three != three or three > least) else least
    return core, open_, tolerance


@numba.njit(cache=True, nogil=True)
def border_spans(labels: IntArray, band: int, n: int) -> npt.NDArray[np.intp]:
    """For each of the ``n`` labels, how far along the picture's edge its pixels within
    ``band`` of it reach, on the edge where that is farthest (last minus first position
    along it; -1 where it does not come that close)."""
    rows, cols = labels.shape
    band_rows, band_cols = min(band, rows), min(band, cols)
    span = np.full(n, -1, dtype=np.intp)
    low = np.empty(n + 1, dtype=np.intp)
    high = np.empty(n + 1, dtype=np.intp)
    for edge in range(4):
        low[:] = rows + cols
        high[:] = -1
        across = band_rows if edge < 2 else band_cols
        along = cols if edge < 2 else rows
        for d in range(across):
            for t in range(along):
                if edge == 0:
                    label = labels[d, t]
                elif edge == 1:
                    label = labels[rows - 1 - d, t]
                elif edge == 2:
                    label = labels[t, d]
                else:
                    label = labels[t, cols - 1 - d]
                if label > 0:
                    low[label] = min(low[label], t)
                    high[label] = max(high[label], t)
        for k in range(n):
            if high[k + 1] >= 0:
                span[k] = max(span[k], high[k + 1] - low[k + 1])
    return span


@numba.njit(cache=True, nogil=True)
def _label_sizes(labels: IntArray) -> npt.NDArray[np.intp]:
    """How many pixels hold each label, 0 to the largest (0: no region). Counted in four
    tallies, by column, summed after: a run of one label does not wait on its own count from
    the pixel before."""
    rows, cols = labels.shape
    largest = 0
    for r in range(rows):
        for c in range(cols):
            largest = max(largest, labels[r, c])
    tallies = np.zeros((4, largest + 1), dtype=np.intp)
    for r in range(rows):
        for c in range(cols):
            tallies[c & 3, labels[r, c]] += 1
    sizes: npt.NDArray[np.intp] = tallies[0] + tallies[1] + tallies[2] + tallies[3]
    return sizes


@numba.njit(cache=True, nogil=True)
def drop_small(labels: IntArray, min_pixels: int) -> IntArray:
    """``labels`` without the regions of fewer than ``min_pixels`` pixels, the rest numbered
    1, 2, ... in their order."""
    rows, cols = labels.shape
    sizes = _label_sizes(labels)
    count = len(sizes) - 1
    renumber = np.zeros(count + 1, dtype=np.int32)
    kept = 0
    for k in range(1, count + 1):
        if sizes[k] >= min_pixels:
            kept += 1
            renumber[k] = kept
    result = np.empty((rows, cols), dtype=np.int32)
    for r in range(rows):
        for c in range(cols):
            result[r, c] = renumber[labels[r, c]]
    return result


@numba.njit(cache=True, nogil=True)
def _reflect(i: int, size: int) -> int:
    """Index ``i`` (one past either end at most) reflected into 0..size - 1 without repeating
    the edge pixel, as OpenCV's default border (BORDER_REFLECT_101) reads it."""
    if i < 0:
        return -i
    if i >= size:
        return 2 * (size - 1) - i
    return i


@numba.njit(cache=True, nogil=True)
def laplacian_counts(grey: npt.NDArray[np.uint8]) -> npt.NDArray[np.int64]:
    """How many pixels, of every second row and column from the first, have each absolute
    value (0 to 1020) of the picture's Laplacian: ``np.bincount(np.abs(cv2.Laplacian(grey,
    cv2.CV_16S)[::2, ::2]).ravel(), minlength=1021)`` (its 3 x 3 kernel, whole numbers, the
    border as OpenCV reads it; at least 2 x 2 pixels)."""
    rows, cols = grey.shape
    counts = np.zeros(1021, dtype=np.int64)
    for r in range(0, rows, 2):
        up, down = _reflect(r - 1, rows), _reflect(r + 1, rows)
        for c in range(0, cols, 2):
            left, right = _reflect(c - 1, cols), _reflect(c + 1, cols)
            value = (
                np.int64(grey[up, c])
                + np.int64(grey[down, c])
                + np.int64(grey[r, left])
                + np.int64(grey[r, right])
                - 4 * np.int64(grey[r, c])
            )
            counts[abs(value)] += 1
    return counts


@numba.njit(cache=True, nogil=True)
def seam_pixels(
    dark: npt.NDArray[np.uint8],
    grey: npt.NDArray[np.uint8],
    dark_step: float,
    edge_step: float,
) -> npt.NDArray[np.uint8]:
    """1 where a pixel is on a thin dark line (``dark``, the black-hat, above ``dark_step``)
    or on a strong colour edge (the squared length of ``grey``'s 3 x 3 Sobel gradient, as
    ``cv2.Sobel`` gives it in float32 (whole numbers, exact; the border as OpenCV reads it),
    above ``edge_step`` squared, in float32 as NumPy compares it), else 0 (at least 2 x 2
    pixels). But in the first and last columns the neighbours are read straight (a loop the
    compiler vectorises)."""
    rows, cols = dark.shape
    edge = np.float32(edge_step * edge_step)
    result = np.zeros((rows, cols), dtype=np.uint8)
    for r in range(rows):
        up, down = _reflect(r - 1, rows), _reflect(r + 1, rows)
        for c in range(1, cols - 1):
            result[r, c] = _seam_at(dark, grey, dark_step, edge, r, up, down, c, c - 1, c + 1)
        for c in (0, cols - 1):
            left, right = _reflect(c - 1, cols), _reflect(c + 1, cols)
            result[r, c] = _seam_at(dark, grey, dark_step, edge, r, up, down, c, left, right)
    return result


@numba.njit(cache=True, nogil=True)
def _seam_at(
    dark: npt.NDArray[np.uint8],
    grey: npt.NDArray[np.uint8],
    dark_step: float,
    edge: np.float32,
    r: int,
    up: int,
    down: int,
    c: int,
    left: int,
    right: int,
) -> np.uint8:
    """:func:`seam_pixels` at (r, c), its neighbours in rows ``up`` and ``down`` and columns
    ``left`` and ``right``."""
    gx = (
        np.int32(grey[up, right])
        + 2 * np.int32(grey[r, right])
        + np.int32(grey[down, right])
        - np.int32(grey[up, left])
        - 2 * np.int32(grey[r, left])
        - np.int32(grey[down, left])
    )
    gy = (
        np.int32(grey[down, left])
        + 2 * np.int32(grey[down, c])
        + np.int32(grey[down, right])
        - np.int32(grey[up, left])
        - 2 * np.int32(grey[up, c])
        - np.int32(grey[up, right])
    )
    fx, fy = np.float32(gx), np.float32(gy)
    return np.uint8((dark[r, c] > dark_step) | (fx * fx + fy * fy > edge))


@numba.njit(cache=True, nogil=True)
def clean_depth(depth: Float32Array) -> Float32Array:
    """A copy of ``depth`` with every kind of no reading (0, negative, inf, NaN) as NaN."""
    rows, cols = depth.shape
    result = np.empty((rows, cols), dtype=np.float32)
    for r in range(rows):
        for c in range(cols):
            d = depth[r, c]
            result[r, c] = d if (d > 0 and d < np.inf) else np.nan
    return result


@numba.njit(cache=True, nogil=True)
def standing_bounds(
    depth: Float32Array, slope: Float32Array, offset: float, min_height: float
) -> tuple[int, int, int, int]:
    """The first and last row and column holding a pixel higher than ``min_height`` (height
    ``depth * slope + offset``, float32 as NumPy computes it); (-1, -1, -1, -1) if none.
    Each row is counted whole (a loop the compiler vectorises), then only the rows that hold
    any are searched from either end."""
    rows, cols = depth.shape
    offset32 = np.float32(offset)
    least = np.float32(min_height)
    first_row, last_row, first_col, last_col = -1, -1, cols, -1
    for r in range(rows):
        count = 0
        for c in range(cols):
            count += depth[r, c] * slope[r, c] + offset32 > least
        if count == 0:
            continue
        if first_row < 0:
            first_row = r
        last_row = r
        for c in range(cols):
            if depth[r, c] * slope[r, c] + offset32 > least:
                first_col = min(first_col, c)
                break
        for c in range(cols - 1, -1, -1):
            if depth[r, c] * slope[r, c] + offset32 > least:
                last_col = max(last_col, c)
                break
    if first_row < 0:
        return -1, -1, -1, -1
    return first_row, last_row, first_col, last_col


@numba.njit(cache=True, nogil=True)
def plane_votes(
    points: Float64Array, threshold: Float64Array, normals: Float64Array, offsets: Float64Array
) -> npt.NDArray[np.int64]:
    """For each plane (``normals`` (m, 3), ``offsets``), how many of ``points`` (n, 3) lie
    within their own ``threshold`` of it."""
    votes = np.zeros(len(normals), dtype=np.int64)
    for j in range(len(normals)):
        n0, n1, n2, offset = normals[j, 0], normals[j, 1], normals[j, 2], offsets[j]
        count = 0
        for i in range(len(points)):
            residual = points[i, 0] * n0 + points[i, 1] * n1 + points[i, 2] * n2 + offset
            count += abs(residual) < threshold[i]
        votes[j] = count
    return votes


@numba.njit(cache=True, nogil=True)
def plane_moments(
    points: Float64Array, inliers: npt.NDArray[np.bool_]
) -> tuple[Float64Array, Float64Array]:
    """The mean of ``points`` (n, 3) where ``inliers``, and their covariance about it (3, 3,
    over count - 1, as ``np.cov``), without gathering them."""
    centre = np.zeros(3)
    count = 0
    for i in range(len(points)):
        if inliers[i]:
            count += 1
            for j in range(3):
                centre[j] += points[i, j]
    centre /= max(count, 1)
    moments = np.zeros((3, 3))
    for i in range(len(points)):
        if inliers[i]:
            d0 = points[i, 0] - centre[0]
            d1 = points[i, 1] - centre[1]
            d2 = points[i, 2] - centre[2]
            moments[0, 0] += d0 * d0
            moments[0, 1] += d0 * d1
            moments[0, 2] += d0 * d2
            moments[1, 1] += d1 * d1
            moments[1, 2] += d1 * d2
            moments[2, 2] += d2 * d2
    moments[1, 0], moments[2, 0], moments[2, 1] = moments[0, 1], moments[0, 2], moments[1, 2]
    moments /= max(count - 1, 1)
    return centre, moments


@numba.njit(cache=True, nogil=True)
def grid_sample(
    depth: Float32Array, stride: int, across: Float64Array, down: Float64Array
) -> tuple[Float64Array, npt.NDArray[np.intp]]:
    """The optical-frame points (n, 3) of the readings (0 < depth < inf) at every ``stride``-th
    pixel each way from ``stride // 2``, in the picture's order, and their flat indices;
    ``across`` and ``down`` are the rays' x/z per column and y/z per row."""
    rows, cols = depth.shape
    first = stride // 2
    count = 0
    for r in range(first, rows, stride):
        for c in range(first, cols, stride):
            if depth[r, c] > 0 and depth[r, c] < np.inf:
                count += 1
    points = np.empty((count, 3))
    index = np.empty(count, dtype=np.intp)
    i = 0
    for r in range(first, rows, stride):
        for c in range(first, cols, stride):
            d = np.float64(depth[r, c])
            if d > 0 and d < np.inf:
                points[i, 0] = across[c] * d
                points[i, 1] = down[r] * d
                points[i, 2] = d
                index[i] = r * cols + c
                i += 1
    return points, index


@numba.njit(cache=True, nogil=True)
def depth_steps(depth: Float32Array, every: int) -> Float64Array:
    """On every ``every``-th row, each non-zero second difference along the row (a pixel
    against the mean of its neighbours either side, twice) under 2 % of the depth, over the
    depth squared (:func:`onebox.perception.support.depth_quantum`), in the picture's order.
    A surface's own slope is no step: on a plane seen at a slant the first differences are
    the slope, the second ones nothing but the steps the depth is reported in."""
    rows, cols = depth.shape
    result = np.empty((rows // every + 1) * cols)
    count = 0
    for r in range(0, rows, every):
        for c in range(1, cols - 1):
            z = np.float64(depth[r, c])
            diff = abs(np.float64(depth[r, c + 1]) - 2.0 * z + np.float64(depth[r, c - 1]))
            if diff > 0 and diff < 0.02 * z:
                result[count] = diff / (z * z)
                count += 1
    return result[:count]


def warm_up() -> None:
    """Compile (or load from the cache) every kernel on a tiny input."""
    label = np.zeros(2, dtype=np.int32)
    a = np.array([0.0, 1.0])
    one = np.ones(2, dtype=np.bool_)
    rectangle_angles(np.array([0, 2]), a, a, np.array([0.0, 0.5]), np.array([0.0, 0.1]))
    grid = np.zeros((2, 2), dtype=np.int32)
    grid[0, 0] = 1
    flat = np.zeros((2, 2), dtype=np.float32)
    grow(grid, flat, np.ones((2, 2), dtype=np.bool_), flat + 1.0, 1)
    measure_tops(np.array([0, 2]), a, a, a, a + 1.0, a, one, a, a, np.eye(3), 1.0, a, a, 0.25)
    picture = np.ones((3, 3), dtype=np.float32)
    lens, plane, limits = (np.ones(k, dtype=np.float32) for k in (4, 6, 6))
    surface_heights(picture, picture, plane, limits)
    faces_up(picture, picture, picture, 1, lens, plane, limits)
    faces_up_sided(picture, lens, plane, limits)
    surface_steps(picture, picture, picture, picture, limits)
    read_or(picture, picture, 0.0)
    merge_flags(picture > 0, picture > 0, picture > 0)
    keep_flags(picture > 0, np.ones((3, 3), dtype=np.uint8))
    settled_steps(picture, picture, picture, picture, limits)
    sight(a, a, a, np.eye(3), 1.0, picture, np.ones(4))
    tops_ab = np.ones((1, 2))
    probe_round(
        tops_ab, tops_ab, a[:1], a[:1], a[:1], a, a[:1], np.eye(3), 1.0, picture, np.ones(4)
    )
    probe_cover(tops_ab, tops_ab, a[:1], a[:1], a, a, a[:1], np.eye(3), 1.0, picture, np.ones(4))
    probe_faces(
        tops_ab, tops_ab, a[:1], a[:1], a[:1], a, tops_ab, np.eye(3), 1.0, picture, np.ones(4)
    )
    top_points(grid, flat, flat, flat, flat[0], flat[0], np.eye(3))
    standing(flat, flat, one.reshape(1, 2), one.reshape(1, 2), 0.01, np.inf)
    drop_small(grid, 2)
    border_spans(grid, 3, 1)
    standing_bounds(flat, flat, 1.0, 0.01)
    grey = np.zeros((2, 2), dtype=np.uint8)
    laplacian_counts(grey)
    seam_pixels(grey, grey, 1.0, 1.0)
    plane_votes(np.eye(3), a[:1].repeat(3), np.eye(3), a[:1].repeat(3))
    plane_moments(np.eye(3), np.ones(3, dtype=np.bool_))
    one_top = np.ones((1, 2))
    seam_cuts(
        np.arange(2),
        label,
        a,
        a,
        one,
        np.zeros(2, dtype=np.uint8),
        one_top,
        one_top,
        np.ones(1),
        np.ones(1),
        np.ones(1),
        np.full(1, 2, dtype=np.int32),
        np.ones(6),
    )
    corner_cuts(
        label,
        a,
        a,
        one_top,
        one_top,
        np.ones(1),
        np.ones(1),
        np.ones(1),
        np.full(1, 2, dtype=np.int32),
        np.ones(1, dtype=np.bool_),
        np.ones(3),
    )
    # A picture decoded from a message and the lens's cached rays are read-only arrays, for
    # which numba compiles a kernel apart: the kernels that take them are compiled for both.
    frozen = flat.copy()
    frozen.flags.writeable = False
    rays = a.copy()
    rays.flags.writeable = False
    for depth in (flat, frozen):
        clean_depth(depth)
        grid_sample(depth, 1, rays, rays)
        depth_steps(depth, 1)
