"""onebox sim: a world of boxes and other objects on a table, and a depth camera on its stand.

Builds the world from a scene file (--scene scene/pallet.toml, or the setting ``scene``), from a
seed (--random-scene 7 --boxes 8 --objects 3), or, with neither, the seed's world: one red box
under a camera looking straight down (scene/one_box.toml says the same). The lens and picture
size settings override the scene's. Steps MuJoCo and, at ``rate_hz`` of simulated time, renders
colour and depth of both cameras in one pass each, adds the depth noise of the scene's [noise]
(or --noise MODEL: none, gaussian, axial, quantise, edge_dropout, speckle, d435, azure_kinect)
and its colour_sigma's noise to the colour, and publishes (keys under ``--namespace``):

  camera/image_raw               Image rgb8, width x height (default 320 x 240)
  camera/depth/image_raw         Image 32FC1, metres; NaN = no reading (outside 0.05-3.0 m),
                                 or 16UC1 millimetres, 0 = no reading (--depth-encoding 16UC1)
  camera/camera_info             CameraInfo: K, D (zeros), R, P
  camera/pose                    TransformStamped world -> camera_optical_frame
  basic_camera/...               the same four from the 80 x 60 basic camera
  clock                          Clock, once a capture
  sim/ground_truth               GroundTruth: every box (pose, size, what it stands on, how
                                 much of its top the camera sees), every object, the table's
                                 plane, the camera's pose
  tf_static                      TFMessage world -> camera_link -> camera_optical_frame, latched

Every message of one capture carries the same stamp: the simulated time of the capture. Runs in
real time by default, dropping a picture when the way out to the router stays full (newest
wins); as fast as it can with --fast, where every picture waits for room and none is dropped;
and stops after --frames captures if given.
--write-scene FILE.toml writes the world it would simulate as a scene file and exits.
Settings (flag > environment variable > config/onebox.toml > default) are listed below.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import numpy.typing as npt
import zenoh

from onebox import bus, pictures, settings
from onebox.errors import SceneError, SettingError
from onebox.settings import SCENE_DIR
from onebox.world import spec
from onebox.world.noise import PRESETS, DepthNoise
from onebox.world.random_scene import random_scene
from onebox.world.render import SceneRenderer
from onebox.world.scene import (
    OPTICAL_FRAME,
    WORLD_FRAME,
    CameraSpec,
    SceneSettings,
    build_model,
    camera_info,
    cameras,
    ground_truth,
    optical_pose,
    seed_scene,
    static_transforms,
)
from onebox.world.spec import SceneDesc, place, visible_top_pixels, with_lens
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


LENS = {"width": (320, int), "height": (240, int), "hfov_deg": (60.0, float)}
"""The lens and picture settings, which override a scene's: name -> (seed default, type)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)
    camera = parser.add_argument_group("camera (the seed's launch arguments)")
    for name, help_text in (
        ("width", "pixels across"),
        ("height", "pixels down"),
        ("hfov_deg", "how wide the camera sees, degrees"),
    ):
        fallback, kind = LENS[name]
        # No default here: a flag or the environment variable overrides the scene's camera;
        # without either, the scene's value stands (config/onebox.toml's for the seed's world).
        camera.add_argument(
            f"--{name.replace('_', '-')}",
            dest=name,
            type=kind,
            default=None,
            metavar=name.upper(),
            help=f"{help_text} (default: the scene's, else "
            f"{settings.default(name, fallback, kind)!r}; "
            f"environment {settings.env_variable(name)})",
        )
    settings.add(camera, "mount_height", 0.40, "the seed's world: the camera's height, metres")
    settings.add(camera, "rate_hz", 5.0, "captures a second of simulated time")
    settings.add(
        camera,
        "depth_encoding",
        "32FC1",
        "32FC1 (metres, NaN = no reading) or 16UC1 (millimetres, 0 = no reading)",
    )
    world = parser.add_argument_group("world")
    settings.add(world, "scene", "", "a scene file (scene/pallet.toml); empty: the seed's world")
    world.add_argument(
        "--random-scene",
        type=int,
        metavar="SEED",
        help="a random world drawn from SEED (the same seed always gives the same world)",
    )
    world.add_argument("--boxes", type=int, default=6, metavar="N", help="random scene: boxes (6)")
    world.add_argument(
        "--objects", type=int, default=3, metavar="N", help="random scene: other objects (3)"
    )
    world.add_argument(
        "--write-scene",
        type=Path,
        metavar="FILE",
        help="write the world as a scene file (TOML) and exit",
    )
    settings.add(
        world,
        "noise",
        "",
        f"depth noise model, overriding the scene's: {', '.join(PRESETS)}",
    )
    seed = parser.add_argument_group("the seed's world (without --scene or --random-scene)")
    settings.add(seed, "box_x", 0.065, "the box's middle, metres along world x")
    settings.add(seed, "box_y", 0.040, "the box's middle, metres along world y")
    settings.add(seed, "box_size", 0.06, "the box's edge, metres")
    settings.add(seed, "box_yaw_deg", 0.0, "the box's turn about the vertical, degrees")
    seed.add_argument(
        "--no-box", dest="box", action="store_false", help="a scene with nothing on the table"
    )
    run = parser.add_argument_group("run")
    settings.add(run, "gui", False, "also open MuJoCo's own window (needs a display)")
    run.add_argument("--frames", type=int, metavar="N", help="stop after N captures")
    run.add_argument(
        "--fast",
        action="store_true",
        help="as fast as it can instead of in real time, dropping no picture",
    )


@dataclass(frozen=True)
class SimSettings:
    """What the sim runs: the world, how often, and how it writes depth."""

    scene: SceneDesc
    source: str
    rate_hz: float
    depth_encoding: str
    frames: int | None
    fast: bool
    gui: bool
    write_scene: Path | None


def _lens_override(args: argparse.Namespace, name: str) -> Any:
    """The flag, else the environment variable, else None (the scene's value stands)."""
    flag = getattr(args, name)
    if flag is not None:
        return flag
    fallback, kind = LENS[name]
    if settings.env_variable(name) in os.environ:
        return settings.default(name, fallback, kind)
    return None


def scene_path(text: str) -> Path:
    """A scene file as given, else by name in scene/ (``pallet`` or ``pallet.toml``)."""
    path = Path(text)
    if path.exists():
        return path
    for candidate in (SCENE_DIR / path.name, SCENE_DIR / f"{path.name}.toml"):
        if candidate.exists():
            return candidate
    raise SceneError(f"no scene file {text}: give a path, or a name in {SCENE_DIR}")


def sim_settings(args: argparse.Namespace) -> SimSettings:
    """The world and the run, from the parsed flags (and the settings behind them)."""
    if args.rate_hz <= 0:
        raise SettingError(f"rate_hz {args.rate_hz}: must be above 0")
    if args.depth_encoding not in {"32FC1", "16UC1"}:
        raise SettingError(f"depth_encoding {args.depth_encoding!r}: use 32FC1 or 16UC1")
    lens = {name: _lens_override(args, name) for name in LENS}
    # The seed's world and random worlds take the settings' lens (config/onebox.toml's).
    seed_lens = {
        name: lens[name] if lens[name] is not None else settings.default(name, *LENS[name])
        for name in LENS
    }
    if args.random_scene is not None:
        if args.boxes < 0 or args.objects < 0:
            raise SettingError("--boxes and --objects: must not be negative")
        scene = random_scene(
            args.random_scene,
            boxes=args.boxes,
            objects=args.objects,
            width=int(seed_lens["width"]),
            height=int(seed_lens["height"]),
            hfov_deg=float(seed_lens["hfov_deg"]),
        )
        source = f"random scene {args.random_scene}"
    elif args.scene:
        path = scene_path(args.scene)
        scene = with_lens(spec.load(path), **lens)
        source = str(path)
    else:
        scene = seed_scene(
            SceneSettings(
                mount_height=args.mount_height,
                box=args.box,
                box_x=args.box_x,
                box_y=args.box_y,
                box_size=args.box_size,
                box_yaw_deg=args.box_yaw_deg,
                **seed_lens,
            )
        )
        source = "the seed's world"
    if args.noise:
        if args.noise not in PRESETS:
            raise SettingError(f"noise {args.noise!r}: use one of {', '.join(PRESETS)}")
        noise = dataclasses.replace(PRESETS[args.noise], seed=scene.noise.seed)
        scene = dataclasses.replace(scene, noise=noise)
    spec.check(scene, source)
    return SimSettings(
        scene=scene,
        source=source,
        rate_hz=args.rate_hz,
        depth_encoding=args.depth_encoding,
        frames=args.frames,
        fast=args.fast,
        gui=args.gui,
        write_scene=args.write_scene,
    )


@dataclass
class CameraPublishers:
    """The four publishers of one camera, its lens, and the noise its depth picture gets."""

    spec: CameraSpec
    colour: bus.Publisher[Image]
    depth: bus.Publisher[Image]
    info: bus.Publisher[CameraInfo]
    pose: bus.Publisher[TransformStamped]
    noise: DepthNoise


def _open_gui(model: mujoco.MjModel, data: mujoco.MjData, wanted: bool) -> Any:
    """MuJoCo's own viewer window, or None: when not asked for, or when there is no display."""
    if not wanted:
        return None
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        log.warning("gui: no display here ($DISPLAY is not set); running headless without it")
        return None
    import mujoco.viewer

    return mujoco.viewer.launch_passive(model, data)


def describe(run: SimSettings) -> str:
    """One line about the world: where it came from, the camera, what stands on the table."""
    scene = run.scene
    cam = scene.camera
    fx = cam.width / 2 / math.tan(math.radians(cam.hfov_deg) / 2)
    return (
        f"{run.source}: {cam.width} x {cam.height}, hfov {cam.hfov_deg:.1f} deg (fx {fx:.3f}), "
        f"camera {cam.z - scene.table.z:.2f} m over the table, tilted {cam.tilt_deg:g} deg; "
        f"{len(scene.boxes)} box{'es' if len(scene.boxes) != 1 else ''}, "
        f"{len(scene.objects)} other object{'s' if len(scene.objects) != 1 else ''}; "
        f"noise {scene.noise.model}; {run.rate_hz:.1f} Hz"
        + (", as fast as possible" if run.fast else "")
    )


def main(args: argparse.Namespace) -> int:
    """Simulate, render and publish until stopped or --frames captures were made."""
    run = sim_settings(args)
    if run.write_scene is not None:
        run.write_scene.write_text(spec.dumps(run.scene))
        log.info("wrote %s (%s)", run.write_scene, run.source)
        return 0
    scene = run.scene
    model = build_model(scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    specs = cameras(scene)
    period_s = 1.0 / run.rate_hz
    steps_per_capture = max(1, round(period_s / model.opt.timestep))

    # In real time a late picture is worth nothing and is dropped when the way out stays full
    # (newest wins). As fast as it can, the sim has no time to keep: every picture waits for
    # room, as a replay's do, so a busy machine slows the run rather than losing captures.
    pictures_qos = zenoh.CongestionControl.BLOCK if run.fast else None
    with bus.open_bus(args) as b, SceneRenderer(model, specs) as renderer:
        pubs = [
            CameraPublishers(
                spec=cam,
                colour=b.publisher(f"{cam.name}/image_raw", Image, congestion_control=pictures_qos),
                depth=b.publisher(
                    f"{cam.name}/depth/image_raw", Image, congestion_control=pictures_qos
                ),
                info=b.publisher(f"{cam.name}/camera_info", CameraInfo),
                pose=b.publisher(f"{cam.name}/pose", TransformStamped),
                noise=DepthNoise(scene.noise, (cam.height, cam.width), stream=i),
            )
            for i, cam in enumerate(specs)
        ]
        clock = b.publisher("clock", Clock)
        truth = b.publisher("sim/ground_truth", GroundTruth)
        tf_static = b.publisher("tf_static", TFMessage, latched=True)
        tf_static.publish(TFMessage(transforms=static_transforms(model)))
        log.info("%s", describe(run))
        # A new session learns of the subscribers already there a moment after it opens; wait
        # for that (at most a second) so that the first capture reaches them too.
        if not pubs[0].depth.wait_for_subscribers(timeout_s=1.0):
            log.info("no subscriber yet; publishing anyway")
        gui = _open_gui(model, data, run.gui)
        placed = place(scene)
        top_pixels: list[int] | None = None
        start = time.monotonic()
        count = 0
        try:
            while run.frames is None or count < run.frames:
                stamp_ns = round(data.time * 1e9)
                clean = publish_capture(model, data, renderer, pubs, stamp_ns, run.depth_encoding)
                clock.publish(Clock(clock_ns=stamp_ns))
                if top_pixels is None:
                    # Nothing in the world moves, so the first noise-free picture says once
                    # how much of each top the camera sees.
                    top_pixels = visible_top_pixels(scene.camera, placed, clean)
                truth.publish(ground_truth(model, data, scene, top_pixels, stamp_ns))
                count += 1
                if gui is not None:
                    if not gui.is_running():
                        break
                    gui.sync()
                mujoco.mj_step(model, data, nstep=steps_per_capture)
                if not run.fast:
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
    depth_encoding: str = "32FC1",
) -> npt.NDArray[np.float32]:
    """Render and publish every camera, all stamped ``stamp_ns``; return the main camera's
    noise-free depth picture."""
    clean = None
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
        if clean is None:
            clean = capture.depth_m
        colour = pictures.rgb8_image(cam.noise.colour(capture.rgb), header)
        depth = pictures.depth_image(cam.noise.apply(capture.depth_m), header, depth_encoding)
        # The depth picture last: whoever pairs the two has the colour by the time the depth
        # picture, which it waits on, comes.
        cam.colour.publish(colour)
        cam.depth.publish(depth)
    assert clean is not None
    return clean
