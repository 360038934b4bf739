"""Print every pixel of the basic camera, then the depth readings of a patch (make camera.pixels).

Waits for one capture of the 80 x 60 basic camera (a colour and a depth picture with the same
stamp) and prints:

  1. the colour picture in 24-bit colour, two pixels a character cell (the half block ▀: the
     upper pixel its foreground, the lower its background), so the 80 x 60 picture takes 80
     columns and 30 lines; a wider picture is thinned to --columns (default 80);
  2. the depth picture the same way, in grey: near is bright, far is dark, and a pixel with no
     reading is dark blue;
  3. the depth readings, in metres, of a patch: by default rows 19-23 and columns 43-50, on the
     left edge of the box, as the seed's section 5.2 shows them:

              43     44     45     46     47     48     49     50
  row 19   0.400  0.400  0.400  0.373  0.340  0.340  0.340  0.340

Reads (under --namespace): CAMERA/image_raw (Image rgb8) and CAMERA/depth/image_raw (Image
32FC1 metres, NaN = no reading), CAMERA being --camera (default basic_camera).
Writes: the terminal only. Run it beside ``honcho start``, or a replay of a recording that has
the camera's keys (the committed capture has the main camera only: ``onebox replay
tests/data/one_box.mcap --loop`` with ``onebox pixels --camera camera``); when nothing arrives
within --timeout-s it says how to start the simulation and exits 2.
Almost every modern terminal shows 24-bit colour; if yours prints strange characters, try
another, or pass --no-pictures for the table alone.
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from onebox import bus, pictures
from onebox.errors import NothingArrived, SettingError
from schemas import Image

log = logging.getLogger("pixels")

NO_READING_RGB = (20, 40, 160)
RESET = "\x1b[0m"
UPPER_HALF = "\u2580"
"""▀: the foreground colours the upper half of the cell, the background the lower."""
CAPTURE = "tests/data/one_box.mcap"
COMMITTED_CAPTURE_CAMERA = "camera"
"""The camera whose keys the committed capture holds (it has no basic_camera keys)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--camera", default="basic_camera", help="whose pictures (default basic_camera)"
    )
    parser.add_argument(
        "--rows",
        type=int,
        nargs=2,
        default=(19, 23),
        metavar=("FIRST", "LAST"),
        help="the patch's rows, both included (default 19 23)",
    )
    parser.add_argument(
        "--cols",
        type=int,
        nargs=2,
        default=(43, 50),
        metavar=("FIRST", "LAST"),
        help="the patch's columns, both included (default 43 50)",
    )
    parser.add_argument(
        "--no-pictures", action="store_true", help="print only the table of depth readings"
    )
    parser.add_argument(
        "--columns",
        type=int,
        default=80,
        help="the most character columns a picture may take; a wider one is thinned (default 80)",
    )
    parser.add_argument(
        "--timeout-s",
        type=float,
        default=10.0,
        help="give up when no capture arrives in this time (default 10)",
    )
    bus.add_arguments(parser)


def thinned(rgb: npt.NDArray[np.uint8], columns: int) -> npt.NDArray[np.uint8]:
    """Every n-th pixel across and down, the smallest n that fits ``columns``."""
    step = max(1, math.ceil(rgb.shape[1] / columns))
    return rgb[::step, ::step]


def half_blocks(rgb: npt.NDArray[np.uint8]) -> str:
    """A picture as rows of ▀ cells, two pixel rows a line: upper pixel foreground, lower pixel
    background, both 24-bit. An odd last row leaves the terminal's own background below it."""
    lines = []
    for top in range(0, rgb.shape[0], 2):
        upper = rgb[top].tolist()
        lower: list[list[int]] | None = rgb[top + 1].tolist() if top + 1 < rgb.shape[0] else None
        parts = []
        previous: tuple[int, ...] | None = None
        for i, (r, g, b) in enumerate(upper):
            colours: tuple[int, ...] = (r, g, b, *(lower[i] if lower is not None else ()))
            # Only a change of colour needs a new escape; a flat table stays short.
            if colours != previous:
                escape = f"\x1b[38;2;{r};{g};{b}"
                if lower is not None:
                    escape += ";48;2;{};{};{}".format(*lower[i])
                parts.append(escape + "m")
                previous = colours
            parts.append(UPPER_HALF)
        lines.append("".join(parts) + RESET)
    return "\n".join(lines)


def depth_grey(depth_m: npt.NDArray[np.float32]) -> npt.NDArray[np.uint8]:
    """Depth as an rgb picture: the nearest reading white-ish, the farthest dark grey."""
    out = np.empty((*depth_m.shape, 3), np.uint8)
    out[:] = NO_READING_RGB
    valid = np.isfinite(depth_m)
    if valid.any():
        near, far = float(depth_m[valid].min()), float(depth_m[valid].max())
        span = far - near if far > near else 1.0
        grey = 245 - (depth_m[valid] - near) / span * 185
        out[valid] = np.round(grey).astype(np.uint8)[:, None]
    return out


def patch_table(
    depth_m: npt.NDArray[np.float32], rows: tuple[int, int], cols: tuple[int, int]
) -> str:
    """The seed's table: column numbers on top, one line a row, metres to the millimetre."""
    first_col, last_col = cols
    columns = range(first_col, last_col + 1)
    lines = [" " * 9 + "".join(f"{c:7d}" for c in columns)]
    for r in range(rows[0], rows[1] + 1):
        values = depth_m[r, first_col : last_col + 1]
        lines.append(f"  row {r:<2d} " + "".join(f"{float(v):7.3f}" for v in values))
    return "\n".join(lines)


def check_patch(shape: tuple[int, ...], rows: tuple[int, int], cols: tuple[int, int]) -> None:
    height, width = shape[:2]
    for name, (first, last), size in (("rows", rows, height), ("cols", cols, width)):
        if not 0 <= first <= last < size:
            raise SettingError(
                f"--{name} {first} {last}: the picture is {width} x {height}, so give "
                f"0 <= FIRST <= LAST <= {size - 1}"
            )


class Capture(NamedTuple):
    """One capture's pictures, decoded."""

    stamp_ns: int
    rgb: npt.NDArray[np.uint8]
    depth_m: npt.NDArray[np.float32]


def wait_for_capture(b: bus.Bus, camera: str, timeout_s: float) -> Capture:
    """The first colour and depth picture of ``camera`` with the same stamp.

    Pictures are decoded as they arrive, so a bad one is logged with its key and skipped.
    """
    colour_key, depth_key = f"{camera}/image_raw", f"{camera}/depth/image_raw"
    colours: dict[int, npt.NDArray[np.uint8]] = {}
    depths: dict[int, npt.NDArray[np.float32]] = {}
    found: list[Capture] = []
    done = threading.Event()
    lock = threading.Lock()

    def on_image(key: str, image: Image) -> None:
        name = b.unkey(key)
        stamp = image.header.stamp_ns
        with lock:
            if done.is_set():
                return
            if name == colour_key:
                colours[stamp] = pictures.rgb(image)
            elif name == depth_key:
                depths[stamp] = pictures.depth_m(image)
            if stamp in colours and stamp in depths:
                found.append(Capture(stamp, colours[stamp], depths[stamp]))
                done.set()
            # A pair turns up within a few captures; keep the waiting pictures few.
            for waiting in (colours, depths):
                while len(waiting) > 10:
                    del waiting[next(iter(waiting))]

    b.subscribe(colour_key, Image, on_image)
    b.subscribe(depth_key, Image, on_image)
    log.info("waiting for one capture on %s and %s", b.key(colour_key), b.key(depth_key))
    if not done.wait(timeout_s):
        with lock:
            got = [key for key, waiting in ((colour_key, colours), (depth_key, depths)) if waiting]
        raise NothingArrived(
            f"no capture of {camera} within {timeout_s:g} s"
            + (f" (only {', '.join(got)})" if got else "")
            + f": {start_hint(camera)}"
        )
    return found[0]


def start_hint(camera: str) -> str:
    """How to get ``camera``'s pictures published; a replay only where the committed capture
    has them."""
    hint = "start the simulation with `honcho start` (or `onebox sim`), then run this again"
    if camera == COMMITTED_CAPTURE_CAMERA:
        return f"{hint}, or replay the committed capture with `onebox replay {CAPTURE} --loop`"
    return (
        f"{hint} (the committed capture has no {camera} keys: beside `onebox replay "
        f"{CAPTURE} --loop`, run `onebox pixels --camera {COMMITTED_CAPTURE_CAMERA}`)"
    )


@dataclass(frozen=True)
class PixelsSettings:
    """Whose pictures ``onebox pixels`` prints, how wide, and which patch of readings."""

    camera: str
    rows: tuple[int, int]
    cols: tuple[int, int]
    pictures: bool
    columns: int
    timeout_s: float


def settings_from(args: argparse.Namespace) -> PixelsSettings:
    if args.columns < 1:
        raise SettingError(f"--columns {args.columns}: must be 1 or more")
    return PixelsSettings(
        camera=args.camera,
        rows=(int(args.rows[0]), int(args.rows[1])),
        cols=(int(args.cols[0]), int(args.cols[1])),
        pictures=not args.no_pictures,
        columns=args.columns,
        timeout_s=args.timeout_s,
    )


def main(args: argparse.Namespace) -> int:
    settings = settings_from(args)
    rows, cols, camera = settings.rows, settings.cols, settings.camera
    with bus.open_bus(args, connect_timeout_s=settings.timeout_s) as b:
        capture = wait_for_capture(b, camera, settings.timeout_s)
    height, width = capture.depth_m.shape
    check_patch(capture.depth_m.shape, rows, cols)
    if settings.pictures:
        rgb = thinned(capture.rgb, settings.columns)
        shown = f"shown {rgb.shape[1]} x {rgb.shape[0]}, " if rgb.shape[1] < width else ""
        print(f"{camera}: {width} x {height}, {shown}colour at {capture.stamp_ns / 1e9:.3f} s")
        print(half_blocks(rgb))
        print(f"{camera}: depth (near = bright, no reading = blue)")
        print(half_blocks(thinned(depth_grey(capture.depth_m), settings.columns)))
    print(f"{camera}: depth in metres, rows {rows[0]}-{rows[1]}, columns {cols[0]}-{cols[1]}")
    print(patch_table(capture.depth_m, rows, cols))
    return 0
