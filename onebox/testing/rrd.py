"""Read a Rerun .rrd back, for the tests: what each entity holds, last value per component."""

from __future__ import annotations

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
