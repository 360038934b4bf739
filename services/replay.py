"""Publish an MCAP recording back onto its keys, as ``ros2 bag play`` did.

    onebox replay tests/data/one_box.mcap
    onebox replay run.mcap --rate 0 --keys 'camera/**'   as fast as possible, cameras only
    onebox replay run.mcap --loop                        again and again until Ctrl-C

Reads: FILE.mcap (a file cut short by a killed recorder needs ``--recover``).
Writes: each recorded key, as recorded (under ``--namespace`` when given), the recorded bytes
unchanged, in log-time order, spaced as recorded divided by ``--rate`` (0: as fast as
possible). ``--loop`` pauses between passes for the recording's mean spacing (a snapshot
repeats at 5 Hz). Publishers block rather than drop, so a slow subscriber slows the replay
instead of losing messages; replay waits up to ``--wait-s`` for a subscriber before it starts,
so the first messages are not published to nobody. ``tf_static`` is published latched, so a
process that starts during the replay still receives it.
``clock``: when the recording has a ``clock`` channel it is replayed like any other key;
otherwise a Clock is synthesised from the header stamps (the publish times of keys whose type
has a header) and published on ``clock`` just before the first message of each new stamp, so
downstream sees the recorded simulated time either way. ``--no-clock`` turns both off.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import zenoh

from onebox import bus
from onebox.errors import RecordingError
from onebox.keys import type_for_key
from onebox.recording import TYPES_BY_NAME, Recorded, describe, has_header, iter_messages
from schemas import Clock, Message, codec

log = logging.getLogger("replay")

CLOCK = "clock"
TF_STATIC = "tf_static"
MIN_PERIOD_S = 0.2
LINGER_S = 0.3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, metavar="FILE.mcap", help="the recording to replay")
    parser.add_argument(
        "--rate",
        type=float,
        default=1.0,
        help="speed: 1 as recorded, 2 twice as fast, 0 as fast as possible (default 1)",
    )
    parser.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    parser.add_argument(
        "--keys",
        action="append",
        metavar="EXPR",
        help="replay only keys matching this key expression, repeatable (default: all)",
    )
    parser.add_argument(
        "--no-clock", action="store_true", help="neither replay nor synthesise clock"
    )
    parser.add_argument(
        "--wait-s",
        type=float,
        default=2.0,
        help="wait this long for a subscriber before starting (default 2; 0 to start at once)",
    )
    parser.add_argument(
        "--recover",
        action="store_true",
        help="replay the complete chunks of a file whose recorder was killed",
    )
    bus.add_arguments(parser)


def is_key(key: str, name: str) -> bool:
    """Whether a recorded key is ``name`` under some namespace (``robot1/tf_static``)."""
    return key == name or key.endswith(f"/{name}")


def selected(keys: list[str], exprs: list[str] | None) -> list[str]:
    """The recorded keys that match any of ``exprs`` (all of them without exprs)."""
    if not exprs:
        return keys
    try:
        wanted = [zenoh.KeyExpr(e) for e in exprs]
    except zenoh.ZError as e:
        raise RecordingError(f"--keys {exprs}: not a Zenoh key expression: {e}") from e
    return [k for k in keys if any(w.intersects(zenoh.KeyExpr(k)) for w in wanted)]


class Pacer:
    """Waits until each message's recorded time, scaled by the rate, has come."""

    def __init__(self, rate: float) -> None:
        if rate < 0:
            raise RecordingError(f"--rate {rate}: must be 0 (as fast as possible) or more")
        self._rate = rate
        self._first_log_ns: int | None = None
        self._start_s = 0.0

    def restart(self) -> None:
        self._first_log_ns = None

    def wait(self, log_time_ns: int) -> None:
        if self._rate == 0:
            return
        if self._first_log_ns is None:
            self._first_log_ns = log_time_ns
            self._start_s = time.monotonic()
            return
        due_s = self._start_s + (log_time_ns - self._first_log_ns) / 1e9 / self._rate
        delay_s = due_s - time.monotonic()
        if delay_s > 0:
            time.sleep(delay_s)  # pacing, not synchronisation: the recording's own spacing


def loop_gap(duration_s: float, message_count: int, rate: float) -> float:
    """The pause between two passes of ``--loop``: the recording's mean spacing.

    A recording shorter than 0.2 s (a snapshot) repeats every 0.2 s, the sim's 5 Hz, rather
    than flooding the bus.
    """
    if rate == 0:
        return 0.0
    mean_spacing_s = duration_s / (message_count - 1) if message_count > 1 else 0.0
    return max(mean_spacing_s, MIN_PERIOD_S - duration_s) / rate


def message_type(recorded: Recorded, namespace: str) -> type[Message] | None:
    return TYPES_BY_NAME.get(recorded.schema_name) or type_for_key(recorded.key, namespace)


def replay_once(
    b: bus.Bus,
    messages: Iterator[Recorded],
    publishers: dict[str, bus.Publisher[Message]],
    pacer: Pacer,
    clock: bus.Publisher[Clock] | None,
) -> int:
    """Publish one pass of the recording; returns how many messages were published."""
    count = 0
    last_clock_ns = -1
    clock_codec = codec(Clock)
    pacer.restart()
    for recorded in messages:
        pacer.wait(recorded.log_time_ns)
        publisher = publishers.get(recorded.key)
        if publisher is None:
            publisher = b.publisher(
                recorded.key,
                message_type(recorded, "") or Message,
                latched=is_key(recorded.key, TF_STATIC),
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
            publishers[recorded.key] = publisher
        if (
            clock is not None
            and recorded.publish_time_ns > last_clock_ns
            and has_header(message_type(recorded, ""))
        ):
            last_clock_ns = recorded.publish_time_ns
            clock.publish_bytes(clock_codec.encode(Clock(clock_ns=last_clock_ns)))
        publisher.publish_bytes(recorded.payload)
        count += 1
    return count


def wait_for_subscribers(b: bus.Bus, timeout_s: float) -> bool:
    """Wait until this session knows of a subscriber to any key, at most ``timeout_s``.

    A new session learns the routes to existing subscribers a few ms after it opens; what it
    publishes before that reaches nobody, which would cost a replay its first messages. A
    publisher on ``**`` matches a subscriber on any key.
    """
    return b.publisher("**", Message).wait_for_subscribers(timeout_s)


@dataclass(frozen=True)
class ReplaySettings:
    """What ``onebox replay`` was asked to do, checked."""

    path: Path
    rate: float
    loop: bool
    exprs: list[str] | None
    clock: bool
    wait_s: float
    recover: bool

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ReplaySettings:
        if not args.rate >= 0 or args.rate == float("inf"):
            raise RecordingError(f"--rate {args.rate}: must be 0 (as fast as possible) or more")
        if not args.wait_s >= 0:
            raise RecordingError(f"--wait-s {args.wait_s}: must be 0 or more seconds")
        return cls(
            path=args.file,
            rate=args.rate,
            loop=args.loop,
            exprs=args.keys,
            clock=not args.no_clock,
            wait_s=args.wait_s,
            recover=args.recover,
        )


def main(args: argparse.Namespace) -> int:
    config = ReplaySettings.from_args(args)
    path = config.path
    info = describe(path, recover=config.recover)
    recorded_keys = [k.key for k in info.keys]
    keys = selected(recorded_keys, config.exprs)
    has_clock = any(is_key(k, CLOCK) for k in recorded_keys)
    if has_clock and config.clock:
        keys = sorted(set(keys) | {k for k in recorded_keys if is_key(k, CLOCK)})
    if not keys:
        raise RecordingError(
            f"{path} has no key matching {' '.join(config.exprs or [])}: it has "
            f"{', '.join(recorded_keys) or 'no messages'}"
        )
    pacer = Pacer(config.rate)
    loop_gap_s = loop_gap(info.duration_s, info.message_count, config.rate)
    if has_clock or not config.clock:
        how = "as recorded" if has_clock and config.clock else "off"
    else:
        how = "synthesised from the header stamps"
    log.info(
        "replaying %s: %d keys, %d messages, %.1f s at rate %g; clock %s",
        path,
        len(keys),
        sum(k.count for k in info.keys if k.key in keys),
        info.duration_s,
        config.rate,
        how,
    )
    with bus.open_bus(args) as b:
        if not wait_for_subscribers(b, config.wait_s):
            log.info("no subscriber yet after %g s; replaying anyway", config.wait_s)
        publishers: dict[str, bus.Publisher[Message]] = {}
        clock = None
        if not has_clock and config.clock:
            clock = b.publisher(CLOCK, Clock, congestion_control=zenoh.CongestionControl.BLOCK)
        passes = 0
        try:
            while True:
                if passes:
                    time.sleep(loop_gap_s)  # pacing between passes, as between messages
                messages = iter_messages(path, keys, recover=config.recover)
                count = replay_once(b, messages, publishers, pacer, clock)
                passes += 1
                if sys.stderr.isatty():
                    sys.stderr.write(f"\r\x1b[K{path}: pass {passes}, {count} messages")
                    sys.stderr.flush()
                if not config.loop:
                    break
        except KeyboardInterrupt:
            pass  # Ctrl-C or SIGTERM: stop replaying; the session closes below
        finally:
            if sys.stderr.isatty():
                sys.stderr.write("\n")
            # Zenoh has no flush: give what is still queued for the network time to leave
            # before the session closes, or the last messages of a fast replay are lost.
            time.sleep(LINGER_S)
    log.info("replayed %s (%d passes)", path, passes)
    return 0
