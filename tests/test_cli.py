"""The ROS CLI habits: echo, hz, bw, pub, --version, did you mean, no flag abbreviations."""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import sys

import msgspec
import pytest

from onebox import topic_stats
from onebox.recording import RecordingWriter, describe
from onebox.testing.fake_capture import capture, tf_static, write_mcap
from onebox.testing.processes import CAPTURE, ROOT
from onebox.testing.processes import run_onebox as onebox
from schemas import Detection3DArray, Header, TFMessage, codec


@pytest.fixture
def replaying(processes, tmp_path):
    """A fake capture replayed again and again (5 Hz) on the test's router."""
    recording = write_mcap(tmp_path / "fake.mcap", captures=3)
    processes.start("replay", str(recording), "--loop")
    return processes.endpoint


def test_echo_prints_each_key_readably_with_large_arrays_summarised(replaying):
    """echo --once prints one message as field lines ending in ---, pictures as their length."""
    detections = onebox("echo", "detections", "--once", "--connect", replaying)
    assert detections.returncode == 0, detections.stderr
    assert "class_id: box" in detections.stdout and "score: 1.0" in detections.stdout
    assert "frame_id: world" in detections.stdout
    assert detections.stdout.rstrip().endswith("---") and detections.stdout.count("---") == 1
    image = onebox("echo", "camera/image_raw", "--once", "--connect", replaying)
    assert image.returncode == 0, image.stderr
    assert "data: <230,400 bytes>" in image.stdout and "encoding: rgb8" in image.stdout
    assert len(image.stdout) < 1000
    # tf_static was published before this echo started: it still arrives, latched.
    tf = onebox("echo", "tf_static", "--once", "--timeout-s", "10", "--connect", replaying)
    assert tf.returncode == 0, tf.stderr
    assert "child_frame_id: camera_optical_frame" in tf.stdout


def test_echo_json_is_one_object_a_line_with_key_and_type(replaying):
    """--json on a key expression prints a JSON line naming the key, its type and the fields."""
    done = onebox("echo", "camera/**", "--json", "--once", "--connect", replaying)
    assert done.returncode == 0, done.stderr
    (line,) = done.stdout.splitlines()
    found = json.loads(line)
    assert found["key"].startswith("camera/")
    assert found["type"].startswith("onebox.") and "header" in found["message"]


def test_echo_under_a_namespace_and_a_key_of_no_known_type(processes, test_bus, tmp_path):
    """--namespace finds robot1/detections' type; an unknown key is dumped from its msgpack."""
    recording = write_mcap(tmp_path / "fake.mcap", captures=2)
    processes.start("replay", str(recording), "--loop", "--namespace", "robot1")
    done = onebox(
        "echo", "detections", "--namespace", "robot1", "--once", "--connect", processes.endpoint
    )
    assert done.returncode == 0, done.stderr
    assert "class_id: box" in done.stdout
    # An expression over the namespace, without --namespace: the type is found all the same.
    done = onebox("echo", "robot1/*", "--once", "--connect", processes.endpoint)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("# robot1/") and "(onebox." in done.stdout.splitlines()[0]

    echo = processes.start("echo", "other/thing", "--once", "--timeout-s", "20")
    raw = test_bus.session.declare_publisher("other/thing")
    payload = msgspec.msgpack.encode({"speed": 2.5, "blob": b"\x00" * 100})
    while echo.poll() is None:
        raw.put(payload)
        try:
            echo.wait(timeout=0.2)
        except subprocess.TimeoutExpired:  # not subscribed yet: put it again
            continue
    out = processes.stop(echo)
    assert echo.returncode == 0, out
    assert "# other/thing: not a onebox key, raw msgpack" in out
    assert "speed: 2.5" in out and "blob: <100 bytes>" in out


def test_echo_with_nothing_published_gives_up_after_its_timeout(router):
    """--timeout-s with nothing on the key: one line naming the key, exit 2."""
    done = onebox("echo", "detections", "--timeout-s", "0.5", "--connect", router)
    assert done.returncode == 2
    assert "nothing arrived on detections within 0.5 s" in done.stderr
    assert "Traceback" not in done.stderr


def test_hz_and_bw_measure_a_replay(replaying):
    """hz reports about 5 Hz with min/max/std dev/window; bw the picture's size per second."""
    hz = subprocess.Popen(
        [sys.executable, "-m", "services.cli", "hz", "camera/image_raw", "--duration-s", "3",
         "--connect", replaying],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    bw = onebox("bw", "camera/depth/image_raw", "--duration-s", "3", "--connect", replaying)
    hz_out, hz_err = hz.communicate(timeout=60)
    assert hz.returncode == 0, hz_err
    last = hz_out.strip().splitlines()[-2:]
    assert last[0].startswith("average rate: "), hz_out
    assert 3.0 < float(last[0].split(": ")[1]) < 7.0
    assert last[1].startswith("\tmin: ") and " std dev: " in last[1] and " window: " in last[1]
    assert bw.returncode == 0, bw.stderr
    last = bw.stdout.strip().splitlines()[-2:]
    assert " MB/s from " in last[0], bw.stdout
    # 320 x 240 float32 depth: 307,200 bytes of pixels plus a few hundred of header.
    assert last[1].startswith("\tMessage size mean: 307.")
    assert " std dev: 0.00 KB" in last[1]


def test_rate_and_bandwidth_figures():
    """Known arrival times give the known mean rate, extremes, spread and bytes a second."""
    items = [(0.0, 100), (0.2, 100), (0.4, 300), (0.7, 100)]
    rate = topic_stats.rate(items)
    assert rate is not None
    assert rate.average_hz == pytest.approx(3 / 0.7)
    assert (rate.min_s, rate.max_s, rate.window) == (pytest.approx(0.2), pytest.approx(0.3), 4)
    assert rate.std_s == pytest.approx(0.04714, abs=1e-5)
    assert topic_stats.rate_text(rate) == (
        "average rate: 4.286\n\tmin: 0.200s max: 0.300s std dev: 0.04714s window: 4"
    )
    assert topic_stats.rate(items[:1]) is None
    bw = topic_stats.bandwidth(items, now_s=1.2)
    assert bw is not None
    assert bw.bytes_per_s == pytest.approx(500.0)
    assert (bw.min_bytes, bw.max_bytes, bw.mean_bytes) == (100, 300, 150.0)
    assert topic_stats.bandwidth_text(bw).startswith("500.00 B/s from 4 messages\n")


def test_pub_publishes_a_typed_message_a_subscriber_receives(processes, test_bus, inbox):
    """pub waits for the subscriber, publishes once, and the message decodes as sent."""
    test_bus.subscribe_raw("detections", inbox)
    body = '{"detections": [{"results": [{"class_id": "box", "score": 0.9}], "id": "b1"}]}'
    done = onebox(
        "pub", "detections", "onebox.vision.Detection3DArray", body, "--connect", processes.endpoint
    )
    assert done.returncode == 0, done.stderr
    ((key, payload),) = inbox.wait(lambda items: len(items) >= 1, timeout_s=10)
    message = codec(Detection3DArray).decode(payload)
    assert key == "detections"
    assert message.detections[0].results[0].class_id == "box"
    assert message.detections[0].id == "b1"


def test_pub_at_a_rate_publishes_the_times_asked(processes, test_bus, inbox):
    """--rate 20 --times 3 publishes three messages."""
    test_bus.subscribe_raw("detections", inbox)
    done = onebox("pub", "detections", "Detection3DArray", "{}", "--rate", "20", "--times", "3",
                  "--connect", processes.endpoint)  # fmt: skip
    assert done.returncode == 0, done.stderr
    inbox.wait(lambda items: len(items) >= 3, timeout_s=10)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["detections", "Detection3DArray", '{"detectionz": []}'], "did you mean 'detections'?"),
        (["detections", "Detection3DArray", '{"detections": 3}'], "got `int` - at `$.detections`"),
        (["detections", "Detection3DArray", "{detections"], "the JSON does not parse"),
        (["detections", "Image", "{}"], "detections carries onebox.vision.Detection3DArray"),
        (["detections", "Detection3DArry", "{}"], "did you mean Detection3DArray?"),
        (["camera/*", "Image", "{}"], "without wildcards"),
        (["detections", "Detection3DArray", "{}", "--rat", "5"], "unrecognized arguments: --rat 5"),
    ],
)  # fmt: skip
def test_pub_refuses_what_does_not_fit_in_one_line(args, says, router):
    """JSON not fitting the type, a wrong type or key, an abbreviated flag: exit 2, one line."""
    done = onebox("pub", *args, "--connect", router)
    assert done.returncode == 2
    assert says in done.stderr
    assert "Traceback" not in done.stderr


def test_no_flag_abbreviations():
    """--rat is not taken as --rate: argparse's prefix matching is off on every parser."""
    done = onebox("replay", "tests/data/one_box.mcap", "--rat", "0")
    assert done.returncode == 2
    assert "unrecognized arguments: --rat 0" in done.stderr
    done = onebox("--vers")
    assert done.returncode == 2 and "unknown command '--vers'" in done.stderr


@pytest.mark.parametrize(
    ("flag", "says"),
    [
        (["--max-pixels", "-1"], "max_pixels -1: must be 0 (every pixel) or more"),
        (["--colour-shift", "1"], "colour_shift '1': expected auto or two whole numbers DY,DX"),
        (["--colour-shift=-1,x"], "colour_shift '-1,x': expected auto or two whole numbers DY,DX"),
        (["--colour-shift", "20,0"], "colour_shift '20,0': more than 12 pixels off"),
    ],
)
def test_locator_refuses_a_setting_it_cannot_use_in_one_line(flag, says):
    """--max-pixels -1, a colour shift that is not two whole numbers or is far off: one line
    naming the setting, exit 2."""
    done = onebox("locator", *flag)
    assert done.returncode == 2
    assert done.stderr == f"onebox locator: {says}\n"


@pytest.mark.parametrize("command", ["locator", "points"])
def test_slop_is_a_setting_that_honcho_passes_on(command):
    """ONEBOX_SLOP_MS reaches the locator and points as --slop-ms does (a real camera's stamps
    under `honcho start`): a negative one is refused in one line naming the setting."""
    done = onebox(command, env={"ONEBOX_SLOP_MS": "-5"})
    assert done.returncode == 2
    assert done.stderr == f"onebox {command}: slop_ms -5.0: must be 0 or more (milliseconds)\n"


def test_a_mistyped_command_suggests_the_right_one():
    """`onebox ehco` says: did you mean `onebox echo`?"""
    done = onebox("ehco", "detections")
    assert done.returncode == 2
    assert "unknown command 'ehco': did you mean `onebox echo`?" in done.stderr


def test_version_and_help():
    """--version prints the installed version; --help lists the topic commands."""
    done = onebox("--version")
    assert done.returncode == 0
    assert done.stdout == f"onebox {importlib.metadata.version('onebox')}\n"
    listed = onebox("--help").stdout
    for command in ("echo", "hz", "bw", "pub"):
        assert f"\n  {command} " in listed


def test_info_leaves_latched_and_unstamped_messages_out_of_the_simulated_time(tmp_path):
    """tf_static (latched, stamped 0 or long ago) does not stretch the simulated-time range."""
    done = onebox("info", str(CAPTURE))
    assert done.returncode == 0, done.stderr
    assert "Simulated time:    1.800 s to 1.800 s (header stamps)" in done.stdout
    path = tmp_path / "late.mcap"
    old_tf = msgspec.structs.replace(
        tf_static(),
        transforms=[
            msgspec.structs.replace(t, header=Header(stamp_ns=5_000_000_000, frame_id="world"))
            for t in tf_static().transforms
        ],
    )
    with RecordingWriter(path) as writer:
        writer.add("tf_static", codec(TFMessage).encode(old_tf), log_time_ns=1)
        writer.add("robot1/tf_static", codec(TFMessage).encode(tf_static()), log_time_ns=2)
        for i, stamp_ns in enumerate((198_000_000_000, 209_600_000_000)):
            for key, message in capture(stamp_ns).items():
                writer.add(key, codec(type(message)).encode(message), log_time_ns=3 + i)
        assert (writer.sim_start_ns, writer.sim_end_ns) == (198_000_000_000, 209_600_000_000)
    info = describe(path)
    assert (info.sim_start_ns, info.sim_end_ns) == (198_000_000_000, 209_600_000_000)
    only_tf = tmp_path / "tf.mcap"
    with RecordingWriter(only_tf) as writer:
        writer.add("tf_static", codec(TFMessage).encode(tf_static()), log_time_ns=1)
    assert "Simulated time" not in onebox("info", str(only_tf)).stdout
