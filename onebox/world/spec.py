"""A scene as a TOML file (scene/*.toml): read, checked, written, and the geometry it implies.

```toml
[camera]          # the lens in the world, metres; tilt_deg off straight down, about world x
x = 0.0           # (positive looks towards +y), then pan_deg about the vertical
y = 0.0
z = 0.40
tilt_deg = 0.0
pan_deg = 0.0
width = 320
height = 240
hfov_deg = 60.0

[table]
z = 0.0           # the top surface, metres
size = [2.0, 2.0] # along x and y, metres

[[box]]           # any number; box[0] is the first
x = 0.065         # the middle of its footprint
y = 0.040
yaw_deg = 0.0
size = [0.06, 0.06, 0.06]   # length, width, height
on = 0            # optional: stands on box[0] instead of the table
rgba = [0.85, 0.05, 0.05, 1.0]
edges = true      # darker lines along its edges, as the seams of real cartons show
tape = false      # packing tape 48 mm wide along the middle of its top's longer side

[[object]]        # not boxes: cylinder, sphere, capsule, standing on the table
shape = "cylinder"
x = 0.2
y = 0.1
size = [0.03, 0.05]         # MuJoCo's numbers: radius (and half-height)
rgba = [0.2, 0.4, 0.8, 1.0]

[noise]           # see onebox.world.noise
model = "d435"
```

No MuJoCo here: the geometry (where each box stands, the camera's rotation, where the stand
goes) is plain NumPy, so the random scenes and the checks can use it without a renderer.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from onebox.errors import SceneError
from onebox.world.noise import NoiseSpec, noise_spec, noise_table

Float64Array = npt.NDArray[np.float64]

MIN_RANGE_M = 0.05
SHAPES = {"cylinder": 2, "sphere": 1, "capsule": 2}
"""Each object shape and how many numbers its size has (MuJoCo's geom size)."""
CARTON_RGBA = (0.72, 0.55, 0.36, 1.0)
TOUCH_M = 0.001
"""Boxes may touch: overlaps up to a millimetre are not counted as boxes inside each other."""


@dataclass(frozen=True)
class CameraDesc:
    """Where the lens is (metres), which way it looks, and its picture."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.40
    tilt_deg: float = 0.0
    pan_deg: float = 0.0
    width: int = 320
    height: int = 240
    hfov_deg: float = 60.0

    @property
    def focal_px(self) -> float:
        return self.width / 2 / math.tan(math.radians(self.hfov_deg) / 2)


@dataclass(frozen=True)
class TableDesc:
    z: float = 0.0
    size: tuple[float, float] = (2.0, 2.0)


@dataclass(frozen=True)
class BoxDesc:
    x: float
    y: float
    size: tuple[float, float, float]
    yaw_deg: float = 0.0
    on: int | None = None
    rgba: tuple[float, float, float, float] = CARTON_RGBA
    edges: bool = True
    tape: bool = False
    """Packing tape along the middle of the top's longer side, where a carton's flaps meet."""


@dataclass(frozen=True)
class ObjectDesc:
    shape: str
    x: float
    y: float
    size: tuple[float, ...]
    rgba: tuple[float, float, float, float] = (0.5, 0.5, 0.55, 1.0)

    @property
    def height(self) -> float:
        """How tall it stands, metres."""
        if self.shape == "sphere":
            return 2 * self.size[0]
        if self.shape == "capsule":
            return 2 * (self.size[0] + self.size[1])
        return 2 * self.size[1]


@dataclass(frozen=True)
class SceneDesc:
    """A whole world: the camera, the table, the boxes, other objects, the depth noise."""

    camera: CameraDesc = CameraDesc()
    table: TableDesc = TableDesc()
    boxes: tuple[BoxDesc, ...] = ()
    objects: tuple[ObjectDesc, ...] = ()
    noise: NoiseSpec = field(default_factory=NoiseSpec)
    description: str = ""


@dataclass(frozen=True)
class PlacedBox:
    """A box where it stands: its middle, its turn, its edges with length >= width."""

    centre: tuple[float, float, float]
    yaw: float
    """Radians about the vertical: the turn of the box's length from world x."""
    size: tuple[float, float, float]
    on: int | None = None

    @property
    def top_z(self) -> float:
        return self.centre[2] + self.size[2] / 2

    def top_corners(self) -> Float64Array:
        """The top's four corners in the world, (4, 3)."""
        return np.column_stack([self.footprint(), np.full(4, self.top_z)])

    def footprint(self) -> Float64Array:
        """The four corners of its footprint, (4, 2), counter-clockwise."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        half_l, half_w = self.size[0] / 2, self.size[1] / 2
        local = np.array(
            [[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]]
        )
        corners: Float64Array = local @ np.array([[c, s], [-s, c]]) + np.array(self.centre[:2])
        return corners

    def contains(self, point: npt.ArrayLike, margin: float = 0.0) -> bool:
        """Whether a world point is inside the box (grown by ``margin``)."""
        p = np.asarray(point, dtype=np.float64) - np.array(self.centre)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        local = (c * p[0] + s * p[1], -s * p[0] + c * p[1], p[2])
        return all(abs(v) <= h / 2 + margin for v, h in zip(local, self.size, strict=True))

    @property
    def quat_wxyz(self) -> tuple[float, float, float, float]:
        return (math.cos(self.yaw / 2), 0.0, 0.0, math.sin(self.yaw / 2))


# --- the camera ------------------------------------------------------------------------------

LINK_FROM_OPTICAL_WXYZ = (0.5, -0.5, 0.5, -0.5)
"""camera_link -> camera_optical_frame, the fixed quarter turn, as MuJoCo's (w, x, y, z)."""
LOOKING_DOWN_WXYZ = (0.5, -0.5, 0.5, 0.5)
"""camera_link looking straight down, its Z (up) along world +y: the seed's camera_mount."""


def quat_multiply(q: tuple[float, ...], r: tuple[float, ...]) -> tuple[float, float, float, float]:
    """The Hamilton product q r of two (w, x, y, z) quaternions: turn by r, then by q."""
    w1, x1, y1, z1 = q
    w2, x2, y2, z2 = r
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


def quat_matrix(q: tuple[float, ...]) -> Float64Array:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def link_quat(camera: CameraDesc) -> tuple[float, float, float, float]:
    """camera_link in the world: looking down, tilted about world x, then panned about z.

    With no tilt and no pan the turns are exactly (1, 0, 0, 0), so the seed's quaternion comes
    out bit for bit."""
    tilt, pan = math.radians(camera.tilt_deg), math.radians(camera.pan_deg)
    q_tilt = (math.cos(tilt / 2), math.sin(tilt / 2), 0.0, 0.0)
    q_pan = (math.cos(pan / 2), 0.0, 0.0, math.sin(pan / 2))
    return quat_multiply(q_pan, quat_multiply(q_tilt, LOOKING_DOWN_WXYZ))


def world_from_optical(camera: CameraDesc) -> Float64Array:
    """The optical frame's axes in the world (columns: right, down, forward)."""
    return quat_matrix(link_quat(camera)) @ quat_matrix(LINK_FROM_OPTICAL_WXYZ)


def project(camera: CameraDesc, points: npt.ArrayLike) -> Float64Array:
    """World points (n, 3) to (n, 3) of (u, v, depth): pixel u's middle at u (cx = (w-1)/2)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rot = world_from_optical(camera)
    local = (p - np.array([camera.x, camera.y, camera.z])) @ rot
    f = camera.focal_px
    with np.errstate(divide="ignore", invalid="ignore"):
        u = f * local[:, 0] / local[:, 2] + (camera.width - 1) / 2
        v = f * local[:, 1] / local[:, 2] + (camera.height - 1) / 2
    return np.column_stack([u, v, local[:, 2]])


def in_picture(camera: CameraDesc, points: npt.ArrayLike, margin_px: float = 0.0) -> bool:
    """Whether every point is in front of the camera and inside the picture."""
    uvz = project(camera, points)
    lo = -0.5 + margin_px
    return bool(
        np.all(uvz[:, 2] > MIN_RANGE_M)
        and np.all((uvz[:, 0] >= lo) & (uvz[:, 0] <= camera.width - 1 - lo))
        and np.all((uvz[:, 1] >= lo) & (uvz[:, 1] <= camera.height - 1 - lo))
    )


def tops_in_picture(camera: CameraDesc, placed: list[PlacedBox]) -> list[bool]:
    """:func:`in_picture` of every box's four top corners, all projected at once."""
    if not placed:
        return []
    corners = np.concatenate([p.top_corners() for p in placed])
    u, v, z = project(camera, corners).reshape(len(placed), 4, 3).transpose(2, 0, 1)
    inside = (
        (z > MIN_RANGE_M)
        & (u >= -0.5)
        & (u <= camera.width - 0.5)
        & (v >= -0.5)
        & (v <= camera.height - 0.5)
    )
    return [bool(b) for b in np.all(inside, axis=1).tolist()]


def highest_ray_z(camera: CameraDesc) -> float:
    """The largest upward part of any ray in the picture (negative: every ray looks down)."""
    half_w = (camera.width / 2) / camera.focal_px
    half_h = (camera.height / 2) / camera.focal_px
    corners = np.array([[sx * half_w, sy * half_h, 1.0] for sx in (-1, 1) for sy in (-1, 1)])
    rays = corners @ world_from_optical(camera).T
    return float(np.max(rays[:, 2] / np.linalg.norm(rays, axis=1)))


# --- the stand -------------------------------------------------------------------------------

STAND_ARM_RISE_M = 0.05
POST_RADIUS_M, ARM_RADIUS_M = 0.012, 0.008


@dataclass(frozen=True)
class Stand:
    """The post and the arm as (from, to) segments in the world, metres."""

    post: tuple[tuple[float, float, float], tuple[float, float, float]]
    arm: tuple[tuple[float, float, float], tuple[float, float, float]]
    drop: tuple[tuple[float, float, float], tuple[float, float, float]]


def _segment_seen(camera: CameraDesc, a: Float64Array, b: Float64Array, radius: float) -> bool:
    points = a + np.linspace(0.0, 1.0, 200)[:, None] * (b - a)
    uvz = project(camera, points)
    ahead = uvz[:, 2] > 0.005
    margin = camera.focal_px * (radius + 0.01) / np.maximum(uvz[:, 2], 1e-9)
    inside = (
        (uvz[:, 0] > -0.5 - margin)
        & (uvz[:, 0] < camera.width - 0.5 + margin)
        & (uvz[:, 1] > -0.5 - margin)
        & (uvz[:, 1] < camera.height - 0.5 + margin)
    )
    return bool(np.any(ahead & inside))


def stand(camera: CameraDesc, floor_z: float) -> Stand:
    """The stand, drawn from the camera's pose so that none of it comes into view.

    A short drop rises from above the lens to the arm, the arm runs level, STAND_ARM_RISE_M above
    the lens, back to the post, and the post stands on the floor behind the camera, as far back
    as it must be to stay out of the picture. Every ray of the picture looks down (the scene is
    refused otherwise), so the drop and the arm, being above the lens, cannot be seen."""
    rot = world_from_optical(camera)
    forward = rot[:2, 2]
    if np.hypot(*forward) < 1e-6:
        pan = math.radians(camera.pan_deg)
        back = np.array([-math.cos(pan), -math.sin(pan)])
    else:
        back = -forward / np.hypot(*forward)
    lens = np.array([camera.x, camera.y, camera.z])
    arm_z = camera.z + STAND_ARM_RISE_M
    distance = 0.9
    for _ in range(100):
        foot = np.array([*(lens[:2] + distance * back), floor_z])
        top = np.array([foot[0], foot[1], arm_z])
        if not _segment_seen(camera, foot, top, POST_RADIUS_M):
            break
        distance *= 1.1
    else:
        raise SceneError("the camera's stand cannot be put out of view; lower camera.tilt_deg")
    over_lens = (camera.x, camera.y, arm_z)
    post_top = (float(top[0]), float(top[1]), arm_z)
    return Stand(
        post=((float(foot[0]), float(foot[1]), floor_z), post_top),
        arm=(post_top, over_lens),
        drop=((camera.x, camera.y, camera.z + 0.02), over_lens),
    )


# --- boxes -----------------------------------------------------------------------------------


def place(scene: SceneDesc) -> list[PlacedBox]:
    """Where each box stands: on the table, or on the box named by ``on``; length >= width."""
    placed: list[PlacedBox] = []
    for box in scene.boxes:
        length, width, height = box.size
        yaw = math.radians(box.yaw_deg)
        if width > length:
            length, width = width, length
            yaw += math.pi / 2
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        base = scene.table.z if box.on is None else placed[box.on].top_z
        placed.append(
            PlacedBox((box.x, box.y, base + height / 2), yaw, (length, width, height), box.on)
        )
    return placed


def footprint_overlap(a: Float64Array, b: Float64Array) -> float:
    """How deep two convex footprints (corners counter-clockwise) overlap; <= 0 apart."""
    depth = math.inf
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for edge in edges:
            normal = np.array([-edge[1], edge[0]]) / np.hypot(*edge)
            pa, pb = a @ normal, b @ normal
            depth = min(depth, min(pa.max(), pb.max()) - max(pa.min(), pb.min()))
    return depth


def _object_box(obj: ObjectDesc, table_z: float) -> PlacedBox:
    """An object's bounding box, for the checks."""
    r = obj.size[0]
    return PlacedBox((obj.x, obj.y, table_z + obj.height / 2), 0.0, (2 * r, 2 * r, obj.height))


def check(scene: SceneDesc, where: str = "scene") -> None:
    """Refuse a scene that cannot be built, naming the key: a box in mid-air or inside another,
    a camera inside a box or under the table, a view that looks above the horizon."""
    cam, table = scene.camera, scene.table
    if cam.width < 1 or cam.height < 1:
        raise SceneError(f"{where}: camera.width x height {cam.width} x {cam.height}: both >= 1")
    if not 1.0 <= cam.hfov_deg <= 170.0:
        raise SceneError(f"{where}: camera.hfov_deg {cam.hfov_deg}: use 1 to 170 degrees")
    if cam.z <= table.z + MIN_RANGE_M:
        raise SceneError(
            f"{where}: camera.z {cam.z} m: the camera must be more than {MIN_RANGE_M} m above "
            f"the table (table.z {table.z} m)"
        )
    if highest_ray_z(cam) >= -0.01:
        raise SceneError(
            f"{where}: camera.tilt_deg {cam.tilt_deg} with hfov_deg {cam.hfov_deg:g} sees up to "
            "the horizon, where the stand's arm is; lower camera.tilt_deg or the lens angle"
        )
    if min(table.size) <= 0:
        raise SceneError(f"{where}: table.size {list(table.size)}: both must be above 0")
    placed = place(scene)
    half_x, half_y = table.size[0] / 2, table.size[1] / 2
    for i, (box, p) in enumerate(zip(scene.boxes, placed, strict=True)):
        if box.on is None:
            if abs(box.x) > half_x or abs(box.y) > half_y:
                raise SceneError(
                    f"{where}: box[{i}] at ({box.x}, {box.y}) is off the table (table.size "
                    f"{list(table.size)}) and would stand in mid-air; move box[{i}].x, y"
                )
        else:
            support = placed[box.on]
            probe = (box.x, box.y, support.top_z - 1e-6)
            if not support.contains(probe):
                raise SceneError(
                    f"{where}: box[{i}].on = {box.on}, but its middle ({box.x}, {box.y}) is not "
                    f"over box[{box.on}]'s top: it would stand in mid-air; move box[{i}].x, y"
                )
        for j in range(i):
            other = placed[j]
            z_overlap = min(p.top_z, other.top_z) - max(
                p.centre[2] - p.size[2] / 2, other.centre[2] - other.size[2] / 2
            )
            if z_overlap > TOUCH_M and footprint_overlap(p.footprint(), other.footprint()) > (
                TOUCH_M
            ):
                raise SceneError(
                    f"{where}: box[{i}] and box[{j}] are inside each other; move box[{i}].x, y "
                    f"or stand it on box[{j}] with box[{i}].on = {j}"
                )
    lens = (cam.x, cam.y, cam.z)
    for i, p in enumerate(placed):
        if p.contains(lens, margin=0.01):
            raise SceneError(
                f"{where}: the camera at {lens} is inside box[{i}]; raise camera.z above "
                f"{p.top_z + 0.01:.3f} m or move the box"
            )
    for i, obj in enumerate(scene.objects):
        if abs(obj.x) > half_x or abs(obj.y) > half_y:
            raise SceneError(f"{where}: object[{i}] at ({obj.x}, {obj.y}) is off the table")
        if _object_box(obj, table.z).contains(lens, margin=0.01):
            raise SceneError(f"{where}: the camera at {lens} is inside object[{i}]")


# --- reading and writing ---------------------------------------------------------------------

_CAMERA_KEYS = ("x", "y", "z", "tilt_deg", "pan_deg", "width", "height", "hfov_deg")
_TABLE_KEYS = ("z", "size")
_BOX_KEYS = ("x", "y", "yaw_deg", "size", "on", "rgba", "edges", "tape")
_OBJECT_KEYS = ("shape", "x", "y", "size", "rgba")
_TOP_KEYS = ("description", "camera", "table", "box", "object", "noise")


def _unknown(table: dict[str, Any], known: tuple[str, ...], where: str) -> None:
    extra = [k for k in table if k not in known]
    if extra:
        raise SceneError(f"unknown key {where}.{extra[0]} (known: {', '.join(known)})")


def _number(table: dict[str, Any], key: str, where: str, fallback: float | None = None) -> float:
    if key not in table:
        if fallback is None:
            raise SceneError(f"{where}.{key} is missing: give it in metres (or degrees)")
        return fallback
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SceneError(f"{where}.{key} = {value!r}: expected a number")
    return float(value)


def _whole(table: dict[str, Any], key: str, where: str, fallback: int) -> int:
    value = table.get(key, fallback)
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(f"{where}.{key} = {value!r}: expected a whole number")
    return value


def _numbers(
    table: dict[str, Any], key: str, where: str, count: int, fallback: tuple[float, ...] | None
) -> tuple[float, ...]:
    if key not in table:
        if fallback is None:
            raise SceneError(f"{where}.{key} is missing: give {count} numbers")
        return fallback
    value = table[key]
    if (
        not isinstance(value, list)
        or len(value) != count
        or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
    ):
        raise SceneError(f"{where}.{key} = {value!r}: expected a list of {count} numbers")
    return tuple(float(v) for v in value)


def _rgba(table: dict[str, Any], where: str, fallback: tuple[float, ...]) -> Any:
    rgba = _numbers(table, "rgba", where, 4, fallback)
    if any(not 0.0 <= v <= 1.0 for v in rgba):
        raise SceneError(f"{where}.rgba = {list(rgba)}: each from 0 to 1")
    return rgba


def _positive(values: tuple[float, ...], key: str) -> None:
    if any(v <= 0 for v in values):
        raise SceneError(f"{key} = {list(values)}: every size must be above 0 m")


def parse(tables: dict[str, Any], where: str = "scene") -> SceneDesc:
    """A scene from a parsed TOML document; ``where`` (the file) starts every error."""
    try:
        scene = _parse(tables)
    except SceneError as e:
        raise SceneError(f"{where}: {e}") from None
    check(scene, where)
    return scene


def _parse(tables: dict[str, Any]) -> SceneDesc:
    _unknown(tables, _TOP_KEYS, "scene")
    for key in ("camera", "table", "noise"):
        if not isinstance(tables.get(key, {}), dict):
            raise SceneError(f"{key} must be a table: [{key}]")
    for key in ("box", "object"):
        if not isinstance(tables.get(key, []), list):
            raise SceneError(f"{key} must be an array of tables: [[{key}]]")
    c = tables.get("camera", {})
    _unknown(c, _CAMERA_KEYS, "camera")
    d = CameraDesc()
    camera = CameraDesc(
        x=_number(c, "x", "camera", d.x),
        y=_number(c, "y", "camera", d.y),
        z=_number(c, "z", "camera", d.z),
        tilt_deg=_number(c, "tilt_deg", "camera", d.tilt_deg),
        pan_deg=_number(c, "pan_deg", "camera", d.pan_deg),
        width=_whole(c, "width", "camera", d.width),
        height=_whole(c, "height", "camera", d.height),
        hfov_deg=_number(c, "hfov_deg", "camera", d.hfov_deg),
    )
    t = tables.get("table", {})
    _unknown(t, _TABLE_KEYS, "table")
    size = _numbers(t, "size", "table", 2, TableDesc().size)
    table = TableDesc(z=_number(t, "z", "table", 0.0), size=(size[0], size[1]))
    boxes = []
    for i, b in enumerate(tables.get("box", [])):
        where = f"box[{i}]"
        _unknown(b, _BOX_KEYS, where)
        box_size = _numbers(b, "size", where, 3, None)
        _positive(box_size, f"{where}.size")
        on = b.get("on")
        if on is not None and (isinstance(on, bool) or not isinstance(on, int) or not 0 <= on < i):
            raise SceneError(f"{where}.on = {on!r}: the index of a box before it (0 to {i - 1})")
        edges, tape = b.get("edges", True), b.get("tape", False)
        for key, flag in (("edges", edges), ("tape", tape)):
            if not isinstance(flag, bool):
                raise SceneError(f"{where}.{key} = {flag!r}: expected true or false")
        boxes.append(
            BoxDesc(
                x=_number(b, "x", where),
                y=_number(b, "y", where),
                size=(box_size[0], box_size[1], box_size[2]),
                yaw_deg=_number(b, "yaw_deg", where, 0.0),
                on=on,
                rgba=_rgba(b, where, CARTON_RGBA),
                edges=edges,
                tape=tape,
            )
        )
    objects = []
    for i, o in enumerate(tables.get("object", [])):
        where = f"object[{i}]"
        _unknown(o, _OBJECT_KEYS, where)
        shape = o.get("shape")
        if shape not in SHAPES:
            raise SceneError(f"{where}.shape = {shape!r}: use one of {', '.join(SHAPES)}")
        numbers = _numbers(o, "size", where, SHAPES[shape], None)
        _positive(numbers, f"{where}.size")
        objects.append(
            ObjectDesc(
                shape=shape,
                x=_number(o, "x", where),
                y=_number(o, "y", where),
                size=numbers,
                rgba=_rgba(o, where, ObjectDesc("sphere", 0, 0, (1.0,)).rgba),
            )
        )
    description = tables.get("description", "")
    if not isinstance(description, str):
        raise SceneError(f"description = {description!r}: expected a string")
    return SceneDesc(
        camera=camera,
        table=table,
        boxes=tuple(boxes),
        objects=tuple(objects),
        noise=noise_spec(tables.get("noise", {})),
        description=description,
    )


def load(path: Path) -> SceneDesc:
    """Read and check a scene file; any problem is one SceneError naming the file and key."""
    try:
        with path.open("rb") as f:
            tables = tomllib.load(f)
    except FileNotFoundError:
        raise SceneError(f"no scene file {path}: give a path to a .toml scene") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path} is not valid TOML: {e}") from None
    return parse(tables, str(path))


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(float(v))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return "[" + ", ".join(_value(x) for x in v) + "]"


def dumps(scene: SceneDesc) -> str:
    """The scene as TOML that ``load`` reads back to the same scene, number for number."""
    lines: list[str] = []
    if scene.description:
        lines.append(f"description = {_value(scene.description)}")
        lines.append("")
    lines.append("[camera]")
    for f in dataclasses.fields(CameraDesc):
        lines.append(f"{f.name} = {_value(getattr(scene.camera, f.name))}")
    lines += ["", "[table]", f"z = {_value(scene.table.z)}", f"size = {_value(scene.table.size)}"]
    for box in scene.boxes:
        lines += ["", "[[box]]", f"x = {_value(box.x)}", f"y = {_value(box.y)}"]
        lines.append(f"yaw_deg = {_value(box.yaw_deg)}")
        lines.append(f"size = {_value(box.size)}")
        if box.on is not None:
            lines.append(f"on = {box.on}")
        lines.append(f"rgba = {_value(box.rgba)}")
        if not box.edges:
            lines.append("edges = false")
        if box.tape:
            lines.append("tape = true")
    for obj in scene.objects:
        lines += ["", "[[object]]", f"shape = {_value(obj.shape)}"]
        lines += [f"x = {_value(obj.x)}", f"y = {_value(obj.y)}", f"size = {_value(obj.size)}"]
        lines.append(f"rgba = {_value(obj.rgba)}")
    noise = noise_table(scene.noise)
    if noise != {"model": "none"}:
        lines += ["", "[noise]"] + [f"{k} = {_value(v)}" for k, v in noise.items()]
    return "\n".join(lines) + "\n"


def with_lens(
    scene: SceneDesc,
    width: int | None = None,
    height: int | None = None,
    hfov_deg: float | None = None,
) -> SceneDesc:
    """The scene with the camera's picture size and lens angle overridden where given."""
    changes: dict[str, Any] = {}
    if width is not None:
        changes["width"] = width
    if height is not None:
        changes["height"] = height
    if hfov_deg is not None:
        changes["hfov_deg"] = hfov_deg
    return dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, **changes))


def pixel_rays(camera: CameraDesc) -> Float64Array:
    """Every pixel's ray in the world, (height, width, 3), scaled so its optical z is 1: a
    point at depth d along pixel (v, u)'s ray is the lens + d * rays[v, u]."""
    f = camera.focal_px
    u = (np.arange(camera.width) - (camera.width - 1) / 2) / f
    v = (np.arange(camera.height) - (camera.height - 1) / 2) / f
    optical = np.stack(
        [np.broadcast_to(u, (camera.height, camera.width)), v[:, None].repeat(camera.width, 1)],
        axis=-1,
    )
    optical = np.concatenate([optical, np.ones((camera.height, camera.width, 1))], axis=-1)
    return optical @ world_from_optical(camera).T


def top_depths(camera: CameraDesc, box: PlacedBox, rays: Float64Array) -> Float64Array:
    """The depth at which each pixel's ray meets the box's top, NaN where it misses the top."""
    lens = np.array([camera.x, camera.y, camera.z])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (box.top_z - lens[2]) / rays[..., 2]
    hit = lens[:2] + t[..., None] * rays[..., :2] - np.array(box.centre[:2])
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    along = c * hit[..., 0] + s * hit[..., 1]
    across = -s * hit[..., 0] + c * hit[..., 1]
    on_top = (np.abs(along) <= box.size[0] / 2) & (np.abs(across) <= box.size[1] / 2) & (t > 0)
    return np.where(on_top, t, np.nan)


def visible_top_pixels(
    camera: CameraDesc, boxes: list[PlacedBox], depth_m: npt.NDArray[np.float32]
) -> list[int]:
    """For each box, how many pixels see its top: the ray meets the top, and the noise-free
    rendered depth there is the top's (within 1 mm + 0.05 %), not something nearer."""
    rays = pixel_rays(camera)
    counts = []
    for box in boxes:
        expected = top_depths(camera, box, rays)
        with np.errstate(invalid="ignore"):
            seen = np.abs(depth_m - expected) <= 0.001 + 0.0005 * expected
        counts.append(int(np.count_nonzero(seen)))
    return counts
