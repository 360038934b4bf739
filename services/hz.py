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

from onebox import topic_stats


def add_arguments(parser: argparse.ArgumentParser) -> None:
    topic_stats.add_arguments(parser, topic_stats.DEFAULT_WINDOW)


def rate_figures(items: list[tuple[float, int]], now_s: float) -> str | None:
    found = topic_stats.rate(items)
    return None if found is None else topic_stats.rate_text(found)


def main(args: argparse.Namespace) -> int:
    settings = topic_stats.WatchSettings.from_args(args, min_window=2)
    topic_stats.watch(args, settings, rate_figures, "rate")
    return 0
