"""onebox export: ROS 2 and Foxglove files, read back by libraries other than the ones that wrote
them (rosbags writes ros2, mcap-ros2-support reads it; the Foxglove SDK writes foxglove,
mcap-protobuf-support reads it), and by Rerun's own MCAP reader."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import msgspec
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from mcap_ros2.decoder import DecoderFactory as Ros2Decoders
from rerun.chunk import RrdReader

from onebox import export
from onebox.recording import Progress, RecordingWriter
from onebox.rerun_sink import rerun_executable
from onebox.testing.fake_capture import BOX_CENTRE, BOX_SIZE, capture, tf_static
from onebox.testing.processes import CAPTURE, ROOT
from schemas import (
    UINT32,
    Clock,
    Detection3D,
    Detection3DArray,
    Header,
    Image,
    PointCloud,
    PointField,
    SupportPlane,
    TFMessage,
    codec,
)

TURNED = (0.0, 0.0, math.sin(math.radians(15)), math.cos(math.radians(15)))
"""A box turned 30 degrees about the world's up."""


def write_source(path: Path, captures: int = 2) -> Path:
    """A recording with tf_static, the clock, whole captures, a support plane and bad messages."""
    with RecordingWriter(path) as w:
        w.add("tf_static", codec(TFMessage).encode(tf_static()), log_time_ns=1)
        for i in range(1, captures + 1):
            stamp = i * 200_000_000
            w.add("clock", codec(Clock).encode(Clock(clock_ns=stamp)), log_time_ns=10 * i)
            for key, message in capture(stamp).items():
                if key == "detections":
                    message = turned(message)
                w.add(key, codec(type(message)).encode(message), log_time_ns=10 * i + 1)
            plane = SupportPlane(header=Header(stamp_ns=stamp, frame_id="world"))
            w.add("support", codec(SupportPlane).encode(plane), log_time_ns=10 * i + 2)
        # Hostile: a stamp no ROS time holds, and a cloud whose rgb overruns each point.
        bad_image = capture(2**62)["camera/image_raw"]
        w.add("camera/image_raw", codec(Image).encode(bad_image), log_time_ns=1000)
        cloud = capture(stamp)["camera/points"]
        fields = [*cloud.fields[:3], PointField(name="rgb", offset=14, datatype=UINT32)]
        overrun = msgspec.structs.replace(cloud, fields=fields)
        w.add("camera/points", codec(PointCloud).encode(overrun), log_time_ns=1001)
    return path


def turned(found: Detection3DArray) -> Detection3DArray:
    d = found.detections[0]
    x, y, z, w = TURNED
    centre = type(d.bbox.center)(
        position=d.bbox.center.position,
        orientation=type(d.bbox.center.orientation)(x=x, y=y, z=z, w=w),
    )
    box = type(d.bbox)(center=centre, size=d.bbox.size)
    return Detection3DArray(
        header=found.header, detections=[Detection3D(header=d.header, results=d.results, bbox=box)]
    )


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_source(tmp_path_factory.mktemp("export") / "source.mcap")


@pytest.fixture(scope="module")
def ros2_file(source, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ros2") / "out.mcap"
    result = export.export(source, out, "ros2")
    assert result.bad == {"camera/image_raw": 1, "camera/points": 1}
    assert result.left_out == {"support": 2}
    return out


@pytest.fixture(scope="module")
def foxglove_file(source, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("foxglove") / "out.mcap"
    export.export(source, out, "foxglove")
    return out


def decoded(path: Path, factory) -> dict[str, list]:
    """{topic: [(schema name, channel, decoded message), ...]} read with ``factory``."""
    out: dict[str, list] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[factory])
        for schema, channel, _, message in reader.iter_decoded_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append((schema, channel, message))
    return out


def test_ros2_export_reads_back_with_mcap_ros2_support(source, ros2_file):
    """Pictures byte for byte, the lens, the frames, the clock and the box, as ROS 2 types."""
    with ros2_file.open("rb") as f:
        header = make_reader(f).get_header()
    assert header.profile == "ros2"
    topics = decoded(ros2_file, Ros2Decoders())
    expected = capture(200_000_000)
    types = {topic: items[0][0].name for topic, items in topics.items()}
    assert types == {
        "/tf_static": "tf2_msgs/msg/TFMessage",
        "/clock": "rosgraph_msgs/msg/Clock",
        "/camera/image_raw": "sensor_msgs/msg/Image",
        "/camera/depth/image_raw": "sensor_msgs/msg/Image",
        "/camera/camera_info": "sensor_msgs/msg/CameraInfo",
        "/camera/pose": "geometry_msgs/msg/TransformStamped",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/camera/points": "sensor_msgs/msg/PointCloud2",
        "/detections": "vision_msgs/msg/Detection3DArray",
    }
    assert all(items[0][1].message_encoding == "cdr" for items in topics.values())
    assert all(items[0][0].encoding == "ros2msg" for items in topics.values())
    # tf_static is latched, as ros2 bag play must republish it to late joiners.
    assert "durability: 1" in topics["/tf_static"][0][1].metadata["offered_qos_profiles"]
    assert "durability: 2" in topics["/camera/image_raw"][0][1].metadata["offered_qos_profiles"]

    for key in ("image_raw", "depth/image_raw"):
        images = [m for _, _, m in topics[f"/camera/{key}"]]
        assert len(images) == 2, "the picture stamped past 2^31 s is left out"
        assert bytes(images[0].data) == expected[f"camera/{key}"].data
        assert (images[0].header.stamp.sec, images[0].header.stamp.nanosec) == (0, 200_000_000)
        assert images[0].header.frame_id == "camera_optical_frame"
    assert images[0].encoding == "32FC1" and images[0].step == 320 * 4
    info = topics["/camera/camera_info"][0][2]
    assert list(info.k) == pytest.approx(expected["camera/camera_info"].k)
    assert list(info.k)[2] == pytest.approx(159.5), "the middle of pixel u at u, as in ROS"
    assert (info.width, info.height) == (320, 240)

    tf = topics["/tf_static"][0][2].transforms
    assert [(t.header.frame_id, t.child_frame_id) for t in tf] == [
        ("world", "camera_link"),
        ("camera_link", "camera_optical_frame"),
    ]
    q = tf[0].transform.rotation
    assert (q.x, q.y, q.z, q.w) == pytest.approx((-0.5, 0.5, 0.5, 0.5))
    assert tf[0].transform.translation.z == pytest.approx(0.4)
    pose = topics["/tf"][0][2].transforms[0]
    assert (pose.header.frame_id, pose.child_frame_id) == ("world", "camera_optical_frame")
    assert [m.clock.nanosec for _, _, m in topics["/clock"]] == [200_000_000, 400_000_000]

    cloud = topics["/camera/points"][0][2]
    assert len(topics["/camera/points"]) == 2, "the cloud whose rgb overruns its point is left out"
    assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [
        ("x", 0, 7),
        ("y", 4, 7),
        ("z", 8, 7),
        ("rgb", 12, 6),
    ]
    assert bytes(cloud.data) == expected["camera/points"].data

    found = topics["/detections"][0][2].detections
    assert len(found) == 1
    box = found[0].bbox
    p, o = box.center.position, box.center.orientation
    assert (p.x, p.y, p.z) == pytest.approx(BOX_CENTRE)
    assert (o.x, o.y, o.z, o.w) == pytest.approx(TURNED)
    assert (box.size.x, box.size.y, box.size.z) == pytest.approx(BOX_SIZE)
    hypothesis = found[0].results[0].hypothesis
    assert (hypothesis.class_id, hypothesis.score) == ("box", pytest.approx(1.0))


def test_foxglove_export_reads_back_with_mcap_protobuf_support(foxglove_file):
    """RawImage bytes, CameraCalibration K, FrameTransforms, PointCloud and a cube a box."""
    topics = decoded(foxglove_file, ProtobufDecoders())
    expected = capture(200_000_000)
    types = {topic: items[0][0].name for topic, items in topics.items()}
    assert types == {
        "tf_static": "foxglove.FrameTransforms",
        "camera/image_raw": "foxglove.RawImage",
        "camera/depth/image_raw": "foxglove.RawImage",
        "camera/camera_info": "foxglove.CameraCalibration",
        "tf": "foxglove.FrameTransforms",
        "camera/points": "foxglove.PointCloud",
        "detections": "foxglove.SceneUpdate",
    }
    for key in ("image_raw", "depth/image_raw"):
        images = [m for _, _, m in topics[f"camera/{key}"]]
        assert len(images) == 2
        assert images[0].data == expected[f"camera/{key}"].data
        assert (images[0].timestamp.seconds, images[0].timestamp.nanos) == (0, 200_000_000)
        assert images[0].frame_id == "camera_optical_frame"
    calibration = topics["camera/camera_info"][0][2]
    assert list(calibration.K) == pytest.approx(expected["camera/camera_info"].k)
    assert (calibration.width, calibration.height) == (320, 240)
    frames = topics["tf_static"][0][2].transforms
    assert [(t.parent_frame_id, t.child_frame_id) for t in frames] == [
        ("world", "camera_link"),
        ("camera_link", "camera_optical_frame"),
    ]
    assert frames[0].translation.z == pytest.approx(0.4)
    cloud = topics["camera/points"][0][2]
    assert cloud.point_stride == 16 and cloud.data == expected["camera/points"].data
    assert [(f.name, f.offset, f.type) for f in cloud.fields] == [
        ("x", 0, 7),
        ("y", 4, 7),
        ("z", 8, 7),
        ("rgb", 12, 5),
    ]
    update = topics["detections"][0][2]
    cube = update.entities[0].cubes[0]
    p, o = cube.pose.position, cube.pose.orientation
    assert (p.x, p.y, p.z) == pytest.approx(BOX_CENTRE)
    assert (o.x, o.y, o.z, o.w) == pytest.approx(TURNED)
    assert (cube.size.x, cube.size.y, cube.size.z) == pytest.approx(BOX_SIZE)
    assert update.entities[0].texts[0].text == "box 60 x 60 x 60 mm, yaw +30°"
    assert update.entities[0].frame_id == "world"


@pytest.mark.parametrize("to", export.FORMATS)
def test_rerun_mcap_reader_brings_the_pictures_through(to, ros2_file, foxglove_file, tmp_path):
    """`rerun mcap convert` of the exported file holds the colour picture, byte for byte."""
    exported = ros2_file if to == "ros2" else foxglove_file
    rrd = tmp_path / "converted.rrd"
    done = subprocess.run(
        [rerun_executable(), "mcap", "convert", str(exported), "-o", str(rrd)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    pictures: dict[str, bytes] = {}
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        for name in ("Image:buffer", "DepthImage:buffer"):
            if name in batch.schema.names:
                values = [v for v in batch.column(name).to_pylist() if v is not None]
                pictures[chunk.entity_path] = bytes(values[0][0])
    expected = capture(200_000_000)
    assert pictures["/camera/image_raw"] == expected["camera/image_raw"].data
    assert pictures["/camera/depth/image_raw"] == expected["camera/depth/image_raw"].data


def run_export(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "services.cli", "export", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_export_of_the_committed_capture_and_overwrite(tmp_path):
    """The command exports the committed capture, then refuses to overwrite without --overwrite."""
    out = tmp_path / "capture_ros2.mcap"
    done = run_export(str(CAPTURE), str(out), "--to", "ros2")
    assert done.returncode == 0, done.stderr
    assert f"export: wrote {out} (ros2): 4 messages" in done.stdout
    size = out.stat().st_size
    again = run_export(str(CAPTURE), str(out), "--to", "foxglove")
    assert again.returncode == 2
    assert "already exists" in again.stderr and "--overwrite" in again.stderr
    assert out.stat().st_size == size, "the existing file is untouched"
    forced = run_export(str(CAPTURE), str(out), "--to", "foxglove", "--overwrite")
    assert forced.returncode == 0, forced.stderr
    with out.open("rb") as f:
        schemas = make_reader(f).get_summary().schemas.values()
    assert {s.encoding for s in schemas} == {"protobuf"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture_ros2.mcap"]


@pytest.mark.parametrize("content", [b"", b"not an mcap file at all", b"\x89MCAP0\r\n\x01trunc"])
def test_bad_input_is_one_line_and_leaves_nothing(content, tmp_path):
    """An empty, foreign or truncated input: exit 2, one line naming it, no output file."""
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    out = tmp_path / "out.mcap"
    done = run_export(str(bad), str(out), "--to", "ros2")
    assert done.returncode == 2
    assert str(bad) in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


def test_progress_is_reported_on_long_files(source, tmp_path, capsys):
    """The progress callback prints 'N of M messages' and reaches the end."""
    seen: list[tuple[int, int]] = []
    export.export(source, tmp_path / "p.mcap", "ros2", progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (seen[-1][1], seen[-1][1]) and seen[-1][1] == 1 + 2 * 8 + 2
    printer = Progress("export", interval_s=0.0)
    printer(100, 400)
    assert capsys.readouterr().out == "export: 100 of 400 messages (25 %)\n"


def test_a_failed_export_removes_its_partial_file(source, tmp_path, monkeypatch):
    """An error half way (here a writer that fails) leaves no file at all behind."""
    from onebox.export import ros2

    calls = 0

    def fail_later(self, name, topic, message, log_time_ns):
        nonlocal calls
        calls += 1
        if calls > 3:
            raise OSError(28, "No space left on device")
        return True

    monkeypatch.setattr(ros2.Ros2Target, "write", fail_later)
    with pytest.raises(export.ExportError, match="No space left on device"):
        export.export(source, tmp_path / "out.mcap", "ros2")
    assert list(tmp_path.iterdir()) == []
