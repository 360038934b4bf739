"""List what is being published, and show one of each (make camera.check).

Listens for --window-s seconds (default 2) on every key under the namespace, then prints:

  1. each live key with the type it carries (by the pipeline's key table) and its rate, or
     ``latched`` for ``tf_static``, whose last sample is asked for as a late joiner would;
  2. each camera's info with the four lens numbers: fx, fy, cx, cy;
  3. one message from each picture key (and the point cloud), with the large arrays left out;
  4. one detection (one with a box, if any arrived in the window).

Reads: ``**`` (any type; a key it does not know is listed as such) and ``tf_static`` (latched).
Writes: the terminal only.

When no router is reachable, or nothing is published within the window, it says so, tells how
to start the system (``honcho start``, or ``onebox replay FILE.mcap``) and exits 2. A message
that does not decode as its key's type is listed as such and never stops the report.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import threading
import time
from dataclasses import dataclass

import msgspec

from onebox import bus
from onebox.describe import describe, split_namespace
from onebox.errors import BusError, NothingArrived
from onebox.keys import type_for_key
from schemas import CameraInfo, Detection3DArray, Image, Message, PointCloud, codec
from schemas import type_name as schema_type_name

log = logging.getLogger("check")

ROUTER_WAIT_S = 1.5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--window-s",
        type=float,
        default=2.0,
        help="how long to listen before reporting; rates are measured over it (default 2)",
    )
    bus.add_arguments(parser)


@dataclass
class Seen:
    """What arrived on one key during the window."""

    count: int = 0
    first_s: float = 0.0
    last_s: float = 0.0
    latched: bool = False
    last: bytes = b""
    last_with_box: bytes = b""

    def rate_hz(self) -> float | None:
        if self.count < 2 or self.last_s <= self.first_s:
            return None
        return (self.count - 1) / (self.last_s - self.first_s)


class Listener:
    """Counts every key and keeps its newest payload; a Zenoh callback feeds it."""

    def __init__(self) -> None:
        self.keys: dict[str, Seen] = {}
        self._lock = threading.Lock()

    def on_sample(self, key: str, payload: bytes) -> None:
        now = time.monotonic()
        with self._lock:
            seen = self.keys.setdefault(key, Seen(first_s=now))
            if seen.count == 0:
                seen.first_s = now
            seen.count += 1
            seen.last_s = now
            seen.last = payload
            if key.endswith("detections") and has_box(payload):
                seen.last_with_box = payload

    def on_latched(self, key: str, payload: bytes) -> None:
        """A sample from the latched subscription: the cached one, then live ones again.

        The live ones also reach :meth:`on_sample`, so only the cache is kept here, uncounted.
        """
        with self._lock:
            seen = self.keys.setdefault(key, Seen())
            seen.latched = True
            if not seen.last:
                seen.last = payload

    def snapshot(self) -> dict[str, Seen]:
        with self._lock:
            return dict(sorted(self.keys.items()))


def has_box(payload: bytes) -> bool:
    try:
        return bool(codec(Detection3DArray).decode(payload).detections)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return False


def lens_line(key: str, info: CameraInfo) -> str:
    if len(info.k) != 9:
        return f"{key}: {info.width} x {info.height}, k has {len(info.k)} numbers, not 9"
    fx, fy, cx, cy = info.k[0], info.k[4], info.k[2], info.k[5]
    return (
        f"{key}: {info.width} x {info.height}, fx {fx:.3f}  fy {fy:.3f}  "
        f"cx {cx:.3f}  cy {cy:.3f}  (frame {info.header.frame_id})"
    )


def wait_for_router(b: bus.Bus, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not bus.routers(b):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)  # Zenoh has no event for "connected to a router" to wait on
    return True


START_HINT = (
    "Start everything with `honcho start` (or `onebox router` and `onebox sim`), "
    "or replay a recording with `onebox replay tests/data/one_box.mcap`"
)


def report(seen: dict[str, Seen], b: bus.Bus, window_s: float) -> list[str]:
    """The whole report, from what arrived."""
    lines = [f"{len(seen)} keys in {window_s:g} s:"]
    width = max(len(k) for k in seen)
    decoded: dict[str, Message | None] = {}
    for key, s in seen.items():
        message_type = type_for_key(b.unkey(key), b.namespace)
        if message_type is None:
            type_text = "(not a onebox key)"
        else:
            type_text = schema_type_name(message_type)
            payload = s.last_with_box or s.last
            try:
                decoded[key] = codec(message_type).decode(payload)
            except (msgspec.DecodeError, msgspec.ValidationError) as e:
                decoded[key] = None
                type_text += f"  (last message does not decode: {e})"
        rate = s.rate_hz()
        if rate is not None:
            rate_text = f"{rate:5.1f} Hz"
        else:
            rate_text = "latched" if s.latched else "once"
        if s.latched and rate is not None:
            type_text += "  (latched)"
        lines.append(f"  {key:<{width}}  {rate_text:>8}  {type_text}")

    infos = [(k, m) for k, m in decoded.items() if isinstance(m, CameraInfo)]
    lines.append("")
    lines.append("camera info (the four lens numbers, pixels):")
    lines.extend(f"  {lens_line(k, m)}" for k, m in infos)
    if not infos:
        lines.append("  none arrived: is the sim running?")

    for key, message in decoded.items():
        if isinstance(message, Image | PointCloud):
            lines.append("")
            lines.append(f"{key} ({schema_type_name(type(message))}), one message:")
            lines.append(describe(message))

    lines.append("")
    detections = [(k, m) for k, m in decoded.items() if isinstance(m, Detection3DArray)]
    if not detections:
        lines.append("detections: none arrived: is the locator running? (`honcho start` starts it)")
    for key, message in detections:
        what = "one detection" if message.detections else "no box in view"
        lines.append(f"{key} ({schema_type_name(Detection3DArray)}), {what}:")
        lines.append(describe(message))
    hint = namespace_hint(list(seen), b.namespace)
    if hint:
        lines += ["", hint]
    return lines


def namespace_hint(keys: list[str], namespace: str) -> str | None:
    """When pipeline keys live under a namespace this run did not ask for, say how to ask."""
    found: set[str] = set()
    for key in keys:
        under = split_namespace(key) if type_for_key(key, namespace) is None else None
        if under is not None:
            found.add(under[0])
    if not found:
        return None
    flag = " or ".join(f"`onebox check --namespace {ns}`" for ns in sorted(found))
    return (
        f"Keys under {', '.join(f'{ns}/' for ns in sorted(found))} look like the pipeline's: "
        f"{flag} reads them with their types"
    )


@dataclass(frozen=True)
class CheckSettings:
    """What ``onebox check`` was asked for."""

    window_s: float
    endpoints: str
    """The routers it connects to, as the user would write them."""


def main(args: argparse.Namespace) -> int:
    default = os.environ.get(bus.ROUTER_ENV) or bus.DEFAULT_ENDPOINT
    settings = CheckSettings(window_s=args.window_s, endpoints=", ".join(args.connect or [default]))
    listener = Listener()
    endpoints = settings.endpoints
    wait_s = min(ROUTER_WAIT_S, settings.window_s)
    nothing = f"nothing is running: no router at {endpoints}. {START_HINT}"
    with contextlib.ExitStack() as stack:
        try:
            b = stack.enter_context(bus.open_bus(args, connect_timeout_s=wait_s))
        except BusError as e:
            raise NothingArrived(
                f"nothing is running: no router at {endpoints}. {START_HINT}"
            ) from e
        # A peer configuration (--config) opens without a router; ask it directly.
        if not wait_for_router(b, wait_s):
            raise NothingArrived(nothing)
        b.subscribe_raw("**", listener.on_sample)
        b.subscribe_raw("tf_static", listener.on_latched, history=True)
        log.info("listening on %s for %g s", b.key("**"), settings.window_s)
        time.sleep(settings.window_s)  # the measuring window itself: rates are counted over it
        seen = listener.snapshot()
        if not seen:
            raise NothingArrived(
                f"the router at {endpoints} is up, but nothing was published in "
                f"{settings.window_s:g} s. {START_HINT}"
            )
        print("\n".join(report(seen, b, settings.window_s)))
    return 0
