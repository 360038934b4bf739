"""How fast ``onebox record`` writes, beside a running sim and on its own.

    python benchmarks/bench_record.py            # 10 s of 640 x 480 at 30 Hz, zstd and none
    python benchmarks/bench_record.py --seconds 20 --compression lz4

1. Beside a running sim: a private router, ``onebox sim --width 640 --height 480 --rate-hz 30``
   for ``--seconds`` of real time, and ``onebox record`` of every key, as real processes. Prints
   the recorder's sustained MB/s and messages/s (over the log times of what it wrote) and the
   colour and depth captures it dropped, counted by stamp against the captures the sim made.
   With ``--fast`` the sim runs as fast as it can, to find where the recorder starts to drop.
   Each ``--compression`` (default: zstd, the recorder's default, then none) is one run, and
   the file sizes are printed side by side.
2. Standalone: the same colour + depth payloads written straight through RecordingWriter, as
   fast as it takes them: MB/s and messages/s, to the page cache and including an fsync.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from onebox import bus  # noqa: E402
from onebox.recording import RecordingWriter, iter_messages  # noqa: E402
from onebox.testing.processes import bus_args, free_port, terminate  # noqa: E402
from schemas import Header, Image, Message, codec  # noqa: E402

CAMERA_KEYS = ("camera/image_raw", "camera/depth/image_raw")
WIDTH, HEIGHT = 640, 480


def start(args: list[str], log_path: Path) -> subprocess.Popen[bytes]:
    log = log_path.open("wb")
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "services.cli", *args],
            cwd=ROOT,
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
    finally:
        log.close()


def wait_port(port: int, timeout_s: float = 15.0) -> None:
    import socket

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def wait_subscribed(endpoint: str, key: str, timeout_s: float = 30.0) -> None:
    """Until the recorder's subscription is known on the router."""
    with bus.open_bus(bus_args(endpoint)) as b:
        if not b.publisher(key, Message).wait_for_subscribers(timeout_s):
            raise RuntimeError(f"the recorder did not subscribe to {key} in {timeout_s} s")


def beside_sim(workdir: Path, seconds: float, rate_hz: float, fast: bool, compression: str) -> int:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    out = workdir / "beside_sim.mcap"
    frames = int(seconds * rate_hz)
    router = start(["router", "--listen", endpoint], workdir / "router.log")
    procs = [router]
    try:
        wait_port(port)
        recorder = start(
            ["record", str(out), "--compression", compression, "--connect", endpoint],
            workdir / "record.log",
        )
        procs.append(recorder)
        wait_subscribed(endpoint, CAMERA_KEYS[0])
        sim_args = ["sim", "--width", str(WIDTH), "--height", str(HEIGHT)]
        sim_args += ["--rate-hz", str(rate_hz), "--frames", str(frames), "--connect", endpoint]
        sim = start([*sim_args, *(["--fast"] if fast else [])], workdir / "sim.log")
        procs.append(sim)
        sim.wait(timeout=seconds * 10 + 60)
        time.sleep(1.0)  # the last captures' way through Zenoh and the recorder's queue
        terminate(recorder, timeout_s=60)
    finally:
        for proc in reversed(procs):
            terminate(proc, timeout_s=60)

    stamps: dict[str, set[int]] = {k: set() for k in CAMERA_KEYS}
    first_ns = last_ns = 0
    count = nbytes = 0
    for r in iter_messages(out):
        if r.key in stamps:
            stamps[r.key].add(r.publish_time_ns)
        if count == 0:
            first_ns = r.log_time_ns
        last_ns = r.log_time_ns
        count += 1
        nbytes += len(r.payload)
    span_s = max((last_ns - first_ns) / 1e9, 1e-9)
    dropped = {k: frames - len(s) for k, s in stamps.items()}
    input_mb_s = rate_hz * WIDTH * HEIGHT * (3 + 4) / 1e6
    mode = "as fast as the sim can" if fast else f"{rate_hz:g} Hz real time"
    record_log = (workdir / "record.log").read_text().strip().splitlines()
    print(f"beside a running sim ({WIDTH} x {HEIGHT} colour + depth, {mode}, {frames} captures,")
    offered = "" if fast else f"; colour + depth alone {input_mb_s:.1f} MB/s"
    print(f"  compression {compression}{offered})")
    print(f"  recorded {count} messages, {nbytes / 1e6:.1f} MB over {span_s:.2f} s")
    print(f"  sustained {nbytes / 1e6 / span_s:.1f} MB/s, {count / span_s:.0f} messages/s")
    print(f"  dropped (by stamp): {', '.join(f'{k} {n}' for k, n in dropped.items())}")
    print(f"  recorder: {record_log[-1] if record_log else '(no output)'}")
    size = out.stat().st_size
    print(f"  file {size / 1e6:.1f} MB ({size / max(nbytes, 1):.0%} of the messages' bytes)")
    out.unlink()
    return size


def payloads(n: int) -> list[bytes]:
    """Colour and depth pictures shaped like the sim's (smooth, with a little noise)."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    result = []
    for i in range(n):
        colour = np.stack([(xx + i) % 256, (yy + i) % 256, np.full_like(xx, 128)], axis=-1)
        colour = (colour + rng.integers(0, 4, colour.shape)).astype(np.uint8)
        depth = (0.4 - 0.06 * ((abs(xx - 320) < 60) & (abs(yy - 240) < 60))).astype(np.float32)
        for encoding, data, step in (
            ("rgb8", colour.tobytes(), WIDTH * 3),
            ("32FC1", depth.tobytes(), WIDTH * 4),
        ):
            image = Image(
                header=Header(stamp_ns=i * 33_333_333, frame_id="camera_optical_frame"),
                height=HEIGHT,
                width=WIDTH,
                encoding=encoding,
                step=step,
                data=data,
            )
            result.append(codec(Image).encode(image))
    return result


def standalone(workdir: Path, total_mb: float, compression: str) -> None:
    sample = payloads(8)
    per_pair = len(sample[0]) + len(sample[1])
    pairs = max(1, int(total_mb * 1e6 / per_pair))
    out = workdir / "standalone.mcap"
    start_s = time.perf_counter()
    with RecordingWriter(out, compression=compression) as writer:
        for i in range(pairs):
            j = (i % 8) * 2
            now = time.time_ns()
            writer.add(CAMERA_KEYS[0], sample[j], now)
            writer.add(CAMERA_KEYS[1], sample[j + 1], now)
    written_s = time.perf_counter() - start_s
    fd = os.open(out, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    synced_s = time.perf_counter() - start_s
    mb = pairs * per_pair / 1e6
    print(
        f"standalone RecordingWriter, compression {compression}, {2 * pairs} messages, {mb:.0f} MB"
    )
    print(f"  to the page cache: {mb / written_s:.0f} MB/s, {2 * pairs / written_s:.0f} messages/s")
    print(f"  including fsync:   {mb / synced_s:.0f} MB/s")
    print(f"  file {out.stat().st_size / 1e6:.0f} MB")
    out.unlink()


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="how long the sim runs")
    parser.add_argument("--rate-hz", type=float, default=30.0)
    parser.add_argument("--fast", action="store_true", help="run the sim as fast as it can")
    parser.add_argument(
        "--compression",
        action="append",
        choices=["none", "lz4", "zstd"],
        help="repeatable; default zstd (the recorder's default) and none, side by side",
    )
    parser.add_argument("--standalone-mb", type=float, default=1000.0)
    parser.add_argument("--skip-sim", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_record_") as tmp:
        workdir = Path(tmp)
        compressions = args.compression or ["zstd", "none"]
        sizes: dict[str, int] = {}
        if not args.skip_sim:
            for compression in compressions:
                sizes[compression] = beside_sim(
                    workdir, args.seconds, args.rate_hz, args.fast, compression
                )
            print(
                f"file size of {args.seconds:g} s: "
                + ", ".join(f"{c} {n / 1e6:.1f} MB" for c, n in sizes.items())
            )
        for compression in compressions:
            standalone(workdir, args.standalone_mb, compression)
    return 0


if __name__ == "__main__":
    sys.exit(main())
