"""onebox pixels: the basic camera's pictures as coloured squares and the seed's 5.2 table."""

from __future__ import annotations

import re
import subprocess

import numpy as np
import pytest

from onebox.testing.fake_capture import capture
from onebox.testing.processes import wait_for_output
from schemas import Image
from services import pixels

# The seed's section 5.2, exactly: the table, the box's side, the box's top.
SEED_TABLE = """\
              43     44     45     46     47     48     49     50
  row 19   0.400  0.400  0.400  0.373  0.340  0.340  0.340  0.340
  row 20   0.400  0.400  0.400  0.373  0.340  0.340  0.340  0.340
  row 21   0.400  0.400  0.400  0.373  0.340  0.340  0.340  0.340
  row 22   0.400  0.400  0.400  0.373  0.340  0.340  0.340  0.340
  row 23   0.400  0.400  0.400  0.373  0.340  0.340  0.340  0.340"""

SQUARE = re.compile(r"\x1b\[48;2;(\d+);(\d+);(\d+)m")


def picture_rows(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("\x1b[48;2;")]


def run_pixels(processes, *args: str) -> tuple[int, str]:
    proc = processes.start("pixels", "--timeout-s", "30", *args)
    # Read while it runs: the pictures are more than a pipe holds.
    out, _ = proc.communicate(timeout=40)
    return proc.returncode, out


def test_pixels_prints_the_seed_table_from_the_running_sim(processes):
    """Beside the real sim it prints both 80 x 60 pictures and the seed's 5.2 table exactly."""
    processes.start("sim", "--fast")
    code, out = run_pixels(processes)
    assert code == 0, out
    assert SEED_TABLE in out
    rows = picture_rows(out)
    assert len(rows) == 2 * 60, "60 rows of colour, then 60 of depth"
    assert all(line.count("  ") >= 80 and line.endswith("\x1b[0m") for line in rows)
    colours = {tuple(map(int, m)) for m in SQUARE.findall("".join(rows[:60]))}
    assert any(r > 150 and g < 60 and b < 60 for r, g, b in colours), "the red box"


def test_pixels_prints_the_seed_table_from_a_replayed_recording(processes, tmp_path):
    """A recording of the sim, replayed, gives the same table: pixels cannot tell the difference."""
    recording = tmp_path / "basic.mcap"
    recorder = processes.start("record", str(recording), "--keys", "basic_camera/**")
    wait_for_output(recorder, "recording ")
    sim = processes.start("sim", "--fast", "--frames", "5")
    sim.wait(timeout=60)
    assert sim.returncode == 0, processes.stop(sim)
    processes.stop(sim)
    processes.stop(recorder)
    assert recorder.returncode == 0
    processes.start("replay", str(recording), "--loop")
    code, out = run_pixels(processes, "--no-pictures")
    assert code == 0, out
    assert SEED_TABLE in out
    assert not picture_rows(out)


def test_pixels_says_how_to_start_when_nothing_arrives(processes):
    """With nothing publishing it exits 2 and says to start the simulation."""
    proc = processes.start("pixels", "--timeout-s", "1")
    proc.wait(timeout=30)
    out = processes.stop(proc)
    assert proc.returncode == 2
    assert "no capture of basic_camera within 1 s" in out
    assert "honcho start" in out and "Traceback" not in out


def test_pixels_other_patch_and_bad_messages(processes, test_bus):
    """Garbage is logged by key and skipped; --rows/--cols choose another patch."""
    proc = processes.start(
        "pixels", "--timeout-s", "30", "--rows", "19", "20", "--cols", "43", "45"
    )
    raw = test_bus.session.declare_publisher("basic_camera/image_raw")
    msgs = capture(400_000_000, camera="basic_camera", width=80, height=60)
    colour = test_bus.publisher("basic_camera/image_raw", Image)
    depth = test_bus.publisher("basic_camera/depth/image_raw", Image)
    while proc.poll() is None:
        raw.put(b"garbage")
        colour.publish(msgs["basic_camera/image_raw"])
        depth.publish(msgs["basic_camera/depth/image_raw"])
        try:
            proc.wait(timeout=0.2)
        except subprocess.TimeoutExpired:  # still waiting: publish the capture again
            continue
    out = processes.stop(proc)
    assert proc.returncode == 0, out
    assert "basic_camera/image_raw" in out and "dropped" in out
    # The fake box's top starts at row 20, column 44.
    assert (
        "              43     44     45\n"
        "  row 19   0.400  0.400  0.400\n"
        "  row 20   0.400  0.340  0.340\n"
    ) in out


def test_pixels_patch_outside_the_picture_is_one_clear_line(processes, test_bus):
    """A patch beyond the 80 x 60 picture exits 2 naming the flag and the picture's size."""
    proc = processes.start("pixels", "--timeout-s", "30", "--rows", "55", "60", "--no-pictures")
    msgs = capture(400_000_000, camera="basic_camera", width=80, height=60)
    colour = test_bus.publisher("basic_camera/image_raw", Image)
    depth = test_bus.publisher("basic_camera/depth/image_raw", Image)
    while proc.poll() is None:
        colour.publish(msgs["basic_camera/image_raw"])
        depth.publish(msgs["basic_camera/depth/image_raw"])
        try:
            proc.wait(timeout=0.2)
        except subprocess.TimeoutExpired:  # still waiting: publish the capture again
            continue
    out = processes.stop(proc)
    assert proc.returncode == 2
    assert "--rows 55 60" in out and "80 x 60" in out and "Traceback" not in out


def test_patch_table_matches_the_seed_format():
    """patch_table lays out the seed's numbers exactly as section 5.2 prints them."""
    depth = np.full((60, 80), 0.4, np.float32)
    depth[:, 46] = 0.373
    depth[:, 47:] = 0.34
    assert pixels.patch_table(depth, (19, 23), (43, 50)) == SEED_TABLE


def test_depth_grey_near_is_bright_and_no_reading_is_blue():
    """Nearer reads brighter; NaN gets its own colour, not a grey."""
    depth = np.array([[0.34, 0.40, np.nan]], np.float32)
    grey = pixels.depth_grey(depth)
    assert grey[0, 0, 0] > grey[0, 1, 0]
    assert grey[0, 0, 0] == grey[0, 0, 1] == grey[0, 0, 2]
    assert tuple(grey[0, 2]) == pixels.NO_READING_RGB


@pytest.mark.parametrize("rgb", [np.zeros((2, 3, 3), np.uint8), np.full((1, 4, 3), 9, np.uint8)])
def test_squares_one_square_per_pixel(rgb):
    """Each pixel is two spaces; each row ends by resetting the colour."""
    lines = pixels.squares(rgb).split("\n")
    assert len(lines) == rgb.shape[0]
    for line in lines:
        assert SQUARE.sub("", line).removesuffix("\x1b[0m") == "  " * rgb.shape[1]
