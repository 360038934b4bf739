"""A distorted lens's pictures put onto the pinhole grid onebox's maths reads.

Every measurement in onebox takes a pixel's ray as ``((u - cx) / fx, (v - cy) / fy, 1)``: a
pinhole. Most depth cameras publish their depth that way (a RealSense's distortion is all
zeros), but some do not: an Azure Kinect's ``depth/image_raw`` carries its lens's
``rational_polynomial`` distortion, which moves a pixel at the picture's edge by a tenth of its
distance from the middle. A CameraInfo with distortion coefficients is read here as ROS's
``image_proc`` reads it: each pixel of the rectified picture, on the pinhole lens of ``P`` (or
``K`` when ``P`` is empty), takes the raw pixel its ray passes through in the distorted picture.

Nearest neighbour, never blended: a depth between the top of a box and the floor behind it is a
surface nobody saw. Depth along the optical axis is unchanged (the camera did not move; ``R``,
a stereo pair's rectifying turn, is the identity for a depth camera and is not read).

Models (the coefficients as ROS and OpenCV order them):

- ``plumb_bob`` / ``rational_polynomial``: k1, k2, p1, p2[, k3[, k4, k5, k6]];
- ``equidistant`` (fisheye): k1, k2, k3, k4.

Contract: :func:`lens_of` reads a CameraInfo into the pinhole the maths uses and, when the
picture must be remapped first, a :class:`Rectifier`; it raises ValueError for a lens it cannot
read (K) or a distortion it does not know.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from onebox.geometry import Float64Array, Intrinsics
from schemas import CameraInfo

POLYNOMIAL = ("plumb_bob", "rational_polynomial")
FISHEYE = ("equidistant",)
MODELS = POLYNOMIAL + FISHEYE
TOLERANCE = 1e-12
"""Coefficients smaller than this are zero: the lens is a pinhole already."""
MAX_PIXELS = 4096 * 4096
"""A lens's picture larger than this is refused: no depth camera sends one, and a map for a
hostile camera_info's size would take gigabytes."""


def distort(
    model: str, d: Sequence[float], x: Float64Array, y: Float64Array
) -> tuple[Float64Array, Float64Array]:
    """Where the lens puts the pinhole's normalised point (x, y): the distorted (x, y)."""
    if model in FISHEYE:
        k1, k2, k3, k4 = (list(d) + [0.0] * 4)[:4]
        r = np.hypot(x, y)
        theta = np.arctan(r)
        t2 = theta * theta
        theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(r > 1e-12, theta_d / r, 1.0)
        return x * scale, y * scale
    k1, k2, p1, p2, k3, k4, k5, k6 = (list(d) + [0.0] * 8)[:8]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy = x * y
    xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * xy
    return xd, yd


@dataclass(frozen=True, eq=False)
class Rectifier:
    """Remaps a distorted camera's pictures onto the pinhole ``lens`` (same size)."""

    lens: Intrinsics
    source: npt.NDArray[np.intp]
    """Per rectified pixel (flat), the raw pixel it takes (0 where ``unseen``)."""
    unseen: npt.NDArray[np.intp]
    """The rectified pixels whose ray leaves the raw picture: no reading."""
    shape: tuple[int, int]

    def depth(self, depth_m: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """The rectified depth (NaN where no raw pixel lies)."""
        out = np.asarray(depth_m, dtype=np.float32).reshape(-1).take(self.source)
        out[self.unseen] = np.nan
        return out.reshape(self.shape)

    def colour(self, rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        """The rectified colour picture (black where no raw pixel lies)."""
        channels = rgb.shape[2]
        out = rgb.reshape(-1, channels).take(self.source, axis=0)
        out[self.unseen] = 0
        return out.reshape(*self.shape, channels)


def lens_of(info: CameraInfo) -> tuple[Intrinsics, Rectifier | None]:
    """The pinhole onebox measures with, and the remap the pictures need first (None for a
    lens without distortion). Raises ValueError for a K that is no lens or an unknown model."""
    raw = Intrinsics.from_k(info.k)
    d = tuple(float(v) for v in info.d)
    if not all(math.isfinite(v) for v in d):
        raise ValueError(f"distortion coefficients {list(d)} are not all finite numbers")
    if all(abs(v) < TOLERANCE for v in d):
        return raw, None
    model = info.distortion_model
    if model not in MODELS:
        raise ValueError(
            f"distortion model {model!r} with coefficients {list(d)} is not one onebox "
            f"undoes ({', '.join(MODELS)}); publish the rectified picture (image_rect)"
        )
    limit = 8 if model in POLYNOMIAL else 4
    if any(abs(v) >= TOLERANCE for v in d[limit:]):
        raise ValueError(
            f"{model} takes at most {limit} coefficients, this lens has {len(d)}: {list(d)}"
        )
    pinhole = _projection(info.p) or raw
    rectifier = _rectifier(info.width, info.height, raw, pinhole, model, d[:limit])
    return pinhole, rectifier


def _projection(p: Sequence[float]) -> Intrinsics | None:
    """P's left 3 x 3 as a pinhole, or None when P is empty or no lens."""
    if len(p) != 12:
        return None
    fx, cx, fy, cy = (float(p[i]) for i in (0, 2, 5, 6))
    if not all(math.isfinite(v) for v in (fx, cx, fy, cy)) or fx <= 0 or fy <= 0:
        return None
    return Intrinsics(fx, fy, cx, cy)


@functools.lru_cache(maxsize=8)
def _rectifier(
    width: int,
    height: int,
    raw: Intrinsics,
    pinhole: Intrinsics,
    model: str,
    d: tuple[float, ...],
) -> Rectifier:
    if width <= 0 or height <= 0 or width * height > MAX_PIXELS:
        raise ValueError(
            f"camera info is {width} x {height} pixels; a lens with distortion needs its "
            f"picture's size (at most {MAX_PIXELS:,} pixels)"
        )
    across, down = pinhole.rays(width, height)
    x = np.broadcast_to(across[np.newaxis, :], (height, width))
    y = np.broadcast_to(down[:, np.newaxis], (height, width))
    # Wild coefficients overflow far from the middle: those rays land nowhere.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        xd, yd = distort(model, d, x, y)
        # The middle of raw pixel u is at u: the nearest raw pixel is the rounded position.
        u = np.rint(xd * raw.fx + raw.cx)
        v = np.rint(yd * raw.fy + raw.cy)
        inside = ((u >= 0) & (u < width) & (v >= 0) & (v < height)).reshape(-1)
    source = np.where(inside, (v * width + u).reshape(-1), 0).astype(np.intp)
    unseen = np.flatnonzero(~inside)
    source.flags.writeable = False
    unseen.flags.writeable = False
    return Rectifier(pinhole, source, unseen, (height, width))
