"""A random world from a seed: boxes of any proportions, some touching, some stacked, other
objects among them, on a table at a random height, under a camera at a random height and tilt.

Every box's top lies wholly inside the picture. The same seed always gives the same world (one
NumPy PCG64 stream, drawn in a fixed order); ``onebox sim --random-scene SEED --write-scene
FILE.toml`` saves it as a scene file. :func:`random_pallet` draws a loaded pallet instead:
cartons of one size in rows on a EUR pallet.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from onebox.world.spec import (
    CARTON_RGBA,
    TOUCH_M,
    BoxDesc,
    CameraDesc,
    ObjectDesc,
    PlacedBox,
    SceneDesc,
    TableDesc,
    check,
    footprint_overlap,
    highest_ray_z,
    in_picture,
    place,
    world_from_optical,
)

BOX_EDGE_M = (0.02, 0.40)
"""Each of a box's length, width and height is drawn from this range, metres."""
CAMERA_HEIGHT_M = (0.3, 2.5)
"""The camera's height over the table, metres."""
TABLE_Z_M = (0.0, 0.8)
MAX_TILT_DEG = 30.0
TRIES = 60


def _round(value: float, step: float) -> float:
    """``value`` to a whole number of ``step`` (a power of ten), written without float dust."""
    return round(float(value), round(-math.log10(step)))


def _camera(
    rng: np.random.Generator, table_z: float, width: int, height: int, hfov: float
) -> CameraDesc:
    """A camera at a random height and tilt, its optical axis through the table's middle."""
    above = float(rng.uniform(*CAMERA_HEIGHT_M))
    tilt = float(rng.uniform(0.0, MAX_TILT_DEG))
    pan = float(rng.uniform(-180.0, 180.0))
    cam = CameraDesc(
        z=_round(table_z + above, 1e-4),
        tilt_deg=_round(tilt, 0.01),
        pan_deg=_round(pan, 0.01),
        width=width,
        height=height,
        hfov_deg=hfov,
    )
    while highest_ray_z(cam) >= -0.02 and cam.tilt_deg > 0:  # a very wide lens: tilt less
        cam = dataclasses.replace(cam, tilt_deg=_round(cam.tilt_deg / 2, 0.01))
    return _aimed_at_middle(cam, above)


def _aimed_at_middle(cam: CameraDesc, above: float) -> CameraDesc:
    """``cam`` moved across, ``above`` over the table, so that its optical axis meets the
    table's middle."""
    forward = world_from_optical(cam)[:, 2]
    reach = above / -forward[2]
    return dataclasses.replace(
        cam, x=_round(-reach * forward[0], 1e-4), y=_round(-reach * forward[1], 1e-4)
    )


def looking_across(scene: SceneDesc, tilt_deg: float) -> SceneDesc:
    """``scene`` seen ``tilt_deg`` from straight down (a robot's head looking across a table)
    from the same height over the table and the same side, the optical axis still through the
    table's middle: the camera steps back to look at what it looked at before."""
    cam = dataclasses.replace(scene.camera, tilt_deg=tilt_deg)
    return dataclasses.replace(scene, camera=_aimed_at_middle(cam, cam.z - scene.table.z))


def _view_on_table(cam: CameraDesc, table_z: float) -> np.ndarray:
    """Where the picture's four corners meet the table plane, (4, 2)."""
    f = cam.focal_px
    half_w, half_h = cam.width / 2 / f, cam.height / 2 / f
    rays = np.array(
        [[sx * half_w, sy * half_h, 1.0] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    )
    world = rays @ world_from_optical(cam).T
    t = (table_z - cam.z) / world[:, 2]
    return np.array([cam.x, cam.y]) + t[:, None] * world[:, :2]


def _colour(rng: np.random.Generator) -> tuple[float, float, float, float]:
    """Mostly cartons, each a slightly different shade; now and then a white or blue box."""
    kind = rng.random()
    if kind < 0.75:
        base = np.array(CARTON_RGBA[:3]) * rng.uniform(0.8, 1.12) + rng.uniform(-0.03, 0.03, 3)
    elif kind < 0.9:
        base = np.full(3, rng.uniform(0.8, 0.95))
    else:
        base = np.array([0.15, 0.3, 0.7]) * rng.uniform(0.8, 1.2)
    r, g, b = (round(float(v), 3) for v in np.clip(base, 0.0, 1.0))
    return (r, g, b, 1.0)


def _collides(new: PlacedBox, others: list[PlacedBox]) -> bool:
    bottom = new.centre[2] - new.size[2] / 2
    for other in others:
        z_overlap = min(new.top_z, other.top_z) - max(bottom, other.centre[2] - other.size[2] / 2)
        if z_overlap > TOUCH_M and footprint_overlap(new.footprint(), other.footprint()) > TOUCH_M:
            return True
    return False


def random_scene(
    seed: int,
    boxes: int = 6,
    objects: int = 3,
    width: int = 320,
    height: int = 240,
    hfov_deg: float = 60.0,
) -> SceneDesc:
    """A world drawn from ``seed`` with up to ``boxes`` boxes and ``objects`` other objects."""
    rng = np.random.default_rng(seed)
    table_z = _round(float(rng.uniform(*TABLE_Z_M)), 1e-4)
    cam = _camera(rng, table_z, width, height, hfov_deg)
    above = cam.z - table_z
    view = _view_on_table(cam, table_z)
    lo, hi = view.min(axis=0), view.max(axis=0)
    # The view's narrowest width at the table bounds the boxes so that several fit.
    narrow = float(min(np.linalg.norm(view[1] - view[0]), np.linalg.norm(view[2] - view[1])))
    max_side = min(BOX_EDGE_M[1], max(BOX_EDGE_M[0] * 1.5, 0.35 * narrow))
    max_height = min(BOX_EDGE_M[1], max(BOX_EDGE_M[0] * 1.5, 0.3 * above))
    table = TableDesc(
        z=table_z,
        size=(
            _round(max(1.0, 2 * float(np.abs(view[:, 0]).max()) + 0.5), 0.01),
            _round(max(1.0, 2 * float(np.abs(view[:, 1]).max()) + 0.5), 0.01),
        ),
    )
    descs: list[BoxDesc] = []
    placed: list[PlacedBox] = []
    for _ in range(boxes):
        for attempt in range(TRIES):
            shrink = 0.97**attempt
            length, width_m, tall = (
                _round(float(rng.uniform(BOX_EDGE_M[0], max(BOX_EDGE_M[0], m * shrink))), 0.001)
                for m in (max_side, max_side, max_height)
            )
            on: int | None = None
            how = rng.random()
            on_table = [i for i, p in enumerate(placed) if p.on is None]
            if how < 0.25 and on_table:
                # Stacked: smaller than the box below, its middle over that box's top.
                on = int(rng.choice(on_table))
                below = placed[on]
                length = _round(min(length, 0.9 * below.size[0]), 0.001)
                width_m = _round(min(width_m, 0.9 * below.size[1]), 0.001)
                if min(length, width_m) < BOX_EDGE_M[0]:
                    continue
                along = rng.uniform(-0.3, 0.3) * below.size[0]
                across = rng.uniform(-0.3, 0.3) * below.size[1]
                c, s = math.cos(below.yaw), math.sin(below.yaw)
                x = below.centre[0] + c * along - s * across
                y = below.centre[1] + s * along + c * across
                yaw = math.degrees(below.yaw) + float(rng.uniform(-20.0, 20.0))
            elif how < 0.6 and on_table:
                # Touching: turned the same way as a box on the table, side by side with it.
                j = int(rng.choice(on_table))
                nb = placed[j]
                length, width_m = max(length, width_m), min(length, width_m)
                side = int(rng.integers(4))
                c, s = math.cos(nb.yaw), math.sin(nb.yaw)
                if side < 2:  # beyond its end: our length runs on along its length
                    gap = (nb.size[0] + length) / 2 * (1 if side == 0 else -1)
                    slide = rng.uniform(-0.3, 0.3) * nb.size[1]
                    along, across = gap, slide
                else:  # beside its long side
                    gap = (nb.size[1] + width_m) / 2 * (1 if side == 2 else -1)
                    slide = rng.uniform(-0.3, 0.3) * nb.size[0]
                    along, across = slide, gap
                x = nb.centre[0] + c * along - s * across
                y = nb.centre[1] + s * along + c * across
                yaw = math.degrees(nb.yaw)
            else:
                x, y = (float(v) for v in rng.uniform(lo, hi))
                yaw = float(rng.uniform(-180.0, 180.0))
            box = BoxDesc(
                x=_round(x, 1e-4),
                y=_round(y, 1e-4),
                size=(length, width_m, tall),
                yaw_deg=round(yaw, 6),
                on=on,
                rgba=_colour(rng),
            )
            trial = place(SceneDesc(camera=cam, table=table, boxes=(*descs, box)))[-1]
            if (
                trial.top_z < cam.z - 0.15
                and in_picture(cam, trial.top_corners(), margin_px=1.0)
                and not _collides(trial, placed)
                and (on is None or placed[on].contains((box.x, box.y, placed[on].top_z - 1e-6)))
            ):
                descs.append(box)
                placed.append(trial)
                break
    objs: list[ObjectDesc] = []
    obstacles = list(placed)
    shapes = ("cylinder", "sphere", "capsule")
    for _ in range(objects):
        for _attempt in range(TRIES):
            shape = shapes[int(rng.integers(3))]
            radius = _round(float(rng.uniform(0.015, 0.06)), 0.001)
            half = _round(float(rng.uniform(0.02, min(0.2, 0.3 * above))), 0.001)
            size = (radius,) if shape == "sphere" else (radius, half)
            x, y = (_round(float(v), 1e-4) for v in rng.uniform(lo, hi))
            obj = ObjectDesc(shape=shape, x=x, y=y, size=size, rgba=_object_colour(rng))
            bounds = PlacedBox(
                (x, y, table_z + obj.height / 2), 0.0, (2 * radius, 2 * radius, obj.height)
            )
            base = np.array([[x, y, table_z]])
            if (
                bounds.top_z < cam.z - 0.15
                and in_picture(cam, base)
                and not _collides(bounds, obstacles)
            ):
                objs.append(obj)
                obstacles.append(bounds)
                break
    scene = SceneDesc(
        camera=cam,
        table=table,
        boxes=tuple(descs),
        objects=tuple(objs),
        description=f"random scene {seed}: {len(descs)} boxes, {len(objs)} other objects",
    )
    check(scene, f"random scene {seed}")
    return scene


def _object_colour(rng: np.random.Generator) -> tuple[float, float, float, float]:
    palette = ((0.2, 0.45, 0.8), (0.25, 0.65, 0.3), (0.85, 0.75, 0.2), (0.55, 0.55, 0.6))
    r, g, b = palette[int(rng.integers(len(palette)))]
    return (r, g, b, 1.0)


PALLET_SIZE_M = (1.2, 0.8, 0.144)
"""A EUR pallet: 1.2 x 0.8 m, 144 mm tall."""
CARTON_SIZES_M = (
    (0.36, 0.275, 0.30),
    (0.30, 0.20, 0.20),
    (0.40, 0.30, 0.25),
    (0.25, 0.25, 0.15),
    (0.60, 0.40, 0.30),
)
"""The cartons a pallet is loaded with, one size a pallet."""


def random_pallet(seed: int, width: int = 640, height: int = 480, taped: bool = False) -> SceneDesc:
    """A loaded pallet drawn from ``seed``: cartons of one size in rows, touching or a few
    millimetres apart, inset 0-6 cm from the pallet's edges, of one shade give or take; one
    place in seven left empty, one carton in five of another height, one in three carrying a
    smaller carton. The camera, 1.6-2.6 m over the floor and tilted up to 25 degrees, looks at
    the pallet's middle. Box 0 is the pallet itself. ``taped``: every carton has packing tape
    along its top (the same pallet otherwise)."""
    rng = np.random.default_rng(seed)
    yaw = float(rng.uniform(0.0, 90.0))
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    boxes = [BoxDesc(0.0, 0.0, PALLET_SIZE_M, round(yaw, 6), None, (0.70, 0.60, 0.45, 1.0))]
    length, width_m, tall = CARTON_SIZES_M[int(rng.integers(len(CARTON_SIZES_M)))]
    if rng.random() < 0.5:
        length, width_m = width_m, length
    inset = float(rng.uniform(0.0, 0.06))
    gap = float(rng.uniform(0.0, 0.004))
    columns = int((PALLET_SIZE_M[0] - 2 * inset + gap) // (length + gap))
    rows = int((PALLET_SIZE_M[1] - 2 * inset + gap) // (width_m + gap))
    x0 = -((columns - 1) * (length + gap)) / 2
    y0 = -((rows - 1) * (width_m + gap)) / 2
    shade = float(rng.uniform(0.55, 0.8))

    def carton_rgba() -> tuple[float, float, float, float]:
        r = shade + float(rng.uniform(-0.04, 0.04))
        return (round(r, 3), round(r * 0.76, 3), round(r * 0.5, 3), 1.0)

    for i in range(columns):
        for j in range(rows):
            if rng.random() < 0.15:
                continue
            u, v = x0 + i * (length + gap), y0 + j * (width_m + gap)
            x, y = _round(u * c - v * s, 1e-4), _round(u * s + v * c, 1e-4)
            h = tall if rng.random() < 0.8 else _round(tall * float(rng.uniform(0.5, 1.3)), 0.001)
            boxes.append(
                BoxDesc(x, y, (length, width_m, h), round(yaw, 6), 0, carton_rgba(), tape=taped)
            )
            if rng.random() < 0.3:
                small = (
                    _round(length * float(rng.uniform(0.5, 0.8)), 0.001),
                    _round(width_m * float(rng.uniform(0.5, 0.8)), 0.001),
                    _round(tall * 0.6, 0.001),
                )
                turn = round(yaw + float(rng.uniform(-10.0, 10.0)), 6)
                boxes.append(BoxDesc(x, y, small, turn, len(boxes) - 1, carton_rgba(), tape=taped))
    above = float(rng.uniform(1.6, 2.6))
    tilt = float(rng.uniform(0.0, 25.0))
    pan = float(rng.uniform(-180.0, 180.0))
    back = (above - 0.3) * math.tan(math.radians(tilt))
    cam = CameraDesc(
        x=_round(back * math.sin(math.radians(pan)), 1e-4),
        y=_round(-back * math.cos(math.radians(pan)), 1e-4),
        z=_round(above, 1e-4),
        tilt_deg=_round(tilt, 0.01),
        pan_deg=_round(pan, 0.01),
        width=width,
        height=height,
        hfov_deg=60.0,
    )
    scene = SceneDesc(
        camera=cam,
        table=TableDesc(z=0.0, size=(6.0, 6.0)),
        boxes=tuple(boxes),
        description=f"random pallet {seed}: {len(boxes) - 1} cartons",
    )
    check(scene, f"random pallet {seed}")
    return scene
