"""Draw the boxes the finder finds in a real capture over its colour picture.

    python docs/draw_found.py [--capture posecnn-000005] [--out docs/real_capture.png]
        [--data tests/data/realdata]

Runs :func:`onebox.perception.boxes.find_boxes` on one of the committed real captures (no pose:
everything in the camera's optical frame) and draws each box's edges (green), its top's
middle and its size in millimetres; the reference tops' outlines are drawn thin in white.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox.perception.boxes import Box, find_boxes
from onebox.testing import realdata

HERE = Path(__file__).resolve().parent


def corners(box: Box) -> np.ndarray:
    """The box's eight corners, optical frame."""
    x, y, z, w = box.quaternion_xyzw
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    half = np.asarray(box.size) / 2
    signs = np.array([[sx, sy, sz] for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)])
    return np.asarray(box.centre) + (signs * half) @ rotation.T


def draw(capture: realdata.RealCapture, scale: int = 2) -> np.ndarray:
    """The colour picture, ``scale`` times larger, with the boxes found drawn on it."""
    found = find_boxes(capture.depth_m, capture.lens, None, capture.colour)
    lens = capture.lens
    picture = cv2.resize(
        cv2.cvtColor(capture.colour, cv2.COLOR_RGB2BGR),
        None,
        fx=scale,
        fy=scale,
        interpolation=cv2.INTER_NEAREST,
    )
    picture = (0.75 * picture).astype(np.uint8)
    for reference in capture.boxes:
        outline, _ = cv2.findContours(
            cv2.resize(reference.mask.astype(np.uint8), None, fx=scale, fy=scale),
            cv2.RETR_EXTERNAL,
            cv2.CHAIN_APPROX_SIMPLE,
        )
        cv2.drawContours(picture, outline, -1, (255, 255, 255), 1, cv2.LINE_AA)

    def pixel(p: np.ndarray) -> tuple[int, int]:
        return (
            round(scale * (lens.fx * p[0] / p[2] + lens.cx)),
            round(scale * (lens.fy * p[1] / p[2] + lens.cy)),
        )

    edges = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7)]
    edges += [(0, 4), (1, 5), (2, 6), (3, 7)]
    for box in found.boxes:
        points = [pixel(p) for p in corners(box)]
        for a, b in edges:
            cv2.line(picture, points[a], points[b], (60, 230, 60), 2, cv2.LINE_AA)
        top = pixel(np.asarray(box.top_middle))
        cv2.circle(picture, top, 4, (60, 230, 60), -1, cv2.LINE_AA)
        label = " x ".join(f"{1000 * s:.0f}" for s in box.size) + " mm"
        for ink, thickness in (((0, 0, 0), 4), ((255, 255, 255), 2)):  # outlined text
            position = (top[0] + 8, top[1] - 8)
            font = cv2.FONT_HERSHEY_SIMPLEX
            cv2.putText(picture, label, position, font, 0.7, ink, thickness, cv2.LINE_AA)
    return picture


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False)
    parser.add_argument("--capture", default="posecnn-000005", help="the capture's name")
    parser.add_argument("--data", type=Path, default=realdata.COMMITTED, help="captures folder")
    parser.add_argument("--out", type=Path, default=HERE / "real_capture.png", help="PNG out")
    args = parser.parse_args()
    try:
        capture = realdata.read_capture(args.data, args.capture)
    except realdata.RealDataError as e:
        print(f"draw_found: {e}", file=sys.stderr)
        return 2
    cv2.imwrite(str(args.out), draw(capture))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
