"""onebox ros2: bridge onebox's keys and ROS 2 topics, live, over ROS 2's own Zenoh middleware.

ROS 2 (Jazzy and later) run with RMW_IMPLEMENTATION=rmw_zenoh_cpp talks Zenoh through a router
at tcp/localhost:7447, where onebox's router is. This process is one ROS 2 node on that router
(`ros2 node list` shows /onebox) and translates key names and payloads (msgpack <-> CDR); no ROS
installation is needed on this side.

Out, onebox -> ROS 2 (on unless --no-out): every onebox key with a ROS 2 type, on the topic
/ + key (/NS/ + key with --namespace NS):

  camera/image_raw, camera/depth/image_raw    sensor_msgs/msg/Image
  camera/camera_info                          sensor_msgs/msg/CameraInfo
  camera/points                               sensor_msgs/msg/PointCloud2
  camera/pose                                 geometry_msgs/msg/TransformStamped
  basic_camera/...                            the same
  tf_static                                   tf2_msgs/msg/TFMessage, TRANSIENT_LOCAL (latched)
  clock                                       rosgraph_msgs/msg/Clock (for use_sim_time)
  detections                                  vision_msgs/msg/Detection3DArray

--out KEY[=TOPIC] (repeatable) bridges only the keys named, each on TOPIC if given (a relative
TOPIC is under the node's namespace). Nothing is converted while no ROS 2 node subscribes.

In, ROS 2 -> onebox: --in TOPIC=KEY (repeatable) subscribes to a ROS 2 topic and publishes
each message as the onebox message on KEY: pictures (sensor_msgs/msg/Image, or
CompressedImage on a topic ending /compressed or /compressedDepth) on camera/image_raw or
camera/depth/image_raw (16UC1, mono16 or 32FC1), CameraInfo on camera/camera_info,
tf2_msgs/msg/TFMessage on tf_static (TRANSIENT_LOCAL: a late bridge still gets a driver's
latched transforms), TransformStamped on camera/pose, Clock on clock. --preset NAME fills in
a driver's default topics:

  realsense      realsense2_camera, `ros2 launch realsense2_camera rs_launch.py
                 align_depth.enable:=true`: /camera/camera/aligned_depth_to_color/image_raw,
                 /camera/camera/color/image_raw, .../aligned_depth_to_color/camera_info,
                 /tf_static
  azure_kinect   the Azure Kinect ROS 2 driver: /depth_to_rgb/image_raw, /rgb/image_raw,
                 /depth_to_rgb/camera_info, /tf_static

A key bridged in is not bridged out. Run the locator with --slop-ms (a real camera stamps
depth and colour apart) and, for its detections in the robot's frame, ONEBOX_WORLD_FRAME.

The ROS domain is --domain-id, else $ROS_DOMAIN_ID, else 0. A message that does not decode is
logged with its key or topic and dropped; a slow direction drops its oldest pictures and says
so. Stops on Ctrl-C, after --duration-s, or after --frames messages have crossed.
"""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from dataclasses import dataclass

from onebox import bus, rmw_zenoh
from onebox.errors import SettingError
from onebox.ros2_bridge import PRESETS, Bridge, BridgeSettings, plan

log = logging.getLogger("ros2")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)
    parser.add_argument(
        "--out",
        action="append",
        metavar="KEY[=TOPIC]",
        help="bridge this onebox key out, on TOPIC if given; repeatable (default: every key "
        "with a ROS 2 type)",
    )
    parser.add_argument("--no-out", action="store_true", help="bridge nothing from onebox to ROS 2")
    parser.add_argument(
        "--in",
        dest="ins",
        action="append",
        default=[],
        metavar="TOPIC=KEY",
        help="publish ROS 2 topic TOPIC's messages on onebox KEY; repeatable",
    )
    parser.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        help="--in for every topic a camera driver publishes by default",
    )
    parser.add_argument(
        "--domain-id",
        type=int,
        metavar="N",
        help=f"the ROS domain (default ${rmw_zenoh.DOMAIN_ENV}, else 0)",
    )
    parser.add_argument(
        "--node-name", default="onebox", help="this node's name in the ROS graph (default onebox)"
    )
    parser.add_argument(
        "--frames", type=int, metavar="N", help="stop after N messages have crossed"
    )
    parser.add_argument("--duration-s", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument(
        "--log-interval-s",
        type=float,
        default=5.0,
        metavar="S",
        help="how often to say what crossed (default 5)",
    )


@dataclass(frozen=True)
class RunSettings:
    """When to stop and how often to report."""

    frames: int | None
    duration_s: float | None
    log_interval_s: float

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RunSettings:
        if args.frames is not None and args.frames < 1:
            raise SettingError(f"--frames {args.frames}: must be at least 1")
        if args.duration_s is not None and not args.duration_s > 0:
            raise SettingError(f"--duration-s {args.duration_s}: must be above 0")
        if not args.log_interval_s > 0:
            raise SettingError(f"--log-interval-s {args.log_interval_s}: must be above 0")
        return cls(args.frames, args.duration_s, args.log_interval_s)


def bridge_settings(args: argparse.Namespace) -> BridgeSettings:
    namespace = bus.check_namespace(args.namespace or "")
    routes_out, routes_in = plan(
        out=args.out,
        no_out=args.no_out,
        ins=args.ins,
        preset=args.preset,
        namespace=namespace,
    )
    return BridgeSettings(
        routes_out=routes_out,
        routes_in=routes_in,
        domain_id=rmw_zenoh.domain_id(args.domain_id, os.environ),
        node_name=rmw_zenoh.check_node_name(args.node_name),
        namespace=namespace,
    )


def run(bridge: Bridge, config: RunSettings) -> None:
    started = time.monotonic()
    next_log = started + config.log_interval_s
    since: dict[str, int] = {}
    quiet = False
    idle = threading.Event()
    while True:
        now = time.monotonic()
        if config.duration_s is not None and now - started >= config.duration_s:
            return
        if config.frames is not None and bridge.crossed >= config.frames:
            return
        if now >= next_log:
            line = bridge.report(since)
            if line is not None:
                log.info("%s", line)
            elif not quiet:
                log.info("nothing crossed in the last %g s", config.log_interval_s)
            quiet = line is None
            for topic in bridge.waiting():
                log.info("waiting for a ROS 2 publisher on %s", topic)
            next_log = now + config.log_interval_s
        idle.wait(0.05)  # the lanes work on their own threads; this one only keeps time


def main(args: argparse.Namespace) -> int:
    """Bridge until stopped."""
    config = bridge_settings(args)
    when = RunSettings.from_args(args)
    with bus.open_bus(args) as b:
        log.info(
            "ROS 2 node %s on domain %d",
            f"{rmw_zenoh.namespace_of(config.namespace).rstrip('/')}/{config.node_name}",
            config.domain_id,
        )
        for route in config.routes_out:
            log.info("%s -> %s (%s)", b.key(route.key), route.topic, route.typename)
        for route in config.routes_in:
            log.info("%s -> %s (%s)", route.topic, b.key(route.key), route.typename)
        with Bridge(b, config) as bridge:
            try:
                run(bridge, when)
            finally:
                log.info("%d messages crossed", bridge.crossed)
    return 0
