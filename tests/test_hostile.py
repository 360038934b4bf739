"""Hostile input against every subscriber, as real processes: garbage, wrong types, cut msgpack,
huge declared sizes, NaN and infinity, impossible sizes and steps, stamps below 0 and past 2^63,
empty and 10,000-frame tf chains, zero quaternions. After all of it each process is alive and
answers a valid capture correctly. (The viewer has its own suite in test_viewer.py.)"""

from __future__ import annotations

import random
import time
from collections.abc import Iterator
from typing import Any

import msgspec
import numpy as np
import pytest

from onebox import bus
from onebox.recording import iter_messages
from onebox.testing import fake_capture
from onebox.testing.processes import Inbox, wait_for_output
from onebox.testing.synthetic import Scene, camera_info, depth_image, depth_picture, tf_static
from schemas import (
    Header,
    Image,
    Message,
    PointCloud,
    TFMessage,
    Transform,
    TransformStamped,
    codec,
)
from tests.test_locator import Output, assert_default_box, decode_detections

DEPTH, COLOUR, INFO, TF, POSE = (
    "camera/depth/image_raw",
    "camera/image_raw",
    "camera/camera_info",
    "tf_static",
    "camera/pose",
)
HUGE = [2**31, 2**32 + 1, 2**62, 2**64 - 1]
STAMPS = [-1, -(2**63), 2**63, 2**64 - 1]


def builtins(message: Message) -> dict[str, Any]:
    """A message as plain msgpack values (its tag included), so a test can break any field."""
    value: dict[str, Any] = msgspec.to_builtins(message, builtin_types=(bytes,))
    return value


def encode(value: Any) -> bytes:
    return msgspec.msgpack.encode(value)


def changed(message: Message, **fields: Any) -> bytes:
    value = builtins(message)
    for name, v in fields.items():
        if name == "stamp_ns":
            value["header"]["stamp_ns"] = v
        else:
            value[name] = v
    return encode(value)


def garbage(good: bytes) -> Iterator[tuple[str, bytes]]:
    """Bytes that are not the key's type, whatever the key."""
    rng = random.Random(8)
    yield "empty", b""
    yield "one zero", b"\x00"
    yield "random", bytes(rng.randrange(256) for _ in range(1000))
    yield "cut in half", good[: len(good) // 2]
    yield "cut by one", good[:-1]
    yield "bin32 of 4 GiB", b"\xc6\xff\xff\xff\xff" + b"x" * 10
    yield "array32 of 4 G items", b"\xdd\xff\xff\xff\xff"
    yield "map32 of 4 G pairs", b"\xdf\xff\xff\xff\xff"
    yield "nested 100,000 deep", b"\x91" * 100_000 + b"\x00"
    yield "an int", encode(7)
    yield "a string", encode("camera")
    yield "a list", encode([1, 2, 3])
    yield "another type's tag", encode({"_type": "Clock", "clock_ns": 5})
    yield "unknown tag", encode({"_type": "Nope"})
    yield "string fields as ints", encode({"_type": "Image", "header": 5, "width": "wide"})


def bad_images(good: Image) -> Iterator[tuple[str, bytes]]:
    yield from garbage(codec(Image).encode(good))
    n = good.width * good.height
    for name in ("width", "height", "step"):
        for v in [0, -1, -(2**63), *HUGE]:
            yield f"{name} {v}", changed(good, **{name: v})
    yield "no data", changed(good, data=b"")
    yield "data one byte short", changed(good, data=good.data[:-1])
    yield "data as text", changed(good, data="x" * 10)
    yield "unknown encoding", changed(good, encoding="32FC9")
    yield "encoding 1 MB long", changed(good, encoding="x" * 1_000_000)
    for stamp in STAMPS:
        yield f"stamp {stamp}", changed(good, stamp_ns=stamp)
    if good.encoding == "32FC1":
        for v in (np.nan, np.inf, -np.inf, -1.0, 0.0, 1e38):
            yield f"all {v}", changed(good, data=np.full(n, v, "<f4").tobytes())
        mixed = np.frombuffer(good.data, "<f4").copy()
        mixed[::3] = np.inf
        mixed[1::3] = np.nan
        yield "a third inf, a third NaN", changed(good, data=mixed.tobytes())


def bad_infos(good: Message) -> Iterator[tuple[str, bytes]]:
    yield from garbage(codec(type(good)).encode(good))
    k = list(good.k)  # type: ignore[attr-defined]
    for v in (float("nan"), float("inf"), -float("inf"), 0.0, -1.0, 1e308):
        yield f"k all {v}", changed(good, k=[v] * 9)
        yield f"fx {v}", changed(good, k=[v, *k[1:]])
    yield "k of 3", changed(good, k=k[:3])
    yield "k of 100,000", changed(good, k=[1.0] * 100_000)
    for name in ("width", "height"):
        for v in [0, -1, *HUGE]:
            yield f"{name} {v}", changed(good, **{name: v})
    for stamp in STAMPS:
        yield f"stamp {stamp}", changed(good, stamp_ns=stamp)


def link(parent: str, child: str, **numbers: float) -> dict[str, Any]:
    t = TransformStamped(
        header=Header(frame_id=parent), child_frame_id=child, transform=Transform()
    )
    value = builtins(t)
    for name, v in numbers.items():
        part = "translation" if name in "xyz" else "rotation"
        value["transform"][part][name.removeprefix("q")] = v
    return value


def bad_tf() -> Iterator[tuple[str, bytes]]:
    good = tf_static()
    yield from garbage(codec(TFMessage).encode(good))

    def tf(*links: dict[str, Any]) -> bytes:
        return encode({"_type": "TFMessage", "transforms": list(links)})

    yield "no transforms", tf()
    yield (
        "10,000-frame chain",
        tf(link("world", "f0"), *(link(f"f{i}", f"f{i + 1}", z=0.001) for i in range(9_999))),
    )
    yield (
        "10,000-frame loop",
        tf(*(link(f"g{i}", f"g{(i + 1) % 10_000}", z=0.001) for i in range(10_000))),
    )
    yield "zero quaternion", tf(link("world", "camera_link", qw=0.0))
    for v in (float("nan"), float("inf"), 1e308):
        yield f"translation {v}", tf(link("world", "camera_link", x=v))
        yield f"quaternion {v}", tf(link("world", "camera_link", qx=v))
    yield "world under the camera", tf(link("camera_optical_frame", "world"))
    yield "a frame its own parent", tf(link("a", "a"))
    yield "no names", tf(link("", ""))
    yield "names 100 kB long", tf(link("p" * 100_000, "c" * 100_000))
    for stamp in STAMPS:
        value = link("world", "elsewhere")
        value["header"]["stamp_ns"] = stamp
        yield f"stamp {stamp}", tf(value)


def bad_samples(keys: list[str]) -> list[tuple[str, str, bytes]]:
    """(key, what, payload) for every key a subscriber reads."""
    scene = Scene()
    depth = depth_image(depth_picture(scene), 1)
    colour = fake_capture.capture(1)[COLOUR]
    info = camera_info(scene, 1)
    makers = {
        DEPTH: lambda: bad_images(depth),
        COLOUR: lambda: bad_images(colour),  # type: ignore[arg-type]
        INFO: lambda: bad_infos(info),
        TF: bad_tf,
        POSE: lambda: garbage(b"\x80"),
    }
    return [(key, what, payload) for key in keys for what, payload in makers[key]()]


def publish_all(b: bus.Bus, samples: list[tuple[str, str, bytes]]) -> None:
    raw = {key: b.publisher(key, Message) for key in {k for k, _, _ in samples}}
    for key, _, payload in samples:
        raw[key].publish_bytes(payload)


def test_the_suite_covers_each_kind():
    """Every kind the issue names is in the set, for each key."""
    whats = {what for _, what, _ in bad_samples([DEPTH, INFO, TF])}
    kinds = ["random", "cut in half", "bin32 of 4 GiB", "all nan", "width -1", "step 0",
             f"stamp {2**63}", "stamp -1", "width 2147483648", "no transforms",
             "10,000-frame chain", "zero quaternion", "k all inf",
             "another type's tag"]  # fmt: skip
    for kind in kinds:
        assert kind in whats, kind
    assert len(bad_samples([DEPTH, COLOUR, INFO, TF])) > 150


# --- each subscriber -----------------------------------------------------------------------------


@pytest.fixture
def started(processes):
    outputs: list[Output] = []

    def start(*args: str) -> Output:
        output = Output(processes.start(*args))
        outputs.append(output)
        return output

    yield start
    for output in outputs:
        output.stop()


def test_locator_survives_everything_and_measures_the_next_capture(started, test_bus):
    """The locator logs and drops every bad sample, then measures a valid capture right."""
    inbox = Inbox()
    test_bus.subscribe_raw("detections", inbox)
    locator = started("locator", "--log-interval-s", "0.5")
    locator.wait_for(r"finding (the|every) box")
    publish_all(test_bus, bad_samples([DEPTH, INFO, TF, POSE]))
    for line in ("camera/depth/image_raw: not a onebox.sensor.Image", "tf_static: refused a"):
        locator.wait_for(line)  # the samples arrived, and were reported with their key
    scene = Scene()
    picture = depth_picture(scene)
    tf = test_bus.publisher(TF, TFMessage, latched=True)
    depth = test_bus.publisher(DEPTH, Image)
    info = test_bus.publisher(INFO, type(camera_info(scene, 0)))
    tf.publish(tf_static())
    deadline = time.monotonic() + 30
    stamp = 0
    measured = None
    while measured is None and time.monotonic() < deadline:
        stamp += 200_000_000
        info.publish(camera_info(scene, stamp))
        depth.publish(depth_image(picture, stamp))
        try:
            items = inbox.wait(
                lambda items, s=stamp: any(
                    d.header.stamp_ns == s for d in decode_detections(items)
                ),
                timeout_s=0.5,
            )
        except AssertionError:
            continue
        measured = next(d for d in decode_detections(items) if d.header.stamp_ns == stamp)
    assert measured is not None, locator.text[-3000:]
    assert_default_box(measured)
    assert locator.proc.poll() is None
    assert "Traceback" not in locator.stop()


def test_points_survives_everything_and_makes_the_next_cloud(started, test_bus):
    """points logs and drops every bad sample, then turns a valid capture into its cloud."""
    inbox = Inbox()
    test_bus.subscribe_raw("camera/points", inbox)
    points = started("points", "--log-interval-s", "0.5")
    points.wait_for("clouds from")
    publish_all(test_bus, bad_samples([DEPTH, COLOUR, INFO]))
    points.wait_for("camera/image_raw: not a onebox.sensor.Image")
    pubs = {key: test_bus.publisher(key, Message) for key in (DEPTH, COLOUR, INFO)}
    deadline = time.monotonic() + 30
    stamp = 10**9
    cloud = None
    while cloud is None and time.monotonic() < deadline:
        stamp += 200_000_000
        capture = fake_capture.capture(stamp)
        for key in (COLOUR, INFO, DEPTH):
            pubs[key].publish_bytes(codec(type(capture[key])).encode(capture[key]))
        try:
            items = inbox.wait(lambda items: bool(items), timeout_s=0.5)
        except AssertionError:
            continue
        clouds = [codec(PointCloud).decode(p) for _, p in items]
        cloud = next((c for c in clouds if c.header.stamp_ns == stamp), None)
    assert cloud is not None, points.text[-3000:]
    _, depth = fake_capture.pictures(320, 240)
    assert cloud.width == int(np.isfinite(depth).sum())
    assert points.proc.poll() is None
    assert "Traceback" not in points.stop()


def test_record_keeps_every_sample_and_writes_a_file_that_reads_back(started, test_bus, tmp_path):
    """record writes every hostile sample's bytes as they came (it never decodes pictures),
    keeps going, and the file reads back strictly, valid capture included."""
    out = tmp_path / "hostile.mcap"
    record = started("record", str(out), "--flush-interval-s", "0.2")
    record.wait_for("recording")
    samples = bad_samples([DEPTH, INFO, TF])
    samples = [s for s in samples if len(s[2]) < 2_000_000]  # the budget is for pictures
    assert test_bus.publisher(DEPTH, Message).wait_for_subscribers(10)
    publish_all(test_bus, samples)
    capture = fake_capture.capture(5)
    valid = {key: codec(type(m)).encode(m) for key, m in capture.items()}
    publish_all(test_bus, [(key, "valid", payload) for key, payload in valid.items()])
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        got = {(r.key, r.payload) for r in iter_messages(out, recover=True)}
        if all((key, payload) in got for key, payload in valid.items()):
            break
        time.sleep(0.1)  # polling the file the recorder writes; it has no other signal
    text = record.stop()
    assert record.proc.returncode == 0, text[-3000:]
    assert "Traceback" not in text
    recorded = [(r.key, r.payload) for r in iter_messages(out)]
    assert all((key, payload) in recorded for key, payload in valid.items())
    assert "dropped" not in text, "a recorder drops only when the disk is behind"
    assert f" {len(recorded)} messages," in text, "the file holds what the recorder says it wrote"
    # Depth pictures from a blocking publisher and tf_static are reliable end to end: every one
    # must be in the file. The router drops camera info rather than wait on a full queue
    # (config/router.json5), so the burst after 2 MB pictures may lose some of it on the way.
    missing = [(key, what) for key, what, payload in samples if (key, payload) not in recorded]
    assert not [m for m in missing if m[0] != INFO], missing


def test_check_survives_everything_and_reports_the_valid_capture(processes, test_bus):
    """check, fed every kind of bad sample and then the valid capture, lists every key with its
    type, the lens and the detection, exits 0, no traceback."""
    proc = processes.start("check", "--window-s", "3")
    samples = bad_samples([DEPTH, INFO, TF])
    capture = fake_capture.capture(5)
    valid = [(key, "valid", codec(type(m)).encode(m)) for key, m in capture.items()]
    seen = wait_for_output(proc, "listening on", timeout_s=30)
    publish_all(test_bus, samples[:60])
    publish_all(test_bus, valid)
    publish_all(test_bus, samples[60:])
    # Then the valid capture until check's window closes, so the last of each key is valid.
    deadline = time.monotonic() + 30
    while proc.poll() is None and time.monotonic() < deadline:
        publish_all(test_bus, valid)
        time.sleep(0.05)  # a camera's pace, not a synchronisation
    text = seen + processes.stop(proc)
    assert proc.returncode == 0, text[-3000:]
    assert "Traceback" not in text
    listed = {line.split()[0]: line for line in text.splitlines() if line.startswith("  ")}
    for key in ("camera/points", "detections", "camera/pose", "camera/camera_info"):
        assert type(capture[key]).__qualname__ in listed[key], listed.get(key)
    assert "camera/camera_info: " in text and "class_id: box" in text  # its lens; one detection
