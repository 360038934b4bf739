"""Record, snapshot, replay and info on MCAP: real routers, real subprocesses, real files."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh
from mcap.reader import make_reader

from onebox import bus
from onebox.errors import RecordingError
from onebox.keys import type_for_key
from onebox.recording import RecordingWriter, describe, iter_messages, read_capture
from onebox.testing.capture import load_capture
from onebox.testing.processes import Inbox, has_key
from onebox.testing.processes import run_onebox as run_cli
from schemas import (
    CameraInfo,
    Clock,
    Header,
    Image,
    Message,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    codec,
)

# --- messages the tests publish -----------------------------------------------------------------


def image(stamp_ns: int, fill: int, encoding: str = "rgb8", w: int = 16, h: int = 12) -> bytes:
    bpp = 3 if encoding == "rgb8" else 4
    data = bytes([fill % 256]) * (w * h * bpp)
    msg = Image(
        header=Header(stamp_ns=stamp_ns, frame_id="camera_optical_frame"),
        height=h,
        width=w,
        encoding=encoding,
        step=w * bpp,
        data=data,
    )
    return codec(Image).encode(msg)


def info(stamp_ns: int) -> bytes:
    k = [20.0, 0.0, 8.0, 0.0, 20.0, 6.0, 0.0, 0.0, 1.0]
    msg = CameraInfo(header=Header(stamp_ns=stamp_ns), width=16, height=12, k=k)
    return codec(CameraInfo).encode(msg)


def tf_static() -> bytes:
    t = TransformStamped(
        header=Header(frame_id="world"),
        child_frame_id="camera_link",
        transform=Transform(translation=Vector3(z=0.4)),
    )
    return codec(TFMessage).encode(TFMessage(transforms=[t]))


CAMERA = {
    "camera/image_raw": lambda s, i: image(s, i),
    "camera/depth/image_raw": lambda s, i: image(s, i, "32FC1"),
    "camera/camera_info": lambda s, i: info(s),
}


def wait_matching(b: bus.Bus, key: str, timeout_s: float = 15.0) -> None:
    """Block until some subscriber on ``key`` is known (the process under test is listening)."""
    assert b.publisher(key, Message).wait_for_subscribers(timeout_s), (
        f"no subscriber on {key} within {timeout_s} s"
    )


def wait_file(condition: Any, timeout_s: float = 15.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out waiting on the recording"
        time.sleep(0.05)


# --- a reader with only mcap and msgpack --------------------------------------------------------


def conforms(value: Any, schema: dict[str, Any], defs: dict[str, Any]) -> list[str]:
    """Problems of ``value`` against a msgspec JSON schema, msgpack-aware (bin = base64 string)."""
    if "$ref" in schema:
        return conforms(value, defs[schema["$ref"].split("/")[-1]], defs)
    if "anyOf" in schema:
        options = [conforms(value, s, defs) for s in schema["anyOf"]]
        return [] if any(not o for o in options) else options[0]
    if "enum" in schema:
        return [] if value in schema["enum"] else [f"{value!r} not in {schema['enum']}"]
    kind = schema.get("type")
    checks = {
        "object": lambda v: isinstance(v, dict),
        "array": lambda v: isinstance(v, list),
        "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
        "number": lambda v: isinstance(v, int | float) and not isinstance(v, bool),
        "boolean": lambda v: isinstance(v, bool),
        "null": lambda v: v is None,
        "string": lambda v: (
            isinstance(v, str)
            or (schema.get("contentEncoding") == "base64" and isinstance(v, bytes))
        ),
    }
    if kind is not None and not checks[kind](value):
        return [f"{value!r:.40} is not {kind}"]
    problems: list[str] = []
    if kind == "object":
        props = schema.get("properties", {})
        problems += [f"missing {r}" for r in schema.get("required", []) if r not in value]
        for name, sub in props.items():
            if name in value:
                problems += [f"{name}: {p}" for p in conforms(value[name], sub, defs)]
    if kind == "array" and "items" in schema:
        for item in value:
            problems += conforms(item, schema["items"], defs)
    return problems


def decode_with_mcap_only(path: Path) -> list[tuple[str, dict[str, Any]]]:
    """Every message decoded by plain msgpack and checked against the schema in the file."""
    decoded = []
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert channel.message_encoding == "msgpack"
            assert schema is not None and schema.encoding == "jsonschema", channel.topic
            js = json.loads(schema.data)
            value = msgspec.msgpack.decode(message.data)
            problems = conforms(value, js, js.get("$defs", {}))
            assert not problems, f"{channel.topic}: {problems}"
            decoded.append((channel.topic, value))
    return decoded


# --- record -------------------------------------------------------------------------------------


def test_record_is_byte_identical_in_order_and_self_describing(processes, test_bus, tmp_path):
    """What travelled is read back byte for byte, per key, in order, and decodes with mcap alone."""
    out = tmp_path / "run.mcap"
    tf_pub = test_bus.publisher("tf_static", TFMessage, latched=True)
    tf_pub.publish_bytes(tf_static())  # before the recorder starts: it must still get it
    rec = processes.start("record", str(out), "--flush-interval-s", "0.2")
    pubs = {
        k: test_bus.publisher(k, Image, congestion_control=zenoh.CongestionControl.BLOCK)
        for k in CAMERA
    }
    for key in CAMERA:
        wait_matching(test_bus, key)
    sent: dict[str, list[bytes]] = {k: [] for k in CAMERA}
    for i in range(20):
        for key, make in CAMERA.items():
            payload = make(1_000_000 * (i + 1), i)
            pubs[key].publish_bytes(payload)
            sent[key].append(payload)
    # tf_static comes from the publisher's cache, by a query of its own: it may land after the
    # pictures sent since.
    wait_file(
        lambda: (
            [r.key for r in _recovered(out)].count("camera/camera_info") == 20
            and any(r.key == "tf_static" for r in _recovered(out))
        )
    )
    output = processes.stop(rec)
    assert rec.returncode == 0, output

    got: dict[str, list[bytes]] = {}
    stamps: dict[str, list[int]] = {}
    for r in iter_messages(out):
        got.setdefault(r.key, []).append(r.payload)
        stamps.setdefault(r.key, []).append(r.publish_time_ns)
    assert got.pop("tf_static") == [tf_static()]
    assert got == sent
    assert stamps["camera/image_raw"] == [1_000_000 * (i + 1) for i in range(20)]
    log_times = [r.log_time_ns for r in iter_messages(out)]
    assert log_times == sorted(log_times)

    plain = decode_with_mcap_only(out)
    assert len(plain) == 61
    assert {v["_type"] for _, v in plain} == {"Image", "CameraInfo", "TFMessage"}


def test_record_a_running_sim(processes, test_bus, tmp_path):
    """Every key the sim publishes is recorded byte for byte, in order, stamped with its header."""
    out = tmp_path / "sim.mcap"
    seen = Inbox()
    test_bus.subscribe_raw("**", seen)
    rec = processes.start("record", str(out), "--flush-interval-s", "0.2")
    wait_matching(test_bus, "camera/image_raw")
    sim = processes.start("sim", "--frames", "5")
    seen.wait(has_key("sim/ground_truth", 5), timeout_s=60)
    assert sim.wait(timeout=30) == 0
    processes.stop(sim)
    wait_file(lambda: sum(r.key == "sim/ground_truth" for r in _recovered(out)) == 5)
    output = processes.stop(rec)
    assert rec.returncode == 0, output

    travelled: dict[str, list[bytes]] = {}
    for key, payload in seen.items:
        travelled.setdefault(key, []).append(payload)
    recorded: dict[str, list[bytes]] = {}
    for r in iter_messages(out):
        recorded.setdefault(r.key, []).append(r.payload)
        if r.key.startswith("camera/"):
            assert r.publish_time_ns == codec(type_for_key(r.key)).decode(r.payload).header.stamp_ns
    assert {"camera/image_raw", "camera/depth/image_raw", "basic_camera/image_raw", "clock",
            "tf_static"} <= set(recorded)  # fmt: skip
    for key, payloads in travelled.items():
        if key != "tf_static":  # the test subscribed without history; the recorder with it
            assert recorded[key] == payloads, key
    assert len(recorded["camera/image_raw"]) == 5
    decode_with_mcap_only(out)

    # Replayed, the recorded clock comes back as it was (nothing synthesised) with the keys asked.
    again = Inbox()
    test_bus.subscribe_raw("**", again)
    replay = processes.start("replay", str(out), "--rate", "0", "--keys", "camera/image_raw")
    # A capture's clock may come after its picture: wait for every one of both.
    clocks = has_key("clock", len(recorded["clock"]))
    again.wait(lambda items: has_key("camera/image_raw", 5)(items) and clocks(items))
    processes.stop(replay)
    replayed = [(k, p) for k, p in again.items]
    assert [p for k, p in replayed if k == "clock"] == recorded["clock"]
    assert [p for k, p in replayed if k == "camera/image_raw"] == recorded["camera/image_raw"]
    assert {k for k, _ in replayed} == {"clock", "camera/image_raw"}


def _recovered(path: Path) -> list[Any]:
    """What a reader can get out of a file still being written (empty until it exists)."""
    if not path.exists() or path.stat().st_size == 0:
        return []
    try:
        return list(iter_messages(path, recover=True))
    except RecordingError:
        return []


def test_sigkill_keeps_every_complete_chunk_and_sigterm_finishes(processes, test_bus, tmp_path):
    """SIGKILL leaves every complete chunk readable; SIGTERM leaves a file with its summary."""
    killed, stopped = tmp_path / "killed.mcap", tmp_path / "stopped.mcap"
    # One key each, so that waiting for a subscriber on a key waits for that recorder.
    keys = {killed: "camera/image_raw", stopped: "basic_camera/image_raw"}
    recorders = {
        path: processes.start("record", str(path), "--keys", key, "--flush-interval-s", "0.1")
        for path, key in keys.items()
    }
    pubs = {
        key: test_bus.publisher(key, Image, congestion_control=zenoh.CongestionControl.BLOCK)
        for key in keys.values()
    }
    for key in keys.values():
        wait_matching(test_bus, key)
    sent: list[bytes] = []

    def publish(n: int) -> None:
        for _ in range(n):
            payload = image(len(sent) + 1, len(sent))
            for pub in pubs.values():
                pub.publish_bytes(payload)
            sent.append(payload)

    publish(30)
    wait_file(lambda: len(_recovered(killed)) >= 30)  # these 30 are in complete chunks now
    publish(10)
    recorders[killed].send_signal(signal.SIGKILL)
    processes.stop(recorders[killed])

    with pytest.raises(RecordingError, match="truncated"):
        list(iter_messages(killed))
    recovered = [r.payload for r in iter_messages(killed, recover=True)]
    assert len(recovered) >= 30
    assert recovered == sent[: len(recovered)]

    wait_file(lambda: len(_recovered(stopped)) >= 40)
    output = processes.stop(recorders[stopped])
    assert recorders[stopped].returncode == 0, output
    summary = describe(stopped)
    assert summary.complete and summary.message_count == 40 and summary.chunk_count >= 1
    assert [r.payload for r in iter_messages(stopped)] == sent


def test_record_and_snapshot_refuse_to_overwrite(processes, tmp_path):
    """An existing file is left alone and the error names it on one line."""
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"keep me")
    for command in ("record", "snapshot"):
        proc = processes.start(command, str(existing))
        out, _ = proc.communicate(timeout=30)
        assert proc.returncode == 2, out
        assert str(existing) in out and "already exists" in out and "Traceback" not in out
        assert existing.read_bytes() == b"keep me"


def test_namespaced_keys_keep_their_prefix_and_their_schema(tmp_path):
    """A key recorded under a namespace keeps it in the file and still gets its type's schema."""
    path = tmp_path / "ns.mcap"
    with RecordingWriter(path, namespace="robot1") as w:
        w.add("robot1/camera/image_raw", image(7, 1), time.time_ns())
        w.add("robot1/tf_static", tf_static(), time.time_ns())
    keys = {k.key: k.schema_name for k in describe(path).keys}
    assert keys == {
        "robot1/camera/image_raw": "onebox.sensor.Image",
        "robot1/tf_static": "onebox.geometry.TFMessage",
    }
    capture = read_capture(path, namespace="robot1")
    assert sorted(capture) == ["camera/image_raw", "tf_static"]
    assert capture["camera/image_raw"].header.stamp_ns == 7


# --- snapshot -----------------------------------------------------------------------------------


def test_snapshot_records_one_matched_capture(processes, test_bus, tmp_path):
    """Snapshot writes colour, depth and info of one stamp plus tf_static, then exits."""
    out = tmp_path / "snap.mcap"
    test_bus.publisher("tf_static", TFMessage, latched=True).publish_bytes(tf_static())
    pubs = {k: test_bus.publisher(k, Image) for k in CAMERA}
    snap = processes.start("snapshot", str(out), "--timeout-s", "20")
    for key in CAMERA:
        wait_matching(test_bus, key)
    # A capture whose depth never comes first; the snapshot must not take it.
    pubs["camera/image_raw"].publish_bytes(image(5, 5))
    pubs["camera/camera_info"].publish_bytes(info(5))
    stamp = 10
    while snap.poll() is None and stamp < 400:
        for key, make in CAMERA.items():
            pubs[key].publish_bytes(make(stamp, stamp))
        stamp += 10
        time.sleep(0.05)  # a camera's own pace, 20 Hz; not waiting on anything
    out_text = processes.stop(snap)
    assert snap.returncode == 0, out_text
    capture = read_capture(out)
    assert sorted(capture) == ["camera/camera_info", "camera/depth/image_raw",
                               "camera/image_raw", "tf_static"]  # fmt: skip
    stamps = {k: m.header.stamp_ns for k, m in capture.items() if k != "tf_static"}
    assert len(set(stamps.values())) == 1 and stamps["camera/image_raw"] >= 10
    assert describe(out).message_count == 4


def test_snapshot_says_what_never_arrived(processes, tmp_path):
    """With nothing publishing, snapshot exits 2 naming the missing keys, and writes nothing."""
    out = tmp_path / "none.mcap"
    proc = processes.start("snapshot", str(out), "--timeout-s", "1")
    text, _ = proc.communicate(timeout=30)
    assert proc.returncode == 2, text
    assert "camera/depth/image_raw" in text and "tf_static" in text and "Traceback" not in text
    assert not out.exists()


# --- replay -------------------------------------------------------------------------------------


SPACING_S = 0.05
FIRST_LATE_S = 0.25
"""How much later than the rest the first message may arrive (its delivery, not the pacing)."""


@pytest.fixture
def spaced_recording(tmp_path) -> tuple[Path, list[tuple[str, bytes]]]:
    """tf_static, then 20 colour + info captures 50 ms apart, no clock channel."""
    path = tmp_path / "spaced.mcap"
    messages: list[tuple[str, bytes]] = [("tf_static", tf_static())]
    t0 = time.time_ns()
    with RecordingWriter(path) as w:
        w.add("tf_static", tf_static(), t0)
        for i in range(20):
            t = t0 + int((i + 1) * SPACING_S * 1e9)
            for key in ("camera/image_raw", "camera/camera_info"):
                payload = CAMERA[key](100_000_000 * (i + 1), i)
                w.add(key, payload, t)
                messages.append((key, payload))
    return path, messages


def test_replay_keeps_bytes_order_and_spacing(processes, test_bus, spaced_recording):
    """At rate 1 the recorded spacing returns; clock is synthesised from the stamps."""
    path, messages = spaced_recording
    arrivals: list[tuple[str, bytes, float]] = []
    inbox = Inbox()

    def on_sample(key: str, payload: bytes) -> None:
        arrivals.append((key, payload, time.monotonic()))
        inbox(key, payload)

    test_bus.subscribe_raw("**", on_sample)
    proc = processes.start("replay", str(path), "--rate", "1")
    infos, clocks = has_key("camera/camera_info", 20), has_key("clock", 20)
    inbox.wait(lambda items: infos(items) and clocks(items))
    out = processes.stop(proc)
    assert proc.returncode == 0, out
    data = [(k, p) for k, p, _ in arrivals if k != "clock"]
    assert data == messages
    clocks = [codec(Clock).decode(p).clock_ns for k, p, _ in arrivals if k == "clock"]
    assert clocks == [100_000_000 * (i + 1) for i in range(20)]
    # What replay promises, which a loaded machine cannot break: no message leaves before its
    # recorded offset (a late first arrival is the only slack), and the whole pass is not
    # much slower than recorded.
    times = [t for k, _, t in arrivals if k == "camera/image_raw"]
    offsets = [i * SPACING_S for i in range(len(times))]
    early = [(t - times[0]) - offset for t, offset in zip(times, offsets, strict=True)]
    assert min(early) > -FIRST_LATE_S, early
    assert times[-1] - times[0] < offsets[-1] + 5.0


def test_replay_rate_zero_is_faster_and_late_joiner_gets_tf_static(
    processes, test_bus, spaced_recording
):
    """At rate 0 the same bytes arrive in a burst; a late subscriber still gets tf_static."""
    path, messages = spaced_recording
    arrivals: list[tuple[str, bytes, float]] = []
    inbox = Inbox()

    def on_sample(key: str, payload: bytes) -> None:
        arrivals.append((key, payload, time.monotonic()))
        inbox(key, payload)

    test_bus.subscribe_raw("**", on_sample)
    proc = processes.start("replay", str(path), "--rate", "0")
    inbox.wait(has_key("camera/camera_info", 20))
    processes.stop(proc)
    assert [(k, p) for k, p, _ in arrivals if k != "clock"] == messages
    times = [t for k, _, t in arrivals if k != "clock"]
    assert times[-1] - times[0] < 0.5 * 20 * SPACING_S  # recorded: 1 s

    slow = processes.start("replay", str(path), "--rate", "0.5")
    first = Inbox()
    test_bus.subscribe_raw("camera/image_raw", first)
    first.wait(has_key("camera/image_raw", 1))
    late = Inbox()
    test_bus.subscribe_raw("tf_static", late, history=True)
    late.wait(has_key("tf_static", 1), timeout_s=10)
    assert late.items[0][1] == tf_static()
    assert slow.poll() is None  # tf_static came from the cache, not from a new pass
    processes.stop(slow)


@pytest.mark.parametrize("kind", ["missing", "empty", "truncated", "not-mcap"])
@pytest.mark.parametrize("command", ["info", "replay"])
def test_bad_input_gives_one_line_naming_the_file(command, kind, tmp_path, spaced_recording):
    """info and replay answer a bad file with exit 2 and one line that names it."""
    path = tmp_path / f"{kind}.mcap"
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "truncated":
        whole = spaced_recording[0].read_bytes()
        path.write_bytes(whole[: len(whole) * 2 // 3])
    elif kind == "not-mcap":
        path.write_text("just some text\n")
    # replay checks the file before it connects, so it needs no router to fail properly.
    extra = ["--connect", "tcp/127.0.0.1:9"] if command == "replay" else []
    result = run_cli(command, str(path), *extra)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "Traceback" not in result.stderr


# --- info ---------------------------------------------------------------------------------------


def test_info_lists_keys_counts_and_schemas(spaced_recording):
    """info prints the duration, the count and each key's type, count, encoding and schema."""
    path, _ = spaced_recording
    result = run_cli("info", str(path))
    assert result.returncode == 0, result.stderr
    text = result.stdout
    assert "Messages:          41" in text
    assert "Duration:          1.000000000 s" in text
    assert "Simulated time:    0.100 s to 2.000 s" in text  # not tf_static's unstamped 0
    assert (
        "Key: camera/image_raw | Type: onebox.sensor.Image | Count: 20 | Encoding: msgpack"
        " | Schema: onebox.sensor.Image (jsonschema)" in " ".join(text.split())
    )
    assert "Key: tf_static" in text and "Count: 1 " in text


def test_recover_reads_a_cut_file_and_info_says_so(spaced_recording, tmp_path):
    """A cut file is truncated to a strict reader and readable with recover."""
    path, messages = spaced_recording
    cut = tmp_path / "cut.mcap"
    whole = path.read_bytes()
    cut.write_bytes(whole[: len(whole) - 200])
    with pytest.raises(RecordingError, match=str(cut)):
        iter_messages(cut)
    assert [(r.key, r.payload) for r in iter_messages(cut, recover=True)] == messages
    result = run_cli("info", str(cut), "--recover")
    assert result.returncode == 0, result.stderr
    assert "truncated" in result.stdout and "Messages:          41" in result.stdout


# --- the committed capture ----------------------------------------------------------------------


def test_committed_capture_loads_as_typed_messages():
    """tests/data/one_box.mcap holds one capture: colour, depth and info of one stamp, tf_static."""
    capture = load_capture()
    assert sorted(capture) == ["camera/camera_info", "camera/depth/image_raw",
                               "camera/image_raw", "tf_static"]  # fmt: skip
    colour, depth = capture["camera/image_raw"], capture["camera/depth/image_raw"]
    assert isinstance(colour, Image) and isinstance(depth, Image)
    assert colour.header.stamp_ns == depth.header.stamp_ns
    assert capture["camera/camera_info"].header.stamp_ns == colour.header.stamp_ns
    assert (colour.encoding, depth.encoding) == ("rgb8", "32FC1")
    assert len(colour.data) == colour.step * colour.height
    assert isinstance(capture["tf_static"], TFMessage) and capture["tf_static"].transforms


# --- stamps MCAP cannot hold, a full disk --------------------------------------------------------


def test_negative_and_huge_stamps_are_recorded_and_said_once(processes, test_bus, tmp_path):
    """Clock(-1), a header stamp below 0 and one of 2^64 - 1: every message is recorded, the
    writer keeps going, and the log says once per key what it changed."""
    out = tmp_path / "stamps.mcap"
    rec = processes.start("record", str(out), "--flush-interval-s", "0.2")
    clock = test_bus.publisher("clock", Clock, congestion_control=zenoh.CongestionControl.BLOCK)
    colour = test_bus.publisher(
        "camera/image_raw", Image, congestion_control=zenoh.CongestionControl.BLOCK
    )
    wait_matching(test_bus, "clock")
    wait_matching(test_bus, "camera/image_raw")
    sent = [
        ("clock", clock.publish(Clock(clock_ns=-1))),
        ("clock", clock.publish(Clock(clock_ns=-(2**63)))),
        ("clock", clock.publish(Clock(clock_ns=-7))),
    ]
    for stamp in (-5, 2**64 - 1):
        colour.publish_bytes(image(stamp, 1))
        sent.append(("camera/image_raw", image(stamp, 1)))
    for i in range(5):
        sent.append(("clock", clock.publish(Clock(clock_ns=i))))
        payload = image(i, i)
        colour.publish_bytes(payload)
        sent.append(("camera/image_raw", payload))
    wait_file(lambda: len(_recovered(out)) == len(sent))
    output = processes.stop(rec)
    assert rec.returncode == 0, output
    recorded = list(iter_messages(out))
    assert sorted((r.key, r.payload) for r in recorded) == sorted(sent)
    assert [r.publish_time_ns for r in recorded if r.key == "clock"][:2] == [0, 0]
    assert output.count("clock: a publish time of") == 1, output  # once, for three
    assert "camera/image_raw: a publish time of -5 ns" in output
    assert "Traceback" not in output


@pytest.fixture
def small_disk(tmp_path) -> Any:
    """A 3 MB tmpfs, so a recording fills it; skipped where it cannot be mounted."""
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(disk)],
        capture_output=True,
        text=True,
        check=False,
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill ({mounted.stderr.strip()}): needs root")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)


def test_a_full_disk_gives_one_line_exit_2_and_a_file_that_reads_back(
    processes, test_bus, small_disk
):
    """The disk fills: one line naming the file, exit 2 at once, and the file reads back
    without --recover, holding what fitted."""
    out = small_disk / "full.mcap"
    rec = processes.start(
        "record", str(out), "--compression", "none", "--chunk-size-mb", "0.25",
        "--flush-interval-s", "0.1",
    )  # fmt: skip
    colour = test_bus.publisher(
        "camera/image_raw", Image, congestion_control=zenoh.CongestionControl.BLOCK
    )
    wait_matching(test_bus, "camera/image_raw")
    sent = 0
    deadline = time.monotonic() + 60
    while rec.poll() is None and time.monotonic() < deadline:
        sent += 1
        colour.publish_bytes(image(sent, sent, w=160, h=120))  # 57 kB each
    output = processes.stop(rec)
    assert rec.returncode == 2, output
    assert "Traceback" not in output
    [line] = [line for line in output.splitlines() if line.startswith("onebox record:")]
    assert f"cannot write {out}" in line and "No space left" in line, line
    assert "reads back as it is" in line, line
    recorded = list(iter_messages(out))
    assert 10 < len(recorded) < sent
