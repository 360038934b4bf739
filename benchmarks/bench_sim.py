"""Captures per second of the sim's camera, as fast as possible, and where the time goes.

    python benchmarks/bench_sim.py [--captures N] [--rate-hz R] [--no-scenes]

For 320 x 240 and 1280 x 720 it times, per capture of the main camera: render (drawing the
scene), read back (both buffers in one call, flipped, depth to metres), encode (two Image
messages to msgpack) and publish: the two Zenoh puts, depth then colour as the sim sends them,
from a client of a private router (config/client.json5) to a subscriber in this process, the
mean and the 95th percentile a capture. "arrives" is the depth picture's put to its callback
here (p50): a put that returns sooner must not deliver later. With --rate-hz the captures come
one a period, as the sim makes them in real time, instead of back to back. Side by side, in
the same run, MuJoCo's stock ``Renderer`` doing colour and then depth on the same scene, and
again with the light casting shadows through MuJoCo's default shadow map.

Then (unless --no-scenes), for the seed's world and scene/pallet.toml (640 x 480) and
scene/clutter.toml (1280 x 720): captures/s without noise and with the d435 and azure_kinect
presets, and the noise's share of a capture (the promise: under 20 % at 640 x 480).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco loads

import mujoco
import numpy as np
import zenoh

from onebox import bus, pictures
from onebox.recording import stamp_ns
from onebox.testing.processes import bus_args, free_port
from onebox.world import scene, spec
from onebox.world.noise import PRESETS, DepthNoise, NoiseSpec
from onebox.world.render import SceneRenderer
from schemas import Header, Image, codec

WARM_UP = 10
"""Captures made before the timing starts: the first warm up caches and the connection."""


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


def ours(
    settings: scene.SceneSettings | spec.SceneDesc,
    captures: int,
    endpoint: str,
    noise: NoiseSpec | None = None,
    rate_hz: float = 0.0,
) -> dict[str, float]:
    """Milliseconds per stage and captures/s of the sim's own pipeline, as fast as possible or,
    with ``rate_hz``, one capture a period as the sim runs in real time."""
    model = scene.build_model(settings)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cam = scene.cameras(settings)[0]
    depth_noise = DepthNoise(noise or NoiseSpec(), (cam.height, cam.width))
    arrived: dict[int, float] = {}
    starts: dict[int, float] = {}
    publish_s: list[float] = []
    counted = threading.Event()
    lock = threading.Lock()
    totals = dict.fromkeys(("render", "read back", "noise", "encode", "publish"), 0.0)

    def on_sample(sample: zenoh.Sample) -> None:
        # The raw session's callback, so that no copy of the picture is timed; the depth's
        # stamp is the capture's number.
        now = time.perf_counter()
        key = str(sample.key_expr)
        with lock:
            if key.endswith("depth/image_raw"):
                stamp = stamp_ns(sample.payload.to_bytes())
                if stamp is not None and stamp >= WARM_UP:
                    arrived[stamp] = now
                    if len(arrived) == captures:
                        counted.set()

    with (
        SceneRenderer(model, [cam]) as renderer,
        bus.open_bus(bus_args(endpoint)) as pub_bus,
        bus.open_bus(bus_args(endpoint)) as sub_bus,
    ):
        subscriber = sub_bus.session.declare_subscriber(sub_bus.key("bench/**"), on_sample)
        colour_pub = pub_bus.publisher("bench/image_raw", Image)
        depth_pub = pub_bus.publisher("bench/depth/image_raw", Image)
        depth_pub.wait_for_subscribers(timeout_s=5.0)
        encoder = codec(Image)
        for i in range(captures + WARM_UP):
            if i == WARM_UP:  # the first few warm up caches and the connection
                totals = dict.fromkeys(totals, 0.0)
                wall = time.perf_counter()
            t0 = time.perf_counter()
            renderer.draw(data, cam.name)
            t1 = time.perf_counter()
            capture = renderer.read(cam.name)
            t2 = time.perf_counter()
            depth_m = depth_noise.apply(capture.depth_m)
            t_noise = time.perf_counter()
            header = Header(stamp_ns=i)
            colour = pictures.rgb8_image(capture.rgb, header)
            depth = pictures.depth_image(depth_m, header)
            colour_bytes, depth_bytes = encoder.encode(colour), encoder.encode(depth)
            t3 = time.perf_counter()
            depth_pub.publish_bytes(depth_bytes)
            colour_pub.publish_bytes(colour_bytes)
            t4 = time.perf_counter()
            stages = (t1 - t0, t2 - t1, t_noise - t2, t3 - t_noise, t4 - t3)
            for stage, dt in zip(totals, stages, strict=True):
                totals[stage] += dt
            if i >= WARM_UP:
                starts[i] = t3
                publish_s.append(t4 - t3)
            if rate_hz:
                time.sleep(max(0.0, t0 + 1 / rate_hz - time.perf_counter()))
        rate = captures / (time.perf_counter() - wall)
        # A subscriber under load may drop some: wait until all came or none came for 2 s; the
        # count below says how many.
        seen = -1
        while not counted.wait(2.0) and seen != len(arrived):
            seen = len(arrived)
        subscriber.undeclare()
    with lock:
        delays = [arrived[i] - t for i, t in starts.items() if i in arrived]
        received = len(delays)
    out = {stage: 1000 * t / captures for stage, t in totals.items()}
    out["publish p95"] = 1000 * float(np.percentile(publish_s, 95))
    out["arrives"] = 1000 * float(np.median(delays)) if delays else math.nan
    out["captures/s"] = rate
    out["received"] = received / captures
    return out


def scenes_table(captures: int, endpoint: str) -> None:
    """Captures/s of each committed scene, without noise and with each camera's preset."""
    root = Path(__file__).resolve().parent.parent / "scene"
    print(
        f"{'scene':>8} {'size':>11} {'none':>7} {'d435':>7} {'share':>6}"
        f" {'azure_kinect':>13} {'share':>6}   (captures/s; share = noise's part of a capture)"
    )
    for name in ("one_box", "pallet", "clutter"):
        desc = spec.load(root / f"{name}.toml")
        cam = desc.camera
        n = captures if cam.width <= 640 else max(30, captures // 5)
        rates, shares = {}, {}
        for model in ("none", "d435", "azure_kinect"):
            r = ours(desc, n, endpoint, PRESETS[model])
            total = sum(r[s] for s in ("render", "read back", "noise", "encode", "publish"))
            rates[model], shares[model] = r["captures/s"], r["noise"] / total
        print(
            f"{name:>8} {cam.width:>4} x {cam.height:<4} {rates['none']:>7.0f}"
            f" {rates['d435']:>7.0f} {100 * shares['d435']:>5.1f}%"
            f" {rates['azure_kinect']:>13.0f} {100 * shares['azure_kinect']:>5.1f}%"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--captures", type=int, default=300)
    parser.add_argument(
        "--rate-hz",
        type=float,
        default=0.0,
        help="the two sizes at this many captures a second, as the sim runs in real time "
        "(default 0: as fast as possible); captures/s then says whether it kept up",
    )
    parser.add_argument(
        "--no-scenes", action="store_true", help="only the two picture sizes, not the scene files"
    )
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
            f" {'p95':>6} {'arrives':>8} {'captures/s':>11} {'recv':>5} {'stock':>7}"
            f" {'ratio':>6} {'stock+shadow':>13} {'ratio':>6}"
        )
        for width, height in ((320, 240), (1280, 720)):
            settings = scene.SceneSettings(width=width, height=height)
            n = args.captures if width <= 640 else max(30, args.captures // 5)
            r = ours(settings, n, endpoint, rate_hz=args.rate_hz)
            plain = stock(settings, max(20, n // 3), shadows=False)
            shadow = stock(settings, max(10, n // 10), shadows=True)
            print(
                f"{width:>4} x {height:<4} {r['render']:>7.2f}m {r['read back']:>8.2f}m"
                f" {r['encode']:>6.2f}m {r['publish']:>7.2f}m {r['publish p95']:>5.2f}m"
                f" {r['arrives']:>7.2f}m {r['captures/s']:>11.0f} {100 * r['received']:>4.0f}%"
                f" {plain:>7.0f} {r['captures/s'] / plain:>5.1f}x {shadow:>13.0f}"
                f" {r['captures/s'] / shadow:>5.1f}x"
            )
            assert np.isfinite(r["captures/s"])
        print(
            "m = milliseconds per capture of the main camera (colour + depth); publish = its two"
            " puts, mean and p95; arrives = the depth's put to the subscriber's callback, p50;"
            " recv = share of the depth pictures that arrived;"
            " stock = mujoco.Renderer, colour then depth"
        )
        if args.no_scenes:
            return
        print()
        scenes_table(args.captures, endpoint)
    finally:
        router.terminate()
        router.wait()


if __name__ == "__main__":
    main()
