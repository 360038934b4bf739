"""Synchronisation: matching messages by stamp, noticing time going back, bounded queues.

- :class:`StampMatcher` pairs the messages of several streams taken at the same moment
  (message_filters' job), exactly or within a slop.
- :class:`StampClock` notices a key's stamps going back (a restarted sim or replay).
- :class:`NewestQueue` is the bounded queue between a Zenoh callback and a worker: when the
  worker is slow the oldest item is dropped, counted, and the newest kept.
- :class:`ReportLimiter` logs a problem once per key per interval, with how many were held back.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

T = TypeVar("T")


class ReportLimiter:
    """Logs a problem once per key per interval, with how many were held back in between."""

    def __init__(self, logger: logging.Logger, interval_s: float = 2.0) -> None:
        self._logger = logger
        self._interval_s = interval_s
        self._last: dict[tuple[str, str], float] = {}
        self._held: collections.Counter[tuple[str, str]] = collections.Counter()
        self._lock = threading.Lock()

    def warn(self, key: str, kind: str, message: str) -> None:
        """Log ``message`` about ``key`` unless one of the same ``kind`` was logged lately."""
        now = time.monotonic()
        slot = (key, kind)
        with self._lock:
            last = self._last.get(slot)
            if last is not None and now - last < self._interval_s:
                self._held[slot] += 1
                return
            held = self._held.pop(slot, 0)
            self._last[slot] = now
        more = f" ({held} more like it since the last report)" if held else ""
        self._logger.warning("%s: %s%s", key, message, more)


class NewestQueue(Generic[T]):
    """A bounded queue that, when full, drops the oldest item and counts it."""

    def __init__(self, maxlen: int = 2) -> None:
        self._items: collections.deque[T] = collections.deque(maxlen=maxlen)
        self._ready = threading.Condition()
        self.dropped = 0

    def put(self, item: T) -> None:
        with self._ready:
            if len(self._items) == self._items.maxlen:
                self.dropped += 1
            self._items.append(item)
            self._ready.notify()

    def get(self, timeout_s: float | None = None) -> T | None:
        """The oldest item kept, or None when nothing came within ``timeout_s``."""
        with self._ready:
            if not self._ready.wait_for(lambda: bool(self._items), timeout=timeout_s):
                return None
            return self._items.popleft()

    def __len__(self) -> int:
        with self._ready:
            return len(self._items)


@dataclass(frozen=True)
class Stamped:
    """One decoded message waiting for its partners."""

    stamp_ns: int
    item: Any
    arrived_s: float


class StampMatcher:
    """Pairs messages of several streams taken at the same moment (message_filters' job).

    The first stream leads: each of its messages is matched with the message of every other
    stream whose stamp is nearest, if no further than ``slop_ns`` (0: equal stamps only).
    Each stream keeps at most ``queue_size`` messages, dropping its oldest; a lead message
    dropped unmatched is handed to ``on_unmatched``.
    """

    def __init__(
        self,
        streams: Sequence[str],
        *,
        slop_ns: int = 0,
        queue_size: int = 4,
        on_unmatched: Callable[[Stamped, str], None] | None = None,
    ) -> None:
        self.streams = tuple(streams)
        self.exact = slop_ns == 0
        self._slop_ns = slop_ns
        self._queues: dict[str, collections.deque[Stamped]] = {
            s: collections.deque(maxlen=queue_size) for s in self.streams
        }
        self._on_unmatched = on_unmatched
        self._lock = threading.Lock()

    def add(self, stream: str, stamp_ns: int, item: Any) -> dict[str, Stamped] | None:
        """Keep ``item``; return a complete set (one Stamped per stream) once one exists."""
        lost: list[Stamped] = []
        with self._lock:
            queue = self._queues[stream]
            if stream == self.streams[0] and len(queue) == queue.maxlen:
                lost.append(queue[0])
            queue.append(Stamped(stamp_ns, item, time.monotonic()))
            matched = self._match(lost)
        for stamped in lost:
            self._unmatched(stamped, "a newer capture came first")
        return matched

    def _match(self, lost: list[Stamped]) -> dict[str, Stamped] | None:
        lead = self._queues[self.streams[0]]
        for lead_item in reversed(lead):  # the newest first: it wins
            found = {self.streams[0]: lead_item}
            for stream in self.streams[1:]:
                queue = self._queues[stream]
                if not queue:
                    break
                nearest = min(queue, key=lambda s: abs(s.stamp_ns - lead_item.stamp_ns))
                if abs(nearest.stamp_ns - lead_item.stamp_ns) > self._slop_ns:
                    break
                found[stream] = nearest
            else:
                for stream, used in found.items():
                    queue = self._queues[stream]
                    while queue and queue[0].stamp_ns <= used.stamp_ns:
                        dropped = queue.popleft()
                        if stream == self.streams[0] and dropped is not used:
                            lost.append(dropped)
                return found
        return None

    def expire(self, max_age_s: float) -> None:
        """Report and drop lead messages that waited more than ``max_age_s`` for partners."""
        now = time.monotonic()
        lost: list[Stamped] = []
        with self._lock:
            lead = self._queues[self.streams[0]]
            while lead and now - lead[0].arrived_s > max_age_s:
                lost.append(lead.popleft())
        for stamped in lost:
            self._unmatched(stamped, f"nothing matched it within {max_age_s:g} s")

    def clear(self) -> None:
        """Forget everything waiting (time went back: nothing old can match the new)."""
        with self._lock:
            for queue in self._queues.values():
                queue.clear()

    def _unmatched(self, stamped: Stamped, why: str) -> None:
        if self._on_unmatched is not None:
            self._on_unmatched(stamped, why)


class StampClock:
    """Notices a key's stamps going back; the message that went back is dropped and reported,
    and the key carries on from its new time (a restarted sim, a replay started again)."""

    def __init__(self) -> None:
        self._last: dict[str, int] = {}
        self._lock = threading.Lock()

    def went_back(self, key: str, stamp_ns: int) -> int | None:
        """The previous stamp on ``key`` if ``stamp_ns`` is older than it, else None."""
        with self._lock:
            last = self._last.get(key)
            self._last[key] = stamp_ns
        return last if last is not None and stamp_ns < last else None

    def accept(self, key: str, stamp_ns: int, report: ReportLimiter, matcher: StampMatcher) -> bool:
        """True if ``stamp_ns`` does not go back on ``key``; otherwise report it, forget the
        half-made matches (they belong to the old time) and return False."""
        previous = self.went_back(key, stamp_ns)
        if previous is None:
            return True
        report.warn(
            key,
            "stamp",
            f"stamp went back from {previous:,} ns to {stamp_ns:,} ns, dropped; carrying on "
            "from the new time (was the sim or a replay restarted?)",
        )
        matcher.clear()
        return False
