"""The box finder on MuJoCo renders of random scenes, judged against their ground truth: the
scenes below hold stacked boxes whose base only their side faces show (a box across a
narrower one, overhanging it) and boxes that hide a side of the box under them, whose top is
then seen as a strip."""

from __future__ import annotations

from dataclasses import replace

import pytest

from onebox.perception.boxes import FinderSettings
from onebox.perception.stream import BoxFinder
from onebox.testing.judged import Judged, judge, render_scene
from onebox.world.noise import PRESETS
from onebox.world.random_scene import looking_across, random_pallet, random_scene
from onebox.world.spec import BoxDesc, CameraDesc, ObjectDesc, SceneDesc, TableDesc


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


@pytest.mark.parametrize("seed", [1, 3, 4, 9, 15, 27, 47])
def test_random_scene_every_box_right(seed):
    """Every box found, none false, each height (partly hidden ones too) within 2 mm."""
    judged = _judged(random_scene(seed, boxes=8, objects=3, width=640, height=480))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 3
    assert max(judged.height_mm + judged.hidden_height_mm) <= 2.0, judged.notes


def test_a_box_flush_on_a_narrow_one_beside_a_lower_top_stands_on_the_narrow_one():
    """Seed 2: a carton 57 x 20 mm stands on one of 63 x 22 mm, their faces nearly flush, and
    the colour steps down the faces where the lower one begins. A wide top 4 mm higher than
    the lower carton stands off to one end of the pair, past the line of that side but beside
    another. Finders before took it for a top meeting the face at the seam (which would put the
    seam there and say nothing of the base) and measured the carton from the table: 209 mm
    for 143."""
    judged = _judged(random_scene(2, boxes=8, objects=3, width=640, height=480))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4
    # The seam's height is read at the points down the face, 4.3 mm apart on this one.
    assert max(judged.height_mm) <= 5.0, judged.notes


def test_a_small_oblong_top_turned_on_the_pixel_grid_is_a_box():
    """Seed 12: a box's top 40 x 25 mm, 2.3 m away, is ten pixels by six turned 48 degrees on
    the pixel grid. Its outermost outline points stand in of its sides by far less than a
    pixel, so the footprint added to their span made it fill 0.80 of its rectangle, and
    finders before left it out. (A squarish top that small is left out still: a ball's or a
    tin's top fills as much.)"""
    judged = _judged(random_scene(12, boxes=8, objects=3, width=640, height=480))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4
    # Ten pixels across, its height is good to 6 mm.
    assert max(judged.height_mm) <= 7.0, judged.notes


def test_a_tiny_picture_looked_at_across_gives_boxes_not_an_error():
    """160 x 120 through a D435's noise, 45 degrees across: a top dropped before it was
    measured kept a label higher than every measured top's, and the finder before failed on it
    (an index out of range) instead of giving the boxes it found."""
    scene = looking_across(random_scene(412, boxes=8, objects=3, width=160, height=120), 45.0)
    judged = _judged(scene, "d435")
    assert judged.found >= 2 and judged.false == 0, judged.notes


@pytest.mark.parametrize("seed", [2, 5, 8, 11, 30, 202, 209])
def test_random_pallet_every_carton_right(seed):
    """A loaded pallet (rows of touching cartons, some lower than their neighbours, some
    carrying a smaller one): every carton seen whole found, none false, each height within
    1 mm. Finders before measured a carton from its lower neighbour: on seed 5 a box's top
    (244 mm short, the neighbour left out); on seed 30 a carton's top that the small carton
    on it keeps from being a box (94 mm short, three cartons); on seed 11 the two cartons
    at the load's edge from the floor (the pallet's rim past them is out of sight); on seeds
    202 and 209 cartons from a neighbour 69-83 mm lower (a quarter of their width was the
    most a box could stand on the next carton of its row by)."""
    judged = _judged(random_pallet(seed))
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 4
    assert max(judged.height_mm) <= 1.0, judged.notes


@pytest.mark.parametrize("seed", [2, 7, 11, 15, 24])
def test_random_pallet_through_d435_every_carton_on_its_base(seed):
    """Through a stereo camera's depth (noise, dropout at every edge), cartons at the load's
    edge stand on the pallet, not on the floor seen past them: the pallet's rim there is lost
    in the dropout band, and the pallet's top seen in front rises to the cartons past that
    band. Finders before measured them 144 mm too tall (the pallet's height), on seed 7 took
    a strip of the pallet's top for a box, and on seeds 11 and 24 measured the small cartons
    on cartons 2.3 m away from the pallet or the floor: a step of 91 mm was within the two
    tops' noise added (3 sigma each, 57 mm), not in quadrature. On seed 15 a place left
    empty, walled in by cartons on three sides, showed the pallet's top, taken for a box."""
    judged = _judged(random_pallet(seed), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 5
    assert max(judged.height_mm + judged.hidden_height_mm) <= 5.0, judged.notes
    assert max(judged.centre_mm) <= 10.0, judged.notes


@pytest.mark.parametrize("seed", [207, 216, 222])
def test_random_pallet_through_d435_cartons_of_one_shade_apart(seed):
    """Cartons of one shade end to end: the seam between them is a shadow that darkens over a
    few pixels, with no step from pixel to pixel as large as a colour edge's, and the depth's
    noise hides the gap. Finders before took each such pair for one box 0.59 m long (the
    cartons are 0.30 m): all 6 false boxes on seeds 201-230."""
    judged = _judged(random_pallet(seed), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found >= 6
    assert max(judged.height_mm) <= 5.0, judged.notes
    assert max(judged.centre_mm) <= 10.0, judged.notes


@pytest.mark.parametrize(
    ("seed", "noise"),
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
)
def test_random_pallet_taped_every_carton_right(seed, noise):
    """The same pallets with packing tape along every carton's top, a shade lighter than the
    carton: colour cuts each top into flaps and tape, which are joined back into one carton
    each (finders before reported each flap and the tape as boxes: 199 false boxes on the 30
    pallets of seeds 1-30). Pallets on which every carton comes out right; the benchmark
    has the rest."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), noise), noise, 3)


@pytest.mark.parametrize("seed", [14, 37, 53])
def test_random_pallet_taped_through_d435_flaps_of_one_length_joined(seed):
    """Through the D435's noise at 2 m (3 sigma about 45 mm) a flap's end reads up to 25 mm
    long, as the side face's first readings are within the top's tolerance. Finders before
    asked the flaps and the tape for one length within 5 %, and reported a 250 mm carton as
    two boxes a flap wide (one of them false)."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), "d435"), "d435", 4)


@pytest.mark.parametrize(("seed", "noise"), [(20, "none"), (38, "d435"), (3, "azure_kinect")])
def test_random_pallet_taped_scraps_round_a_box_on_a_carton_are_no_boxes(seed, noise):
    """A smaller carton on a taped one hides most of its top: what shows are scraps of flap
    and tape, cut apart by colour, each against a flap at its level on one side and the box
    on it on another. Finders before reported the scraps of tape (5-8 cm) as boxes of the
    carton's height: five on seed 20."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), noise), noise, 4)


@pytest.mark.parametrize(
    ("seed", "noise"),
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
)
def test_random_pallet_taped_flaps_round_a_box_on_a_carton_are_no_boxes(seed, noise):
    """A smaller carton standing across a taped one's tape: what shows of the lower top round
    it are its flaps, 10-60 cm long, cut apart by the tape and the box. Finders before
    reported each flap as a box beside the upper carton, and measured that one from the pallet
    (seed 16: 0.341 m tall for 0.180): 8 of the 9 false boxes on the taped pallets of seeds
    1-30. Seeds 1 and 18 show only stubs of the tape past the box's ends; on seed 8 through
    the Kinect's noise a stub's other side is a whole carton packed against the flap, which
    stays a box."""
    _every_carton_right(_judged(random_pallet(seed, taped=True), noise), noise, 2)


@pytest.mark.parametrize(("seed", "noise"), [(8, "none"), (8, "d435"), (10, "d435")])
def test_random_pallet_in_a_d435s_own_picture_every_carton_found(seed, noise):
    """A D435's own depth picture, 848 x 480 through an 87-degree lens, is read whole. Read at
    every second pixel (the finder's limit was 640 x 480), these pallets lost one or two
    cartons each. Through the D435's noise, a carton 2 m away at this lens's coarser footprint
    comes out up to 21 mm too wide (centres 9-15 mm off), against 7 mm at the p90 through a
    60-degree lens."""
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
    any level under the box's top. Finders before took that for the level of a lower top cut
    off at the picture's edge (80 mm of the cube's 100, noise-free and through every camera);
    a reading on no top now matches a level past a side the camera sees only within half the
    drop the ray makes from the point to the face."""
    judged = _judged(_across_a_table(), noise)
    assert judged.found == 1 and judged.missed == 0 and judged.false == 0, judged.notes
    assert max(judged.height_mm) <= 1.0, judged.notes
    assert max(judged.centre_mm) <= (2.0 if noise == "none" else 6.0), judged.notes


@pytest.mark.parametrize("noise", ["none", "azure_kinect"])
def test_a_carton_carrying_a_smaller_one_is_a_box_of_its_own(noise):
    """Two stacks: three cartons, each smaller than the one under it and turned on it, and two.
    The middle carton's top shows only round the one on it (47 % of it seen). Finders before
    took a top more than half covered for a platform (a pallet's, not a box) and left the
    middle carton out; a top two or more boxes stand on still is one."""
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


def test_cartons_touching_in_rows_stand_on_the_floor():
    """A carton 2 cm taller than its neighbour shows a strip of its face over the neighbour's
    top, seen nearly edge-on from above: one pixel there steps 35 mm down the face, and the
    colour step where the neighbour's top meets it read as a seam 32 mm under that top. The
    finder before stood the carton on that seam: 52 mm tall for 220."""
    judged = _judged(_nine_cartons())
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found + judged.hidden_found == 9, judged.notes
    assert max(judged.height_mm + judged.hidden_height_mm) <= 1.0, judged.notes


def test_cartons_touching_in_rows_through_d435_not_on_their_faces():
    """Through a D435's noise the near faces of the front row, seen at a slant and spread over
    the tolerance, came out as one piece 0.89 m long at 126 mm, and the finder before stood
    all nine cartons on it (74-94 mm tall for 200-220). A piece whose plane along the rays
    stands upright is a face, no level."""
    judged = _judged(_nine_cartons(), "d435")
    assert judged.missed == 0 and judged.false == 0, judged.notes
    assert judged.found + judged.hidden_found == 9, judged.notes
    assert max(judged.height_mm + judged.hidden_height_mm) <= 2.0, judged.notes


def test_random_pallet_is_the_same_for_a_seed():
    """The same seed gives the same pallet; another seed another; the pallet is box 0."""
    assert random_pallet(11) == random_pallet(11)
    assert random_pallet(11) != random_pallet(12)
    assert random_pallet(11).boxes[0].size == (1.2, 0.8, 0.144)
