"""How the box finder does on real cameras: real RGB-D captures scored against reference tops.

    python benchmarks/bench_real.py [--data PATH] [--only SUBSTRING] [--repeats N]
        [--no-colour] [--json DETECTIONS.json] [-v]

Reads a folder of real captures (:mod:`onebox.testing.realdata`: depth, colour, K and the
reference tops; by default ``../shared/realdata`` beside the repository if it is there, else
the committed ``tests/data/realdata``) and runs the box finder on each picture fresh, with no
camera pose (everything in the camera's optical frame) and with the colour picture unless
``--no-colour``: ``onebox.perception.boxes.find_boxes(depth_m, lens, None, colour=colour)``.

The very first call is timed apart (warm-up: compiling, caches) and left out; then each
picture's time is the median of ``--repeats`` runs, and the boxes of its first run are scored
by the folder's rule (:func:`onebox.testing.realdata.score`): found / missed / false / off /
ignored. For each box found, its errors, detected less reference, in mm: ``top`` is how far the
top's middle lies from the reference's (the reference measures a top; the box's centre is that
less half the height, its error the top's and half the height's), ``L`` and ``W`` the sorted
sides (not for partly hidden tops, whose reference is the visible part only), ``h`` the top's
height above the support plane.

Prints a line per capture (with ``-v`` why each box was missed and each detection was off or
false), then per source (oakd, posecnn, mosd) and overall: the counts, the median and p90 of each
|error| with the median signed error (bias), and the median ms a picture by picture size.
``--json`` writes the detections in the folder's format, for its ``score.py``. Ctrl-C stops
and prints the totals of the captures measured so far.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox import memory
from onebox.perception.boxes import Box, find_boxes
from onebox.testing.realdata import (
    COMMITTED,
    SHARED,
    RealCapture,
    RealDataError,
    Score,
    capture_names,
    default_folder,
    detections_json,
    read_capture,
    score,
)

SOURCES = ("oakd", "posecnn", "mosd")


@dataclass
class Tally:
    """Counts, errors (metres, signed) and times of a group of captures."""

    counts: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    errors: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    ms_by_size: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    captures: int = 0
    failed: int = 0

    def add(self, capture: RealCapture, result: Score, ms: float | None) -> None:
        self.captures += 1
        for key, value in result.counts().items():
            self.counts[key] += value
        for m in result.found:
            self.errors["top"].append(m.top_m)
            self.errors["h"].append(m.height_m)
            if m.length_m is not None and m.width_m is not None:
                self.errors["L"].append(m.length_m)
                self.errors["W"].append(m.width_m)
        if ms is not None:
            width, height = capture.size
            self.ms_by_size[f"{width}x{height}"].append(ms)


def run(capture: RealCapture, repeats: int, colour: bool) -> tuple[list[Box], float]:
    """The finder's boxes on its first run, and the median ms of ``repeats`` runs."""
    boxes: list[Box] | None = None
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        found = find_boxes(
            capture.depth_m, capture.lens, None, colour=capture.colour if colour else None
        )
        times.append((time.perf_counter() - start) * 1000.0)
        if boxes is None:
            boxes = list(found.boxes)
    assert boxes is not None
    return boxes, float(np.median(times))


def describe_found(capture: RealCapture, result: Score) -> list[str]:
    lines = []
    for m in result.found:
        sides = (
            f"L {m.length_m * 1000:+5.0f}  W {m.width_m * 1000:+5.0f}"
            if m.length_m is not None and m.width_m is not None
            else "L     -  W     - (partial)"
        )
        lines.append(
            f"    box{m.box} found by det{m.detection}: top {m.top_m * 1000:4.0f}  {sides}  "
            f"h {m.height_m * 1000:+5.0f} mm"
        )
    return lines


def print_tally(label: str, tally: Tally) -> None:
    c = tally.counts
    print(
        f"{label:<10} {tally.captures:3d} captures  {c['boxes']:3d} boxes: found {c['found']:3d}"
        f"  missed {c['missed']:3d}  false {c['false']:3d}  off {c['off']:3d}"
        f"  ign {c['ignored']:2d}" + (f"  ({tally.failed} failed)" if tally.failed else "")
    )
    for name in ("top", "L", "W", "h"):
        values = np.asarray(tally.errors.get(name, []), dtype=np.float64) * 1000.0
        if values.size:
            print(
                f"    {name:<4} |err| median {np.median(np.abs(values)):5.1f}  "
                f"p90 {np.percentile(np.abs(values), 90):5.1f} mm   "
                f"bias {np.median(values):+5.1f} mm   (n={values.size})"
            )
    for size, ms in sorted(tally.ms_by_size.items()):
        print(f"    {size}: {np.median(ms):7.1f} ms a picture (median of {len(ms)})")


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--data",
        type=Path,
        default=default_folder(),
        help=f"a folder of real captures (default: {SHARED} if there, else {COMMITTED})",
    )
    parser.add_argument("--only", default="", help="only captures whose name contains this")
    parser.add_argument("--repeats", type=int, default=3, help="runs a picture (default 3)")
    parser.add_argument("--no-colour", action="store_true", help="depth only: no colour picture")
    parser.add_argument("--json", type=Path, help="write the detections here (score.py's format)")
    parser.add_argument("-v", "--verbose", action="store_true", help="say why, box by box")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be 1 or more")

    try:
        names = capture_names(args.data, args.only)
    except RealDataError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if not names:
        print(f"error: no capture in {args.data} has {args.only!r} in its name", file=sys.stderr)
        return 2
    colour = not args.no_colour
    print(
        f"{len(names)} captures from {args.data}, {'depth + colour' if colour else 'depth only'}, "
        f"median of {args.repeats} run(s) a picture"
    )

    totals: dict[str, Tally] = defaultdict(Tally)
    overall = Tally()
    detections: dict[str, list[Box]] = {}
    failures: list[str] = []
    skipped: list[str] = []
    progress = sys.stderr.isatty()
    interrupted = False
    try:
        memory.bound_heap()  # as the locator does when it starts
        first = read_capture(args.data, names[0])
        start = time.perf_counter()
        find_boxes(first.depth_m, first.lens, None, colour=first.colour if colour else None)
        print(
            f"warm-up: {(time.perf_counter() - start) * 1000:.0f} ms "
            f"(first call, {first.name}; left out of the times)"
        )
        print(
            f"{'capture':<26} {'size':>7} {'ms':>7} {'boxes':>5} {'found':>5} {'missed':>6} "
            f"{'false':>5} {'off':>4} {'ign':>4}"
        )
        for i, name in enumerate(names):
            if progress:
                print(f"\r[{i + 1}/{len(names)}] {name} ...", end="", file=sys.stderr, flush=True)
            try:
                capture = read_capture(args.data, name)
            except RealDataError as error:  # e.g. files kept out of a copy of the folder
                skipped.append(name)
                print(f"{name:<26} skipped: {error}")
                continue
            tally = totals[capture.source]
            ms: float | None
            try:
                boxes, ms = run(capture, args.repeats, colour)
            except Exception as error:  # report it and go on: one capture must not end the run
                failures.append(f"{name}: {type(error).__name__}: {error}")
                tally.failed += 1
                overall.failed += 1
                if progress:
                    print("\r\033[K", end="", file=sys.stderr)
                print(f"{name:<26} FAILED: {type(error).__name__}: {error}")
                if args.verbose:
                    traceback.print_exc()
                boxes, ms = [], None
            detections[name] = boxes
            result = score(capture, boxes)
            if progress:
                print("\r\033[K", end="", file=sys.stderr)
            c = result.counts()
            width, height = capture.size
            took = f"{ms:7.1f}" if ms is not None else "      -"
            print(
                f"{name:<26} {f'{width}x{height}':>7} {took} {c['boxes']:5d} {c['found']:5d} "
                f"{c['missed']:6d} {c['false']:5d} {c['off']:4d} {c['ignored']:4d}"
            )
            for line in describe_found(capture, result):
                print(line)
            if args.verbose:
                for note in result.notes:
                    print(f"    {note}")
            tally.add(capture, result, ms)
            overall.add(capture, result, ms)
    except KeyboardInterrupt:
        interrupted = True
        if progress:
            print("\r\033[K", end="", file=sys.stderr)
        print(f"\ninterrupted: totals of the {overall.captures} of {len(names)} captures measured")

    print()
    for source in [*SOURCES, *sorted(set(totals) - set(SOURCES))]:
        if source in totals:
            print_tally(source, totals[source])
    print_tally("overall", overall)
    if skipped:
        print(f"skipped {len(skipped)} captures whose files could not be read")
    for failure in failures:
        print(f"failed: {failure}")
    if args.json:
        args.json.write_text(json.dumps(detections_json(detections), indent=1) + "\n")
        print(f"detections written to {args.json}")
    return 130 if interrupted else 0


if __name__ == "__main__":
    sys.exit(main())
