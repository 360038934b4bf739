"""Network figures: shared memory's latency against the memory it holds, and (as root, in
network namespaces) hosts that lose their link.

    .venv/bin/python benchmarks/bench_network.py shm            # seconds, any user
    .venv/bin/python benchmarks/bench_network.py hosts --runs 20  # root: ip netns, minutes

``shm``: a depth picture (32FC1) sent from one client to another through a private router,
p50 and p95 publish -> callback, with Zenoh's shared-memory transport on and off, and what
/dev/shm and the router's RSS hold afterwards.

``hosts`` (benchmarks/netlab.py): three hosts A, B, C in network namespaces, a router each in a
full mesh (no host's traffic to another passes through a third); the sim on A, the locator on B,
a probe subscriber on C. First B's link is taken down ``--down-s`` (15 s) ``--runs`` times:
the time from its return to the first detection at C, and the longest gap in the depth
pictures A sends C from the link going down to 3 s after its return. Then, in a new lab, B's
two links (B -> A and C -> B) go through a TCP proxy that delays every chunk it forwards by
20 ms and, for 5 % of the chunks (chosen at random, seeded), by a further 200 ms, keeping the
order: TCP loses no bytes, a lost segment costs a stall of one retransmission timeout (200 ms is
Linux's least), and everything behind it waits. Over ``--loss-s`` (60 s) the captures are the
ground-truth stamps that reach C (A -> C is direct and clean); a capture is detected when a
detection with its stamp reaches C. ``--only outage|loss`` runs one half. The load average is
printed: the figures are from a shared machine.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import zenoh

from onebox import bus
from onebox.testing.processes import Processes, free_port


def shm_bytes() -> int:
    """Bytes held in /dev/shm (every file, as the kernel counts blocks)."""
    total = 0
    for entry in os.scandir("/dev/shm"):
        with contextlib.suppress(OSError):
            total += entry.stat(follow_symlinks=False).st_blocks * 512
    return total


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


@contextlib.contextmanager
def router(shm: bool) -> Iterator[tuple[str, subprocess.Popen[str]]]:
    """A private router with shared memory on or off."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs = Processes(endpoint)
    env = {"ONEBOX_LOG": "WARNING"}
    config = _config_file(bus.ROUTER_CONFIG, shm)
    proc = procs.start(
        "router", "--listen", endpoint, "--config", str(config), env=env, connect=False
    )
    _wait_port(endpoint)
    try:
        yield endpoint, proc
    finally:
        procs.stop_all()


def _config_file(base: Path, shm: bool) -> Path:
    """``base`` with shared memory switched on or off, written beside the others in /tmp."""
    config = zenoh.Config.from_file(str(base))
    config.insert_json5("transport/shared_memory/enabled", "true" if shm else "false")
    path = Path(f"/tmp/onebox-bench-{base.stem}-shm-{shm}.json5")
    path.write_text(str(config))
    return path


def _wait_port(endpoint: str) -> None:
    import socket

    host, port = endpoint.removeprefix("tcp/").rsplit(":", 1)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            with socket.create_connection((host, int(port)), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"no router at {endpoint}")


def client(endpoint: str, shm: bool) -> zenoh.Session:
    config = zenoh.Config.from_file(str(_config_file(bus.CLIENT_CONFIG, shm)))
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    return zenoh.open(config)


def latency_ms(endpoint: str, shm: bool, size: int, count: int) -> list[float]:
    """Publish ``count`` pictures of ``size`` bytes one at a time; time each to the callback."""
    arrived = threading.Event()
    got: list[float] = []

    def on_sample(sample: zenoh.Sample) -> None:
        got.append(time.perf_counter())
        arrived.set()

    with client(endpoint, shm) as sub_session, client(endpoint, shm) as pub_session:
        sub = sub_session.declare_subscriber("bench/depth", on_sample)
        pub = bus.Publisher(
            "bench/depth",
            bus.PICTURE_TYPES[0],
            pub_session.declare_publisher(
                "bench/depth", congestion_control=zenoh.CongestionControl.BLOCK, express=True
            ),
        )
        assert pub.wait_for_subscribers(10), "no subscriber"
        payload = os.urandom(size)
        times = []
        for _ in range(count):
            arrived.clear()
            start = time.perf_counter()
            pub.publish_bytes(payload)
            if not arrived.wait(5):
                continue
            times.append((got[-1] - start) * 1000)
        sub.undeclare()
    return times


def bench_shm(count: int, restarts: int) -> None:
    print("shared memory: depth 32FC1 client -> router -> client, one at a time")
    print(f"{'picture':>10} {'shm':>4} {'p50 ms':>8} {'p95 ms':>8}")
    for width, height in ((640, 480), (1280, 720)):
        for shm in (False, True):
            with router(shm) as (endpoint, _):
                times = sorted(latency_ms(endpoint, shm, width * height * 4, count))
            p50 = statistics.median(times)
            p95 = times[int(0.95 * (len(times) - 1))]
            print(f"{width}x{height:<5} {'on' if shm else 'off':>4} {p50:8.2f} {p95:8.2f}")
    print(f"\nwhat restarts leave: {restarts} client pairs started and stopped beside one router")
    header = f"{'/dev/shm before':>16} {'after':>10} {'router RSS before':>18} {'after':>10}"
    print(f"{'shm':>4} {header}")
    for shm in (False, True):
        with router(shm) as (endpoint, proc):
            latency_ms(endpoint, shm, 1280 * 720 * 4, 5)
            shm0, rss0 = shm_bytes(), rss_bytes(proc.pid)
            for _ in range(restarts):
                latency_ms(endpoint, shm, 1280 * 720 * 4, 5)
            shm1, rss1 = shm_bytes(), rss_bytes(proc.pid)
        mib = 1 << 20
        print(
            f"{'on' if shm else 'off':>4} {shm0 / mib:13.1f} MiB {shm1 / mib:6.1f} MiB "
            f"{rss0 / mib:15.1f} MiB {rss1 / mib:6.1f} MiB"
        )


def bench_hosts(runs: int, down_s: float, loss_s: float, only: str | None) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import netlab  # benchmarks/ is a folder of programs, not a package

    reason = netlab.can_run()
    if reason:
        print(f"hosts: skipped, {reason}")
        return
    print(f"load average at the start: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    if only in (None, "outage"):
        bench_outages(netlab, runs, down_s)
    if only in (None, "loss"):
        bench_loss(netlab, loss_s)
    print(f"load average at the end: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


def bench_outages(netlab: Any, runs: int, down_s: float) -> None:
    """B's link down ``down_s``, ``runs`` times, in one lab."""
    print(
        f"hosts: sim on A, locator on B, subscriber on C; B's link down {down_s:.0f} s, "
        f"{runs} times"
    )
    recovered: list[float] = []
    gaps: list[float] = []
    with netlab.Lab(subnet=8) as lab, netlab.pipeline(lab) as probe:
        for run in range(runs):
            took, gap, at = netlab.outage(lab, probe, "b", down_s)
            gaps.append(gap)
            if took is not None:
                recovered.append(took)
            print(
                f"  run {run + 1}: first detection at C "
                f"{'never' if took is None else f'{took:.2f} s'} after the link returned; "
                f"longest A -> C depth gap {gap:.2f} s, from {at:.1f} s after the link went down",
                flush=True,
            )
    if recovered:
        print(
            f"recovered in {len(recovered)} of {runs} runs; first detection after the link "
            f"returned: median {statistics.median(recovered):.2f} s, worst {max(recovered):.2f} s"
        )
    else:
        print(f"recovered in 0 of {runs} runs")
    print(
        f"A -> C depth from B's link going down to 3 s after its return: longest gap median "
        f"{statistics.median(gaps):.2f} s, worst {max(gaps):.2f} s (5 Hz: 0.20 s apart); "
        f"over 1 s in {sum(g > 1.0 for g in gaps)} of {runs} outages"
    )


def bench_loss(netlab: Any, loss_s: float) -> None:
    """B's links through a :class:`netlab.LossyProxy`: 20 ms each way, 5 % of chunks stalled."""
    print(
        f"\nhosts: B's links (B -> A and C -> B) through a TCP proxy that delays every chunk it "
        f"forwards 20 ms and stalls 5 % of chunks a further 200 ms (Linux's least TCP "
        f"retransmission timeout: what a lost segment costs on TCP), {loss_s:.0f} s"
    )
    with netlab.Lab(subnet=9) as lab:
        with (
            netlab.lossy_proxy_process(lab, "a", 7450, 0.020, 0.05) as to_a,
            netlab.lossy_proxy_process(lab, "b", 7450, 0.020, 0.05) as to_b,
            netlab.pipeline(lab, via={("b", "a"): to_a, ("c", "b"): to_b}) as probe,
        ):
            start = time.monotonic()
            time.sleep(loss_s)  # the window being measured
            end = time.monotonic()
            probe.wait_for(netlab.DETECTIONS, end + 5.0, 10.0)  # the window's last detections
            captures, detected = probe.detected(start, end, settle_s=5.0)
            latency = probe.latencies(start, end)
    p50 = statistics.median(latency) * 1000 if latency else float("nan")
    p95 = latency[int(0.95 * (len(latency) - 1))] * 1000 if latency else float("nan")
    print(
        f"captures (ground truth stamps at C) {captures}, with their detection at C {detected}: "
        f"{100 * detected / max(captures, 1):.1f} % detected; capture -> detection at C "
        f"p50 {p50:.0f} ms, p95 {p95:.0f} ms"
    )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="what", required=True)
    shm = sub.add_parser("shm", help="shared memory on and off")
    shm.add_argument("--count", type=int, default=200)
    shm.add_argument("--restarts", type=int, default=10)
    hosts = sub.add_parser("hosts", help="three hosts in network namespaces (root)")
    hosts.add_argument("--runs", type=int, default=5)
    hosts.add_argument("--down-s", type=float, default=15.0)
    hosts.add_argument("--loss-s", type=float, default=60.0)
    hosts.add_argument("--only", choices=("outage", "loss"), help="run one of the two")
    args = parser.parse_args()
    if args.what == "shm":
        bench_shm(args.count, args.restarts)
    else:
        bench_hosts(args.runs, args.down_s, args.loss_s, args.only)
    return 0


if __name__ == "__main__":
    sys.exit(main())
