"""onebox ros2: the rmw_zenoh wire format checked against what ROS 2 publishes about itself, and
the bridge end to end with an independent rmw_zenoh peer (onebox/testing/rmw_peer.py: its own
token parsing, Zenoh's serializer for attachments, mcap-ros2-support's CDR, Jazzy's stated type
hashes), the real sim and the real locator, on private ports."""

from __future__ import annotations

import struct
import threading
import time

import msgspec
import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic
from rosbags.typesys import Stores
from zenoh.ext import Int64, UInt8, z_serialize

from onebox import keys, rmw_zenoh
from onebox.errors import SettingError
from onebox.export.ros2 import CAMERA_INFO, IMAGE, RosMessages, typestore
from onebox.rmw_zenoh import Attachment, Entity, Kind, Qos, Topic
from onebox.ros2_bridge import OUT_KEYS, Dropped, FromRos, ToRos, plan
from onebox.testing.capture import load_capture
from onebox.testing.processes import Output, has_key, run_onebox
from onebox.testing.rmw_peer import DEFINITIONS, JAZZY_HASHES, RmwPeer, short_name
from schemas import (
    CameraInfo,
    Detection3DArray,
    GroundTruth,
    Image,
    ImageView,
    PointCloud,
    PointCloudView,
    TFMessage,
    codec,
)

CHATTER_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


# --- the wire format -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("typename", "stated"),
    [
        # rmw_zenoh's docs/design.md, its key of demo_nodes_cpp's chatter topic.
        ("std_msgs/msg/String", CHATTER_HASH),
        # ROS 2 Jazzy's image_pipeline tutorials ("Using QoS Overrides",
        # docs.ros.org/en/jazzy/p/image_pipeline/tutorials.html): `ros2 topic info -v` output.
        (
            "sensor_msgs/msg/Image",
            "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
        ),
        # rosidl_generator_c's sensor_msgs/msg/detail/camera_info__description.c, as shipped in
        # hpmicro/hpm_sdk's micro-ROS headers: {0xb3, 0xdf, 0xd6, 0x8f, ...}.
        (
            "sensor_msgs/msg/CameraInfo",
            "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
        ),
    ],
)
def test_type_hashes_are_the_ones_ros2_states(typename, stated):
    """REP-2011's RIHS01 computed from Jazzy's definitions equals the hash ROS 2 itself states
    for a well-known type (sources beside each case)."""
    assert rmw_zenoh.type_hash(typestore(Stores.ROS2_JAZZY), typename) == stated


@pytest.mark.parametrize("typename", sorted(JAZZY_HASHES))
def test_every_bridged_type_hashes_as_the_peer_states(typename):
    """The bridge's hash of each type it speaks is the one the test peer holds as Jazzy's."""
    assert rmw_zenoh.type_hash(typestore(Stores.ROS2_JAZZY), typename) == JAZZY_HASHES[typename]


def test_keys_and_tokens_are_the_design_documents_examples():
    """Data keys, node and entity tokens and the compact QoS come out exactly as the examples
    of rmw_zenoh's docs/design.md, and read back."""
    assert (
        rmw_zenoh.topic_key(0, "/robot1/chatter", "std_msgs/msg/String", CHATTER_HASH)
        == f"0/robot1/chatter/std_msgs::msg::dds_::String_/{CHATTER_HASH}"
    )
    session = "aac3178e146ba6f1fc6e6a4085e77f21"
    node = Entity(2, session, 0, 0, Kind.NODE, "/", "listener")
    assert node.token() == f"@ros2_lv/2/{session}/0/0/NN/%/%/listener"
    chatter = Topic("/chatter", "std_msgs/msg/String", CHATTER_HASH, Qos(depth=10))
    listener = Entity(2, session, 0, 10, Kind.SUBSCRIPTION, "/", "listener", chatter)
    assert listener.token() == (
        f"@ros2_lv/2/{session}/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
        f"{CHATTER_HASH}/::,10:,:,:,,"
    )
    assert Entity.parse(listener.token()) == listener
    assert Entity.parse(node.token()) == node
    assert Qos(depth=7).keyexpr() == "::,7:,:,:,,"
    assert rmw_zenoh.STATIC_BROADCASTER.keyexpr() == ":1:,1:,:,:,,"
    assert rmw_zenoh.SENSOR_DATA.keyexpr() == "2::,5:,:,:,,"
    assert Qos.parse(":1:,1:,:,:,,") == rmw_zenoh.STATIC_BROADCASTER
    robot = Entity(0, session, 0, 3, Kind.PUBLISHER, "/robot1", "onebox", chatter)
    assert "/MP/%/%robot1/onebox/%chatter/" in robot.token()
    assert Entity.parse(robot.token()).node_path == "/robot1/onebox"
    with pytest.raises(ValueError, match="not an rmw_zenoh"):
        Entity.parse("@ros2_lv/0/abc/0/0/NN/%")


def test_attachment_is_what_zenohs_serializer_writes():
    """The attachment is rmw_zenoh's 33 bytes (int64 sequence, int64 time, GID length 16, GID),
    byte for byte what zenoh-ext's serializer makes of the same values; short ones are refused."""
    gid = bytes(range(16))
    ours = Attachment(7, 1_700_000_000_123_456_789, gid).encode()
    theirs = z_serialize((Int64(7), Int64(1_700_000_000_123_456_789), [UInt8(b) for b in gid]))
    assert ours == theirs.to_bytes() and len(ours) == 33
    assert Attachment.decode(ours) == Attachment(7, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError, match="32 bytes"):
        Attachment.decode(ours[:-1])


def test_domain_id_comes_from_the_flag_then_the_environment():
    """--domain-id wins over ROS_DOMAIN_ID, which wins over 0; nonsense is refused."""
    assert rmw_zenoh.domain_id(None, {}) == 0
    assert rmw_zenoh.domain_id(None, {"ROS_DOMAIN_ID": "7"}) == 7
    assert rmw_zenoh.domain_id(3, {"ROS_DOMAIN_ID": "7"}) == 3
    for flag, env in [(None, {"ROS_DOMAIN_ID": "seven"}), (400, {}), (-1, {})]:
        with pytest.raises(SettingError, match="whole number from 0 to 232"):
            rmw_zenoh.domain_id(flag, env)


def test_views_are_the_messages_they_stand_for():
    """ImageView and PointCloudView have their messages' fields in order and encode to the same
    bytes, so a view crosses the bus as the message itself."""
    for message, view in [(Image, ImageView), (PointCloud, PointCloudView)]:
        assert message.__struct_fields__ == view.__struct_fields__
    picture = load_capture()["camera/image_raw"]
    assert isinstance(picture, Image)
    as_view = msgspec.msgpack.Decoder(ImageView).decode(codec(Image).encode(picture))
    assert isinstance(as_view.data, memoryview) and bytes(as_view.data) == picture.data
    assert codec(ImageView).encode(as_view) == codec(Image).encode(picture)


# --- routes --------------------------------------------------------------------------------------


def test_default_routes_bridge_every_typed_key_out():
    """By default every key with a ROS 2 type goes out on / + key (under /NS with a namespace),
    tf_static TRANSIENT_LOCAL; the support plane and ground truth have no ROS type and stay."""
    out, into = plan(namespace="robot1")
    assert into == []
    by_key = {r.key: r for r in out}
    assert set(by_key) == set(OUT_KEYS)
    assert keys.SUPPORT not in by_key and keys.GROUND_TRUTH not in by_key
    assert by_key["camera/image_raw"].topic == "/robot1/camera/image_raw"
    assert by_key["detections"].typename == "vision_msgs/msg/Detection3DArray"
    assert by_key["tf_static"].latched and not by_key["clock"].latched


def test_routes_from_flags_and_presets():
    """--out chooses keys and names; --preset realsense fills in the driver's topics, which then
    do not go out; mistakes get errors that say what to give."""
    out, into = plan(out=["detections=found", "clock=/sim_clock"], namespace="r1")
    assert [(r.key, r.topic) for r in out] == [("detections", "/r1/found"), ("clock", "/sim_clock")]
    out, into = plan(preset="realsense", ins=["/compressed/image_raw/compressedDepth=camera/pose"])
    topics = {r.key: r.topic for r in into}
    assert topics["camera/depth/image_raw"] == "/camera/camera/aligned_depth_to_color/image_raw"
    assert into[-1].typename == "geometry_msgs/msg/TransformStamped"
    assert {r.key for r in into}.isdisjoint(r.key for r in out)
    tf = next(r for r in into if r.key == "tf_static")
    assert tf.latched and tf.qos.depth == 100
    _, [compressed] = plan(no_out=True, ins=["/cam/image_raw/compressed=camera/image_raw"])
    assert compressed.typename == "sensor_msgs/msg/CompressedImage"
    for kwargs, message in [
        ({"ins": ["/camera/image_raw"]}, "give TOPIC=KEY"),
        ({"ins": ["/x=camera/nothing"]}, "not a key with a ROS 2 type"),
        ({"ins": ["/x=detections"]}, "not a key with a ROS 2 type"),
        ({"ins": ["/a=clock", "/b=clock"]}, "already comes from /a"),
        ({"ins": ["/clock=clock"], "out": ["clock"]}, "a key goes one way"),
        ({"ins": ["/detections=camera/image_raw"]}, "both read from ROS 2 and written"),
        ({"out": ["camera/image_raw=/9lives"]}, "not a ROS 2 name"),
        ({"no_out": True}, "nothing to bridge"),
        ({"preset": "kinect2"}, "one of realsense, azure_kinect"),
    ]:
        with pytest.raises(SettingError, match=message):
            plan(**kwargs)


def test_command_line_errors_exit_with_the_reason():
    """--help explains both directions; bad flags and a bad ROS_DOMAIN_ID end the command with
    exit 2 and one line saying why."""
    helped = run_onebox("ros2", "--help")
    assert helped.returncode == 0
    assert "--preset {azure_kinect,realsense}" in helped.stdout and "rmw_zenoh" in helped.stdout
    done = run_onebox("ros2", "--in", "/camera/image_raw", "--connect", "tcp/127.0.0.1:1")
    assert done.returncode == 2 and "give TOPIC=KEY" in done.stderr
    done = run_onebox("ros2", env={"ROS_DOMAIN_ID": "abc"})
    assert done.returncode == 2 and "ROS_DOMAIN_ID 'abc'" in done.stderr


# --- end to end ----------------------------------------------------------------------------------


def _ground_truth(items: list[tuple[str, bytes]]) -> dict[int, GroundTruth]:
    decoder = codec(GroundTruth)
    return {
        t.header.stamp_ns: t
        for t in (decoder.decode(p) for k, p in items if k == "sim/ground_truth")
    }


def test_sim_and_locator_seen_from_ros2(processes, test_bus, inbox):
    """Router, sim, locator and bridge: the peer lists /onebox and its topics with Jazzy's types
    and hashes; decodes the depth picture (the sim's own pixels), the lens, the clock and the
    detections (the box within 1 mm of the truth); gets tf_static though it subscribes late;
    each sample carries the attachment; garbage on a key is logged and the rest goes on."""
    for key in ("camera/depth/image_raw", "sim/ground_truth"):
        test_bus.subscribe_raw(key, inbox)
    bridge = Output(processes.start("ros2", "--log-interval-s", "1"))
    bridge.wait_for("ROS 2 node /onebox on domain 0")
    processes.start("locator", "--log-interval-s", "1")
    processes.start("sim", "--rate-hz", "10", "--frames", "100")
    peer = RmwPeer(test_bus.session, name="rviz")
    try:
        graph = peer.wait_for(
            lambda g: sum(e.kind == "MP" and e.node == "/onebox" for e in g) == len(OUT_KEYS)
        )
        published = {e.topic: e for e in graph if e.kind == "MP"}
        assert {e.node for e in graph if e.kind == "NN"} >= {"/onebox", "/rviz"}
        for topic, typename in [
            ("/camera/depth/image_raw", "sensor_msgs/msg/Image"),
            ("/camera/camera_info", "sensor_msgs/msg/CameraInfo"),
            ("/camera/points", "sensor_msgs/msg/PointCloud2"),
            ("/tf_static", "tf2_msgs/msg/TFMessage"),
            ("/clock", "rosgraph_msgs/msg/Clock"),
            ("/detections", "vision_msgs/msg/Detection3DArray"),
        ]:
            assert published[topic].typename == typename
            assert published[topic].type_hash == JAZZY_HASHES[typename]
        assert published["/tf_static"].qos == ":1:,1:,:,:,,"  # TRANSIENT_LOCAL, depth 1
        depth = peer.subscribe("/camera/depth/image_raw", "sensor_msgs/msg/Image")
        info = peer.subscribe("/camera/camera_info", "sensor_msgs/msg/CameraInfo")
        clock = peer.subscribe("/clock", "rosgraph_msgs/msg/Clock")
        found = peer.subscribe("/detections", "vision_msgs/msg/Detection3DArray")
        pictures = depth.wait(3)
        test_bus.session.put("camera/camera_info", b"not msgpack")
        tf = peer.subscribe("/tf_static", "tf2_msgs/msg/TFMessage", transient_local=True)
        [latched] = tf.wait(1)
        chain = {t.child_frame_id: t.header.frame_id for t in latched.message.transforms}
        assert chain == {"camera_link": "world", "camera_optical_frame": "camera_link"}

        first = pictures[0]
        assert (first.message.encoding, first.message.width, first.message.height) == (
            "32FC1",
            320,
            240,
        )
        stamp_ns = first.message.header.stamp.sec * 10**9 + first.message.header.stamp.nanosec
        inbox.wait(lambda items: len(_ground_truth(items)) >= 3)
        onebox_depth = {
            m.header.stamp_ns: m
            for m in (codec(Image).decode(p) for k, p in inbox.items if k.endswith("image_raw"))
        }
        assert first.message.data == onebox_depth[stamp_ns].data  # the sim's pixels, exactly
        sequences = [r.sequence for r in pictures]
        assert sequences == list(range(sequences[0], sequences[0] + len(pictures)))
        assert len({r.gid for r in pictures}) == 1 and first.gid != latched.gid
        assert abs(first.source_time_ns / 1e9 - time.time()) < 60

        lens = info.wait(1)[0].message
        assert list(lens.k)[2] == 159.5 and (lens.width, lens.height) == (320, 240)
        assert clock.wait(1)[0].message.clock.sec >= 0
        detections = found.wait(3)
        truths = _ground_truth(inbox.items)
        checked = 0
        for received in detections:
            header = received.message.header
            truth = truths.get(header.stamp.sec * 10**9 + header.stamp.nanosec)
            if truth is None or truth.box_pose is None or not received.message.detections:
                continue
            centre = received.message.detections[0].bbox.center.position
            assert abs(centre.x - truth.box_pose.position.x) < 0.001
            assert abs(centre.y - truth.box_pose.position.y) < 0.001
            assert header.frame_id == "world"
            checked += 1
        assert checked >= 1
        # The bad sample: logged with its key, and the lens keeps coming afterwards.
        bridge.wait_for(r"camera/camera_info: does not decode as CameraInfo")
        count = len(info.received)
        info.wait(count + 2)
    finally:
        peer.close()
    assert "Traceback" not in bridge.stop()


def _realsense_messages(stamp_ns: int) -> dict[str, dict]:
    """The committed capture as a RealSense's ROS 2 driver publishes it: the depth aligned to
    colour in 16UC1 millimetres, rgb8 colour, the aligned lens."""
    capture = load_capture()
    depth, colour, lens = (
        capture["camera/depth/image_raw"],
        capture["camera/image_raw"],
        capture["camera/camera_info"],
    )
    assert isinstance(depth, Image) and isinstance(colour, Image)
    assert isinstance(lens, CameraInfo)
    metres = np.frombuffer(depth.data, np.float32).reshape(depth.height, depth.width)
    millimetres = np.where(np.isfinite(metres), np.round(metres * 1000), 0).astype("<u2")
    sec, nanosec = divmod(stamp_ns, 10**9)
    frame = "camera_color_optical_frame"
    header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame}
    picture = {"header": header, "height": depth.height, "width": depth.width, "is_bigendian": 0}
    return {
        "depth": {**picture, "encoding": "16UC1", "step": depth.width * 2,
                  "data": millimetres.tobytes()},
        "colour": {**picture, "encoding": "rgb8", "step": colour.step, "data": colour.data},
        "info": {"header": header, "height": lens.height, "width": lens.width,
                 "distortion_model": "plumb_bob", "d": [0.0] * 5, "k": list(lens.k),
                 "r": list(lens.r), "p": list(lens.p)},
    }  # fmt: skip


def _static(parent: str, child: str, t: tuple[float, ...], q: tuple[float, ...]) -> dict:
    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": dict(zip("xyz", t, strict=True)),
            "rotation": dict(zip("xyzw", q, strict=True)),
        },
    }


def test_locator_finds_the_box_in_a_realsenses_pictures(processes, test_bus, inbox):
    """A peer publishes as realsense2_camera would (its topics, 16UC1 depth, two latched
    tf_static publishers declared before the bridge starts); `onebox ros2 --preset realsense`
    on domain 7 feeds the real locator, which finds the box within 2 mm; both latched
    transforms reach onebox's tf_static; garbage and a colour picture on the depth topic are
    logged with their topic and the box is still found."""
    test_bus.subscribe_raw("detections", inbox)
    test_bus.subscribe_raw("tf_static", inbox, history=True)
    peer = RmwPeer(test_bus.session, domain=7, name="camera", namespace="/camera")
    try:
        # The robot's frames (as robot_state_publisher latches them) and the camera's own.
        mount = peer.publisher("/tf_static", "tf2_msgs/msg/TFMessage", transient_local=True)
        capture_tf = load_capture()["tf_static"]
        assert isinstance(capture_tf, TFMessage)
        world_link, link_optical = capture_tf.transforms
        mount.publish({"transforms": [_from_onebox(world_link)]})
        optical = RmwPeer(test_bus.session, domain=7, name="realsense2_camera")
        driver_tf = optical.publisher("/tf_static", "tf2_msgs/msg/TFMessage", transient_local=True)
        driver_tf.publish({"transforms": [
            _from_onebox(link_optical, child="camera_color_optical_frame"),
            _static("camera_link", "camera_depth_frame", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        ]})  # fmt: skip
        depth = optical.publisher(
            "/camera/camera/aligned_depth_to_color/image_raw", "sensor_msgs/msg/Image"
        )
        colour = optical.publisher("/camera/camera/color/image_raw", "sensor_msgs/msg/Image")
        info = optical.publisher(
            "/camera/camera/aligned_depth_to_color/camera_info", "sensor_msgs/msg/CameraInfo"
        )
        bridge = Output(
            processes.start(
                "ros2", "--preset", "realsense", "--no-out", "--log-interval-s", "1",
                env={"ROS_DOMAIN_ID": "7"},
            )
        )  # fmt: skip
        processes.start("locator", "--log-interval-s", "1")
        peer.wait_for(lambda g: sum(e.kind == "MS" and e.node == "/onebox" for e in g) == 4)
        inbox.wait(has_key("tf_static"))
        # First what a broken driver might send: bytes that are no Image, a colour picture on
        # the depth topic. Each is logged with its topic; the bridge goes on.
        depth.publish_raw(b"\x00\x01\x00\x00garbage")
        depth.publish(_realsense_messages(1_700_000_000_000_000_000)["colour"])
        bridge.wait_for(
            r"/camera/camera/aligned_depth_to_color/image_raw: does not decode as "
            r"sensor_msgs/msg/Image"
        )
        bridge.wait_for(r"aligned_depth_to_color/image_raw: a rgb8 picture for camera/depth")
        stop = threading.Event()
        sent = {"n": 0}

        def camera() -> None:
            while not stop.is_set():
                sent["n"] += 1
                messages = _realsense_messages(1_700_000_000_000_000_000 + sent["n"] * 10**8)
                colour.publish(messages["colour"])
                info.publish(messages["info"])
                depth.publish(messages["depth"])
                stop.wait(0.2)  # the camera's frame rate

        thread = threading.Thread(target=camera, daemon=True)
        thread.start()
        try:
            items = inbox.wait(
                lambda items: any(
                    codec(Detection3DArray).decode(p).detections
                    for k, p in items
                    if k == "detections"
                ),
                timeout_s=30,
            )
        finally:
            stop.set()
            thread.join()
        found = next(
            a
            for a in (codec(Detection3DArray).decode(p) for k, p in items if k == "detections")
            if a.detections
        )
        box = found.detections[0].bbox
        assert found.header.frame_id == "world"
        assert abs(box.center.position.x - 0.065) < 0.002
        assert abs(box.center.position.y - 0.040) < 0.002
        assert abs(box.size.z - 0.060) < 0.002
        tf = [codec(TFMessage).decode(p) for k, p in inbox.items if k == "tf_static"][-1]
        assert {t.child_frame_id for t in tf.transforms} >= {
            "camera_link",
            "camera_color_optical_frame",
            "camera_depth_frame",
        }
        optical.close()
    finally:
        peer.close()
    assert "Traceback" not in bridge.stop()


def _from_onebox(t, child: str | None = None) -> dict:
    v, q = t.transform.translation, t.transform.rotation
    return _static(
        t.header.frame_id, child or t.child_frame_id, (v.x, v.y, v.z), (q.x, q.y, q.z, q.w)
    )


def test_bridge_needs_no_ros_node_to_close_cleanly(processes):
    """Started with nothing on the other side, the bridge runs, says it waits, and stops cleanly
    on SIGTERM."""
    bridge = Output(processes.start("ros2", "--in", "/clock=clock", "--log-interval-s", "0.5"))
    bridge.wait_for("waiting for a ROS 2 publisher on /clock")
    text = bridge.stop()
    assert bridge.proc.returncode == 0 and "Traceback" not in text


# --- hostile input, both ways --------------------------------------------------------------------


@pytest.fixture(scope="module")
def store():
    return typestore(Stores.ROS2_JAZZY)


def test_every_hostile_onebox_message_is_carried_or_dropped_with_a_reason(store):
    """The hostile suite's samples (garbage, cut msgpack, huge sizes, NaN, impossible stamps,
    10,000-frame tf chains) on each bridged key: each becomes CDR that mcap-ros2-support
    decodes, or is Dropped with a reason; nothing else escapes."""
    from tests.test_hostile import COLOUR, DEPTH, INFO, TF, bad_samples

    messages = RosMessages(store)
    routes = {r.key: r for r in plan(out=[DEPTH, COLOUR, INFO, TF])[0]}
    translators = {key: ToRos(route, store, messages) for key, route in routes.items()}
    decoders = {
        key: generate_dynamic(short_name(r.typename), DEFINITIONS[r.typename])[
            short_name(r.typename)
        ]
        for key, r in routes.items()
    }
    carried = dropped = 0
    for key, what, payload in bad_samples([DEPTH, COLOUR, INFO, TF]):
        try:
            cdr = translators[key].translate(payload)
        except Dropped as e:
            assert str(e), (key, what)
            dropped += 1
            continue
        decoders[key](bytes(cdr))
        carried += 1
    assert dropped > 100 and carried > 30


def _cdr(store, typename: str, message) -> bytes:
    return bytes(store.serialize_cdr(message, typename))


def test_every_hostile_ros_message_is_dropped_with_a_reason(store):
    """CDR that is empty, cut, random, big-endian-labelled, of another type, with a 4 GiB
    sequence or string, not UTF-8, or a colour picture on a depth key is Dropped with a
    reason; a good picture right after crosses with its pixels."""
    messages = RosMessages(store)
    [route] = plan(no_out=True, ins=["/d=camera/depth/image_raw"])[1]
    depth = FromRos(route, store)
    capture = load_capture()
    picture = capture["camera/depth/image_raw"]
    assert isinstance(picture, Image)
    good = _cdr(store, IMAGE, messages.image(picture))
    info = _cdr(store, CAMERA_INFO, messages.camera_info(capture["camera/camera_info"]))
    colour = _cdr(store, IMAGE, messages.image(capture["camera/image_raw"]))
    # The data length sits just before the pixels: 4 GiB of them declared.
    huge = bytearray(good)
    struct.pack_into("<I", huge, len(good) - len(picture.data) - 4, 0xFFFFFFFF)
    # The frame id's length sits after the encapsulation and the stamp.
    long_name = bytearray(good)
    struct.pack_into("<I", long_name, 12, 0xFFFFFFFF)
    not_utf8 = good.replace(b"camera_optical_frame", b"\xff" * len("camera_optical_frame"))
    hostile = {
        "empty": b"",
        "one zero": b"\x00",
        "header only": b"\x00\x01\x00\x00",
        "random": b"\x00\x01\x00\x00" + np.random.default_rng(3).bytes(1000),
        "cut in half": good[: len(good) // 2],
        "4 GiB of pixels": bytes(huge),
        "4 GiB frame id": bytes(long_name),
        "not UTF-8": not_utf8,
        "said big-endian": b"\x00\x00" + good[2:],
        "another type": info,
        "colour on depth": colour,
    }
    for what, payload in hostile.items():
        with pytest.raises(Dropped):
            depth.translate(payload)
            pytest.fail(f"{what} crossed")
    crossed = depth.translate(good)
    assert isinstance(crossed, ImageView) and bytes(crossed.data) == picture.data
    assert codec(ImageView).encode(crossed) == codec(Image).encode(picture)
