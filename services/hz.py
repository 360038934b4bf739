"""Print how often messages arrive on a key, as ``ros2 topic hz`` did.

    onebox hz camera/image_raw
    onebox hz 'camera/**' --window 50         every camera key, over its newest 50 messages

Reads: KEY (any key expression, under --namespace; any type: only arrivals are counted).
Writes: the terminal, once a second for each key:

    average rate: 5.001
        min: 0.199s max: 0.201s std dev: 0.00050s window: 25

the mean rate over the window of newest messages, and the shortest, longest and standard
deviation of the gaps between them (arrival times at this process). A key with nothing new
since the last report prints ``no new messages``. Runs until Ctrl-C, or for --duration-s.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass

from onebox import bus, topic_stats
from onebox.describe import key_expression
from onebox.errors import SettingError

log = logging.getLogger("hz")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY", help="the key or key expression to measure")
    parser.add_argument(
        "--window",
        "-w",
        type=int,
        default=topic_stats.DEFAULT_WINDOW,
        help=f"how many of the newest messages the figures cover (default "
        f"{topic_stats.DEFAULT_WINDOW}, as ros2)",
    )
    parser.add_argument(
        "--duration-s", type=float, help="stop after this many seconds (default: until Ctrl-C)"
    )
    bus.add_arguments(parser)


@dataclass(frozen=True)
class HzSettings:
    """What ``onebox hz`` measures, and for how long."""

    key: str
    window: int
    duration_s: float | None
    period_s: float = 1.0


def settings_from(args: argparse.Namespace) -> HzSettings:
    if args.window < 2:
        raise SettingError(f"--window {args.window}: a rate needs at least 2 messages")
    if args.duration_s is not None and args.duration_s <= 0:
        raise SettingError(f"--duration-s {args.duration_s:g}: must be above 0")
    return HzSettings(key=key_expression(args.key), window=args.window, duration_s=args.duration_s)


def rate_figures(items: list[tuple[float, int]], now_s: float) -> str | None:
    found = topic_stats.rate(items)
    return None if found is None else topic_stats.rate_text(found)


def main(args: argparse.Namespace) -> int:
    settings = settings_from(args)
    windows = topic_stats.KeyWindows(settings.window)
    with bus.open_bus(args) as b:
        b.subscribe_raw(settings.key, windows.on_sample)
        log.info("measuring the rate of %s", b.key(settings.key))
        topic_stats.report_until(
            windows,
            rate_figures,
            period_s=settings.period_s,
            duration_s=settings.duration_s,
            name_keys="*" in settings.key,
            out=lambda text: print(text, flush=True),
        )
    return 0
