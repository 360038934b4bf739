"""A real camera's ROS bag as a onebox recording, so ``onebox replay`` drives the locator with it.

:func:`import_bag` reads a ROS 2 bag (an ``.mcap`` or ``.db3`` file, or the folder ``ros2 bag
record`` makes) or a ROS 1 ``.bag`` with the ``rosbags`` library, and writes a onebox MCAP
recording (zstd) of:

  the depth picture    sensor_msgs/Image 16UC1, 32FC1 or mono16  ->  camera/depth/image_raw
  its lens             sensor_msgs/CameraInfo beside it           ->  camera/camera_info
  the colour picture   sensor_msgs/Image rgb8, bgr8, rgba8, bgra8 ->  camera/image_raw
  the fixed frames     tf2_msgs/TFMessage on .../tf_static        ->  tf_static (all of them)
  a moving camera      its chain through /tf at each depth stamp  ->  camera/pose

A camera on an arm hangs off a moving transform: its pose in ``world_frame`` (default: the
root of its tree) is looked up at each depth picture's stamp as tf2 does (between the two
samples of each moving transform around the stamp, never extrapolated past 0.2 s) and written
on camera/pose with the picture's stamp, for a locator run with ``--pose-source pose``.

Bags recorded to save space often hold only ``image_transport``'s compressed topics; those are
read too: ``.../compressedDepth`` (sensor_msgs/CompressedImage, a 12-byte header and a PNG:
16UC1 millimetres as they are, 32FC1 as quantised inverse depth) becomes 16UC1 or 32FC1, and
``.../compressed`` (JPEG or PNG) becomes rgb8. When a bag has a stream both raw and compressed,
the raw one is taken. ``rvl`` compressed depth is not read (the error says so).

Which topic is which is read from the pictures' encodings; a bag with several depth topics
(a RealSense's depth/image_rect_raw and aligned_depth_to_color/image_raw) takes the one the
colour picture is aligned with (the same size), and ``depth``/``colour``/``info`` name topics
outright. The lens is the CameraInfo in the depth topic's own folder
(``.../aligned_depth_to_color/camera_info``). A colour picture of another size than the depth
(not aligned to it) is left out: the locator then reads depth alone. Stamps are the bag's
header stamps (sec, nanosec) in nanoseconds; frames keep their names, so the locator reports
in the camera's optical frame unless a ``world_frame`` it is given is on tf_static
(``ONEBOX_WORLD_FRAME=base_link``). Real cameras stamp depth and colour apart: run the locator
with ``--slop-ms`` (half the frame period) to pair them.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import struct
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from onebox import keys
from onebox.errors import RecordingError
from onebox.geometry import Float64Array, FrameError, FrameTree
from onebox.pictures import depth_image, rgb8_image
from onebox.recording import RecordingWriter, output_problem, written_whole
from onebox.sync import ReportLimiter
from schemas import (
    CameraInfo,
    Clock,
    Header,
    Image,
    ImageView,
    Message,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    codec,
)

log = logging.getLogger("import")

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
TRANSPORTS = ("/compressedDepth", "/compressed")
"""image_transport's topics beside a raw picture's: the compressed picture of ``.../image_raw``
is on ``.../image_raw/compressed`` (colour) or ``.../image_raw/compressedDepth`` (depth)."""
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF = "tf2_msgs/msg/TFMessage"
TRANSFORM = "geometry_msgs/msg/TransformStamped"
CLOCK = "rosgraph_msgs/msg/Clock"
DEPTH_ENCODINGS = {"16UC1": "16UC1", "mono16": "16UC1", "32FC1": "32FC1"}
"""A depth picture's encodings, and what onebox calls each (mono16 is 16UC1's other name)."""
COLOUR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8")


class BagError(RecordingError):
    """A bag could not be imported; the message says why and what to do."""


@dataclass(frozen=True)
class Picture:
    """An image topic, as its first message shows it."""

    topic: str
    encoding: str
    """What onebox writes it as (a compressed picture: what it decodes to)."""
    width: int
    height: int
    compressed: str = ""
    """A CompressedImage's format ("16UC1; compressedDepth png", "rgb8; jpeg compressed bgr8");
    empty for a raw picture."""

    @property
    def described(self) -> str:
        how = f", from {self.compressed}" if self.compressed else ""
        return f"{self.encoding}{how}, {self.width} x {self.height}"

    @property
    def stream(self) -> str:
        """The raw picture's topic this is (itself, or the topic its transport hangs off)."""
        for suffix in TRANSPORTS:
            if self.compressed and self.topic.endswith(suffix):
                return self.topic[: -len(suffix)]
        return self.topic


@dataclass(frozen=True)
class Choice:
    """The topics taken, and the image topics seen."""

    depth: Picture
    info: str
    colour: Picture | None
    tf_static: tuple[str, ...]
    pictures: tuple[Picture, ...]
    colour_left_out: str = ""
    """Why no colour picture is taken, when there is a colour topic."""
    tf: tuple[str, ...] = ()
    """The bag's moving transforms (``/tf``): a camera on an arm or a robot."""


@dataclass
class ImportResult:
    """What an import wrote and what it left out."""

    choice: Choice
    written: Counter[str] = field(default_factory=Counter)
    """Messages written, by onebox key."""
    left_out: Counter[str] = field(default_factory=Counter)
    """Messages of the bag not imported, by topic."""
    bad: Counter[str] = field(default_factory=Counter)
    """Messages that did not decode or convert, by topic."""
    distorted: bool = False
    """The depth lens has distortion coefficients (kept: the locator rectifies as it reads)."""
    world_frame: str = ""
    """The frame camera/pose places the camera in, when the camera moves (on ``/tf``)."""
    unplaced: int = 0
    """Depth pictures of a moving camera with no transform at their stamp (no camera/pose)."""


def _folder(topic: str) -> str:
    return topic.rsplit("/", 1)[0]


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _header(header: Any) -> Header:
    return Header(stamp_ns=_stamp_ns(header), frame_id=str(header.frame_id))


def _pictures(reader: Any) -> list[Picture]:
    """Every image topic as its first message shows it."""
    pictures = []
    for connection in reader.connections:
        if connection.msgtype not in (IMAGE, COMPRESSED):
            continue
        for _, _, raw in reader.messages(connections=[connection]):
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.msgtype == IMAGE:
                encoding, width, height = str(msg.encoding), int(msg.width), int(msg.height)
                compressed = ""
            else:
                compressed = str(msg.format)
                try:
                    image = _decompressed(msg)
                except ValueError as e:
                    log.warning("%s: left out: %s", connection.topic, e)
                    break
                encoding, width, height = image.encoding, image.width, image.height
            pictures.append(Picture(connection.topic, encoding, width, height, compressed))
            break
    return pictures


def choose(
    reader: Any, depth: str | None = None, colour: str | None = None, info: str | None = None
) -> Choice:
    """Which of the bag's topics are the depth picture, its lens and the colour picture."""
    pictures = _pictures(reader)
    listed = ", ".join(f"{p.topic} ({p.described})" for p in pictures)
    by_topic = {p.topic: p for p in pictures}
    # A stream recorded both raw and compressed is taken raw unless named.
    raw_streams = {p.topic for p in pictures if not p.compressed}
    streams = [p for p in pictures if not p.compressed or p.stream not in raw_streams]
    depths = [p for p in streams if p.encoding in DEPTH_ENCODINGS]
    colours = [p for p in streams if p.encoding in COLOUR_ENCODINGS]
    if colour is not None and colour not in by_topic:
        raise BagError(f"--colour {colour}: no such image topic in the bag (its images: {listed})")
    if colour is not None and by_topic[colour].encoding not in COLOUR_ENCODINGS:
        raise BagError(
            f"--colour {colour} is {by_topic[colour].encoding}, not a colour picture "
            f"({', '.join(COLOUR_ENCODINGS)})"
        )
    if depth is not None:
        if depth not in by_topic:
            raise BagError(
                f"--depth {depth}: no such image topic in the bag (its images: {listed})"
            )
        chosen = by_topic[depth]
        if chosen.encoding not in DEPTH_ENCODINGS:
            raise BagError(
                f"--depth {depth} is {chosen.encoding}, not a depth picture "
                f"({', '.join(DEPTH_ENCODINGS)})"
            )
    elif not depths:
        raise BagError(
            "the bag holds no depth picture (sensor_msgs/Image in 16UC1, mono16 or 32FC1); "
            f"its images: {listed or 'none'}"
        )
    else:
        wanted = [by_topic[colour]] if colour is not None else colours
        aligned = [
            d for d in depths if any((c.width, c.height) == (d.width, d.height) for c in wanted)
        ]
        pool = aligned or depths
        if len(pool) > 1:
            named = [d for d in pool if "aligned" in d.topic]
            pool = named or pool
        if len(pool) > 1:
            raise BagError(
                "the bag holds several depth pictures: name one with --depth "
                f"({', '.join(d.topic for d in pool)})"
            )
        chosen = pool[0]
    infos = [c.topic for c in reader.connections if c.msgtype == CAMERA_INFO]
    if info is not None:
        if info not in infos:
            raise BagError(
                f"--info {info}: no such CameraInfo topic in the bag "
                f"(its CameraInfo topics: {', '.join(infos) or 'none'})"
            )
        lens = info
    else:
        folder = _folder(chosen.stream)
        beside = [t for t in infos if _folder(t) == folder]
        if not beside:
            raise BagError(
                f"no CameraInfo beside {chosen.topic} (in {folder}/): name the depth "
                f"picture's lens with --info (the bag's: {', '.join(infos) or 'none'})"
            )
        lens = beside[0]
    picked: Picture | None = None
    why = ""
    candidates = [by_topic[colour]] if colour is not None else colours
    same = [c for c in candidates if (c.width, c.height) == (chosen.width, chosen.height)]
    if same:
        named = [c for c in same if "color" in c.topic or "colour" in c.topic]
        picked = (named or same)[0]
    elif candidates:
        c = candidates[0]
        why = (
            f"{c.topic} is {c.width} x {c.height} but the depth is {chosen.width} x "
            f"{chosen.height}: not aligned, so the locator reads depth alone (record the "
            "depth aligned to colour, e.g. a RealSense's aligned_depth_to_color)"
        )
    tf_static = tuple(
        c.topic for c in reader.connections if c.msgtype == TF and c.topic.endswith("tf_static")
    )
    tf = tuple(
        dict.fromkeys(
            c.topic for c in reader.connections if c.msgtype == TF and c.topic not in tf_static
        )
    )
    return Choice(chosen, lens, picked, tf_static, tuple(pictures), why, tf)


def _image(msg: Any, encoding: str) -> ImageView:
    """The picture with its pixels left in the ROS message's buffer: encoding it copies them
    once, straight into the onebox message."""
    return ImageView(
        header=_header(msg.header),
        height=int(msg.height),
        width=int(msg.width),
        encoding=encoding,
        is_bigendian=int(msg.is_bigendian),
        step=int(msg.step),
        data=memoryview(msg.data),
    )


def _decompressed(msg: Any) -> Image:
    """A sensor_msgs/CompressedImage as the raw Image it was: compressedDepth's PNG as 16UC1
    (or 32FC1 from its quantised inverse depth), a JPEG or PNG colour picture as rgb8. Raises
    ValueError for what it cannot read."""
    import PIL.Image

    fmt = str(msg.format)
    data = msg.data.tobytes() if hasattr(msg.data, "tobytes") else bytes(msg.data)
    header = _header(msg.header)
    if "compressedDepth" in fmt:
        if "rvl" in fmt:
            raise ValueError(f"{fmt!r}: rvl compressed depth is not read; record it as png")
        start = data.find(b"\x89PNG")
        if start < 0:
            raise ValueError(f"{fmt!r} without a PNG in it")
        try:
            with PIL.Image.open(io.BytesIO(data[start:])) as picture:
                values = np.asarray(picture)
        except (OSError, SyntaxError, PIL.Image.DecompressionBombError) as e:
            raise ValueError(f"{fmt!r}: the PNG does not decode ({e})") from e
        if values.ndim != 2:
            raise ValueError(f"{fmt!r}: a PNG of {values.shape}, not one channel")
        height, width = values.shape
        encoding = fmt.split(";")[0].strip()
        if encoding in ("16UC1", "mono16"):
            depth = values.astype("<u2")
            return Image(header=header, height=height, width=width, encoding="16UC1",
                         step=width * 2, data=depth.tobytes())  # fmt: skip
        if encoding == "32FC1":
            # compressed_depth_image_transport stores q = A / depth + B, 0 for no reading.
            if start < 12:
                raise ValueError(f"{fmt!r}: no quantisation header before the PNG")
            a, b = struct.unpack_from("<ff", data, start - 8)
            q = values.astype(np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                metres = np.where(q > 0, a / (q - b), np.nan).astype(np.float32)
            return depth_image(metres, header)
        raise ValueError(f"{fmt!r}: compressed depth of {encoding!r} is not read")
    try:
        with PIL.Image.open(io.BytesIO(data)) as picture:
            rgb = np.asarray(picture.convert("RGB"))
    except (OSError, SyntaxError, ValueError, PIL.Image.DecompressionBombError) as e:
        raise ValueError(f"{fmt!r}: the picture does not decode ({e})") from e
    return rgb8_image(rgb, header)


def _numbers(msg: Any, name: str) -> list[float]:
    """A CameraInfo array: ``d`` in ROS 2, ``D`` in ROS 1."""
    values = getattr(msg, name) if hasattr(msg, name) else getattr(msg, name.upper())
    return [float(v) for v in values]


def _camera_info(msg: Any) -> CameraInfo:
    return CameraInfo(
        header=_header(msg.header),
        height=int(msg.height),
        width=int(msg.width),
        distortion_model=str(msg.distortion_model),
        d=_numbers(msg, "d"),
        k=_numbers(msg, "k"),
        r=_numbers(msg, "r"),
        p=_numbers(msg, "p"),
    )


def _stamped(
    header: Header,
    child: str,
    t: Sequence[float] | Float64Array,
    q_xyzw: Sequence[float] | Float64Array,
) -> TransformStamped:
    x, y, z, w = (float(v) for v in q_xyzw)
    return TransformStamped(
        header=header,
        child_frame_id=child,
        transform=Transform(
            translation=Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
            rotation=Quaternion(x=x, y=y, z=z, w=w),
        ),
    )


def _transform(t: Any) -> TransformStamped:
    v, q = t.transform.translation, t.transform.rotation
    return _stamped(_header(t.header), str(t.child_frame_id), (v.x, v.y, v.z), (q.x, q.y, q.z, q.w))


FROM_ROS: dict[type[Message], tuple[str, ...]] = {
    Image: (IMAGE, COMPRESSED),
    CameraInfo: (CAMERA_INFO,),
    TFMessage: (TF,),
    TransformStamped: (TRANSFORM,),
    Clock: (CLOCK,),
}
"""The onebox messages a ROS message becomes, and the ROS types each is read from."""


def from_ros(msg: Any, key: str, statics: dict[str, TransformStamped]) -> Message | None:
    """The onebox message on ``key`` (a key of :data:`onebox.keys.TYPES`, no namespace) for
    the ROS 2 message ``msg``, or None for a picture whose encoding that key does not carry.

    A depth key takes 16UC1, mono16 (as 16UC1) and 32FC1 only; a CompressedImage is decoded
    (:func:`_decompressed`). tf_static gathers every transform it is given in ``statics`` (each
    ROS publisher latches its own; onebox keeps them all in one message). Raises ValueError
    (or AttributeError, for a message of another type) for what it cannot read.
    """
    kind = keys.TYPES.get(key)
    if kind is Image:
        if hasattr(msg, "format"):
            return _decompressed(msg)
        if key in keys.DEPTH_KEYS:
            encoding = DEPTH_ENCODINGS.get(str(msg.encoding))
            return None if encoding is None else _image(msg, encoding)
        return _image(msg, str(msg.encoding))
    if kind is CameraInfo:
        return _camera_info(msg)
    if kind is TFMessage:
        for t in msg.transforms:
            statics[str(t.child_frame_id)] = _transform(t)
        return TFMessage(transforms=list(statics.values()))
    if kind is TransformStamped:
        return _transform(msg)
    if kind is Clock:
        return Clock(clock_ns=int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec))
    raise ValueError(f"{key}: no ROS 2 message becomes a {kind.__name__ if kind else 'key'}")


def _open(source: Path) -> Any:
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    try:
        reader = AnyReader([source], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as e:
        raise BagError(
            f"{source}: not a ROS bag onebox can read ({e}); give a ROS 2 bag (.mcap or .db3 "
            "file, or its folder) or a ROS 1 .bag"
        ) from e
    return reader


MAX_TF_GAP_NS = 200_000_000
"""A moving transform is looked up between its two samples around a picture's stamp; past its
first or last sample by more than this it is not known there (tf2 does not extrapolate)."""


class Motion:
    """The transforms of a bag's ``/tf`` and ``tf_static``, to place the camera at each
    picture's stamp as tf2 would: a moving frame between its two samples around the stamp
    (translation linear, turn by slerp), a fixed one as it is."""

    def __init__(self) -> None:
        self.statics: dict[str, TransformStamped] = {}
        self._samples: dict[str, list[tuple[int, str, Float64Array, Float64Array]]] = {}
        self._stamps: dict[str, npt.NDArray[np.int64]] = {}

    def add(self, transform: TransformStamped, moving: bool) -> None:
        child = transform.child_frame_id
        if not moving:
            self.statics[child] = transform
            return
        v, q = transform.transform.translation, transform.transform.rotation
        self._samples.setdefault(child, []).append(
            (
                transform.header.stamp_ns,
                transform.header.frame_id,
                np.array([v.x, v.y, v.z]),
                np.array([q.x, q.y, q.z, q.w]),
            )
        )

    def finish(self) -> None:
        """Sort the samples by stamp (a bag's /tf may come from several publishers)."""
        for child, samples in self._samples.items():
            samples.sort(key=lambda sample: sample[0])
            self._stamps[child] = np.array([sample[0] for sample in samples], dtype=np.int64)

    def chain(self, frame: str) -> tuple[str, bool]:
        """The root above ``frame`` and whether a moving transform is on the way up."""
        moving, seen = False, {frame}
        while True:
            if frame in self._samples:
                moving, frame = True, self._samples[frame][-1][1]
            elif frame in self.statics:
                frame = self.statics[frame].header.frame_id
            else:
                return frame, moving
            if frame in seen:  # a loop: FrameTree refuses it when the pose is looked up
                return frame, moving
            seen.add(frame)

    def _at(self, child: str, stamp_ns: int) -> TransformStamped | None:
        """A moving frame's transform at ``stamp_ns``, or None when it is not known then."""
        samples, stamps = self._samples[child], self._stamps[child]
        i = int(np.searchsorted(stamps, stamp_ns))
        if i < len(samples) and stamps[i] == stamp_ns:
            lo = hi = samples[i]
        elif 0 < i < len(samples):
            lo, hi = samples[i - 1], samples[i]
        elif i == 0 and stamps[0] - stamp_ns <= MAX_TF_GAP_NS:
            lo = hi = samples[0]
        elif i == len(samples) and stamp_ns - stamps[-1] <= MAX_TF_GAP_NS:
            lo = hi = samples[-1]
        else:
            return None
        share = 0.0 if hi[0] == lo[0] else (stamp_ns - lo[0]) / (hi[0] - lo[0])
        header = Header(stamp_ns=stamp_ns, frame_id=hi[1])
        return _stamped(header, child, lo[2] + share * (hi[2] - lo[2]), _slerp(lo[3], hi[3], share))

    def _up_from(self, frame: str, stamp_ns: int) -> list[TransformStamped]:
        """The transforms from ``frame`` up to its root as they stood at ``stamp_ns`` (a moving
        one not known then ends the walk)."""
        found: list[TransformStamped] = []
        seen = {frame}
        while True:
            if frame in self._samples:
                transform = self._at(frame, stamp_ns)
            else:
                transform = self.statics.get(frame)
            if transform is None:
                return found
            found.append(transform)
            frame = transform.header.frame_id
            if frame in seen:
                return found
            seen.add(frame)

    def pose(self, world: str, frame: str, stamp_ns: int) -> TransformStamped | None:
        """``world <- frame`` at ``stamp_ns`` as camera/pose carries it, or None when unknown."""
        try:
            tree = FrameTree(self._up_from(frame, stamp_ns) + self._up_from(world, stamp_ns))
            matrix = tree.lookup(world, frame)
        except FrameError:
            return None
        turn = Rotation.from_matrix(matrix[:3, :3]).as_quat()
        return _stamped(Header(stamp_ns=stamp_ns, frame_id=world), frame, matrix[:3, 3], turn)


def _slerp(a: Float64Array, b: Float64Array, share: float) -> Float64Array:
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    dot = float(a @ b)
    if dot < 0.0:  # the shorter way round
        b, dot = -b, -dot
    if dot > 0.9995:
        q = a + share * (b - a)
    else:
        angle = math.acos(dot)
        q = (math.sin((1 - share) * angle) * a + math.sin(share * angle) * b) / math.sin(angle)
    result: Float64Array = q / np.linalg.norm(q)
    return result


def import_bag(
    source: Path,
    destination: Path,
    *,
    depth: str | None = None,
    colour: str | None = None,
    info: str | None = None,
    world_frame: str | None = None,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> ImportResult:
    """Write the camera topics of the bag ``source`` into the onebox recording ``destination``.

    When the camera's frame hangs off a moving transform (``/tf``), each depth picture also
    gets the camera's pose on camera/pose, in ``world_frame`` (default: the root of its tree).

    ``progress(done, total)`` is called every few hundred messages. Raises BagError with a line
    that says what to do; nothing is left at ``destination`` then.
    """
    if not source.exists():
        raise BagError(f"{source} does not exist: give the path of a ROS bag")
    problem = output_problem(source, destination, overwrite=overwrite)
    if problem is not None:
        raise BagError(problem)
    reader = _open(source)
    try:
        with contextlib.closing(reader), written_whole(destination) as partial:
            choice = choose(reader, depth, colour, info)
            try:
                writer = RecordingWriter(partial, compression="zstd")
            except OSError as e:
                raise BagError(f"cannot create {destination}: {e.strerror}") from e
            with writer:
                result = _copy(reader, choice, writer, progress, world_frame)
    except OSError as e:
        raise BagError(f"cannot write {destination}: {e.strerror or e}") from e
    return result


def _motion(reader: Any, choice: Choice, limiter: ReportLimiter) -> Motion:
    """Every transform of the bag, when the depth picture's frame hangs off a moving one."""
    motion = Motion()
    moving = set(choice.tf)
    connections = [c for c in reader.connections if c.topic in moving | set(choice.tf_static)]
    for connection, _, raw in reader.messages(connections=connections):
        try:
            for t in reader.deserialize(raw, connection.msgtype).transforms:
                motion.add(_transform(t), connection.topic in moving)
        except Exception as e:  # a damaged message of any kind: reported by topic, left out
            limiter.warn(connection.topic, "bad", f"left out: {type(e).__name__}: {e}")
    motion.finish()
    return motion


def _place(
    motion: Motion,
    header: Header,
    world: str,
    result: ImportResult,
    writer: RecordingWriter,
    log_time_ns: int,
) -> None:
    """camera/pose for a depth picture of a moving camera, stamped as the picture."""
    pose = motion.pose(world, header.frame_id, header.stamp_ns)
    if pose is None:
        result.unplaced += 1
        return
    writer.add(keys.CAMERA.pose, codec(TransformStamped).encode(pose), log_time_ns)
    result.written[keys.CAMERA.pose] += 1


def _copy(
    reader: Any,
    choice: Choice,
    writer: RecordingWriter,
    progress: Callable[[int, int], None] | None,
    world_frame: str | None,
) -> ImportResult:
    result = ImportResult(choice)
    routes: dict[str, str] = {choice.depth.topic: keys.CAMERA.depth, choice.info: keys.CAMERA.info}
    if choice.colour is not None:
        routes[choice.colour.topic] = keys.CAMERA.colour
    for topic in choice.tf_static:
        routes[topic] = keys.TF_STATIC
    statics: dict[str, TransformStamped] = {}
    limiter = ReportLimiter(log)
    motion = _motion(reader, choice, limiter) if choice.tf else None
    world: str | None = None
    total = sum(c.msgcount for c in reader.connections)
    wanted = [c for c in reader.connections if c.topic in routes]
    for c in reader.connections:
        if c.topic not in routes and (motion is None or c.topic not in choice.tf):
            result.left_out[c.topic] += c.msgcount
    done = 0
    for connection, log_time_ns, raw in reader.messages(connections=wanted):
        done += 1
        if progress is not None and done % 200 == 0:
            progress(done, total)
        key = routes[connection.topic]
        try:
            message = from_ros(reader.deserialize(raw, connection.msgtype), key, statics)
        except Exception as e:  # a damaged message of any kind: reported by topic, left out
            result.bad[connection.topic] += 1
            limiter.warn(connection.topic, "bad", f"left out: {type(e).__name__}: {e}")
            continue
        if message is None:
            result.left_out[connection.topic] += 1
            continue
        if isinstance(message, CameraInfo):
            result.distorted |= any(abs(v) > 1e-9 for v in message.d)
        if (
            motion is not None
            and key == keys.CAMERA.depth
            and isinstance(message, Image | ImageView)
        ):
            if world is None:  # decided on the first picture: does the camera move?
                root, moving = motion.chain(message.header.frame_id)
                world = (world_frame or root) if moving else ""
                result.world_frame = world
            if world:
                _place(motion, message.header, world, result, writer, log_time_ns)
        payload = codec(type(message)).encode(message)
        writer.add(key, payload, log_time_ns)
        result.written[key] += 1
    if progress is not None:
        progress(done, total)
    return result
