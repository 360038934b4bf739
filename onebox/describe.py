"""Messages as text a person reads: indented ``field: value`` lines, large arrays summarised.

``onebox check`` and ``onebox echo`` print messages through this module, so both print them the
same way, the way ``ros2 topic echo`` does:

    header:
      stamp_ns: 1800000000
      frame_id: camera_optical_frame
    height: 240
    encoding: rgb8
    data: <230,400 bytes>

Bytes and lists longer than :data:`SHOWN_IN_FULL` become a note of their length; ``full=True``
keeps everything. A payload whose key the key table does not know is shown as its raw msgpack
(:func:`raw`), so an unknown publisher can still be read.
"""

from __future__ import annotations

from typing import Any

import msgspec
import zenoh

from onebox.errors import SettingError
from onebox.keys import TYPES, type_for_key
from schemas import Message

SHOWN_IN_FULL = 16
"""A list longer than this (or any bytes) is left out and described by its length."""


def brief(value: Any, *, full: bool = False) -> Any:
    """``value`` (builtins) with bytes and long lists replaced by a note of their length.

    The ``_type`` tag each encoded struct carries is dropped: the type is named elsewhere.
    """
    if isinstance(value, bytes | bytearray | memoryview):
        return bytes(value) if full else f"<{len(value):,} bytes>"
    if isinstance(value, dict):
        return {str(k): brief(v, full=full) for k, v in value.items() if k != "_type"}
    if isinstance(value, list | tuple):
        if len(value) > SHOWN_IN_FULL and not full:
            return f"<{len(value):,} values>"
        return [brief(v, full=full) for v in value]
    return value


def lines(value: Any, indent: int = 0) -> list[str]:
    """``value`` (builtins, after :func:`brief`) as YAML-like lines, two spaces a level."""
    pad = "  " * indent
    out: list[str] = []
    if isinstance(value, dict):
        for k, v in value.items():
            if isinstance(v, dict | list) and v and not _flat(v):
                out.append(f"{pad}{k}:")
                out.extend(lines(v, indent + 1))
            else:
                out.append(f"{pad}{k}: {_scalar(v)}")
    elif isinstance(value, list):
        for item in value:
            inner = lines(item, indent + 1)
            out.append(f"{pad}- {inner[0].strip()}" if inner else f"{pad}-")
            out.extend(inner[1:])
    else:
        out.append(f"{pad}{_scalar(value)}")
    return out


def _flat(value: dict[str, Any] | list[Any]) -> bool:
    """A list of plain numbers prints on one line, as ``[277.1, 0, 159.5, ...]``."""
    return isinstance(value, list) and all(not isinstance(v, dict | list) for v in value)


def _scalar(value: Any) -> str:
    if isinstance(value, float):
        text = f"{value:.6g}"
        # A float stays a float to the eye, as ROS prints it: 1.0, not 1 (an int field's 1).
        return text if any(c in text for c in ".enai") else f"{text}.0"
    if isinstance(value, list):
        return "[" + ", ".join(_scalar(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{}"
    if isinstance(value, str):
        return value if value else "''"
    if isinstance(value, bytes):
        return value.hex()
    if value is None:
        return "null"
    return str(value)


def to_builtins(message: Message, *, full: bool = False) -> Any:
    """A message as dicts, lists and scalars, large arrays summarised unless ``full``."""
    return brief(msgspec.to_builtins(message, builtin_types=(bytes,)), full=full)


def describe(message: Message, indent: int = 1, *, full: bool = False) -> str:
    """The message as indented ``field: value`` lines, large arrays left out."""
    return "\n".join(lines(to_builtins(message, full=full), indent))


def raw(payload: bytes, indent: int = 0, *, full: bool = False) -> str:
    """A payload of no known type: its msgpack as lines, or its length when it is not msgpack."""
    try:
        value = msgspec.msgpack.decode(payload)
    except msgspec.DecodeError:
        return "  " * indent + f"<{len(payload):,} bytes, not msgpack>"
    return "\n".join(lines(brief(value, full=full), indent))


def raw_builtins(payload: bytes, *, full: bool = False) -> Any:
    """A payload of no known type as builtins (None when it is not msgpack)."""
    try:
        return brief(msgspec.msgpack.decode(payload), full=full)
    except msgspec.DecodeError:
        return None


def split_namespace(key: str) -> tuple[str, str] | None:
    """``robot1/camera/image_raw`` -> (``robot1``, ``camera/image_raw``): a pipeline key under a
    namespace, found by its longest known ending; None when no ending is a pipeline key."""
    parts = key.split("/")
    for i in range(1, len(parts)):
        name = "/".join(parts[i:])
        if name in TYPES:
            return "/".join(parts[:i]), name
    return None


def type_of(key: str, namespace: str = "") -> type[Message] | None:
    """The type a key carries by the key table, also under a namespace not given."""
    known = type_for_key(key, namespace)
    if known is not None:
        return known
    found = split_namespace(key)
    return TYPES[found[1]] if found else None


def key_expression(text: str) -> str:
    """``text`` if it is a Zenoh key expression; else a one-line error that says how to write it.

    ROS topics start with a slash and Zenoh keys cannot: ``/camera/image_raw`` is refused with
    the key to type instead.
    """
    if text.startswith("/"):
        raise SettingError(
            f"{text}: keys have no leading slash here (ROS topic /a/b is key a/b): "
            f"try {text.lstrip('/') or '**'}"
        )
    try:
        zenoh.KeyExpr(text)
    except zenoh.ZError as e:
        raise SettingError(
            f"{text!r} is not a Zenoh key expression ({str(e).split(' at /', 1)[0]}): "
            "write keys as camera/image_raw, camera/*, camera/** or **"
        ) from e
    return text
