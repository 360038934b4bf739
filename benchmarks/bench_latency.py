"""End-to-end latency: a depth picture published -> its detection received by an outside process.

    python benchmarks/bench_latency.py [--captures 300] [--rate-hz 30] [--source sim|bench]
        [--capture NAME [--data DIR]] [--against-seed]

Starts a private ``onebox router`` and a real ``onebox locator`` process, and subscribes from
this process to ``detections`` (and to the depth pictures). Captures come at ``--rate-hz``:

- ``--source sim`` (the default): a real ``onebox sim --rate-hz 30`` publishes them, 320 x 240.
  The clock starts when this process receives the depth picture, which reaches it through the
  router at the same moment it reaches the locator, so the sim's own hop to the router is not
  counted.
- ``--source bench``: this process publishes the same messages the sim would for the seed's
  world, 320 x 240 (tf_static once, then camera info and depth with the same stamp), and the
  clock starts just before the depth picture's put: publisher to router to locator to router
  to subscriber, every hop counted.
- ``--capture NAME``: this process publishes one real RGB-D capture of ``--data`` (a folder
  of real captures, :mod:`onebox.testing.realdata`; by default ``../shared/realdata`` beside
  the repository if it is there, else the committed ``tests/data/realdata``) as a real
  camera's driver would, with a fresh stamp each time: ``camera/camera_info`` (K as the
  folder gives it), ``camera/image_raw`` (rgb8) and ``camera/depth/image_raw`` (16UC1
  millimetres, 0 = no reading), in that order, and no tf: the locator reports in the
  camera's frame. The clock starts just before the depth picture's put, as with ``bench``.

``--against-seed`` runs the same captures twice in one run, the same messages at the same
rate: first to a locator started as usual (the box finder), then to one started with
``--method seed``, and prints both rows and the ratio of their p50s (finder over seed). The
seed's method measures over a table in a world frame, so with ``--capture`` both locators
are also given a tf_static placing the camera over the capture's support plane (world z = 0
on it, from captures.json); ``--capture`` alone publishes no tf.

Prints a progress line while publishing; then, for each locator, p50, p90, p99 and the worst
in milliseconds, and how many captures had no detection.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import msgspec
import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox import bus, pictures
from onebox.recording import stamp_ns as stamp_of
from onebox.testing.processes import Processes, bus_args, free_port, wait_for_output
from onebox.testing.realdata import (
    COMMITTED,
    SHARED,
    RealCapture,
    RealDataError,
    default_folder,
    read_capture,
)
from onebox.testing.synthetic import (
    OPTICAL,
    Scene,
    camera_info,
    depth_image,
    depth_picture,
    header,
    tf_static,
)
from schemas import (
    CameraInfo,
    Detection3DArray,
    Image,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    codec,
)

WARM_UP_S = 60.0
"""How long the locator may take to answer its first capture (starting, compiling)."""
READY_TIMEOUT_S = 180.0
"""How long the locator's finder may take to compile its kernels into an empty cache."""


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


class Relay:
    """Hands this process's subscriptions to the clock of the locator being measured."""

    def __init__(self) -> None:
        self.clock = Clock()

    def on_depth(self, key: str, payload: bytes) -> None:
        self.clock.on_depth(key, payload)

    def on_detections(self, key: str, payload: bytes) -> None:
        self.clock.on_detections(key, payload)


class Progress:
    """One line saying how far the publishing has got: rewritten in place on a terminal,
    printed at every quarter otherwise."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.tty = sys.stdout.isatty()
        self.next_s = 0.0
        self.quarter = 0

    def show(self, published: int, clock: Clock) -> None:
        with clock.lock:
            detected = len(clock.end_ns)
        line = f"  {published} of {self.total} published, {detected} detected"
        if self.tty:
            if time.monotonic() >= self.next_s or published == self.total:
                self.next_s = time.monotonic() + 0.5
                print("\r" + line, end="", flush=True)
        elif published * 4 >= (self.quarter + 1) * self.total:
            self.quarter = published * 4 // self.total
            print(line, flush=True)

    def done(self) -> None:
        if self.tty:
            print()


@dataclass(frozen=True)
class Feed:
    """What this process publishes for one capture, as a camera's driver would."""

    label: str
    """What the pictures are, for the result line."""
    info: Callable[[int], CameraInfo]
    depth: Callable[[int], Image]
    colour: Callable[[int], Image] | None = None
    tf: TFMessage | None = None


def seed_world_feed() -> Feed:
    """The seed's world, as the sim publishes it: tf_static, camera info and 32FC1 depth."""
    scene = Scene()
    picture = depth_picture(scene)
    return Feed(
        label=f"bench source, {scene.width} x {scene.height}",
        info=lambda stamp_ns: camera_info(scene, stamp_ns),
        depth=lambda stamp_ns: depth_image(picture, stamp_ns),
        tf=tf_static(),
    )


def support_tf(capture: RealCapture) -> TFMessage:
    """world -> the camera's optical frame with world z = 0 on the capture's support plane and
    z up along its normal; world x is the camera's x laid onto the plane."""
    up = capture.support.normal / np.linalg.norm(capture.support.normal)
    x = np.array([1.0, 0.0, 0.0]) - up[0] * up
    x /= np.linalg.norm(x)
    world_from_camera = np.stack([x, np.cross(up, x), up])  # rows: world axes in camera terms
    q = Rotation.from_matrix(world_from_camera).as_quat()
    return TFMessage(
        transforms=[
            TransformStamped(
                header=header(0, "world"),
                child_frame_id=OPTICAL,
                transform=Transform(
                    translation=Vector3(z=float(capture.support.offset_m)),
                    rotation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
                ),
            )
        ]
    )


def capture_feed(capture: RealCapture, placed: bool) -> Feed:
    """One real capture as its camera's driver publishes it: camera info, rgb8 colour and
    16UC1 millimetres; with ``placed``, a tf_static over its support plane too."""
    width, height = capture.size
    lens = capture.lens
    k = [lens.fx, 0.0, lens.cx, 0.0, lens.fy, lens.cy, 0.0, 0.0, 1.0]
    depth = pictures.depth_image(capture.depth_m, header(0), "16UC1")
    colour = pictures.rgb8_image(capture.colour, header(0))

    def info(stamp_ns: int) -> CameraInfo:
        return CameraInfo(
            header=header(stamp_ns),
            width=width,
            height=height,
            d=[0.0] * 5,
            k=k,
            r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p=[lens.fx, 0.0, lens.cx, 0.0, 0.0, lens.fy, lens.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        )

    def restamp(image: Image) -> Callable[[int], Image]:
        return lambda stamp_ns: msgspec.structs.replace(image, header=header(stamp_ns))

    return Feed(
        label=f"{capture.name}, {width} x {height}, 16UC1 + rgb8",
        info=info,
        depth=restamp(depth),
        colour=restamp(colour),
        tf=support_tf(capture) if placed else None,
    )


def wait_until(condition: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


class Publishers:
    """This process's publishers of a feed's keys, made once for every locator measured."""

    def __init__(self, b: bus.Bus, feed: Feed) -> None:
        self.feed = feed
        self.info = b.publisher("camera/camera_info", CameraInfo)
        self.depth = b.publisher("camera/depth/image_raw", Image)
        self.colour = b.publisher("camera/image_raw", Image) if feed.colour else None
        if feed.tf is not None:
            b.publisher("tf_static", TFMessage, latched=True).publish(feed.tf)
        self.codec_image = codec(Image)

    def before_depth(self, stamp_ns: int) -> bytes:
        """Publish what comes before the depth picture, and return the depth's payload."""
        self.info.publish(self.feed.info(stamp_ns))
        if self.colour is not None and self.feed.colour is not None:
            self.colour.publish(self.feed.colour(stamp_ns))
        return self.codec_image.encode(self.feed.depth(stamp_ns))


def run_bench_source(pubs: Publishers, clock: Clock, captures: int, rate_hz: float) -> None:
    """Publish captures from here, as a camera would, timing from just before the depth put."""
    period_s = 1.0 / rate_hz
    # Warm up: until the locator answers, so its subscriptions are in place.
    deadline = time.monotonic() + WARM_UP_S
    stamp = 0
    while True:
        stamp += 1
        pubs.depth.publish_bytes(pubs.before_depth(stamp))
        if wait_until(lambda: bool(clock.end_ns), 0.5):
            break
        if time.monotonic() > deadline:
            print(f"  no answer from the locator in {WARM_UP_S:.0f} s", flush=True)
            return
    with clock.lock:
        clock.end_ns.clear()
    progress = Progress(captures)
    start = time.monotonic()
    for n in range(captures):
        stamp_ns = (n + 1) * 1_000_000_000
        payload = pubs.before_depth(stamp_ns)
        with clock.lock:
            clock.start_ns[stamp_ns] = time.perf_counter_ns()
        pubs.depth.publish_bytes(payload)
        progress.show(n + 1, clock)
        delay_s = start + (n + 1) * period_s - time.monotonic()
        if delay_s > 0:
            time.sleep(delay_s)
    wait_until(lambda: len(clock.end_ns) >= captures, 2.0)
    progress.show(captures, clock)
    progress.done()


def run_sim_source(procs: Processes, clock: Clock, captures: int, rate_hz: float) -> None:
    """A real sim publishes; the clock starts when its depth picture reaches this process."""
    time.sleep(2.0)  # the locator subscribes before the first capture
    sim = procs.start("sim", "--rate-hz", str(rate_hz), "--frames", str(captures))
    progress = Progress(captures)
    deadline = time.monotonic() + captures / rate_hz + 60
    while sim.poll() is None and time.monotonic() < deadline:
        with clock.lock:
            published = len(clock.start_ns)
        progress.show(min(published, captures), clock)
        time.sleep(0.1)
    try:
        sim.wait(timeout=max(0.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        pass  # stopped with the rest at the end; the captures that came are counted
    wait_until(lambda: len(clock.end_ns) >= len(clock.start_ns), 2.0)
    progress.show(len(clock.start_ns), clock)
    progress.done()


@dataclass(frozen=True)
class Row:
    """One locator's figures."""

    method: str
    latencies_ms: list[float]
    sent: int
    log_tail: list[str]

    def p(self, percent: int) -> float:
        return statistics.quantiles(self.latencies_ms, n=100)[percent - 1]


def measure(
    procs: Processes,
    relay: Relay,
    pubs: Publishers | None,
    method: str,
    args: argparse.Namespace,
) -> Row:
    """Start a locator (``--method method``), feed it the captures, stop it: its figures."""
    clock = relay.clock = Clock()
    seed = ["--method", "seed"] if method == "seed" else []
    locator = procs.start("locator", "--log-interval-s", "5", *seed)
    name = f"{method}: " if args.against_seed else ""
    if method != "seed":
        # The finder compiles its kernels before its first picture (tens of seconds on a first
        # run, with an empty cache): captures sent before then would time nothing.
        print(f"{name}waiting for the locator's finder to be ready ...", flush=True)
        try:
            wait_for_output(locator, "finder ready", READY_TIMEOUT_S)
        except AssertionError as error:  # it ended, or never said it was ready
            return Row(method, [], 0, [*str(error).splitlines()[-3:], procs.stop(locator)])
    what = "sim publishing" if pubs is None else "publishing"
    print(f"{name}{what} {args.captures} captures at {args.rate_hz:g} Hz ...", flush=True)
    if pubs is None:
        run_sim_source(procs, clock, args.captures, args.rate_hz)
    else:
        run_bench_source(pubs, clock, args.captures, args.rate_hz)
    latencies = sorted(clock.latencies_ms())
    with clock.lock:
        sent = len(clock.start_ns)
    log_tail = procs.stop(locator).strip().splitlines()[-3:]
    return Row(method, latencies, sent, log_tail)


def print_row(row: Row, label: str, rate_hz: float, named: bool) -> bool:
    """The row's figures, or what the locator said when nothing came back; False then."""
    name = f"{row.method}: " if named else ""
    if len(row.latencies_ms) < 2:
        print(f"{name}no detection arrived; locator said:\n" + "\n".join(row.log_tail))
        return False
    print(
        f"{name}{len(row.latencies_ms)} of {row.sent} captures detected ({label}, "
        f"{rate_hz:g} Hz): p50 {row.p(50):.2f} ms, p90 {row.p(90):.2f} ms, "
        f"p99 {row.p(99):.2f} ms, worst {row.latencies_ms[-1]:.2f} ms"
    )
    print(f"{name}locator: " + " | ".join(row.log_tail))
    return True


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--captures", type=int, default=300, help="captures measured (300)")
    parser.add_argument("--rate-hz", type=float, default=30.0, help="captures a second (30)")
    parser.add_argument(
        "--source",
        choices=("sim", "bench"),
        help="who publishes the seed's world: a real sim (the default) or this process",
    )
    parser.add_argument(
        "--capture",
        metavar="NAME",
        help="publish this real capture of --data from this process instead (e.g. mosd-learn0)",
    )
    parser.add_argument(
        "--data",
        type=Path,
        metavar="DIR",
        help=f"the folder of real captures (default: {SHARED} if there, else {COMMITTED})",
    )
    parser.add_argument(
        "--against-seed",
        action="store_true",
        help="measure a second locator with --method seed on the same captures, and the ratio",
    )
    args = parser.parse_args()
    if args.captures < 2 or args.rate_hz <= 0:
        parser.error("--captures must be 2 or more and --rate-hz above 0")
    if args.capture is not None and args.source is not None:
        parser.error("--capture publishes from this process: leave out --source")
    if args.data is not None and args.capture is None:
        parser.error("--data is the folder of --capture: name a capture")
    return args


def main() -> int:
    args = parse_args()
    feed: Feed | None = None
    if args.capture is not None:
        data = args.data or default_folder()
        try:
            capture = read_capture(data, args.capture)
        except RealDataError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        feed = capture_feed(capture, placed=args.against_seed)
    elif args.source == "bench":
        feed = seed_world_feed()
    label = feed.label if feed is not None else "sim source, 320 x 240"
    methods = ("boxes", "seed") if args.against_seed else ("boxes",)

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs = Processes(endpoint)
    relay = Relay()
    rows: list[Row] = []
    try:
        procs.start("router", "--listen", endpoint, connect=False)
        time.sleep(1.0)  # the router binds its port; every other process retries until it does
        with bus.open_bus(bus_args(endpoint)) as b:
            b.subscribe_raw("detections", relay.on_detections)
            if feed is None:
                b.subscribe_raw("camera/depth/image_raw", relay.on_depth)
            pubs = Publishers(b, feed) if feed is not None else None
            for method in methods:
                rows.append(measure(procs, relay, pubs, method, args))
    finally:
        procs.stop_all()
    ok = [print_row(row, label, args.rate_hz, named=args.against_seed) for row in rows]
    if not all(ok):
        return 1
    if args.against_seed:
        finder, seed = rows
        print(
            f"ratio of p50s, finder over seed: {finder.p(50) / seed.p(50):.2f}x "
            f"(p90s: {finder.p(90) / seed.p(90):.2f}x)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
