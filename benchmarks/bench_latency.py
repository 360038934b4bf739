"""End-to-end latency: a depth picture published -> its detection received by an outside process.

    python benchmarks/bench_latency.py [--captures 300] [--rate-hz 30] [--source sim|bench]

Starts a private ``onebox router`` and a real ``onebox locator`` process, and subscribes from
this process to ``detections`` (and to the depth pictures). Captures are 320 x 240 at
``--rate-hz``:

- ``--source sim`` (the default): a real ``onebox sim --rate-hz 30`` publishes them. The clock
  starts when this process receives the depth picture, which reaches it through the router at
  the same moment it reaches the locator, so the sim's own hop to the router is not counted.
- ``--source bench``: this process publishes the same messages the sim would (camera info,
  then depth, with the same stamp) and the clock starts just before the depth picture's put:
  publisher to router to locator to router to subscriber, every hop counted.

Prints p50, p90, p99 and the worst in milliseconds, and how many captures had no detection.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox import bus
from onebox.recording import stamp_ns as stamp_of
from onebox.testing.processes import Processes, bus_args, free_port
from onebox.testing.synthetic import Scene, camera_info, depth_image, depth_picture, tf_static
from schemas import CameraInfo, Detection3DArray, Image, TFMessage, codec


class Clock:
    """Start and end times by stamp, from the Zenoh callbacks of this process."""

    def __init__(self) -> None:
        self.start_ns: dict[int, int] = {}
        self.end_ns: dict[int, int] = {}
        self.lock = threading.Lock()
        self.decoder = codec(Detection3DArray)

    def on_depth(self, key: str, payload: bytes) -> None:
        now = time.perf_counter_ns()
        stamp = stamp_of(payload)
        if stamp is not None:
            with self.lock:
                self.start_ns.setdefault(stamp, now)

    def on_detections(self, key: str, payload: bytes) -> None:
        now = time.perf_counter_ns()
        stamp = self.decoder.decode(payload).header.stamp_ns
        with self.lock:
            self.end_ns.setdefault(stamp, now)

    def latencies_ms(self) -> list[float]:
        with self.lock:
            return [
                (self.end_ns[s] - t) / 1e6 for s, t in self.start_ns.items() if s in self.end_ns
            ]


def wait_until(condition, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def run_bench_source(b: bus.Bus, clock: Clock, captures: int, rate_hz: float) -> None:
    """Publish captures from here, as the sim would, timing from just before the depth put."""
    scene = Scene()
    picture = depth_picture(scene)
    depth_pub = b.publisher("camera/depth/image_raw", Image)
    info_pub = b.publisher("camera/camera_info", CameraInfo)
    tf_pub = b.publisher("tf_static", TFMessage, latched=True)
    tf_pub.publish(tf_static())
    codec_image = codec(Image)
    period_s = 1.0 / rate_hz
    # Warm up: until the locator answers, so its subscriptions are in place.
    stamp = 0
    while True:
        stamp += 1
        info_pub.publish(camera_info(scene, stamp))
        depth_pub.publish(depth_image(picture, stamp))
        if wait_until(lambda: bool(clock.end_ns), 0.5):
            break
    with clock.lock:
        clock.end_ns.clear()
    start = time.monotonic()
    for n in range(captures):
        stamp_ns = (n + 1) * 1_000_000_000
        info_pub.publish(camera_info(scene, stamp_ns))
        payload = codec_image.encode(depth_image(picture, stamp_ns))
        with clock.lock:
            clock.start_ns[stamp_ns] = time.perf_counter_ns()
        depth_pub.publish_bytes(payload)
        delay_s = start + (n + 1) * period_s - time.monotonic()
        if delay_s > 0:
            time.sleep(delay_s)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--captures", type=int, default=300)
    parser.add_argument("--rate-hz", type=float, default=30.0)
    parser.add_argument("--source", choices=("sim", "bench"), default="sim")
    args = parser.parse_args()

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs = Processes(endpoint)
    clock = Clock()
    try:
        procs.start("router", "--listen", endpoint, connect=False)
        time.sleep(1.0)  # the router binds its port; every other process retries until it does
        with bus.open_bus(bus_args(endpoint)) as b:
            b.subscribe_raw("detections", clock.on_detections)
            if args.source == "sim":
                b.subscribe_raw("camera/depth/image_raw", clock.on_depth)
            locator = procs.start("locator", "--log-interval-s", "5")
            if args.source == "sim":
                time.sleep(2.0)  # the locator subscribes before the first capture
                sim = procs.start(
                    "sim", "--rate-hz", str(args.rate_hz), "--frames", str(args.captures)
                )
                print(f"sim publishing {args.captures} captures at {args.rate_hz:g} Hz ...")
                sim.wait(timeout=args.captures / args.rate_hz + 60)
                wait_until(lambda: len(clock.end_ns) >= len(clock.start_ns), 2.0)
            else:
                print(f"publishing {args.captures} captures at {args.rate_hz:g} Hz ...")
                run_bench_source(b, clock, args.captures, args.rate_hz)
                wait_until(lambda: len(clock.end_ns) >= args.captures, 2.0)
            latencies = sorted(clock.latencies_ms())
            sent = len(clock.start_ns)
        log_tail = procs.stop(locator).strip().splitlines()[-3:]
    finally:
        procs.stop_all()
    if not latencies:
        print("no detection arrived; locator said:\n" + "\n".join(log_tail))
        return 1
    q = statistics.quantiles(latencies, n=100)
    print(
        f"{len(latencies)} of {sent} captures detected ({args.source} source, 320 x 240, "
        f"{args.rate_hz:g} Hz): p50 {q[49]:.2f} ms, p90 {q[89]:.2f} ms, p99 {q[98]:.2f} ms, "
        f"worst {latencies[-1]:.2f} ms"
    )
    print("locator: " + " | ".join(log_tail))
    return 0


if __name__ == "__main__":
    sys.exit(main())
