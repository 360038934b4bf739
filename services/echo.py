"""Print every message on a key, readable, as ``ros2 topic echo`` did.

    onebox echo detections
    onebox echo camera/camera_info --once
    onebox echo 'camera/**' --json | jq .key            one JSON object a line
    onebox echo tf_static --namespace robot1            robot1/tf_static

Reads: KEY (any key expression, under --namespace), and the last sample of a latched key
(``tf_static``) published before it started. Writes: the terminal. Each message is decoded by
the key table's type and printed as indented ``field: value`` lines, then ``---``; bytes and
lists longer than 16 values are summarised as ``data: <230,400 bytes>`` (``--full`` prints
them). A key expression with wildcards puts ``# KEY (TYPE)`` above each message. A key the
table does not know (or a message that does not decode as its key's type) is printed from its
raw msgpack, under a ``#`` line that says so.

``--json`` prints one JSON object a line instead: ``{"key": ..., "type": ..., "message": ...}``
(the type null for a raw message; with ``--full``, bytes are base64). ``--once`` exits after
the first message; ``--timeout-s`` exits 2 when nothing arrives in that time.
"""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import dataclass

import msgspec

from onebox import bus, describe
from onebox.errors import NothingArrived, SettingError
from onebox.sync import NewestQueue
from schemas import Message, codec, type_name

log = logging.getLogger("echo")

QUEUE_LENGTH = 64
"""Messages waiting to be printed; when the terminal is slower, the oldest are dropped."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY", help="the key or key expression to print")
    parser.add_argument("--once", action="store_true", help="print one message and exit")
    parser.add_argument(
        "--json", action="store_true", help="one JSON object a line, for jq and scripts"
    )
    parser.add_argument(
        "--full", action="store_true", help="print bytes and long lists whole, not summarised"
    )
    parser.add_argument(
        "--timeout-s",
        type=float,
        help="exit 2 when no message arrives in this time (default: wait until Ctrl-C)",
    )
    bus.add_arguments(parser)


@dataclass(frozen=True)
class EchoSettings:
    """What ``onebox echo`` prints, and how."""

    key: str
    namespace: str
    once: bool
    json: bool
    full: bool
    timeout_s: float | None
    name_keys: bool
    """Put each message's key above it: the expression can match several keys."""


def settings_from(args: argparse.Namespace) -> EchoSettings:
    if args.timeout_s is not None and args.timeout_s <= 0:
        raise SettingError(f"--timeout-s {args.timeout_s:g}: must be above 0")
    key = describe.key_expression(args.key)
    return EchoSettings(
        key=key,
        namespace=args.namespace or "",
        once=args.once,
        json=args.json,
        full=args.full,
        timeout_s=args.timeout_s,
        name_keys="*" in key or "$" in key,
    )


class Printer:
    """Turns (key, payload) into the text ``onebox echo`` prints."""

    def __init__(self, settings: EchoSettings) -> None:
        self.settings = settings

    def decoded(self, key: str, payload: bytes) -> tuple[type[Message] | None, Message | None]:
        message_type = describe.type_of(key, self.settings.namespace)
        if message_type is None:
            return None, None
        try:
            return message_type, codec(message_type).decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError) as e:
            log.warning("%s: not a %s (%s); printed raw", key, type_name(message_type), e)
            return message_type, None

    def text(self, key: str, payload: bytes) -> str:
        message_type, message = self.decoded(key, payload)
        full = self.settings.full
        if self.settings.json:
            if message is not None and message_type is not None:
                found: dict[str, object] = {
                    "key": key,
                    "type": type_name(message_type),
                    "message": describe.to_builtins(message, full=full),
                }
            else:
                found = {"key": key, "type": None, "message": describe.raw_builtins(payload)}
            return msgspec.json.encode(found).decode()
        if message is not None and message_type is not None:
            head = f"# {key} ({type_name(message_type)})\n" if self.settings.name_keys else ""
            return f"{head}{describe.describe(message, 0, full=full)}\n---"
        why = "not a onebox key" if message_type is None else "does not decode"
        return f"# {key}: {why}, raw msgpack\n{describe.raw(payload, full=full)}\n---"


def main(args: argparse.Namespace) -> int:
    settings = settings_from(args)
    printer = Printer(settings)
    waiting: NewestQueue[tuple[str, bytes]] = NewestQueue(QUEUE_LENGTH)
    with bus.open_bus(args) as b:
        # history: a latched key's last sample (tf_static) reaches a late echo too.
        b.subscribe_raw(
            settings.key, lambda key, payload: waiting.put((key, payload)), history=True
        )
        log.info("printing %s", b.key(settings.key))
        dropped = 0
        while True:
            item = waiting.get(settings.timeout_s)
            if item is None:
                raise NothingArrived(
                    f"nothing arrived on {b.key(settings.key)} within {settings.timeout_s:g} s: "
                    "`onebox check` lists what is published"
                )
            if waiting.dropped > dropped:
                print(
                    f"onebox echo: {waiting.dropped - dropped} messages dropped: "
                    "the terminal is slower than the key",
                    file=sys.stderr,
                )
                dropped = waiting.dropped
            print(printer.text(*item), flush=True)
            if settings.once:
                return 0
