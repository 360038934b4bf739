"""onebox sim: the table, the box and the camera on its stand, simulated and rendered.

Steps MuJoCo and, at ``rate_hz`` of simulated time, renders colour and depth of both cameras
in one pass each and publishes (keys under ``--namespace``):

  camera/image_raw               Image rgb8, width x height (default 320 x 240)
  camera/depth/image_raw         Image 32FC1, metres; NaN = no reading (outside 0.05-3.0 m)
  camera/camera_info             CameraInfo: K, D (zeros), R, P
  camera/pose                    TransformStamped world -> camera_optical_frame
  basic_camera/...               the same four from the 80 x 60 basic camera
  clock                          Clock, once a capture
  sim/ground_truth               GroundTruth: the box's true pose and size, the camera's pose
  tf_static                      TFMessage world -> camera_link -> camera_optical_frame, latched

Every message of one capture carries the same stamp: the simulated time of the capture. Runs in
real time by default, as fast as it can with --fast, and stops after --frames captures if given.
Settings (flag > environment variable > config/onebox.toml > default) are listed below.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import time
from dataclasses import dataclass
from typing import Any

import mujoco

from onebox import bus, pictures, settings
from onebox.errors import SettingError
from onebox.world.render import SceneRenderer
from onebox.world.scene import (
    OPTICAL_FRAME,
    WORLD_FRAME,
    CameraSpec,
    SceneSettings,
    box_pose,
    build_model,
    camera_info,
    cameras,
    optical_pose,
    static_transforms,
)
from schemas import (
    CameraInfo,
    Clock,
    GroundTruth,
    Header,
    Image,
    TFMessage,
    Transform,
    TransformStamped,
)

log = logging.getLogger("sim")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)
    camera = parser.add_argument_group("camera (the seed's launch arguments)")
    settings.add(camera, "width", 320, "pixels across")
    settings.add(camera, "height", 240, "pixels down")
    settings.add(camera, "hfov_deg", 60.0, "how wide the camera sees, degrees")
    settings.add(camera, "mount_height", 0.40, "how high the stand holds the camera, metres")
    settings.add(camera, "rate_hz", 5.0, "captures a second of simulated time")
    scene = parser.add_argument_group("scene")
    settings.add(scene, "box_x", 0.065, "the box's middle, metres along world x")
    settings.add(scene, "box_y", 0.040, "the box's middle, metres along world y")
    settings.add(scene, "box_size", 0.06, "the box's edge, metres")
    settings.add(scene, "box_yaw_deg", 0.0, "the box's turn about the vertical, degrees")
    scene.add_argument(
        "--no-box", dest="box", action="store_false", help="a scene with nothing on the table"
    )
    settings.add(scene, "gui", False, "also open MuJoCo's own window (needs a display)")
    run = parser.add_argument_group("run")
    run.add_argument("--frames", type=int, metavar="N", help="stop after N captures")
    run.add_argument(
        "--fast", action="store_true", help="as fast as possible instead of in real time"
    )


def scene_settings(args: argparse.Namespace) -> SceneSettings:
    return SceneSettings(
        width=args.width,
        height=args.height,
        hfov_deg=args.hfov_deg,
        mount_height=args.mount_height,
        box=args.box,
        box_x=args.box_x,
        box_y=args.box_y,
        box_size=args.box_size,
        box_yaw_deg=args.box_yaw_deg,
    )


@dataclass
class CameraPublishers:
    """The four publishers of one camera, and the lens it publishes with every capture."""

    spec: CameraSpec
    colour: bus.Publisher[Image]
    depth: bus.Publisher[Image]
    info: bus.Publisher[CameraInfo]
    pose: bus.Publisher[TransformStamped]


def _open_gui(model: mujoco.MjModel, data: mujoco.MjData, wanted: bool) -> Any:
    """MuJoCo's own viewer window, or None: when not asked for, or when there is no display."""
    if not wanted:
        return None
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        log.warning("gui: no display here ($DISPLAY is not set); running headless without it")
        return None
    import mujoco.viewer

    return mujoco.viewer.launch_passive(model, data)


def main(args: argparse.Namespace) -> int:
    """Simulate, render and publish until stopped or --frames captures were made."""
    scene = scene_settings(args)
    if args.rate_hz <= 0:
        raise SettingError(f"rate_hz {args.rate_hz}: must be above 0")
    model = build_model(scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    specs = cameras(scene)
    period_s = 1.0 / args.rate_hz
    steps_per_capture = max(1, round(period_s / model.opt.timestep))

    with bus.open_bus(args) as b, SceneRenderer(model, specs) as renderer:
        pubs = [
            CameraPublishers(
                spec=cam,
                colour=b.publisher(f"{cam.name}/image_raw", Image),
                depth=b.publisher(f"{cam.name}/depth/image_raw", Image),
                info=b.publisher(f"{cam.name}/camera_info", CameraInfo),
                pose=b.publisher(f"{cam.name}/pose", TransformStamped),
            )
            for cam in specs
        ]
        clock = b.publisher("clock", Clock)
        truth = b.publisher("sim/ground_truth", GroundTruth)
        tf_static = b.publisher("tf_static", TFMessage, latched=True)
        tf_static.publish(TFMessage(transforms=static_transforms(model)))
        main_cam = specs[0]
        log.info(
            "%d x %d, hfov %.1f deg (fx %.3f), camera %.2f m up, %s, %.1f Hz%s",
            main_cam.width,
            main_cam.height,
            main_cam.hfov_deg,
            main_cam.focal_px,
            scene.mount_height,
            f"box {scene.box_size:.3f} m at ({scene.box_x:+.3f}, {scene.box_y:+.3f})"
            if scene.box
            else "no box",
            args.rate_hz,
            ", as fast as possible" if args.fast else "",
        )
        # A new session learns of the subscribers already there a moment after it opens; wait
        # for that (at most a second) so that the first capture reaches them too.
        if not pubs[0].depth.wait_for_subscribers(timeout_s=1.0):
            log.info("no subscriber yet; publishing anyway")
        gui = _open_gui(model, data, args.gui)
        start = time.monotonic()
        count = 0
        try:
            while args.frames is None or count < args.frames:
                stamp_ns = round(data.time * 1e9)
                publish_capture(model, data, renderer, pubs, stamp_ns)
                clock.publish(Clock(clock_ns=stamp_ns))
                truth.publish(ground_truth(model, data, stamp_ns))
                count += 1
                if gui is not None:
                    if not gui.is_running():
                        break
                    gui.sync()
                mujoco.mj_step(model, data, nstep=steps_per_capture)
                if not args.fast:
                    # Real time: capture n is due at n periods after the start.
                    delay_s = start + count * period_s - time.monotonic()
                    if delay_s > 0:
                        time.sleep(delay_s)
        finally:
            if gui is not None:
                gui.close()
            elapsed_s = time.monotonic() - start
            log.info(
                "%d captures in %.1f s (%.1f a second)",
                count,
                elapsed_s,
                count / elapsed_s if elapsed_s else math.nan,
            )
    return 0


def publish_capture(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    renderer: SceneRenderer,
    pubs: list[CameraPublishers],
    stamp_ns: int,
) -> None:
    """Render and publish every camera, all stamped ``stamp_ns``."""
    for cam in pubs:
        header = Header(stamp_ns=stamp_ns, frame_id=OPTICAL_FRAME)
        pose = optical_pose(model, data, cam.spec.name)
        cam.pose.publish(
            TransformStamped(
                header=Header(stamp_ns=stamp_ns, frame_id=WORLD_FRAME),
                child_frame_id=OPTICAL_FRAME,
                transform=Transform(translation=pose.position, rotation=pose.orientation),
            )
        )
        cam.info.publish(camera_info(cam.spec, stamp_ns))
        capture = renderer.render(data, cam.spec.name)
        colour = pictures.rgb8_image(capture.rgb, header)
        depth = pictures.depth_image(capture.depth_m, header)
        cam.depth.publish(depth)
        cam.colour.publish(colour)


def ground_truth(model: mujoco.MjModel, data: mujoco.MjData, stamp_ns: int) -> GroundTruth:
    box = box_pose(model, data)
    return GroundTruth(
        header=Header(stamp_ns=stamp_ns, frame_id=WORLD_FRAME),
        box_pose=box[0] if box else None,
        box_size=box[1] if box else None,
        camera_pose=optical_pose(model, data, "camera"),
    )
