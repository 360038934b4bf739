"""Captures per second of the sim's camera, as fast as possible, and where the time goes.

    python benchmarks/bench_sim.py [--captures N]

For 320 x 240 and 1280 x 720 it times, per capture of the main camera: render (drawing the
scene), read back (both buffers in one call, flipped, depth to metres), encode (two Image
messages to msgpack) and publish (two Zenoh puts to a subscriber on a private router). Side by
side, in the same run, MuJoCo's stock ``Renderer`` doing colour and then depth on the same
scene, and again with the light casting shadows through MuJoCo's default shadow map.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco loads

import mujoco
import numpy as np

from onebox import bus, pictures
from onebox.testing.processes import Inbox, bus_args, free_port
from onebox.world import scene
from onebox.world.render import SceneRenderer
from schemas import Header, Image, codec


def stock(settings: scene.SceneSettings, captures: int, shadows: bool) -> float:
    """Captures/s of mujoco.Renderer: a colour render, then a depth render."""
    model = scene.build_model(settings)
    if shadows:
        model.light_castshadow[:] = 1
        model.vis.quality.shadowsize = 4096  # MuJoCo's default
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with mujoco.Renderer(model, settings.height, settings.width) as r:
        start = time.perf_counter()
        for _ in range(captures):
            r.disable_depth_rendering()
            r.update_scene(data, "camera")
            r.render()
            r.enable_depth_rendering()
            r.update_scene(data, "camera")
            r.render()
        return captures / (time.perf_counter() - start)


def ours(settings: scene.SceneSettings, captures: int, endpoint: str) -> dict[str, float]:
    """Milliseconds per stage and captures/s of the sim's own pipeline."""
    model = scene.build_model(settings)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cam = scene.cameras(settings)[0]
    inbox = Inbox()
    totals = dict.fromkeys(("render", "read back", "encode", "publish"), 0.0)
    with (
        SceneRenderer(model, [cam]) as renderer,
        bus.open_bus(bus_args(endpoint)) as pub_bus,
        bus.open_bus(bus_args(endpoint)) as sub_bus,
    ):
        sub_bus.subscribe_raw("bench/**", lambda k, p: inbox(k, b""))
        colour_pub = pub_bus.publisher("bench/image_raw", Image)
        depth_pub = pub_bus.publisher("bench/depth/image_raw", Image)
        encoder = codec(Image)
        for i in range(captures + 10):
            if i == 10:  # the first few warm up caches and the connection
                totals = dict.fromkeys(totals, 0.0)
                inbox.items.clear()
                wall = time.perf_counter()
            t0 = time.perf_counter()
            renderer.draw(data, cam.name)
            t1 = time.perf_counter()
            capture = renderer.read(cam.name)
            t2 = time.perf_counter()
            header = Header(stamp_ns=i)
            colour = pictures.rgb8_image(capture.rgb, header)
            depth = pictures.depth_image(capture.depth_m, header)
            colour_bytes, depth_bytes = encoder.encode(colour), encoder.encode(depth)
            t3 = time.perf_counter()
            colour_pub.publish_bytes(colour_bytes)
            depth_pub.publish_bytes(depth_bytes)
            t4 = time.perf_counter()
            for stage, dt in zip(totals, (t1 - t0, t2 - t1, t3 - t2, t4 - t3), strict=True):
                totals[stage] += dt
        rate = captures / (time.perf_counter() - wall)
        inbox.wait(lambda items: len(items) >= 2 * captures * 0.95, 30)
        received = len(inbox.items) / 2
    out = {stage: 1000 * t / captures for stage, t in totals.items()}
    out["captures/s"] = rate
    out["received"] = received
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--captures", type=int, default=300)
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = subprocess.Popen(
        [sys.executable, "-m", "services.cli", "router", "--listen", endpoint],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(1.0)  # the router's port opens within a second; no message to wait on
        print(
            f"{'size':>10} {'render':>8} {'readback':>9} {'encode':>7} {'publish':>8}"
            f" {'captures/s':>11} {'stock':>7} {'ratio':>6} {'stock+shadow':>13} {'ratio':>6}"
        )
        for width, height in ((320, 240), (1280, 720)):
            settings = scene.SceneSettings(width=width, height=height)
            n = args.captures if width <= 640 else max(30, args.captures // 5)
            r = ours(settings, n, endpoint)
            plain = stock(settings, max(20, n // 3), shadows=False)
            shadow = stock(settings, max(10, n // 10), shadows=True)
            print(
                f"{width:>4} x {height:<4} {r['render']:>7.2f}m {r['read back']:>8.2f}m"
                f" {r['encode']:>6.2f}m {r['publish']:>7.2f}m {r['captures/s']:>11.0f}"
                f" {plain:>7.0f} {r['captures/s'] / plain:>5.1f}x {shadow:>13.0f}"
                f" {r['captures/s'] / shadow:>5.1f}x"
            )
            assert np.isfinite(r["captures/s"])
        print(
            "m = milliseconds per capture of the main camera (colour + depth);"
            " stock = mujoco.Renderer, colour then depth"
        )
    finally:
        router.terminate()
        router.wait()


if __name__ == "__main__":
    main()
