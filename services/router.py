"""onebox router: the Zenoh router every onebox process on this host connects to.

Reads nothing and writes nothing itself; it routes. Listens on tcp/127.0.0.1:7447 by default
(config/router.json5), or on $ONEBOX_ROUTER, or on --listen; loopback only, with multicast
scouting off. Runs until Ctrl-C or SIGTERM. Its TCP links close without lingering (see
onebox.sockets), so a host dropping off never holds traffic between the others.
"""

from __future__ import annotations

import argparse
import logging
import threading

from onebox import bus, sockets

log = logging.getLogger("router")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bus.add_arguments(parser)


def main(args: argparse.Namespace) -> int:
    """Open a router session and hold it until stopped."""
    # Closing a link to a host that has gone must not hold a thread other hosts need.
    with sockets.without_linger(), bus.open_bus(args, default_file=bus.ROUTER_CONFIG) as b:
        config = bus.zenoh_config(args, bus.ROUTER_CONFIG)
        log.info(
            "routing on %s (zid %s)", config.get_json("listen/endpoints"), b.session.info.zid()
        )
        threading.Event().wait()
    return 0
