"""ROS 2 on Zenoh as rmw_zenoh (Jazzy and later) puts it on the wire, after its docs/design.md.

Nothing here knows onebox's messages; :mod:`onebox.ros2_bridge` uses it to stand in a ROS 2
graph as a node:

- a topic's data travels on ``<domain_id>/<topic without its leading slash>/<DDS type
  name>/<type hash>`` (:func:`topic_key`), e.g.
  ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...``; the DDS type name of
  ``std_msgs/msg/String`` is ``std_msgs::msg::dds_::String_`` (:func:`dds_type`); the hash is
  REP-2011's RIHS01 of the type's description (:func:`type_hash`, computed by ``rosbags``);
- the payload is the CDR-encoded message; every sample carries an attachment of 33 bytes:
  int64 sequence number, int64 source time (ns since the Unix epoch), both little-endian, the
  GID's length (one byte, 16) and the GID (:class:`Attachment`); rmw_zenoh's subscriptions drop
  a sample without one;
- each node, publisher and subscription holds a liveliness token that ``ros2 node list``,
  ``ros2 topic list`` and every other graph query read (:class:`Entity`):
  ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/
  <node name>[/<topic>/<DDS type>/<type hash>/<QoS>]``, names with each ``/`` written ``%``
  (an empty enclave or the root namespace is ``%``), the QoS in rmw_zenoh's compact form
  (:class:`Qos`);
- a TRANSIENT_LOCAL publisher keeps its last ``depth`` samples in a Zenoh advanced publisher's
  cache, and a TRANSIENT_LOCAL subscription asks for them (the caller declares those).
"""

from __future__ import annotations

import hashlib
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum

from rosbags.typesys.store import Typestore

from onebox.errors import SettingError

ADMIN_SPACE = "@ros2_lv"
"""The liveliness tokens' prefix: a hermetic chunk, which ``*`` and ``**`` never match."""
DOMAIN_ENV = "ROS_DOMAIN_ID"
MAX_DOMAIN_ID = 232
"""The largest domain id ROS 2 accepts (rcl's limit, from DDS's port arithmetic)."""


class Reliability(IntEnum):
    """rmw_qos_reliability_policy_e."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(IntEnum):
    """rmw_qos_durability_policy_e."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(IntEnum):
    """rmw_qos_history_policy_e."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True)
class Qos:
    """An entity's QoS as rmw_zenoh writes it into its liveliness token.

    rmw_zenoh's defaults (reliable, volatile, keep last 42; deadline, lifespan and liveliness
    lease infinite; liveliness automatic) are written as nothing, so ``depth=10`` alone is
    ``::,10:,:,:,,``. Deadline, lifespan and liveliness are always the defaults here.
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10

    DEFAULT_DEPTH = 42

    def keyexpr(self) -> str:
        def unless(value: int, default: int) -> str:
            return "" if value == default else str(int(value))

        return ":".join(
            [
                unless(self.reliability, Reliability.RELIABLE),
                unless(self.durability, Durability.VOLATILE),
                unless(self.history, History.KEEP_LAST)
                + ","
                + unless(self.depth, self.DEFAULT_DEPTH),
                ",",  # deadline sec, nsec
                ",",  # lifespan sec, nsec
                ",,",  # liveliness kind, lease sec, lease nsec
            ]
        )

    @classmethod
    def parse(cls, text: str) -> Qos:
        """The reliability, durability, history and depth of a token's QoS chunk; ValueError
        for one that is not rmw_zenoh's form."""
        parts = text.split(":")
        if len(parts) != 6 or len(parts[2].split(",")) != 2:
            raise ValueError(f"{text!r} is not an rmw_zenoh QoS")
        history, depth = parts[2].split(",")
        return cls(
            reliability=Reliability(int(parts[0])) if parts[0] else Reliability.RELIABLE,
            durability=Durability(int(parts[1])) if parts[1] else Durability.VOLATILE,
            history=History(int(history)) if history else History.KEEP_LAST,
            depth=int(depth) if depth else cls.DEFAULT_DEPTH,
        )


SENSOR_DATA = Qos(Reliability.BEST_EFFORT, depth=5)
"""rclcpp's SensorDataQoS: what a subscriber of pictures asks for (REP-2003)."""
DEFAULT = Qos()
"""rclcpp's QoS(10): reliable, volatile, keep last 10; what publishers use unless told."""
STATIC_BROADCASTER = Qos(durability=Durability.TRANSIENT_LOCAL, depth=1)
"""tf2_ros's StaticBroadcasterQoS: the last message kept for late joiners."""
STATIC_LISTENER = Qos(durability=Durability.TRANSIENT_LOCAL, depth=100)
"""tf2_ros's StaticListenerQoS: every static broadcaster's message, however late."""


def domain_id(flag: int | None, environ: Mapping[str, str]) -> int:
    """``--domain-id`` if given, else ``ROS_DOMAIN_ID``, else 0, as ROS 2 reads it."""
    if flag is not None:
        value, where = str(flag), "--domain-id"
    else:
        value, where = environ.get(DOMAIN_ENV, "").strip(), DOMAIN_ENV
        if not value:
            return 0
    if not value.isdigit() or int(value) > MAX_DOMAIN_ID:
        raise SettingError(
            f"{where} {value!r}: a ROS domain id is a whole number from 0 to {MAX_DOMAIN_ID}"
        )
    return int(value)


_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def check_node_name(name: str) -> str:
    """``name`` if ROS 2 takes it as a node name; otherwise a SettingError saying why."""
    if not _TOKEN.fullmatch(name) or len(name) > 255:
        raise SettingError(
            f"node name {name!r}: letters, digits and '_', not starting with a digit"
        )
    return name


def resolve(name: str, namespace: str = "/") -> str:
    """The fully qualified ROS 2 name of topic ``name`` for a node in ``namespace``: a name
    with a leading '/' as it is, another under the namespace. SettingError for a name ROS 2
    refuses (tokens of letters, digits and '_', none starting with a digit; '~' and
    substitutions are not taken here)."""
    full = name if name.startswith("/") else f"{namespace.rstrip('/')}/{name}"
    tokens = full[1:].split("/")
    if not all(_TOKEN.fullmatch(t) for t in tokens):
        raise SettingError(
            f"topic {name!r} ({full}) is not a ROS 2 name: '/'-separated parts of letters, "
            "digits and '_', none empty or starting with a digit"
        )
    return full


def namespace_of(prefix: str) -> str:
    """The ROS 2 namespace of a onebox key prefix: ``robot1`` is ``/robot1``, none is ``/``."""
    return resolve(prefix) if prefix else "/"


def dds_type(typename: str) -> str:
    """``sensor_msgs/msg/Image`` as rmw_zenoh names it: ``sensor_msgs::msg::dds_::Image_``."""
    package, kind, name = typename.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type(dds: str) -> str:
    """The inverse of :func:`dds_type`; ValueError for a name not of that form."""
    parts = dds.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise ValueError(f"{dds!r} is not a DDS type name")
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def type_hash(store: Typestore, typename: str) -> str:
    """REP-2011's RIHS01 hash of ``typename`` as ``store`` defines it (``RIHS01_<64 hex>``)."""
    return store.hash_rihs01(typename)


def topic_key(domain: int, topic: str, typename: str, hash_: str) -> str:
    """The key expression a topic's samples travel on."""
    return f"{domain}/{topic.strip('/')}/{dds_type(typename)}/{hash_}"


def mangle(name: str) -> str:
    """A name inside one liveliness chunk: each '/' written '%' (empty: '%')."""
    return name.replace("/", "%") or "%"


def demangle(chunk: str) -> str:
    return chunk.replace("%", "/")


class Kind:
    """The entity kinds of a liveliness token."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


@dataclass(frozen=True)
class Topic:
    """What a publisher's or subscription's token says of its topic."""

    name: str
    """Fully qualified: ``/camera/image_raw``."""
    typename: str
    """``sensor_msgs/msg/Image``."""
    hash: str
    qos: Qos


@dataclass(frozen=True)
class Entity:
    """A node, publisher or subscription in the ROS 2 graph, as its liveliness token says."""

    domain: int
    session: str
    node_id: int
    entity_id: int
    kind: str
    namespace: str
    node: str
    topic: Topic | None = None
    enclave: str = ""

    def token(self) -> str:
        chunks = [
            ADMIN_SPACE,
            str(self.domain),
            self.session,
            str(self.node_id),
            str(self.entity_id),
            self.kind,
            mangle(self.enclave),
            mangle("" if self.namespace == "/" else self.namespace),
            self.node,
        ]
        if self.topic is not None:
            t = self.topic
            chunks += [mangle(t.name), dds_type(t.typename), t.hash, t.qos.keyexpr()]
        return "/".join(chunks)

    def gid(self) -> bytes:
        """16 bytes that name this entity alone: a hash of its token, as rmw_zenoh's are."""
        return hashlib.blake2b(self.token().encode(), digest_size=16).digest()

    @property
    def node_path(self) -> str:
        """``/namespace/node`` as ``ros2 node list`` prints it."""
        return f"{self.namespace.rstrip('/')}/{self.node}"

    @classmethod
    def parse(cls, token: str) -> Entity:
        """The entity of a liveliness token; ValueError for a token that is not rmw_zenoh's."""
        chunks = token.split("/")
        if chunks[0] != ADMIN_SPACE or len(chunks) not in (9, 13) or "" in chunks:
            raise ValueError(f"{token!r} is not an rmw_zenoh liveliness token")
        kind = chunks[5]
        topic = None
        if kind != Kind.NODE:
            if len(chunks) != 13:
                raise ValueError(f"{token!r}: a {kind} token without its topic")
            topic = Topic(
                demangle(chunks[9]), ros_type(chunks[10]), chunks[11], Qos.parse(chunks[12])
            )
        namespace = demangle(chunks[7])
        return cls(
            domain=int(chunks[1]),
            session=chunks[2],
            node_id=int(chunks[3]),
            entity_id=int(chunks[4]),
            kind=kind,
            enclave="" if chunks[6] == "%" else demangle(chunks[6]),
            namespace=namespace if namespace.startswith("/") else f"/{namespace}",
            node=chunks[8],
            topic=topic,
        )


@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh attaches to every sample: how its subscribers tell publishers apart and
    see what was lost."""

    sequence: int
    """1 for a publisher's first sample, then one more each."""
    source_time_ns: int
    """When it was published, in ns since the Unix epoch (the wall clock, not sim time)."""
    gid: bytes
    """The publisher's 16-byte GID."""

    LAYOUT = struct.Struct("<qqB16s")

    def encode(self) -> bytes:
        return self.LAYOUT.pack(self.sequence, self.source_time_ns, len(self.gid), self.gid)

    @classmethod
    def decode(cls, raw: bytes) -> Attachment:
        """ValueError for bytes that are not an rmw_zenoh attachment."""
        if len(raw) != cls.LAYOUT.size:
            raise ValueError(f"an attachment of {len(raw)} bytes, not {cls.LAYOUT.size}")
        sequence, stamp, length, gid = cls.LAYOUT.unpack(raw)
        if length != 16:
            raise ValueError(f"a GID of {length} bytes, not 16")
        return cls(sequence, stamp, gid)
