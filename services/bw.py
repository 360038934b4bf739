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

from onebox import topic_stats

DEFAULT_WINDOW = 100
"""Messages the figures cover by default, as ``ros2 topic bw``."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    topic_stats.add_arguments(parser, DEFAULT_WINDOW)


def bandwidth_figures(items: list[tuple[float, int]], now_s: float) -> str | None:
    found = topic_stats.bandwidth(items, now_s)
    return None if found is None else topic_stats.bandwidth_text(found)


def main(args: argparse.Namespace) -> int:
    settings = topic_stats.WatchSettings.from_args(args, min_window=1)
    topic_stats.watch(args, settings, bandwidth_figures, "bandwidth")
    return 0
