"""Memory under a flood: the locator's and the recorder's resident size while 640 x 480 depth
pictures arrive as fast as one publisher can send them, and after the flood stops.

    python benchmarks/bench_faults.py                 # a 1-minute flood
    python benchmarks/bench_faults.py --minutes 2     # the figures in docs/benchmarks.md

A private router; two locators side by side on the same flood, one with glibc's malloc as it
comes (``ONEBOX_MALLOC=glibc``) and one as onebox runs it (a fixed mmap threshold, two arenas,
trimmed every interval: see ``onebox/memory.py``); one ``onebox record`` of every key (zstd) into
a temporary folder. This process publishes the pictures, their camera info and tf_static. It
prints each process's RSS at the start (after its first capture), every ``--every-s``, at the
end of the flood, and after ``--idle-s`` of quiet.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from onebox import bus  # noqa: E402
from onebox.memory import rss_mb  # noqa: E402
from onebox.testing.processes import bus_args, private_router, terminate  # noqa: E402
from onebox.testing.synthetic import (  # noqa: E402
    Scene,
    camera_info,
    depth_image,
    depth_picture,
    tf_static,
)
from schemas import CameraInfo, Image, TFMessage, codec  # noqa: E402


def start(args: list[str], log_path: Path, **env: str) -> subprocess.Popen[bytes]:
    with log_path.open("wb") as log:
        return subprocess.Popen(
            [sys.executable, "-m", "services.cli", *args],
            cwd=ROOT,
            stdout=log,
            stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **env},
        )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--minutes", type=float, default=1.0, help="how long the flood lasts")
    parser.add_argument("--every-s", type=float, default=15.0, help="how often to print RSS")
    parser.add_argument("--idle-s", type=float, default=10.0, help="quiet after the flood")
    args = parser.parse_args()
    scene = Scene(width=640, height=480)
    picture = depth_picture(scene)
    with tempfile.TemporaryDirectory(prefix="bench_faults_") as tmp, private_router() as endpoint:
        work = Path(tmp)
        flags = ["--connect", endpoint]
        procs = {
            "locator (glibc malloc)": start(
                ["locator", *flags], work / "locator_glibc.log", ONEBOX_MALLOC="glibc"
            ),
            "locator (onebox)": start(["locator", *flags], work / "locator.log"),
            "record (onebox)": start(
                ["record", str(work / "flood.mcap"), *flags], work / "record.log"
            ),
        }
        try:
            with bus.open_bus(bus_args(endpoint)) as b:
                depth = b.publisher("camera/depth/image_raw", Image)
                info = b.publisher("camera/camera_info", CameraInfo)
                b.publisher("tf_static", TFMessage, latched=True).publish(tf_static())
                if not depth.wait_for_subscribers(30):
                    raise RuntimeError("no locator subscribed within 30 s")
                encoded_info = codec(CameraInfo)
                stamp = 0
                sent = 0
                start_s = time.monotonic()
                end_s = start_s + args.minutes * 60
                first: dict[str, float] = {}
                next_print = start_s + 5.0
                print(f"flood of 640 x 480 depth + camera info for {args.minutes:g} min")
                print(f"{'s':>6}  " + "  ".join(f"{name:>24}" for name in procs) + "  pictures/s")
                while time.monotonic() < end_s:
                    stamp += 1_000_000
                    info.publish_bytes(encoded_info.encode(camera_info(scene, stamp)))
                    depth.publish(depth_image(picture, stamp))
                    sent += 1
                    now = time.monotonic()
                    if now >= next_print:
                        sizes = {name: rss_mb(p.pid) for name, p in procs.items()}
                        first = first or sizes
                        elapsed = now - start_s
                        print(
                            f"{elapsed:6.0f}  "
                            + "  ".join(f"{sizes[n]:21.0f} MB" for n in procs)
                            + f"  {sent / elapsed:9.0f}"
                        )
                        next_print = now + args.every_s
                end = {name: rss_mb(p.pid) for name, p in procs.items()}
            time.sleep(args.idle_s)  # the quiet after the flood is what is measured
            idle = {name: rss_mb(p.pid) for name, p in procs.items()}
        finally:
            for proc in procs.values():
                terminate(proc, timeout_s=30)
        print()
        for name in procs:
            print(
                f"{name:>24}: start {first[name]:.0f} MB, end of flood {end[name]:.0f} MB "
                f"({end[name] - first[name]:+.0f}), after {args.idle_s:g} s idle "
                f"{idle[name]:.0f} MB ({idle[name] - first[name]:+.0f})"
            )
        print(f"{sent:,} pictures in {args.minutes:g} min ({sent / args.minutes / 60:.0f}/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
