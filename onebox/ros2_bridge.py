"""onebox keys to ROS 2 topics and back, live, over rmw_zenoh: the engine of ``onebox ros2``.

:func:`plan` turns the command line into routes (which key goes to which topic, as which ROS
type, with which QoS); :class:`Bridge` stands in the ROS 2 graph as one node and moves each
route's messages:

- out (onebox -> ROS 2): a subscriber on the onebox key, a Zenoh publisher on the topic's
  rmw_zenoh key with its liveliness token; each message is turned into its ROS message
  (:class:`onebox.export.ros2.RosMessages`, the converter ``onebox export --to ros2`` uses),
  CDR-encoded by ``rosbags`` and put with rmw_zenoh's attachment. tf_static is published
  TRANSIENT_LOCAL (a Zenoh advanced publisher with a cache), so a late RViz still gets it.
  Nothing is converted while no ROS subscriber matches (a matching listener says so).
- in (ROS 2 -> onebox): a subscription on the topic (TRANSIENT_LOCAL for tf_static, asking
  every publisher's cache, as rmw_zenoh's own subscriptions do) with its token; each sample is
  decoded by ``rosbags`` and turned into the onebox message
  (:func:`onebox.ros_bag.from_ros`, the converter ``onebox import`` uses).

A picture crosses with one copy of its pixels in either direction: out, the onebox message is
decoded into an :class:`ImageView` (pixels left in the payload) and the CDR encoder copies
them into the ROS message; in, ``rosbags`` decodes the CDR into a view of the payload and the
msgpack encoder copies them into the onebox message. (Zenoh's Python binding copies a payload
once as it arrives and once as it leaves, as it does for every onebox process.)

Each route has its own bounded queue and worker thread, so a slow picture never holds up
tf_static, the clock or the detections, and the Zenoh threads that deliver samples only
enqueue them: the bridge never slows the pipeline. A full queue drops its oldest sample and
counts it. A sample that does not decode or convert is logged with its key or topic (once per
interval) and dropped. Samples the bridge itself published never come back to it (subscribers
take remote samples only), so a key that is both bridged in and out cannot loop.
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import msgspec
import zenoh
import zenoh.ext
from rosbags.typesys import Stores
from rosbags.typesys.store import Typestore

from onebox import bus, keys, rmw_zenoh
from onebox.errors import SettingError
from onebox.export.ros2 import (
    CAMERA_INFO,
    CLOCK,
    DETECTIONS,
    IMAGE,
    POINT_CLOUD,
    TF,
    TRANSFORM,
    RosMessages,
    typestore,
)
from onebox.rmw_zenoh import Attachment, Entity, Kind, Qos, Topic
from onebox.ros_bag import COMPRESSED, from_ros
from onebox.sync import NewestQueue, ReportLimiter
from schemas import (
    CameraInfo,
    Clock,
    Detection3DArray,
    Image,
    ImageView,
    Message,
    PointCloud,
    PointCloudView,
    TFMessage,
    TransformStamped,
    codec,
)

log = logging.getLogger("ros2")

RELEASE = Stores.ROS2_JAZZY
"""The ROS 2 release whose message definitions give the type hashes (Jazzy, the first with
rmw_zenoh; later releases have the same definitions for these types)."""

OUT_TYPES: dict[type[Message], str] = {
    Image: IMAGE,
    CameraInfo: CAMERA_INFO,
    PointCloud: POINT_CLOUD,
    TransformStamped: TRANSFORM,
    TFMessage: TF,
    Clock: CLOCK,
    Detection3DArray: DETECTIONS,
}
"""The onebox messages that have a ROS 2 type, and that type."""
OUT_KEYS = tuple(key for key, kind in keys.TYPES.items() if kind in OUT_TYPES)
"""Every key bridged out by default: each key of the pipeline with a ROS 2 type."""
IN_TYPES: dict[type[Message], str] = {
    Image: IMAGE,
    CameraInfo: CAMERA_INFO,
    TransformStamped: TRANSFORM,
    TFMessage: TF,
    Clock: CLOCK,
}
"""The onebox messages a ROS 2 message can become, and the ROS type read for each (a topic
ending in /compressed or /compressedDepth is read as sensor_msgs/msg/CompressedImage)."""
VIEWS: dict[type[Message], type[Message]] = {Image: ImageView, PointCloud: PointCloudView}
PICTURES = (Image, PointCloud)
COMPRESSED_SUFFIXES = ("/compressed", "/compressedDepth")

PRESETS: dict[str, tuple[tuple[str, str], ...]] = {
    "realsense": (
        ("/camera/camera/aligned_depth_to_color/image_raw", keys.CAMERA.depth),
        ("/camera/camera/color/image_raw", keys.CAMERA.colour),
        ("/camera/camera/aligned_depth_to_color/camera_info", keys.CAMERA.info),
        ("/tf_static", keys.TF_STATIC),
    ),
    "azure_kinect": (
        ("/depth_to_rgb/image_raw", keys.CAMERA.depth),
        ("/rgb/image_raw", keys.CAMERA.colour),
        ("/depth_to_rgb/camera_info", keys.CAMERA.info),
        ("/tf_static", keys.TF_STATIC),
    ),
}
"""The topics of a driver run with its defaults: realsense2_camera 4.x's ``rs_launch.py
align_depth.enable:=true`` (/camera/camera/...), and the Azure Kinect ROS 2 driver's
``driver.launch.py`` (its depth registered to the colour camera on depth_to_rgb/)."""


@dataclass(frozen=True)
class Route:
    """One onebox key and the ROS 2 topic it is bridged to or from."""

    key: str
    """The onebox key, without the namespace."""
    topic: str
    """The fully qualified ROS 2 topic."""
    typename: str
    """The ROS 2 type, ``sensor_msgs/msg/Image``."""
    qos: Qos

    @property
    def latched(self) -> bool:
        return self.qos.durability == rmw_zenoh.Durability.TRANSIENT_LOCAL

    @property
    def onebox_type(self) -> type[Message]:
        return keys.TYPES[self.key]


def _pairs(text: str, flag: str, what: str) -> tuple[str, str]:
    left, sep, right = text.partition("=")
    if not sep or not left or not right:
        raise SettingError(f"{flag} {text!r}: give {what}")
    return left, right


def _known(key: str, flag: str, types: dict[type[Message], str]) -> type[Message]:
    kind = keys.TYPES.get(key)
    if kind is None or kind not in types:
        known = ", ".join(k for k, t in keys.TYPES.items() if t in types)
        raise SettingError(f"{flag}: {key!r} is not a key with a ROS 2 type (these are: {known})")
    return kind


def plan(
    *,
    out: Iterable[str] | None = None,
    no_out: bool = False,
    ins: Iterable[str] = (),
    preset: str | None = None,
    namespace: str = "",
) -> tuple[list[Route], list[Route]]:
    """The out and in routes the command line asks for; SettingError for what cannot be.

    ``out``: ``KEY`` or ``KEY=TOPIC`` items (None: every key of :data:`OUT_KEYS` not bridged
    in); ``ins``: ``TOPIC=KEY`` items, after those of ``preset``. A relative topic is under the
    node's namespace, ``/`` + ``namespace``; a key is under ``namespace`` on the bus.
    """
    ros_namespace = rmw_zenoh.namespace_of(namespace)
    wanted_in: list[tuple[str, str, str]] = []
    if preset is not None:
        if preset not in PRESETS:
            raise SettingError(f"--preset {preset!r}: one of {', '.join(PRESETS)}")
        wanted_in += [(t, k, f"--preset {preset}") for t, k in PRESETS[preset]]
    for item in ins:
        topic, key = _pairs(
            item, "--in", "TOPIC=KEY, e.g. /camera/color/image_raw=camera/image_raw"
        )
        wanted_in.append((topic, key, f"--in {item}"))
    routes_in: dict[str, Route] = {}
    for topic, key, flag in wanted_in:
        kind = _known(key, flag, IN_TYPES)
        full = rmw_zenoh.resolve(topic, ros_namespace)
        if key in routes_in and routes_in[key].topic != full:
            raise SettingError(
                f"{flag}: {key} already comes from {routes_in[key].topic}; one topic a key"
            )
        typename = IN_TYPES[kind]
        if kind is Image and full.endswith(COMPRESSED_SUFFIXES):
            typename = COMPRESSED
        if key == keys.TF_STATIC:
            qos = rmw_zenoh.STATIC_LISTENER
        elif kind in PICTURES:
            qos = rmw_zenoh.SENSOR_DATA
        else:
            qos = rmw_zenoh.DEFAULT
        routes_in[key] = Route(key, full, typename, qos)
    routes_out: dict[str, Route] = {}
    if not no_out:
        items = list(out) if out is not None else [k for k in OUT_KEYS if k not in routes_in]
        for item in items:
            key, _, topic = item.partition("=")
            flag = f"--out {item}"
            kind = _known(key, flag, OUT_TYPES)
            if key in routes_in:
                raise SettingError(
                    f"{flag}: {key} comes from ROS 2 ({routes_in[key].topic}); a key goes one way"
                )
            full = rmw_zenoh.resolve(topic or key, ros_namespace)
            if key in routes_out:
                raise SettingError(f"{flag}: {key} is already bridged out")
            qos = rmw_zenoh.STATIC_BROADCASTER if key == keys.TF_STATIC else rmw_zenoh.DEFAULT
            routes_out[key] = Route(key, full, OUT_TYPES[kind], qos)
    topics_in = {r.topic: r for r in routes_in.values()}
    seen: set[str] = set()
    for route in routes_out.values():
        if route.topic in seen:
            raise SettingError(f"--out: two keys on one topic, {route.topic}")
        seen.add(route.topic)
        if route.topic in topics_in:
            raise SettingError(f"{route.topic} is both read from ROS 2 and written to it")
    if not routes_out and not routes_in:
        raise SettingError("nothing to bridge: --no-out and no --in or --preset")
    return list(routes_out.values()), list(routes_in.values())


@dataclass
class Counts:
    """What one route did since the bridge started."""

    crossed: int = 0
    bad: int = 0
    dropped: int = 0
    """Dropped by a full queue: the worker was slower than the samples came."""


@dataclass(frozen=True)
class BridgeSettings:
    """What ``onebox ros2`` was asked to do, checked."""

    routes_out: list[Route]
    routes_in: list[Route]
    domain_id: int = 0
    node_name: str = "onebox"
    namespace: str = ""
    """The onebox key prefix; the node's ROS namespace is ``/`` + it."""


class Dropped(Exception):
    """A sample the bridge cannot carry, with why (logged with the key or topic)."""

    def __init__(self, kind: str, why: str) -> None:
        super().__init__(why)
        self.kind = kind


class ToRos:
    """A onebox payload as the CDR of its ROS 2 message: what an out route does to a sample."""

    def __init__(self, route: Route, store: Typestore, messages: RosMessages) -> None:
        self.route = route
        self._store = store
        self._messages = messages
        self._decoder: msgspec.msgpack.Decoder[Any] = msgspec.msgpack.Decoder(
            VIEWS.get(route.onebox_type, route.onebox_type)
        )

    def translate(self, payload: bytes) -> memoryview:
        """The CDR bytes (a view of the buffer the encoder wrote); Dropped for what cannot go."""
        what = self.route.onebox_type.__name__
        try:
            message = self._decoder.decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError) as e:
            raise Dropped("decode", f"does not decode as {what}, dropped: {e}") from e
        try:
            converted = self._messages.convert(message)
        except ValueError as e:
            raise Dropped("convert", f"dropped: {e}") from e
        if converted is None:
            raise Dropped("empty", f"an empty {what}, which ROS 2 tools cannot use: dropped")
        typename, ros = converted
        try:
            return self._store.serialize_cdr(ros, typename)
        except (struct.error, OverflowError, ValueError) as e:
            raise Dropped("range", f"a number {typename} cannot hold ({e}): dropped") from e


class FromRos:
    """A ROS 2 CDR payload as the onebox message: what an in route does to a sample."""

    def __init__(self, route: Route, store: Typestore) -> None:
        self.route = route
        self._store = store
        self._statics: dict[str, TransformStamped] = {}

    def translate(self, payload: bytes) -> Message:
        """The onebox message (its pixels, if any, a view of ``payload``); Dropped for what
        cannot go."""
        typename = self.route.typename
        try:
            ros: Any = self._store.deserialize_cdr(payload, typename)
        except Exception as e:  # rosbags raises SerdeError, or index and value errors on garbage
            raise Dropped("decode", f"does not decode as {typename}, dropped: {e}") from e
        try:
            message = from_ros(ros, self.route.key, self._statics)
        except (ValueError, AttributeError, TypeError) as e:
            raise Dropped("convert", f"dropped: {e}") from e
        if message is None:
            raise Dropped(
                "encoding",
                f"a {ros.encoding} picture for {self.route.key}, which takes depth (16UC1, "
                "mono16, 32FC1): dropped",
            )
        return message


class _Lane:
    """One route's queue and worker thread."""

    def __init__(self, name: str, maxlen: int, limiter: ReportLimiter) -> None:
        self.name = name
        self.counts = Counts()
        self._queue: NewestQueue[zenoh.Sample] = NewestQueue(maxlen=maxlen)
        self._limiter = limiter
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, name=f"ros2 {name}", daemon=True)
        self._closers: list[Callable[[], None]] = []

    def start(self) -> None:
        self._thread.start()

    def offer(self, sample: zenoh.Sample) -> None:
        """Called on Zenoh's thread: enqueue and return at once."""
        self._queue.put(sample)

    def handle(self, sample: zenoh.Sample) -> bool:
        """Move one sample across; True if it crossed."""
        raise NotImplementedError

    def _work(self) -> None:
        while not self._stop.is_set():
            sample = self._queue.get(timeout_s=0.2)
            if sample is None:
                continue
            try:
                crossed = self.handle(sample)
            except Dropped as e:
                crossed = False
                self._limiter.warn(self.name, e.kind, str(e))
            except Exception as e:  # one bad sample must never end the lane
                crossed = False
                self._limiter.warn(self.name, type(e).__name__, f"dropped: {e!r}")
            if crossed:
                self.counts.crossed += 1
            else:
                self.counts.bad += 1
            self.counts.dropped = self._queue.dropped

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        while self._closers:
            closer = self._closers.pop()
            try:
                closer()
            except zenoh.ZError as e:
                log.debug("%s: %s while closing", self.name, e)


def _payload(view: memoryview) -> bytes | bytearray:
    """The bytes under ``rosbags``'s encoded message, without copying them again."""
    owner = view.obj
    if isinstance(owner, bytearray) and len(owner) == view.nbytes:
        return owner
    return view.tobytes()


class _OutLane(_Lane):
    """A onebox key published on a ROS 2 topic."""

    def __init__(self, bridge: Bridge, route: Route, entity_id: int) -> None:
        super().__init__(bridge.bus.key(route.key), 2 if route.onebox_type in PICTURES else 64,
                         bridge.limiter)  # fmt: skip
        self.route = route
        self.hash = rmw_zenoh.type_hash(bridge.store, route.typename)
        self.entity = bridge.entity(
            Kind.PUBLISHER, entity_id, Topic(route.topic, route.typename, self.hash, route.qos)
        )
        self._gid = self.entity.gid()
        self._sequence = 0
        self._to_ros = ToRos(route, bridge.store, bridge.messages)
        self.matched = route.latched
        session = bridge.bus.session
        topic_key = rmw_zenoh.topic_key(bridge.domain, route.topic, route.typename, self.hash)
        publisher: Any
        if route.latched:
            publisher = zenoh.ext.declare_advanced_publisher(
                session,
                topic_key,
                cache=zenoh.ext.CacheConfig(max_samples=route.qos.depth),
                publisher_detection=True,
                # As rmw_zenoh for RELIABLE + TRANSIENT_LOCAL: a subscriber that missed the
                # last sample learns so from a heartbeat and fetches it from the cache.
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=0.5
                ),
                congestion_control=zenoh.CongestionControl.BLOCK,
            )
        else:
            picture = route.onebox_type in PICTURES
            publisher = session.declare_publisher(
                topic_key,
                congestion_control=zenoh.CongestionControl.DROP,
                express=picture,
            )
            listener = publisher.declare_matching_listener(self._on_matching)
            self._closers.append(listener.undeclare)
            status: Any = publisher.matching_status  # a MatchingStatus, whatever the stubs say
            self.matched = bool(status.matching)
        self._publisher = publisher
        self._closers.append(publisher.undeclare)
        token = session.liveliness().declare_token(self.entity.token())
        self._closers.append(token.undeclare)
        expr = bridge.bus.key(route.key)
        subscriber: Any
        if route.latched:
            subscriber = zenoh.ext.declare_advanced_subscriber(
                session,
                expr,
                self._on_sample,
                allowed_origin=zenoh.Locality.REMOTE,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
                subscriber_detection=True,
            )
        else:
            subscriber = session.declare_subscriber(
                expr, self._on_sample, allowed_origin=zenoh.Locality.REMOTE
            )
        self._closers.append(subscriber.undeclare)

    def _on_matching(self, status: zenoh.MatchingStatus) -> None:
        self.matched = status.matching

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if self.matched:
            self.offer(sample)

    def handle(self, sample: zenoh.Sample) -> bool:
        cdr = self._to_ros.translate(sample.payload.to_bytes())
        self._sequence += 1
        attachment = Attachment(self._sequence, time.time_ns(), self._gid).encode()
        self._publisher.put(_payload(cdr), attachment=attachment)
        return True


class _InLane(_Lane):
    """A ROS 2 topic published on a onebox key."""

    def __init__(self, bridge: Bridge, route: Route, entity_id: int) -> None:
        super().__init__(route.topic, 2 if route.onebox_type in PICTURES else 64, bridge.limiter)
        self.route = route
        self.hash = rmw_zenoh.type_hash(bridge.store, route.typename)
        self.entity = bridge.entity(
            Kind.SUBSCRIPTION, entity_id, Topic(route.topic, route.typename, self.hash, route.qos)
        )
        self.publishers: set[str] = set()
        """The tokens of the ROS 2 publishers seen on this topic."""
        self._from_ros = FromRos(route, bridge.store)
        self._hashes_seen: set[str] = set()
        self._publisher = bridge.bus.publisher(
            route.key, route.onebox_type, latched=route.key == keys.TF_STATIC
        )
        session = bridge.bus.session
        # Any type hash: a publisher of another release's definition is read and, if its
        # bytes do not decode, dropped with a warning, rather than silently never matched.
        expr = rmw_zenoh.topic_key(bridge.domain, route.topic, route.typename, "*")
        subscriber: Any
        if route.latched:
            subscriber = zenoh.ext.declare_advanced_subscriber(
                session,
                expr,
                self.offer,
                allowed_origin=zenoh.Locality.REMOTE,
                history=zenoh.ext.HistoryConfig(
                    detect_late_publishers=True, max_samples=route.qos.depth
                ),
                recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
                subscriber_detection=True,
            )
        else:
            subscriber = session.declare_subscriber(
                expr, self.offer, allowed_origin=zenoh.Locality.REMOTE
            )
        self._closers.append(subscriber.undeclare)
        token = session.liveliness().declare_token(self.entity.token())
        self._closers.append(token.undeclare)

    def handle(self, sample: zenoh.Sample) -> bool:
        hash_ = str(sample.key_expr).rsplit("/", 1)[-1]
        if hash_ != self.hash and hash_ not in self._hashes_seen:
            self._hashes_seen.add(hash_)
            log.warning(
                "%s: published with type hash %s, not ROS 2 Jazzy's %s for %s (another "
                "release's definition?); read with Jazzy's, dropped where it does not decode",
                self.name, hash_, self.hash, self.route.typename,
            )  # fmt: skip
        message = self._from_ros.translate(sample.payload.to_bytes())
        self._publisher.publish_bytes(codec(type(message)).encode(message))
        return True


class Bridge:
    """One ROS 2 node on an open onebox bus: its routes, their lanes, and the graph's view.

    Use as a context manager: everything it declared is undeclared when the block ends.
    """

    def __init__(self, b: bus.Bus, config: BridgeSettings) -> None:
        self.bus = b
        self.config = config
        self.domain = config.domain_id
        self.store = typestore(RELEASE)
        self.messages = RosMessages(self.store)
        self.limiter = ReportLimiter(log)
        self.session_id = str(b.session.zid())
        self.namespace = rmw_zenoh.namespace_of(config.namespace)
        self.node = self.entity(Kind.NODE, 0)
        self.out: list[_OutLane] = []
        self.into: list[_InLane] = []
        self._closers: list[Callable[[], None]] = []

    def entity(self, kind: str, entity_id: int, topic: Topic | None = None) -> Entity:
        return Entity(
            domain=self.domain,
            session=self.session_id,
            node_id=0,
            entity_id=entity_id,
            kind=kind,
            namespace=self.namespace,
            node=self.config.node_name,
            topic=topic,
        )

    def __enter__(self) -> Bridge:
        session = self.bus.session
        try:
            token = session.liveliness().declare_token(self.node.token())
            self._closers.append(token.undeclare)
            entity_id = 0
            for route in self.config.routes_out:
                entity_id += 1
                self.out.append(_OutLane(self, route, entity_id))
            for route in self.config.routes_in:
                entity_id += 1
                self.into.append(_InLane(self, route, entity_id))
            watcher = session.liveliness().declare_subscriber(
                f"{rmw_zenoh.ADMIN_SPACE}/{self.domain}/**", self._on_token, history=True
            )
            self._closers.append(watcher.undeclare)
            for lane in [*self.out, *self.into]:
                lane.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def close(self) -> None:
        for lane in [*self.into, *self.out]:
            lane.close()
        self.into, self.out = [], []
        while self._closers:
            closer = self._closers.pop()
            try:
                closer()
            except zenoh.ZError as e:
                log.debug("%s while closing", e)

    @property
    def crossed(self) -> int:
        return sum(lane.counts.crossed for lane in [*self.out, *self.into])

    def _on_token(self, sample: zenoh.Sample) -> None:
        try:
            entity = Entity.parse(str(sample.key_expr))
        except ValueError:
            return  # not a token of ours to read (another rmw's, or a newer layout)
        if entity.session == self.session_id or entity.topic is None:
            return
        gone = sample.kind == zenoh.SampleKind.DELETE
        topic = entity.topic
        if entity.kind == Kind.PUBLISHER:
            for lane in self.into:
                if lane.route.topic == topic.name:
                    self._publisher_seen(lane, entity, sample.key_expr, gone)
        elif entity.kind == Kind.SUBSCRIPTION:
            for out in self.out:
                if out.route.topic == topic.name:
                    verb = "stopped reading" if gone else "reads"
                    log.info("ROS 2 node %s %s %s", entity.node_path, verb, topic.name)

    def _publisher_seen(self, lane: _InLane, entity: Entity, token: Any, gone: bool) -> None:
        topic = entity.topic
        assert topic is not None
        if gone:
            lane.publishers.discard(str(token))
            log.info("%s: ROS 2 publisher %s left", topic.name, entity.node_path)
            return
        lane.publishers.add(str(token))
        log.info("%s: ROS 2 publisher %s (%s)", topic.name, entity.node_path, topic.typename)
        if topic.typename != lane.route.typename:
            log.warning(
                "%s is published by %s as %s, but read as %s for %s: nothing crosses from it",
                topic.name, entity.node_path, topic.typename, lane.route.typename,
                self.bus.key(lane.route.key),
            )  # fmt: skip

    def report(self, since: dict[str, int]) -> str | None:
        """One line: what crossed each way since the counts in ``since`` (updated), or None
        when nothing did."""
        parts = []
        moved_any = False
        for direction, lanes in (("to ROS 2", self.out), ("from ROS 2", self.into)):
            moved = Counter[str]()
            for lane in lanes:
                moved[lane.name] = lane.counts.crossed - since.get(lane.name, 0)
                since[lane.name] = lane.counts.crossed
            busy = ", ".join(f"{name} {n}" for name, n in moved.items() if n)
            moved_any |= bool(busy)
            if lanes:
                parts.append(f"{direction}: {busy or 'nothing'}")
        dropped = sum(lane.counts.dropped for lane in [*self.out, *self.into])
        if dropped:
            parts.append(f"{dropped} dropped by full queues so far")
        return "; ".join(parts) if moved_any else None

    def waiting(self) -> list[str]:
        """The in topics with no ROS 2 publisher seen."""
        return [lane.route.topic for lane in self.into if not lane.publishers]
