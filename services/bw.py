"""Print how many bytes a second a key carries, as ``ros2 topic bw`` did.

    onebox bw camera/image_raw
    onebox bw 'camera/**' --window 50         every camera key, over its newest 50 messages

Reads: KEY (any key expression, under --namespace; any type: only payload sizes are counted).
Writes: the terminal, once a second for each key:

    1.15 MB/s from 25 messages
        Message size mean: 0.23 MB min: 0.23 MB max: 0.23 MB std dev: 0.00 MB window: 25

the bytes of the window's messages over the time from its first message until now (so a key
that stops drops towards 0, as in ros2), and their sizes: mean, smallest, largest and standard
deviation. Sizes are the payloads as they travel (msgpack), in units of 1000 bytes. A key with
nothing new since the last report prints ``no new messages``. Runs until Ctrl-C, or for
--duration-s.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass

from onebox import bus, topic_stats
from onebox.describe import key_expression
from onebox.errors import SettingError

log = logging.getLogger("bw")

DEFAULT_WINDOW = 100
"""Messages the figures cover by default, as ``ros2 topic bw``."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY", help="the key or key expression to measure")
    parser.add_argument(
        "--window",
        "-w",
        type=int,
        default=DEFAULT_WINDOW,
        help=f"how many of the newest messages the figures cover (default {DEFAULT_WINDOW}, "
        "as ros2)",
    )
    parser.add_argument(
        "--duration-s", type=float, help="stop after this many seconds (default: until Ctrl-C)"
    )
    bus.add_arguments(parser)


@dataclass(frozen=True)
class BwSettings:
    """What ``onebox bw`` measures, and for how long."""

    key: str
    window: int
    duration_s: float | None
    period_s: float = 1.0


def settings_from(args: argparse.Namespace) -> BwSettings:
    if args.window < 1:
        raise SettingError(f"--window {args.window}: must be 1 or more")
    if args.duration_s is not None and args.duration_s <= 0:
        raise SettingError(f"--duration-s {args.duration_s:g}: must be above 0")
    return BwSettings(key=key_expression(args.key), window=args.window, duration_s=args.duration_s)


def bandwidth_figures(items: list[tuple[float, int]], now_s: float) -> str | None:
    found = topic_stats.bandwidth(items, now_s)
    return None if found is None else topic_stats.bandwidth_text(found)


def main(args: argparse.Namespace) -> int:
    settings = settings_from(args)
    windows = topic_stats.KeyWindows(settings.window)
    with bus.open_bus(args) as b:
        b.subscribe_raw(settings.key, windows.on_sample)
        log.info("measuring the bandwidth of %s", b.key(settings.key))
        topic_stats.report_until(
            windows,
            bandwidth_figures,
            period_s=settings.period_s,
            duration_s=settings.duration_s,
            name_keys="*" in settings.key,
            out=lambda text: print(text, flush=True),
        )
    return 0
