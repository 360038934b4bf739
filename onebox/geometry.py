"""Geometry: the lens, shifts and turns as 4 x 4 matrices, and the frame tree.

The frame tree is the part of tf2 the locator needs: fill it with the TransformStamped messages
of ``tf_static`` (each says where a child frame sits in its parent) and ask
:meth:`FrameTree.lookup` for ``parent <- child`` between any two connected frames.

Pixels follow real cameras' CameraInfo (OpenCV, depth_image_proc): the middle of pixel ``u``
is at ``u``, so a centred 320-wide lens has cx = 159.5. The seed wrote the same lens the other
way (the middle of pixel ``u`` at ``u + 0.5``, cx = 160); :meth:`Intrinsics.seed_cx` converts.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from onebox.errors import OneboxError
from schemas import TransformStamped

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Intrinsics:
    """The four lens numbers, in pixels: K = [fx 0 cx; 0 fy cy; 0 0 1], middle of pixel u at u."""

    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_k(cls, k: Sequence[float]) -> Intrinsics:
        """Read a row-major 3 x 3 K; raises ValueError when it cannot be a pinhole lens."""
        if len(k) != 9:
            raise ValueError(f"K has {len(k)} numbers, expected 9 (3 x 3, row-major)")
        fx, fy, cx, cy = float(k[0]), float(k[4]), float(k[2]), float(k[5])
        if not all(np.isfinite([fx, fy, cx, cy])) or fx <= 0.0 or fy <= 0.0:
            raise ValueError(f"K has fx={fx}, fy={fy}, cx={cx}, cy={cy}; fx and fy must be > 0")
        return cls(fx, fy, cx, cy)

    def rays(self, width: int, height: int) -> tuple[Float64Array, Float64Array]:
        """Each column's (u - cx) / fx and each row's (v - cy) / fy (cached per size and lens).

        A pixel (v, u) with depth d is the optical-frame point (across[u] d, down[v] d, d).
        """
        return _rays(width, height, self)


@functools.lru_cache(maxsize=16)
def _rays(width: int, height: int, lens: Intrinsics) -> tuple[Float64Array, Float64Array]:
    across: Float64Array = (np.arange(width, dtype=np.float64) - lens.cx) / lens.fx
    down: Float64Array = (np.arange(height, dtype=np.float64) - lens.cy) / lens.fy
    across.flags.writeable = False
    down.flags.writeable = False
    return across, down


def transform_matrix(
    translation: Sequence[float], quaternion_xyzw: Sequence[float]
) -> Float64Array:
    """A shift and a turn as a 4 x 4 matrix moving a child frame's points into its parent.

    Raises ValueError for a quaternion of length zero or any number that is not finite.
    """
    numbers = [*translation, *quaternion_xyzw]
    if len(numbers) != 7 or not np.all(np.isfinite(numbers)):
        raise ValueError(f"a transform needs 3 finite numbers and 4 finite numbers, got {numbers}")
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(quaternion_xyzw).as_matrix()
    matrix[:3, 3] = translation
    return matrix


def to_world(points: npt.NDArray[np.floating], matrix: Float64Array) -> Float64Array:
    """Move (N, 3) points with a 4 x 4 matrix: start at its position, walk its three columns."""
    result: Float64Array = points @ matrix[:3, :3].T + matrix[:3, 3]
    return result


# --- the frame tree ----------------------------------------------------------------------------


class FrameError(OneboxError):
    """No chain of transforms joins two frames, or a transform cannot be used."""


def matrix_of(transform: TransformStamped) -> Float64Array:
    """The 4 x 4 matrix moving points of ``child_frame_id`` into ``header.frame_id``."""
    t, q = transform.transform.translation, transform.transform.rotation
    try:
        return transform_matrix((t.x, t.y, t.z), (q.x, q.y, q.z, q.w))
    except ValueError as e:
        raise FrameError(
            f"transform {transform.header.frame_id} -> {transform.child_frame_id} is not "
            f"usable: {e}"
        ) from e


MAX_FRAMES = 65_536
"""The most frames a tree holds: a stranger naming new frames forever cannot grow it further."""


class FrameTree:
    """Frames joined by transforms; each frame has at most one parent, as in tf2's tf_static.

    A newer transform for a child frame replaces the older one. A message (a list of
    transforms, as one ``tf_static`` sample carries) is checked whole before any of it is used
    and then applied at once: if one transform in it is unusable, would close a loop, or would
    give a ``root`` frame (the world) a parent, the whole message is refused and the tree is
    left as it was.
    """

    def __init__(
        self, transforms: Iterable[TransformStamped] = (), *, roots: Iterable[str] = ()
    ) -> None:
        self._parent: dict[str, tuple[str, Float64Array]] = {}
        self.roots = frozenset(roots)
        """Frames that stay roots: a transform that gives one a parent is refused."""
        self.version = 0
        """Counts changes, so a caller can cache a lookup until the tree changes."""
        self.add_all(transforms)

    def add(self, transform: TransformStamped) -> None:
        """Put ``child`` under ``parent`` (replacing where it was). Raises FrameError."""
        self.add_all([transform])

    def add_all(self, transforms: Iterable[TransformStamped]) -> list[str]:
        """Apply one message's transforms, all or none; returns the child frames it set.

        Raises FrameError (and changes nothing) when any transform cannot be used.
        """
        changes: dict[str, tuple[str, Float64Array]] = {}
        for transform in transforms:
            parent, child = transform.header.frame_id, transform.child_frame_id
            if not parent or not child or parent == child:
                raise FrameError(
                    f"a transform needs two different frame names, got parent {parent!r} and "
                    f"child {child!r}"
                )
            if child in self.roots:
                raise FrameError(
                    f"{parent} -> {child} would give {child} a parent, but {child} is the "
                    "root of the tree"
                )
            changes[child] = (parent, matrix_of(transform))
        if not changes:
            return []
        merged = {**self._parent, **changes}
        if len(merged) > MAX_FRAMES:
            raise FrameError(
                f"the message would make the tree {len(merged):,} frames, more than {MAX_FRAMES:,}"
            )
        _refuse_loops(merged, changes)
        self._parent = merged
        self.version += 1
        return list(changes)

    @property
    def frames(self) -> set[str]:
        """Every frame named so far by a transform."""
        return set(self._parent) | {parent for parent, _ in self._parent.values()}

    def _to_root(self, frame: str) -> tuple[str, Float64Array]:
        """The root of ``frame``'s tree and the matrix ``root <- frame``."""
        matrix = np.eye(4)
        while frame in self._parent:
            frame, parent_from_frame = self._parent[frame]
            matrix = parent_from_frame @ matrix
        return frame, matrix

    def lookup(self, parent: str, child: str) -> Float64Array:
        """The 4 x 4 matrix moving points of ``child`` into ``parent``. Raises FrameError."""
        if parent == child:
            return np.eye(4)
        known = self.frames | self.roots
        for name in (parent, child):
            if name not in known:
                listed = ", ".join(sorted(known)) or "none yet"
                raise FrameError(
                    f"no frame {name!r} in the frame tree (known: {listed}); is tf_static "
                    "being published, and does it name that frame?"
                )
        parent_root, root_from_parent = self._to_root(parent)
        child_root, root_from_child = self._to_root(child)
        if parent_root != child_root:
            raise FrameError(
                f"no chain of transforms joins {parent!r} and {child!r}: they are in separate "
                f"trees, rooted at {parent_root!r} and {child_root!r}"
            )
        # Up from the child to the root, then down to the parent.
        result: Float64Array = np.linalg.inv(root_from_parent) @ root_from_child
        return result


def _refuse_loops(parents: dict[str, tuple[str, Float64Array]], changed: Iterable[str]) -> None:
    """Raise FrameError if walking up from any changed frame comes back to a frame on its way.

    Each frame is walked at most once, so a chain of N frames costs N steps, not N squared.
    """
    settled: set[str] = set()
    for start in changed:
        path: list[str] = []
        on_path: set[str] = set()
        frame: str | None = start
        while frame is not None and frame not in settled:
            if frame in on_path:
                loop = path[path.index(frame) :]
                shown = " -> ".join(reversed([*loop, frame][-12:]))
                raise FrameError(f"the transforms would make {frame} its own ancestor ({shown})")
            path.append(frame)
            on_path.add(frame)
            frame = parents[frame][0] if frame in parents else None
        settled.update(path)
