"""A catalogue of a site's box sizes: read from TOML, matched against measured tops, and used by
the finder and the locator (a full layer's carton takes its entry's height and name)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from onebox.errors import SettingError
from onebox.perception.boxes import FinderSettings, find_boxes
from onebox.perception.catalogue import Entry, match, read_catalogue
from onebox.testing.raycast import Camera, Plane, Scene, box_on, render
from services.locator import detection_array

CARTONS = """
[[box]]
name = "A4 carton"
length = 0.22   # sides in either order
width = 0.31
height = 0.25

[[box]]
name = "flat A4"
length = 0.31
width = 0.22
height = 0.08

[[box]]
name = "small"
length = 0.2
width = 0.15
height = 0.1
"""


@pytest.fixture
def catalogue(tmp_path):
    path = tmp_path / "cartons.toml"
    path.write_text(CARTONS)
    return read_catalogue(path)


def test_a_catalogue_reads_every_entry_length_first(catalogue):
    """Three entries, each with its name and its sides sorted (length >= width), metres."""
    assert catalogue == (
        Entry("A4 carton", 0.31, 0.22, 0.25),
        Entry("flat A4", 0.31, 0.22, 0.08),
        Entry("small", 0.2, 0.15, 0.1),
    )


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (None, "cannot read the catalogue"),
        ("box = 3", "lists no boxes"),
        ("[[box]]\nname = 'x'\nlength = 0.3\nwidth = 0.2\n", "box 1: needs name"),
        ("[[box]]\nname = 'x'\nlength = 'long'\nwidth = 0.2\nheight = 0.1\n", "box 1"),
        ("[[box]]\nname = 'x'\nlength = 300\nwidth = 200\nheight = 100\n", "sizes are metres"),
        ("[[box]\n", "is not TOML"),
    ],
)
def test_a_bad_catalogue_is_refused_naming_the_file(tmp_path, text, says):
    """A missing file, no boxes, a missing or non-numeric size, millimetres for metres or broken
    TOML: a SettingError that names the file and what is wrong."""
    path = tmp_path / "cartons.toml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(SettingError, match=says) as raised:
        read_catalogue(path)
    assert str(path) in str(raised.value)


def test_a_top_matches_the_entry_of_its_size_and_nearest_height(catalogue):
    """Within 12 mm a side it fits; the two A4 sizes differ by height only, so the nearer
    height wins; 2 cm off a side it fits nothing; a hidden side may be shorter, not longer."""
    assert match(0.305, 0.225, 0.24, catalogue) == catalogue[0]
    assert match(0.305, 0.225, 0.1, catalogue) == catalogue[1]
    assert match(0.33, 0.22, 0.24, catalogue) is None
    assert match(0.2, 0.22, 0.24, catalogue) is None
    assert match(0.2, 0.22, 0.24, catalogue, hidden_length=True) == catalogue[0]
    assert match(0.36, 0.22, 0.24, catalogue, hidden_length=True) is None


def test_the_finder_gives_a_catalogued_carton_its_height_and_name(catalogue):
    """A 0.31 x 0.22 m carton 0.25 m tall under a camera straight overhead, in a ring of others
    as tall, shows no level round it: without a catalogue its height is not seen; with one it
    is the entry's, and its name is the entry's. A box of no entry's size keeps its own."""
    ring = [
        box_on(Plane(), x * 0.32, y * 0.23, (0.31, 0.22, 0.25), 0.0, (170, 130, 80))
        for x in (-1, 0, 1)
        for y in (-1, 0, 1)
    ]
    lone = box_on(Plane(), 0.6, 0.0, (0.12, 0.09, 0.06), 0.0, (60, 90, 200))
    camera = Camera.tilted(1.6, 0.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), (*ring, lone)))
    plain = find_boxes(depth, camera.lens, camera.camera_to_world, colour)
    listed = find_boxes(
        depth, camera.lens, camera.camera_to_world, colour, FinderSettings(catalogue=catalogue)
    )

    def middle_of(found, x: float):
        return min(found.boxes, key=lambda b: math.dist(b.top_middle[:2], (x, 0.0)))

    assert not middle_of(plain, 0.0).height_seen
    carton = middle_of(listed, 0.0)
    assert carton.name == "A4 carton"
    assert carton.size[2] == pytest.approx(0.25)
    assert carton.centre[2] == pytest.approx(0.125, abs=0.003)
    small = middle_of(listed, 0.6)
    assert small.name == ""
    assert small.size[2] == pytest.approx(0.06, abs=0.002)


def test_the_locator_says_the_entry_as_a_second_class(catalogue):
    """A catalogued box's detection has two hypotheses, "box" and the entry's name, and says
    whether its height was seen and how many sides are hidden."""
    ring = [box_on(Plane(), 0.0, 0.0, (0.31, 0.22, 0.25), 0.0, (170, 130, 80))]
    camera = Camera.tilted(1.2, 20.0, width=640, height=480)
    depth, colour = render(Scene(camera, Plane(), tuple(ring)))
    found = find_boxes(
        depth, camera.lens, camera.camera_to_world, colour, FinderSettings(catalogue=catalogue)
    )
    (detection,) = detection_array(found, 7, "world").detections
    assert [(h.class_id, h.score) for h in detection.results] == [
        ("box", found.boxes[0].score),
        ("A4 carton", found.boxes[0].score),
    ]
    assert detection.height_seen and detection.hidden_sides == 0


def test_the_locator_refuses_a_bad_catalogue_with_one_line(tmp_path):
    """`onebox locator --catalogue` on a missing file: exit status 2 and one line naming it."""
    missing = tmp_path / "none.toml"
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "locator", "--catalogue", str(missing)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert str(missing) in done.stderr and "Traceback" not in done.stderr
