"""onebox check: what is live, with types and rates, the lens, and one of each message."""

from __future__ import annotations

import subprocess

from onebox.describe import describe as describe_message
from onebox.keys import TYPES
from onebox.recording import describe
from onebox.testing.fake_capture import write_mcap
from onebox.testing.processes import CAPTURE, free_port, run_onebox
from schemas import CameraInfo, Header, Image
from services import check


def run_check(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return run_onebox("check", "--connect", endpoint, *args)


def test_check_with_nothing_running_says_how_to_start_and_fails():
    """No router at all: a one-line message naming the endpoint and `honcho start`, exit 2."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    done = run_check(endpoint)
    assert done.returncode == 2
    assert f"nothing is running: no router at {endpoint}" in done.stderr
    assert "honcho start" in done.stderr and "Traceback" not in done.stderr
    assert done.stdout == ""


def test_check_with_a_quiet_router_says_nothing_is_published(router):
    """A router but no publishers: it says so, how to start, and exits 2."""
    done = run_check(router, "--window-s", "0.5")
    assert done.returncode == 2
    assert "is up, but nothing was published in 0.5 s" in done.stderr
    assert "honcho start" in done.stderr


def test_check_lists_a_replay_with_types_rates_lens_and_one_of_each(processes, tmp_path):
    """Beside a replay it lists every key with its type, the four lens numbers, brief messages."""
    recording = write_mcap(tmp_path / "fake.mcap", captures=3)
    processes.start("replay", str(recording), "--loop")
    done = run_check(processes.endpoint, "--window-s", "2")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    for key in ("camera/image_raw", "camera/depth/image_raw", "camera/points", "detections"):
        assert f"  {key} " in out
    lines = {line.split()[0]: line for line in out.splitlines() if line.startswith("  ")}
    for key in ("camera/image_raw", "camera/camera_info", "camera/pose", "detections"):
        assert TYPES[key].__qualname__ in lines[key], lines[key]
        assert "Hz" in lines[key]
    assert "latched" in lines["tf_static"]
    assert "camera/camera_info: 320 x 240, fx 277.128  fy 277.128  cx 159.500  cy 119.500" in out
    assert "data: <230,400 bytes>" in out and "data: <307,200 bytes>" in out
    assert "class_id: box" in out and "one detection" in out
    assert len(out) < 20_000, "the large arrays must be left out"


def test_check_lists_every_key_of_the_committed_capture(processes):
    """Replaying tests/data/one_box.mcap, check lists each of its keys with its type."""
    keys = {k.key: k.schema_name for k in describe(CAPTURE).keys}
    processes.start("replay", str(CAPTURE), "--loop")
    done = run_check(processes.endpoint, "--window-s", "2")
    assert done.returncode == 0, done.stderr
    listed = {line.split()[0]: line for line in done.stdout.splitlines() if line.startswith("  ")}
    for key, schema_name in keys.items():
        assert schema_name in listed[key], listed.get(key)


def test_check_hints_at_the_namespace_of_namespaced_keys(processes, tmp_path):
    """A replay under robot1/ seen without --namespace: check names the flag that reads it."""
    recording = write_mcap(tmp_path / "fake.mcap", captures=2)
    processes.start("replay", str(recording), "--loop", "--namespace", "robot1")
    done = run_check(processes.endpoint, "--window-s", "1.5")
    assert done.returncode == 0, done.stderr
    assert "  robot1/camera/image_raw " in done.stdout
    assert "`onebox check --namespace robot1`" in done.stdout


def test_describe_leaves_large_arrays_out():
    """Bytes become their length, long lists their count; short ones stay."""
    image = Image(header=Header(stamp_ns=5, frame_id="f"), width=2, height=1, data=b"\x01" * 6)
    text = describe_message(image)
    assert "data: <6 bytes>" in text and "stamp_ns: 5" in text and "_type" not in text
    info = CameraInfo(k=[1.0] * 9, d=[0.0] * 40)
    text = describe_message(info)
    assert "d: <40 values>" in text and "k: [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]" in text


def test_namespace_hint_names_the_namespace_only_when_keys_are_under_one():
    """Pipeline keys under robot1/ without --namespace give the flag to use; plain keys none."""
    keys = ["robot1/camera/image_raw", "robot1/tf_static", "other/thing"]
    hint = check.namespace_hint(keys, "")
    assert hint is not None and "`onebox check --namespace robot1`" in hint
    assert "other" not in hint
    assert check.namespace_hint(keys, "robot1") is None
    assert check.namespace_hint(["camera/image_raw", "tf_static"], "") is None


def test_lens_line_names_the_four_numbers():
    """fx, fy, cx, cy come from K's row-major places 0, 4, 2, 5."""
    info = CameraInfo(width=80, height=60, k=[69.3, 0, 40, 0, 69.4, 30, 0, 0, 1])
    assert check.lens_line("basic_camera/camera_info", info).startswith(
        "basic_camera/camera_info: 80 x 60, fx 69.300  fy 69.400  cx 40.000  cy 30.000"
    )
