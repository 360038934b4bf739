"""The one way every onebox process talks Zenoh.

- :func:`add_arguments` gives every parser ``--connect``, ``--listen``, ``--config`` and
  ``--namespace`` (as zenoh-python's examples/common does), and :func:`open_bus` turns them into
  an open session on loopback with multicast scouting off.
- :class:`Bus` makes typed publishers and subscribers on namespaced keys. A payload that does
  not decode is logged with its key (once per key per interval) and dropped; it never reaches
  the callback and never kills the process.
- :class:`NewestQueue` is the bounded queue between a Zenoh callback and a worker: when the
  worker is slow the oldest item is dropped, counted, and the newest kept.
- ``latched=True`` publishers keep their last sample in a Zenoh publication cache and
  ``history=True`` subscribers ask for it, so a late joiner still receives ``tf_static``.
- Quality of service follows the message type (:func:`qos`): a picture (Image, PointCloud) is
  worth nothing late, so it is dropped under congestion and sent at once (express);
  everything else (detections, tf_static, clock, camera info, ...) is small and blocks rather
  than drops. config/router.json5 bounds how long a stalled link may block the router, and
  has routers drop a capture's camera info and pose rather than wait on a full queue.
- A namespace is a plain key prefix (:func:`check_namespace`); a sample on a wildcard key is
  logged and dropped, never delivered as if it were on the subscribed key.
- Every process logs losing and regaining its router (:class:`RouterWatch`).
- ``--secure DIR`` (or ``ONEBOX_SECURE``) opens the session with config/secure/ and the
  process's own certificate from DIR (made by ``onebox certs DIR``).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any, Generic, TypeVar

import msgspec
import zenoh
import zenoh.ext

from onebox import settings
from onebox.errors import BusError, SettingError
from onebox.sync import ReportLimiter
from schemas import Image, Message, PointCloud, codec

log = logging.getLogger("bus")

M = TypeVar("M", bound=Message)
T = TypeVar("T")

CLIENT_CONFIG = settings.CONFIG_DIR / "client.json5"
ROUTER_CONFIG = settings.CONFIG_DIR / "router.json5"
SECURE_DIR = settings.CONFIG_DIR / "secure"
SECURE_CLIENT_CONFIG = SECURE_DIR / "client.json5"
SECURE_ROUTER_CONFIG = SECURE_DIR / "router.json5"
SECURE_ENDPOINT = "tls/localhost:7447"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
ROUTER_ENV = "ONEBOX_ROUTER"
"""An environment variable naming the local router's endpoint: the router listens there and
every other process connects there (``ONEBOX_ROUTER=tcp/127.0.0.1:17447 honcho start``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The Zenoh flags every onebox command takes."""
    group = parser.add_argument_group("zenoh")
    group.add_argument(
        "--connect",
        "-e",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to connect to, repeatable (default ${ROUTER_ENV} or {DEFAULT_ENDPOINT}, "
        "the local router)",
    )
    group.add_argument(
        "--listen",
        "-l",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to listen on, repeatable: the router's (default $ONEBOX_ROUTER or "
        f"{DEFAULT_ENDPOINT}); other processes are clients of the router and need none",
    )
    group.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help=f"a Zenoh JSON5 configuration to start from (default {CLIENT_CONFIG.name} in config/)",
    )
    settings.add(
        group,
        "namespace",
        "",
        "prefix for every key: robot1 gives robot1/camera/image_raw (a plain key prefix: no "
        "wildcards, no empty or leading or trailing '/')",
        kind=check_namespace,
    )
    group.add_argument(
        "--secure",
        type=Path,
        metavar="DIR",
        default=os.environ.get(SECURE_ENV) or None,
        help=f"open the secured configuration (config/secure/: TLS, access control) with this "
        f"process's certificate from DIR, made by `onebox certs DIR` (default ${SECURE_ENV})",
    )
    # The process's identity in a secured deployment: its command's name (`onebox sim` is sim),
    # the common name of its certificate, which the router's access control knows it by.
    parser.set_defaults(identity=parser.prog.split()[-1])


SECURE_ENV = "ONEBOX_SECURE"
"""An environment variable naming the certificate folder: ``ONEBOX_SECURE=certs honcho start``
runs the whole pipeline with TLS, one identity a process, and access control."""

NAMESPACE_HINT = "a namespace is a plain key prefix such as robot1 or site/robot1"


def check_namespace(namespace: str) -> str:
    """``namespace`` if it is a plain key prefix; otherwise a SettingError saying what is wrong."""
    if not namespace:
        return ""
    if namespace.startswith("/") or namespace.endswith("/"):
        raise SettingError(
            f"namespace {namespace!r} starts or ends with '/': {NAMESPACE_HINT}; "
            f"use {namespace.strip('/')!r}"
        )
    if "" in namespace.split("/"):
        raise SettingError(f"namespace {namespace!r} has an empty chunk ('//'): {NAMESPACE_HINT}")
    wild = [c for c in "*$?#" if c in namespace]
    if wild:
        raise SettingError(
            f"namespace {namespace!r} contains {' '.join(wild)}: wildcards and the characters "
            f"* $ ? # are not allowed, {NAMESPACE_HINT}"
        )
    try:
        zenoh.KeyExpr(namespace)
    except zenoh.ZError as e:
        raise SettingError(
            f"namespace {namespace!r} is not a valid key: {_reason(e)}; {NAMESPACE_HINT}"
        ) from e
    return namespace


def is_concrete(key: str) -> bool:
    """True for a key with no wildcard chunk (``*``, ``**``, ``$*``): what a sample should carry."""
    return not any(chunk in {"*", "**"} or "$*" in chunk for chunk in key.split("/"))


@dataclass(frozen=True)
class Qos:
    """How one key's samples travel: see :func:`qos`."""

    congestion_control: zenoh.CongestionControl
    priority: zenoh.Priority
    express: bool


PICTURE_QOS = Qos(zenoh.CongestionControl.DROP, zenoh.Priority.DATA, express=True)
RELIABLE_QOS = Qos(zenoh.CongestionControl.BLOCK, zenoh.Priority.DATA, express=False)
PICTURE_TYPES: tuple[type[Message], ...] = (Image, PointCloud)


def qos(message_type: type[Message]) -> Qos:
    """Pictures drop under congestion (newest wins); everything else blocks.

    A picture late is worth nothing, and a stalled link must not hold up anything else: it
    goes out at once (express) and is dropped when its queue stays full. It keeps the data
    priority of the rest of its capture, so a capture's messages arrive in the order they were
    sent (ground truth last). Routers drop camera info and pose, which also come with every
    capture, rather than wait on a full queue (config/router.json5), so that one host's
    stalled link never holds a router's fan-out to the others.
    """
    return PICTURE_QOS if issubclass(message_type, PICTURE_TYPES) else RELIABLE_QOS


def zenoh_config(args: argparse.Namespace, default_file: Path = CLIENT_CONFIG) -> zenoh.Config:
    """The configuration file, then the flags on top of it."""
    secure: Path | None = getattr(args, "secure", None)
    router = default_file == ROUTER_CONFIG
    if secure is not None and default_file in (CLIENT_CONFIG, ROUTER_CONFIG):
        default_file = SECURE_ROUTER_CONFIG if router else SECURE_CLIENT_CONFIG
    path: Path = args.config or default_file
    try:
        config = zenoh.Config.from_file(str(path))
    except Exception as e:  # zenoh raises its own ZError for a missing or malformed file
        raise BusError(f"cannot load Zenoh configuration {path}: {e}") from e
    if secure is not None:
        _insert_identity(config, secure, "router" if router else getattr(args, "identity", ""))
    connect, listen = args.connect, args.listen
    router_endpoint = os.environ.get(ROUTER_ENV)
    if router_endpoint and args.config is None:
        if default_file == ROUTER_CONFIG:
            listen = listen or [router_endpoint]
        else:
            connect = connect or [router_endpoint]
    if connect:
        config.insert_json5("connect/endpoints", msgspec.json.encode(connect).decode())
    if listen:
        config.insert_json5("listen/endpoints", msgspec.json.encode(listen).decode())
    return config


def _insert_identity(config: zenoh.Config, folder: Path, identity: str) -> None:
    """Point the TLS settings at ``folder``'s CA and at ``identity``'s certificate and key."""
    ca, cert, key = (folder / "ca.pem", folder / f"{identity}.pem", folder / f"{identity}.key")
    for needed in (ca, cert, key):
        if not needed.is_file():
            raise SettingError(
                f"no {needed} for the secured configuration: make the certificates with "
                f"`onebox certs {folder}` (identity {identity!r})"
            )
    tls = {
        "root_ca_certificate": str(ca.resolve()),
        "listen_certificate": str(cert.resolve()),
        "listen_private_key": str(key.resolve()),
        "connect_certificate": str(cert.resolve()),
        "connect_private_key": str(key.resolve()),
    }
    for name, value in tls.items():
        config.insert_json5(f"transport/link/tls/{name}", msgspec.json.encode(value).decode())


def install_signal_handlers() -> None:
    """Make SIGTERM (what honcho and kill send) unwind like Ctrl-C, so every ``with`` closes."""

    def _raise(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, _raise)


class Publisher(Generic[M]):
    """Publishes messages of one type on one key."""

    def __init__(self, key: str, message_type: type[M], publisher: Any) -> None:
        self.key = key
        self._codec = codec(message_type)
        self._publisher = publisher

    def publish(self, message: M) -> bytes:
        """Encode and send ``message``; returns the bytes that travelled."""
        payload = self._codec.encode(message)
        self._publisher.put(payload)
        return payload

    def publish_bytes(self, payload: bytes) -> None:
        """Send bytes already encoded (a replay sends exactly what was recorded)."""
        self._publisher.put(payload)

    def wait_for_subscribers(self, timeout_s: float) -> bool:
        """Block until some subscriber matches this key (or ``timeout_s`` passes); True if one does.

        Declarations travel through the router, so a sample put right after a subscriber
        opened elsewhere can miss it; waiting here is waiting on Zenoh's matching listener.
        This is the one such wait in onebox: a publisher on ``**`` waits for any subscriber.
        """
        matched = threading.Event()

        def on_status(status: zenoh.MatchingStatus) -> None:
            if status.matching:
                matched.set()

        listener = self._publisher.declare_matching_listener(on_status)
        try:
            # zenoh's stubs call matching_status a bool; it is a MatchingStatus, always truthy.
            status: Any = self._publisher.matching_status
            return bool(status.matching) or matched.wait(timeout_s)
        finally:
            listener.undeclare()


class RouterWatch:
    """Logs each router this session loses and each it (re)gains, from Zenoh's transport events.

    A client has one router, the local one; a router's routers are the other hosts' routers.
    """

    def __init__(self, session: zenoh.Session) -> None:
        self.lost = 0
        self.regained = 0
        self._listener: Any = session.info.declare_transport_events_listener(
            self._on_event, history=True
        )

    def _on_event(self, event: zenoh.TransportEvent) -> None:
        transport = event.transport
        if transport.whatami != zenoh.WhatAmI.ROUTER:
            return
        if event.kind == zenoh.SampleKind.DELETE:
            self.lost += 1
            log.warning("lost router %s; reconnecting", transport.zid)
        elif self.lost:
            self.regained += 1
            log.warning("router %s connected again", transport.zid)
        else:
            log.info("router %s connected", transport.zid)

    def close(self) -> None:
        self._listener.undeclare()


@dataclass
class Bus:
    """An open Zenoh session with the namespace applied to every key it names."""

    session: zenoh.Session
    namespace: str = ""
    _closers: list[Callable[[], None]] = field(default_factory=list)
    _limiter: ReportLimiter = field(default_factory=lambda: ReportLimiter(log))

    def __post_init__(self) -> None:
        self.namespace = check_namespace(self.namespace)

    def key(self, name: str) -> str:
        """``camera/image_raw`` under the namespace: ``robot1/camera/image_raw``."""
        return f"{self.namespace}/{name}" if self.namespace else name

    def unkey(self, key: str) -> str:
        """The key without the namespace prefix."""
        return key.removeprefix(f"{self.namespace}/") if self.namespace else key

    def publisher(
        self,
        name: str,
        message_type: type[M],
        *,
        latched: bool = False,
        congestion_control: zenoh.CongestionControl | None = None,
    ) -> Publisher[M]:
        """A publisher on ``name`` with the :func:`qos` of its type; ``latched`` keeps the last
        sample for late joiners; ``congestion_control`` overrides the type's (a replay blocks)."""
        key = self.key(name)
        how = qos(message_type)
        if latched:
            pub: Any = zenoh.ext.declare_advanced_publisher(
                self.session,
                key,
                cache=zenoh.ext.CacheConfig(max_samples=1),
                publisher_detection=True,
                congestion_control=zenoh.CongestionControl.BLOCK,
                priority=how.priority,
            )
        else:
            pub = self.session.declare_publisher(
                key,
                congestion_control=congestion_control or how.congestion_control,
                priority=how.priority,
                express=how.express,
            )
        self._closers.append(pub.undeclare)
        return Publisher(key, message_type, pub)

    def subscribe_raw(
        self, expr: str, callback: Callable[[str, bytes], None], *, history: bool = False
    ) -> None:
        """Call ``callback(key, payload)`` for every sample on ``expr`` (namespaced).

        ``history`` asks latched publishers for what they published before this subscriber
        started. An exception in ``callback`` is logged with the key and the sample dropped.
        """
        key_expr = self.key(expr)

        def on_sample(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            if not is_concrete(key):
                # Zenoh delivers a put on `**` to every subscriber it intersects; it names no
                # key the pipeline knows, so it is nobody's capture.
                self._limiter.warn(key, "wildcard", "a sample on a wildcard key, dropped")
                return
            try:
                callback(key, sample.payload.to_bytes())
            except Exception as e:  # a bad sample must never kill the subscriber thread
                self._limiter.warn(key, type(e).__name__, f"dropped: {e}")

        if history:
            sub: Any = zenoh.ext.declare_advanced_subscriber(
                self.session,
                key_expr,
                on_sample,
                # No max_samples: on a wildcard it bounds the whole history query, not each
                # key, so a recorder on `**` got one latched key of several (tf_static missed
                # in 4 of 12 tries). Each latched publisher caches only its last sample.
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
                subscriber_detection=True,
            )
        else:
            sub = self.session.declare_subscriber(key_expr, on_sample)
        self._closers.append(sub.undeclare)

    def subscribe(
        self,
        expr: str,
        message_type: type[M],
        callback: Callable[[str, M], None],
        *,
        history: bool = False,
    ) -> None:
        """Call ``callback(key, message)`` with each sample on ``expr`` decoded as ``message_type``.

        A payload that is not a ``message_type`` is logged with its key and dropped.
        """
        decoder = codec(message_type)

        def on_payload(key: str, payload: bytes) -> None:
            try:
                message = decoder.decode(payload)
            except (msgspec.DecodeError, msgspec.ValidationError) as e:
                self._limiter.warn(key, "decode", f"not a {decoder.name}, dropped: {e}")
                return
            callback(key, message)

        self.subscribe_raw(expr, on_payload, history=history)

    def close(self) -> None:
        """Undeclare everything this bus declared (the session itself closes with its ``with``)."""
        while self._closers:
            closer = self._closers.pop()
            with contextlib.suppress(zenoh.ZError):
                closer()


@contextlib.contextmanager
def open_bus(
    args: argparse.Namespace,
    default_file: Path = CLIENT_CONFIG,
    connect_timeout_s: float | None = None,
) -> Iterator[Bus]:
    """Open a session from the parsed flags; everything closes when the block ends.

    ``connect_timeout_s`` overrides how long a client waits for its router.
    """
    check_namespace(getattr(args, "namespace", "") or "")
    config = zenoh_config(args, default_file)
    if connect_timeout_s is not None:
        config.insert_json5("connect/timeout_ms", str(round(connect_timeout_s * 1000)))
    try:
        session = zenoh.open(config)
    except zenoh.ZError as e:
        if default_file == ROUTER_CONFIG:
            where = config.get_json("listen/endpoints")
            raise BusError(
                f"cannot listen on {where}: {_reason(e)}. Is another router running there? "
                "Stop it, or choose another port with --listen (or ONEBOX_ROUTER)"
            ) from e
        where = config.get_json("connect/endpoints")
        raise BusError(
            f"no router at {where}: start it with `honcho start router` or `onebox router` "
            f"(or point --connect / {ROUTER_ENV} at the one you have)"
        ) from e
    with session:
        bus = Bus(session, getattr(args, "namespace", "") or "")
        watch = RouterWatch(session)
        bus._closers.append(watch.close)
        try:
            yield bus
        finally:
            bus.close()


def _reason(error: Exception) -> str:
    """Zenoh's message without the source locations it appends."""
    return str(error).split(" at /", 1)[0]


def routers(bus: Bus) -> list[str]:
    """The routers this session is connected to, as Zenoh ids."""
    return [str(zid) for zid in bus.session.info.routers_zid()]
