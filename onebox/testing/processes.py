"""Running onebox as real processes for tests and benchmarks: free ports, a private router,
subprocesses stopped at the end, an inbox of samples, waiting for a line of output.

Every test pipeline lives on its own loopback port (never 7447), so tests and benchmarks run
beside a running ``honcho start``. Nothing here sleeps to synchronise: it waits on messages,
on output or on a port.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent.parent
"""The checkout: the tests and the committed capture live here."""
DATA = ROOT / "tests" / "data"
CAPTURE = DATA / "one_box.mcap"
"""One capture of the seed's scene, made with ``onebox snapshot``."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def terminate(proc: subprocess.Popen[bytes], timeout_s: float = 30.0) -> None:
    """SIGTERM ``proc`` (as honcho does) and wait for it; SIGKILL it after ``timeout_s``."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


class Processes:
    """onebox subprocesses started by a test; all stopped (SIGTERM, then SIGKILL) at its end."""

    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self.started: list[subprocess.Popen[str]] = []

    def start(
        self, *args: str, env: dict[str, str] | None = None, connect: bool = True
    ) -> subprocess.Popen[str]:
        """Start ``onebox ARGS`` connected to this test's router; output is captured."""
        cmd = [*ONEBOX, *args]
        if connect:
            cmd += ["--connect", self.endpoint]
        full_env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
        proc = subprocess.Popen(
            cmd,
            cwd=ROOT,
            env=full_env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.started.append(proc)
        return proc

    def stop(self, proc: subprocess.Popen[str], timeout_s: float = 10.0) -> str:
        """SIGTERM ``proc``, wait, and return everything it printed."""
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            out, _ = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
        return out or ""

    def stop_all(self) -> None:
        """Stop every process still running, and close the pipes of those that ended."""
        for proc in reversed(self.started):
            self.stop(proc)


def wait_for_listening(
    procs: Processes, proc: subprocess.Popen[str], port: int, timeout_s: float = 15.0
) -> None:
    """Wait until ``proc`` (a router) listens on the loopback ``port``; raise with its output
    if it ends or takes longer than ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"router did not start: {procs.stop(proc)}") from None
            time.sleep(0.05)  # polling a port that has no event to wait on


@contextlib.contextmanager
def private_router() -> Iterator[str]:
    """Start ``onebox router`` on a free loopback port, yield its endpoint, stop it."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    procs = Processes(endpoint)
    proc = procs.start("router", "--listen", endpoint, connect=False)
    wait_for_listening(procs, proc, port)
    try:
        yield endpoint
    finally:
        procs.stop_all()


def honcho_env(**extra: str) -> dict[str, str]:
    """The environment for a ``honcho start`` test: the Procfile's ``onebox`` found beside this
    interpreter (as in an activated venv), unbuffered output, plus ``extra``."""
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    return {**os.environ, "PYTHONUNBUFFERED": "1", "PATH": path, **extra}


def bus_args(endpoint: str, namespace: str = "") -> argparse.Namespace:
    """The parsed Zenoh flags of a process connected to ``endpoint``."""
    return argparse.Namespace(connect=[endpoint], listen=None, config=None, namespace=namespace)


class Inbox:
    """Collects (key, payload) from a subscription; ``wait`` blocks until a condition holds."""

    def __init__(self) -> None:
        self.items: list[tuple[str, bytes]] = []
        self._cond = threading.Condition()

    def __call__(self, key: str, payload: bytes) -> None:
        with self._cond:
            self.items.append((key, payload))
            self._cond.notify_all()

    def wait(
        self, done: Callable[[list[tuple[str, bytes]]], bool], timeout_s: float = 20.0
    ) -> list[tuple[str, bytes]]:
        with self._cond:
            if not self._cond.wait_for(lambda: done(self.items), timeout=timeout_s):
                raise AssertionError(
                    f"timed out after {timeout_s} s; got keys {sorted({k for k, _ in self.items})}"
                )
            return list(self.items)

    def keys(self) -> set[str]:
        with self._cond:
            return {k for k, _ in self.items}


def has_key(key: str, count: int = 1) -> Callable[[list[tuple[str, Any]]], bool]:
    """A condition for Inbox.wait: at least ``count`` samples on ``key``."""
    return lambda items: sum(1 for k, _ in items if k == key) >= count


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


ONEBOX = [sys.executable, "-m", "services.cli"]
"""The ``onebox`` command, run with this interpreter from the checkout."""


def run_onebox(
    *args: str, timeout_s: float = 60.0, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``onebox ARGS`` to its end; its output is captured as text."""
    return subprocess.run(
        [*ONEBOX, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
        env=None if env is None else {**os.environ, **env},
    )


class Output:
    """Collects a process's output lines as they come, so a test can wait on a log line."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()

    def wait_for(self, pattern: str, timeout_s: float = 20.0) -> str:
        """The first line matching ``pattern`` (a regular expression)."""
        regex = re.compile(pattern)

        def found() -> str | None:
            return next((line for line in self.lines if regex.search(line)), None)

        with self._cond:
            if not self._cond.wait_for(lambda: found() is not None, timeout=timeout_s):
                raise AssertionError(
                    f"no line matching {pattern!r} in {timeout_s} s:\n" + self.text
                )
            line = found()
            assert line is not None
            return line

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def stop(self) -> str:
        """SIGTERM the process, wait for it and return everything it printed."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._thread.join(timeout=5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return self.text
