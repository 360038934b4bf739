"""The worlds in-process (MuJoCo, no Zenoh): scene files, random scenes, ground truth, the stand."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from onebox.errors import SceneError
from onebox.world import scene, spec
from onebox.world.noise import PRESETS, DepthNoise
from onebox.world.random_scene import looking_across, random_pallet, random_scene
from onebox.world.render import Capture, SceneRenderer
from onebox.world.spec import CameraDesc, SceneDesc, TableDesc
from schemas import GroundTruth

SCENES = Path(__file__).resolve().parent.parent / "scene"


def render(desc: SceneDesc) -> tuple[mujoco.MjModel, mujoco.MjData, Capture]:
    """Build the scene and render its main camera once, noise-free."""
    model = scene.build_model(desc)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with SceneRenderer(model, scene.cameras(desc)[:1]) as renderer:
        return model, data, renderer.render(data, "camera")


def truth_of(desc: SceneDesc) -> tuple[GroundTruth, Capture, mujoco.MjModel, mujoco.MjData]:
    model, data, capture = render(desc)
    counts = spec.visible_top_pixels(desc.camera, spec.place(desc), capture.depth_m)
    return scene.ground_truth(model, data, desc, counts), capture, model, data


def test_seed_scene_file_is_the_seed_world() -> None:
    """scene/one_box.toml describes exactly the world the sim builds without --scene."""
    assert spec.load(SCENES / "one_box.toml") == scene.seed_scene()


@pytest.mark.parametrize("name", ["one_box", "pallet", "clutter"])
def test_committed_scene_builds_with_every_box_top_in_view(name: str) -> None:
    """Each committed scene renders, reads the table and tops, and sees every top whole."""
    desc = spec.load(SCENES / f"{name}.toml")
    truth, capture, _, _ = truth_of(desc)
    assert capture.depth_m.shape == (desc.camera.height, desc.camera.width)
    assert np.isfinite(capture.depth_m).mean() > 0.95
    assert len(truth.boxes) == len(desc.boxes) >= 1
    assert all(b.top_in_view for b in truth.boxes)
    # a carton on the pallet shows its top; the pallet's own top is all but covered
    assert all(b.top_pixels > 100 for b in truth.boxes[1:] if b.on is not None or name != "pallet")
    assert truth.box_pose == truth.boxes[0].pose and truth.box_size == truth.boxes[0].size


def test_pallet_is_as_described() -> None:
    """The pallet scene: 640 x 480, fx 600, tilted 10 deg, 12 cartons on it, tops at 3 heights."""
    desc = spec.load(SCENES / "pallet.toml")
    cam = scene.cameras(desc)[0]
    assert (cam.width, cam.height, round(cam.focal_px, 1)) == (640, 480, 600.0)
    placed = spec.place(desc)
    cartons = [p for p in placed if p.on is not None]
    assert len(cartons) == 12
    assert sorted({round(p.top_z, 3) for p in cartons}) == [0.344, 0.444, 0.644]


def test_every_top_in_view_at_once_is_each_top_in_view() -> None:
    """The ground truth's top_in_view, all boxes projected at once, says what in_picture says
    of each box on its own, tilted cameras and tops half out of the picture included."""
    answers = []
    for seed in range(40):
        desc = random_scene(seed, boxes=8, objects=0)
        placed = spec.place(desc)
        for tilt_deg in (0.0, 40.0):
            cam = dataclasses.replace(desc.camera, tilt_deg=tilt_deg, width=161, height=120)
            each = [spec.in_picture(cam, p.top_corners()) for p in placed]
            assert spec.tops_in_picture(cam, placed) == each, (seed, tilt_deg)
            answers += each
    assert any(answers) and not all(answers)  # both answers were tried
    assert spec.tops_in_picture(desc.camera, []) == []


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_random_truth_agrees_with_the_rendered_depth(seed: int) -> None:
    """Every box top lies in the picture; a pixel on a top reads the depth its pose predicts."""
    desc = random_scene(seed, boxes=6, objects=3)
    truth, capture, _, _ = truth_of(desc)
    assert len(truth.boxes) >= 4
    cam = scene.cameras(desc)[0]
    info = scene.camera_info(cam)
    fx, cx, cy = info.k[0], info.k[2], info.k[5]
    p, o = truth.camera_pose.position, truth.camera_pose.orientation
    world_from_cam = Rotation.from_quat([o.x, o.y, o.z, o.w]).as_matrix()
    lens = np.array([p.x, p.y, p.z])
    depth = capture.depth_m.astype(np.float64)
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    rays = np.stack([(u - cx) / fx, (v - cy) / fx, np.ones_like(depth)], -1) @ world_from_cam.T
    points = lens + depth[..., None] * rays
    checked = 0
    for index, box in enumerate(truth.boxes):
        assert box.top_in_view
        q, c = box.pose.orientation, box.pose.position
        box_rot = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        top_z = c.z + box.size.z / 2
        local = (points - [c.x, c.y, c.z]) @ box_rot
        with np.errstate(invalid="ignore"):
            on_top = (
                (np.abs(points[..., 2] - top_z) < 0.001 + 0.0005 * depth)
                & (np.abs(local[..., 0]) <= box.size.x / 2 + 0.0005)
                & (np.abs(local[..., 1]) <= box.size.y / 2 + 0.0005)
            )
        # counted from the picture back into the world, as the ground truth counts forwards
        # (where a box stands on this one, the foot of its sides also lies at this top's height)
        counted = int(on_top.sum())
        if any(other.on == index for other in truth.boxes):
            assert box.top_pixels <= counted + 3
        else:
            assert abs(counted - box.top_pixels) <= max(3, 0.05 * box.top_pixels)
        if box.top_pixels < 5:
            continue
        # the pixel under the top's middle, when it sees the top, reads the plane's depth
        middle = (np.array([c.x, c.y, top_z]) - lens) @ world_from_cam
        pu, pv = round(fx * middle[0] / middle[2] + cx), round(fx * middle[1] / middle[2] + cy)
        if not on_top[pv, pu]:
            continue  # hidden by a box stacked on it
        ray = rays[pv, pu]
        expected = (top_z - lens[2]) / ray[2]
        assert abs(depth[pv, pu] - expected) < 0.0005, (box, depth[pv, pu], expected)
        checked += 1
    assert checked >= 3


@pytest.mark.parametrize("tilt_deg", [0.0, 30.0])
@pytest.mark.parametrize("hfov_deg", [60.0, 120.0])
def test_the_stand_never_comes_into_view(tilt_deg: float, hfov_deg: float) -> None:
    """From 0.2 to 3 m up, tilted up to 30 deg, hfov up to 120: no pixel sees the stand."""
    for height in (0.2, 0.45, 0.5, 1.0, 2.0, 3.0):
        desc = SceneDesc(
            camera=CameraDesc(
                z=height, tilt_deg=tilt_deg, pan_deg=25.0, width=160, height=120, hfov_deg=hfov_deg
            ),
            table=TableDesc(size=(30.0, 30.0)),
        )
        model = scene.build_model(desc)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        stand = {
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
            for name in ("stand_post", "stand_arm", "stand_drop")
        }
        with mujoco.Renderer(model, 120, 160) as r:
            r.enable_segmentation_rendering()
            r.update_scene(data, "camera")
            seen = r.render()
        ids = set(np.unique(seen[..., 0][seen[..., 1] == mujoco.mjtObj.mjOBJ_GEOM]).tolist())
        assert ids and not ids & stand, (height, ids)


def test_the_stand_follows_the_camera_up() -> None:
    """The arm rides above the lens wherever the camera is (the seed's was fixed at 0.43 m)."""
    for height in (0.3, 0.6, 2.5):
        model = scene.build_model(
            dataclasses.replace(scene.seed_scene(), camera=CameraDesc(z=height))
        )
        arm = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "stand_arm")
        assert model.geom_pos[arm][2] > height


@pytest.mark.parametrize(("tilt_deg", "pan_deg"), [(0.0, 0.0), (10.0, 0.0), (30.0, -70.0)])
def test_optical_pose_is_the_described_camera(tilt_deg: float, pan_deg: float) -> None:
    """MuJoCo's camera sits where the scene says, looking where tilt and pan say."""
    desc = dataclasses.replace(
        scene.seed_scene(),
        camera=CameraDesc(x=0.1, y=-0.2, z=1.0, tilt_deg=tilt_deg, pan_deg=pan_deg),
    )
    model = scene.build_model(desc)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pose = scene.optical_pose(model, data, "camera")
    q = pose.orientation
    rot = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    assert np.allclose(rot, spec.world_from_optical(desc.camera), atol=1e-9)
    forward = rot[:, 2]
    assert math.degrees(math.acos(-forward[2])) == pytest.approx(tilt_deg, abs=1e-6)
    assert [pose.position.x, pose.position.y, pose.position.z] == pytest.approx([0.1, -0.2, 1.0])


@pytest.fixture
def seven() -> Iterator[SceneDesc]:
    yield random_scene(7, boxes=8, objects=4)


def test_same_seed_same_world_same_pictures(seven: SceneDesc) -> None:
    """The same seed gives the same world, through a scene file too, and identical pictures."""
    again = random_scene(7, boxes=8, objects=4)
    assert again == seven
    assert spec.parse(tomllib.loads(spec.dumps(seven))) == seven
    assert random_scene(8, boxes=8, objects=4) != seven
    _, _, first = render(seven)
    _, _, second = render(again)
    assert first.rgb.tobytes() == second.rgb.tobytes()
    assert first.depth_m.tobytes() == second.depth_m.tobytes()


def test_random_scenes_touch_stack_and_vary(seven: SceneDesc) -> None:
    """Across seeds: boxes of independent sides, some stacked, some touching, tilted cameras."""
    scenes = [random_scene(s) for s in range(12)]
    boxes = [b for d in scenes for b in d.boxes]
    assert any(b.on is not None for b in boxes)
    sides = np.array([b.size for b in boxes])
    assert sides.min() >= 0.02 and sides.max() <= 0.40
    assert len({tuple(s) for s in sides}) == len(sides)
    assert max(d.camera.tilt_deg for d in scenes) > 15
    assert all(0.3 <= d.camera.z - d.table.z <= 2.5 for d in scenes)
    assert len({d.table.z for d in scenes}) == len(scenes)
    touching = 0
    for d in scenes:
        placed = [p for p in spec.place(d) if p.on is None]
        for i, a in enumerate(placed):
            for b in placed[:i]:
                if abs(spec.footprint_overlap(a.footprint(), b.footprint())) < 0.001:
                    touching += 1
    assert touching >= 3


BAD = [
    ("[camera]\nzoom = 2\n", "camera.zoom"),
    ("[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1, 0.1]\ncolour = [1, 0, 0, 1]\n", "box[0].colour"),
    ("[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1]\n", "box[0].size"),
    (
        "[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1, 0.1]\n"
        "[[box]]\nx = 0.3\ny = 0\nsize = [0.1, 0.1, 0.1]\non = 0\n",
        "box[1].on = 0",
    ),
    ("[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1, 0.1]\non = 3\n", "box[0].on"),
    ("[[box]]\nx = 5\ny = 0\nsize = [0.1, 0.1, 0.1]\n", "box[0]"),
    ("[[box]]\nx = 0\ny = 0\nsize = [0.5, 0.5, 0.5]\n", "inside box[0]"),
    (
        "[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1, 0.1]\n[[box]]\nx = 0.05\ny = 0\n"
        "size = [0.1, 0.1, 0.1]\n",
        "box[1] and box[0]",
    ),
    ("[camera]\ntilt_deg = 80\n", "camera.tilt_deg"),
    ('[[object]]\nshape = "cone"\nx = 0\ny = 0\nsize = [0.1]\n', "object[0].shape"),
    ('[noise]\nmodel = "kinect"\n', "noise.model"),
    ('[noise]\nmodel = "gaussian"\nsigma = 0.01\n', "noise.sigma"),
    ('[noise]\nmodel = "d435"\ncorrelation_px = -2\n', "noise.correlation_px"),
    ("[tabel]\nz = 0\n", "tabel"),
]


@pytest.mark.parametrize(("text", "named"), BAD)
def test_a_bad_scene_is_one_line_naming_the_key(text: str, named: str) -> None:
    """An unknown key, a box in mid-air or inside another, a camera inside a box: one line."""
    with pytest.raises(SceneError) as e:
        spec.parse(tomllib.loads(text), "bad.toml")
    message = str(e.value)
    assert named in message and message.startswith("bad.toml: ") and "\n" not in message


def test_lumpy_noise_through_a_scene_file() -> None:
    """``correlation_px`` in a scene's [noise] goes through a scene file and makes the sim's
    depth error lumpy: neighbours err together."""
    text = '[noise]\nmodel = "d435"\ncorrelation_px = 3\n[camera]\nwidth = 320\nheight = 240\n'
    scene = spec.parse(tomllib.loads(text))
    assert scene.noise.correlation_px == 3.0 and scene.noise.b == PRESETS["d435"].b
    assert spec.parse(tomllib.loads(spec.dumps(scene))) == scene
    clean = np.full((240, 320), 1.5, dtype=np.float32)
    err = DepthNoise(scene.noise, clean.shape).apply(clean) - clean
    left, right = err[:, :-1].ravel(), err[:, 1:].ravel()
    normal = (np.abs(left) < 0.1) & (np.abs(right) < 0.1)  # not the speckles
    assert np.corrcoef(left[normal], right[normal])[0, 1] > 0.9


def test_taped_cartons_through_a_scene_file() -> None:
    """``tape = true`` puts packing tape on a box's top; it goes through a scene file, and a
    value that is not true or false is a clear error."""
    taped = random_pallet(3, taped=True)
    assert not taped.boxes[0].tape and all(box.tape for box in taped.boxes[1:])
    assert spec.parse(tomllib.loads(spec.dumps(taped))) == taped
    plain = random_pallet(3)
    assert [dataclasses.replace(box, tape=False) for box in taped.boxes] == list(plain.boxes)
    _, _, with_tape = render(taped)
    _, _, without = render(plain)
    assert with_tape.rgb.tobytes() != without.rgb.tobytes()
    bad = {"box": [{"x": 0.0, "y": 0.0, "size": [0.1, 0.1, 0.1], "tape": "yes"}]}
    with pytest.raises(SceneError, match=r"box\[0\]\.tape = 'yes': expected true or false"):
        spec.parse(bad)


def test_a_random_scene_looked_at_across_keeps_what_the_camera_looks_at():
    """The same scene 45 degrees from straight down: the same boxes, the camera at the same
    height and turned the same way, its optical axis still through the table's middle."""
    scene = random_scene(3, boxes=8, objects=3, width=640, height=480)
    across = looking_across(scene, 45.0)
    assert across.boxes == scene.boxes and across.objects == scene.objects
    assert across.camera.tilt_deg == 45.0
    assert (across.camera.z, across.camera.pan_deg) == (scene.camera.z, scene.camera.pan_deg)
    forward = spec.world_from_optical(across.camera)[:, 2]
    reach = (across.camera.z - scene.table.z) / -forward[2]
    on_table = np.array([across.camera.x, across.camera.y]) + reach * forward[:2]
    assert np.allclose(on_table, 0.0, atol=2e-4)
    assert np.hypot(across.camera.x, across.camera.y) > np.hypot(scene.camera.x, scene.camera.y)
