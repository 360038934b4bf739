"""Rate and bandwidth of a key over a window of its newest messages, as ``ros2 topic hz/bw``.

:class:`Window` is fed from a Zenoh callback (arrival time, payload size) and read from the
thread that prints; :func:`rate` and :func:`bandwidth` are the sums, and :func:`rate_text` and
:func:`bandwidth_text` print them the way ``ros2 topic hz`` and ``ros2 topic bw`` do:

    average rate: 5.001
        min: 0.199s max: 0.201s std dev: 0.00050s window: 25

    1.15 MB/s from 25 messages
        Message size mean: 0.23 MB min: 0.23 MB max: 0.23 MB std dev: 0.00 MB window: 25
"""

from __future__ import annotations

import argparse
import collections
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from onebox import bus
from onebox.describe import key_expression
from onebox.errors import SettingError

DEFAULT_WINDOW = 10_000
"""Messages kept per key, as ``ros2 topic hz`` keeps by default."""


class Window:
    """The arrival times and sizes of a key's newest ``size`` messages; safe across threads."""

    def __init__(self, size: int = DEFAULT_WINDOW) -> None:
        self._items: collections.deque[tuple[float, int]] = collections.deque(maxlen=size)
        self._lock = threading.Lock()
        self.total = 0
        """Messages seen since the start, including those the window no longer holds."""

    def add(self, arrived_s: float, size_bytes: int) -> None:
        with self._lock:
            self._items.append((arrived_s, size_bytes))
            self.total += 1

    def items(self) -> list[tuple[float, int]]:
        with self._lock:
            return list(self._items)


@dataclass(frozen=True)
class Rate:
    """The spacing of messages in a window."""

    average_hz: float
    min_s: float
    max_s: float
    std_s: float
    window: int
    """How many messages the figures cover."""


@dataclass(frozen=True)
class Bandwidth:
    """The bytes a key carries in a window."""

    bytes_per_s: float
    messages: int
    mean_bytes: float
    min_bytes: int
    max_bytes: int
    std_bytes: float


def _std(values: list[float], mean: float) -> float:
    return math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))


def rate(items: list[tuple[float, int]]) -> Rate | None:
    """Rate from arrival times (seconds); None with fewer than two messages."""
    times = [t for t, _ in items]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    if not gaps or sum(gaps) <= 0:
        return None
    mean = sum(gaps) / len(gaps)
    return Rate(1.0 / mean, min(gaps), max(gaps), _std(gaps, mean), len(items))


def bandwidth(items: list[tuple[float, int]], now_s: float) -> Bandwidth | None:
    """Bytes a second over the window, from its first message until ``now_s``, as ``ros2 topic
    bw`` measures it; None when the window is empty or no time has passed."""
    if not items or now_s <= items[0][0]:
        return None
    sizes = [float(n) for _, n in items]
    mean = sum(sizes) / len(sizes)
    return Bandwidth(
        bytes_per_s=sum(sizes) / (now_s - items[0][0]),
        messages=len(items),
        mean_bytes=mean,
        min_bytes=min(n for _, n in items),
        max_bytes=max(n for _, n in items),
        std_bytes=_std(sizes, mean),
    )


def rate_text(r: Rate) -> str:
    """Two lines, as ``ros2 topic hz`` prints them."""
    return (
        f"average rate: {r.average_hz:.3f}\n"
        f"\tmin: {r.min_s:.3f}s max: {r.max_s:.3f}s std dev: {r.std_s:.5f}s window: {r.window}"
    )


def _unit(nbytes: float) -> tuple[float, str]:
    """The unit ``ros2 topic bw`` would print a size in (1000s, not 1024s)."""
    if nbytes < 1000:
        return 1.0, "B"
    if nbytes < 1000**2:
        return 1000.0, "KB"
    return 1000.0**2, "MB"


def bandwidth_text(bw: Bandwidth) -> str:
    """Two lines, as ``ros2 topic bw`` prints them, with the standard deviation and window."""
    rate_scale, rate_unit = _unit(bw.bytes_per_s)
    scale, unit = _unit(bw.mean_bytes)
    return (
        f"{bw.bytes_per_s / rate_scale:.2f} {rate_unit}/s from {bw.messages} messages\n"
        f"\tMessage size mean: {bw.mean_bytes / scale:.2f} {unit} "
        f"min: {bw.min_bytes / scale:.2f} {unit} max: {bw.max_bytes / scale:.2f} {unit} "
        f"std dev: {bw.std_bytes / scale:.2f} {unit} window: {bw.messages}"
    )


class KeyWindows:
    """One :class:`Window` per key a subscription sees; its :meth:`on_sample` is the callback."""

    def __init__(
        self, size: int = DEFAULT_WINDOW, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._size = size
        self._clock = clock
        self._windows: dict[str, Window] = {}
        self._lock = threading.Lock()

    def on_sample(self, key: str, payload: bytes) -> None:
        now = self._clock()
        with self._lock:
            window = self._windows.get(key)
            if window is None:
                window = self._windows[key] = Window(self._size)
        window.add(now, len(payload))

    def windows(self) -> dict[str, Window]:
        """Every key seen so far, sorted, with its window."""
        with self._lock:
            return dict(sorted(self._windows.items()))


def report_until(
    windows: KeyWindows,
    text: Callable[[list[tuple[float, int]], float], str | None],
    *,
    period_s: float,
    duration_s: float | None,
    name_keys: bool,
    out: Callable[[str], None] = print,
    clock: Callable[[], float] = time.monotonic,
) -> None:
    """Every ``period_s``, print ``text(window, now)`` for each key, until ``duration_s`` has
    passed (or forever); a key with nothing new since the last report says so, as ros2 does.

    ``name_keys`` puts each key's name above its figures (for a key expression with wildcards).
    """
    start_s = clock()
    reported: dict[str, int] = {}
    stop = threading.Event()
    while True:
        remaining = None if duration_s is None else start_s + duration_s - clock()
        wait_s = period_s if remaining is None else max(0.0, min(period_s, remaining))
        stop.wait(wait_s)  # the report period itself, as `ros2 topic hz` prints once a second
        now = clock()
        for key, window in windows.windows().items():
            named = len(windows.windows()) > 1 or name_keys
            if reported.get(key) == window.total:
                out(f"{key}: no new messages" if named else "no new messages")
                continue
            figures = text(window.items(), now)
            if figures is None:
                continue
            reported[key] = window.total
            out(f"{key}\n{figures}" if named else figures)
        if duration_s is not None and now - start_s >= duration_s:
            return


Figures = Callable[[list[tuple[float, int]], float], str | None]
"""Turns a window's (arrival time, size) items and the time now into the printed figures."""


def add_arguments(parser: argparse.ArgumentParser, default_window: int) -> None:
    """The flags ``onebox hz`` and ``onebox bw`` share."""
    parser.add_argument("key", metavar="KEY", help="the key or key expression to measure")
    parser.add_argument(
        "--window",
        "-w",
        type=int,
        default=default_window,
        help=f"how many of the newest messages the figures cover (default {default_window}, "
        "as ros2)",
    )
    parser.add_argument(
        "--duration-s", type=float, help="stop after this many seconds (default: until Ctrl-C)"
    )
    bus.add_arguments(parser)


@dataclass(frozen=True)
class WatchSettings:
    """What ``onebox hz`` or ``onebox bw`` measures, and for how long."""

    key: str
    window: int
    duration_s: float | None
    period_s: float = 1.0

    @classmethod
    def from_args(cls, args: argparse.Namespace, min_window: int) -> WatchSettings:
        if args.window < min_window:
            raise SettingError(
                f"--window {args.window}: must be {min_window} or more"
                + (" (a rate needs two messages)" if min_window == 2 else "")
            )
        if args.duration_s is not None and args.duration_s <= 0:
            raise SettingError(f"--duration-s {args.duration_s:g}: must be above 0")
        return cls(key=key_expression(args.key), window=args.window, duration_s=args.duration_s)


def watch(args: argparse.Namespace, settings: WatchSettings, figures: Figures, what: str) -> None:
    """Subscribe to the key and print its figures every period until stopped."""
    windows = KeyWindows(settings.window)
    with bus.open_bus(args) as b:
        b.subscribe_raw(settings.key, windows.on_sample)
        logging.getLogger("topic").info("measuring the %s of %s", what, b.key(settings.key))
        report_until(
            windows,
            figures,
            period_s=settings.period_s,
            duration_s=settings.duration_s,
            name_keys="*" in settings.key,
            out=lambda text: print(text, flush=True),
        )
