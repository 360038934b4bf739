"""Messages: msgpack round trips, typed decoders that reject other types, JSON schemas."""

from __future__ import annotations

import json

import msgspec
import pytest

from onebox.keys import TYPES, type_for_key
from schemas import (
    BoundingBox3D,
    CameraInfo,
    Clock,
    Detection3D,
    Detection3DArray,
    GroundTruth,
    Header,
    Image,
    Message,
    ObjectHypothesis,
    PointCloud,
    PointField,
    Pose,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    codec,
    json_schema,
    type_name,
)

HEADER = Header(stamp_ns=1_200_000_000, frame_id="camera_optical_frame")
EXAMPLES: list[Message] = [
    Image(header=HEADER, height=1, width=2, encoding="rgb8", step=6, data=bytes(range(6))),
    CameraInfo(
        header=HEADER, height=240, width=320, d=[0.0] * 5, k=[277.1, 0, 160, 0, 277.1, 120, 0, 0, 1]
    ),
    TFMessage(
        transforms=[
            TransformStamped(
                header=Header(frame_id="world"),
                child_frame_id="camera_link",
                transform=Transform(translation=Vector3(z=0.4)),
            )
        ]
    ),
    Clock(clock_ns=5),
    Detection3DArray(
        header=Header(frame_id="world"),
        detections=[
            Detection3D(
                results=[ObjectHypothesis(class_id="box", score=1.0)],
                bbox=BoundingBox3D(center=Pose(position=Vector3(x=0.064)), size=Vector3(z=0.06)),
            )
        ],
    ),
    PointCloud(
        header=HEADER,
        width=1,
        fields=[PointField(name="x", offset=0, datatype=7)],
        point_step=4,
        row_step=4,
        data=b"\0\0\0\0",
    ),
    GroundTruth(header=Header(frame_id="world"), box_pose=Pose(), box_size=Vector3(x=0.06)),
]


@pytest.mark.parametrize("message", EXAMPLES, ids=lambda m: type(m).__name__)
def test_round_trip(message: Message) -> None:
    """Encoding then decoding gives back an equal message."""
    c = codec(type(message))
    assert c.decode(c.encode(message)) == message


@pytest.mark.parametrize("message", EXAMPLES, ids=lambda m: type(m).__name__)
def test_another_type_is_rejected(message: Message) -> None:
    """A decoder refuses a message of another type instead of filling in defaults."""
    other = Clock if not isinstance(message, Clock) else Image
    with pytest.raises(msgspec.ValidationError):
        codec(other).decode(codec(type(message)).encode(message))


def test_garbage_is_a_decode_error() -> None:
    """Bytes that are not msgpack raise msgspec's DecodeError, which callers catch."""
    with pytest.raises(msgspec.DecodeError):
        codec(Image).decode(b"\xc1 not msgpack")


def test_an_older_reader_ignores_new_fields() -> None:
    """A field added by a newer writer does not break a reader that lacks it."""

    class ClockV2(Message, frozen=True, kw_only=True, tag="Clock"):
        clock_ns: int = 0
        rate: float = 1.0

    payload = msgspec.msgpack.encode(ClockV2(clock_ns=7, rate=2.0))
    assert codec(Clock).decode(payload) == Clock(clock_ns=7)


@pytest.mark.parametrize("message_type", sorted(set(TYPES.values()), key=type_name))
def test_json_schema_describes_the_type(message_type: type[Message]) -> None:
    """Each key's type has a JSON schema titled with its name, listing its fields."""
    schema = json.loads(json_schema(message_type))
    assert schema["title"] == type_name(message_type)
    definition = schema["$defs"][message_type.__name__]
    assert "_type" in definition["properties"]
    assert set(message_type.__struct_fields__) <= set(definition["properties"])


@pytest.mark.parametrize(
    ("key", "message_type"),
    [
        ("robot1/camera/depth/image_raw", Image),
        ("robot1/camera/camera_info", CameraInfo),
        ("robot1/tf_static", TFMessage),
        ("robot1/detections", Detection3DArray),
        ("robot1/camera/points", PointCloud),
        ("robot1/sim/ground_truth", GroundTruth),
        ("robot1/camera/unknown", None),
        ("robot2/detections", None),
    ],
)
def test_a_namespaced_key_has_its_type(key: str, message_type: type[Message] | None) -> None:
    """Under namespace robot1 each pipeline key has its type; other keys and namespaces none."""
    assert type_for_key(key, "robot1") is message_type
