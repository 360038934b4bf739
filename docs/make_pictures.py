"""Make the README's pictures with onebox's own commands.

    python docs/make_pictures.py              every picture below, in docs/
    python docs/make_pictures.py --no-scene   all but scene.png (no browser needed)
    python docs/make_pictures.py --worlds     only the scene files' pictures

- docs/colour.png and docs/depth.png: the committed capture (tests/data/one_box.mcap), the
  colour picture as it is and the depth picture as ``onebox pixels`` shades it (near is bright,
  no reading is blue), each pixel 2 x 2.
- docs/world_one_box.png, docs/world_pallet.png, docs/world_clutter.png: the colour picture of
  each committed scene file (scene/*.toml), rendered as ``onebox sim --scene`` renders it;
  clutter's 1280 x 720 halved. docs/world_pallet_depth.png: the pallet's depth through its
  d435 noise, shaded as ``onebox pixels`` shades depth (near is bright, no reading is blue).
- docs/scene.png: the live system (router, sim, points, locator, viewer) on private loopback
  ports, the viewer serving its web viewer, photographed by headless Chromium (Debian's
  ``chromium``, with SwiftShader for WebGL) through the DevTools protocol after --wait-s
  seconds, since the viewer's WebAssembly takes a while to load and draw.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
import zlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from onebox import pictures  # noqa: E402
from onebox.recording import read_capture  # noqa: E402
from schemas import Image  # noqa: E402  (after the path, so it runs from a checkout)
from services import pixels  # noqa: E402

CAPTURE = ROOT / "tests" / "data" / "one_box.mcap"
DOCS = ROOT / "docs"


def write_png(path: Path, rgb: npt.NDArray[np.uint8]) -> None:
    """An 8-bit RGB PNG, written with zlib alone."""
    height, width, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[row].tobytes() for row in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )


def capture_pictures(out_dir: Path, scale: int = 2) -> None:
    capture = read_capture(CAPTURE)
    colour, depth = capture["camera/image_raw"], capture["camera/depth/image_raw"]
    assert isinstance(colour, Image) and isinstance(depth, Image)
    rgb = pictures.rgb(colour)
    grey = pixels.depth_grey(pictures.depth_m(depth))
    for name, picture in (("colour.png", rgb), ("depth.png", grey)):
        big = picture.repeat(scale, axis=0).repeat(scale, axis=1)
        write_png(out_dir / name, big)
        print(f"wrote {out_dir / name} ({big.shape[1]} x {big.shape[0]})")


def world_pictures(out_dir: Path) -> None:
    """Colour of each committed scene file, and the pallet's depth with its d435 noise."""
    import mujoco

    from onebox.world import scene, spec
    from onebox.world.noise import DepthNoise
    from onebox.world.render import SceneRenderer

    for name in ("one_box", "pallet", "clutter"):
        desc = spec.load(ROOT / "scene" / f"{name}.toml")
        model = scene.build_model(desc)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        with SceneRenderer(model, scene.cameras(desc)[:1]) as renderer:
            capture = renderer.render(data, "camera")
        step = 2 if desc.camera.width > 640 else 1
        pictures_out = {f"world_{name}.png": capture.rgb[::step, ::step]}
        if name == "pallet":
            noisy = DepthNoise(desc.noise, capture.depth_m.shape).apply(capture.depth_m)
            pictures_out["world_pallet_depth.png"] = pixels.depth_grey(noisy)
        for file, picture in pictures_out.items():
            write_png(out_dir / file, np.ascontiguousarray(picture))
            print(f"wrote {out_dir / file} ({picture.shape[1]} x {picture.shape[0]})")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def started(commands: list[list[str]], env: dict[str, str]) -> Iterator[None]:
    """Run ``commands`` for the length of the block; each is stopped by its own pid."""
    procs: list[subprocess.Popen[bytes]] = []
    logs = tempfile.TemporaryFile()
    try:
        for cmd in commands:
            procs.append(subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=logs, stderr=logs))
            time.sleep(0.5)  # the router first; the rest in the order given
        yield
    finally:
        for proc in reversed(procs):
            proc.send_signal(signal.SIGTERM)
        for proc in reversed(procs):
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        logs.close()


def screenshot(url: str, out: Path, wait_s: float, size: tuple[int, int]) -> None:
    """Open ``url`` in headless Chromium, wait, and save what it shows."""
    from websockets.sync.client import connect  # only this picture needs it

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("no chromium: apt-get install -y chromium")
    port = free_port()
    with tempfile.TemporaryDirectory() as profile:
        cmd = [
            chromium,
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            f"--window-size={size[0]},{size[1]}",
            f"--remote-debugging-port={port}",
            f"--user-data-dir={profile}",
            url,
        ]
        browser = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 30
            socket_url = ""
            while not socket_url:
                with contextlib.suppress(OSError, ValueError):
                    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=2) as r:
                        targets = json.load(r)
                    pages = [t for t in targets if t.get("type") == "page"]
                    socket_url = pages[0]["webSocketDebuggerUrl"] if pages else ""
                if time.monotonic() > deadline:
                    raise SystemExit("chromium did not open its DevTools port")
                time.sleep(0.2)
            print(f"waiting {wait_s:g} s for the web viewer to load and draw")
            time.sleep(wait_s)
            with connect(socket_url, max_size=None) as ws:
                ws.send(json.dumps({"id": 1, "method": "Page.captureScreenshot"}))
                while True:
                    reply = json.loads(ws.recv())
                    if reply.get("id") == 1:
                        break
            out.write_bytes(base64.b64decode(reply["result"]["data"]))
            print(f"wrote {out}")
        finally:
            browser.terminate()
            try:
                browser.wait(timeout=10)
            except subprocess.TimeoutExpired:
                browser.kill()
                browser.wait()


def scene(out: Path, wait_s: float) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    grpc_port, web_port = free_port(), free_port()
    onebox = [sys.executable, "-m", "services.cli"]
    env = {**os.environ, "ONEBOX_ROUTER": endpoint, "DISPLAY": "", "WAYLAND_DISPLAY": ""}
    commands = [
        [*onebox, "router"],
        [*onebox, "sim"],
        [*onebox, "points"],
        [*onebox, "locator"],
        [*onebox, "viewer", "--grpc-port", str(grpc_port), "--web-port", str(web_port)],
    ]
    url = f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"
    with started(commands, env):
        time.sleep(3)  # the web server and the first captures
        screenshot(url, out, wait_s, (1400, 800))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--no-scene", action="store_true", help="skip the browser screenshot")
    parser.add_argument("--worlds", action="store_true", help="only the scene files' pictures")
    parser.add_argument("--wait-s", type=float, default=40.0, help="browser load time (40)")
    parser.add_argument("--out", type=Path, default=DOCS, help="where to write (docs/)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    world_pictures(args.out)
    if args.worlds:
        return 0
    capture_pictures(args.out)
    if not args.no_scene:
        scene(args.out / "scene.png", args.wait_s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
