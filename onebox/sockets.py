"""Closing a link to a host that is gone without stalling the router.

Zenoh 1.10 sets SO_LINGER to 10 s on every TCP (and TLS) link it opens, with no setting to
change it. When a router's lease closes its link to a host that has dropped off the network,
``close()`` then blocks one of the router's few runtime threads for up to 10 s, waiting for a
FIN that nobody acknowledges; when that thread is one another host's traffic needs, that
traffic stops for 10 s too (measured: A -> C depth stopped 10.6 s while B was away).

:func:`clear_linger` turns SO_LINGER off on this process's TCP sockets, so a close returns at
once and the kernel finishes the connection in the background, as TCP normally does;
:func:`without_linger` does that every ``period_s`` while a block runs (a router opens links
at any time). Linux only (it walks /proc/self/fd); elsewhere it does nothing.
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import threading
from collections.abc import Iterator
from pathlib import Path

FD_DIR = Path("/proc/self/fd")
_LINGER = struct.Struct("ii")


def clear_linger() -> int:
    """Turn SO_LINGER off on every TCP socket of this process; returns how many were changed."""
    changed = 0
    try:
        names = os.listdir(FD_DIR)
    except OSError:
        return 0
    for name in names:
        try:
            if not os.readlink(FD_DIR / name).startswith("socket:"):
                continue
            sock = socket.socket(fileno=int(name))
        except (OSError, ValueError):
            continue  # closed meanwhile, or not a socket after all
        try:
            if sock.type == socket.SOCK_STREAM and sock.family in (
                socket.AF_INET,
                socket.AF_INET6,
            ):
                onoff, _ = _LINGER.unpack(
                    sock.getsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _LINGER.size)
                )
                if onoff:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _LINGER.pack(0, 0))
                    changed += 1
        except OSError:
            pass
        finally:
            sock.detach()  # the descriptor is Zenoh's: never close it
    return changed


@contextlib.contextmanager
def without_linger(period_s: float = 0.1) -> Iterator[None]:
    """Keep SO_LINGER off on this process's TCP sockets while the block runs."""
    if not FD_DIR.is_dir():
        yield
        return
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(period_s):
            clear_linger()

    thread = threading.Thread(target=loop, name="no-linger", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=1.0)
