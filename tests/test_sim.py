"""onebox sim as a real process on a private router: the seed's pictures, lens, frames and clock."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt
import pytest
from scipy.spatial.transform import Rotation

from onebox import bus
from onebox.testing.processes import (
    ROOT,
    Inbox,
    Processes,
    bus_args,
    free_port,
    has_key,
    honcho_env,
)
from schemas import (
    CameraInfo,
    Clock,
    GroundTruth,
    Image,
    Message,
    TFMessage,
    TransformStamped,
    codec,
)

SEED_PATCH = "\n".join(["0.400 0.400 0.400 0.373 0.340 0.340 0.340 0.340"] * 5)
"""The seed's section 5.2: basic camera rows 19-23, columns 43-50, metres to three decimals."""


class Run:
    """Everything one sim run published, decoded by key."""

    def __init__(self, items: list[tuple[str, bytes]], log: str = "") -> None:
        self.items = items
        self.log = log

    def all(self, key: str) -> list[Message]:
        message_type = {
            "tf_static": TFMessage,
            "clock": Clock,
            "sim/ground_truth": GroundTruth,
        }.get(key)
        if message_type is None:
            message_type = (
                CameraInfo
                if key.endswith("camera_info")
                else TransformStamped
                if key.endswith("pose")
                else Image
            )
        return [codec(message_type).decode(p) for k, p in self.items if k == key]

    def first(self, key: str) -> Message:
        found = self.all(key)
        assert found, f"nothing on {key}; the sim said:\n{self.log}"
        return found[0]


def run_sim(
    processes: Processes,
    endpoint: str,
    *flags: str,
    env: dict[str, str] | None = None,
    frames: int = 3,
) -> Run:
    """Run ``onebox sim --fast --frames N`` to the end and collect everything it published."""
    inbox = Inbox()
    with bus.open_bus(bus_args(endpoint)) as b:
        b.subscribe_raw("**", inbox, history=True)
        proc = processes.start("sim", "--fast", "--frames", str(frames), *flags, env=env)
        # ground truth is the last message of each capture
        inbox.wait(has_key("sim/ground_truth", frames))
        inbox.wait(has_key("tf_static"))
        out, _ = proc.communicate(timeout=30)
        assert "captures in" in out, out
    return Run(inbox.items, out)


@pytest.fixture(scope="module")
def default_run(module_router: str) -> Iterator[Run]:
    procs = Processes(module_router)
    yield run_sim(procs, module_router)
    procs.stop_all()


def depth_of(image: Image) -> npt.NDArray[np.float32]:
    assert image.encoding == "32FC1"
    assert image.step == image.width * 4
    return np.frombuffer(image.data, np.float32).reshape(image.height, image.width)


def matrix(t: TransformStamped) -> npt.NDArray[np.float64]:
    q, v = t.transform.rotation, t.transform.translation
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    m[:3, 3] = [v.x, v.y, v.z]
    return m


def world_from_optical(tf: TFMessage) -> npt.NDArray[np.float64]:
    """Walk tf_static from camera_optical_frame up to world."""
    by_child = {t.child_frame_id: t for t in tf.transforms}
    m, frame = np.eye(4), "camera_optical_frame"
    while frame != "world":
        t = by_child[frame]
        m = matrix(t) @ m
        frame = t.header.frame_id
    return m


def test_depth_reads_the_seeds_numbers(default_run: Run) -> None:
    """Row 86, column 212 reads 0.340 m (the box's top) and the table 0.400 m, to 0.1 mm."""
    depth = depth_of(default_run.first("camera/depth/image_raw"))
    assert depth.shape == (240, 320)
    assert abs(depth[86, 212] - 0.340) < 1e-4
    assert abs(depth[120, 160] - 0.400) < 1e-4
    assert abs(depth[200, 40] - 0.400) < 1e-4


def test_basic_camera_patch_is_the_seeds_table(default_run: Run) -> None:
    """The 80 x 60 basic camera's rows 19-23, columns 43-50 give section 5.2 exactly."""
    depth = depth_of(default_run.first("basic_camera/depth/image_raw"))
    assert depth.shape == (60, 80)
    patch = "\n".join(" ".join(f"{d:.3f}" for d in row) for row in depth[19:24, 43:51])
    assert patch == SEED_PATCH


def assert_seeds_counts(run: Run) -> None:
    """Published lens + tf_static turn the capture into 76,800 / 2,582 / 2,401 points."""
    info = run.first("camera/camera_info")
    assert isinstance(info, CameraInfo)
    depth = depth_of(run.first("camera/depth/image_raw")).astype(np.float64)
    fx, cx, fy, cy = info.k[0], info.k[2], info.k[4], info.k[5]
    v, u = np.mgrid[0 : info.height, 0 : info.width]  # the middle of pixel u is at u
    camera = np.stack([(u - cx) * depth / fx, (v - cy) * depth / fy, depth], axis=-1)
    tf = run.first("tf_static")
    assert isinstance(tf, TFMessage)
    m = world_from_optical(tf)
    points = camera.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    standing = points[points[:, 2] > 0.01]
    top_z = standing[:, 2].max()
    top = standing[standing[:, 2] > top_z - 0.001]
    assert (len(points), len(standing), len(top)) == (76_800, 2_582, 2_401)
    assert f"{top[:, 0].mean():+.3f} {top[:, 1].mean():+.3f} {top_z:.3f}" == "+0.064 +0.040 0.060"
    truth = run.first("sim/ground_truth")
    assert isinstance(truth, GroundTruth) and truth.box_pose and truth.box_size
    assert abs(top_z - (truth.box_pose.position.z + truth.box_size.z / 2)) < 1e-4
    patch = depth_of(run.first("basic_camera/depth/image_raw"))[19:24, 43:51]
    assert "\n".join(" ".join(f"{d:.3f}" for d in row) for row in patch) == SEED_PATCH


def test_every_pixel_into_the_room_gives_the_seeds_counts(default_run: Run) -> None:
    """Published lens + tf_static turn the capture into 76,800 / 2,582 / 2,401 points."""
    assert_seeds_counts(default_run)


def test_frames_agree_with_mujocos_camera(default_run: Run) -> None:
    """tf_static's chain, camera/pose and MuJoCo's own camera give one optical pose."""
    tf = default_run.first("tf_static")
    assert isinstance(tf, TFMessage)
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [
        ("world", "camera_link"),
        ("camera_link", "camera_optical_frame"),
    ]
    q = tf.transforms[1].transform.rotation
    assert np.allclose([q.x, q.y, q.z, q.w], [-0.5, 0.5, -0.5, 0.5])
    chain = world_from_optical(tf)
    truth = default_run.first("sim/ground_truth")
    assert isinstance(truth, GroundTruth)
    p, o = truth.camera_pose.position, truth.camera_pose.orientation
    mujoco_m = np.eye(4)
    mujoco_m[:3, :3] = Rotation.from_quat([o.x, o.y, o.z, o.w]).as_matrix()
    mujoco_m[:3, 3] = [p.x, p.y, p.z]
    pose = default_run.first("camera/pose")
    assert isinstance(pose, TransformStamped)
    assert np.allclose(chain, mujoco_m, atol=1e-9)
    assert np.allclose(matrix(pose), mujoco_m, atol=1e-9)
    # Optical axes in the room: right = +x, down = -y, forward = -z, 0.40 m up.
    assert np.allclose(chain[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-9)
    assert np.allclose(chain[:3, 3], [0.0, 0.0, 0.40])


def test_camera_info_at_the_defaults(default_run: Run) -> None:
    """fx = fy = 277.128..., cx = 159.5, cy = 119.5 (the middle of pixel u at u), P = [K | 0]."""
    info = default_run.first("camera/camera_info")
    assert isinstance(info, CameraInfo)
    f = 160 / math.tan(math.radians(30))
    assert info.k == pytest.approx([f, 0, 159.5, 0, f, 119.5, 0, 0, 1])
    assert f"{info.k[0]:.3f}" == "277.128"
    assert info.p == pytest.approx([f, 0, 159.5, 0, 0, f, 119.5, 0, 0, 0, 1, 0])
    assert info.d == [0.0] * 5
    assert (info.width, info.height, info.header.frame_id) == (320, 240, "camera_optical_frame")


def test_one_capture_one_stamp_following_the_clock(default_run: Run) -> None:
    """A capture's colour, depth, info and pose share one stamp: the clock's, 0.2 s apart."""
    clock = [m.clock_ns for m in default_run.all("clock") if isinstance(m, Clock)]
    assert clock == [0, 200_000_000, 400_000_000]
    for camera in ("camera", "basic_camera"):
        for key in ("image_raw", "depth/image_raw", "camera_info", "pose"):
            stamps = [m.header.stamp_ns for m in default_run.all(f"{camera}/{key}")]  # type: ignore[attr-defined]
            assert stamps == clock, (camera, key)


def test_picture_is_lit_like_the_seeds(default_run: Run) -> None:
    """The table shows grey 121 with darker grid lines; the box's top outshines its sides."""
    image = default_run.first("camera/image_raw")
    assert isinstance(image, Image) and image.encoding == "rgb8" and image.step == 320 * 3
    rgb = np.frombuffer(image.data, np.uint8).reshape(240, 320, 3).astype(int)
    assert abs(rgb[150, 40, 0] - 121) <= 3
    # Along a row of table, grid lines every 5 cm (about 35 pixels) are darker than the cells.
    row = rgb[200, :150, 0]
    assert row.min() < row.max() - 20
    assert (row < row.max() - 20).sum() >= 3
    top, side = rgb[85, 212], rgb[85, 186]
    assert top[0] > 150 and top[1] < 40  # red, lit
    assert side[0] < top[0] - 60  # the side the camera sees faces away from the light


@pytest.mark.parametrize(
    ("flags", "env", "width", "height", "hfov_deg"),
    [
        ((), {"ONEBOX_HFOV_DEG": "90"}, 320, 240, 90.0),
        (("--hfov-deg", "90"), {}, 320, 240, 90.0),
        (("--width", "640", "--height", "480"), {}, 640, 480, 60.0),
    ],
)
def test_lens_and_picture_change_together(
    processes: Processes,
    router: str,
    flags: tuple[str, ...],
    env: dict[str, str],
    width: int,
    height: int,
    hfov_deg: float,
) -> None:
    """A wider lens or a larger picture changes K, and the box lands where the new K says."""
    run = run_sim(processes, router, *flags, env=env, frames=1)
    info = run.first("camera/camera_info")
    assert isinstance(info, CameraInfo)
    f = width / 2 / math.tan(math.radians(hfov_deg) / 2)
    assert info.k == pytest.approx([f, 0, (width - 1) / 2, 0, f, (height - 1) / 2, 0, 0, 1])
    depth = depth_of(run.first("camera/depth/image_raw"))
    assert depth.shape == (height, width)
    # The box's top spans x 0.035..0.095 at depth 0.34; along the row through its middle
    # (y = 0.040), the first top pixel is the first whose middle lies past the projected edge.
    row = int(height / 2 - f * 0.040 / 0.34)
    first_top = int(np.argmax(np.abs(depth[row] - 0.34) < 1e-4))
    assert first_top == math.ceil(width / 2 + f * 0.035 / 0.34 - 0.5)
    last_top = width - 1 - int(np.argmax(np.abs(depth[row, ::-1] - 0.34) < 1e-4))
    assert last_top == math.floor(width / 2 + f * 0.095 / 0.34 - 0.5)


def test_late_joiner_still_receives_tf_static(processes: Processes, router: str) -> None:
    """A subscriber that starts 2 s into the run still gets the latched transforms."""
    early = Inbox()
    with bus.open_bus(bus_args(router)) as b:
        b.subscribe("clock", Clock, lambda k, m: early(k, m.clock_ns.to_bytes(8, "little")))
        processes.start("sim")  # real time, 5 Hz
        early.wait(
            lambda items: bool(items) and int.from_bytes(items[-1][1], "little") >= 2_000_000_000,
            30,
        )
    late = Inbox()
    with bus.open_bus(bus_args(router)) as b:
        b.subscribe_raw("tf_static", late, history=True)
        items = late.wait(has_key("tf_static"), 10)
    tf = codec(TFMessage).decode(items[0][1])
    assert [t.child_frame_id for t in tf.transforms] == ["camera_link", "camera_optical_frame"]


def test_bad_setting_is_one_line(router: str) -> None:
    """A setting out of range stops the sim with one line naming it, not a traceback."""
    proc = subprocess.run(
        [sys.executable, "-m", "services.cli", "sim", "--hfov-deg", "0", "--connect", router],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "hfov_deg 0.0" in proc.stderr and "Traceback" not in proc.stderr


def test_honcho_starts_router_and_sim() -> None:
    """``honcho start router sim`` on a private port publishes the clock and stops on SIGTERM."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = honcho_env(ONEBOX_ROUTER=endpoint)
    honcho = subprocess.Popen(
        [sys.executable, "-m", "honcho", "start", "router", "sim"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        inbox = Inbox()
        with bus.open_bus(bus_args(endpoint)) as b:
            b.subscribe_raw("clock", inbox)
            inbox.wait(has_key("clock", 2), 60)
    finally:
        honcho.send_signal(signal.SIGTERM)
        out, _ = honcho.communicate(timeout=30)
    assert "router" in out and "sim" in out
    assert "Traceback" not in out, out


SCENE_DIR = ROOT / "scene"


@pytest.mark.parametrize(
    ("name", "width", "height", "boxes", "objects"),
    [("one_box", 320, 240, 1, 0), ("pallet", 640, 480, 13, 1), ("clutter", 1280, 720, 3, 5)],
)
def test_each_committed_scene_publishes(
    processes: Processes, router: str, name: str, width: int, height: int, boxes: int, objects: int
) -> None:
    """--scene FILE builds the file's world: its picture size, every box and object in truth."""
    run = run_sim(processes, router, "--scene", str(SCENE_DIR / f"{name}.toml"), frames=1)
    depth = depth_of(run.first("camera/depth/image_raw"))
    assert depth.shape == (height, width)
    assert np.isfinite(depth).mean() > 0.9
    truth = run.first("sim/ground_truth")
    assert isinstance(truth, GroundTruth)
    assert (len(truth.boxes), len(truth.objects)) == (boxes, objects)
    assert all(b.top_in_view for b in truth.boxes)
    assert truth.header.stamp_ns == run.first("camera/depth/image_raw").header.stamp_ns  # type: ignore[attr-defined]
    if name == "one_box":
        assert_seeds_counts(run)


def test_scene_setting_and_lens_flag_together(processes: Processes, router: str) -> None:
    """ONEBOX_SCENE picks the pallet; --hfov-deg 90 still overrides its lens."""
    run = run_sim(
        processes,
        router,
        "--hfov-deg",
        "90",
        env={"ONEBOX_SCENE": str(SCENE_DIR / "pallet.toml")},
        frames=1,
    )
    info = run.first("camera/camera_info")
    assert isinstance(info, CameraInfo)
    assert (info.width, info.height) == (640, 480)
    assert info.k[0] == pytest.approx(320.0)


def test_depth_in_millimetres(processes: Processes, router: str) -> None:
    """--depth-encoding 16UC1 publishes whole millimetres: the box's top reads 340."""
    run = run_sim(processes, router, "--depth-encoding", "16UC1", frames=1)
    image = run.first("camera/depth/image_raw")
    assert isinstance(image, Image) and image.encoding == "16UC1" and image.step == 320 * 2
    mm = np.frombuffer(image.data, "<u2").reshape(240, 320)
    assert (mm[86, 212], mm[120, 160]) == (340, 400)


def test_random_scene_written_and_read_back(processes: Processes, router: str, tmp_path) -> None:
    """--random-scene 5 --write-scene saves a file that --scene builds into the same world."""
    path = tmp_path / "five.toml"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "services.cli",
            "sim",
            "--random-scene",
            "5",
            "--write-scene",
            str(path),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    first = run_sim(processes, router, "--random-scene", "5", frames=1)
    again = run_sim(processes, router, "--scene", str(path), frames=1)
    for key in ("camera/image_raw", "camera/depth/image_raw"):
        assert first.first(key).data == again.first(key).data  # type: ignore[attr-defined]
    truth = again.first("sim/ground_truth")
    assert isinstance(truth, GroundTruth) and len(truth.boxes) == 6


def test_noise_flag_roughens_the_depth(processes: Processes, router: str) -> None:
    """--noise d435 roughens the table's 0.400 m by the D435's 0.6 mm, plus a few speckles."""
    run = run_sim(processes, router, "--noise", "d435", frames=1)
    depth = depth_of(run.first("camera/depth/image_raw"))
    table = depth[150:230, 10:150]
    near = np.abs(table - 0.400) < 0.01
    assert 0.0004 < np.std(table[near]) < 0.0009
    assert 0 < (table < 0.35).sum() < 0.01 * table.size  # speckle, much nearer


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1, 0.1]\ncolor = [1, 0, 0, 1]\n", "box[0].color"),
        ("[[box]]\nx = 0\ny = 0\nsize = [0.1, 0.1, 0.1]\non = 0\n", "box[0].on"),
    ],
)
def test_bad_scene_file_is_one_line(router: str, tmp_path, text: str, named: str) -> None:
    """A scene file with an unknown key or a box on nothing stops the sim with one line."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    proc = subprocess.run(
        [sys.executable, "-m", "services.cli", "sim", "--scene", str(path), "--connect", router],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert named in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
