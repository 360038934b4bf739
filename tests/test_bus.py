"""The bus: namespaces, typed subscriptions that survive garbage, newest-wins queues, settings."""

from __future__ import annotations

import argparse
import threading

import pytest
import zenoh

from onebox import bus, settings, sync
from onebox.errors import SettingError
from onebox.testing.processes import Inbox, bus_args, has_key
from schemas import (
    CameraInfo,
    Clock,
    Detection3DArray,
    Image,
    PointCloud,
    SupportPlane,
    TFMessage,
    codec,
)


def test_garbage_is_logged_with_its_key_and_dropped(
    router: str, caplog: pytest.LogCaptureFixture
) -> None:
    """A payload that is not the subscribed type is logged with its key; good ones still arrive."""
    got: list[Clock] = []
    arrived = threading.Event()

    def on_clock(key: str, message: Clock) -> None:
        got.append(message)
        arrived.set()

    with bus.open_bus(bus_args(router)) as sub, bus.open_bus(bus_args(router)) as pub:
        sub.subscribe("clock", Clock, on_clock)
        inbox = Inbox()
        sub.subscribe_raw("clock", inbox)
        raw = pub.publisher("clock", Clock)
        assert raw.wait_for_subscribers(10)
        raw.publish_bytes(b"\xc1garbage")
        raw.publish_bytes(codec(Image).encode(Image(width=3)))
        raw.publish_bytes(codec(Clock).encode(Clock(clock_ns=42)))
        inbox.wait(has_key("clock", 3))
        assert arrived.wait(10)
    assert got == [Clock(clock_ns=42)]
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert any(w.startswith("clock: not a onebox.sim.Clock") for w in warnings), warnings


def test_no_subscriber_means_no_match(router: str) -> None:
    """A publisher with no subscriber does not match; once one subscribes elsewhere, it does."""
    with bus.open_bus(bus_args(router)) as sub, bus.open_bus(bus_args(router)) as pub:
        p = pub.publisher("clock", Clock)
        assert not p.wait_for_subscribers(0.5)
        sub.subscribe_raw("other", Inbox())
        assert not p.wait_for_subscribers(0.5)
        sub.subscribe_raw("clock", Inbox())
        assert p.wait_for_subscribers(10)


def test_pictures_drop_and_small_messages_block(test_bus: bus.Bus) -> None:
    """Pictures are dropped under congestion at low priority; detections and the clock block."""
    picture = test_bus.publisher("camera/depth/image_raw", Image)
    clock = test_bus.publisher("clock", Clock)
    assert picture._publisher.congestion_control == zenoh.CongestionControl.DROP
    assert picture._publisher.priority == zenoh.Priority.DATA_LOW
    assert clock._publisher.congestion_control == zenoh.CongestionControl.BLOCK
    assert clock._publisher.priority == zenoh.Priority.DATA
    for message_type in (Detection3DArray, TFMessage, CameraInfo, SupportPlane):
        assert bus.qos(message_type) == bus.RELIABLE_QOS, message_type
    assert bus.qos(PointCloud) == bus.PICTURE_QOS


def test_a_callback_error_does_not_kill_the_subscriber(router: str) -> None:
    """An exception in a callback drops that sample; the next one is still delivered."""
    seen: list[int] = []
    done = threading.Event()

    def flaky(key: str, message: Clock) -> None:
        if message.clock_ns == 1:
            raise ValueError("cannot use this one")
        seen.append(message.clock_ns)
        done.set()

    with bus.open_bus(bus_args(router)) as sub, bus.open_bus(bus_args(router)) as pub:
        sub.subscribe("clock", Clock, flaky)
        probe = Inbox()
        sub.subscribe_raw("clock", probe)
        p = pub.publisher("clock", Clock)
        assert p.wait_for_subscribers(10)
        p.publish(Clock(clock_ns=1))
        p.publish(Clock(clock_ns=2))
        probe.wait(has_key("clock", 2))
        assert done.wait(10)
    assert seen == [2]


def test_namespace_prefixes_every_key(router: str) -> None:
    """--namespace robot1 puts camera/image_raw at robot1/camera/image_raw."""
    inbox = Inbox()
    with (
        bus.open_bus(bus_args(router)) as plain,
        bus.open_bus(bus_args(router, "robot1")) as robot,
    ):
        plain.subscribe_raw("**", inbox)
        assert robot.key("camera/image_raw") == "robot1/camera/image_raw"
        assert robot.unkey("robot1/camera/image_raw") == "camera/image_raw"
        p = robot.publisher("camera/image_raw", Image)
        assert p.wait_for_subscribers(10)
        p.publish(Image(width=1))
        inbox.wait(has_key("robot1/camera/image_raw"))


def test_newest_queue_keeps_the_newest_and_counts_drops() -> None:
    """A full queue drops its oldest item, counts it, and hands out the newest."""
    q: sync.NewestQueue[int] = sync.NewestQueue(maxlen=2)
    for i in range(5):
        q.put(i)
    assert q.dropped == 3
    assert [q.get(0), q.get(0), q.get(0)] == [3, 4, None]


def test_settings_precedence(monkeypatch: pytest.MonkeyPatch) -> None:
    """A flag beats the environment, which beats config/onebox.toml, which beats the default."""
    parser = argparse.ArgumentParser()
    monkeypatch.delenv("ONEBOX_HFOV_DEG", raising=False)
    settings.add(parser, "hfov_deg", 45.0, "lens")
    assert parser.parse_args([]).hfov_deg == 60.0  # the file's value, not the fallback
    monkeypatch.setenv("ONEBOX_HFOV_DEG", "90")
    parser = argparse.ArgumentParser()
    settings.add(parser, "hfov_deg", 45.0, "lens")
    assert parser.parse_args([]).hfov_deg == 90.0
    assert parser.parse_args(["--hfov-deg", "30"]).hfov_deg == 30.0


def test_bad_environment_value_names_the_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    """ONEBOX_HFOV_DEG=wide is reported as that variable and value, not a deep traceback."""
    monkeypatch.setenv("ONEBOX_HFOV_DEG", "wide")
    with pytest.raises(SettingError, match="ONEBOX_HFOV_DEG='wide'"):
        settings.add(argparse.ArgumentParser(), "hfov_deg", 60.0, "lens")


@pytest.mark.parametrize(("text", "value"), [("false", False), ("0", False), ("On", True)])
def test_yes_no_settings(monkeypatch: pytest.MonkeyPatch, text: str, value: bool) -> None:
    """ONEBOX_VIEWER=false and friends parse as the seed's rviz:=false did."""
    monkeypatch.setenv("ONEBOX_VIEWER", text)
    parser = argparse.ArgumentParser()
    settings.add(parser, "viewer", True, "viewer")
    assert parser.parse_args([]).viewer is value
    assert parser.parse_args(["--viewer"]).viewer is True


def test_router_env_moves_every_endpoint(monkeypatch: pytest.MonkeyPatch) -> None:
    """ONEBOX_ROUTER sets where the router listens and where every peer connects."""
    monkeypatch.setenv(bus.ROUTER_ENV, "tcp/127.0.0.1:17999")
    args = argparse.Namespace(connect=None, listen=None, config=None)
    peer = bus.zenoh_config(args)
    router = bus.zenoh_config(args, bus.ROUTER_CONFIG)
    assert "17999" in peer.get_json("connect/endpoints")
    assert "17999" in router.get_json("listen/endpoints")
    assert "17999" not in peer.get_json("listen/endpoints")
