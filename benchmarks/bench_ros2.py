"""What a 640 x 480 picture costs ``onebox ros2``, beside a plain onebox -> onebox hop.

    python benchmarks/bench_ros2.py [--pictures 40]

Starts a private ``onebox router`` and one real ``onebox ros2`` process bridging
camera/depth/image_raw and camera/image_raw out, and two ROS 2 topics in (published by this
process as an rmw_zenoh node would, onebox/testing/rmw_peer.py). For a 640 x 480 depth picture
(32FC1, 1.2 MB) and a colour picture (rgb8, 0.9 MB), one at a time (each waits for the last
to arrive, so nothing queues), it measures:

- hop: this process publishes the onebox picture and receives it back through the router on
  the same key: the plain onebox -> onebox hop (publisher, router, subscriber);
- out: this process publishes the onebox picture; the bridge turns it into CDR and publishes
  it on the rmw_zenoh key; this process receives it there (publisher, router, bridge, router,
  subscriber);
- in: this process publishes the CDR picture on the ROS topic; the bridge turns it into the
  onebox message; this process receives it on the onebox key.

Prints the median latency of each in milliseconds and its ratio to the hop, the relay's and
the bridge's CPU time per picture (from /proc, 10 ms ticks, so averaged), and the conversion
alone in this process (msgpack -> CDR and back, as the bridge's lanes do it) beside a plain
msgpack decode and encode of the same picture.
"""

from __future__ import annotations

import argparse
import os
import statistics
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import msgspec
from rosbags.typesys import Stores

from onebox import bus
from onebox.export.ros2 import RosMessages, typestore
from onebox.rmw_zenoh import topic_key, type_hash
from onebox.ros_bag import from_ros
from onebox.testing.processes import Output, Processes, bus_args, private_router
from onebox.testing.rmw_peer import RmwPeer
from schemas import Header, Image, ImageView, codec

WIDTH, HEIGHT = 640, 480
IMAGE = "sensor_msgs/msg/Image"
KEYS = {
    "depth": ("camera/depth/image_raw", "/bench/depth", "basic_camera/depth/image_raw"),
    "colour": ("camera/image_raw", "/bench/colour", "basic_camera/image_raw"),
}
"""Each picture's onebox key bridged out, ROS topic bridged in, and the key it comes in on."""


def pictures(stamp_ns: int) -> dict[str, Image]:
    rng = np.random.default_rng(stamp_ns % 2**32)
    depth = rng.uniform(0.3, 3.0, (HEIGHT, WIDTH)).astype(np.float32)
    colour = rng.integers(0, 255, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    header = Header(stamp_ns=stamp_ns, frame_id="camera_optical_frame")
    return {
        "depth": Image(header=header, height=HEIGHT, width=WIDTH, encoding="32FC1",
                       step=WIDTH * 4, data=depth.tobytes()),
        "colour": Image(header=header, height=HEIGHT, width=WIDTH, encoding="rgb8",
                        step=WIDTH * 3, data=colour.tobytes()),
    }  # fmt: skip


class Arrivals:
    """When each stamp arrived, from the Zenoh callbacks of this process."""

    def __init__(self) -> None:
        self.at: dict[int, int] = {}
        self.cond = threading.Condition()

    def add(self, stamp_ns: int) -> None:
        now = time.perf_counter_ns()
        with self.cond:
            self.at.setdefault(stamp_ns, now)
            self.cond.notify_all()

    def wait(self, stamp_ns: int, timeout_s: float = 5.0) -> int:
        with self.cond:
            if not self.cond.wait_for(lambda: stamp_ns in self.at, timeout_s):
                raise RuntimeError(f"picture {stamp_ns} never arrived")
            return self.at[stamp_ns]


def onebox_stamp(payload: bytes) -> int:
    return msgspec.msgpack.decode(payload, type=ImageView).header.stamp_ns


def cdr_stamp(payload: bytes) -> int:
    sec, nanosec = struct.unpack_from("<iI", payload, 4)  # after the 4-byte CDR header
    return sec * 1_000_000_000 + nanosec


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def series(
    count: int,
    make: Callable[[int], Any],
    send: Callable[[Any], None],
    arrivals: Arrivals,
    pid: int | None,
) -> tuple[list[float], float]:
    """Latencies in ms of the pictures that arrived of ``count`` sent one at a time (each made
    before its clock starts), and the CPU time of process ``pid`` a picture in ms."""
    latencies = []
    # Warm up until three pictures have made it: the first puts declare routes, and the bridge
    # converts nothing until it hears that a subscriber matches.
    warmed = 0
    for attempt in range(100):
        stamp = 10**9 * (1 + attempt) + int(time.time_ns() % 10**6)
        send(make(stamp))
        try:
            arrivals.wait(stamp, timeout_s=0.5)
        except RuntimeError:
            continue
        warmed += 1
        if warmed == 3:
            break
    else:
        raise RuntimeError("nothing arrives: is the bridge running?")
    cpu_before = cpu_s(pid) if pid else 0.0
    for i in range(count):
        stamp = 10**12 + 10**9 * i + int(time.time_ns() % 10**6)
        payload = make(stamp)
        started = time.perf_counter_ns()
        send(payload)
        try:
            latencies.append((arrivals.wait(stamp, timeout_s=2.0) - started) / 1e6)
        except RuntimeError:
            continue  # pictures travel drop-on-congestion: a lost one is counted, not waited on
    cpu = (cpu_s(pid) - cpu_before) / count if pid else 0.0
    return latencies, cpu * 1000


def conversion_ms(picture: Image, repeats: int = 40) -> tuple[float, float, float]:
    """Per picture, in this process: msgpack -> CDR (out), CDR -> msgpack (in), and a plain
    msgpack decode + encode."""
    store = typestore(Stores.ROS2_JAZZY)
    messages = RosMessages(store)
    payload = codec(Image).encode(picture)
    view_decoder = msgspec.msgpack.Decoder(ImageView)
    key = "camera/depth/image_raw" if picture.encoding == "32FC1" else "camera/image_raw"

    def out() -> bytes:
        converted = messages.convert(view_decoder.decode(payload))
        assert converted is not None
        return bytes(store.serialize_cdr(converted[1], converted[0]))

    cdr = out()

    def into() -> bytes:
        message = from_ros(store.deserialize_cdr(cdr, "sensor_msgs/msg/Image"), key, {})
        assert message is not None
        return codec(type(message)).encode(message)

    def plain() -> bytes:
        return codec(Image).encode(codec(Image).decode(payload))

    assert into() == payload
    timings = []
    for run in (out, into, plain):
        rounds = []
        for _ in range(5):
            started = time.perf_counter()
            for _ in range(repeats):
                run()
            rounds.append((time.perf_counter() - started) / repeats * 1000)
        timings.append(statistics.median(rounds))
    return timings[0], timings[1], timings[2]


def run_relay(endpoint: str, key: str) -> int:
    """A plain onebox process in the middle: each picture read, decoded, encoded and sent on
    hop/KEY, as any onebox process that re-publishes a message does."""
    stop = threading.Event()
    with bus.open_bus(bus_args(endpoint)) as b:
        publisher = b.publisher(f"hop/{key}", Image)
        b.subscribe(key, Image, lambda _, image: publisher.publish(image))
        print("relaying", flush=True)
        try:
            stop.wait()
        except KeyboardInterrupt:
            pass
    return 0


@dataclass
class Row:
    kind: str
    picture: Image
    hop_ms: list[float]
    hop_cpu_ms: float
    out_ms: list[float]
    out_cpu_ms: float
    in_ms: list[float]
    in_cpu_ms: float
    conversion: tuple[float, float, float]


def measure(kind: str, endpoint: str, b: bus.Bus, peer: RmwPeer, pid: int, count: int) -> Row:
    """The three series for one kind of picture."""
    store = typestore(Stores.ROS2_JAZZY)
    messages = RosMessages(store)
    session = b.session
    key, ros_topic, back = KEYS[kind]
    publisher = b.publisher(key, Image)

    def make_onebox(stamp: int) -> bytes:
        return codec(Image).encode(pictures(stamp)[kind])

    def heard(arrivals: Arrivals, stamp_of: Callable[[bytes], int]) -> Callable[[Any], None]:
        return lambda sample: arrivals.add(stamp_of(sample.payload.to_bytes()))

    # The plain hop: a onebox process in the middle, reading and re-sending.
    hop = Arrivals()
    hop_sub = session.declare_subscriber(f"hop/{key}", heard(hop, onebox_stamp))
    command = [sys.executable, __file__, "--relay", endpoint, key]
    started = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    relay = Output(started)
    relay.wait_for("relaying")
    publisher.wait_for_subscribers(5)
    hop_ms, hop_cpu = series(count, make_onebox, publisher.publish_bytes, hop, started.pid)
    hop_sub.undeclare()
    relay.stop()

    out = Arrivals()
    ros_key = topic_key(0, "/" + key, IMAGE, type_hash(store, IMAGE))
    out_sub = session.declare_subscriber(ros_key, heard(out, cdr_stamp))
    peer.wait_for(lambda g: any(e.topic == "/" + key for e in g))
    out_ms, out_cpu = series(count, make_onebox, publisher.publish_bytes, out, pid)
    out_sub.undeclare()

    into = Arrivals()
    ros = peer.publisher(ros_topic, IMAGE)

    def make_ros(stamp: int) -> bytes:
        return bytes(store.serialize_cdr(messages.image(pictures(stamp)[kind]), IMAGE))

    in_sub = session.declare_subscriber(back, heard(into, onebox_stamp))
    peer.wait_for(lambda g: any(e.topic == ros_topic and e.kind == "MS" for e in g))
    in_ms, in_cpu = series(count, make_ros, ros.publish_raw, into, pid)
    in_sub.undeclare()
    picture = pictures(1)[kind]
    return Row(
        kind, picture, hop_ms, hop_cpu, out_ms, out_cpu, in_ms, in_cpu, conversion_ms(picture)
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pictures", type=int, default=40, help="pictures a series")
    parser.add_argument("--relay", nargs=2, metavar=("ENDPOINT", "KEY"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.relay:
        bus.install_signal_handlers()
        return run_relay(*args.relay)
    rows = []
    with private_router() as endpoint:
        procs = Processes(endpoint)
        try:
            flags = ["--log-interval-s", "60"]
            for key, ros_topic, back in KEYS.values():
                flags += ["--out", key, "--in", f"{ros_topic}={back}"]
            bridge = Output(procs.start("ros2", *flags))
            bridge.wait_for("ROS 2 node /onebox")
            with bus.open_bus(bus_args(endpoint)) as b:
                peer = RmwPeer(b.session, name="bench")
                try:
                    for kind in KEYS:
                        rows.append(
                            measure(kind, endpoint, b, peer, bridge.proc.pid, args.pictures)
                        )
                finally:
                    peer.close()
        finally:
            procs.stop_all()
    print(f"onebox ros2, {WIDTH} x {HEIGHT} pictures, {args.pictures} a series, one at a time")
    print("latency medians: hop = publisher -> router -> a onebox relay process (decode,")
    print("encode, publish) -> router -> subscriber; out/in the same with the bridge between")
    for row in rows:
        hop, out_med, in_med = (statistics.median(x) for x in (row.hop_ms, row.out_ms, row.in_ms))
        size = len(row.picture.data) / 1e6
        print(f"\n{row.kind} ({row.picture.encoding}, {size:.2f} MB)")
        relay_cpu = f"relay CPU {row.hop_cpu_ms:.1f} ms a picture"
        lost = {
            name: args.pictures - len(x)
            for name, x in (("hop", row.hop_ms), ("out", row.out_ms), ("in", row.in_ms))
        }
        if any(lost.values()):
            print(f"  lost (dropped under congestion): {lost}")
        print(f"  plain hop          {hop:7.2f} ms                 {relay_cpu}")
        print(f"  out to ROS 2       {out_med:7.2f} ms   x{out_med / hop:.2f} the hop; "
              f"bridge CPU {row.out_cpu_ms:.1f} ms a picture "
              f"(x{row.out_cpu_ms / row.hop_cpu_ms:.2f})")  # fmt: skip
        print(f"  in from ROS 2      {in_med:7.2f} ms   x{in_med / hop:.2f} the hop; "
              f"bridge CPU {row.in_cpu_ms:.1f} ms a picture "
              f"(x{row.in_cpu_ms / row.hop_cpu_ms:.2f})")  # fmt: skip
        out_conv, in_conv, plain = row.conversion
        print(f"  conversion alone   out {out_conv:.2f} ms, in {in_conv:.2f} ms; a plain "
              f"msgpack decode + encode {plain:.2f} ms (x{out_conv / plain:.1f}, "
              f"x{in_conv / plain:.1f})")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
