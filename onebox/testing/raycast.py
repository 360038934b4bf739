"""Depth and colour pictures of boxes and other things on a surface, worked out by casting rays.

Every pixel's ray is intersected analytically with every shape (a plane, oriented boxes, upright
or tilted cylinders, spheres), so a test knows the exact answer: each box's centre, size and
yaw. The noise models of real depth cameras are added afterwards by :func:`add_noise`.

Conventions are those of the pipeline: the lens follows CameraInfo (the middle of pixel ``u`` is
at ``u``), the optical frame is X right, Y down, Z forward, depth is metres along the optical
axis, float32, NaN where a ray hits nothing. The world frame is Z up.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from onebox.geometry import Intrinsics
from onebox.rectify import distort

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]
Vec3 = tuple[float, float, float]
Rgb = tuple[int, int, int]


def _unit(v: Sequence[float] | npt.NDArray[np.floating]) -> Float64Array:
    a = np.asarray(v, dtype=np.float64)
    result: Float64Array = a / np.linalg.norm(a)
    return result


def frame_from_normal(normal: Sequence[float] | Float64Array, yaw_deg: float = 0.0) -> Float64Array:
    """A rotation whose z column is ``normal`` and whose x column is turned ``yaw_deg`` about it.

    Yaw 0 puts x as close to world +x as the normal allows (world +y when the normal is +x).
    """
    z = _unit(normal)
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x0 = _unit(ref - z * (ref @ z))
    y0 = np.cross(z, x0)
    yaw = math.radians(yaw_deg)
    x = math.cos(yaw) * x0 + math.sin(yaw) * y0
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


@dataclass(frozen=True)
class Camera:
    """A camera: picture size, lens and its pose (optical frame into the world).

    A pinhole, unless ``distortion`` (a CameraInfo's model and coefficients) bends its rays as
    a real lens does: then its pictures are what a camera publishing ``image_raw`` sends.
    """

    width: int
    height: int
    lens: Intrinsics
    camera_to_world: Float64Array
    distortion: tuple[str, tuple[float, ...]] | None = None

    def distorted(self, model: str, coefficients: Sequence[float]) -> Camera:
        """This camera with a lens that distorts."""
        return dataclasses.replace(self, distortion=(model, tuple(coefficients)))

    @classmethod
    def looking_at(
        cls,
        eye: Sequence[float],
        target: Sequence[float],
        width: int = 320,
        height: int = 240,
        hfov_deg: float = 60.0,
        roll_deg: float = 0.0,
    ) -> Camera:
        """A camera at ``eye`` looking at ``target``; picture "up" as close to world +y/+z as
        possible (world +y when looking straight down, as the seed's camera)."""
        forward = _unit(np.subtract(target, eye))
        hint = np.array([0.0, 0.0, -1.0])
        if abs(forward @ hint) > 0.999:
            hint = np.array([0.0, -1.0, 0.0])
        down = _unit(hint - forward * (hint @ forward))
        right = np.cross(down, forward)  # optical X = Y x Z
        rot = np.stack([right, down, forward], axis=1)
        if roll_deg:
            c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
            rot = rot @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        matrix = np.eye(4)
        matrix[:3, :3] = rot
        matrix[:3, 3] = eye
        fx = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
        lens = Intrinsics(fx, fx, (width - 1) / 2, (height - 1) / 2)
        return cls(width, height, lens, matrix)

    @classmethod
    def tilted(
        cls,
        height_m: float,
        tilt_deg: float,
        target: Sequence[float] = (0.0, 0.0, 0.0),
        width: int = 320,
        height: int = 240,
        hfov_deg: float = 60.0,
        azimuth_deg: float = -90.0,
    ) -> Camera:
        """A camera ``height_m`` above ``target`` (world z), looking at it ``tilt_deg`` from
        straight down, standing off toward ``azimuth_deg`` (-90: on the -y side)."""
        tilt, az = math.radians(tilt_deg), math.radians(azimuth_deg)
        horizontal = height_m * math.tan(tilt)
        eye = (
            target[0] + horizontal * math.cos(az),
            target[1] + horizontal * math.sin(az),
            target[2] + height_m,
        )
        return cls.looking_at(eye, target, width, height, hfov_deg)


@dataclass(frozen=True)
class Plane:
    """An endless flat surface through ``point`` with ``normal`` (pointing up)."""

    point: Vec3 = (0.0, 0.0, 0.0)
    normal: Vec3 = (0.0, 0.0, 1.0)
    colour: Rgb = (150, 150, 140)


@dataclass(frozen=True)
class Mark:
    """A patch of another colour on a box's top (a label, packing tape, a print): ``x`` and
    ``y`` ranges in the box's own axes, from the top's middle; drawn in order."""

    x: tuple[float, float]
    y: tuple[float, float]
    colour: Rgb


@dataclass(frozen=True)
class Box:
    """A box: ``centre`` of the whole box, ``size`` along its own x, y, z, ``rotation`` 3 x 3."""

    centre: Vec3
    size: Vec3
    rotation: tuple[Vec3, Vec3, Vec3] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    colour: Rgb = (190, 60, 50)
    lid_m: float = 0.0
    """The lid bulges up (+) or sags (-) this much at its middle, smoothly to flat at its rim
    (cos x cos), as an overfilled or a soft carton's does; ``size`` is to the rim."""
    marks: tuple[Mark, ...] = ()

    @property
    def matrix(self) -> Float64Array:
        return np.asarray(self.rotation, dtype=np.float64)

    @property
    def top_middle(self) -> Float64Array:
        result: Float64Array = np.asarray(self.centre) + self.matrix[:, 2] * self.size[2] / 2
        return result

    def yaw_deg(self) -> float:
        """Yaw of the longer horizontal side about the box's own z, in (-90, 90]."""
        axis = self.matrix[:, 0] if self.size[0] >= self.size[1] else self.matrix[:, 1]
        yaw = math.degrees(math.atan2(axis[1], axis[0]))
        return (yaw + 90.0) % 180.0 - 90.0 if yaw != 90.0 else 90.0


@dataclass(frozen=True)
class Cylinder:
    """A cylinder around its own z axis: ``centre`` of the whole, ``radius``, ``length``."""

    centre: Vec3
    radius: float
    length: float
    rotation: tuple[Vec3, Vec3, Vec3] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    colour: Rgb = (60, 120, 190)


def table_on_legs(
    size: tuple[float, float], height_m: float, yaw_deg: float = 0.0, top_m: float = 0.03
) -> tuple[Box, ...]:
    """A table on the plane z = 0, its middle over the origin: a top ``top_m`` thick whose
    upper face is ``height_m`` up, on four legs 4 cm square set 2 cm in from its corners."""
    top = box_on(Plane(), 0.0, 0.0, (*size, top_m), yaw_deg, (150, 140, 130))
    top = dataclasses.replace(top, centre=(0.0, 0.0, height_m - top_m / 2))
    yaw = math.radians(yaw_deg)
    legs = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (size[0] / 2 - 0.04), sy * (size[1] / 2 - 0.04)
            middle = (x * math.cos(yaw) - y * math.sin(yaw), x * math.sin(yaw) + y * math.cos(yaw))
            legs.append(box_on(Plane(), *middle, (0.04, 0.04, height_m - top_m), yaw_deg))
    return (top, *legs)


def lying(x: float, y: float, radius: float, length: float, yaw_deg: float) -> Cylinder:
    """A cylinder lying on the plane z = 0 (a can or a roll on its side), its axis turned
    ``yaw_deg`` from x."""
    yaw = math.radians(yaw_deg)
    axis = (math.cos(yaw), math.sin(yaw), 0.0)
    side = (-math.sin(yaw), math.cos(yaw), 0.0)
    rotation = tuple(zip(side, (0.0, 0.0, 1.0), axis, strict=True))
    return Cylinder((x, y, radius), radius, length, rotation)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Sphere:
    """A ball."""

    centre: Vec3
    radius: float
    colour: Rgb = (60, 170, 80)


Shape = Box | Cylinder | Sphere


def box_on(
    plane: Plane | Box,
    x: float,
    y: float,
    size: Vec3,
    yaw_deg: float = 0.0,
    colour: Rgb = (190, 60, 50),
) -> Box:
    """A box standing on a plane (at the world point nearest (x, y) in the plane's own axes) or
    on top of another box ((x, y) from the middle of its top, in its own axes)."""
    if isinstance(plane, Plane):
        rot = frame_from_normal(plane.normal, 0.0)
        origin = np.asarray(plane.point, dtype=np.float64)
        n = rot[:, 2]
        # (x, y) are world x, y: the plane's point straight above or below them.
        base = np.array([x, y, 0.0])
        base[2] = origin[2] - (n[0] * (x - origin[0]) + n[1] * (y - origin[1])) / n[2]
    else:
        rot = plane.matrix
        base = plane.top_middle + rot[:, 0] * x + rot[:, 1] * y
    yaw_rot = frame_from_normal(rot[:, 2], 0.0)
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    own = yaw_rot @ turn
    centre = base + own[:, 2] * size[2] / 2
    rows = tuple(tuple(float(v) for v in row) for row in own)
    return Box(
        tuple(float(v) for v in centre),  # type: ignore[arg-type]
        size,
        rows,  # type: ignore[arg-type]
        colour,
    )


def taped(
    box: Box,
    colour: Rgb = (185, 140, 90),
    width_m: float = 0.048,
    flap_line: Rgb | None = None,
) -> Box:
    """``box`` as a taped carton: packing tape ``width_m`` wide along the middle of its top's
    longer side, where its flaps meet, and the line between the flaps (``flap_line``: seen
    through clear tape) drawn 3 mm wide over it."""
    along_x = box.size[0] >= box.size[1]
    long_half = max(box.size[0], box.size[1]) / 2
    marks = []
    for half_width, mark_colour in ((width_m / 2, colour), (0.0015, flap_line)):
        if mark_colour is None:
            continue
        span, across = (-long_half, long_half), (-half_width, half_width)
        marks.append(
            Mark(span, across, mark_colour) if along_x else Mark(across, span, mark_colour)
        )
    return dataclasses.replace(box, marks=(*box.marks, *marks))


@dataclass(frozen=True)
class Scene:
    """What the camera sees: a plane (optional) and shapes; ``seam_m`` darkens box top edges
    that wide in the colour picture (to ``seam_shade`` of their colour), as a carton's edge and
    the seam between two cartons; ``seam_fades``: the darkening fades in across ``seam_m``, as
    the shadow in a seam does, with no sharp step."""

    camera: Camera
    plane: Plane | None = field(default_factory=Plane)
    shapes: tuple[Shape, ...] = ()
    seam_m: float = 0.001
    seam_shade: float = 0.45
    seam_fades: bool = False

    @property
    def boxes(self) -> list[Box]:
        return [s for s in self.shapes if isinstance(s, Box)]


def undistort(
    model: str, d: Sequence[float], xd: Float64Array, yd: Float64Array
) -> tuple[Float64Array, Float64Array]:
    """The pinhole point a lens distorts to (xd, yd): the inverse of :func:`rectify.distort`,
    by Newton's method on it (numerical Jacobian), to 1e-12."""
    x, y = xd.copy(), yd.copy()
    h = 1e-7
    for _ in range(50):
        fx, fy = distort(model, d, x, y)
        ex, ey = fx - xd, fy - yd
        if max(float(np.abs(ex).max()), float(np.abs(ey).max())) < 1e-12:
            break
        ax, ay = distort(model, d, x + h, y)
        bx, by = distort(model, d, x, y + h)
        j11, j21 = (ax - fx) / h, (ay - fy) / h
        j12, j22 = (bx - fx) / h, (by - fy) / h
        det = j11 * j22 - j12 * j21
        x = x - (j22 * ex - j12 * ey) / det
        y = y - (j11 * ey - j21 * ex) / det
    else:
        raise ValueError(f"{model} {list(d)} cannot be undone over this picture")
    return x, y


def _world_rays(camera: Camera) -> tuple[Float64Array, Float64Array]:
    """Camera position (3,) and, per pixel, the world direction whose optical z is 1 (H, W, 3)."""
    across, down = camera.lens.rays(camera.width, camera.height)
    optical = np.empty((camera.height, camera.width, 3))
    optical[..., 0] = across[np.newaxis, :]
    optical[..., 1] = down[:, np.newaxis]
    optical[..., 2] = 1.0
    if camera.distortion is not None:
        model, d = camera.distortion
        optical[..., 0], optical[..., 1] = undistort(model, d, optical[..., 0], optical[..., 1])
    rot = camera.camera_to_world[:3, :3]
    world: Float64Array = optical @ rot.T
    origin: Float64Array = camera.camera_to_world[:3, 3].copy()
    return origin, world


def _hit_box(
    origin: Float64Array, dirs: Float64Array, box: Box
) -> tuple[Float64Array, Float64Array, Float64Array]:
    """Distance along each ray to the box (inf for a miss), the face normal, the local point."""
    rot = box.matrix
    o = (origin - np.asarray(box.centre)) @ rot
    d = dirs @ rot
    half = np.asarray(box.size) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (-half - o) * inv
        t2 = (half - o) * inv
    near = np.fmin(t1, t2)
    far = np.fmax(t1, t2)
    t_near = near.max(axis=-1)
    t_far = far.min(axis=-1)
    hit = (t_far >= t_near) & (t_near > 0)
    t = np.where(hit, t_near, np.inf)
    axis = near.argmax(axis=-1)
    sign = -np.sign(np.take_along_axis(d, axis[..., np.newaxis], axis=-1))[..., 0]
    local_normal = np.zeros(d.shape)
    np.put_along_axis(local_normal, axis[..., np.newaxis], sign[..., np.newaxis], axis=-1)
    local = o + d * np.where(hit, t, 0.0)[..., np.newaxis]
    return t, local_normal @ rot.T, local


def _hit_cylinder(
    origin: Float64Array, dirs: Float64Array, cyl: Cylinder
) -> tuple[Float64Array, Float64Array]:
    rot = np.asarray(cyl.rotation, dtype=np.float64)
    o = (origin - np.asarray(cyl.centre)) @ rot
    d = dirs @ rot
    half = cyl.length / 2
    a = d[..., 0] ** 2 + d[..., 1] ** 2
    b = 2 * (o[0] * d[..., 0] + o[1] * d[..., 1])
    c = o[0] ** 2 + o[1] ** 2 - cyl.radius**2
    disc = b * b - 4 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-b - np.sqrt(disc)) / (2 * a)
        z_side = o[2] + t_side * d[..., 2]
        side_ok = (disc >= 0) & (t_side > 0) & (np.abs(z_side) <= half)
        t_side = np.where(side_ok, t_side, np.inf)
        caps = []
        for z_cap in (half, -half):
            t_cap = (z_cap - o[2]) / d[..., 2]
            px = o[0] + t_cap * d[..., 0]
            py = o[1] + t_cap * d[..., 1]
            ok = (t_cap > 0) & (px * px + py * py <= cyl.radius**2)
            caps.append(np.where(ok, t_cap, np.inf))
    t = np.minimum(t_side, np.minimum(caps[0], caps[1]))
    p = o + d * np.where(np.isfinite(t), t, 0.0)[..., np.newaxis]
    normal = np.zeros(d.shape)
    on_side = t == t_side
    normal[..., 0] = np.where(on_side, p[..., 0], 0.0)
    normal[..., 1] = np.where(on_side, p[..., 1], 0.0)
    normal[..., 2] = np.where(on_side, 0.0, np.sign(p[..., 2]))
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    return t, normal @ rot.T


def _hit_sphere(
    origin: Float64Array, dirs: Float64Array, ball: Sphere
) -> tuple[Float64Array, Float64Array]:
    o = origin - np.asarray(ball.centre)
    a = np.einsum("...i,...i->...", dirs, dirs)
    b = 2 * dirs @ o
    c = o @ o - ball.radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / (2 * a)
    t = np.where((disc >= 0) & (t > 0), t, np.inf)
    p = o + dirs * np.where(np.isfinite(t), t, 0.0)[..., np.newaxis]
    return t, p / ball.radius


def render(scene: Scene) -> tuple[Float32Array, npt.NDArray[np.uint8]]:
    """The scene's depth (metres, NaN where nothing is hit) and colour (H x W x 3 rgb8)."""
    origin, dirs = _world_rays(scene.camera)
    shape = dirs.shape[:2]
    depth = np.full(shape, np.inf)
    normal = np.zeros((*shape, 3))
    base = np.zeros((*shape, 3))
    shade_mul = np.ones(shape)
    if scene.plane is not None:
        n = np.asarray(scene.plane.normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((np.asarray(scene.plane.point) - origin) @ n) / (dirs @ n)
        t = np.where(t > 0, t, np.inf)
        hit = t < depth
        depth[hit] = t[hit]
        normal[hit] = n
        base[hit] = scene.plane.colour
    for shape_ in scene.shapes:
        paint = np.broadcast_to(np.asarray(shape_.colour, dtype=np.float64), (*shape, 3))
        if isinstance(shape_, Box):
            t, nrm, local = _hit_box(origin, dirs, shape_)
            half = np.asarray(shape_.size) / 2
            # The top face's rim: a carton's edge, the dark line between two touching cartons.
            on_top = local[..., 2] > half[2] - 1e-9
            if shape_.lid_m:
                # The lid's point over (x, y) moves along the box's z: t' = t + b / (d . z).
                bump = shape_.lid_m * np.cos(
                    np.pi * np.clip(local[..., 0] / shape_.size[0], -0.5, 0.5)
                )
                bump *= np.cos(np.pi * np.clip(local[..., 1] / shape_.size[1], -0.5, 0.5))
                along = dirs @ shape_.matrix[:, 2]
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = np.where(on_top & np.isfinite(t), t + bump / along, t)
            rim = np.minimum(half[0] - np.abs(local[..., 0]), half[1] - np.abs(local[..., 1]))
            fade = np.clip(rim / scene.seam_m, 0.0, 1.0) if scene.seam_fades else 0.0
            dark = np.where(
                on_top & (rim < scene.seam_m), 1.0 - (1.0 - scene.seam_shade) * (1.0 - fade), 1.0
            )
            if shape_.marks:
                paint = paint.copy()
                for mark in shape_.marks:
                    paint[
                        on_top
                        & (local[..., 0] >= mark.x[0])
                        & (local[..., 0] <= mark.x[1])
                        & (local[..., 1] >= mark.y[0])
                        & (local[..., 1] <= mark.y[1])
                    ] = mark.colour
        elif isinstance(shape_, Cylinder):
            t, nrm = _hit_cylinder(origin, dirs, shape_)
            dark = np.ones(shape)
        else:
            t, nrm = _hit_sphere(origin, dirs, shape_)
            dark = np.ones(shape)
        hit = t < depth
        depth[hit] = t[hit]
        normal[hit] = nrm[hit]
        base[hit] = paint[hit]
        shade_mul[hit] = dark[hit]
    light = _unit((0.3, 0.2, 1.0))
    shade = 0.35 + 0.65 * np.abs(normal @ light)
    colour = np.clip(base * (shade * shade_mul)[..., np.newaxis], 0, 255).astype(np.uint8)
    depth_m = np.where(np.isfinite(depth), depth, np.nan).astype(np.float32)
    return depth_m, colour


@dataclass(frozen=True)
class Noise:
    """Depth camera noise. Every field 0 means that effect is off.

    - ``sigma_m``: gaussian noise, the same everywhere;
    - ``axial_a_m``, ``axial_b_per_m``, ``axial_c_m``: axial noise sigma(z) = a + b (z - c)^2
      (Azure Kinect-like: a ~ 1.5 mm, b ~ 2.5 mm/m^2, c ~ 0.4 m; a D435 grows faster);
    - ``quantum_m``: readings rounded to this (0.001 for millimetre depth);
    - ``edge_hole_share``: share of pixels within ``edge_px`` of a depth edge that read nothing;
    - ``flying_share``: share of depth-edge pixels that read a mix of the two sides;
    - ``speckle_share``: share of pixels that read much nearer (0.3-0.9 of the truth), alone or
      in clumps of up to ``speckle_clump_px`` across;
    - ``correlation_px``: the gaussian and axial noise smoothed over this many pixels (a
      Gaussian's sigma) and scaled back to its sigma, as a stereo camera's matching window
      and a depth filter leave it: neighbours err together, in lumps.
    """

    sigma_m: float = 0.0
    axial_a_m: float = 0.0
    axial_b_per_m: float = 0.0
    axial_c_m: float = 0.0
    quantum_m: float = 0.0
    edge_hole_share: float = 0.0
    edge_px: int = 1
    edge_step_m: float = 0.01
    flying_share: float = 0.0
    speckle_share: float = 0.0
    speckle_clump_px: int = 1
    correlation_px: float = 0.0

    @classmethod
    def kinect(cls) -> Noise:
        """Roughly an Azure Kinect NFOV: 1.5 mm + growth, mm steps, holes and flying pixels."""
        return cls(
            axial_a_m=0.0015,
            axial_b_per_m=0.0025,
            axial_c_m=0.4,
            quantum_m=0.001,
            edge_hole_share=0.5,
            edge_px=1,
            flying_share=0.3,
            speckle_share=0.001,
            speckle_clump_px=3,
        )

    @classmethod
    def d435(cls) -> Noise:
        """Roughly a RealSense D435 (stereo: sigma grows with z^2), holes at edges, speckles."""
        return cls(
            axial_a_m=0.001,
            axial_b_per_m=0.002,
            axial_c_m=0.0,
            quantum_m=0.001,
            edge_hole_share=0.6,
            edge_px=2,
            flying_share=0.2,
            speckle_share=0.002,
            speckle_clump_px=4,
        )


def add_noise(depth_m: Float32Array, noise: Noise, rng: np.random.Generator) -> Float32Array:
    """A noisy copy of a clean depth picture (NaN stays NaN; holes become NaN)."""
    d = depth_m.astype(np.float64)
    valid = np.isfinite(d)
    filled = np.where(valid, d, 0.0)
    out = d.copy()
    if noise.edge_hole_share > 0 or noise.flying_share > 0:
        # A depth edge: a neighbour more than edge_step_m away (or no reading at all).
        big = np.zeros(d.shape, dtype=bool)
        near_side = np.zeros(d.shape)
        for axis in (0, 1):
            diff = np.diff(filled, axis=axis)
            step = (np.abs(diff) > noise.edge_step_m) | (np.diff(valid, axis=axis) != 0)
            sl_a = [slice(None), slice(None)]
            sl_b = [slice(None), slice(None)]
            sl_a[axis] = slice(None, -1)
            sl_b[axis] = slice(1, None)
            big[tuple(sl_a)] |= step
            big[tuple(sl_b)] |= step
            far_b = np.where(step, np.maximum(filled[tuple(sl_a)], filled[tuple(sl_b)]), 0.0)
            near_side[tuple(sl_a)] = np.maximum(near_side[tuple(sl_a)], far_b)
            near_side[tuple(sl_b)] = np.maximum(near_side[tuple(sl_b)], far_b)
        band = (
            ndimage.binary_dilation(big, iterations=max(noise.edge_px - 1, 0))
            if (noise.edge_px > 1)
            else big
        )
        band &= valid
        if noise.flying_share > 0:
            fly = band & (rng.random(d.shape) < noise.flying_share)
            mix = rng.random(d.shape)
            far = np.where(near_side > 0, near_side, filled)
            out = np.where(fly, filled + (far - filled) * mix, out)
        if noise.edge_hole_share > 0:
            holes = band & (rng.random(d.shape) < noise.edge_hole_share)
            out[holes] = np.nan
    sigma = np.full(d.shape, noise.sigma_m)
    if noise.axial_a_m or noise.axial_b_per_m:
        sigma = np.hypot(sigma, noise.axial_a_m + noise.axial_b_per_m * (d - noise.axial_c_m) ** 2)
    if np.any(sigma > 0):
        field = rng.standard_normal(d.shape)
        if noise.correlation_px > 0:
            field = ndimage.gaussian_filter(field, noise.correlation_px)
            field /= field.std()
        out = out + field * np.where(valid, sigma, 0.0)
    if noise.speckle_share > 0:
        seeds = rng.random(d.shape) < noise.speckle_share / max(noise.speckle_clump_px, 1) ** 1.0
        if noise.speckle_clump_px > 1:
            size = int(rng.integers(1, noise.speckle_clump_px + 1))
            seeds = ndimage.binary_dilation(seeds, structure=np.ones((size, size), dtype=bool))
        clumps, count = ndimage.label(seeds)
        factor = np.concatenate([[1.0], rng.uniform(0.3, 0.9, count)])
        out = np.where(seeds & np.isfinite(out), out * factor[clumps], out)
    if noise.quantum_m > 0:
        out = np.round(out / noise.quantum_m) * noise.quantum_m
    result: Float32Array = out.astype(np.float32)
    return result


def loaded_pallet(rng: np.random.Generator) -> tuple[Box, list[Box], Camera]:
    """A pallet 0.15 m tall with twelve touching cartons in three rows of three heights (the
    middle row wider), and the camera 2 m up tilted 10 degrees, 640 x 480 (fx ~600), that the
    pallet benchmark and tests look through. ``rng`` gives the cartons' colours."""
    pallet = box_on(Plane(), 0.0, 0.0, (1.2, 1.0, 0.15), 0.0, (120, 90, 60))
    cartons = []
    for row in range(3):
        for col in range(4):
            size = (0.28, 0.3 if row == 1 else 0.25, (0.2, 0.3, 0.25)[(row + col) % 3])
            red, green, blue = (int(v) for v in rng.integers(120, 220, 3))
            cartons.append(
                box_on(pallet, (col - 1.5) * 0.285, (row - 1) * 0.3, size, 0.0, (red, green, blue))
            )
    camera = Camera.tilted(2.0, 10.0, width=640, height=480, hfov_deg=56.0)
    return pallet, cartons, camera
