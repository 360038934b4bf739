"""Read a Rerun .rrd back, for the tests: what each entity holds, last value per component."""

from __future__ import annotations

import os
import select
import subprocess
import time
from pathlib import Path
from typing import Any

from rerun.chunk import RrdReader


def contents(path: Path) -> dict[str, dict[str, Any]]:
    """{entity path: {component column: its last logged value, as Python}} of the recording."""
    out: dict[str, dict[str, Any]] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        entity = out.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            if name.startswith("rerun.controls") or name in {"log_time", "sim_time"}:
                continue
            values = [v for v in batch.column(name).to_pylist() if v is not None]
            if values:
                entity[name] = values[-1]
        if "sim_time" in batch.schema.names:
            entity.setdefault("_times", []).extend(batch.column("sim_time").to_pylist())
    return out


def wait_for_output(proc: subprocess.Popen[str], text: str, timeout_s: float = 30.0) -> str:
    """Read ``proc``'s output until ``text`` appears; returns what was read.

    Reads the raw pipe (not the text wrapper), so Processes.stop still gets the rest later.
    """
    assert proc.stdout is not None
    fd = proc.stdout.fileno()
    seen = b""
    deadline = time.monotonic() + timeout_s
    while text.encode() not in seen:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise AssertionError(f"no {text!r} within {timeout_s} s; got:\n{seen.decode()}")
        ready, _, _ = select.select([fd], [], [], remaining)
        if ready:
            chunk = os.read(fd, 65536)
            if not chunk:
                raise AssertionError(f"exited before {text!r}; got:\n{seen.decode()}")
            seen += chunk
    return seen.decode()
