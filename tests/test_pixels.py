"""onebox pixels: the basic camera's pictures as coloured squares and the seed's 5.2 table."""

from __future__ import annotations

import re
import subprocess

import numpy as np
import pytest

from onebox.recording import describe
from onebox.testing.fake_capture import capture
from onebox.testing.processes import ROOT, wait_for_output
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

CELL = re.compile(r"\x1b\[38;2;(\d+);(\d+);(\d+)(?:;48;2;(\d+);(\d+);(\d+))?m")
ESCAPE = re.compile(r"\x1b\[[0-9;]*m")


def picture_rows(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("\x1b[38;2;")]


def columns(line: str) -> int:
    """How many character cells a line takes in a terminal."""
    return len(ESCAPE.sub("", line))


def unblock(text: str, width: int) -> np.ndarray:
    """The picture back from its half blocks (an odd last row comes back as -1)."""
    rows = []
    for line in text.split("\n"):
        upper, lower = [], []
        for cell in re.findall(r"((?:\x1b\[[0-9;]*m)*)\u2580", line):
            found = CELL.findall(cell)
            if found:
                r, g, b, r2, g2, b2 = found[-1]
                colour = (int(r), int(g), int(b))
                below = (int(r2), int(g2), int(b2)) if r2 else (-1, -1, -1)
            upper.append(colour)
            lower.append(below)
        assert len(upper) == width
        rows += [upper, lower]
    return np.array(rows)


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
    assert len(rows) == 2 * 30, "two pixel rows a line: 30 lines of colour, then 30 of depth"
    assert all(columns(line) == 80 and line.endswith("\x1b[0m") for line in rows)
    colours = {tuple(map(int, m[:3])) for m in CELL.findall("".join(rows[:30]))}
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
    assert "the committed capture has no basic_camera keys" in out


@pytest.mark.parametrize("camera", ["basic_camera", "camera"])
def test_pixels_hint_suggests_a_replay_only_of_a_capture_that_has_the_keys(camera):
    """Whatever replay the hint names holds the colour and depth keys of the camera it names."""
    hint = pixels.start_hint(camera)
    assert "honcho start" in hint
    keys = {k.key for k in describe(ROOT / pixels.CAPTURE).keys}
    suggested = pixels.COMMITTED_CAPTURE_CAMERA
    assert f"onebox replay {pixels.CAPTURE} --loop" in hint
    assert {f"{suggested}/image_raw", f"{suggested}/depth/image_raw"} <= keys
    if camera != suggested:
        assert f"{camera}/image_raw" not in keys
        assert f"`onebox pixels --camera {suggested}`" in hint


def test_pixels_of_the_committed_capture_fit_80_columns(processes):
    """The hint's replay works: the 320 x 240 camera is thinned to 80 columns and 30 lines."""
    processes.start("replay", str(ROOT / pixels.CAPTURE), "--loop")
    code, out = run_pixels(processes, "--camera", "camera")
    assert code == 0, out
    rows = picture_rows(out)
    assert len(rows) == 2 * 30
    assert all(columns(line) == 80 for line in rows)
    assert "camera: 320 x 240, shown 80 x 60, colour at 1.800 s" in out


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


@pytest.mark.parametrize("height", [1, 4, 5])
def test_half_blocks_two_pixel_rows_a_line_and_every_colour_kept(height):
    """Each cell is ▀ with the upper pixel as foreground, the lower as background; nothing lost."""
    rng = np.random.default_rng(height)
    rgb = rng.integers(0, 256, (height, 80, 3), dtype=np.uint8)
    rgb[:, 10:20] = 7  # a flat run: one escape covers it
    text = pixels.half_blocks(rgb)
    lines = text.split("\n")
    assert len(lines) == (height + 1) // 2
    assert all(columns(line) == 80 and line.endswith("\x1b[0m") for line in lines)
    back = unblock(text, 80)
    assert np.array_equal(back[:height], rgb)
    if height % 2:
        assert (back[height] == -1).all(), "an odd last row keeps the terminal's background"


def test_thinned_fits_the_columns():
    """80 pixels stay 80; 320 become every 4th pixel across and down; 81 become 41."""
    assert pixels.thinned(np.zeros((60, 80, 3), np.uint8), 80).shape == (60, 80, 3)
    assert pixels.thinned(np.zeros((240, 320, 3), np.uint8), 80).shape == (60, 80, 3)
    assert pixels.thinned(np.zeros((10, 81, 3), np.uint8), 80).shape == (5, 41, 3)
