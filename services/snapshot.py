"""Record one capture into an MCAP file and exit, as the seed's save_snapshot.py did.

    onebox snapshot tests/data/one_box.mcap

Reads: ``camera/camera_info``, ``camera/depth/image_raw`` and ``camera/image_raw`` until one of
each has arrived with the same ``header.stamp_ns``, and the latched ``tf_static``.
Writes: OUT.mcap with exactly those four messages, as ``onebox record`` writes them (one channel
a key, msgpack, jsonschema; the bytes that travelled; log time = arrival, publish time = stamp).

Refuses to overwrite OUT.mcap (delete the old one first, or pass ``--overwrite``). When no
complete capture arrives within ``--timeout-s`` it says which keys were missing and exits 2.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from onebox import bus, settings
from onebox.errors import NothingArrived, RecordingError, SettingError
from onebox.recording import RecordingWriter, stamp_ns

log = logging.getLogger("snapshot")

CAMERA_KEYS = ("camera/camera_info", "camera/depth/image_raw", "camera/image_raw")
TF_STATIC = "tf_static"
KEPT_STAMPS = 8
"""How many recent stamps wait for their other pictures before the oldest is forgotten."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, metavar="OUT.mcap", help="the file to write")
    parser.add_argument(
        "--overwrite", action="store_true", help="replace OUT.mcap if it already exists"
    )
    settings.add(parser, "timeout_s", 10.0, "give up when no whole capture arrives in this time")
    bus.add_arguments(parser)


Sample = tuple[int, bytes]
"""(log time ns, payload)"""


class CaptureCollector:
    """Collects samples until one stamp has every camera key and tf_static has arrived."""

    def __init__(self, camera_keys: list[str], tf_key: str) -> None:
        self._camera_keys = camera_keys
        self._tf_key = tf_key
        self._by_stamp: dict[int, dict[str, Sample]] = {}
        self._tf: Sample | None = None
        self._seen: set[str] = set()
        self._lock = threading.Lock()
        self.done = threading.Event()
        self.capture: dict[str, Sample] = {}

    def on_sample(self, key: str, payload: bytes, log_time_ns: int) -> None:
        with self._lock:
            if self.done.is_set():
                return
            self._seen.add(key)
            if key == self._tf_key:
                self._tf = (log_time_ns, payload)
            elif key in self._camera_keys:
                stamp = stamp_ns(payload)
                if stamp is None:
                    log.warning("%s: a message with no header stamp, ignored", key)
                    return
                self._by_stamp.setdefault(stamp, {})[key] = (log_time_ns, payload)
                while len(self._by_stamp) > KEPT_STAMPS:
                    del self._by_stamp[min(self._by_stamp)]
            if self._tf is None:
                return
            for samples in self._by_stamp.values():
                if len(samples) == len(self._camera_keys):
                    self.capture = {**samples, self._tf_key: self._tf}
                    self.done.set()
                    return

    def missing(self) -> list[str]:
        """The keys that never arrived, or, when all did, the ones no stamp had together."""
        with self._lock:
            keys = [*self._camera_keys, self._tf_key]
            never = [k for k in keys if k not in self._seen]
            if never:
                return never
            best = max(self._by_stamp.values(), key=len, default={})
            return [k for k in self._camera_keys if k not in best]


@dataclass(frozen=True)
class SnapshotSettings:
    """What ``onebox snapshot`` was asked to do, checked."""

    out: Path
    overwrite: bool
    timeout_s: float

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> SnapshotSettings:
        if not args.timeout_s > 0:
            raise SettingError(f"--timeout-s {args.timeout_s}: must be more than 0 seconds")
        return cls(out=args.out, overwrite=args.overwrite, timeout_s=args.timeout_s)


def main(args: argparse.Namespace) -> int:
    config = SnapshotSettings.from_args(args)
    out = config.out
    if out.exists() and not config.overwrite:
        raise RecordingError(
            f"{out} already exists: delete it first, choose another name, or pass --overwrite"
        )
    with bus.open_bus(args) as b:
        collector = CaptureCollector([b.key(k) for k in CAMERA_KEYS], b.key(TF_STATIC))

        def on_sample(key: str, payload: bytes) -> None:
            collector.on_sample(key, payload, time.time_ns())

        b.subscribe_raw(TF_STATIC, on_sample, history=True)
        for key in CAMERA_KEYS:
            b.subscribe_raw(key, on_sample)
        log.info("waiting up to %.0f s for one capture", config.timeout_s)
        if not collector.done.wait(config.timeout_s):
            endpoints = ", ".join(args.connect or [bus.DEFAULT_ENDPOINT])
            raise NothingArrived(
                f"no whole capture within {config.timeout_s:g} s on {endpoints} (missing "
                f"{', '.join(collector.missing())}): is `onebox sim` running there?"
            )
    ordered = sorted(collector.capture.items(), key=lambda item: item[1][0])
    with RecordingWriter(
        out, namespace=b.namespace, compression="zstd", overwrite=config.overwrite
    ) as writer:
        for key, (log_time_ns, payload) in ordered:
            writer.add(key, payload, log_time_ns)
    camera_stamp = stamp_ns(collector.capture[b.key(CAMERA_KEYS[0])][1])
    log.info("wrote %s: %s at stamp %s ns", out, ", ".join(k for k, _ in ordered), camera_stamp)
    return 0
