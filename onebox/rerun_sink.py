"""Where a Rerun recording goes: a .rrd file, the native viewer, or the loopback web viewer.

The SDK's own ``serve_web_viewer()`` binds every interface; the ``rerun`` executable that
rerun-sdk ships can bind loopback only, so the web viewer runs as a child process of ours. The
child runs in its own session, so a Ctrl-C or honcho's SIGTERM to our process group reaches us
first: we flush and disconnect, then stop it, and no "transport error" is printed. A port left
at 0 means "the usual port (9876, 9090) if free, else any free one", so two pipelines with
viewers run side by side.

The page itself is served by us, in front of the child's own (which listens on a loopback port
of its own): Rerun's page keeps every message it is sent until it holds 2.3 GiB, and takes a
memory limit only from the page that starts it, so ours is the child's page with that limit
written in (:data:`Sink.page_memory_limit`). Everything else is passed through unchanged.

A saved .rrd is written to a hidden file beside it and renamed when complete: a failure leaves
nothing behind, and an existing file is replaced only when asked to.
"""

from __future__ import annotations

import argparse
import contextlib
import http.server
import importlib.util
import json
import logging
import os
import re
import shutil
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request
import urllib.response
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import rerun as rr

from onebox import rerun_scene
from onebox.errors import OneboxError

log = logging.getLogger("viewer")

APPLICATION_ID = "onebox"
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090


class ViewerError(OneboxError):
    """The Rerun viewer could not be started or reached."""


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def rerun_executable() -> str:
    """The ``rerun`` binary the rerun-sdk wheel ships (RERUN_CLI_PATH overrides it)."""
    override = os.environ.get("RERUN_CLI_PATH")
    if override:
        return override
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin is not None:
        bundled = Path(spec.origin).parent / "rerun"
        if bundled.exists():
            return str(bundled)
    found = shutil.which("rerun")
    if found is None:
        raise ViewerError("no `rerun` executable: reinstall rerun-sdk (pip install rerun-sdk)")
    return found


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        # As the server will: a port whose last connections linger in TIME_WAIT is free.
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def choose_port(port: int, usual: int, flag: str) -> int:
    """``port`` if set (it must be free); for 0, ``usual`` if free, else any free port."""
    if port:
        if not _port_free(port):
            raise ViewerError(
                f"port {port} on 127.0.0.1 is taken (another viewer?): choose another with "
                f"{flag}, or 0 for any free port"
            )
        return port
    return usual if _port_free(usual) else any_free_port()


def any_free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


SETTLE_S = 1.0
"""How long a freshly started web server must stay up before its ports are taken as its own."""


class PortTaken(OneboxError):
    """The web server's port was taken by someone else as it started."""


def _wait_for_port(port: int, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
            return
        if proc.poll() is not None:
            raise ViewerError(f"the Rerun web server exited with code {proc.returncode}")
        if time.monotonic() > deadline:
            raise ViewerError(f"the Rerun web server did not listen on 127.0.0.1:{port}")
        time.sleep(0.05)  # polling a port that has no event to wait on


PAGE_OPTIONS = "const options = {"
"""Where Rerun's page (index.html) gathers the options it starts the viewer with."""
MEMORY_LIMIT = re.compile(r"\d+(\.\d+)?\s*([kMGT]i?B|B)?|\d+(\.\d+)?%", re.IGNORECASE)
"""A size as Rerun reads one: ``200MiB``, ``1.5GB``, ``25%`` (of the machine's memory)."""


def check_memory_limit(text: str, flag: str) -> str:
    """``text`` if Rerun reads it as a size (empty: no limit of ours), else a clear error."""
    if text and not MEMORY_LIMIT.fullmatch(text.strip()):
        raise ViewerError(f"{flag} {text!r} is no size: write it as 200MiB, 1GB or 25%")
    return text.strip()


def page_with_memory_limit(page: bytes, memory_limit: str) -> bytes | None:
    """Rerun's index.html, starting the viewer with ``memory_limit``; None when the page has
    no place for it (a Rerun whose page changed)."""
    marker = PAGE_OPTIONS.encode()
    if marker not in page:
        return None
    option = f"{PAGE_OPTIONS} memory_limit: {json.dumps(memory_limit)},".encode()
    return page.replace(marker, option, 1)


class _PageHandler(http.server.BaseHTTPRequestHandler):
    """GET: the child's page with the memory limit written in; anything else passed through."""

    upstream_port = 0
    memory_limit = ""

    def do_GET(self) -> None:
        try:
            upstream = urllib.request.urlopen(
                f"http://127.0.0.1:{self.upstream_port}{self.path}", timeout=30
            )
        except urllib.error.HTTPError as e:
            upstream = e
        except OSError as e:
            self.send_error(502, f"the Rerun web server did not answer: {e}")
            return
        with upstream:
            route = self.path.split("?", 1)[0]
            if route in ("/", "/index.html") and self.memory_limit and upstream.status == 200:
                body = upstream.read()
                patched = page_with_memory_limit(body, self.memory_limit)
                self._send(upstream, patched or body)
                return
            self._send(upstream, None)

    def _send(
        self, upstream: urllib.response.addinfourl | urllib.error.HTTPError, body: bytes | None
    ) -> None:
        self.send_response(upstream.status or 502)
        for name in ("Content-Type", "Content-Encoding", "rerun-final-length", "Cache-Control"):
            value = upstream.headers.get(name)
            if value:
                self.send_header(name, value)
        if body is not None:
            self.send_header("Content-Length", str(len(body)))
        self.end_headers()  # HTTP/1.0: without a length, the body ends when the connection closes
        if body is not None:
            self.wfile.write(body)
        else:
            shutil.copyfileobj(upstream, self.wfile, 256 * 1024)

    def log_message(self, format: str, *args: object) -> None:
        log.debug("page: " + format, *args)


class _PageServer(http.server.ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request: object, client_address: object) -> None:
        # A browser that goes away mid-download (a reload) is no error of ours.
        log.debug("page: a request from %s ended early", client_address, exc_info=True)


@contextlib.contextmanager
def page_server(web_port: int, upstream_port: int, memory_limit: str) -> Iterator[None]:
    """The web viewer's page on 127.0.0.1:``web_port``, in front of the child's on
    ``upstream_port``. A port that cannot be bound raises :class:`PortTaken`."""
    handler = type(
        "PageHandler",
        (_PageHandler,),
        {"upstream_port": upstream_port, "memory_limit": memory_limit},
    )
    if memory_limit:
        with urllib.request.urlopen(f"http://127.0.0.1:{upstream_port}/", timeout=30) as page:
            if page_with_memory_limit(page.read(), memory_limit) is None:
                log.warning(
                    "Rerun's page has no %r: the page's memory is not limited", PAGE_OPTIONS
                )
    try:
        server = _PageServer(("127.0.0.1", web_port), handler)
    except OSError as e:
        raise PortTaken(f"the web viewer's page could not listen on {web_port}: {e}") from e
    thread = threading.Thread(target=server.serve_forever, name="page", daemon=True)
    thread.start()
    try:
        yield
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


@contextlib.contextmanager
def web_server(
    grpc_port: int, web_port: int, memory_limit: str, page_memory_limit: str = ""
) -> Iterator[str]:
    """A loopback-only ``rerun --serve-web`` child behind our page on ``web_port``; yields the
    gRPC address to log to."""
    # The child's own page, on a port of its own: ours, in front of it, sets the memory limit.
    child_web_port = any_free_port()
    # The SDK's own serve_web_viewer() binds every interface; the CLI can bind loopback only.
    cmd = [
        rerun_executable(),
        "--serve-web",
        "--bind",
        "127.0.0.1",
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(child_web_port),
        "--server-memory-limit",
        memory_limit,
        # A page that joins late is sent the newest data first, then what the limit kept.
        "--newest-first",
    ]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        # Another viewer starting at the same moment may have taken a port between our check
        # and the server's bind: then the port answers, but not for our server, which exits
        # at once (while we wait for its other port, or just after). Give it that moment
        # before trusting the ports.
        try:
            _wait_for_port(grpc_port, proc, timeout_s=20.0)
            _wait_for_port(child_web_port, proc, timeout_s=20.0)
            proc.wait(timeout=SETTLE_S)
        except subprocess.TimeoutExpired:
            pass
        except ViewerError:
            if proc.poll() is None:
                raise
        if proc.poll() is not None:
            raise PortTaken(
                f"the Rerun web server could not listen on {grpc_port} or {child_web_port} "
                f"(exit code {proc.returncode})"
            )
        with page_server(web_port, child_web_port, page_memory_limit):
            yield f"rerun+http://127.0.0.1:{grpc_port}/proxy"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@contextlib.contextmanager
def serve_web(sink: Sink, attempts: int = 3) -> Iterator[tuple[str, int, int]]:
    """The web server on the sink's ports; a port left to choose (0) that another viewer took
    at the same moment is chosen again. Yields the gRPC address and both ports."""
    for attempt in range(attempts):
        grpc_port = choose_port(sink.grpc_port, DEFAULT_GRPC_PORT, "--grpc-port")
        web_port = choose_port(sink.web_port, DEFAULT_WEB_PORT, "--web-port")
        if attempt:  # the usual ports lost a race once: take any free ones now
            grpc_port = sink.grpc_port or any_free_port()
            web_port = sink.web_port or any_free_port()
        try:
            with web_server(grpc_port, web_port, sink.memory_limit, sink.page_memory_limit) as url:
                yield url, grpc_port, web_port
                return
        except PortTaken:
            if (sink.grpc_port and sink.web_port) or attempt == attempts - 1:
                raise
            log.info(
                "port %d or %d was taken as the web server started; trying others",
                grpc_port,
                web_port,
            )


def web_address(grpc_port: int, web_port: int) -> str:
    """The page to open: the web viewer, told where the data is."""
    return f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"


@dataclass(frozen=True)
class Sink:
    """Where a recording goes: a .rrd file, the native viewer, or the loopback web viewer."""

    save: Path | None = None
    """Write a .rrd file here instead of showing anything."""
    web: bool = False
    """Serve the web viewer even when a display is there."""
    camera: str = "camera"
    grpc_port: int = 0
    """0: 9876 if free, else any free port."""
    web_port: int = 0
    """0: 9090 if free, else any free port."""
    memory_limit: str = "256KiB"
    """What the web server keeps (compressed) for pages that join late, sent to them newest
    first; static data is dropped only when it alone is over the limit."""
    page_memory_limit: str = ""
    """The web page's viewer drops its oldest data once its memory (Rerun's own count of its
    heap) passes this, the newest of each kind always kept; empty: Rerun's 2.3 GiB."""
    overwrite: bool = False
    """Replace an existing --save file."""

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> Sink:
        """The sink the viewer's and view's shared flags describe (view has no page limit:
        a recording is shown whole)."""
        page_memory_limit = check_memory_limit(
            getattr(args, "page_memory_limit", ""), "--page-memory-limit"
        )
        return cls(
            page_memory_limit=page_memory_limit,
            save=args.save,
            web=args.web,
            camera=args.camera,
            grpc_port=args.grpc_port,
            web_port=args.web_port,
            memory_limit=args.memory_limit,
            overwrite=args.overwrite,
        )


def _partial(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.partial")


@contextlib.contextmanager
def open_recording(sink: Sink) -> Iterator[rr.RecordingStream]:
    """A recording sent where ``sink`` says; a saved file is complete when the block ends."""
    if sink.save is not None and sink.save.exists() and not sink.overwrite:
        raise ViewerError(
            f"{sink.save} already exists: delete it, choose another name, or pass --overwrite"
        )
    rec = rr.RecordingStream(APPLICATION_ID)
    blueprint = rerun_scene.blueprint(sink.camera)
    partial = _partial(sink.save) if sink.save is not None else None
    with contextlib.ExitStack() as stack:
        if partial is not None:
            partial.parent.mkdir(parents=True, exist_ok=True)
            rec.save(partial, default_blueprint=blueprint)
            print(f"viewer: writing {sink.save}", flush=True)
        elif has_display() and not sink.web:
            port = choose_port(sink.grpc_port, DEFAULT_GRPC_PORT, "--grpc-port")
            rec.spawn(port=port, default_blueprint=blueprint)
            print("viewer: opened the Rerun viewer", flush=True)
        else:
            url, grpc_port, web_port = stack.enter_context(serve_web(sink))
            rec.connect_grpc(url, default_blueprint=blueprint)
            print(f"viewer: no display; open {web_address(grpc_port, web_port)}", flush=True)
        try:
            # Leaving `with rec` flushes and finalizes the .rrd (writes its footer).
            with rec:
                yield rec
        except BaseException:
            if partial is not None:
                rec.disconnect()
                with contextlib.suppress(FileNotFoundError):
                    partial.unlink()
            raise
        finally:
            # Send what is left while the web server (our child) is still up, then let go of it.
            with contextlib.suppress(RuntimeError):
                rec.flush(timeout_sec=5.0)
            rec.disconnect()
    if partial is not None and sink.save is not None:
        os.replace(partial, sink.save)
