"""Real RGB-D captures with reference tops, and the rule that scores box detections on them.

A capture folder (``tests/data/realdata`` holds the ones that may be committed) has
``captures.json``, a JSON list of captures, and for each capture ``NAME``:

- ``NAME.depth.png``: 16-bit z-depth in millimetres, 0 = no reading;
- ``NAME.colour.png``: 8-bit RGB, aligned pixel for pixel with the depth;
- ``NAME.box<k>.png``, ``NAME.notbox<k>.png``, ``NAME.ignore<k>.png``: 0/255 masks of each
  reference box's visible top face, of the objects that are not boxes, of the boxes whose top
  cannot be measured.

Everything is in the camera's optical frame (x right, y down, z forward, metres); K follows
OpenCV (the middle of pixel u is at u), as :class:`onebox.geometry.Intrinsics` does.

:func:`read_captures` reads a folder; :func:`score` judges detections on one capture by the
folder's rule (the folder's README, "Scoring"):

- a detection's top middle is ``t = centre + H/2 z``, its z turned toward the camera;
- it is ON box k when ``t``, projected with K and rounded to a pixel, lies in box k's mask or,
  for a partial box, in its reference rectangle projected into the picture;
- it FINDS box k when ``|t - top_middle| <= max(15 mm, 1.5 % of the box's distance)``, its
  height above the support plane is within ``max(10 mm, 2 %)`` of the reference's and, for a
  box seen whole, its sorted length and width are each within ``max(15 mm, 2 %)``;
- matching is one to one, nearest top middle first; a box left unmatched is MISSED;
- a detection on no box is FALSE, or IGNORED when ``t`` lies in an ignore mask; a detection on
  a box that it does not match is OFF.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from PIL import Image
from scipy.spatial.transform import Rotation

from onebox.errors import OneboxError
from onebox.geometry import Intrinsics

__all__ = [
    "COMMITTED",
    "SHARED",
    "BoxLike",
    "Detection",
    "Match",
    "RealCapture",
    "RealDataError",
    "Score",
    "Support",
    "TopReference",
    "capture_names",
    "default_folder",
    "detections_json",
    "read_capture",
    "read_captures",
    "read_detections",
    "reference_detection",
    "score",
    "top_middle",
]

COMMITTED = Path(__file__).resolve().parent.parent.parent / "tests" / "data" / "realdata"
"""The captures in the repository (the OAK-D and PoseCNN ones, MIT)."""
SHARED = COMMITTED.parent.parent.parent.parent / "shared" / "realdata"
"""The full folder of real captures, kept beside the repository (some may not be committed)."""


def default_folder() -> Path:
    """The full folder of captures when it is beside the repository, else the committed ones."""
    return SHARED if SHARED.is_dir() else COMMITTED


Vec3 = npt.NDArray[np.float64]
Mask = npt.NDArray[np.bool_]

# The folder's tolerances (its README, "Scoring"): (floor in metres, share of the reference).
TOP_TOLERANCE = (0.015, 0.015)
"""Top middle: of the box's distance from the camera."""
HEIGHT_TOLERANCE = (0.010, 0.02)
"""Height of the top above the support: of the reference height."""
SIDE_TOLERANCE = (0.015, 0.02)
"""Length and width, boxes seen whole only: of the reference side."""


class RealDataError(OneboxError):
    """A capture folder, capture or detection that cannot be read; the message says which."""


@dataclass(frozen=True)
class Support:
    """The plane the boxes stand on: ``normal`` (unit, toward the camera) . X + ``offset_m`` is
    a point's height above it."""

    normal: Vec3
    offset_m: float

    def height_m(self, point: npt.ArrayLike) -> float:
        """How far ``point`` (optical frame, metres) lies above the plane."""
        return float(self.normal @ np.asarray(point, dtype=np.float64) + self.offset_m)


@dataclass(frozen=True)
class TopReference:
    """One box's top as measured from the capture's own depth (the folder's README, "What a
    reference is"); for a partial top, the sides and middle are those of the visible part."""

    mask: Mask
    """H x W, the top face's visible pixels."""
    top_middle_m: Vec3
    top_normal: Vec3
    """Unit, pointing up, away from the support."""
    long_axis: Vec3
    length_m: float
    width_m: float
    height_m: float
    """The top's height above the support plane (for a stacked box, above the table)."""
    partial: bool
    """Part of the top is hidden (by a nearer object, the picture's edge or missing depth)."""
    top_corners_m: npt.NDArray[np.float64]
    """4 x 3, the rectangle's corners in order."""
    label: str = ""
    partial_reason: str | None = None
    tilt_deg: float = 0.0


@dataclass(frozen=True)
class RealCapture:
    """One capture: its pictures, lens, support and references."""

    name: str
    source: str
    """The name's first part: ``oakd``, ``posecnn`` or ``mosd``."""
    depth_m: npt.NDArray[np.float32]
    """H x W z-depth, metres; NaN = no reading."""
    colour: npt.NDArray[np.uint8]
    """H x W x 3, RGB."""
    lens: Intrinsics
    support: Support
    boxes: list[TopReference]
    not_boxes: list[tuple[str, Mask]] = field(default_factory=list)
    """(kind, mask) of each object standing on the support that is not a box."""
    ignore: list[Mask] = field(default_factory=list)
    """Boxes with no measurable top: a detection there is neither false nor found."""
    notes: list[str] = field(default_factory=list)
    entry: Mapping[str, Any] = field(default_factory=dict)
    """The capture's line of captures.json, as read."""

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.depth_m.shape[1], self.depth_m.shape[0]


# ---------------------------------------------------------------------------------- reading
def _index(folder: Path) -> list[dict[str, Any]]:
    path = Path(folder) / "captures.json"
    if not path.is_file():
        raise RealDataError(
            f"no captures at {folder}: expected {path} (a folder of real captures such as "
            f"{COMMITTED})"
        )
    try:
        entries = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise RealDataError(f"cannot read {path}: {error}") from error
    if not isinstance(entries, list) or not all(
        isinstance(e, dict) and isinstance(e.get("name"), str) for e in entries
    ):
        raise RealDataError(f"{path}: expected a JSON list of captures, each with a name")
    return entries


def capture_names(folder: Path | str = COMMITTED, only: str = "") -> list[str]:
    """The names in ``folder``'s captures.json that contain ``only``, in its order."""
    return [e["name"] for e in _index(Path(folder)) if only in e["name"]]


def _read_png(path: Path, modes: tuple[str, ...], what: str) -> npt.NDArray[Any]:
    """The PNG's pixels, which must be in one of Pillow's ``modes``."""
    try:
        with Image.open(path) as picture:
            mode = picture.mode
            pixels = np.asarray(picture)
    except FileNotFoundError as error:
        raise RealDataError(f"{path} is missing") from error
    except OSError as error:
        raise RealDataError(f"cannot read {path} as a PNG: {error}") from error
    if mode not in modes:
        raise RealDataError(f"{path}: expected {what} (PNG mode {' or '.join(modes)}), got {mode}")
    return pixels


def _mask(folder: Path, name: str, shape: tuple[int, ...]) -> Mask:
    pixels = _read_png(folder / name, ("L", "1"), "an 8-bit mask")
    if pixels.shape != shape:
        raise RealDataError(f"{folder / name}: {pixels.shape} pixels, the depth has {shape}")
    return pixels > 0


def _vector(value: Any, where: str, shape: tuple[int, ...] = (3,)) -> Vec3:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise RealDataError(f"{where}: expected {shape} finite numbers, got {value!r}")
    return array


def read_capture(folder: Path | str, name: str) -> RealCapture:
    """The capture ``name`` of ``folder``; raises RealDataError naming the file or field."""
    folder = Path(folder)
    entries = [e for e in _index(folder) if e["name"] == name]
    if not entries:
        raise RealDataError(f"no capture {name!r} in {folder / 'captures.json'}")
    return _capture(folder, entries[0])


def read_captures(folder: Path | str = COMMITTED, only: str = "") -> list[RealCapture]:
    """Every capture of ``folder`` whose name contains ``only``, in captures.json's order."""
    folder = Path(folder)
    return [_capture(folder, e) for e in _index(folder) if only in e["name"]]


def _capture(folder: Path, entry: Mapping[str, Any]) -> RealCapture:
    name = entry["name"]
    try:
        depth_mm = _read_png(folder / entry["depth"], ("I;16", "I"), "16-bit depth in mm")
        colour = _read_png(folder / entry["colour"], ("RGB",), "8-bit RGB colour")
        shape = depth_mm.shape
        if colour.shape[:2] != shape:
            raise RealDataError(f"{name}: colour is {colour.shape[:2]}, depth {shape}")
        depth_m = depth_mm.astype(np.float32) / np.float32(1000.0)
        depth_m[depth_mm <= 0] = np.nan
        try:
            lens = Intrinsics.from_k(entry["K"])
        except (TypeError, ValueError) as error:
            raise RealDataError(f"{name}: K {entry['K']!r}: {error}") from error
        plane = entry["support_plane"]
        support = Support(_vector(plane["normal"], f"{name} support normal"), plane["offset_m"])
        boxes = [_reference(folder, name, b, shape) for b in entry["boxes"]]
        not_boxes = [(n["kind"], _mask(folder, n["mask"], shape)) for n in entry["not_boxes"]]
        ignore = [_mask(folder, g["mask"], shape) for g in entry.get("ignore", [])]
    except (KeyError, TypeError) as error:
        raise RealDataError(f"{name} in {folder / 'captures.json'}: bad or no {error}") from error
    return RealCapture(
        name=name,
        source=name.split("-", 1)[0],
        depth_m=depth_m,
        colour=np.ascontiguousarray(colour, dtype=np.uint8),
        lens=lens,
        support=support,
        boxes=boxes,
        not_boxes=not_boxes,
        ignore=ignore,
        notes=list(entry.get("notes", [])),
        entry=entry,
    )


def _reference(
    folder: Path, name: str, box: Mapping[str, Any], shape: tuple[int, ...]
) -> TopReference:
    where = f"{name} {box['mask']}"
    return TopReference(
        mask=_mask(folder, box["mask"], shape),
        top_middle_m=_vector(box["top_middle_m"], f"{where} top_middle_m"),
        top_normal=_vector(box["top_normal"], f"{where} top_normal"),
        long_axis=_vector(box["long_axis"], f"{where} long_axis"),
        length_m=box["length_mm"] / 1000.0,
        width_m=box["width_mm"] / 1000.0,
        height_m=box["height_mm"] / 1000.0,
        partial=bool(box["partial"]),
        top_corners_m=_vector(box["top_corners_m"], f"{where} top_corners_m", (4, 3)),
        label=box.get("label", ""),
        partial_reason=box.get("partial_reason"),
        tilt_deg=float(box.get("top_tilt_deg", 0.0)),
    )


# ------------------------------------------------------------------------------- detections
class BoxLike(Protocol):
    """What a detection needs: :class:`onebox.perception.boxes.Box` is one."""

    @property
    def centre(self) -> Sequence[float]: ...
    @property
    def quaternion_xyzw(self) -> Sequence[float]: ...
    @property
    def size(self) -> Sequence[float]: ...


@dataclass(frozen=True)
class Detection:
    """A box as the scorer reads it: camera frame, metres, the quaternion's z the box's up."""

    centre: tuple[float, float, float]
    quaternion_xyzw: tuple[float, float, float, float]
    size: tuple[float, float, float]
    """Length, width, height."""

    @classmethod
    def checked(
        cls,
        centre: Iterable[float],
        quaternion_xyzw: Iterable[float],
        size: Iterable[float],
    ) -> Detection:
        """Three numbers, four and three, finite, the quaternion not of length zero."""
        c, q, s = (tuple(float(v) for v in x) for x in (centre, quaternion_xyzw, size))
        if (len(c), len(q), len(s)) != (3, 4, 3) or not all(math.isfinite(v) for v in c + q + s):
            raise RealDataError(
                f"a detection needs centre [x,y,z], quaternion [x,y,z,w] and size [L,W,H], "
                f"finite, in metres; got {c}, {q}, {s}"
            )
        if math.hypot(*q) < 1e-9:
            raise RealDataError(f"a detection's quaternion {q} has length zero")
        return cls((c[0], c[1], c[2]), (q[0], q[1], q[2], q[3]), (s[0], s[1], s[2]))

    @classmethod
    def of(cls, box: BoxLike) -> Detection:
        """Any box with ``centre``, ``quaternion_xyzw`` and ``size``, checked."""
        return cls.checked(box.centre, box.quaternion_xyzw, box.size)

    def to_json(self) -> dict[str, list[float]]:
        """The folder's detection format: ``{"centre", "quaternion", "size"}``."""
        return {
            "centre": list(self.centre),
            "quaternion": list(self.quaternion_xyzw),
            "size": list(self.size),
        }


def detections_json(
    detections: Mapping[str, Iterable[BoxLike]],
) -> dict[str, list[dict[str, list[float]]]]:
    """``{capture name: [detection, ...]}`` in the folder's format (``json.dump`` it)."""
    return {name: [Detection.of(b).to_json() for b in boxes] for name, boxes in detections.items()}


def read_detections(path: Path | str) -> dict[str, list[Detection]]:
    """A detections file: ``{name: [{centre, quaternion, size}]}`` or ``[{name, boxes}]``."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text())
        if isinstance(raw, list):
            raw = {entry["name"]: entry.get("boxes", []) for entry in raw}
        return {
            name: [Detection.checked(d["centre"], d["quaternion"], d["size"]) for d in boxes]
            for name, boxes in raw.items()
        }
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise RealDataError(f"cannot read detections {path}: {error}") from error
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise RealDataError(
            f"{path}: expected {{capture name: [{{centre, quaternion, size}}]}} or "
            f"[{{name, boxes}}]: {error!r}"
        ) from error


def reference_detection(reference: TopReference) -> Detection:
    """The detection a perfect finder would report for ``reference``: its top's middle, sides
    and height, up along the top's normal."""
    up = reference.top_normal
    along = reference.long_axis - (reference.long_axis @ up) * up
    along /= np.linalg.norm(along)
    turn = np.stack([along, np.cross(up, along), up], axis=1)
    centre = reference.top_middle_m - reference.height_m / 2 * up
    q = Rotation.from_matrix(turn).as_quat()
    return Detection(
        (float(centre[0]), float(centre[1]), float(centre[2])),
        (float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        (reference.length_m, reference.width_m, reference.height_m),
    )


# ---------------------------------------------------------------------------------- scoring
@dataclass(frozen=True)
class Match:
    """A box found: which detection found which box, and its errors (detected - reference)."""

    detection: int
    box: int
    top_m: float
    """How far the detection's top middle lies from the reference's."""
    height_m: float
    """The detection's top's height above the support less the reference's."""
    length_m: float | None
    """Sorted length and width less the reference's; None for a partial box (its reference
    describes the visible part only)."""
    width_m: float | None


@dataclass(frozen=True)
class Score:
    """One capture's score; the lists hold indices into the boxes and the detections."""

    name: str
    boxes: int
    found: list[Match]
    missed: list[int]
    """Reference boxes no detection found."""
    false: list[int]
    """Detections on no box (and in no ignore mask)."""
    off: list[int]
    """Detections on a box that they do not match (out of tolerance, or a second one)."""
    ignored: list[int]
    """Detections in an ignore mask."""
    notes: list[str]
    """Why each box was missed and each detection was off or false."""

    def counts(self) -> dict[str, int]:
        """boxes, found, missed, false, off, ignored: the folder's score.py's counts."""
        return {
            "boxes": self.boxes,
            "found": len(self.found),
            "missed": len(self.missed),
            "false": len(self.false),
            "off": len(self.off),
            "ignored": len(self.ignored),
        }


def top_middle(detection: BoxLike) -> Vec3:
    """``centre + H/2 z`` with the box's z turned toward the camera (at the origin)."""
    d = Detection.of(detection)
    centre = np.asarray(d.centre, dtype=np.float64)
    up: Vec3 = Rotation.from_quat(d.quaternion_xyzw).as_matrix()[:, 2]
    if up @ centre > 0:  # z points away from the camera: the top is the other end
        up = -up
    top: Vec3 = centre + d.size[2] / 2 * up
    return top


def _pixel(point: Vec3, lens: Intrinsics) -> tuple[int, int] | None:
    if point[2] <= 0:
        return None
    # Python's round, half to even, as the folder's scorer rounds.
    return (
        round(lens.fx * point[0] / point[2] + lens.cx),
        round(lens.fy * point[1] / point[2] + lens.cy),
    )


def _inside(mask: Mask, pixel: tuple[int, int] | None) -> bool:
    if pixel is None:
        return False
    u, v = pixel
    return 0 <= v < mask.shape[0] and 0 <= u < mask.shape[1] and bool(mask[v, u])


def _in_rectangle(reference: TopReference, lens: Intrinsics, pixel: tuple[int, int] | None) -> bool:
    """Whether the pixel's middle lies in the reference rectangle seen in the picture (even-odd
    rule against its projected corners)."""
    corners = reference.top_corners_m
    if pixel is None or (corners[:, 2] <= 0).any():
        return False
    xs = lens.fx * corners[:, 0] / corners[:, 2] + lens.cx
    ys = lens.fy * corners[:, 1] / corners[:, 2] + lens.cy
    u, v = pixel
    hit = False
    for i in range(len(xs)):
        x1, y1, x2, y2 = xs[i], ys[i], xs[(i + 1) % len(xs)], ys[(i + 1) % len(xs)]
        if (y1 > v) != (y2 > v) and u < x1 + (v - y1) * (x2 - x1) / (y2 - y1):
            hit = not hit
    return hit


def _tolerance(limits: tuple[float, float], reference: float) -> float:
    return max(limits[0], limits[1] * reference)


def _judge(
    reference: TopReference, detection: Detection, top: Vec3, support: Support
) -> tuple[Match, list[str]]:
    """The detection's errors against the box (as a Match of detection -1 and box -1), and why
    it does not match the box (empty when it does)."""
    why = []
    off = float(np.linalg.norm(top - reference.top_middle_m))
    tol = _tolerance(TOP_TOLERANCE, float(np.linalg.norm(reference.top_middle_m)))
    if off > tol:
        why.append(f"top middle {off * 1000:.0f} mm off (> {tol * 1000:.0f})")
    height = support.height_m(top)
    tol = _tolerance(HEIGHT_TOLERANCE, reference.height_m)
    if abs(height - reference.height_m) > tol:
        why.append(
            f"height {height * 1000:.0f} mm vs {reference.height_m * 1000:.0f} "
            f"(> +-{tol * 1000:.0f})"
        )
    sides: list[float | None] = [None, None]
    if not reference.partial:
        got = sorted(detection.size[:2], reverse=True)
        for i, (side, value, ref) in enumerate(
            (("L", got[0], reference.length_m), ("W", got[1], reference.width_m))
        ):
            sides[i] = value - ref
            tol = _tolerance(SIDE_TOLERANCE, ref)
            if abs(value - ref) > tol:
                why.append(
                    f"{side} {value * 1000:.0f} mm vs {ref * 1000:.0f} (> +-{tol * 1000:.0f})"
                )
    return Match(-1, -1, off, height - reference.height_m, sides[0], sides[1]), why


def score(capture: RealCapture, detections: Sequence[BoxLike]) -> Score:
    """Judge ``detections`` (camera frame) against ``capture``'s references (see the module
    docstring for the rule)."""
    dets = [Detection.of(d) for d in detections]
    tops = [top_middle(d) for d in dets]
    pixels = [_pixel(t, capture.lens) for t in tops]
    candidates: list[tuple[float, int, int, Match]] = []
    notes: list[str] = []
    on_box = [False] * len(dets)
    for j, (det, top, pixel) in enumerate(zip(dets, tops, pixels, strict=True)):
        for k, ref in enumerate(capture.boxes):
            if not (
                _inside(ref.mask, pixel)
                or (ref.partial and _in_rectangle(ref, capture.lens, pixel))
            ):
                continue
            on_box[j] = True
            match, why = _judge(ref, det, top, capture.support)
            if why:
                notes.append(f"det{j} on box{k}: " + "; ".join(why))
            else:
                candidates.append((match.top_m, j, k, match))
    found: list[Match] = []
    used_det: set[int] = set()
    used_box: set[int] = set()
    for _, j, k, match in sorted(candidates, key=lambda c: c[:3]):
        if j not in used_det and k not in used_box:
            used_det.add(j)
            used_box.add(k)
            found.append(replace(match, detection=j, box=k))
    false = [
        j
        for j in range(len(dets))
        if not on_box[j] and not any(_inside(m, pixels[j]) for m in capture.ignore)
    ]
    ignored = [j for j in range(len(dets)) if not on_box[j] and j not in false]
    off = [j for j in range(len(dets)) if on_box[j] and j not in used_det]
    notes += [f"det{j} false: top middle at pixel {pixels[j]} is on no box" for j in false]
    missed = [k for k in range(len(capture.boxes)) if k not in used_box]
    notes += [f"box{k} missed" + (" (partial)" if capture.boxes[k].partial else "") for k in missed]
    return Score(
        name=capture.name,
        boxes=len(capture.boxes),
        found=sorted(found, key=lambda m: m.box),
        missed=missed,
        false=false,
        off=off,
        ignored=ignored,
        notes=notes,
    )
