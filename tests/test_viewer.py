"""onebox viewer and onebox view: what they log to Rerun, read back from the .rrd they write."""

from __future__ import annotations

import signal
import subprocess
import sys
import urllib.request

import numpy as np
import pytest
import rerun as rr

from onebox import rerun_scene
from onebox.keys import type_for_key
from onebox.testing.fake_capture import BOX_CENTRE, BOX_SIZE, capture, tf_static, write_mcap
from onebox.testing.processes import CAPTURE, ROOT, free_port, honcho_env, wait_for_output
from onebox.testing.rrd import contents
from schemas import Detection3DArray, GroundTruth, Image, TFMessage, codec
from schemas.base import Header
from schemas.geometry import Pose, Vector3
from schemas.sim import BoxTruth


def publish_until_exit(test_bus, proc: subprocess.Popen[str], camera: str = "camera") -> None:
    """Publish captures 5 a second, new stamps each, until the viewer has what it wants."""
    tf = test_bus.publisher("tf_static", TFMessage, latched=True)
    tf.publish(tf_static())
    publishers = {}
    stamp_ns = 0
    while proc.poll() is None:
        stamp_ns += 200_000_000
        for key, message in capture(stamp_ns, camera).items():
            if key not in publishers:
                publishers[key] = test_bus.publisher(key, type(message))
            publishers[key].publish(message)
        try:
            proc.wait(timeout=0.2)  # the capture rate; returns early once the viewer is done
        except subprocess.TimeoutExpired:
            continue
        assert stamp_ns < 100 * 200_000_000, "the viewer never completed a capture"


def check_scene(held: dict, width: int = 320, height: int = 240) -> None:
    """The pinhole, both pictures, the points, the frames and the box, as the capture said.

    Each component holds a list of instances; the single ones are taken with [0].
    """
    pinhole = held["/world/camera/image"]
    # Rerun stores the 3 x 3 matrix column by column.
    k = np.asarray(pinhole["Pinhole:image_from_camera"][0]).reshape(3, 3).T
    assert k[0, 2] == pytest.approx(width / 2) and k[1, 2] == pytest.approx(height / 2)
    assert k[0, 0] == pytest.approx(width / 2 / np.tan(np.radians(30)), rel=1e-5)
    assert pinhole["Pinhole:resolution"][0] == [width, height]
    rgb = held["/world/camera/image/rgb"]
    assert rgb["EncodedImage:media_type"] == ["image/jpeg"], "colour is sent compressed"
    assert bytes(rgb["EncodedImage:blob"][0][:2]) == b"\xff\xd8"
    depth = held["/world/camera/image/depth"]
    assert depth["DepthImage:format"][0]["width"] == width
    depth_mm = np.frombuffer(bytes(depth["DepthImage:buffer"][0]), "<u2")
    assert depth_mm.size == width * height
    assert depth_mm[0] == 0, "NaN (no reading) must reach Rerun as 0"
    assert np.unique(depth_mm[1:]).tolist() == [340, 400]
    near, far = 340.0, 400.0
    assert depth["DepthImage:depth_range"][0] == pytest.approx([far, near]), "near is bright"
    assert "/world/camera/points" not in held, "the depth under the pinhole shows the points"
    assert held["/world/camera"]["Transform3D:translation"][0] == pytest.approx([0, 0, 0.4])
    assert held["/world/camera_link"]["Transform3D:translation"][0] == pytest.approx([0, 0, 0.4])
    assert "/world/camera_link/camera_optical_frame" in held
    box = held["/world/detections"]
    assert box["Boxes3D:centers"][0] == pytest.approx(BOX_CENTRE)
    assert np.asarray(box["Boxes3D:half_sizes"][0]) * 2 == pytest.approx(BOX_SIZE)
    assert box["Boxes3D:labels"][0] == "box: 60 x 60 x 60 mm, yaw +0°"
    assert "/world/table" in held


def test_viewer_saves_what_the_bus_carries(processes, test_bus, tmp_path):
    """Fed captures over Zenoh, --save writes an .rrd with pinhole, pictures, points and box."""
    out = tmp_path / "live.rrd"
    proc = processes.start("viewer", "--save", str(out), "--frames", "1", "--duration-s", "60")
    publish_until_exit(test_bus, proc)
    log = processes.stop(proc)
    assert proc.returncode == 0, log
    assert "capture at" in log
    held = contents(out)
    check_scene(held)
    assert held["/world/camera/image/rgb"]["_times"][0].total_seconds() > 0, "on sim time"


def test_viewer_keeps_going_after_bad_messages(processes, test_bus, tmp_path):
    """Garbage and a picture whose step is wrong are reported by key; the viewer carries on."""
    out = tmp_path / "bad.rrd"
    proc = processes.start("viewer", "--save", str(out), "--frames", "1", "--duration-s", "60")
    raw = test_bus.session.declare_publisher("camera/image_raw")
    sheared = test_bus.publisher("camera/depth/image_raw", Image)
    bad_image = Image(width=320, height=240, encoding="32FC1", step=100, data=b"\0" * 100)
    for _ in range(3):
        raw.put(b"\xc1 not msgpack")
        sheared.publish(bad_image)
    publish_until_exit(test_bus, proc)
    log = processes.stop(proc)
    assert proc.returncode == 0, log
    check_scene(contents(out))


def test_viewer_off_idles_until_stopped(processes):
    """ONEBOX_VIEWER=false logs "viewer off", stays up (honcho would stop all) and exits 0."""
    proc = processes.start("viewer", env={"ONEBOX_VIEWER": "false"})
    wait_for_output(proc, "viewer off", timeout_s=20)
    assert proc.poll() is None
    processes.stop(proc)
    assert proc.returncode == 0


def test_viewer_serves_the_web_viewer_on_loopback(processes, test_bus):
    """With no display it serves the web viewer on 127.0.0.1 and prints the address to open;
    the page starts Rerun's viewer with the page memory limit, the rest is Rerun's own."""
    grpc_port, web_port = free_port(), free_port()
    proc = processes.start(
        "viewer",
        "--grpc-port",
        str(grpc_port),
        "--web-port",
        str(web_port),
        env={"DISPLAY": "", "WAYLAND_DISPLAY": "", "ONEBOX_PAGE_MEMORY_LIMIT": "96MiB"},
    )
    printed = wait_for_output(proc, "/proxy", timeout_s=40)
    address = f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"
    assert address in printed
    with urllib.request.urlopen(address, timeout=10) as page:
        html = page.read()
        assert page.status == 200 and b"<html" in html.lower()
    assert html.count(b'memory_limit: "96MiB"') == 1, "the viewer is started with the limit"
    with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/re_viewer.js", timeout=10) as js:
        assert b"wasm_bindgen" in js.read()
    # A browser that leaves mid-download (a reload) is no error.
    with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/re_viewer_bg.wasm", timeout=10) as w:
        assert w.headers["Content-Type"] == "application/wasm" and w.read(4) == b"\0asm"
    out = processes.stop(proc)
    assert proc.returncode == 0
    assert "Traceback" not in printed + out
    # The web server child went with it: its port is free again.
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=2)


def test_a_page_memory_limit_that_is_no_size_is_one_line():
    """--page-memory-limit must be a size Rerun reads; anything else is one line, exit 2."""
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "viewer", "--web", "--page-memory-limit", "lots"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert "--page-memory-limit 'lots' is no size" in done.stderr
    assert "Traceback" not in done.stderr


def test_scene_log_draws_an_empty_detection_array_as_no_box(tmp_path):
    """An empty Detection3DArray clears the box instead of leaving the last one standing."""
    out = tmp_path / "empty.rrd"
    rec = rr.RecordingStream("onebox_test")
    rec.save(out)
    msgs = capture(200_000_000)
    empty = type(msgs["detections"])()
    with rec:
        scene = rerun_scene.SceneLog(rec)
        scene.start()
        assert scene.log("detections", msgs["detections"]) == "detections"
        assert scene.log("detections", empty) == "detections"
        assert scene.log("basic_camera/image_raw", msgs["camera/image_raw"]) is None
    held = contents(out)
    assert any("Clear" in name for name in held["/world/detections"])


def test_every_pipeline_type_round_trips_through_scene_log(tmp_path):
    """Each message of a capture decodes from its wire bytes and becomes the entity it should."""
    rec = rr.RecordingStream("onebox_test")
    rec.save(tmp_path / "kinds.rrd")
    with rec:
        scene = rerun_scene.SceneLog(rec)
        kinds = {}
        for key, message in capture(1).items():
            wire = codec(type(message)).encode(message)
            kinds[key] = scene.log(key, codec(type_for_key(key)).decode(wire))
    assert kinds == {
        "camera/image_raw": "colour",
        "camera/depth/image_raw": "depth",
        "camera/camera_info": "info",
        "camera/pose": "pose",
        "camera/points": "points",
        "detections": "detections",
    }


def test_view_writes_an_rrd_of_a_recording(tmp_path):
    """onebox view FILE.mcap --save OUT.rrd shows a recording as the live viewer would."""
    recording = write_mcap(tmp_path / "fake.mcap", captures=2)
    out = tmp_path / "view.rrd"
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "view", str(recording), "--save", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert "13 messages shown" in done.stdout
    held = contents(out)
    check_scene(held)
    stamps = {t.total_seconds() for t in held["/world/camera/image/rgb"]["_times"]}
    assert stamps == {0.2, 0.4}, "each capture at its own simulated time"


def test_view_of_a_missing_file_is_one_clear_line(tmp_path):
    """A path that does not exist: exit 2 and a line naming it, no traceback."""
    missing = tmp_path / "nope.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "view", str(missing), "--save", str(tmp_path / "x")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert str(missing) in done.stderr and "Traceback" not in done.stderr


def test_camera_sits_on_the_tf_static_chain_until_a_pose_arrives(tmp_path):
    """Without camera/pose the pinhole is placed by world -> camera_link -> optical frame."""
    out = tmp_path / "tf.rrd"
    rec = rr.RecordingStream("onebox_test")
    rec.save(out)
    msgs = capture(200_000_000)
    with rec:
        scene = rerun_scene.SceneLog(rec)
        scene.log("tf_static", tf_static())
        scene.log("camera/image_raw", msgs["camera/image_raw"])
    camera = contents(out)["/world/camera"]
    assert camera["Transform3D:translation"][0] == pytest.approx([0, 0, 0.4])
    # Looking straight down: optical x = world +x, y = world -y, z = world -z.
    x, y, z, w = camera["Transform3D:quaternion"][0]
    assert abs(x) == pytest.approx(1.0) and y == z == w == pytest.approx(0.0, abs=1e-9)


def test_viewer_fed_a_replay_of_the_committed_capture(processes, test_bus, tmp_path):
    """Replay + points + locator + viewer: the .rrd has the pinhole, pictures, cloud and the box."""
    detections = []
    test_bus.subscribe("detections", Detection3DArray, lambda key, m: detections.append(m))
    out = tmp_path / "capture.rrd"
    viewer = processes.start("viewer", "--save", str(out), "--frames", "1", "--duration-s", "60")
    processes.start("points")
    processes.start("locator")
    processes.start("replay", str(CAPTURE), "--loop")
    viewer.wait(timeout=90)
    log = processes.stop(viewer)
    assert viewer.returncode == 0 and "capture at" in log, log
    held = contents(out)
    pinhole = held["/world/camera/image"]
    assert pinhole["Pinhole:resolution"][0] == [320, 240]
    assert held["/world/camera/image/rgb"]["EncodedImage:media_type"] == ["image/jpeg"]
    assert len(held["/world/camera/image/depth"]["DepthImage:buffer"][0]) == 320 * 240 * 2
    # The camera is where tf_static puts it: the capture has no camera/pose.
    assert held["/world/camera"]["Transform3D:translation"][0] == pytest.approx([0, 0, 0.4])
    found = next(m for m in detections if m.detections).detections[0].bbox
    box = held["/world/detections"]
    p, s = found.center.position, found.size
    # The viewer shows the newest detection, which may be a later capture than the first found.
    assert box["Boxes3D:centers"][0] == pytest.approx([p.x, p.y, p.z], abs=1e-4)
    assert np.asarray(box["Boxes3D:half_sizes"][0]) * 2 == pytest.approx([s.x, s.y, s.z], abs=1e-4)
    # The seed's box: middle (+0.064, +0.040) m, 6 cm tall.
    assert box["Boxes3D:centers"][0][:2] == pytest.approx([0.064, 0.040], abs=0.002)
    assert box["Boxes3D:labels"][0].endswith("°")


def test_honcho_start_with_viewer_false_runs_without_a_viewer(tmp_path):
    """ONEBOX_HFOV_DEG=90 ONEBOX_VIEWER=false honcho start: all runs, the viewer idles, 90° lens."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = honcho_env(ONEBOX_ROUTER=endpoint, ONEBOX_HFOV_DEG="90", ONEBOX_VIEWER="false")
    honcho = subprocess.Popen(
        [sys.executable, "-m", "honcho", "start"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait_for_output(honcho, "viewer off", timeout_s=60)
        done = subprocess.run(
            [sys.executable, "-m", "services.cli", "check", "--window-s", "1.5"],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
        )
    finally:
        honcho.send_signal(signal.SIGTERM)
        out, _ = honcho.communicate(timeout=30)
    assert done.returncode == 0, done.stderr
    # hfov 90 degrees: fx = 160 / tan(45 degrees) = 160 for the 320-wide camera.
    assert "camera/camera_info: 320 x 240, fx 160.000  fy 160.000" in done.stdout
    assert "camera/points" in done.stdout and "detections" in done.stdout
    assert "viewer.1 stopped" in out, "the idle viewer stayed up until honcho stopped it"
    assert "Traceback" not in out


def test_a_live_page_gets_fewer_smaller_pictures_and_the_pose_once(tmp_path):
    """Live: pictures once a simulated second at half size under a halved lens, boxes with
    every capture, the unmoving camera's pose once and static."""
    out = tmp_path / "live.rrd"
    rec = rr.RecordingStream("onebox_test")
    rec.save(out)
    with rec:
        scene = rerun_scene.SceneLog(rec, jpeg=False, live=rerun_scene.Live(picture_hz=1, scale=2))
        for i in range(1, 7):
            for key, message in capture(i * 200_000_000).items():
                scene.log(key, message)
            header = Header(stamp_ns=i * 200_000_000, frame_id="world")
            box = BoxTruth(
                pose=Pose(position=Vector3(x=0.1, z=0.03)), size=Vector3(x=0.06, y=0.06, z=0.06)
            )
            scene.log("sim/ground_truth", GroundTruth(header=header, boxes=[box]))
    held = contents(out)
    assert "_times" not in held["/world/ground_truth"], "the unmoving true box: static, once"
    assert held["/world/ground_truth"]["Boxes3D:centers"][0] == pytest.approx([0.1, 0, 0.03])
    seconds = {
        name: sorted(t.total_seconds() for t in held[name].get("_times", []))
        for name in ("/world/camera/image/rgb", "/world/camera/image/depth", "/world/detections")
    }
    assert seconds["/world/camera/image/rgb"] == [0.2, 1.2]
    assert seconds["/world/camera/image/depth"] == [0.2, 1.2]
    assert seconds["/world/detections"] == [0.2, 0.4, 0.6, 0.8, 1.0, 1.2]
    assert held["/world/camera/image/rgb"]["Image:format"][0]["width"] == 160
    assert held["/world/camera/image/depth"]["DepthImage:format"][0]["width"] == 160
    pinhole = held["/world/camera/image"]
    assert pinhole["Pinhole:resolution"][0] == [160, 120]
    k = np.asarray(pinhole["Pinhole:image_from_camera"][0]).reshape(3, 3).T
    assert k[0, 2] == pytest.approx(80) and k[1, 2] == pytest.approx(60)
    assert k[0, 0] == pytest.approx(160 / 2 / np.tan(np.radians(30)), rel=1e-5)
    assert "_times" not in held["/world/camera"], "the pose is static"
    assert held["/world/camera"]["Transform3D:translation"][0] == pytest.approx([0, 0, 0.4])
