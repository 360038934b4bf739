"""Export an .mcap recording for the tools robotics people already use.

  onebox export IN.mcap OUT.mcap --to ros2       rosbag2's MCAP: CDR with ros2msg schemas
  onebox export IN.mcap OUT.mcap --to foxglove   Foxglove's well-known protobuf schemas

``--to ros2`` writes what ``ros2 bag record`` would have: sensor_msgs/msg/Image,
sensor_msgs/msg/CameraInfo, sensor_msgs/msg/PointCloud2, tf2_msgs/msg/TFMessage (tf_static
latched; the camera's pose also on /tf), geometry_msgs/msg/TransformStamped,
rosgraph_msgs/msg/Clock and vision_msgs/msg/Detection3DArray, on the keys' own names with a
leading slash. ``ros2 bag play OUT.mcap``, Foxglove and Rerun's MCAP reader open it.
``--to foxglove`` writes RawImage, CameraCalibration, FrameTransforms, PointCloud and SceneUpdate
(a cube and a label a detected box) for Foxglove's 3D panel.

The lens is copied as it is: onebox's CameraInfo already puts the middle of pixel u at u, as ROS
does. Keys with no counterpart (the support plane, the ground truth) are left out and counted; a
message that does not decode, or whose stamp the format cannot hold, is reported by key and
left out. Prints progress on long files. Refuses to overwrite OUT without --overwrite, and never
leaves a partial OUT behind: the file is written beside it and renamed when complete.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass
from pathlib import Path

from onebox import export, settings
from onebox.recording import Progress, counted

log = logging.getLogger("export")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", type=Path, metavar="IN.mcap", help="a onebox recording")
    parser.add_argument("destination", type=Path, metavar="OUT.mcap", help="the file to write")
    parser.add_argument(
        "--to", required=True, choices=export.FORMATS, help="ros2 (rosbag2 MCAP) or foxglove"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    parser.add_argument(
        "--recover", action="store_true", help="read a truncated IN up to its last whole chunk"
    )
    settings.add(parser, "namespace", "", "the prefix the recorded keys carry, if any")


@dataclass(frozen=True)
class ExportSettings:
    source: Path
    destination: Path
    to: str
    overwrite: bool
    recover: bool
    namespace: str


def main(args: argparse.Namespace) -> int:
    s = ExportSettings(
        source=args.source,
        destination=args.destination,
        to=args.to,
        overwrite=args.overwrite,
        recover=args.recover,
        namespace=args.namespace,
    )
    result = export.export(
        s.source,
        s.destination,
        s.to,
        namespace=s.namespace,
        overwrite=s.overwrite,
        recover=s.recover,
        progress=Progress("export"),
    )
    for topic, count in sorted(result.topics.items()):
        print(f"  {topic:<28} {count:>6} messages")
    if result.left_out:
        listed = counted(result.left_out)
        print(f"  left out, no {s.to} counterpart: {listed}")
    if result.bad:
        listed = counted(result.bad)
        print(f"  left out, not convertible: {listed}")
    print(f"export: wrote {s.destination} ({s.to}): {result.written} messages")
    return 0
