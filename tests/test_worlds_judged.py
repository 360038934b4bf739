"""The box finder on MuJoCo renders of random scenes, judged against their ground truth: the
scenes below hold stacked boxes whose base only their side faces show (a box across a
narrower one, overhanging it) and boxes that hide a side of the box under them, whose top is
then seen as a strip."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from onebox.geometry import Intrinsics
from onebox.perception.boxes import Box, FinderSettings, Found
from onebox.perception.stream import BoxFinder
from onebox.testing.judged import Judged, Rendered, judge, render_scene
from onebox.world import spec
from onebox.world.noise import PRESETS
from onebox.world.random_scene import looking_across, random_pallet, random_scene
from onebox.world.spec import BoxDesc, CameraDesc, ObjectDesc, SceneDesc, TableDesc
from schemas import BoxTruth, GroundTruth, Pose, Vector3

# --- what the finder does wrong, by physical cause ------------------------------------------------
# Each failing case is marked with what the finder does there, as measured (python -m pytest
# tests/test_worlds_judged.py -rx lists them; a case it gets right again fails as XPASS until it
# leaves its table).

LOWER = "measured from a lower neighbour"
"""A carton's base taken at the top of a lower carton beside it, not at what it stands on."""
TABLE = "measured from the table"
"""A box on a mostly hidden box measured from the table, not from the box under it."""
SHADE = "cartons of one shade not parted"
"""Touching cartons of one shade found as one top: reported as one box, or left out (the top
fills too little of its rectangle, or boxes stand on it and it is a platform)."""
PLATFORM = "a carton taken for a platform"
"""A carton seen whole left out: two or more boxes (its neighbours' upper cartons, or cartons
beside it measured from it) stand on it."""
PALLET = "the pallet's bare top a box"

XFAIL_SCENE = {
    1: "box 6 0.199 x 0.077 m for 0.160 x 0.062, its centre 18 mm off (box 0's top beside it 2 mm "
    "lower)",
    3: f"{LOWER}: box 5 (partly hidden) 0.011 m for 0.094, from box 6's top (0.083 m); box 0 "
    "(partly hidden, under box 1) 0.146 m for 0.193",
    9: f"{LOWER}: box 0 (partly hidden) 0.018 m for 0.095, from box 1's top (0.077 m)",
    15: f"{LOWER}: box 6 0.104 m for 0.221, from box 4's top (0.117 m) beside it",
    47: f"{TABLE}: box 2 (0.117 m on box 1, mostly hidden, which carries two boxes) 0.315 m",
}

XFAIL_PALLET = {
    30: f"{LOWER}: box 9 0.033 m for 0.183, from the 0.150 m tops beside it",
    202: f"{LOWER}: the three 0.250 m cartons 0.083 m, from box 1 beside them (0.167 m); "
    f"{PLATFORM}: box 1 (three boxes on it), missed; {PALLET}: 1.066 x 0.805 x 0.144 m",
    209: f"{LOWER}: boxes 5 and 7 0.069 m for 0.150 and box 6 0.012 m for 0.162, from their "
    "neighbours' tops; box 2 (0.081 m tall) missed, and box 1, one top 0.754 m long with the "
    "cartons either side of a sliver of box 3 between taller ones",
}

XFAIL_PALLET_D435 = {
    7: f"{SHADE}: a pair one box 0.491 x 0.244 m (box 1 missed, a centre 124 mm off); {LOWER}: "
    "box 3 0.017 m for 0.170",
    11: "every carton found, none false; box 9 (0.090 m on a carton) 6.1 mm short (bound 5), "
    "its centre 10.5 mm off (bound 10)",
    15: f"{LOWER}: box 11 0.017 m for 0.168, from its neighbours' tops; boxes 1, 4, 5, 10 and 13 "
    "and boxes 2 and 6 (partly hidden) 0.287-0.294 m for 0.142-0.150, measured down to the "
    "floor past the pallet's edge",
    24: f"{SHADE}: a pair one box 0.496 x 0.242 m (a centre 122 mm off), box 10 missed",
}

XFAIL_ONE_SHADE = {
    216: f"{SHADE}: boxes 10 and 11 one box 0.588 x 0.200 m, and a 0.614 x 0.301 m box (2 "
    f"false): 3 missed; {LOWER}: box 6 0.038 m and box 8 (partly hidden) 0.037 m for 0.200",
    222: f"{SHADE}: boxes 4, 6 and 7 one box 0.405 x 0.315 m (centre 96 mm off): 2 missed",
}

XFAIL_TAPED = {
    (30, "none"): f"{LOWER}: box 9 0.033 m for 0.183, from the 0.150 m tops beside it",
    (7, "d435"): f"{SHADE}: a pair one box 0.491 x 0.244 m (box 1 missed, a centre 124 mm off); "
    f"{LOWER}: box 3 0.018 m for 0.170",
    (11, "d435"): "box 9 0.084 m for 0.090 (6.1 mm short, bound 5), its centre 10.5 mm off "
    "(bound 10); every carton found, none false",
}

XFAIL_TAPED_FLAPS = {
    14: "every carton found, none false; centres of boxes 2 and 6 (on a carton) 10-11 mm off "
    "(bound 10)",
    53: f"{LOWER}: box 7 0.011 m for 0.163, from box 4 beside it (0.150 m); box 8 0.032 m for "
    "0.150, from box 6 (0.117 m)",
}

XFAIL_TAPED_SCRAPS = {
    (20, "none"): "box 7 missed",
}

XFAIL_TAPED_ROUND = {
    (1, "none"): f"{SHADE}: boxes 3 and 6 one box 0.503 x 0.249 m, 0.070 m tall for 0.150: box 6 "
    f"missed; {LOWER}: box 9 0.066 m for 0.146, from box 8 beside it (0.080 m)",
    (18, "none"): f"{LOWER}: box 7 0.044 m for 0.163, from box 8 (0.119 m)",
    (24, "none"): "every carton found, none false, every height right; a centre 6.7 mm off "
    "(bound 5)",
    (5, "d435"): f"{LOWER}: boxes 4 and 6 (partly hidden) 0.057-0.058 m for 0.300, from box 3 "
    f"beside them (0.244 m); {PLATFORM}: box 3, missed",
}

XFAIL_D435_LENS = {
    (8, "none"): "box 6 0.314 x 0.219 m for 0.300 x 0.200, its centre 8 mm off (bound 5)",
    (8, "d435"): f"{SHADE}: box 6 part of a 0.803 x 0.294 m top (fill 0.47, no box), missed",
    (10, "d435"): f"{LOWER}: box 12 0.033 m for 0.235, from its 0.200 m neighbours",
}


def xfail(reason: str) -> pytest.MarkDecorator:
    return pytest.mark.xfail(strict=True, reason=reason)


def marked(params: list, table: dict) -> list:
    """``params`` for parametrize, those in ``table`` marked to fail for its reason."""
    return [
        pytest.param(*(p if isinstance(p, tuple) else (p,)), marks=xfail(table[p]))
        if p in table
        else p
        for p in params
    ]


def _judged(scene: SceneDesc, noise: str = "none") -> Judged:
    """The finder on ``scene`` rendered with ``noise`` (a preset), judged against its ground
    truth."""
    rendered = render_scene(scene, PRESETS[noise])
    found = BoxFinder(FinderSettings())(
        rendered.depth_m, rendered.lens, rendered.camera_to_world, rendered.rgb
    )
    judged = Judged()
    judge(found, rendered, judged)
    return judged


def _every_carton_right(judged: Judged, noise: str, found: int) -> None:
    """No box missed, none false, at least ``found`` found; heights within 1 mm and centres
    within 5 mm noise-free, 5 mm and 10 mm through noise."""
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= found
    assert max(judged.height_mm + judged.hidden_height_mm) <= (1.0 if noise == "none" else 5.0)
    assert max(judged.centre_mm) <= (5.0 if noise == "none" else 10.0), judged.notes


@pytest.mark.parametrize("seed", marked([1, 3, 4, 6, 9, 13, 15, 27, 47], XFAIL_SCENE))
def test_random_scene_every_box_right(seed):
    """Every box found, none false, each height (partly hidden ones too) within 2 mm. (Seeds 6
    and 13: a box on a wider box, whose rectangle holds its middle, stands on it; it was read
    from a level below it, the floor on seed 13.)"""
    judged = _judged(random_scene(seed, boxes=8, objects=3, width=640, height=480))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 3
    assert max(judged.height_mm + judged.hidden_height_mm) <= 2.0, judged.notes


def test_a_box_flush_on_a_narrow_one_beside_a_lower_top_stands_on_the_narrow_one():
    """Seed 2: a carton 57 x 20 mm stands on one of 63 x 22 mm, their faces nearly flush, and
    the colour steps down the faces where the lower one begins. A wide top 4 mm higher than
    the lower carton stands off to one end of the pair, past the line of that side but beside
    another. Every box found, none false, the carton measured from the narrow one under it."""
    judged = _judged(random_scene(2, boxes=8, objects=3, width=640, height=480))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4
    # The seam's height is read at the points down the face, 4.3 mm apart on this one.
    assert max(judged.height_mm) <= 5.0, judged.notes


def test_a_small_oblong_top_turned_on_the_pixel_grid_is_a_box():
    """Seed 12: a box's top 40 x 25 mm, 2.3 m away, is ten pixels by six turned 48 degrees on
    the pixel grid; it is a box, as is every other box seen whole, and none is false."""
    judged = _judged(random_scene(12, boxes=8, objects=3, width=640, height=480))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4
    # Ten pixels across, its height is good to 6 mm.
    assert max(judged.height_mm) <= 7.0, judged.notes


def test_a_long_narrow_top_through_a_stereo_cameras_noise_is_level_along_it():
    """Seed 20 through a D435's noise: a box 158 x 22 mm standing on another, 13 pixels wide
    1.1 m away. Its edges' smear leans its fitted plane 21 degrees across it; along it, it is
    level within a degree. Every box found, none false."""
    judged = _judged(random_scene(20, boxes=8, objects=3, width=640, height=480), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4


def test_a_tiny_picture_looked_at_across_gives_boxes_not_an_error():
    """160 x 120 through a D435's noise, 45 degrees across: the boxes found (two at least, none
    false), not an error."""
    scene = looking_across(random_scene(412, boxes=8, objects=3, width=160, height=120), 45.0)
    judged = _judged(scene, "d435")
    assert judged.found >= 2 and judged.false == 0, judged.notes


def test_a_carton_with_a_box_lying_across_it_is_one_carton():
    """A 0.141 x 0.138 m carton with a 0.124 x 0.031 m box lying across its middle: its top is
    seen in two strips either side, which are one top, the line in the colour along the box's
    edge no seam. Found whole and measured (its size within 5 mm), nothing false."""
    scene = random_scene(14, boxes=8, objects=3, width=640, height=480)
    carton, lying = scene.boxes[5], scene.boxes[6]
    assert lying.on == 5 and carton.size[:2] == (0.141, 0.138)  # the world this test is about
    rendered = render_scene(scene, PRESETS["none"])
    found = BoxFinder(FinderSettings())(
        rendered.depth_m, rendered.lens, rendered.camera_to_world, rendered.rgb
    )
    nearest = min(
        found.boxes, key=lambda b: np.hypot(b.centre[0] - carton.x, b.centre[1] - carton.y)
    )
    assert np.hypot(nearest.centre[0] - carton.x, nearest.centre[1] - carton.y) < 0.005
    assert sorted(nearest.size[:2]) == pytest.approx(sorted(carton.size[:2]), abs=0.005)
    judged = Judged()
    judge(found, rendered, judged)
    assert judged.false == 0, judged.notes


@pytest.mark.parametrize("seed", marked([2, 5, 8, 11, 30, 202, 209], XFAIL_PALLET))
def test_random_pallet_every_carton_right(seed):
    """A loaded pallet (rows of touching cartons, some lower than their neighbours, some
    carrying a smaller one): every carton seen whole found, none false, each height within
    1 mm, each measured from what it stands on, not from a lower neighbour."""
    judged = _judged(random_pallet(seed))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4
    assert max(judged.height_mm) <= 1.0, judged.notes


@pytest.mark.parametrize("seed", marked([2, 7, 11, 15, 24], XFAIL_PALLET_D435))
def test_random_pallet_through_d435_every_carton_on_its_base(seed):
    """Through a stereo camera's depth (noise, dropout at every edge), cartons at the load's
    edge stand on the pallet, not on the floor seen past them: the pallet's rim there is lost
    in the dropout band, and the pallet's top seen in front rises to the cartons past that
    band. Every carton found, none false (a place left empty, walled in by cartons, shows the
    pallet's top: no box), heights within 5 mm, centres within 10 mm."""
    judged = _judged(random_pallet(seed), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 5
    assert max(judged.height_mm + judged.hidden_height_mm) <= 5.0, judged.notes
    assert max(judged.centre_mm) <= 10.0, judged.notes


@pytest.mark.parametrize("seed", marked([207, 216, 222], XFAIL_ONE_SHADE))
def test_random_pallet_through_d435_cartons_of_one_shade_apart(seed):
    """Cartons of one shade end to end: the seam between them is a shadow that darkens over a
    few pixels, with no step from pixel to pixel as large as a colour edge's, and the depth's
    noise hides the gap. Each carton is found on its own (0.30 m long, not a pair's 0.59 m),
    none false."""
    judged = _judged(random_pallet(seed), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 6
    assert max(judged.height_mm) <= 5.0, judged.notes
    assert max(judged.centre_mm) <= 10.0, judged.notes


@pytest.mark.parametrize(
    ("seed", "noise"),
    marked(
        [
            (2, "none"),
            (8, "none"),
            (21, "none"),
            (30, "none"),
            (6, "d435"),
            (7, "d435"),
            (11, "d435"),
            (22, "d435"),
        ],
        XFAIL_TAPED,
    ),
)
def test_random_pallet_taped_every_carton_right(seed, noise):
    """The same pallets with packing tape along every carton's top, a shade lighter than the
    carton: colour cuts each top into flaps and tape, which are joined back into one carton
    each, and every carton comes out right (the benchmark has more pallets)."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), noise), noise, 3)


@pytest.mark.parametrize("seed", marked([14, 37, 53], XFAIL_TAPED_FLAPS))
def test_random_pallet_taped_through_d435_flaps_of_one_length_joined(seed):
    """Through the D435's noise at 2 m (3 sigma about 45 mm) a flap's end reads up to 25 mm
    long, as the side face's first readings are within the top's tolerance: a carton's flaps
    and tape are still joined into one box, every carton right."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), "d435"), "d435", 4)


@pytest.mark.parametrize(
    ("seed", "noise"),
    marked([(20, "none"), (38, "d435"), (3, "azure_kinect")], XFAIL_TAPED_SCRAPS),
)
def test_random_pallet_taped_scraps_round_a_box_on_a_carton_are_no_boxes(seed, noise):
    """A smaller carton on a taped one hides most of its top: what shows are scraps of flap
    and tape, cut apart by colour, each against a flap at its level on one side and the box
    on it on another. The scraps are no boxes; every carton right."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), noise), noise, 4)


@pytest.mark.parametrize(
    ("seed", "noise"),
    marked(
        [
            (1, "none"),
            (5, "none"),
            (16, "none"),
            (18, "none"),
            (24, "none"),
            (5, "d435"),
            (16, "d435"),
            (8, "azure_kinect"),
        ],
        XFAIL_TAPED_ROUND,
    ),
)
def test_random_pallet_taped_flaps_round_a_box_on_a_carton_are_no_boxes(seed, noise):
    """A smaller carton standing across a taped one's tape: what shows of the lower top round
    it are its flaps, 10-60 cm long, cut apart by the tape and the box. The flaps are no boxes
    beside the upper carton, which is measured from the carton under it; every carton right.
    Seeds 1 and 18 show only stubs of the tape past the box's ends; on seed 8 through the
    Kinect's noise a stub's other side is a whole carton packed against the flap, a box."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), noise), noise, 2)


@pytest.mark.parametrize(
    ("seed", "noise"), marked([(8, "none"), (8, "d435"), (10, "d435")], XFAIL_D435_LENS)
)
def test_random_pallet_in_a_d435s_own_picture_every_carton_found(seed, noise):
    """A D435's own depth picture, 848 x 480 through an 87-degree lens, is read whole: every
    carton found, none false. At this lens's coarser footprint a carton 2 m away is measured
    less closely than through a 60-degree lens: centres within 16 mm through the D435's
    noise."""
    scene = random_pallet(seed, width=848, height=480)
    scene = replace(scene, camera=replace(scene.camera, hfov_deg=87.0))
    judged = _judged(scene, noise)
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 7
    assert max(judged.height_mm + judged.hidden_height_mm) <= (1.0 if noise == "none" else 5.0)
    assert max(judged.centre_mm) <= (5.0 if noise == "none" else 16.0), judged.notes


def _across_a_table() -> SceneDesc:
    """A robot's head camera 45 degrees from straight down, over a table 0.7 m high: a cube,
    a lower box and a long low one (both cut off at the picture's far edge), and a can."""
    return SceneDesc(
        camera=CameraDesc(y=-0.9, z=1.2, tilt_deg=45.0, width=640, height=480),
        table=TableDesc(z=0.7, size=(2.5, 2.5)),
        boxes=(
            BoxDesc(-0.2, 0.0, (0.20, 0.15, 0.12), yaw_deg=25.0, rgba=(0.7, 0.55, 0.35, 1.0)),
            BoxDesc(0.15, 0.1, (0.30, 0.10, 0.08), yaw_deg=-10.0, rgba=(0.3, 0.3, 0.8, 1.0)),
            BoxDesc(0.05, -0.25, (0.10, 0.10, 0.10), yaw_deg=45.0, rgba=(0.75, 0.5, 0.35, 1.0)),
        ),
        objects=(ObjectDesc("cylinder", 0.3, -0.2, (0.04, 0.06)),),
    )


@pytest.mark.parametrize("noise", ["none", "d435", "azure_kinect"])
def test_camera_at_45_degrees_a_cube_stands_on_the_table_not_on_a_lower_top(noise):
    """Looking 45 degrees across a table, a probe point just past a box's near side lies right
    in front of the box's own face, and the face behind it reads within a few millimetres of
    any level under the box's top: the cube stands on the table (its height within 1 mm), not
    on a lower top cut off at the picture's edge."""
    judged = _judged(_across_a_table(), noise)
    assert judged.found == 1 and judged.missed == 0 and judged.false == 0, judged.notes
    assert max(judged.height_mm) <= 1.0, judged.notes
    assert max(judged.centre_mm) <= (2.0 if noise == "none" else 6.0), judged.notes


CARRYING = (
    "the middle carton found (0.25 x 0.20 x 0.15 m within 2 mm) but with a side reported "
    "hidden, so no partly hidden carton's size is judged"
)


@pytest.mark.parametrize(
    "noise", [pytest.param(n, marks=xfail(CARRYING)) for n in ("none", "azure_kinect")]
)
def test_a_carton_carrying_a_smaller_one_is_a_box_of_its_own(noise):
    """Two stacks: three cartons, each smaller than the one under it and turned on it, and two.
    The middle carton's top shows only round the one on it (47 % of it seen): a carton with a
    box on it is still a box, found with every side seen and measured."""
    brown = (0.72, 0.55, 0.36, 1.0)
    scene = SceneDesc(
        camera=CameraDesc(x=0.1, y=-0.45, z=1.3, tilt_deg=25.0, width=640, height=480),
        table=TableDesc(z=0.0, size=(2.0, 2.0)),
        boxes=(
            BoxDesc(-0.2, 0.0, (0.30, 0.25, 0.20), yaw_deg=5.0, rgba=brown),
            BoxDesc(-0.2, 0.0, (0.25, 0.20, 0.15), yaw_deg=15.0, on=0, rgba=(0.68, 0.52, 0.34, 1)),
            BoxDesc(-0.2, 0.0, (0.15, 0.12, 0.10), yaw_deg=35.0, on=1, rgba=(0.75, 0.58, 0.4, 1)),
            BoxDesc(0.25, 0.05, (0.20, 0.20, 0.25), yaw_deg=-20.0, rgba=brown),
            BoxDesc(0.25, 0.05, (0.18, 0.14, 0.12), yaw_deg=-5.0, on=3, rgba=(0.7, 0.5, 0.3, 1)),
        ),
    )
    judged = _judged(scene, noise)
    assert judged.found == 2 and judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.hidden_found >= 1, judged.notes
    assert max(judged.height_mm + judged.hidden_height_mm) <= 1.0, judged.notes
    # Sizes are judged of the partly hidden cartons reported with no side hidden.
    assert judged.hidden_size_mm and max(judged.hidden_size_mm) <= 3.0, judged.notes


def _nine_cartons() -> SceneDesc:
    """Nine cartons 30 x 20 cm touching in three rows on the floor, one brown, those on a
    diagonal 22 cm tall and the rest 20 cm, seen from 2.3 m by a camera tilted 22 degrees."""
    return SceneDesc(
        camera=CameraDesc(x=0.1, y=-1.0, z=2.3, tilt_deg=22.0, width=640, height=480),
        table=TableDesc(z=0.0, size=(3.0, 3.0)),
        boxes=tuple(
            BoxDesc(-0.3 + 0.3 * j, -0.2 + 0.2 * i, (0.30, 0.20, 0.22 if i == j else 0.20))
            for i in range(3)
            for j in range(3)
        ),
    )


@xfail(
    f"{SHADE}: the six 0.200 m cartons one top 0.904 x 0.600 m (fills 0.65, no box): 4 missed; "
    f"{LOWER}: the three 0.220 m ones 0.020 m, from that top"
)
def test_cartons_touching_in_rows_stand_on_the_floor():
    """A carton 2 cm taller than its neighbour shows a strip of its face over the neighbour's
    top, seen nearly edge-on from above: one pixel there steps 35 mm down the face, and the
    colour step where the neighbour's top meets it reads as a seam 32 mm under that top. Every
    carton stands on the floor: all nine found, heights within 1 mm."""
    judged = _judged(_nine_cartons())
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found + judged.hidden_found == 9, judged.notes
    assert max(judged.height_mm + judged.hidden_height_mm) <= 1.0, judged.notes


@xfail(f"{SHADE}: all nine one box 0.886 x 0.589 x 0.207 m: 6 missed")
def test_cartons_touching_in_rows_through_d435_not_on_their_faces():
    """Through a D435's noise the near faces of the front row are seen at a slant and spread
    over the tolerance: no carton stands on them; all nine found, heights within 2 mm."""
    judged = _judged(_nine_cartons(), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found + judged.hidden_found == 9, judged.notes
    assert max(judged.height_mm + judged.hidden_height_mm) <= 2.0, judged.notes


@pytest.mark.parametrize("noise", ["d435", "azure_kinect"])
def test_a_pallets_rim_in_front_of_its_load_is_no_box(noise):
    """pallet.toml: 5 cm of the pallet's top shows in front of the near row, a strip 1.2 m long
    with no reading along its back edge (the depth camera's hole at the cartons' faces) and the
    cartons standing on it past that edge. It is the pallet's top going on under them, not a
    box: no box is reported at the pallet's height."""
    scene = spec.load(Path(__file__).resolve().parent.parent / "scene" / "pallet.toml")
    rendered = render_scene(scene, PRESETS[noise])
    found = BoxFinder(FinderSettings())(
        rendered.depth_m, rendered.lens, rendered.camera_to_world, rendered.rgb
    )
    pallet_top = scene.boxes[0].size[2]
    assert found.boxes, "the cartons are found"
    assert all(abs(box.top_middle[2] - pallet_top) > 0.02 for box in found.boxes), [
        (box.top_middle, box.size) for box in found.boxes
    ]


def test_random_pallet_is_the_same_for_a_seed():
    """The same seed gives the same pallet; another seed another; the pallet is box 0."""
    assert random_pallet(11) == random_pallet(11)
    assert random_pallet(11) != random_pallet(12)
    assert random_pallet(11).boxes[0].size == (1.2, 0.8, 0.144)


def test_the_judge_takes_the_part_seen_of_a_box_under_another_for_that_box():
    """A carton half hidden under a box on it is reported at the strip that shows: the judge
    pairs that report with the carton (its middle lies on the carton's top), counts it among
    the partly hidden found and judges its height; a report on no top is false."""
    carton = BoxTruth(
        pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.05)),
        size=Vector3(x=0.3, y=0.2, z=0.1),
        top_in_view=True,
        top_pixels=500,
    )
    box = BoxTruth(
        pose=Pose(position=Vector3(x=0.05, y=0.0, z=0.15)),
        size=Vector3(x=0.1, y=0.1, z=0.1),
        on=0,
        top_in_view=True,
        top_pixels=400,
    )
    camera = np.eye(4)
    camera[2, 3] = 1.0
    rendered = Rendered(
        np.zeros((2, 2)),
        np.zeros((2, 2, 3), np.uint8),
        Intrinsics(1.0, 1.0, 0.0, 0.0),
        camera,
        GroundTruth(boxes=[carton, box]),
        [1000, 400],
    )

    def reported(top: tuple[float, float, float], height: float, hidden: int) -> Box:
        centre = (top[0], top[1], top[2] - height / 2)
        return Box(centre, (0.0, 0.0, 0.0, 1.0), (0.1, 0.1, height), 0.0, 1.0, 100, top, 0,
                   hidden_sides=hidden)  # fmt: skip

    strip = reported((-0.11, 0.0, 0.1), 0.1, 1)  # 110 mm from the carton's middle, on its top
    judged = Judged()
    judge(
        Found(None, [reported((0.05, 0.0, 0.2), 0.1, 0), strip, reported((0.5, 0.5, 0.1), 0.1, 0)]),
        rendered,
        judged,
    )
    assert (judged.found, judged.missed, judged.false) == (1, 0, 1), judged.notes
    assert (judged.hidden, judged.hidden_found) == (1, 1)
    assert judged.hidden_height_mm == [pytest.approx(0.0)]
