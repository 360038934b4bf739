"""The base every onebox message shares, and the header of every message about the world."""

from __future__ import annotations

import msgspec


class Message(
    msgspec.Struct,
    frozen=True,
    kw_only=True,
    forbid_unknown_fields=False,
    tag_field="_type",
    tag=True,
):
    """Base of every message on the bus.

    - ``frozen``: a received message is a fact; nothing downstream may edit it in place, and
      frozen structs hash, so they can key caches.
    - ``kw_only``: fields are always named at construction, so adding a field (always with a
      default, at the end) never silently shifts a positional argument.
    - ``forbid_unknown_fields=False``: an older reader ignores fields a newer writer added,
      so the schemas can grow without breaking recordings or running processes.
    - ``tag``: every encoded struct carries its class name in ``_type``, so a decoder rejects a
      message of another type instead of filling it with defaults (all fields have defaults).
    """


class Header(Message, frozen=True, kw_only=True):
    """When a message was true, in simulated time, and the frame its numbers are measured in."""

    stamp_ns: int = 0
    """Simulated time, nanoseconds since the simulation started."""
    frame_id: str = ""
