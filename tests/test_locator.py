"""onebox locator as a real process on a private router: replayed, end to end, and fed garbage."""

from __future__ import annotations

import os
import platform
import re
import subprocess
import sys
import time
from dataclasses import replace

import msgspec
import numpy as np
import pytest

from onebox import bus
from onebox.geometry import FrameTree, matrix_of
from onebox.perception.boxes import Found
from onebox.perception.support import Support
from onebox.sync import StampMatcher
from onebox.testing.capture import CAPTURE
from onebox.testing.processes import Inbox, Output, has_key
from onebox.testing.synthetic import (
    Scene,
    camera_info,
    camera_pose,
    depth_image,
    depth_picture,
    tf_static,
)
from schemas import (
    CameraInfo,
    Detection3DArray,
    GroundTruth,
    Image,
    SupportPlane,
    TFMessage,
    TransformStamped,
    codec,
)
from services.locator import ColourCache, describe_support

SEED_LINE = "box: middle (+0.064, +0.040) m, height 0.060 m, from 2,401 points on its top"
BOX_LINE = (
    r"box: middle \(\+0\.06[45], \+0\.04[01]\) m, height 0\.060 m, from [\d,]+ points on its top"
)
"""The seed's line as the box finder prints it: the same numbers or truer ones (the box's y is
0.0405, which rounds either way)."""
SECOND_NS = 1_000_000_000


@pytest.fixture
def locators(processes):
    """Starts ``onebox locator`` processes whose output a test can wait on; stops them all."""
    started: list[Output] = []

    def start(*flags: str) -> Output:
        output = Output(processes.start("locator", "--log-interval-s", "0.5", *flags))
        started.append(output)
        output.wait_for("finding (every box|the box)")
        return output

    yield start
    for output in started:
        output.stop()


def decode_detections(items: list[tuple[str, bytes]]) -> list[Detection3DArray]:
    decoder = codec(Detection3DArray)
    return [decoder.decode(p) for k, p in items if k == "detections"]


class Camera:
    """Publishes synthetic captures from the test, as the sim would."""

    def __init__(self, b: bus.Bus, scene: Scene | None = None, prefix: str = "") -> None:
        self.scene = scene = scene or Scene()
        self.depth = b.publisher(f"{prefix}camera/depth/image_raw", Image)
        self.info = b.publisher(f"{prefix}camera/camera_info", CameraInfo)
        self.pose = b.publisher(f"{prefix}camera/pose", TransformStamped)
        self.tf = b.publisher(f"{prefix}tf_static", TFMessage, latched=True)
        self.picture = depth_picture(scene)
        self.stamp_ns = 0

    def publish_tf(self) -> None:
        self.tf.publish(tf_static(self.scene.mount_height))

    def capture(self, *, depth: Image | None = None, info: bool = True) -> int:
        self.stamp_ns += SECOND_NS // 5
        self.pose.publish(camera_pose(self.scene.mount_height, self.stamp_ns))
        if info:
            self.info.publish(camera_info(self.scene, self.stamp_ns))
        self.depth.publish(depth or depth_image(self.picture, self.stamp_ns))
        return self.stamp_ns

    def depth_16uc1(self, stamp_ns: int) -> Image:
        """The picture as a real camera sends it: millimetres, 0 where there is no reading."""
        mm = np.round(self.picture * 1000).astype("<u2")
        mm[:4] = 0
        image = depth_image(self.picture, stamp_ns)
        return msgspec.structs.replace(
            image, encoding="16UC1", step=image.width * 2, data=mm.tobytes()
        )

    def until_measured(
        self, inbox: Inbox, timeout_s: float = 20.0, millimetres: bool = False
    ) -> Detection3DArray:
        """Publish captures until one comes back measured (the locator may still be joining)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            next_ns = self.stamp_ns + SECOND_NS // 5
            stamp = self.capture(depth=self.depth_16uc1(next_ns) if millimetres else None)

            def measured(items: list[tuple[str, bytes]], stamp: int = stamp) -> bool:
                return any(d.header.stamp_ns == stamp for d in decode_detections(items))

            try:
                items = inbox.wait(measured, timeout_s=0.5)
            except AssertionError:
                continue
            return next(d for d in decode_detections(items) if d.header.stamp_ns == stamp)
        raise AssertionError("the locator measured nothing")


def assert_default_box(array: Detection3DArray) -> None:
    scene = Scene()
    assert array.header.frame_id == "world"
    [detection] = array.detections
    centre = detection.bbox.center.position
    assert detection.results[0].class_id == "box"
    assert 0.5 < detection.results[0].score <= 1.0
    assert abs(centre.x - scene.box_x) < 0.001 and abs(centre.y - scene.box_y) < 0.001
    assert centre.z == pytest.approx(scene.box_size / 2, abs=1e-4)
    assert detection.bbox.size.z == pytest.approx(scene.box_size, abs=1e-4)
    assert detection.bbox.size.x == pytest.approx(scene.box_size, abs=0.002)
    assert detection.bbox.size.y == pytest.approx(scene.box_size, abs=0.002)


# --- unit: matching by stamp ---------------------------------------------------------------------


def test_matcher_pairs_equal_stamps_and_newest_wins():
    """Equal stamps pair in any order; an older unmatched lead is reported when a newer pairs."""
    lost = []
    matcher = StampMatcher(["depth", "info"], on_unmatched=lambda s, why: lost.append(s.stamp_ns))
    assert matcher.add("depth", 1, "d1") is None
    assert matcher.add("depth", 2, "d2") is None
    found = matcher.add("info", 2, "i2")
    assert found is not None and (found["depth"].item, found["info"].item) == ("d2", "i2")
    assert lost == [1]
    assert matcher.add("info", 3, "i3") is None
    found = matcher.add("depth", 3, "d3")
    assert found is not None and found["info"].item == "i3"


def test_matcher_with_slop_pairs_the_nearest():
    """Within the slop the nearest stamp pairs; beyond it nothing does."""
    matcher = StampMatcher(["depth", "info"], slop_ns=5)
    matcher.add("info", 100, "far")
    matcher.add("info", 197, "near")
    found = matcher.add("depth", 200, "d")
    assert found is not None and found["info"].item == "near"
    assert matcher.add("depth", 300, "d2") is None


def test_colour_of_a_run_before_the_clock_went_back_is_never_paired():
    """A restarted camera starts its stamps again: the colour kept from the run before, whose
    stamps this run reaches later, is dropped, not paired with this run's depth."""
    cache = ColourCache(keep=4)
    old, new = np.zeros((2, 2, 3), np.uint8), np.ones((2, 2, 3), np.uint8)
    for stamp in (2_700, 2_800, 2_900, 3_000):
        cache.put(stamp, old)
    cache.put(100, new)
    assert cache.take(100, slop_ns=10, wait_s=0) is new
    assert cache.take(2_800, slop_ns=10, wait_s=0) is None
    cache.put(2_800, new)
    assert cache.take(2_800, slop_ns=10, wait_s=0) is new


# --- the real process, synthetic captures --------------------------------------------------------


def test_synthetic_capture_is_detected_and_logged(locators, test_bus, inbox):
    """Depth + info + tf_static give a detection at the box and the seed-style line; so does
    a 16UC1 picture in millimetres with holes of 0."""
    test_bus.subscribe_raw("detections", inbox)
    camera = Camera(test_bus)
    camera.publish_tf()
    output = locators()
    assert_default_box(camera.until_measured(inbox))
    output.wait_for(BOX_LINE)
    assert_default_box(camera.until_measured(inbox, millimetres=True))
    assert "Traceback" not in output.stop()


def test_pose_source_pose_agrees_with_tf(locators, test_bus, inbox):
    """--pose-source pose (stamp-matched camera/pose) measures what tf_static gives."""
    test_bus.subscribe_raw("detections", inbox)
    camera = Camera(test_bus)
    camera.publish_tf()
    assert np.allclose(
        FrameTree(tf_static(0.4).transforms).lookup("world", "camera_optical_frame"),
        matrix_of(camera_pose(0.4, 0)),
        atol=1e-12,
    )
    output = locators("--pose-source", "pose")
    by_pose = camera.until_measured(inbox)
    assert_default_box(by_pose)
    output.stop()
    locators("--pose-source", "tf")
    by_tf = camera.until_measured(inbox)
    assert by_tf.detections[0].bbox == by_pose.detections[0].bbox


def test_without_a_pose_the_box_is_reported_in_the_cameras_frame(locators, test_bus, inbox):
    """--pose-source none (a user with only a depth camera): the box and the surface come out in
    camera_optical_frame, the box 0.34 m away along the optical axis's side of the surface,
    6 cm tall and 6 cm wide, with no tilt from a world it does not know."""
    test_bus.subscribe_raw("detections", inbox)
    test_bus.subscribe_raw("support", inbox)
    camera = Camera(test_bus)
    locators("--pose-source", "none")
    array = camera.until_measured(inbox)
    assert array.header.frame_id == "camera_optical_frame"
    [detection] = array.detections
    size, centre = detection.bbox.size, detection.bbox.center.position
    assert size.z == pytest.approx(0.06, abs=1e-4)
    assert size.x == pytest.approx(0.06, abs=0.002) and size.y == pytest.approx(0.06, abs=0.002)
    # The seed's camera looks straight down from 0.40 m: the box's middle is 0.37 m away, and
    # world (x, y) = (0.065, 0.0405) is optical (x, -y).
    assert (centre.x, centre.y, centre.z) == pytest.approx((0.065, -0.0405, 0.37), abs=0.001)
    items = inbox.wait(has_key("support"))
    support = [codec(SupportPlane).decode(p) for k, p in items if k == "support"][-1]
    assert support.header.frame_id == "camera_optical_frame" and support.tilt_deg is None
    assert support.offset_m == pytest.approx(0.40, abs=0.001)


def test_the_seeds_method_without_a_pose_says_so_and_waits_for_one(locators, test_bus, inbox):
    """--method seed measures in the world: with nothing placing the camera it drops each
    picture with a line saying why (no traceback), and measures once tf_static comes."""
    test_bus.subscribe_raw("detections", inbox)
    camera = Camera(test_bus)
    output = locators("--method", "seed")
    deadline = time.monotonic() + 20.0
    while "needs the camera's pose" not in output.text and time.monotonic() < deadline:
        camera.capture()
        time.sleep(0.2)
    output.wait_for("needs the camera's pose", timeout_s=1.0)
    camera.publish_tf()
    assert_default_box(camera.until_measured(inbox))
    assert "Traceback" not in output.stop()


def test_workspace_leaves_out_what_lies_outside(locators, test_bus, inbox):
    """A workspace that does not hold the box: an empty array, and the no-box line."""
    test_bus.subscribe_raw("detections", inbox)
    camera = Camera(test_bus)
    camera.publish_tf()
    output = locators("--workspace=-0.5,0.0,-0.5,0.5,0.0,0.5")
    assert camera.until_measured(inbox).detections == []
    output.wait_for("no box in view")


def test_no_box_gives_an_empty_array_and_the_no_box_line(locators, test_bus, inbox):
    """An empty table: an empty Detection3DArray, and the log says no box is in view."""
    test_bus.subscribe_raw("detections", inbox)
    camera = Camera(test_bus, Scene(has_box=False))
    camera.publish_tf()
    output = locators()
    array = camera.until_measured(inbox)
    assert array.detections == [] and array.header.frame_id == "world"
    output.wait_for("no box in view")


def test_the_surface_line_says_how_noisy_the_depth_is():
    """The surface in the log says the depth noise the finder measured on it and, where the
    errors come in lumps (a stereo camera's), how wide: what tells a user why a far box is
    lost. Independent errors get no word on lumps."""
    plane = Support((0.0, 0.0, 1.0), -0.7, 0.8, 1.2, "world", sigma_m=0.0041, distance_m=1.5)
    lumpy = describe_support(Found(replace(plane, lump_px=2.84), [], "world"), "world")
    assert lumpy == (
        "surface +0.700 m along (+0.00, +0.00, +1.00) in world, 1.2 deg from level, "
        "depth noise 4.1 mm at 1.50 m in lumps 2.8 px wide"
    )
    alone = describe_support(Found(replace(plane, lump_px=0.2), [], "world"), "world")
    assert alone.endswith("depth noise 4.1 mm at 1.50 m")


def test_every_bad_input_is_reported_and_the_locator_keeps_measuring(locators, test_bus, inbox):
    """Each unusable message gives its log line, nothing crashes, and a good capture still works."""
    test_bus.subscribe_raw("detections", inbox)
    camera = Camera(test_bus)
    camera.publish_tf()
    output = locators()
    camera.until_measured(inbox)
    raw_depth = test_bus.session.declare_publisher("camera/depth/image_raw")
    raw_info = test_bus.session.declare_publisher("camera/camera_info")
    try:
        good = depth_image(camera.picture, 0)

        def bad(frame_id: str = "camera_optical_frame", **changes) -> Image:
            """The good picture, stamped as the next capture, with ``changes``."""
            header = msgspec.structs.replace(
                good.header, stamp_ns=camera.stamp_ns + SECOND_NS // 5, frame_id=frame_id
            )
            return msgspec.structs.replace(good, header=header, **changes)

        def small_lens() -> None:
            """A depth picture whose camera info, same stamp, is for another size."""
            camera.capture(depth=bad(), info=False)
            camera.info.publish(camera_info(Scene(width=160, height=120), camera.stamp_ns))

        cases: list[tuple[str, object]] = [
            ("not a onebox.sensor.Image", lambda: raw_depth.put(b"\x00garbage\xff")),
            (
                "camera/camera_info: not a onebox.sensor.CameraInfo",
                lambda: raw_info.put(codec(Image).encode(good)),
            ),
            ("is not a depth picture", lambda: camera.capture(depth=bad(encoding="rgb8"))),
            (r"step x height", lambda: camera.capture(depth=bad(height=239))),
            (r"step counts bytes", lambda: camera.capture(depth=bad(step=320))),
            (
                "has no reading at all",
                lambda: camera.capture(
                    depth=bad(data=np.full((240, 320), np.nan, "<f4").tobytes())
                ),
            ),
            ("no transform from 'elsewhere'", lambda: camera.capture(depth=bad("elsewhere"))),
            ("no camera/camera_info with that stamp", lambda: camera.capture(info=False)),
            ("camera info is for 160 x 120", small_lens),
            ("stamp went back", lambda: camera.depth.publish(depth_image(camera.picture, 1))),
        ]
        for line, send in cases:
            # Pictures travel with congestion control "drop": on a loaded machine one may be
            # lost on the way, so a case is sent again until its line comes (as a camera would).
            pattern = re.escape(line) if "\\" not in line else line
            deadline = time.monotonic() + 20.0
            while True:
                send()
                try:
                    output.wait_for(pattern, timeout_s=2.0)
                    break
                except AssertionError:
                    if time.monotonic() > deadline:
                        raise
        lens = test_bus.publisher("camera/camera_info", CameraInfo)
        zero_fx = camera_info(camera.scene, camera.stamp_ns + 1)
        lens.publish(msgspec.structs.replace(zero_fx, k=[0.0] * 9))
        output.wait_for("fx and fy must be > 0")
        assert output.proc.poll() is None
        assert_default_box(camera.until_measured(inbox))
    finally:
        raw_depth.undeclare()
        raw_info.undeclare()
    assert "Traceback" not in output.stop()


# --- replayed capture ----------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["boxes", "seed"])
def test_replayed_capture_gives_the_seed_detection(locators, processes, test_bus, inbox, method):
    """onebox replay of the committed capture into a real locator: the seed's (+0.064, +0.040),
    0.060 m and its line exactly with --method seed; the box finder's within 1 mm of the truth
    (+0.065, +0.040) with the seed's line in the same form."""
    test_bus.subscribe_raw("detections", inbox)
    output = locators("--method", method)
    replay = processes.start("replay", str(CAPTURE), "--loop")
    inbox.wait(has_key("detections"))
    processes.stop(replay)
    array = decode_detections(inbox.items)[0]
    [detection] = array.detections
    centre = detection.bbox.center.position
    if method == "seed":
        assert f"({centre.x:+.3f}, {centre.y:+.3f}) {detection.bbox.size.z:.3f}" == (
            "(+0.064, +0.040) 0.060"
        )
        output.wait_for(re.escape(SEED_LINE))
    else:
        assert abs(centre.x - 0.065) < 0.001 and abs(centre.y - 0.040) < 0.001
        assert abs(detection.bbox.size.z - 0.060) < 0.001
        assert abs(detection.bbox.size.x - 0.060) < 0.002
        output.wait_for(BOX_LINE)


# --- end to end with the sim ---------------------------------------------------------------------


def truths(items: list[tuple[str, bytes]]) -> dict[int, GroundTruth]:
    decoder = codec(GroundTruth)
    return {
        t.header.stamp_ns: t
        for t in (decoder.decode(p) for k, p in items if k == "sim/ground_truth")
    }


def matched(items) -> list[tuple[Detection3DArray, GroundTruth]]:
    by_stamp = truths(items)
    return [
        (d, by_stamp[d.header.stamp_ns])
        for d in decode_detections(items)
        if d.header.stamp_ns in by_stamp
    ]


def test_end_to_end_with_the_sim(locators, processes, test_bus, inbox):
    """Router, sim and locator: the seed's line, a detection within 1 mm of the truth; moving the
    box moves it; no box gives the no-box line and empty arrays; tf and camera/pose agree."""
    for key in ("detections", "sim/ground_truth", "camera/pose", "tf_static"):
        test_bus.subscribe_raw(key, inbox, history=key == "tf_static")
    output = locators("--log-interval-s", "2")  # the seed's line, every 2 s
    sim = processes.start("sim", "--rate-hz", "10", "--frames", "30")
    started = time.monotonic()
    inbox.wait(lambda items: len(matched(items)) >= 3, timeout_s=30)
    output.wait_for(BOX_LINE, timeout_s=30 - (time.monotonic() - started))
    detection, truth = matched(inbox.items)[-1]
    assert truth.box_pose is not None
    centre, true_centre = detection.detections[0].bbox.center.position, truth.box_pose.position
    assert abs(centre.x - true_centre.x) < 0.001 and abs(centre.y - true_centre.y) < 0.001
    assert abs(centre.z - true_centre.z) < 0.001
    # The fixed camera: the chain on tf_static and the stamped camera/pose agree.
    tf = next(codec(TFMessage).decode(p) for k, p in inbox.items if k == "tf_static")
    pose = next(codec(TransformStamped).decode(p) for k, p in inbox.items if k == "camera/pose")
    np.testing.assert_allclose(
        FrameTree(tf.transforms).lookup("world", "camera_optical_frame"),
        matrix_of(pose),
        atol=1e-6,
    )
    processes.stop(sim)

    inbox.items.clear()
    sim = processes.start(
        "sim", "--rate-hz", "10", "--frames", "30", "--box-x", "-0.1", "--box-y", "0.06"
    )
    inbox.wait(lambda items: len(matched(items)) >= 2, timeout_s=30)
    detection, truth = matched(inbox.items)[-1]
    centre = detection.detections[0].bbox.center.position
    assert truth.box_pose is not None
    assert abs(centre.x - (-0.1)) < 0.002 and abs(centre.y - 0.06) < 0.002
    assert abs(centre.x - truth.box_pose.position.x) < 0.001
    processes.stop(sim)

    inbox.items.clear()
    sim = processes.start("sim", "--rate-hz", "10", "--frames", "30", "--no-box")
    inbox.wait(lambda items: len(matched(items)) >= 2, timeout_s=30)
    assert all(d.detections == [] for d, _ in matched(inbox.items))
    output.wait_for("no box in view")
    processes.stop(sim)
    assert "Traceback" not in output.stop()
    # Each of the two new sims starts its clock at 0: its depth and its camera info each go
    # back once, and nothing else does.
    assert output.text.count("stamp went back") <= 4


@pytest.mark.parametrize("malloc", ["onebox", "glibc"])
def test_the_heap_is_bound_as_the_locator_starts_unless_glibc_is_asked_for(malloc):
    """memory.bound_heap (called by the locator and the recorder before Zenoh's threads start)
    sets malloc's thresholds and arenas on glibc, and leaves glibc's defaults with
    ONEBOX_MALLOC=glibc; a fresh process each time, as the setting lasts a process's life."""
    env = {**os.environ, "ONEBOX_MALLOC": malloc}
    done = subprocess.run(
        [sys.executable, "-c", "from onebox import memory; print(memory.bound_heap())"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    on_glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
    assert done.stdout.strip() == str(on_glibc and malloc == "onebox")
