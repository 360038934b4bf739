"""onebox import: a real camera's ROS 2 bag, written by another library (mcap-ros2-support) the
way a RealSense driver's topics look, turned into a onebox recording and replayed into a real
locator, which finds the boxes in it."""

from __future__ import annotations

import io
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from onebox import keys
from onebox.geometry import Intrinsics, matrix_of
from onebox.recording import iter_messages
from onebox.testing.processes import Inbox, run_onebox
from onebox.testing.raycast import Camera, Noise, Plane, Scene, add_noise, box_on, render
from schemas import CameraInfo, Detection3DArray, Image, TFMessage, TransformStamped, codec

ROS = "/camera/camera"
ALIGNED = f"{ROS}/aligned_depth_to_color"
OPTICAL_IN_LINK = (-0.5, 0.5, -0.5, 0.5)
"""camera_link -> camera_color_optical_frame, (x, y, z, w): the REP 103 quarter turn."""
BOXES = (
    box_on(Plane(), 0.05, 0.02, (0.12, 0.08, 0.06), 25.0, (200, 60, 40)),
    box_on(Plane(), -0.12, -0.05, (0.09, 0.09, 0.10), -10.0, (60, 90, 200)),
)


def _quat_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _matrix_quat(m: np.ndarray) -> tuple[float, float, float, float]:
    w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    assert w > 0.1, "the test's camera is never turned half round"
    x, y, z = (
        (m[2, 1] - m[1, 2]) / (4 * w),
        (m[0, 2] - m[2, 0]) / (4 * w),
        (m[1, 0] - m[0, 1]) / (4 * w),
    )
    return (x, y, z, w)


def _header(stamp_ns: int, frame: str) -> dict:
    return {
        "stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000},
        "frame_id": frame,
    }


def _image(stamp_ns: int, frame: str, pixels: np.ndarray, encoding: str) -> dict:
    height, width = pixels.shape[:2]
    data = np.ascontiguousarray(pixels).tobytes()
    return {
        "header": _header(stamp_ns, frame),
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": len(data) // height,
        "data": data,
    }


def _info(stamp_ns: int, frame: str, lens: Intrinsics, width: int, height: int) -> dict:
    k = [lens.fx, 0.0, lens.cx, 0.0, lens.fy, lens.cy, 0.0, 0.0, 1.0]
    return {
        "header": _header(stamp_ns, frame),
        "height": height,
        "width": width,
        "distortion_model": "plumb_bob",
        "d": [0.0] * 5,
        "k": k,
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": [lens.fx, 0.0, lens.cx, 0.0, 0.0, lens.fy, lens.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def _transform(parent: str, child: str, t: np.ndarray, q: tuple[float, ...]) -> dict:
    return {
        "header": _header(0, parent),
        "child_frame_id": child,
        "transform": {
            "translation": {"x": t[0], "y": t[1], "z": t[2]},
            "rotation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]},
        },
    }


@pytest.fixture(scope="module")
def realsense_bag(tmp_path_factory) -> tuple[Path, np.ndarray, Camera]:
    """A D435-like ROS 2 bag: colour (bgr8), depth aligned to it (16UC1 mm, 0 = no reading),
    the unaligned depth at another size, their CameraInfo, tf_static world -> camera_link ->
    camera_color_optical_frame, and a topic onebox has no use for."""
    camera = Camera.tilted(0.7, 20.0, width=640, height=480)
    depth_m, colour = render(Scene(camera, Plane(), BOXES))
    noisy = add_noise(depth_m, Noise.d435(), np.random.default_rng(5))
    depth_mm = np.where(np.isfinite(noisy), np.rint(noisy * 1000), 0).astype(np.uint16)
    small = depth_mm[::2, ::2]
    lens = camera.lens
    small_lens = Intrinsics(lens.fx / 2, lens.fy / 2, lens.cx / 2, lens.cy / 2)
    link_to_world = camera.camera_to_world @ np.block(
        [
            [_quat_matrix(*OPTICAL_IN_LINK).T, np.zeros((3, 1))],
            [np.zeros((1, 3)), np.ones((1, 1))],
        ]
    )
    store = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path_factory.mktemp("bag") / "realsense.mcap"
    optical = "camera_color_optical_frame"
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        schemas = {
            name: writer.register_msgdef(name, store.generate_msgdef(name, ros_version=2)[0])
            for name in (
                "sensor_msgs/msg/Image",
                "sensor_msgs/msg/CameraInfo",
                "tf2_msgs/msg/TFMessage",
                "std_msgs/msg/String",
            )
        }
        image, info = schemas["sensor_msgs/msg/Image"], schemas["sensor_msgs/msg/CameraInfo"]
        start = 1_700_000_000_000_000_000
        statics = {
            "transforms": [
                _transform(
                    "world",
                    "camera_link",
                    link_to_world[:3, 3],
                    _matrix_quat(link_to_world[:3, :3]),
                ),
                _transform("camera_link", optical, np.zeros(3), OPTICAL_IN_LINK),
            ]
        }
        writer.write_message("/tf_static", schemas["tf2_msgs/msg/TFMessage"], statics, start, start)
        for n in range(4):
            t = start + 10_000_000 + n * 200_000_000
            # A real camera stamps the colour a few milliseconds after the depth.
            bgr = np.ascontiguousarray(colour[..., ::-1])
            for topic, schema, message, stamp in (
                (f"{ROS}/color/image_raw", image, _image(t + 4_000_000, optical, bgr, "bgr8"), t),
                (
                    f"{ROS}/color/camera_info",
                    info,
                    _info(t + 4_000_000, optical, lens, 640, 480),
                    t,
                ),
                (f"{ALIGNED}/image_raw", image, _image(t, optical, depth_mm, "16UC1"), t),
                (f"{ALIGNED}/camera_info", info, _info(t, optical, lens, 640, 480), t),
                (f"{ROS}/depth/image_rect_raw", image, _image(t, "depth", small, "16UC1"), t),
                (f"{ROS}/depth/camera_info", info, _info(t, "depth", small_lens, 320, 240), t),
                ("/rosout_text", schemas["std_msgs/msg/String"], {"data": "hello"}, t),
            ):
                writer.write_message(topic, schema, message, stamp, stamp)
        writer.finish()
    return path, depth_mm, camera


def test_import_takes_the_aligned_depth_its_lens_colour_and_frames(realsense_bag, tmp_path):
    path, depth_mm, camera = realsense_bag
    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(path), str(out))
    assert done.returncode == 0, done.stderr
    assert f"depth   {ALIGNED}/image_raw (16UC1, 640 x 480)" in done.stdout
    assert f"lens    {ALIGNED}/camera_info" in done.stdout
    assert f"colour  {ROS}/color/image_raw (bgr8)" in done.stdout
    assert "/rosout_text (4)" in done.stdout
    items = list(iter_messages(out))
    by_key: dict[str, list[bytes]] = {}
    for item in items:
        by_key.setdefault(item.key, []).append(bytes(item.payload))
    assert {k: len(v) for k, v in by_key.items()} == {
        keys.CAMERA.depth: 4,
        keys.CAMERA.info: 4,
        keys.CAMERA.colour: 4,
        keys.TF_STATIC: 1,
    }
    depth = codec(Image).decode(by_key[keys.CAMERA.depth][0])
    assert (depth.encoding, depth.width, depth.height) == ("16UC1", 640, 480)
    assert np.array_equal(np.frombuffer(depth.data, np.uint16).reshape(480, 640), depth_mm)
    assert depth.header.stamp_ns == 1_700_000_000_010_000_000
    lens = codec(CameraInfo).decode(by_key[keys.CAMERA.info][0])
    assert lens.k[0] == camera.lens.fx and lens.k[2] == camera.lens.cx
    colour = codec(Image).decode(by_key[keys.CAMERA.colour][0])
    assert colour.encoding == "bgr8"
    assert colour.header.stamp_ns - depth.header.stamp_ns == 4_000_000
    frames = codec(TFMessage).decode(by_key[keys.TF_STATIC][0])
    assert {(t.header.frame_id, t.child_frame_id) for t in frames.transforms} == {
        ("world", "camera_link"),
        ("camera_link", "camera_color_optical_frame"),
    }


def _replayed_to_a_locator(
    bag: Path, tmp_path: Path, processes, test_bus, *locator_flags: str
) -> Inbox:
    """Import ``bag`` and replay it (looping) into a real locator run with ``locator_flags``;
    the inbox collects its detections."""
    out = tmp_path / "run.mcap"
    assert run_onebox("import", str(bag), str(out)).returncode == 0
    inbox = Inbox()
    test_bus.subscribe_raw(keys.DETECTIONS, inbox)
    processes.start("locator", *locator_flags, "--log-interval-s", "1")
    processes.start("replay", str(out), "--loop", "--wait-s", "10")
    return inbox


def test_imported_bag_replayed_into_the_locator_finds_every_box(
    realsense_bag, tmp_path, processes, test_bus
):
    """The real pipeline on the imported bag: replay -> locator (pairing depth and colour 4 ms
    apart with --slop-ms) -> detections in the world frame through tf_static's chain."""
    path, _, _ = realsense_bag
    inbox = _replayed_to_a_locator(path, tmp_path, processes, test_bus, "--slop-ms", "20")

    def boxes_found(items: list[tuple[str, bytes]]) -> bool:
        return any(codec(Detection3DArray).decode(p).detections for _, p in items)

    inbox.wait(boxes_found, timeout_s=60)
    found = next(
        d for d in (codec(Detection3DArray).decode(p) for _, p in inbox.items) if d.detections
    )
    assert found.header.frame_id == "world"
    assert len(found.detections) == len(BOXES)
    centres = [(d.bbox.center.position, d) for d in found.detections]
    for true in BOXES:
        c, d = min(centres, key=lambda cd: math.dist(true.centre, (cd[0].x, cd[0].y, cd[0].z)))
        assert math.dist(true.centre, (c.x, c.y, c.z)) < 0.010
        assert d.bbox.size.x == pytest.approx(max(true.size[:2]), abs=0.015)
        assert d.bbox.size.y == pytest.approx(min(true.size[:2]), abs=0.015)
        assert d.bbox.size.z == pytest.approx(true.size[2], abs=0.015)


def test_several_depth_topics_and_no_colour_ask_for_depth(realsense_bag, tmp_path):
    path, _, _ = realsense_bag
    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(path), str(out), "--colour", f"{ROS}/depth/image_rect_raw")
    assert done.returncode == 2
    assert "is 16UC1, not a colour picture" in done.stderr
    done = run_onebox("import", str(path), str(out), "--depth", f"{ROS}/depth/image_rect_raw")
    assert done.returncode == 0, done.stderr
    assert f"lens    {ROS}/depth/camera_info" in done.stdout
    assert "not aligned, so the locator reads depth alone" in done.stdout
    again = run_onebox("import", str(path), str(out))
    assert again.returncode == 2 and "already exists" in again.stderr
    assert not list(tmp_path.glob(".*partial"))


def test_a_file_that_is_no_bag_gets_one_line_and_leaves_nothing(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a bag at all")
    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(junk), str(out))
    assert done.returncode == 2
    assert "not a ROS bag onebox can read" in done.stderr
    assert "Traceback" not in done.stderr
    assert not out.exists() and not list(tmp_path.glob(".*partial"))


def test_a_ros1_bag_reads_its_capitalised_lens(tmp_path):
    """ROS 1's CameraInfo spells its arrays D, K, R, P. (The bag is written with rosbags, the
    reader's own library: no other ROS 1 writer installs here; this checks onebox's mapping.)"""
    from rosbags.rosbag1 import Writer as Ros1Writer

    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    header = types["std_msgs/msg/Header"](
        seq=0, stamp=types["builtin_interfaces/msg/Time"](sec=5, nanosec=7), frame_id="cam"
    )
    depth = np.array([[0, 500, 501], [502, 0, 503]], dtype=np.uint16)
    image = types["sensor_msgs/msg/Image"](
        header=header, height=2, width=3, encoding="mono16", is_bigendian=0, step=6,
        data=depth.view(np.uint8).ravel(),
    )  # fmt: skip
    roi = types["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    k = np.array([300.0, 0, 1.0, 0, 300.0, 0.5, 0, 0, 1])
    info = types["sensor_msgs/msg/CameraInfo"](
        header=header, height=2, width=3, distortion_model="plumb_bob", D=np.zeros(5), K=k,
        R=np.eye(3).ravel(), P=np.zeros(12), binning_x=0, binning_y=0, roi=roi,
    )  # fmt: skip
    bag = tmp_path / "camera.bag"
    with Ros1Writer(bag) as w:
        for topic, message in (("/cam/depth/image_raw", image), ("/cam/depth/camera_info", info)):
            connection = w.add_connection(topic, message.__msgtype__, typestore=store)
            w.write(connection, 5_000_000_007, store.serialize_ros1(message, message.__msgtype__))
    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(bag), str(out))
    assert done.returncode == 0, done.stderr
    got = {item.key: bytes(item.payload) for item in iter_messages(out)}
    image_out = codec(Image).decode(got[keys.CAMERA.depth])
    assert image_out.encoding == "16UC1" and image_out.header.stamp_ns == 5_000_000_007
    assert np.array_equal(np.frombuffer(image_out.data, np.uint16).reshape(2, 3), depth)
    assert codec(CameraInfo).decode(got[keys.CAMERA.info]).k == list(k)


def _png16(values: np.ndarray) -> bytes:
    """A 16-bit greyscale PNG written by hand (zlib, no filter), as OpenCV writes the PNG of
    compressed_depth_image_transport: not by the library that reads it."""
    height, width = values.shape
    rows = b"".join(b"\x00" + values[r].astype(">u2").tobytes() for r in range(height))

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = struct.pack(">I", zlib.crc32(kind + body))
        return struct.pack(">I", len(body)) + kind + body + crc

    head = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", head)
        + chunk(b"IDAT", zlib.compress(rows))
        + chunk(b"IEND", b"")
    )


def _compressed(stamp_ns: int, frame: str, fmt: str, data: bytes) -> dict:
    return {"header": _header(stamp_ns, frame), "format": fmt, "data": data}


def test_a_bag_of_compressed_pictures_comes_in_as_the_raw_pictures(tmp_path):
    """Bags recorded to save space hold image_transport's topics: compressedDepth (a 12-byte
    header and a 16-bit PNG; 32FC1 as quantised inverse depth) and compressed (JPEG). They come
    in as 16UC1 / 32FC1 / rgb8, the lens found beside the raw topic they hang off."""
    import PIL.Image

    camera = Camera.tilted(0.7, 20.0, width=160, height=120)
    depth_m, colour = render(Scene(camera, Plane(), BOXES))
    depth_mm = np.where(np.isfinite(depth_m), np.rint(depth_m * 1000), 0).astype(np.uint16)
    # compressed_depth_image_transport's 32FC1: q = A / depth + B, A = Q (Q + 1), B = 1 - A / max.
    a = 100.0 * 101.0
    b = 1.0 - a / 10.0
    inverse = np.where(np.isfinite(depth_m), np.rint(a / depth_m + b), 0).astype(np.uint16)
    jpeg = io.BytesIO()
    PIL.Image.fromarray(colour).save(jpeg, format="JPEG", quality=95)
    store = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path / "compressed.mcap"
    depth_topic = f"{ALIGNED}/image_raw/compressedDepth"
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        schemas = {
            name: writer.register_msgdef(name, store.generate_msgdef(name, ros_version=2)[0])
            for name in ("sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo")
        }
        compressed, info = (
            schemas["sensor_msgs/msg/CompressedImage"],
            schemas["sensor_msgs/msg/CameraInfo"],
        )
        t = 1_700_000_000_000_000_000
        for topic, schema, message in (
            (
                depth_topic,
                compressed,
                _compressed(t, "optical", "16UC1; compressedDepth png",
                            struct.pack("<iff", 0, 0.0, 0.0) + _png16(depth_mm)),
            ),
            (
                f"{ROS}/depth/image_rect_raw/compressedDepth",
                compressed,
                _compressed(t, "depth", "32FC1; compressedDepth png",
                            struct.pack("<iff", 0, a, b) + _png16(inverse[::2, ::2])),
            ),
            (f"{ALIGNED}/camera_info", info, _info(t, "optical", camera.lens, 160, 120)),
            (
                f"{ROS}/color/image_raw/compressed",
                compressed,
                _compressed(t, "optical", "rgb8; jpeg compressed bgr8", jpeg.getvalue()),
            ),
        ):  # fmt: skip
            writer.write_message(topic, schema, message, t, t)
        writer.finish()
    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(path), str(out))
    assert done.returncode == 0, done.stderr
    assert f"depth   {depth_topic} (16UC1, from 16UC1; compressedDepth png, 160 x 120)" in (
        done.stdout
    )
    assert f"lens    {ALIGNED}/camera_info" in done.stdout
    got = {item.key: bytes(item.payload) for item in iter_messages(out)}
    depth = codec(Image).decode(got[keys.CAMERA.depth])
    assert np.array_equal(np.frombuffer(depth.data, np.uint16).reshape(120, 160), depth_mm)
    rgb = codec(Image).decode(got[keys.CAMERA.colour])
    assert rgb.encoding == "rgb8"
    pixels = np.frombuffer(rgb.data, np.uint8).reshape(120, 160, 3).astype(int)
    assert np.abs(pixels - colour).mean() < 3, "JPEG at quality 95 stays close"

    other = tmp_path / "other.mcap"
    done = run_onebox(
        "import",
        str(path),
        str(other),
        "--depth",
        f"{ROS}/depth/image_rect_raw/compressedDepth",
        "--info",
        f"{ALIGNED}/camera_info",
    )
    assert done.returncode == 0, done.stderr
    image = codec(Image).decode(next(i.payload for i in iter_messages(other)
                                     if i.key == keys.CAMERA.depth))  # fmt: skip
    assert image.encoding == "32FC1" and (image.width, image.height) == (80, 60)
    metres = np.frombuffer(image.data, np.float32).reshape(60, 80)
    truth = depth_m[::2, ::2]
    seen = np.isfinite(truth)
    assert np.array_equal(np.isfinite(metres), seen)
    assert np.abs(metres[seen] - truth[seen]).max() < 0.0001, "within the quantisation"


def test_a_damaged_compressed_picture_is_left_out_and_counted(tmp_path):
    """A compressedDepth message whose PNG is cut short is left out and counted by topic; the
    good ones around it come in. A bag whose only depth does not decode says so in one line."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    good = struct.pack("<iff", 0, 0.0, 0.0) + _png16(np.full((4, 6), 700, np.uint16))
    lens = Intrinsics(5.0, 5.0, 2.5, 1.5)
    topic = f"{ALIGNED}/image_raw/compressedDepth"

    def bag(name: str, payloads: list[bytes]) -> Path:
        path = tmp_path / name
        with path.open("wb") as f:
            writer = Ros2Writer(f)
            compressed, info = (
                writer.register_msgdef(n, store.generate_msgdef(n, ros_version=2)[0])
                for n in ("sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo")
            )
            for n, data in enumerate(payloads):
                t = 1_000_000_000 + n
                fmt = "16UC1; compressedDepth png"
                writer.write_message(topic, compressed, _compressed(t, "o", fmt, data), t, t)
                writer.write_message(
                    f"{ALIGNED}/camera_info", info, _info(t, "o", lens, 6, 4), t, t
                )
            writer.finish()
        return path

    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(bag("some.mcap", [good, good[:40], good])), str(out))
    assert done.returncode == 0, done.stderr
    assert f"left out, damaged: {topic} (1)" in done.stdout
    assert sum(1 for i in iter_messages(out) if i.key == keys.CAMERA.depth) == 2
    done = run_onebox("import", str(bag("none.mcap", [good[:40]])), str(tmp_path / "no.mcap"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "the PNG does not decode" in done.stderr and "holds no depth picture" in done.stderr


def _turned_z(angle_deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _moving_optical(t_s: float) -> np.ndarray:
    """world <- camera_color_optical_frame at t_s: a camera on an arm sliding 10 cm along x and
    turning 16 degrees about the world's up, both at a constant rate, over one second."""
    start = Camera.tilted(0.7, 20.0, width=320, height=240).camera_to_world
    pose = np.eye(4)
    pose[:3, :3] = _turned_z(-8.0 + 16.0 * t_s) @ start[:3, :3]
    pose[:3, 3] = start[:3, 3] + np.array([-0.05 + 0.10 * t_s, 0.0, 0.0])
    return pose


@pytest.fixture(scope="module")
def moving_bag(tmp_path_factory) -> tuple[Path, list[tuple[int, np.ndarray]]]:
    """A camera on an arm: /tf world -> camera_link every 50 ms, tf_static camera_link ->
    optical, four depth pictures stamped between /tf's samples, each rendered from where the
    camera was at its stamp."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path_factory.mktemp("arm") / "arm.mcap"
    optical = "camera_color_optical_frame"
    link_in_optical = np.eye(4)
    link_in_optical[:3, :3] = _quat_matrix(*OPTICAL_IN_LINK).T
    start = 1_700_000_000_000_000_000
    base = Camera.tilted(0.7, 20.0, width=320, height=240)
    truth = []
    with path.open("wb") as f:
        writer = Ros2Writer(f)
        image, info, tf = (
            writer.register_msgdef(n, store.generate_msgdef(n, ros_version=2)[0])
            for n in (
                "sensor_msgs/msg/Image",
                "sensor_msgs/msg/CameraInfo",
                "tf2_msgs/msg/TFMessage",
            )
        )
        fixed = _transform("camera_link", optical, np.zeros(3), OPTICAL_IN_LINK)
        writer.write_message("/tf_static", tf, {"transforms": [fixed]}, start, start)
        for k in range(21):
            t = start + k * 50_000_000
            link = _moving_optical(k * 0.05) @ link_in_optical
            moved = _transform("world", "camera_link", link[:3, 3], _matrix_quat(link[:3, :3]))
            moved["header"] = _header(t, "world")
            writer.write_message("/tf", tf, {"transforms": [moved]}, t, t)
        for n in range(4):
            t = start + 110_000_000 + n * 200_000_000
            pose = _moving_optical((t - start) / 1e9)
            camera = Camera(320, 240, base.lens, pose)
            depth_m, _ = render(Scene(camera, Plane(), BOXES))
            depth_mm = np.where(np.isfinite(depth_m), np.rint(depth_m * 1000), 0).astype(np.uint16)
            writer.write_message(
                f"{ALIGNED}/image_raw", image, _image(t, optical, depth_mm, "16UC1"), t, t
            )
            writer.write_message(
                f"{ALIGNED}/camera_info", info, _info(t, optical, base.lens, 320, 240), t, t
            )
            truth.append((t, pose))
        writer.finish()
    return path, truth


def test_a_moving_camera_gets_its_pose_at_each_pictures_stamp(moving_bag, tmp_path):
    path, truth = moving_bag
    out = tmp_path / "run.mcap"
    done = run_onebox("import", str(path), str(out))
    assert done.returncode == 0, done.stderr
    assert "pose    from /tf: the camera moves; camera/pose in 'world'" in done.stdout
    assert "--pose-source pose and ONEBOX_WORLD_FRAME=world" in done.stdout
    poses = [
        codec(TransformStamped).decode(i.payload)
        for i in iter_messages(out)
        if i.key == keys.CAMERA.pose
    ]
    assert [p.header.stamp_ns for p in poses] == [t for t, _ in truth]
    for pose, (_, true) in zip(poses, truth, strict=True):
        assert (pose.header.frame_id, pose.child_frame_id) == (
            "world",
            "camera_color_optical_frame",
        )
        assert np.allclose(matrix_of(pose), true, atol=1e-6), "interpolated as tf2 does"
    again = run_onebox(
        "import", str(path), str(tmp_path / "b.mcap"), "--world-frame", "camera_link"
    )
    assert "in 'camera_link'" in again.stdout


def test_a_moving_camera_replayed_puts_the_boxes_where_they_stand(
    moving_bag, tmp_path, processes, test_bus
):
    """The locator, fed camera/pose from the bag's /tf, measures in the world from a camera
    that moves between pictures: the boxes stay where they stand."""
    path, _ = moving_bag
    inbox = _replayed_to_a_locator(path, tmp_path, processes, test_bus, "--pose-source", "pose")

    def pictures_measured(items: list[tuple[str, bytes]]) -> bool:
        arrays = [codec(Detection3DArray).decode(p) for _, p in items]
        return len({a.header.stamp_ns for a in arrays if a.detections}) >= 3

    inbox.wait(pictures_measured, timeout_s=60)
    arrays = [codec(Detection3DArray).decode(p) for _, p in inbox.items]
    for found in (a for a in arrays if a.detections):
        assert found.header.frame_id == "world"
        assert len(found.detections) == len(BOXES)
        for true in BOXES:
            c = min(
                (d.bbox.center.position for d in found.detections),
                key=lambda c: math.dist(true.centre, (c.x, c.y, c.z)),
            )
            assert math.dist(true.centre, (c.x, c.y, c.z)) < 0.006
