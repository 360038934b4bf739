"""A small frame tree, the part of tf2 the locator needs: where one frame sits in another.

Fill it with the TransformStamped messages of ``tf_static`` (each says where a child frame sits
in its parent, as a shift and a turn) and ask :meth:`FrameTree.lookup` for ``parent <- child``
between any two connected frames: up from the child to the root of the tree, composing 4 x 4
matrices, and back down to the parent by the inverse. A frame that is not connected raises
:class:`FrameError` naming the frames that are known.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from schemas import TransformStamped
from services.errors import OneboxError
from services.measure import Float64Array, transform_matrix


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


class FrameTree:
    """Frames joined by transforms; each frame has at most one parent, as in tf2."""

    def __init__(self, transforms: Iterable[TransformStamped] = ()) -> None:
        self._parent: dict[str, tuple[str, Float64Array]] = {}
        self.version = 0
        """Counts changes, so a caller can cache a lookup until the tree changes."""
        self.add_all(transforms)

    def add(self, transform: TransformStamped) -> None:
        """Put ``child`` under ``parent`` (replacing where it was). Raises FrameError."""
        parent, child = transform.header.frame_id, transform.child_frame_id
        if not parent or not child or parent == child:
            raise FrameError(
                f"a transform needs two different frame names, got parent {parent!r} and "
                f"child {child!r}"
            )
        matrix = matrix_of(transform)
        # A transform that closes a loop would make the tree a graph with two answers.
        ancestor: str | None = parent
        while ancestor is not None:
            if ancestor == child:
                raise FrameError(f"{parent} -> {child} would make {child} its own ancestor")
            ancestor = self._parent[ancestor][0] if ancestor in self._parent else None
        self._parent[child] = (parent, matrix)
        self.version += 1

    def add_all(self, transforms: Iterable[TransformStamped]) -> None:
        """Add each transform; raises FrameError at the first that cannot be used."""
        for transform in transforms:
            self.add(transform)

    @property
    def frames(self) -> set[str]:
        """Every frame named so far."""
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
        known = self.frames
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
