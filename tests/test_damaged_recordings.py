"""Damaged copies of the committed capture: info, replay and view refuse them with one line
(exit 2) or read what is intact (exit 0), never a traceback; checksums are checked by default."""

from __future__ import annotations

import io
import random
from dataclasses import dataclass
from pathlib import Path

import pytest
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from onebox.recording import RecordingWriter, iter_messages
from onebox.testing.capture import CAPTURE
from services import cli

SEED = 12


@dataclass(frozen=True)
class Variant:
    name: str
    data: bytes
    in_chunk_data: bool
    """The damage lies wholly inside a chunk's (compressed) messages: a checksum must catch it."""


def chunk_data_ranges(data: bytes) -> list[tuple[int, int]]:
    """Where each chunk's message bytes lie in the file."""
    f = io.BytesIO(data)
    reader = StreamReader(f, emit_chunks=True)
    ranges = []
    records = reader.records
    while True:
        start = f.tell()
        try:
            record = next(records)
        except StopIteration:
            return ranges
        if isinstance(record, Chunk):
            head = 1 + 8 + 8 + 8 + 8 + 4 + 4 + len(record.compression) + 8
            ranges.append((start + head, start + head + len(record.data)))


def zstd_copy(tmp: Path) -> bytes:
    path = tmp / "zstd.mcap"
    with RecordingWriter(path, compression="zstd") as writer:
        for r in iter_messages(CAPTURE):
            writer.add(r.key, r.payload, r.log_time_ns)
    return path.read_bytes()


def variants(tmp: Path) -> list[Variant]:
    """About fifty seeded damages of the plain capture and of a zstd copy of it."""
    rng = random.Random(SEED)
    found: list[Variant] = []
    for label, original in (("plain", CAPTURE.read_bytes()), ("zstd", zstd_copy(tmp))):
        ranges = chunk_data_ranges(original)
        lo, hi = ranges[0]
        counts = {"flip-chunk": 10, "flip-anywhere": 8, "zero-chunk": 4, "zero-anywhere": 3}
        if label == "zstd":
            counts = {"flip-chunk": 8, "flip-anywhere": 3, "zero-chunk": 3, "zero-anywhere": 2}
        for kind, count in counts.items():
            for i in range(count):
                data = bytearray(original)
                inside = kind.endswith("chunk")
                first, last = (lo, hi) if inside else (8, len(data) - 1)
                at = rng.randrange(first, last)
                if kind.startswith("flip"):
                    data[at] ^= 1 << rng.randrange(8)
                else:
                    length = min(rng.randrange(1, 4096), (hi if inside else len(data)) - at)
                    if bytes(data[at : at + length]) == bytes(length):
                        continue  # already zeros: nothing would change
                    data[at : at + length] = bytes(length)
                found.append(Variant(f"{label}-{kind}-{i}", bytes(data), inside))
        for i in range(4):
            cut = rng.randrange(9, len(original) - 1)
            found.append(Variant(f"{label}-cut-{i}", original[:cut], False))
    return found


def depth_pixel_changed() -> bytes:
    """Four bytes of one depth pixel in the middle of the picture set to another float."""
    data = bytearray(CAPTURE.read_bytes())
    depth = next(r.payload for r in iter_messages(CAPTURE) if r.key == "camera/depth/image_raw")
    at = data.find(depth) + len(depth) // 2
    at -= at % 4
    data[at : at + 4] = bytes(b ^ 0x5A for b in data[at : at + 4])
    return bytes(data)


@pytest.fixture(scope="module")
def damaged(tmp_path_factory) -> list[tuple[Variant, Path]]:
    tmp = tmp_path_factory.mktemp("damaged")
    made = []
    for variant in variants(tmp):
        path = tmp / f"{variant.name}.mcap"
        path.write_bytes(variant.data)
        made.append((variant, path))
    return made


def run(capsys, caplog, *argv: str) -> tuple[int, str]:
    """``onebox ARGV`` in this process: its exit code and what it wrote to stderr and its log.

    Any exception that escapes the command (what a user would see as a traceback) fails the
    test here."""
    capsys.readouterr()
    caplog.clear()
    code = cli.main(list(argv))
    return code, capsys.readouterr().err + caplog.text


def test_about_fifty_variants_are_made(damaged):
    """The seeded set has damage inside chunks, outside them, cuts, and a zstd copy."""
    made = [variant for variant, _ in damaged]
    assert 45 <= len(made) <= 60
    assert sum(v.in_chunk_data for v in made) >= 20
    assert any(v.name.startswith("zstd") for v in made)


@pytest.mark.parametrize("recover", [False, True], ids=["strict", "recover"])
def test_info_on_every_damaged_file_is_one_line_or_a_summary(capsys, caplog, damaged, recover):
    """info: exit 0 or 2 and no traceback on every variant; strict refuses damage in chunks."""
    flags = ["--recover"] if recover else []
    for variant, path in damaged:
        code, err = run(capsys, caplog, "info", str(path), *flags)
        assert code in (0, 2), (variant.name, err)
        assert "Traceback" not in err, (variant.name, err)
        if code == 2:
            assert f"onebox info: {path}" in err, err
        if variant.in_chunk_data and not recover:
            assert code == 2 and "damaged" in err, (variant.name, err)
        if variant.in_chunk_data and recover:
            assert code == 0 and "skipped 1 damaged chunk" in err, (variant.name, err)


@pytest.mark.parametrize("recover", [False, True], ids=["strict", "recover"])
def test_replay_on_every_damaged_file_is_one_line_or_a_replay(
    capsys, caplog, damaged, module_router, recover
):
    """replay: exit 0 or 2 and no traceback; damage in a chunk is refused before publishing."""
    flags = ["--recover"] if recover else []
    for variant, path in damaged:
        code, err = run(
            capsys, caplog, "replay", str(path), "--rate", "0", "--wait-s", "0",
            "--connect", module_router, *flags,
        )  # fmt: skip
        assert code in (0, 2), (variant.name, err)
        assert "Traceback" not in err, (variant.name, err)
        if variant.in_chunk_data and not recover:
            assert code == 2 and "damaged" in err and "replaying" not in err, (variant.name, err)


def test_view_save_on_damaged_files_never_gives_a_traceback(capsys, caplog, damaged, tmp_path):
    """view --save: exit 0 or 2 and no traceback on a sample of every kind of damage."""
    pytest.importorskip("rerun")
    sample = damaged[::4]
    for variant, path in sample:
        code, err = run(capsys, caplog, "view", str(path), "--save", str(tmp_path / "out.rrd"))
        assert code in (0, 2), (variant.name, err)
        assert "Traceback" not in err, (variant.name, err)
        if variant.in_chunk_data:
            assert code == 2, (variant.name, err)


def test_a_changed_depth_pixel_is_refused_by_default(capsys, caplog, tmp_path):
    """Four changed bytes of one depth pixel: info refuses the file, --recover skips its chunk."""
    path = tmp_path / "pixel.mcap"
    path.write_bytes(depth_pixel_changed())
    code, err = run(capsys, caplog, "info", str(path))
    assert code == 2 and "damaged" in err and "crc" in err.lower(), err
    code, err = run(capsys, caplog, "info", str(path), "--recover")
    assert code == 0 and "skipped 1 damaged chunk" in err, err
    with pytest.raises(Exception, match="damaged"):
        list(iter_messages(path))
