"""Import a real camera's ROS bag as a onebox recording, for ``onebox replay`` and the locator.

  onebox import realsense.mcap run.mcap                   a ROS 2 bag (.mcap, .db3 or folder)
  onebox import d435.bag run.mcap --depth /camera/aligned_depth_to_color/image_raw
  onebox replay run.mcap                                   then, beside `honcho start`

Reads a ROS 2 bag (rosbag2 MCAP or SQLite, the file or the folder ``ros2 bag record`` makes) or
a ROS 1 .bag. Writes a onebox recording (zstd) of the depth picture (sensor_msgs/Image 16UC1,
mono16 or 32FC1, or image_transport's compressedDepth PNG) on camera/depth/image_raw, its lens
(the CameraInfo in the depth topic's folder) on camera/camera_info, the colour picture (raw,
or JPEG/PNG compressed: written as rgb8) on camera/image_raw when it is aligned with the depth
(the same size), and every tf_static transform on tf_static. Which topic is which comes from
the pictures' encodings; ``--depth``, ``--colour`` and ``--info`` name topics outright (a bag
with several depth pictures needs ``--depth`` unless one is aligned to the colour). Stamps are
the bag's header stamps.

A camera that moves (on an arm: its frame hangs off ``/tf``) gets its pose at each depth
picture's stamp on camera/pose, in ``--world-frame`` (default: the root of its tree), looked up
as tf2 does (between the two samples around the stamp); run the locator with ``--pose-source
pose`` and that world frame. A real camera stamps depth and colour apart: run the locator with
``--slop-ms`` (about half the frame period, ONEBOX_SLOP_MS) so that they pair. The locator
reports in the camera's optical frame unless its world frame is on tf_static
(ONEBOX_WORLD_FRAME=base_link). Refuses to overwrite OUT without --overwrite, and never leaves a
partial OUT behind.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from onebox import ros_bag
from onebox.recording import Progress, counted

log = logging.getLogger("import")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", type=Path, metavar="BAG", help="a ROS 2 or ROS 1 bag")
    parser.add_argument("destination", type=Path, metavar="OUT.mcap", help="the file to write")
    parser.add_argument("--depth", metavar="TOPIC", help="the depth picture's topic")
    parser.add_argument("--colour", metavar="TOPIC", help="the colour picture's topic")
    parser.add_argument("--info", metavar="TOPIC", help="the depth picture's CameraInfo topic")
    parser.add_argument(
        "--world-frame",
        metavar="FRAME",
        help="a moving camera (on /tf) is placed in this frame on camera/pose (default: the "
        "root of its tree)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")


def main(args: argparse.Namespace) -> int:
    result = ros_bag.import_bag(
        args.source,
        args.destination,
        depth=args.depth,
        colour=args.colour,
        info=args.info,
        world_frame=args.world_frame,
        overwrite=args.overwrite,
        progress=Progress("import"),
    )
    choice = result.choice
    d = choice.depth
    print(f"  depth   {d.topic} ({d.described})")
    print(f"  lens    {choice.info}")
    if choice.colour is not None:
        c = choice.colour
        how = f", from {c.compressed}" if c.compressed else ""
        print(f"  colour  {c.topic} ({c.encoding}{how})")
    elif choice.colour_left_out:
        print(f"  colour  left out: {choice.colour_left_out}")
    if choice.tf_static:
        print(f"  frames  {', '.join(choice.tf_static)}")
    if result.world_frame:
        missing = (
            f", {result.unplaced} without a transform at their stamp" if result.unplaced else ""
        )
        print(
            f"  pose    from {', '.join(choice.tf)}: the camera moves; camera/pose in "
            f"{result.world_frame!r} at each picture's stamp{missing}"
        )
    for key, count in sorted(result.written.items()):
        print(f"  {key:<24} {count:>6} messages")
    if result.left_out:
        listed = counted(result.left_out)
        print(f"  left out: {listed}")
    if result.bad:
        listed = counted(result.bad)
        print(f"  left out, damaged: {listed}")
    if result.distorted:
        log.info(
            "the depth lens %s has distortion coefficients: the locator and points rectify "
            "each picture as they read it",
            choice.info,
        )
    print(f"import: wrote {args.destination}: {sum(result.written.values())} messages")
    if result.world_frame:
        print(
            "  replay it to a locator run with --pose-source pose and "
            f"ONEBOX_WORLD_FRAME={result.world_frame}"
        )
    return 0
