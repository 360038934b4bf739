"""A catalogue of the box sizes a site handles, the way palletising cells are set up.

Contract: :func:`read_catalogue` reads a TOML file of entries,

    [[box]]
    name = "A4 carton"
    length = 0.31   # metres, the top's longer side
    width = 0.22
    height = 0.25

and :func:`match` finds the entry a measured top fits: its length and width each within
``max(SIZE_TOLERANCE_M, SIZE_SHARE * size)`` of the entry's (a side hidden by something nearer
may be shorter than the entry's, never longer), the height nearest the measured one breaking a
tie. A box that matches takes the entry's height and name: a carton in a full layer shows no
side and no floor round it, so the catalogue is what knows its height.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from onebox.errors import SettingError

SIZE_TOLERANCE_M = 0.012
"""A top's side matches an entry's within this (the noise at a few metres, a smeared edge)..."""
SIZE_SHARE = 0.03
"""...or within this share of it, whichever is more."""


@dataclass(frozen=True)
class Entry:
    """One kind of box: its top's sides (length >= width) and its height, metres."""

    name: str
    length_m: float
    width_m: float
    height_m: float


def read_catalogue(path: Path) -> tuple[Entry, ...]:
    """The entries of a catalogue file; SettingError naming the file and entry when wrong."""
    try:
        data = tomllib.loads(path.read_text())
    except OSError as e:
        raise SettingError(f"cannot read the catalogue {path}: {e.strerror}") from e
    except tomllib.TOMLDecodeError as e:
        raise SettingError(f"the catalogue {path} is not TOML: {e}") from e
    boxes = data.get("box")
    if not isinstance(boxes, list) or not boxes:
        raise SettingError(
            f"the catalogue {path} lists no boxes: write one [[box]] table a size, with name, "
            "length, width and height in metres"
        )
    entries = []
    for i, box in enumerate(boxes):
        try:
            name = str(box["name"])
            sides = sorted((float(box["length"]), float(box["width"])), reverse=True)
            height = float(box["height"])
        except (KeyError, TypeError, ValueError) as e:
            raise SettingError(
                f"the catalogue {path}, box {i + 1}: needs name and numbers length, width and "
                f"height (metres): {e}"
            ) from e
        if min(*sides, height) <= 0.0 or max(*sides, height) > 10.0:
            raise SettingError(
                f"the catalogue {path}, box {i + 1} ({name}): sizes are metres, each over 0 "
                f"and at most 10; got {sides[0]} x {sides[1]} x {height}"
            )
        entries.append(Entry(name, sides[0], sides[1], height))
    return tuple(entries)


def _fits(seen: float, entry: float, hidden: bool) -> bool:
    tolerance = max(SIZE_TOLERANCE_M, SIZE_SHARE * entry)
    if hidden:
        return seen <= entry + tolerance
    return abs(seen - entry) <= tolerance


def match(
    length_m: float,
    width_m: float,
    height_m: float,
    entries: tuple[Entry, ...],
    hidden_length: bool = False,
    hidden_width: bool = False,
) -> Entry | None:
    """The entry the top fits (see the module docstring), or None."""
    fitting = [
        e
        for e in entries
        if _fits(length_m, e.length_m, hidden_length) and _fits(width_m, e.width_m, hidden_width)
    ]
    if not fitting:
        return None
    return min(
        fitting,
        key=lambda e: (
            abs(length_m - e.length_m) + abs(width_m - e.width_m) + abs(height_m - e.height_m)
        ),
    )
