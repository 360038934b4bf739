"""tf_static as in ROS: newer replaces older, a message is used whole or not at all, the world
stays a root; and the locator heals from a poisoned tf_static when the sim starts again."""

from __future__ import annotations

import numpy as np
import pytest

from onebox.geometry import FrameError, FrameTree
from onebox.testing.processes import Inbox
from onebox.testing.synthetic import tf_static
from schemas import (
    Detection3DArray,
    GroundTruth,
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    codec,
)
from tests.test_locator import Output

OPTICAL = "camera_optical_frame"


def link(parent: str, child: str, z: float = 0.0, quat=(0.0, 0.0, 0.0, 1.0)) -> TransformStamped:
    return TransformStamped(
        header=Header(frame_id=parent),
        child_frame_id=child,
        transform=Transform(
            translation=Vector3(z=z),
            rotation=Quaternion(x=quat[0], y=quat[1], z=quat[2], w=quat[3]),
        ),
    )


def camera_tree() -> FrameTree:
    return FrameTree(tf_static().transforms, roots=["world"])


# --- the frame tree ------------------------------------------------------------------------------


def test_a_newer_transform_for_a_child_replaces_the_older():
    """Publishing camera_link again under world moves it; the chain follows."""
    tree = camera_tree()
    assert tree.lookup("world", OPTICAL)[2, 3] == pytest.approx(0.4)
    assert tree.add_all([link("world", "camera_link", z=0.5, quat=(-0.5, 0.5, 0.5, 0.5))]) == [
        "camera_link"
    ]
    assert tree.lookup("world", OPTICAL)[2, 3] == pytest.approx(0.5)


def test_a_message_that_makes_a_loop_is_refused_whole():
    """A loop at the end of a message refuses the valid transforms before it too."""
    tree = camera_tree()
    before, version = tree.lookup("world", OPTICAL), tree.version
    message = [link("world", "table", z=1.0), link(OPTICAL, "base"), link("base", "camera_link")]
    with pytest.raises(FrameError, match="own ancestor"):
        tree.add_all(message)
    assert "table" not in tree.frames and "base" not in tree.frames
    assert tree.version == version
    np.testing.assert_array_equal(tree.lookup("world", OPTICAL), before)


def test_an_unusable_transform_refuses_its_message_whole():
    """A zero quaternion among good transforms: none of them is used."""
    tree = camera_tree()
    with pytest.raises(FrameError, match="not usable"):
        tree.add_all([link("world", "table"), link("world", "door", quat=(0, 0, 0, 0))])
    assert "table" not in tree.frames


def test_the_world_stays_a_root():
    """A transform that gives the world a parent is refused, even with no loop."""
    tree = camera_tree()
    with pytest.raises(FrameError, match="root"):
        tree.add(link("elsewhere", "world"))
    with pytest.raises(FrameError, match="root"):
        tree.add(link(OPTICAL, "world"))
    assert tree.lookup("world", OPTICAL)[2, 3] == pytest.approx(0.4)


def test_the_issues_two_poisoning_messages_then_the_sims_again():
    """base -> camera_link cuts the camera off, optical -> world is refused; the sim's own
    tf_static then puts the camera back where it was."""
    tree = camera_tree()
    good = tree.lookup("world", OPTICAL)
    tree.add_all([link("base", "camera_link")])
    with pytest.raises(FrameError, match="separate trees"):
        tree.lookup("world", OPTICAL)
    with pytest.raises(FrameError, match="root"):
        tree.add_all([link(OPTICAL, "world")])
    tree.add_all(tf_static().transforms)
    np.testing.assert_allclose(tree.lookup("world", OPTICAL), good, atol=1e-12)


def test_a_ten_thousand_frame_chain_is_checked_in_linear_time():
    """10,000 frames in one message are checked and looked up without recursion."""
    chain = [link("world", "f0", z=0.001)] + [
        link(f"f{i}", f"f{i + 1}", z=0.001) for i in range(9_999)
    ]
    tree = FrameTree(chain, roots=["world"])
    assert tree.lookup("world", "f9999")[2, 3] == pytest.approx(10.0)
    with pytest.raises(FrameError, match="own ancestor"):
        tree.add_all([link("f9999", "f0")])


# --- the real locator, attacked and healed ------------------------------------------------------


def detections_with_truth(
    items: list[tuple[str, bytes]],
) -> list[tuple[Detection3DArray, GroundTruth]]:
    truths = {
        t.header.stamp_ns: t
        for t in (codec(GroundTruth).decode(p) for k, p in items if k == "sim/ground_truth")
    }
    arrays = [codec(Detection3DArray).decode(p) for k, p in items if k == "detections"]
    return [(a, truths[a.header.stamp_ns]) for a in arrays if a.header.stamp_ns in truths]


def is_right(array: Detection3DArray, truth: GroundTruth) -> bool:
    if len(array.detections) != 1 or truth.box_pose is None:
        return False
    found, true = array.detections[0].bbox.center.position, truth.box_pose.position
    return abs(found.x - true.x) < 0.002 and abs(found.y - true.y) < 0.002


def test_poisoned_tf_static_is_refused_and_a_restarted_sim_heals_the_locator(processes, test_bus):
    """The issue's two messages: the chain change is logged, the world's parent refused; the
    restarted sim is measured right from its first second on, the locator never restarted."""
    inbox = Inbox()
    for key in ("detections", "sim/ground_truth"):
        test_bus.subscribe_raw(key, inbox)
    locator = Output(processes.start("locator", "--log-interval-s", "0.5"))
    locator.wait_for(r"finding (the|every) box")
    sim = processes.start("sim", "--rate-hz", "10")
    inbox.wait(lambda items: any(is_right(*m) for m in detections_with_truth(items)), 60)

    stranger = test_bus.publisher("tf_static", TFMessage, latched=True)
    stranger.publish(TFMessage(transforms=[link("base", "camera_link")]))
    locator.wait_for(
        rf"the camera's chain changed: {OPTICAL} in world was at \(\+0\.000, \+0\.000, "
        r"\+0\.400\) m.*, now not connected"
    )
    stranger.publish(TFMessage(transforms=[link(OPTICAL, "world")]))
    locator.wait_for(r"refused a message of 1 transforms, all of it: .* world a parent")

    processes.stop(sim)
    inbox.items.clear()
    processes.start("sim", "--rate-hz", "10")
    inbox.wait(lambda items: len(detections_with_truth(items)) >= 5, 60)
    found = detections_with_truth(inbox.items)
    assert all(is_right(*m) for m in found), [a.detections for a, _ in found]
    first_truth = min(
        codec(GroundTruth).decode(p).header.stamp_ns
        for k, p in inbox.items
        if k == "sim/ground_truth"
    )
    assert found[0][0].header.stamp_ns - first_truth <= 1_000_000_000  # simulated time
    locator.wait_for(
        r"the camera's chain changed: .* was not connected, now at \(\+0\.000, \+0\.000, "
        r"\+0\.400\) m"
    )
    assert locator.proc.poll() is None
    assert "Traceback" not in locator.stop()
