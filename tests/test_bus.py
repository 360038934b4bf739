"""The bus: namespaces, typed subscriptions that survive garbage, newest-wins queues, settings."""

from __future__ import annotations

import argparse
import json
import subprocess
import threading
from pathlib import Path

import pytest
import zenoh

from onebox import bus, settings, sync
from onebox.errors import SettingError
from onebox.testing.processes import (
    Inbox,
    Processes,
    bus_args,
    free_port,
    has_key,
    wait_for_output,
)
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


@pytest.mark.parametrize("attempt", range(3))
def test_a_late_wildcard_subscriber_gets_every_latched_key(router: str, attempt: int) -> None:
    """A subscriber on ``**`` that joins late (a recorder) gets the last sample of every latched
    key, not only of the first publisher to answer its history query."""
    keys = ("tf_static", "support", "scene/boxes")
    with bus.open_bus(bus_args(router)) as a:
        for key in keys:
            a.publisher(key, TFMessage, latched=True).publish_bytes(key.encode())
        with bus.open_bus(bus_args(router)) as b:
            inbox = Inbox()
            b.subscribe_raw("**", inbox, history=True)
            items = inbox.wait(lambda items: {k for k, _ in items} >= set(keys), timeout_s=10)
    assert sorted(items) == sorted((key, key.encode()) for key in keys)


def test_pictures_drop_and_small_messages_block(test_bus: bus.Bus) -> None:
    """Pictures are dropped under congestion at low priority; detections and the clock block."""
    picture = test_bus.publisher("camera/depth/image_raw", Image)
    clock = test_bus.publisher("clock", Clock)
    assert picture._publisher.congestion_control == zenoh.CongestionControl.DROP
    assert bus.qos(Image).express and not bus.qos(Clock).express
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


def test_a_process_logs_losing_and_regaining_its_router() -> None:
    """A locator whose router stops says so, and says so again when a router is back."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    procs = Processes(endpoint)
    try:
        router = procs.start("router", "--listen", endpoint, connect=False)
        wait_for_output(router, "routing on", timeout_s=30)
        locator = procs.start("locator")
        wait_for_output(locator, "router", timeout_s=30)
        procs.stop(router)
        wait_for_output(locator, "lost router", timeout_s=30)
        router = procs.start("router", "--listen", endpoint, connect=False)
        wait_for_output(locator, "connected", timeout_s=30)
        assert locator.poll() is None
    finally:
        procs.stop_all()


@pytest.mark.parametrize("config", [bus.CLIENT_CONFIG, bus.SECURE_CLIENT_CONFIG])
def test_a_capture_fits_the_client_queue_pictures_go_on(config: Path) -> None:
    """Colour and depth of a 320 x 240 capture fit, as 64 KiB batches, in the client's queue of
    the priority pictures travel on, so the sim's puts return without waiting on the link."""
    zenoh_config = zenoh.Config.from_file(str(config))
    # The configuration names a queue as the priority is named: Priority.DATA is "data".
    priority = next(
        name
        for name in ("data_high", "data", "data_low")
        if getattr(zenoh.Priority, name.upper()) == bus.PICTURE_QOS.priority
    )
    size = json.loads(zenoh_config.get_json(f"transport/link/tx/queue/size/{priority}"))
    batch = json.loads(zenoh_config.get_json("transport/link/tx/batch_size"))
    capture = 320 * 240 * 3 + 320 * 240 * 4
    assert size * batch >= capture + batch, (priority, size, batch)


def test_clients_that_come_and_go_leave_nothing_in_the_router(router: str) -> None:
    """Clients sending 1280 x 720 depth map no shared memory into the router; its RSS stays flat."""
    pid = _router_pid(router)

    def clients_come_and_go(times: int) -> None:
        for _ in range(times):
            with bus.open_bus(bus_args(router)) as sub, bus.open_bus(bus_args(router)) as pub:
                inbox = Inbox()
                sub.subscribe_raw("camera/depth/image_raw", inbox)
                p = pub.publisher("camera/depth/image_raw", Image)
                assert p.wait_for_subscribers(10)
                for _ in range(3):
                    p.publish(Image(width=1280, height=720, data=bytes(1280 * 720 * 4)))
                inbox.wait(has_key("camera/depth/image_raw", 1))

    clients_come_and_go(2)
    rss_before = _rss_mib(pid)
    clients_come_and_go(8)
    maps = Path(f"/proc/{pid}/maps").read_text()
    assert "/dev/shm" not in maps, "the router maps shared memory from its clients"
    assert _rss_mib(pid) - rss_before < 16, (rss_before, _rss_mib(pid))


def _router_pid(endpoint: str) -> int:
    """The pid of the process listening on ``endpoint``'s port (the test's private router)."""
    port = int(endpoint.rsplit(":", 1)[1])
    out = subprocess.run(
        ["ss", "-Htlnp", f"sport = :{port}"], capture_output=True, text=True, check=True
    ).stdout
    return int(out.split("pid=", 1)[1].split(",", 1)[0])


def _rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no VmRSS for {pid}")
