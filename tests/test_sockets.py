"""A router's links close without lingering: SO_LINGER cleared on every TCP socket it holds."""

from __future__ import annotations

import socket
import struct

import pytest

from onebox import sockets

LINGER = struct.Struct("ii")


def linger(sock: socket.socket) -> tuple[int, int]:
    return LINGER.unpack(sock.getsockopt(socket.SOL_SOCKET, socket.SO_LINGER, LINGER.size))


@pytest.mark.skipif(not sockets.FD_DIR.is_dir(), reason="needs /proc/self/fd (Linux)")
def test_clear_linger_turns_it_off_on_tcp_sockets_and_leaves_them_open():
    """A TCP socket lingering 10 s, as Zenoh's links do, lingers no more and still works."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        client = socket.create_connection(server.getsockname())
        accepted, _ = server.accept()
        with client, accepted:
            client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, LINGER.pack(1, 10))
            assert linger(client) == (1, 10)
            assert sockets.clear_linger() >= 1
            assert linger(client)[0] == 0
            client.sendall(b"still open")
            assert accepted.recv(16) == b"still open"
            assert sockets.clear_linger() == 0
