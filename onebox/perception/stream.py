"""The finder over a stream of pictures: the support kept, ids kept, still boxes held still.

Contract: :class:`BoxFinder` is called with each picture as
:func:`~onebox.perception.boxes.find_boxes` is, and returns its :class:`Found` with three
differences that only a stream allows:

- **The support is kept** while the camera does not move and the plane still fits the new
  picture (checked on a grid sample), instead of being fitted again every picture.
- **The colour's offset from the depth** is measured on the first picture with colour and
  every ``register_every`` after (:mod:`onebox.perception.register`).
- **Ids are kept** while a box does not move: a box within ``match_distance_m`` of one of the
  last picture's, of a similar size, takes its id.
- **A still box does not jitter**: while a box moves less than its noise allows, its top's
  middle, its axis and its size are running means (each new picture weighs ``SMOOTHING``); a
  box that moves further is taken as it is seen, at once.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from onebox.geometry import Intrinsics
from onebox.perception import register
from onebox.perception.boxes import Box, FinderSettings, Found, find_boxes, quaternion
from onebox.perception.support import Support, fit_support, support_holds
from onebox.perception.tops import cross

Float64Array = npt.NDArray[np.float64]

SMOOTHING = 0.3
"""A still box's running mean takes this share of each new picture's measurement."""
STILL_M = 0.005
"""A box whose top moves less than this between pictures is still..."""
STILL_DEG = 3.0
"""...and turns less than this."""


class BoxFinder:
    """:func:`find_boxes` for a stream (see the module docstring)."""

    def __init__(self, settings: FinderSettings = FinderSettings()) -> None:
        self.settings = settings
        self._support: Support | None = None
        self._pose: Float64Array | None = None
        self._lens: Intrinsics | None = None
        self._last: list[Box] = []
        self._next_id = 0
        self.refits = 0
        """How often the support was fitted (not kept)."""
        self.registration = register.Registration(settings.colour_shift or (0, 0))
        """The colour's shift against the depth, as last measured (or as set)."""
        self._coloured = 0

    def __call__(
        self,
        depth_m: npt.NDArray[np.floating],
        lens: Intrinsics,
        camera_to_world: Float64Array | None,
        colour: npt.NDArray[np.uint8] | None = None,
    ) -> Found:
        depth = np.asarray(depth_m, dtype=np.float32)
        same_pose = (self._pose is None and camera_to_world is None) or (
            self._pose is not None
            and camera_to_world is not None
            and np.allclose(self._pose, camera_to_world, atol=1e-6)
        )
        support = self._support
        if lens != self._lens:
            self._coloured = 0
        if (
            support is None
            or not same_pose
            or lens != self._lens
            or not support_holds(depth, lens, support)
        ):
            support = fit_support(
                depth,
                lens,
                camera_to_world,
                max_tilt_deg=self.settings.max_tilt_deg,
                noise_sigma_m=self.settings.noise_sigma_m,
                table_z_m=self.settings.table_z_m,
            )
            self.refits += 1
        self._support, self._lens = support, lens
        self._pose = None if camera_to_world is None else np.array(camera_to_world, copy=True)
        frame = "world" if camera_to_world is not None else "camera"
        if support is None:
            self._last = []
            return Found(None, [], frame)
        if colour is not None and self.settings.colour_shift is None:
            self._register(depth, colour, support)
        found = find_boxes(
            depth, lens, camera_to_world, colour, self.settings, support, self.registration.shift
        )
        boxes = self._follow(found.boxes)
        return Found(found.support, boxes, found.frame)

    def _register(
        self, depth: npt.NDArray[np.float32], colour: npt.NDArray[np.uint8], support: Support
    ) -> None:
        """Measure the colour's shift on the first picture and every ``register_every`` after;
        a later measurement replaces the shift kept only if it is sure."""
        if self._coloured % max(self.settings.register_every, 1) == 0:
            measured = register.colour_offset(depth, colour, support.sigma_m)
            if measured.sure or self._coloured == 0:
                self.registration = measured
        self._coloured += 1

    def _follow(self, boxes: list[Box]) -> list[Box]:
        """Ids from the last picture's boxes, and running means for the still ones."""
        taken: set[int] = set()
        result = []
        for box in boxes:
            best, best_distance = None, self.settings.match_distance_m
            for old in self._last:
                if old.id in taken:
                    continue
                distance = math.dist(old.top_middle, box.top_middle)
                similar = all(
                    abs(a - b) < max(0.02, 0.2 * b) for a, b in zip(old.size, box.size, strict=True)
                )
                if similar and distance <= best_distance:
                    best, best_distance = old, distance
            if best is None:
                followed = replace(box, id=self._next_id)
                self._next_id += 1
            else:
                followed = _held(best, replace(box, id=best.id))
            taken.add(followed.id)
            result.append(followed)
        self._last = result
        return result


def _axes(box: Box) -> Float64Array:
    """The box's rotation matrix (columns: length, width, up)."""
    x, y, z, w = box.quaternion_xyzw
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _held(old: Box, new: Box) -> Box:
    """``new`` as a running mean with ``old`` if the box stood still, else ``new`` itself."""
    moved = math.dist(old.top_middle, new.top_middle)
    old_axes, new_axes = _axes(old), _axes(new)
    along = float(old_axes[:, 0] @ new_axes[:, 0])
    turned = math.degrees(math.acos(min(1.0, abs(along))))
    if moved > STILL_M or turned > STILL_DEG:
        return new
    up = new_axes[:, 2]
    x_axis = (1 - SMOOTHING) * math.copysign(1.0, along) * old_axes[:, 0]
    x_axis += SMOOTHING * new_axes[:, 0]
    x_axis -= (x_axis @ up) * up
    x_axis /= np.linalg.norm(x_axis)
    rotation = np.stack([x_axis, cross(up, x_axis), up], axis=1)
    top = (1 - SMOOTHING) * np.asarray(old.top_middle) + SMOOTHING * np.asarray(new.top_middle)
    size = (1 - SMOOTHING) * np.asarray(old.size) + SMOOTHING * np.asarray(new.size)
    centre = top - 0.5 * size[2] * up
    q = quaternion(rotation)
    yaw = new.yaw_deg + math.degrees(
        math.atan2(float(cross(new_axes[:, 0], x_axis) @ up), float(new_axes[:, 0] @ x_axis))
    )
    yaw = (yaw + 90.0) % 180.0 - 90.0
    return replace(
        new,
        centre=(float(centre[0]), float(centre[1]), float(centre[2])),
        quaternion_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        size=(float(size[0]), float(size[1]), float(size[2])),
        top_middle=(float(top[0]), float(top[1]), float(top[2])),
        yaw_deg=90.0 if yaw == -90.0 else yaw,
    )
