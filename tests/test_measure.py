"""The maths: the seed's numbers on analytic pictures and on the committed capture, no processes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from onebox import geometry, pictures
from onebox.geometry import FrameError, FrameTree
from onebox.perception import seed
from onebox.testing.capture import CAPTURE, load_capture
from onebox.testing.synthetic import Scene, depth_picture, tf_static
from schemas import CameraInfo, Image, TFMessage, Transform, TransformStamped
from schemas import Header as H
from schemas import Quaternion as Q
from schemas import Vector3 as V

# The seed's lens (cx 160 with the middle of pixel u at u + 0.5) as real cameras write it.
SEED_K = [277.1, 0.0, 159.5, 0.0, 277.1, 119.5, 0.0, 0.0, 1.0]
SEED_LENS = geometry.Intrinsics.from_k(SEED_K)
OPTICAL = "camera_optical_frame"


def world_matrix(tf: TFMessage) -> np.ndarray:
    return FrameTree(tf.transforms).lookup("world", OPTICAL)


def reference(depth_m, lens, matrix, table_z=0.0, min_height=0.01):
    """The seed's steps 1 to 4 on every pixel."""
    points = seed.depth_to_points(depth_m, lens.fx, lens.fy, lens.cx + 0.5, lens.cy + 0.5)
    return seed.measure_box(geometry.to_world(points, matrix), table_z, min_height)


# --- seed 3.2 and 3.3 ----------------------------------------------------------------------------


def test_pixel_212_86_is_the_seed_point():
    """Pixel (212, 86) at 0.340 m is (+0.0644, -0.0411, +0.3400) in the optical frame (seed 3.2)."""
    depth = np.full((240, 320), 0.4, np.float32)
    depth[86, 212] = 0.34
    point = seed.depth_to_points(depth, 277.1, 277.1, 160.0, 120.0)[86 * 320 + 212]
    assert f"{point[0]:+.4f} {point[1]:+.4f} {point[2]:+.4f}" == "+0.0644 -0.0411 +0.3400"


def test_the_tf_chain_moves_the_seed_point_into_the_room():
    """world <- camera_link <- optical on tf_static puts that point at (+0.0644, +0.0411, +0.06)."""
    matrix = world_matrix(tf_static(0.40))
    np.testing.assert_allclose(matrix[:3, :3], [[1, 0, 0], [0, -1, 0], [0, 0, -1]], atol=1e-12)
    room = geometry.to_world(np.array([[0.0644, -0.0411, 0.340]]), matrix)[0]
    assert f"{room[0]:+.4f} {room[1]:+.4f} {room[2]:+.4f}" == "+0.0644 +0.0411 +0.0600"


def test_the_optical_quarter_turn_is_x_right_y_down_z_forward():
    """(-0.5, 0.5, -0.5, 0.5) sends optical X to camera_link -Y, Y to -Z and Z to +X."""
    matrix = geometry.transform_matrix((0, 0, 0), (-0.5, 0.5, -0.5, 0.5))
    np.testing.assert_allclose(matrix[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
    same_turn = geometry.transform_matrix((0, 0, 0), (0.5, -0.5, 0.5, -0.5))
    np.testing.assert_allclose(same_turn, matrix, atol=1e-12)


# --- the box on analytic pictures ----------------------------------------------------------------


def test_default_scene_gives_the_seed_answer():
    """A 6 cm box at (0.065, 0.0405) under the 320 x 240 camera: middle (+0.064, +0.040), 0.060."""
    scene = Scene()
    lens = geometry.Intrinsics.from_k(scene.k)
    box = seed.locate_box(depth_picture(scene), lens, world_matrix(tf_static()))
    assert box is not None
    assert f"({box.x:+.3f}, {box.y:+.3f}) {box.height:.3f}" == "(+0.064, +0.040) 0.060"
    assert abs(box.x - scene.box_x) < 0.001 and abs(box.y - scene.box_y) < 0.001
    assert 2300 < box.top_count < box.standing_count < 2700


SCENES = [
    Scene(),
    Scene(box_x=-0.1, box_y=0.05, box_size=0.04),
    Scene(box_x=0.02, box_y=-0.08, box_size=0.08, box_yaw_deg=30.0),
    Scene(width=640, height=480, box_yaw_deg=45.0),
    Scene(width=1280, height=720, hfov_deg=90.0, box_x=0.15, box_y=-0.1),
    Scene(width=80, height=60),
]


@pytest.mark.parametrize("scene", SCENES, ids=lambda s: f"{s.width}x{s.height}-{s.box_yaw_deg}")
def test_fast_path_equals_the_seed_steps(scene: Scene):
    """locate_box gives the seed's step-by-step counts exactly and its middle and height."""
    depth = depth_picture(scene)
    lens = geometry.Intrinsics.from_k(scene.k)
    matrix = world_matrix(tf_static(scene.mount_height))
    slow = reference(depth, lens, matrix)
    fast = seed.locate_box(depth, lens, matrix)
    assert slow is not None and fast is not None
    assert (fast.standing_count, fast.top_count) == (slow.standing_count, slow.top_count)
    for name in ("x", "y", "top_z", "height", "extent_x", "extent_y"):
        assert getattr(fast, name) == pytest.approx(getattr(slow, name), abs=1e-12), name
    assert abs(fast.height - scene.box_size) < 1e-6


@pytest.mark.parametrize(
    "turn",
    [
        Rotation.from_euler("xyz", [180, 10, -20], degrees=True),  # tilted, still looking down
        Rotation.from_euler("xyz", [100, 0, 0], degrees=True),  # some rays point up
    ],
    ids=["tilted", "some-rays-up"],
)
def test_fast_path_equals_the_seed_steps_for_any_camera_pose(turn: Rotation):
    """For a camera turned any way (rays up or down), both ways keep the same points."""
    scene = Scene()
    depth = depth_picture(scene)
    lens = geometry.Intrinsics.from_k(scene.k)
    matrix = np.eye(4)
    matrix[:3, :3] = turn.as_matrix()
    matrix[:3, 3] = [0.01, -0.02, 0.35]
    world = geometry.to_world(
        seed.depth_to_points(depth, lens.fx, lens.fy, lens.cx + 0.5, lens.cy + 0.5), matrix
    )
    table_z = float(np.percentile(world[:, 2], 95)) - 0.01  # a few percent stand above it
    slow = reference(depth, lens, matrix, table_z=table_z)
    fast = seed.locate_box(depth, lens, matrix, table_z=table_z)
    assert slow is not None and fast is not None
    assert (fast.standing_count, fast.top_count) == (slow.standing_count, slow.top_count)
    assert (fast.x, fast.y, fast.top_z) == pytest.approx((slow.x, slow.y, slow.top_z), abs=1e-12)


def test_no_box_is_none():
    """An empty table gives None from both ways, not an exception."""
    scene = Scene(has_box=False)
    depth = depth_picture(scene)
    lens = geometry.Intrinsics.from_k(scene.k)
    matrix = world_matrix(tf_static())
    assert seed.locate_box(depth, lens, matrix) is None
    assert reference(depth, lens, matrix) is None
    assert seed.has_reading(depth)


def test_all_nan_is_none_and_has_no_reading():
    """A picture with no reading anywhere gives None and has_reading False."""
    depth = np.full((240, 320), np.nan, np.float32)
    matrix = world_matrix(tf_static())
    assert seed.locate_box(depth, SEED_LENS, matrix) is None
    assert reference(depth, SEED_LENS, matrix) is None
    assert not seed.has_reading(depth)
    assert not seed.has_reading(np.zeros((2, 2), np.float32))
    assert not seed.has_reading(np.full((2, 2), np.inf, np.float32))


def test_nan_holes_are_skipped():
    """NaN on half the box's top leaves the same height and a middle on the rest of the top."""
    scene = Scene()
    depth = depth_picture(scene)
    depth[:, :212] = np.nan
    lens = geometry.Intrinsics.from_k(scene.k)
    box = seed.locate_box(depth, lens, world_matrix(tf_static()))
    assert box is not None
    assert box.height == pytest.approx(0.06, abs=1e-6)
    assert box.x > scene.box_x  # only the right part of the top remains


def test_zero_and_negative_float_readings_are_not_points():
    """0, -inf and negative readings in a 32FC1 picture do not become points inside the lens."""
    scene = Scene()
    depth = depth_picture(scene)
    depth[0, :10] = 0.0
    depth[1, :10] = -np.inf
    depth[2, :10] = -0.3
    lens = geometry.Intrinsics.from_k(scene.k)
    box = seed.locate_box(depth, lens, world_matrix(tf_static()))
    assert box is not None
    assert box.height == pytest.approx(0.06, abs=1e-6)


def test_16uc1_millimetres_with_zero_holes():
    """16UC1 (mm, 0 = no reading) gives the same box; its zeros are not points at the lens."""
    scene = Scene()
    depth = depth_picture(scene)
    mm = np.round(depth * 1000).astype("<u2")
    mm[:5, :] = 0  # holes: were they read as 0 m, they would stand 0.40 m high
    data = mm.tobytes()
    metres = pictures.depth_metres(data, width=320, height=240, step=640, encoding="16UC1")
    assert np.isnan(metres[:5]).all() and metres[86, 212] == pytest.approx(0.34)
    lens = geometry.Intrinsics.from_k(scene.k)
    box = seed.locate_box(metres, lens, world_matrix(tf_static()))
    assert box is not None
    assert box.height == pytest.approx(0.06, abs=1e-6)
    assert abs(box.x - scene.box_x) < 0.001


def test_table_z_and_min_height_are_honoured():
    """table_z raises the table (height measured from it); min_height above the box: no box."""
    scene = Scene()
    depth = depth_picture(scene)
    lens = geometry.Intrinsics.from_k(scene.k)
    matrix = world_matrix(tf_static())
    raised = seed.locate_box(depth, lens, matrix, table_z=0.02)
    assert raised is not None and raised.height == pytest.approx(0.04, abs=1e-6)
    assert seed.locate_box(depth, lens, matrix, min_height=0.07) is None
    assert reference(depth, lens, matrix, min_height=0.07) is None
    # A table below the real one makes the table itself stand: everything is "box".
    low = seed.locate_box(depth, lens, matrix, table_z=-0.05)
    assert low is not None and low.standing_count == 320 * 240


# --- pictures: step, byte order, sizes -----------------------------------------------------------


def test_step_with_padding_is_honoured():
    """A row padded to step bytes decodes unsheared: step counts bytes, not pixels."""
    depth = np.arange(12, dtype="<f4").reshape(3, 4)
    padded = np.zeros((3, 6), "<f4")
    padded[:, :4] = depth
    out = pictures.depth_metres(padded.tobytes(), width=4, height=3, step=24, encoding="32FC1")
    np.testing.assert_array_equal(out, depth)


def test_big_endian_depth():
    """is_bigendian=1 32FC1 decodes to the same metres."""
    depth = np.array([[0.34, 0.4]], dtype=">f4")
    out = pictures.depth_metres(
        depth.tobytes(), width=2, height=1, step=8, encoding="32FC1", is_bigendian=1
    )
    np.testing.assert_array_equal(out, depth.astype(np.float32))


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"width": 320, "height": 240, "step": 1280, "encoding": "rgb8"}, "not a depth"),
        ({"width": 320, "height": 240, "step": 320, "encoding": "32FC1"}, "step counts bytes"),
        ({"width": 320, "height": 241, "step": 1280, "encoding": "32FC1"}, "step x height"),
        ({"width": 0, "height": 240, "step": 1280, "encoding": "32FC1"}, "at least 1"),
    ],
)
def test_bad_headers_raise_image_error(kwargs, words):
    """A header that does not fit the bytes raises ImageError saying why."""
    data = np.zeros((240, 320), "<f4").tobytes()
    with pytest.raises(pictures.ImageError, match=words):
        pictures.depth_metres(data, **kwargs)


def test_colour_bgr8_becomes_rgb():
    """bgr8 bytes come out red, green, blue."""
    data = bytes([1, 2, 3, 4, 5, 6])
    rgb = pictures.colour_rgb(data, width=2, height=1, step=6, encoding="bgr8")
    assert rgb.tolist() == [[[3, 2, 1], [6, 5, 4]]]


def test_bad_lens_is_refused():
    """K with fx 0 or the wrong length raises ValueError naming it."""
    with pytest.raises(ValueError, match="fx"):
        geometry.Intrinsics.from_k([0.0, 0, 160, 0, 277, 120, 0, 0, 1])
    with pytest.raises(ValueError, match="9"):
        geometry.Intrinsics.from_k([277.1])


# --- the point cloud -----------------------------------------------------------------------------


def test_cloud_skips_no_reading_and_keeps_the_half_pixel():
    """One point a pixel with a reading, pixel (212, 86) at the seed's point, with its colour."""
    depth = np.full((240, 320), 0.4, np.float32)
    depth[86, 212] = 0.34
    depth[0, :] = np.nan
    colour = np.zeros((240, 320, 3), np.uint8)
    colour[86, 212] = (200, 10, 20)
    points = pictures.cloud_points(depth, SEED_LENS, colour)
    assert len(points) == 320 * 239
    seed = points[86 * 320 + 212 - 320]
    assert f"{seed['x']:+.4f} {seed['y']:+.4f} {seed['z']:+.4f}" == "+0.0644 -0.0411 +0.3400"
    assert seed["rgb"] == (200 << 16) | (10 << 8) | 20
    assert pictures.CLOUD_DTYPE.itemsize == 16


# --- the frame tree ------------------------------------------------------------------------------


def stamped(parent: str, child: str, xyz=(0.0, 0.0, 0.0), quat=(0.0, 0.0, 0.0, 1.0)):
    return TransformStamped(
        header=H(frame_id=parent),
        child_frame_id=child,
        transform=Transform(
            translation=V(x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=Q(x=quat[0], y=quat[1], z=quat[2], w=quat[3]),
        ),
    )


def test_frame_tree_composes_any_chain_both_ways():
    """A four-step chain composes; a lookup across branches and its reverse are inverses."""
    turn = Rotation.from_euler("z", 90, degrees=True).as_quat()
    tree = FrameTree(
        [
            stamped("world", "table", (1.0, 0.0, 0.0)),
            stamped("table", "stand", (0.0, 0.0, 0.5), turn),
            stamped("stand", "arm", (0.2, 0.0, 0.0)),
            stamped("arm", "cam", (0.0, 0.0, 0.1)),
            stamped("world", "door", (0.0, 3.0, 0.0)),
        ]
    )
    world_from_cam = tree.lookup("world", "cam")
    # The stand turns a quarter about z, so the arm's 0.2 m along x is 0.2 m along world y.
    np.testing.assert_allclose(world_from_cam[:3, 3], [1.0, 0.2, 0.6], atol=1e-12)
    door_from_cam = tree.lookup("door", "cam")
    np.testing.assert_allclose(door_from_cam[:3, 3], [1.0, -2.8, 0.6], atol=1e-12)
    np.testing.assert_allclose(tree.lookup("cam", "door") @ door_from_cam, np.eye(4), atol=1e-12)


def test_frame_tree_errors_name_the_frames():
    """Unknown frames, separate trees, loops and broken quaternions raise FrameError."""
    tree = FrameTree([stamped("world", "a"), stamped("elsewhere", "b")])
    with pytest.raises(FrameError, match=r"no frame 'nowhere'.*known: a, b, elsewhere, world"):
        tree.lookup("world", "nowhere")
    with pytest.raises(FrameError, match="separate trees"):
        tree.lookup("world", "b")
    with pytest.raises(FrameError, match="own ancestor"):
        tree.add(stamped("a", "world"))
    with pytest.raises(FrameError, match="not usable"):
        tree.add(stamped("world", "c", quat=(0.0, 0.0, 0.0, 0.0)))
    with pytest.raises(FrameError, match="two different frame names"):
        tree.add(stamped("", "c"))


def test_frame_tree_replaces_a_moved_frame():
    """Adding a child again moves it, and the version changes so caches notice."""
    tree = FrameTree([stamped("world", "cam", (0, 0, 0.4))])
    version = tree.version
    tree.add(stamped("world", "cam", (0, 0, 0.5)))
    assert tree.version > version
    assert tree.lookup("world", "cam")[2, 3] == pytest.approx(0.5)


# --- the committed capture (seed 3.1 to 3.5) -----------------------------------------------------


@pytest.fixture(scope="module")
def capture():
    return load_capture(CAPTURE)


def capture_arrays(capture):
    image = capture["camera/depth/image_raw"]
    info = capture["camera/camera_info"]
    assert isinstance(image, Image) and isinstance(info, CameraInfo)
    depth = pictures.depth_metres(
        image.data,
        width=image.width,
        height=image.height,
        step=image.step,
        encoding=image.encoding,
        is_bigendian=image.is_bigendian,
    )
    tf = capture["tf_static"]
    assert isinstance(tf, TFMessage)
    return depth, geometry.Intrinsics.from_k(info.k), world_matrix(tf), image.header.frame_id


def test_capture_holds_the_seed_keys(capture):
    """The capture holds depth, colour, camera info and tf_static, in the optical frame."""
    assert {"camera/camera_info", "camera/depth/image_raw", "camera/image_raw", "tf_static"} <= set(
        capture
    )
    depth, lens, _, frame_id = capture_arrays(capture)
    assert depth.shape == (240, 320) and frame_id == OPTICAL
    assert (lens.fx, lens.cx, lens.cy) == pytest.approx(
        (160 / math.tan(math.radians(30)), 159.5, 119.5)
    )


def test_capture_pixel_212_86_and_the_room(capture):
    """Seed 3.2 and 3.3 on the capture: (+0.0644, -0.0411, +0.34), then in the room +0.06 up."""
    depth, lens, matrix, _ = capture_arrays(capture)
    assert f"{depth[86, 212]:.3f}" == "0.340"
    point = seed.depth_to_points(depth, lens.fx, lens.fy, lens.cx + 0.5, lens.cy + 0.5)[
        86 * 320 + 212
    ]
    assert f"{point[0]:+.4f} {point[1]:+.4f} {point[2]:+.4f}" == "+0.0644 -0.0411 +0.3400"
    room = geometry.to_world(point[np.newaxis], matrix)[0]
    assert f"{room[0]:+.4f} {room[1]:+.4f} {room[2]:+.4f}" == "+0.0644 +0.0411 +0.0600"


def test_capture_gives_the_seed_counts_and_answer(capture):
    """Seed 3.5: 76,800 points, 2,582 standing, 2,401 on top; middle (+0.064, +0.040), 0.060 m."""
    depth, lens, matrix, _ = capture_arrays(capture)
    points = geometry.to_world(
        seed.depth_to_points(depth, lens.fx, lens.fy, lens.cx + 0.5, lens.cy + 0.5), matrix
    )
    box = seed.measure_box(points)
    assert box is not None
    assert f"{len(points):,} {box.standing_count:,} {box.top_count:,}" == "76,800 2,582 2,401"
    assert f"({box.x:+.3f}, {box.y:+.3f}) {box.height:.3f}" == "(+0.064, +0.040) 0.060"
    fast = seed.locate_box(depth, lens, matrix)
    assert fast is not None
    assert (fast.standing_count, fast.top_count) == (2582, 2401)
    assert (fast.x, fast.y, fast.height) == pytest.approx((box.x, box.y, box.height), abs=1e-12)
