"""MuJoCo renders of scene files with their ground truth, and the boxes found in them judged
against it: what the accuracy benchmark prints and the scene tests assert.

A detection is paired with the true box whose top's middle is nearest its top's middle (within
half the true top's smaller side, at least 2 cm), or, for a box whose top is not all seen, with
its middle on that top (the part seen, as the real captures' rule has it for a partial box). A
box whose whole top is in the picture and seen (at least 95 % of its top's pixels see it, not
hidden under another box) and that nothing detected is "missed"; a detection near no true top
is "false". A box partly hidden under
another counts neither way for its size, since the camera cannot see its whole top, but its
height is judged; a platform (a true box that two or more others stand on, such as a pallet)
is not judged at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onebox.geometry import Intrinsics
from onebox.perception.boxes import Found
from onebox.world import spec
from onebox.world.noise import NoiseSpec
from onebox.world.spec import SceneDesc
from schemas import BoxTruth, GroundTruth


@dataclass(frozen=True)
class Rendered:
    """One picture of a scene: noisy depth, colour, the lens and the camera's pose (optical
    frame -> world, 4 x 4), the ground truth, and per true box how many pixels its whole top
    would cover with nothing in front."""

    depth_m: np.ndarray
    rgb: np.ndarray
    lens: Intrinsics
    camera_to_world: np.ndarray
    truth: GroundTruth
    whole_top_px: list[int]


def render_scene(scene: SceneDesc, noise: NoiseSpec) -> Rendered:
    """The main camera's picture of ``scene`` as ``onebox sim`` makes it, with ``noise``."""
    import mujoco  # after onebox, which makes MuJoCo render headless

    from onebox.world.noise import DepthNoise
    from onebox.world.render import SceneRenderer
    from onebox.world.scene import build_model, camera_info, cameras, ground_truth, optical_pose

    model = build_model(scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    main = cameras(scene)[0]
    with SceneRenderer(model, [main]) as renderer:
        capture = renderer.render(data, main.name)
    clean = capture.depth_m
    camera_noise = DepthNoise(noise, clean.shape)
    depth = camera_noise.apply(clean)
    pose = optical_pose(model, data, main.name)
    p, q = pose.position, pose.orientation
    matrix = np.eye(4)
    matrix[:3, :3] = spec.quat_matrix((q.w, q.x, q.y, q.z))
    matrix[:3, 3] = (p.x, p.y, p.z)
    placed = spec.place(scene)
    truth = ground_truth(model, data, scene, spec.visible_top_pixels(scene.camera, placed, clean))
    rays = spec.pixel_rays(scene.camera)
    whole = [int(np.isfinite(spec.top_depths(scene.camera, b, rays)).sum()) for b in placed]
    lens = Intrinsics.from_k(camera_info(main).k)
    return Rendered(depth, camera_noise.colour(capture.rgb), lens, matrix, truth, whole)


@dataclass
class Judged:
    """Errors over many pictures, one entry a matched box."""

    centre_mm: list[float] = field(default_factory=list)
    centre_share: list[float] = field(default_factory=list)
    yaw_deg: list[float] = field(default_factory=list)
    size_mm_at_04: list[float] = field(default_factory=list)
    size_mm: list[float] = field(default_factory=list)
    height_mm: list[float] = field(default_factory=list)
    hidden_height_mm: list[float] = field(default_factory=list)
    """Heights of boxes partly hidden under another box: their top is seen in part, but how
    high it stands is as measurable as any top's."""
    found: int = 0
    missed: int = 0
    false: int = 0
    pictures: int = 0
    hidden_found: int = 0
    hidden: int = 0
    """Boxes whose top is in the picture but partly hidden (under or behind another box), not
    under two or more (a platform's)."""
    hidden_size_mm: list[float] = field(default_factory=list)
    """Length and width errors of partly hidden boxes found with every side seen (the finder
    then gives their whole size, not a lower bound)."""
    notes: list[str] = field(default_factory=list)


def _on_top_of(point: np.ndarray, box: BoxTruth) -> bool:
    """Whether a point lies on a true box's top: inside its rectangle (1 cm spare) and within
    2 cm of its height."""
    p, q = box.pose.position, box.pose.orientation
    rotation = spec.quat_matrix((q.w, q.x, q.y, q.z))
    local = rotation.T @ (point - np.array([p.x, p.y, p.z]))
    return bool(
        abs(local[0]) <= box.size.x / 2 + 0.01
        and abs(local[1]) <= box.size.y / 2 + 0.01
        and abs(local[2] - box.size.z / 2) <= 0.02
    )


def yaw_of(rotation: np.ndarray) -> float:
    """The length axis's angle about world z, degrees."""
    return math.degrees(math.atan2(rotation[1, 0], rotation[0, 0]))


def yaw_error(detected: float, true: float, square: bool) -> float:
    """The smallest turn between two length axes (a box looks the same turned half a turn, and
    a square top a quarter)."""
    period = 90.0 if square else 180.0
    diff = (detected - true) % period
    return min(diff, period - diff)


def judge(found: Found, rendered: Rendered, judged: Judged) -> None:
    """Pair ``found``'s boxes with the true boxes and add the errors to ``judged``."""
    judged.pictures += 1
    boxes: list[BoxTruth] = list(rendered.truth.boxes)
    camera = rendered.camera_to_world[:3, 3]
    tops = np.array(
        [[b.pose.position.x, b.pose.position.y, b.pose.position.z + b.size.z / 2] for b in boxes]
    ).reshape(-1, 3)
    carried = [sum(1 for b in boxes if b.on == i) for i in range(len(boxes))]
    seen = [
        b.top_in_view and b.top_pixels >= 0.95 * max(n, 1)
        for b, n in zip(boxes, rendered.whole_top_px, strict=True)
    ]
    unjudged = {i for i, n in enumerate(carried) if n >= 2 or not seen[i]}
    partly = {i for i, b in enumerate(boxes) if b.top_in_view and not seen[i] and carried[i] < 2}
    judged.hidden += len(partly)
    used: set[int] = set()
    for box in found.boxes:
        top, centre = np.array(box.top_middle), np.array(box.centre)
        distances = np.linalg.norm(tops - top, axis=1)
        nearest = int(np.argmin(distances)) if len(boxes) else -1
        reach = (
            0.0
            if nearest < 0
            else max(0.02, 0.5 * min(boxes[nearest].size.x, boxes[nearest].size.y))
        )
        if nearest < 0 or distances[nearest] > reach or nearest in used:
            # ... or the part seen of a box whose top is not all seen, its middle on that top
            on = [i for i in sorted(unjudged - used) if _on_top_of(top, boxes[i])]
            nearest = on[0] if on else -1
        if nearest < 0:
            judged.false += 1
            judged.notes.append(
                f"false box, top at ({top[0]:+.3f}, {top[1]:+.3f}, {top[2]:+.3f}), size "
                f"{box.size[0]:.3f} x {box.size[1]:.3f} x {box.size[2]:.3f}"
            )
            continue
        used.add(nearest)
        true = boxes[nearest]
        if nearest in unjudged:
            # Its whole top is not to be seen: neither right nor wrong, but counted.
            judged.hidden_found += nearest in partly
            if carried[nearest] < 2:  # ... but its height is (not a platform's, under many)
                height_error = abs(box.size[2] - true.size.z)
                judged.hidden_height_mm.append(1000 * height_error)
                if box.hidden_sides == 0 and nearest in partly:
                    sides = sorted((true.size.x, true.size.y), reverse=True)
                    judged.hidden_size_mm.extend(
                        1000 * abs(m - t) for m, t in zip(box.size[:2], sides, strict=True)
                    )
                if height_error > 0.01:
                    judged.notes.append(
                        f"box {nearest} (partly hidden) height {box.size[2]:.3f}, true "
                        f"{true.size.z:.3f}"
                    )
            continue
        judged.found += 1
        distance_m = float(np.linalg.norm(top - camera))
        p = true.pose.position
        centre_error = float(np.linalg.norm(centre - np.array([p.x, p.y, p.z])))
        judged.centre_mm.append(1000 * centre_error)
        judged.centre_share.append(100 * centre_error / distance_m)
        q = true.pose.orientation
        true_yaw = yaw_of(spec.quat_matrix((q.w, q.x, q.y, q.z)))
        square = abs(true.size.x - true.size.y) < 0.005
        judged.yaw_deg.append(yaw_error(box.yaw_deg, true_yaw, square))
        size_err = [abs(box.size[0] - true.size.x), abs(box.size[1] - true.size.y)]
        judged.size_mm.extend(1000 * s for s in size_err)
        judged.size_mm_at_04.extend(1000 * s * 0.4 / distance_m for s in size_err)
        judged.height_mm.append(1000 * abs(box.size[2] - true.size.z))
        if max(size_err) > 0.015 or centre_error > 0.01:
            judged.notes.append(
                f"box {nearest} off by {1000 * centre_error:.0f} mm: measured "
                f"{box.size[0]:.3f} x {box.size[1]:.3f} x {box.size[2]:.3f}, true "
                f"{true.size.x:.3f} x {true.size.y:.3f} x {true.size.z:.3f}"
            )
    for index, true in enumerate(boxes):
        if index not in used and index not in unjudged:
            judged.missed += 1
            p = true.pose.position
            judged.notes.append(
                f"missed box {index} at ({p.x:+.3f}, {p.y:+.3f}, {p.z:+.3f}) size "
                f"{true.size.x:.3f} x {true.size.y:.3f} x {true.size.z:.3f}"
            )
