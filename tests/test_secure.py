"""The secured configuration: TLS, one identity a process, access control by that identity."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path

import pytest

from onebox import bus
from onebox.errors import BusError
from onebox.testing.processes import (
    Inbox,
    Processes,
    free_port,
    has_key,
    wait_for_listening,
    wait_for_output,
)
from schemas import Clock, Detection3DArray, GroundTruth, Image, codec
from services import certs


@pytest.fixture(scope="module")
def cert_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A CA and every process's certificate, plus a `stranger` the router knows nothing of."""
    folder = tmp_path_factory.mktemp("certs")
    certs.make_certificates(
        certs.CertSettings(folder, (*certs.IDENTITIES, "stranger"), hosts=(), days=1)
    )
    return folder


@pytest.fixture(scope="module")
def secure_router(cert_dir: Path) -> Iterator[str]:
    """`onebox router --secure` on a free port; yields the endpoint clients connect to."""
    port = free_port()
    procs = Processes(f"tls/localhost:{port}")
    proc = procs.start(
        "router", "--secure", str(cert_dir), "--listen", f"tls/127.0.0.1:{port}", connect=False
    )
    wait_for_listening(procs, proc, port)
    yield procs.endpoint
    procs.stop_all()


def args_as(endpoint: str, folder: Path | None, identity: str) -> argparse.Namespace:
    """The parsed flags of process ``identity`` connecting to the secured router."""
    return argparse.Namespace(
        connect=[endpoint],
        listen=None,
        config=bus.SECURE_CLIENT_CONFIG if folder is None else None,
        namespace="",
        secure=folder,
        identity=identity,
    )


def test_no_certificate_cannot_connect(secure_router: str, cert_dir: Path) -> None:
    """A client without a certificate is refused at the TLS handshake."""
    args = args_as(secure_router, None, "stranger")
    with pytest.raises(BusError), bus.open_bus(args, connect_timeout_s=2):
        pass


def test_a_strangers_publish_is_refused(secure_router: str, cert_dir: Path) -> None:
    """A certificate the router has no rule for publishes nothing; the locator's arrives."""
    inbox = Inbox()
    with (
        bus.open_bus(args_as(secure_router, cert_dir, "viewer")) as viewer,
        bus.open_bus(args_as(secure_router, cert_dir, "stranger")) as stranger,
        bus.open_bus(args_as(secure_router, cert_dir, "locator")) as locator,
    ):
        viewer.subscribe_raw("**", inbox)
        forged = stranger.publisher("detections", Detection3DArray)
        real = locator.publisher("detections", Detection3DArray)
        assert real.wait_for_subscribers(10)
        assert not forged.wait_for_subscribers(0.5)
        forged.publish(Detection3DArray())
        stranger.publisher("camera/depth/image_raw", Image).publish(Image(width=1))
        stranger.session.put("clock", codec(Clock).encode(Clock(clock_ns=1)))
        real.publish(Detection3DArray())
        inbox.wait(has_key("detections"))
        forged.publish(Detection3DArray())
        real.publish(Detection3DArray())
        inbox.wait(has_key("detections", 2))
    assert [k for k, _ in inbox.items] == ["detections", "detections"]


def test_the_locator_cannot_publish_pictures(secure_router: str, cert_dir: Path) -> None:
    """Only the sim may publish depth: the locator's depth never reaches a subscriber."""
    inbox = Inbox()
    with (
        bus.open_bus(args_as(secure_router, cert_dir, "record")) as record,
        bus.open_bus(args_as(secure_router, cert_dir, "locator")) as locator,
        bus.open_bus(args_as(secure_router, cert_dir, "sim")) as sim,
    ):
        record.subscribe_raw("camera/**", inbox)
        forged = locator.publisher("camera/depth/image_raw", Image)
        real = sim.publisher("camera/depth/image_raw", Image)
        assert real.wait_for_subscribers(10)
        forged.publish(Image(width=2))
        real.publish(Image(width=1))
        forged.publish(Image(width=2))
        real.publish(Image(width=1))
        inbox.wait(has_key("camera/depth/image_raw", 2))
    assert [codec(Image).decode(p).width for _, p in inbox.items] == [1, 1]


def test_a_stranger_cannot_subscribe_to_pictures(secure_router: str, cert_dir: Path) -> None:
    """The sim's pictures reach the recorder but never a stranger's subscriber."""
    stranger_inbox, record_inbox = Inbox(), Inbox()
    with (
        bus.open_bus(args_as(secure_router, cert_dir, "stranger")) as stranger,
        bus.open_bus(args_as(secure_router, cert_dir, "record")) as record,
        bus.open_bus(args_as(secure_router, cert_dir, "sim")) as sim,
    ):
        stranger.subscribe_raw("**", stranger_inbox)
        record.subscribe_raw("**", record_inbox)
        depth = sim.publisher("camera/depth/image_raw", Image)
        assert depth.wait_for_subscribers(10)
        for width in range(3):
            depth.publish(Image(width=width))
        record_inbox.wait(has_key("camera/depth/image_raw", 3))
    assert stranger_inbox.items == []


def test_the_secured_pipeline_finds_the_box(secure_router: str, cert_dir: Path) -> None:
    """sim and locator under --secure: the viewer's identity gets the box where the sim put it."""
    procs = Processes(secure_router)
    inbox = Inbox()
    try:
        with bus.open_bus(args_as(secure_router, cert_dir, "viewer")) as viewer:
            viewer.subscribe_raw("detections", inbox)
            viewer.subscribe_raw("sim/ground_truth", inbox)
            locator = procs.start("locator", "--secure", str(cert_dir))
            wait_for_output(locator, "router", timeout_s=60)
            procs.start("sim", "--secure", str(cert_dir), "--frames", "100")
            try:
                items = inbox.wait(
                    lambda got: has_key("detections")(got) and has_key("sim/ground_truth")(got),
                    timeout_s=60,
                )
            except AssertionError as e:
                raise AssertionError(f"{e}\nlocator said:\n{procs.stop(locator)}") from None
        found = codec(Detection3DArray).decode(next(p for k, p in items if k == "detections"))
        truth = codec(GroundTruth).decode(next(p for k, p in items if k == "sim/ground_truth"))
        assert len(found.detections) == 1
        centre, true_centre = found.detections[0].bbox.center.position, truth.box_pose.position
        assert abs(centre.x - true_centre.x) < 0.01, (centre, true_centre)
        assert abs(centre.y - true_centre.y) < 0.01, (centre, true_centre)
    finally:
        procs.stop_all()
