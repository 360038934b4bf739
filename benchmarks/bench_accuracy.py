"""How close the seed's method gets: the locator's detections against sim/ground_truth.

    python benchmarks/bench_accuracy.py [--boxes 50] [--seed 1] [--random-yaw]

Starts a private ``onebox router`` and one real ``onebox locator``, then for each of ``--boxes``
random boxes (edge 3 to 10 cm, anywhere the whole box stays in the 320 x 240 camera's view,
turned when ``--random-yaw``) runs ``onebox sim --rate-hz 30 --frames 4`` with that box and
pairs each detection with the sim's ground truth of the same stamp. Prints the median and the
worst error of the middle (x, y and the distance) and of the height, in millimetres, and the
default scene's error on its own line.
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox import bus
from onebox.testing.processes import Processes, bus_args, free_port
from schemas import Detection3DArray, GroundTruth, codec

HALF_VIEW_X_M = 0.40 * math.tan(math.radians(30)) * (0.40 - 0.10) / 0.40  # at the highest top
HALF_VIEW_Y_M = HALF_VIEW_X_M * 240 / 320
MARGIN_M = 0.01


class Pairs:
    """Detections and ground truth of one sim run, paired by stamp."""

    def __init__(self) -> None:
        self.detections: dict[int, Detection3DArray] = {}
        self.truths: dict[int, GroundTruth] = {}
        self.cond = threading.Condition()

    def on_detections(self, key: str, payload: bytes) -> None:
        array = codec(Detection3DArray).decode(payload)
        with self.cond:
            self.detections[array.header.stamp_ns] = array
            self.cond.notify_all()

    def on_truth(self, key: str, payload: bytes) -> None:
        truth = codec(GroundTruth).decode(payload)
        with self.cond:
            self.truths[truth.header.stamp_ns] = truth
            self.cond.notify_all()

    def paired(self) -> list[tuple[Detection3DArray, GroundTruth]]:
        return [(d, self.truths[s]) for s, d in self.detections.items() if s in self.truths]

    def reset(self) -> None:
        with self.cond:
            self.detections.clear()
            self.truths.clear()

    def wait(self, count: int, timeout_s: float) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: len(self.paired()) >= count, timeout=timeout_s)


def random_box(rng: random.Random, yaw: bool) -> tuple[float, float, float, float]:
    size = rng.uniform(0.03, 0.10)
    reach = size / 2 * math.sqrt(2) + MARGIN_M  # a turned box reaches out to its corner
    x = rng.uniform(-HALF_VIEW_X_M + reach, HALF_VIEW_X_M - reach)
    y = rng.uniform(-HALF_VIEW_Y_M + reach, HALF_VIEW_Y_M - reach)
    return x, y, size, rng.uniform(0.0, 90.0) if yaw else 0.0


def errors_mm(array: Detection3DArray, truth: GroundTruth) -> tuple[float, float, float] | None:
    """(x, y, height) errors of one detection, or None when the box was missed."""
    if not array.detections or truth.box_pose is None or truth.box_size is None:
        return None
    bbox = array.detections[0].bbox
    middle, true_middle = bbox.center.position, truth.box_pose.position
    true_height = true_middle.z + truth.box_size.z / 2
    return (
        (middle.x - true_middle.x) * 1e3,
        (middle.y - true_middle.y) * 1e3,
        (bbox.size.z - true_height) * 1e3,
    )


def summary(name: str, values: list[float], signed: bool = True) -> str:
    magnitudes = [abs(v) for v in values]
    bias = f" (mean signed {statistics.fmean(values):+.2f} mm)" if signed else ""
    return (
        f"{name:<10} median {statistics.median(magnitudes):.2f} mm, "
        f"worst {max(magnitudes):.2f} mm{bias}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--boxes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--random-yaw", action="store_true")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    boxes = [(0.065, 0.040, 0.06, 0.0)] + [
        random_box(rng, args.random_yaw) for _ in range(args.boxes)
    ]

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs = Processes(endpoint)
    pairs = Pairs()
    results: list[tuple[float, float, float]] = []
    missed = 0
    default: tuple[float, float, float] | None = None
    start = time.monotonic()
    try:
        procs.start("router", "--listen", endpoint, connect=False)
        time.sleep(1.0)  # the router binds its port; every other process retries until it does
        with bus.open_bus(bus_args(endpoint)) as b:
            b.subscribe_raw("detections", pairs.on_detections)
            b.subscribe_raw("sim/ground_truth", pairs.on_truth)
            procs.start("locator", "--log-interval-s", "60")
            time.sleep(2.0)  # the locator subscribes before the first capture
            for n, (x, y, size, yaw) in enumerate(boxes):
                pairs.reset()
                sim = procs.start(
                    "sim",
                    *("--rate-hz", "30", "--frames", "4"),
                    *("--box-x", f"{x:.5f}", "--box-y", f"{y:.5f}"),
                    *("--box-size", f"{size:.5f}", "--box-yaw-deg", f"{yaw:.3f}"),
                )
                sim.wait(timeout=60)
                # The first capture of each new sim goes back in time and is dropped.
                pairs.wait(2, timeout_s=5.0)
                found = [e for e in (errors_mm(d, t) for d, t in pairs.paired()) if e]
                if not found:
                    missed += 1
                    why = "no box in its detections" if pairs.paired() else "no detection came"
                    print(
                        f"  missed box {n}: ({x:+.4f}, {y:+.4f}), {size * 100:.1f} cm, "
                        f"yaw {yaw:.0f} deg: {why}; sim said: {procs.stop(sim).strip()[-300:]}"
                    )
                    continue
                if n == 0:
                    default = found[-1]
                else:
                    results.append(found[-1])
                if n % 10 == 0:
                    print(f"  {n} of {len(boxes) - 1} boxes, {time.monotonic() - start:.0f} s")
    finally:
        procs.stop_all()
    if not results:
        print("no box was measured")
        return 1
    print(
        f"{len(results)} random boxes measured, {missed} missed; seed's method against "
        "sim/ground_truth:"
    )
    print(summary("middle x", [r[0] for r in results]))
    print(summary("middle y", [r[1] for r in results]))
    print(summary("distance", [math.hypot(r[0], r[1]) for r in results], signed=False))
    print(summary("height", [r[2] for r in results]))
    if default is not None:
        print(
            f"default scene (0.065, 0.040), 6 cm: x {default[0]:+.2f} mm, "
            f"y {default[1]:+.2f} mm, height {default[2]:+.2f} mm"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
