"""Read a recorded capture into typed messages, as the seed's tests read their rosbag (3.1)."""

from __future__ import annotations

from pathlib import Path

from onebox.recording import read_capture
from onebox.testing.processes import CAPTURE
from schemas import Message


def load_capture(path: Path | str = CAPTURE, namespace: str = "") -> dict[str, Message]:
    """The last message on each key of ``path``, keyed without ``namespace``.

    For the committed capture: ``camera/camera_info``, ``camera/depth/image_raw``,
    ``camera/image_raw`` (one stamp) and ``tf_static``.
    """
    return read_capture(path, namespace)
