"""Shared fixtures: a private Zenoh router per test, onebox processes as real subprocesses.

Every test pipeline lives on its own loopback port (never 7447), so the suite runs beside a
running ``honcho start``. Tests wait on messages, never on a bare sleep.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from services import bus

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
CAPTURE = DATA / "one_box.mcap"

os.environ.setdefault("MUJOCO_GL", "egl")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Processes:
    """onebox subprocesses started by a test; all stopped (SIGTERM, then SIGKILL) at its end."""

    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self.started: list[subprocess.Popen[str]] = []

    def start(
        self, *args: str, env: dict[str, str] | None = None, connect: bool = True
    ) -> subprocess.Popen[str]:
        """Start ``onebox ARGS`` connected to this test's router; output is captured."""
        cmd = [sys.executable, "-m", "services.cli", *args]
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


def _run_router() -> Iterator[str]:
    """Start ``onebox router`` on a free loopback port, yield its endpoint, stop it."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    procs = Processes(endpoint)
    proc = procs.start("router", "--listen", endpoint, connect=False)
    deadline = time.monotonic() + 15
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                break
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"router did not start: {procs.stop(proc)}") from None
            time.sleep(0.05)
    yield endpoint
    procs.stop_all()


@pytest.fixture
def router() -> Iterator[str]:
    """A private ``onebox router`` on a free loopback port; yields its endpoint."""
    yield from _run_router()


@pytest.fixture(scope="module")
def module_router() -> Iterator[str]:
    """One private router shared by the tests of a module (for an expensive shared capture)."""
    yield from _run_router()


@pytest.fixture
def processes(router: str) -> Iterator[Processes]:
    """Start onebox processes on the test's private router; they are stopped afterwards."""
    procs = Processes(router)
    yield procs
    procs.stop_all()


def honcho_env(**extra: str) -> dict[str, str]:
    """The environment for a ``honcho start`` test: the Procfile's ``onebox`` found beside this
    interpreter (as in an activated venv), unbuffered output, plus ``extra``."""
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    return {**os.environ, "PYTHONUNBUFFERED": "1", "PATH": path, **extra}


def bus_args(endpoint: str, namespace: str = "") -> argparse.Namespace:
    """The parsed Zenoh flags of a process connected to ``endpoint``."""
    return argparse.Namespace(connect=[endpoint], listen=None, config=None, namespace=namespace)


@pytest.fixture
def test_bus(router: str) -> Iterator[bus.Bus]:
    """An open bus in the test process itself, on the private router."""
    with bus.open_bus(bus_args(router)) as b:
        yield b


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


@pytest.fixture
def inbox() -> Inbox:
    return Inbox()


def has_key(key: str, count: int = 1) -> Callable[[list[tuple[str, Any]]], bool]:
    """A condition for Inbox.wait: at least ``count`` samples on ``key``."""
    return lambda items: sum(1 for k, _ in items if k == key) >= count
