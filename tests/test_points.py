"""onebox points as a real process: depth + colour + camera info in, camera/points out."""

from __future__ import annotations

import time

import numpy as np

from onebox.testing.processes import has_key
from onebox.testing.synthetic import Scene, camera_info, depth_image, depth_picture
from schemas import CameraInfo, Image, PointCloud, codec

SCENE = Scene()


def colour_image(stamp_ns: int, width: int = 320, height: int = 240) -> Image:
    rgb = np.zeros((height, width, 3), np.uint8)
    rgb[..., 0] = 121
    rgb[min(86, height - 1), min(212, width - 1)] = (200, 10, 20)
    depth = depth_image(np.zeros((1, 1), np.float32), stamp_ns)
    return Image(
        header=depth.header,
        height=height,
        width=width,
        encoding="rgb8",
        step=width * 3,
        data=rgb.tobytes(),
    )


def test_points_builds_the_cloud_and_survives_bad_input(processes, test_bus, inbox):
    """A capture gives one point a reading pixel, the seed's point and its colour; a colour
    picture of the wrong size is reported and a later capture still becomes a cloud."""
    test_bus.subscribe_raw("camera/points", inbox)
    depth_pub = test_bus.publisher("camera/depth/image_raw", Image)
    colour_pub = test_bus.publisher("camera/image_raw", Image)
    info_pub = test_bus.publisher("camera/camera_info", CameraInfo)
    picture = depth_picture(SCENE)
    picture[0, :] = np.nan  # no reading along the top row: those pixels are skipped
    proc = processes.start("points", "--log-interval-s", "0.5")

    def capture(stamp_ns: int, colour: Image | None = None) -> None:
        info_pub.publish(camera_info(SCENE, stamp_ns))
        colour_pub.publish(colour or colour_image(stamp_ns))
        depth_pub.publish(depth_image(picture, stamp_ns))

    stamp_ns = 0
    deadline = time.monotonic() + 20
    while not inbox.items and time.monotonic() < deadline:
        stamp_ns += 200_000_000
        capture(stamp_ns)
        try:
            inbox.wait(has_key("camera/points"), timeout_s=0.5)
        except AssertionError:
            continue
    cloud = codec(PointCloud).decode(inbox.items[0][1])
    assert cloud.header.frame_id == "camera_optical_frame"
    assert cloud.width == 320 * 239 and cloud.point_step == 16 and cloud.is_dense
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"]
    points = np.frombuffer(
        cloud.data, np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    )
    seed = points[85 * 320 + 212]  # row 86, one row fewer because row 0 has no reading
    assert f"{seed['x']:+.4f} {seed['y']:+.4f} {seed['z']:+.4f}" == "+0.0644 -0.0411 +0.3400"
    assert seed["rgb"] == 0xC80A14

    stamp_ns += 200_000_000
    capture(stamp_ns, colour=colour_image(stamp_ns, width=160, height=120))
    stamp_ns += 200_000_000
    inbox.items.clear()
    capture(stamp_ns)
    items = inbox.wait(has_key("camera/points"))
    assert codec(PointCloud).decode(items[-1][1]).header.stamp_ns == stamp_ns
    output = processes.stop(proc)
    assert "colour 160 x 120" in output and "Traceback" not in output
