"""Fixtures: a private Zenoh router per test, onebox processes as real subprocesses.

The helpers behind them live in :mod:`onebox.testing.processes`, where the benchmarks use them
too.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from onebox import bus
from onebox.perception import kernels
from onebox.testing.processes import Inbox, Processes, bus_args, private_router


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the finder's kernels into numba's cache once, before any locator process
    starts: each then loads them in a fraction of a second instead of compiling them itself
    against a test's timeout."""
    kernels.warm_up()


@pytest.fixture
def router() -> Iterator[str]:
    """A private ``onebox router`` on a free loopback port; yields its endpoint."""
    with private_router() as endpoint:
        yield endpoint


@pytest.fixture(scope="module")
def module_router() -> Iterator[str]:
    """One private router shared by the tests of a module (for an expensive shared capture)."""
    with private_router() as endpoint:
        yield endpoint


@pytest.fixture
def processes(router: str) -> Iterator[Processes]:
    """Start onebox processes on the test's private router; they are stopped afterwards."""
    procs = Processes(router)
    yield procs
    procs.stop_all()


@pytest.fixture
def test_bus(router: str) -> Iterator[bus.Bus]:
    """An open bus in the test process itself, on the private router."""
    with bus.open_bus(bus_args(router)) as b:
        yield b


@pytest.fixture
def inbox() -> Inbox:
    """Collects the samples of a subscription, for ``Inbox.wait``."""
    return Inbox()
