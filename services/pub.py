"""Publish a message typed from JSON, as ``ros2 topic pub`` did: for trying a process by hand.

    onebox pub detections Detection3DArray '{"detections": []}'
    onebox pub clock onebox.sim.Clock '{"clock_ns": 2000000000}' --rate 5
    onebox pub detections Detection3DArray "$(cat boxes.json)" --rate 2 --times 10

TYPE is a message's class name (``Detection3DArray``) or its full name, as recordings and
``onebox check`` name it (``onebox.vision.Detection3DArray``). JSON gives the fields to set,
named as in the schema (``schemas/``); every field left out keeps its default, bytes are
base64. JSON that does not fit the type (a field that does not exist, a value of the wrong
kind) is one line saying where, and nothing is published. A key the key table knows must get
its own type.

Writes: KEY (under --namespace), msgpack exactly as the pipeline's publishers write it.
``--once`` (the default) waits up to --wait-s for a subscriber, publishes once and exits;
``--rate HZ`` publishes again every 1/HZ s until Ctrl-C, or --times messages.
"""

from __future__ import annotations

import argparse
import difflib
import logging
import threading
import time
from dataclasses import dataclass
from typing import Any

import msgspec

import schemas
from onebox import bus
from onebox.describe import key_expression, type_of
from onebox.errors import SettingError
from schemas import Message, type_name

log = logging.getLogger("pub")

LINGER_S = 0.3
"""Zenoh has no flush: time for the last message to leave before the session closes."""

MESSAGE_TYPES: dict[str, type[Message]] = {
    name: cls
    for name, cls in sorted(vars(schemas).items())
    if isinstance(cls, type) and issubclass(cls, Message) and cls is not Message
}
"""Every message type by its class name; :func:`message_type` also takes the full name."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY", help="the key to publish on (no wildcards)")
    parser.add_argument(
        "type",
        metavar="TYPE",
        help="the message type: Detection3DArray or onebox.vision.Detection3DArray; one of "
        + ", ".join(MESSAGE_TYPES),
    )
    parser.add_argument(
        "json", metavar="JSON", help="the message's fields as JSON, e.g. '{\"detections\": []}'"
    )
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--once", action="store_true", help="publish once and exit (the default)")
    how.add_argument("--rate", type=float, metavar="HZ", help="publish HZ times a second")
    parser.add_argument(
        "--times", type=int, metavar="N", help="with --rate: stop after N messages (default: never)"
    )
    parser.add_argument(
        "--wait-s",
        type=float,
        default=2.0,
        help="wait this long for a subscriber before the first message (default 2; 0: at once)",
    )
    bus.add_arguments(parser)


def message_type(name: str) -> type[Message]:
    """The type named ``Detection3DArray`` or ``onebox.vision.Detection3DArray``."""
    by_full_name = {type_name(t): t for t in MESSAGE_TYPES.values()}
    found = MESSAGE_TYPES.get(name) or by_full_name.get(name)
    if found is not None:
        return found
    close = difflib.get_close_matches(name, [*MESSAGE_TYPES, *by_full_name], n=1)
    hint = f"did you mean {close[0]}? " if close else ""
    raise SettingError(f"no message type {name!r}: {hint}Types: {', '.join(MESSAGE_TYPES)}")


def _unknown_field(value: Any, info: msgspec.inspect.Type, path: str) -> str | None:
    """The first field in ``value`` the type does not have, as ``$.a[0].b``; None if none.

    The messages accept unknown fields (so old readers survive new writers), but a person
    typing ``detectionz`` wants to hear of it, not to publish an empty message.
    """
    if isinstance(info, msgspec.inspect.StructType) and isinstance(value, dict):
        fields = {f.encode_name: f for f in info.fields}
        for name, inner in value.items():
            if name == info.tag_field:
                continue
            field = fields.get(name)
            if field is None:
                close = difflib.get_close_matches(name, fields, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                return f"`{path}.{name}`{hint}; {info.cls.__name__} has {', '.join(fields)}"
            found = _unknown_field(inner, field.type, f"{path}.{name}")
            if found:
                return found
    elif isinstance(info, msgspec.inspect.ListType) and isinstance(value, list):
        for i, item in enumerate(value):
            found = _unknown_field(item, info.item_type, f"{path}[{i}]")
            if found:
                return found
    elif isinstance(info, msgspec.inspect.UnionType):
        for option in info.types:
            found = _unknown_field(value, option, path)
            if found:
                return found
    return None


def parse_message(text: str, wanted: type[Message]) -> Message:
    """``text`` (JSON) as a ``wanted``; a one-line SettingError saying where it does not fit."""
    name = wanted.__name__
    try:
        message = msgspec.json.decode(text, type=wanted)
        unknown = _unknown_field(msgspec.json.decode(text), msgspec.inspect.type_info(wanted), "$")
    except msgspec.ValidationError as e:
        raise SettingError(f"the JSON is not a {name}: {e}") from None
    except msgspec.DecodeError as e:
        raise SettingError(f"the JSON does not parse: {e} (quote it in single quotes)") from None
    if unknown:
        raise SettingError(f"the JSON is not a {name}: no field {unknown}")
    return message


@dataclass(frozen=True)
class PubSettings:
    """What ``onebox pub`` publishes, where, and how often."""

    key: str
    message: Message
    period_s: float | None
    """None: publish once."""
    times: int | None
    wait_s: float


def settings_from(args: argparse.Namespace) -> PubSettings:
    key = key_expression(args.key)
    if "*" in key or "$" in key:
        raise SettingError(f"{key}: publish on one key, without wildcards")
    wanted = message_type(args.type)
    carried = type_of(key, args.namespace or "")
    if carried is not None and carried is not wanted:
        raise SettingError(
            f"{key} carries {type_name(carried)} (by the key table), not {type_name(wanted)}: "
            f"its subscribers would drop it"
        )
    if args.rate is not None and args.rate <= 0:
        raise SettingError(
            f"--rate {args.rate:g}: must be above 0 (or leave it out to publish once)"
        )
    if args.times is not None and (args.rate is None or args.times < 1):
        raise SettingError(f"--times {args.times}: goes with --rate, and must be 1 or more")
    if args.wait_s < 0:
        raise SettingError(f"--wait-s {args.wait_s:g}: must be 0 or more")
    return PubSettings(
        key=key,
        message=parse_message(args.json, wanted),
        period_s=None if args.rate is None else 1.0 / args.rate,
        times=args.times,
        wait_s=args.wait_s,
    )


def main(args: argparse.Namespace) -> int:
    settings = settings_from(args)
    with bus.open_bus(args) as b:
        publisher = b.publisher(settings.key, type(settings.message))
        if settings.wait_s > 0 and not publisher.wait_for_subscribers(settings.wait_s):
            log.warning(
                "no subscriber on %s after %g s; publishing anyway", publisher.key, settings.wait_s
            )
        if settings.period_s is None:
            publisher.publish(settings.message)
            log.info("published one %s on %s", type(settings.message).__name__, publisher.key)
        else:
            publish_at_rate(publisher, settings)
        time.sleep(LINGER_S)  # Zenoh has no flush: let the last message leave before closing
    return 0


def publish_at_rate(publisher: bus.Publisher[Message], settings: PubSettings) -> None:
    """Publish every ``period_s`` on a fixed schedule (no drift), until Ctrl-C or ``times``."""
    assert settings.period_s is not None
    log.info(
        "publishing %s on %s every %g s",
        type(settings.message).__name__,
        publisher.key,
        settings.period_s,
    )
    tick = threading.Event()
    start_s = time.monotonic()
    count = 0
    while settings.times is None or count < settings.times:
        if count:
            tick.wait(max(0.0, start_s + count * settings.period_s - time.monotonic()))
        publisher.publish(settings.message)
        count += 1
