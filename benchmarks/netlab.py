"""Hosts in network namespaces, for the multi-host test and benchmark (root only).

Three hosts A, B and C (namespaces ``ob<id>a`` ...) hang off one bridge in a fourth namespace,
addresses 10.213.<n>.1-3/24, a range that exists only inside these namespaces: no traffic
leaves them. Each host runs its own ``onebox router`` on loopback and on its address, connected
to the other two. :meth:`Lab.link` takes a host's link down or up. Everything is removed on
exit, also on failure.

Shared memory is off in config/*.json5, so pictures cross the links as bytes (namespaces
share /dev/shm; with shared memory on they would not travel at all).

:class:`LossyProxy` forwards TCP between two routers with a delay and "loss": TCP never loses
bytes, a lost segment is retransmitted after the retransmission timeout (Linux's least is
200 ms), so loss is emulated as that stall: every chunk read (up to 64 KiB) is sent on
``delay_s`` later, and a random ``loss`` of them ``stall_s`` later still, in order (a chunk
never overtakes the one before it, so everything behind a stall waits, as behind a lost
segment). The proxy buffers without bound: it never pushes back on the router.

Every process writes its output to its own file in a temporary folder, removed on exit unless
``ONEBOX_NETLAB_LOGS`` is set (then its path is printed).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import random
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HOSTS = ("a", "b", "c")
PORT = 7447

PROBE = r"""
import sys, threading, time, zenoh
from onebox import keys
from schemas import codec
decoders = {
    keys.CAMERA.depth: codec(keys.TYPES[keys.CAMERA.depth]),
    keys.DETECTIONS: codec(keys.TYPES[keys.DETECTIONS]),
    keys.GROUND_TRUTH: codec(keys.TYPES[keys.GROUND_TRUTH]),
}
lock = threading.Lock()  # callbacks of different subscribers run on different threads
def on(sample):
    key = str(sample.key_expr)
    stamp = decoders[key].decode(sample.payload.to_bytes()).header.stamp_ns
    with lock:
        sys.stdout.write(f"{key} {time.monotonic():.4f} {stamp}\n")
        sys.stdout.flush()
config = zenoh.Config.from_file("config/client.json5")
config.insert_json5("connect/timeout_ms", "60000")
with zenoh.open(config) as s:
    for key in decoders:
        s.declare_subscriber(key, on)
    print("probe ready", flush=True)
    sys.stdin.read()
"""
"""A subscriber printing ``key monotonic-time stamp_ns`` for each depth picture, detection and
ground truth (one a capture, reliable: what the sim captured)."""

DEPTH, DETECTIONS, TRUTH = "camera/depth/image_raw", "detections", "sim/ground_truth"


def can_run() -> str | None:
    """None when namespaces can be made here, else why not."""
    if os.geteuid() != 0:
        return "needs root for ip netns"
    name = f"ob{os.getpid()}probe"
    result = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True)
    if result.returncode != 0:
        return f"ip netns add failed: {result.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", name], check=False)
    return None


def _ip(*args: str, ns: str | None = None) -> None:
    cmd = ["ip", "netns", "exec", ns, "ip", *args] if ns else ["ip", *args]
    subprocess.run(cmd, check=True, capture_output=True)


class Lab:
    """Three hosts on one bridge; routers started by :meth:`start_routers`."""

    def __init__(self, subnet: int = 1) -> None:
        self.tag = f"ob{os.getpid() % 100000}"
        self.subnet = subnet
        self.switch = f"{self.tag}sw"
        self.procs: list[subprocess.Popen[str]] = []
        # Each process writes to its own file: a pipe nobody reads would, once full, block the
        # process on its next log line (a router or locator stalled by its own logging).
        self.logs = Path(tempfile.mkdtemp(prefix=f"{self.tag}-"))
        self._log_of: dict[int, Path] = {}

    def ns(self, host: str) -> str:
        return f"{self.tag}{host}"

    def address(self, host: str) -> str:
        return f"10.213.{self.subnet}.{HOSTS.index(host) + 1}"

    def __enter__(self) -> Lab:
        try:
            subprocess.run(["ip", "netns", "add", self.switch], check=True, capture_output=True)
            _ip("link", "add", "br0", "type", "bridge", ns=self.switch)
            _ip("link", "set", "br0", "up", ns=self.switch)
            for host in HOSTS:
                ns = self.ns(host)
                subprocess.run(["ip", "netns", "add", ns], check=True, capture_output=True)
                _ip("link", "set", "lo", "up", ns=ns)
                _ip(
                    "link",
                    "add",
                    "eth0",
                    "netns",
                    ns,
                    "type",
                    "veth",
                    "peer",
                    "name",
                    f"p{host}",
                    "netns",
                    self.switch,
                    ns=self.switch,
                )
                _ip("link", "set", f"p{host}", "master", "br0", ns=self.switch)
                _ip("link", "set", f"p{host}", "up", ns=self.switch)
                _ip("addr", "add", f"{self.address(host)}/24", "dev", "eth0", ns=ns)
                _ip("link", "set", "eth0", "up", ns=ns)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.terminate()
        for proc in reversed(self.procs):
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            for pipe in (proc.stdin, proc.stdout):
                if pipe is not None:
                    with contextlib.suppress(OSError):
                        pipe.close()
        for name in (*(self.ns(h) for h in HOSTS), self.switch):
            subprocess.run(["ip", "netns", "del", name], check=False, capture_output=True)
        if os.environ.get("ONEBOX_NETLAB_LOGS"):
            print(f"netlab: the processes' output is kept in {self.logs}", file=sys.stderr)
        else:
            shutil.rmtree(self.logs, ignore_errors=True)

    def run(self, host: str, *argv: str, stdin: bool = False) -> subprocess.Popen[str]:
        """Start ``argv`` inside ``host``'s namespace, its output going to a log file (see
        :meth:`output`); with ``stdin`` its output is a pipe the caller reads instead."""
        log = self.logs / f"{len(self.procs):02d}-{host}-{Path(argv[-1]).name[:24]}.log"
        out = subprocess.PIPE if stdin else log.open("w")
        proc = subprocess.Popen(
            ["ip", "netns", "exec", self.ns(host), *argv],
            cwd=ROOT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
        )
        if not stdin:
            out.close()  # type: ignore[union-attr]  # the child holds its own copy
            self._log_of[proc.pid] = log
        self.procs.append(proc)
        return proc

    def output(self, proc: subprocess.Popen[str], lines: int = 20) -> str:
        """The last ``lines`` of what ``proc`` wrote."""
        log = self._log_of.get(proc.pid)
        if log is None or not log.exists():
            return ""
        return "\n".join(log.read_text(errors="replace").splitlines()[-lines:])

    def wait_listening(self, host: str, port: int, proc: subprocess.Popen[str]) -> None:
        """Block until something in ``host`` listens on TCP ``port``; raise if ``proc`` dies
        first or 60 s pass (a loaded machine starts Python slowly)."""
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            listening = subprocess.run(
                ["ip", "netns", "exec", self.ns(host), "ss", "-Hltn", f"sport = :{port}"],
                capture_output=True,
                text=True,
            ).stdout.strip()
            if listening:
                return
            if proc.poll() is not None:
                raise RuntimeError(
                    f"{proc.args[-1]!r} on {host} exited {proc.returncode}:\n{self.output(proc)}"
                )
            time.sleep(0.1)  # polling the kernel's socket table: there is no event to wait on
        raise RuntimeError(f"nothing listens on port {port} in {host} after 60 s")

    def onebox(self, host: str, *argv: str) -> subprocess.Popen[str]:
        return self.run(host, sys.executable, "-m", "services.cli", *argv)

    def start_routers(
        self, via: dict[tuple[str, str], str] | None = None
    ) -> list[subprocess.Popen[str]]:
        """A router per host on loopback and its address, in a full mesh: each connects to the
        hosts before it (B to A, C to A and B), so no host's traffic to another passes through
        a third. Returns once every router listens.

        ``via[(host, other)]`` is the endpoint ``host`` reaches ``other`` at (a proxy)."""
        via = via or {}
        routers = []
        for index, host in enumerate(HOSTS):
            argv = ["router", "--listen", f"tcp/127.0.0.1:{PORT}"]
            argv += ["--listen", f"tcp/{self.address(host)}:{PORT}"]
            for other in HOSTS[:index]:
                argv += ["--connect", via.get((host, other), f"tcp/{self.address(other)}:{PORT}")]
            routers.append(self.onebox(host, *argv))
        for host, router in zip(HOSTS, routers, strict=True):
            self.wait_listening(host, PORT, router)
        return routers

    def link(self, host: str, up: bool) -> None:
        """Take ``host``'s only link down or bring it up (its bridge port)."""
        _ip("link", "set", f"p{host}", "up" if up else "down", ns=self.switch)

    def probe(self, host: str) -> Probe:
        """A :data:`PROBE` in ``host``; its output is read as it comes."""
        return Probe(self.run(host, sys.executable, "-c", PROBE, stdin=True))


class Probe:
    """Arrival times and stamps of depth pictures, detections and ground truth at one host."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.times: dict[str, list[float]] = {DEPTH: [], DETECTIONS: [], TRUTH: []}
        self.stamps: dict[str, list[tuple[float, int]]] = {DEPTH: [], DETECTIONS: [], TRUTH: []}
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self.ready = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("probe ready"):
                self.ready.set()
                continue
            parts = line.split()
            if len(parts) == 3 and parts[0] in self.times:
                with self._cond:
                    self.times[parts[0]].append(float(parts[1]))
                    self.stamps[parts[0]].append((float(parts[1]), int(parts[2])))
                    self._cond.notify_all()
            else:
                self.lines = [*self.lines[-19:], line.rstrip()]
        with self._cond:
            self._cond.notify_all()

    def wait_ready(self, timeout_s: float) -> None:
        """Block until the probe subscribes; raise with its output if it dies or is slow."""
        deadline = time.monotonic() + timeout_s
        while not self.ready.wait(0.2):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(
                    f"the probe did not start (exit {self.proc.poll()}):\n" + "\n".join(self.lines)
                )

    def wait_for(self, key: str, after: float, timeout_s: float) -> float | None:
        """The first arrival on ``key`` after monotonic ``after``, waiting up to ``timeout_s``."""

        def first() -> float | None:
            return next((t for t in self.times[key] if t > after), None)

        with self._cond:
            self._cond.wait_for(lambda: first() is not None, timeout=timeout_s)
            return first()

    def max_gap(self, key: str, start: float, end: float) -> tuple[float, float]:
        """The longest time without ``key`` between ``start`` and ``end``, and when it began
        (seconds after ``start``)."""
        with self._cond:
            times = [start, *(t for t in self.times[key] if start < t < end), end]
        gap, at = max((b - a, a) for a, b in itertools.pairwise(times))
        return gap, at - start

    def count(self, key: str, start: float, end: float) -> int:
        with self._cond:
            return sum(1 for t in self.times[key] if start < t < end)

    def detected(self, start: float, end: float, settle_s: float) -> tuple[int, int]:
        """(captures, captures with a detection): the captures are the stamps of the ground
        truth that arrived between ``start`` and ``end``; a detection counts when its stamp is
        one of them and it arrives within ``settle_s`` after ``end``."""
        with self._cond:
            captures = {s for t, s in self.stamps[TRUTH] if start < t < end}
            found = {s for t, s in self.stamps[DETECTIONS] if start < t < end + settle_s}
        return len(captures), len(captures & found)

    def latencies(self, start: float, end: float) -> list[float]:
        """Seconds from each capture's ground truth at C to its detection at C."""
        with self._cond:
            truth = {s: t for t, s in self.stamps[TRUTH] if start < t < end}
            return sorted(t - truth[s] for t, s in self.stamps[DETECTIONS] if s in truth)


class LossyProxy:
    """TCP forwarder adding ``delay_s`` each way and a ``stall_s`` stall to ``loss`` of chunks."""

    def __init__(
        self,
        listen: tuple[str, int],
        target: tuple[str, int],
        delay_s: float,
        loss: float,
        stall_s: float = 0.2,
        seed: int = 1,
    ) -> None:
        self.listen, self.target = listen, target
        self.delay_s, self.loss, self.stall_s = delay_s, loss, stall_s
        self.random = random.Random(seed)

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        queue: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()
        last = 0.0

        async def send() -> None:
            while True:
                due, data = await queue.get()
                if not data:
                    break
                await asyncio.sleep(max(0.0, due - time.monotonic()))
                writer.write(data)
                await writer.drain()
            writer.close()

        sender = asyncio.create_task(send())
        while data := await reader.read(65536):
            extra = self.stall_s if self.random.random() < self.loss else 0.0
            last = max(last, time.monotonic() + self.delay_s + extra)  # in order, as TCP is
            await queue.put((last, data))
        await queue.put((0.0, b""))
        await sender

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with contextlib.suppress(OSError):
            up_reader, up_writer = await asyncio.open_connection(*self.target)
            await asyncio.gather(
                self._pipe(reader, up_writer), self._pipe(up_reader, writer), return_exceptions=True
            )

    async def serve(self) -> None:
        server = await asyncio.start_server(self._client, *self.listen)
        async with server:
            await server.serve_forever()


@contextlib.contextmanager
def lossy_proxy_process(
    lab: Lab, host: str, listen_port: int, delay_s: float, loss: float
) -> Iterator[str]:
    """A :class:`LossyProxy` in ``host``'s namespace in front of its router; yields its endpoint."""
    code = (
        "import asyncio, sys; sys.path.insert(0, 'benchmarks'); import netlab; "
        f"asyncio.run(netlab.LossyProxy(('{lab.address(host)}', {listen_port}), "
        f"('127.0.0.1', {PORT}), {delay_s}, {loss}).serve())"
    )
    proc = lab.run(host, sys.executable, "-c", code)
    try:
        lab.wait_listening(host, listen_port, proc)
        yield f"tcp/{lab.address(host)}:{listen_port}"
    finally:
        proc.terminate()


@contextlib.contextmanager
def pipeline(
    lab: Lab, via: dict[tuple[str, str], str] | None = None, sim_args: tuple[str, ...] = ()
) -> Iterator[Probe]:
    """Routers on every host, the sim on A, the locator on B, a probe on C; yields the probe
    once C receives detections (so the whole path works)."""
    lab.start_routers(via)
    probe = lab.probe("c")
    probe.wait_ready(60)
    locator = lab.onebox("b", "locator")
    sim = lab.onebox("a", "sim", *sim_args)
    if probe.wait_for(DETECTIONS, 0.0, 90) is None:
        raise RuntimeError(
            "no detection reached C from B within 90 s\nsim:\n"
            f"{lab.output(sim)}\nlocator:\n{lab.output(locator)}"
        )
    yield probe


def outage(
    lab: Lab, probe: Probe, host: str = "b", down_s: float = 15.0, recover_timeout_s: float = 60.0
) -> tuple[float | None, float, float]:
    """Take ``host``'s link down ``down_s``, bring it back; returns (seconds from the link's
    return to the first detection at C, or None; the longest A -> C depth gap from the link's
    going down to 3 s after its return; when that gap began, seconds after the link went
    down)."""
    lab.link(host, up=False)
    down_at = time.monotonic()
    time.sleep(down_s)  # the outage itself is what is measured: its length is the experiment
    lab.link(host, up=True)
    up_at = time.monotonic()
    first = probe.wait_for(DETECTIONS, up_at, recover_timeout_s)
    # The routers' reconnection after the return is part of the outage too.
    probe.wait_for(DEPTH, up_at + 3.0, 10.0)
    gap, at = probe.max_gap(DEPTH, down_at, max(time.monotonic(), up_at + 3.0))
    return (None if first is None else first - up_at), gap, at
