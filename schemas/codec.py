"""msgpack on the wire: one Encoder and one typed Decoder per message type, made once.

Which type travels on which key is :mod:`onebox.keys`.
"""

from __future__ import annotations

import functools
import json
from typing import Any, Generic, TypeVar

import msgspec

from schemas.base import Message

M = TypeVar("M", bound=Message)

_ENCODER = msgspec.msgpack.Encoder()


class Codec(Generic[M]):
    """Encodes and decodes one message type; get one with :func:`codec`."""

    def __init__(self, message_type: type[M]) -> None:
        self.type = message_type
        self.name = type_name(message_type)
        self._decoder = msgspec.msgpack.Decoder(message_type)

    def encode(self, message: M) -> bytes:
        return _ENCODER.encode(message)

    def decode(self, payload: bytes | bytearray | memoryview) -> M:
        """Raises msgspec.DecodeError (a ValueError) when the bytes are not this type."""
        return self._decoder.decode(payload)


@functools.cache
def codec(message_type: type[M]) -> Codec[M]:
    """The one codec of ``message_type``."""
    return Codec(message_type)


def type_name(message_type: type[Message]) -> str:
    """A stable, readable name: ``onebox.sensor.Image``."""
    module = message_type.__module__.removeprefix("schemas.")
    return f"onebox.{module}.{message_type.__qualname__}"


@functools.cache
def json_schema(message_type: type[Message]) -> bytes:
    """The JSON schema of a type, written into MCAP recordings so they describe themselves."""
    schema: dict[str, Any] = msgspec.json.schema(message_type)
    schema["title"] = type_name(message_type)
    return json.dumps(schema, sort_keys=True).encode()
