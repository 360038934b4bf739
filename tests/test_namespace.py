"""A namespace is a plain key prefix; a sample on a wildcard key reaches no callback."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from onebox import bus
from onebox.errors import SettingError
from onebox.testing.processes import ROOT, Inbox, bus_args, has_key
from schemas import Clock


@pytest.mark.parametrize(
    ("namespace", "complaint"),
    [
        ("**", "wildcards"),
        ("*", "wildcards"),
        ("robot*", "wildcards"),
        ("a/$*", "wildcards"),
        ("a//b", "empty chunk"),
        ("/robot1", "starts or ends with '/'"),
        ("robot1/", "starts or ends with '/'"),
        ("what?", "wildcards"),
    ],
)
def test_a_namespace_that_is_not_a_plain_prefix_is_refused(namespace: str, complaint: str) -> None:
    """Wildcards, empty chunks and stray slashes are refused with a message that says why."""
    with pytest.raises(SettingError, match=complaint):
        bus.check_namespace(namespace)


@pytest.mark.parametrize("namespace", ["", "robot1", "site/robot-1", "a_b/c.d"])
def test_a_plain_prefix_is_kept(namespace: str) -> None:
    """Plain prefixes pass unchanged."""
    assert bus.check_namespace(namespace) == namespace


@pytest.mark.parametrize(
    "argv", [["--namespace", "**"], ["--namespace", "a//b"]], ids=["wildcard", "empty-chunk"]
)
def test_the_locator_refuses_a_bad_namespace_in_one_line(argv: list[str]) -> None:
    """`onebox locator --namespace '**'` prints one line naming the namespace and exits 2."""
    result = subprocess.run(
        [sys.executable, "-m", "services.cli", "locator", *argv],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "namespace" in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_the_environment_namespace_is_checked_too(monkeypatch: pytest.MonkeyPatch) -> None:
    """ONEBOX_NAMESPACE='a//b' is refused as the flag is."""
    monkeypatch.setenv("ONEBOX_NAMESPACE", "a//b")
    with pytest.raises(SettingError, match="empty chunk"):
        bus.add_arguments(argparse.ArgumentParser(prog="onebox test"))


def test_a_put_on_a_wildcard_key_is_nobodys_sample(router: str) -> None:
    """A put on `**`, `*` or `clo$*` is dropped with a warning; the next put on the key arrives."""
    got: list[tuple[str, Clock]] = []
    inbox = Inbox()
    with bus.open_bus(bus_args(router)) as sub, bus.open_bus(bus_args(router)) as pub:
        sub.subscribe("clock", Clock, lambda key, message: got.append((key, message)))
        sub.subscribe_raw("**", inbox)
        assert pub.publisher("clock", Clock).wait_for_subscribers(10)
        payload = pub.publisher("clock", Clock).publish(Clock(clock_ns=1))
        pub.session.put("**", payload)
        pub.session.put("*", payload)
        pub.session.put("clo$*", payload)
        pub.publisher("clock", Clock).publish(Clock(clock_ns=2))
        inbox.wait(has_key("clock", 2))
    assert got == [("clock", Clock(clock_ns=1)), ("clock", Clock(clock_ns=2))]
    assert {key for key, _ in inbox.items} == {"clock"}
