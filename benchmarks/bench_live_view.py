"""How the live web viewer keeps up in a real, software-rendered browser.

Runs a private pipeline (router, sim, locator, viewer with the web viewer, all on free ports)
from --repo, waits --late-s seconds, then opens the viewer's page in headless Chromium
(SwiftShader, no GPU) driven by playwright-core and watches it for --watch-s seconds.

What the page shows is read from the web viewer itself, through its Viewer Control API: the
page's ``window._handle.viewer_state()`` is the encoded ``GetStateResponse`` of Rerun's
``viewer_control.proto`` (the message ``rerun.experimental.ViewerClient.get_state()`` returns in
Python). It is decoded field by field, not guessed from numbers in it: the active recording's
time cursor (``current_time``: the timeline's name and the time on it) is the time every view
draws its latest-at query for, so it is the simulated time the page shows. The cursor moves
only when the viewer has taken in data in its frame loop, so a page that cannot keep up shows
an old cursor. The views' reports (what a view failed to draw, e.g. "2D visualizers require a
pinhole ancestor") and the sources still loading come from the same message.

Lag: while the page is watched, this process subscribes to the colour pictures on the bus and
notes the wall-clock time each capture's stamp was published. Once a second:

  - behind (wall): now minus the time the capture the cursor is on was published: how old the
    picture on screen is, as a person at the robot would see it;
  - behind (sim): the newest stamp on the bus minus the cursor, in simulated seconds;
  - the page's frames a second (its requestAnimationFrame callbacks, counted in the page): the
    picture on screen is at most one frame older than the cursor.

"The whole scene" is judged on screenshots (CDP Page.captureScreenshot, every --shot-every-s
seconds and at the end, in --shots): the cursor is on sim_time, no view reports a problem,
nothing is loading, and the colour and depth panels of the layout (the right-hand third) show
a picture: at least half of each panel's pixels are not the viewer's white background (a
loading spinner on white does not count). The 3D view (frustum, table, boxes) is drawn
from static data plus the newest boxes: look at the screenshots.

Memory: the JS heap in use (CDP Performance.getMetrics), the viewer's wasm memory (it only
grows, so it is the high-water mark of the viewer's heap), and the resident memory of the
browser: of all its processes, and of its renderers (the page) alone, from /proc, counting
only the processes this run started. The page's console says when the viewer dropped old data
to stay within its memory limit ("GC result"), and when its wasm was loaded and the app
started: the page's own start-up, before any data.

  .venv/bin/python benchmarks/bench_live_view.py                          # after, 60 s late
  .venv/bin/python benchmarks/bench_live_view.py --late-s 0 --watch-s 60  # at start
  git worktree add /tmp/before_view ffa7902^
  .venv/bin/python benchmarks/bench_live_view.py --repo /tmp/before_view  # the code before

Needs /usr/bin/chromium (apt-get install -y chromium) and playwright-core from npm in
--node-modules (npm install playwright-core in that folder's parent).
"""

# The page script and the report lines read best unwrapped.
# ruff: noqa: E501

from __future__ import annotations

import argparse
import bisect
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from PIL import Image as PILImage

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox import bus
from onebox.testing.processes import bus_args, free_port, private_router
from schemas import Image

PAGE_SCRIPT = r"""
const { chromium } = require('playwright-core');
const fs = require('fs');
const [url, watchS, shots, shotEveryS, profile, firstShotS] = process.argv.slice(2);

// Protobuf, schema-less: a list of [field number, value]; a length-delimited value is kept
// both as bytes (for strings) and, when it parses, as a nested list.
function varint(b, p) {
  let v = 0n, s = 0n, x;
  do { if (p.i >= b.length) throw new Error('eof'); x = b[p.i++]; v |= BigInt(x & 0x7f) << s; s += 7n; } while (x & 0x80);
  return v;
}
function parse(b) {
  const p = { i: 0 }, out = [];
  while (p.i < b.length) {
    const key = varint(b, p), f = Number(key >> 3n), w = Number(key & 7n);
    if (f === 0) throw new Error('field 0');
    if (w === 0) out.push([f, varint(b, p)]);
    else if (w === 2) { const n = Number(varint(b, p)); if (p.i + n > b.length) throw new Error('length'); out.push([f, b.subarray(p.i, p.i + n)]); p.i += n; }
    else if (w === 1) p.i += 8; else if (w === 5) p.i += 4; else throw new Error('wire type ' + w);
  }
  return out;
}
const all = (msg, f) => msg.filter(x => x[0] === f).map(x => x[1]);
const one = (msg, f) => all(msg, f)[0];
const text = (bytes) => bytes === undefined ? null : Buffer.from(bytes).toString('utf8');
const sub = (bytes) => bytes === undefined ? [] : parse(bytes);

// Field numbers of rerun.viewer_control.v1alpha1 as Rerun 0.41 encodes them (checked against
// the names rerun.experimental.ViewerClient.get_state() gives them):
// GetStateResponse: 2 active_store_id, 3 recordings, 5 views, 6 viewer_version, 7 loading.
// ViewerRecording: 1 store_id, 3 current_time (TimeCursor: 1 timeline {1 name}, 3 time {1 value}), 5 play_state.
// View: 3 name, 4 origin, 5 visible, 6 reports (1 severity, 2 summary).
function viewerState(bytes) {
  const state = parse(bytes);
  const active = text(one(state, 2));
  const out = { active, timeline: null, time_ns: null, play_state: null, views: [], loading: [] };
  for (const r of all(state, 3).map(sub)) {
    if (text(one(r, 1)) !== active) continue;
    const cursor = sub(one(r, 3));
    out.timeline = text(one(sub(one(cursor, 1)), 1));
    const t = one(sub(one(cursor, 3)), 1);
    out.time_ns = t === undefined ? null : String(t);
    out.play_state = one(r, 5) === undefined ? null : Number(one(r, 5));
  }
  for (const v of all(state, 5).map(sub)) {
    const reports = all(v, 6).map(sub).map(rep => text(one(rep, 2)) || '(report)');
    out.views.push({ name: text(one(v, 3)), reports });
  }
  for (const l of all(state, 7).map(sub)) out.loading.push(text(one(l, 1)) || '?');
  return out;
}

// A page too busy to answer within 5 s is recorded as not answering, and the watch goes on.
const within = (promise, ms) => Promise.race([promise, new Promise((_, no) => setTimeout(() => no(new Error(`no answer in ${ms / 1000} s`)), ms))]);

(async () => {
  const browser = await chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium',
    viewport: { width: 1280, height: 720 },
    args: ['--headless', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
           '--disable-gpu-sandbox', '--disable-background-networking', '--disable-component-update',
           '--disable-sync', '--no-first-run'],
  });
  const page = browser.pages()[0] || await browser.newPage();
  const t0 = Date.now();
  // Count the page's frames: every requestAnimationFrame callback that runs.
  await page.addInitScript(() => {
    // The viewer's wasm memory: it only grows, so it is the high-water mark of the viewer's heap.
    const instantiate = WebAssembly.instantiate;
    WebAssembly.instantiate = async (...a) => {
      const r = await instantiate(...a);
      window.__wasmMemory = (r.instance || r).exports.memory;
      return r;
    };
    window.__frames = 0;
    const raf = window.requestAnimationFrame.bind(window);
    window.requestAnimationFrame = (cb) => raf((t) => { window.__frames += 1; cb(t); });
  });
  // The page's own start-up, from its console: the wasm fetched and compiled, the app started.
  page.on('console', (m) => {
    const text = m.text();
    if (/loading wasm|Wasm loaded|App started|memory limit|GC result/.test(text)) console.log(JSON.stringify({ event: 'console', t: (Date.now() - t0) / 1000, text }));
  });
  if (process.env.PAGE_MEMORY_LIMIT) {
    await page.route(/\/(index\.html)?(\?.*)?$/, async (route) => {
      const r = await route.fetch();
      const body = (await r.text()).replace('const options = {', `const options = { memory_limit: ${JSON.stringify(process.env.PAGE_MEMORY_LIMIT)},`);
      await route.fulfill({ response: r, body });
    });
  }
  const cdp = await browser.newCDPSession(page);
  await cdp.send('Performance.enable');
  console.log(JSON.stringify({ event: 'open', wall: Date.now() / 1000 }));
  try { await page.goto(url, { timeout: 60000 }); } catch (e) { console.log(JSON.stringify({ event: 'goto', error: String(e).slice(0, 200) })); }
  const end = t0 + Number(watchS) * 1000;
  let lastFrames = 0, lastT = Date.now(), nextShot = t0 + Number(firstShotS) * 1000, n = 0;
  for (;;) {
    const now = Date.now();
    const row = { t: (now - t0) / 1000, wall: now / 1000 };
    try {
      const raw = await within(page.evaluate(() => window._handle ? Array.from(window._handle.viewer_state()) : null), 5000);
      row.state = raw ? viewerState(Uint8Array.from(raw)) : null;
      row.wall = Date.now() / 1000;  // when the state was read
      const [frames, wasm] = await within(page.evaluate(() => [window.__frames, window.__wasmMemory ? window.__wasmMemory.buffer.byteLength : null]), 5000);
      row.wasm = wasm;
      row.fps = (frames - lastFrames) / Math.max((Date.now() - lastT) / 1000, 1e-3);
      lastFrames = frames; lastT = Date.now();
    } catch (e) { row.error = String(e).slice(0, 200); }
    try {
      const m = await within(cdp.send('Performance.getMetrics'), 5000);
      row.heap = (m.metrics.find(x => x.name === 'JSHeapUsedSize') || {}).value;
    } catch (e) {}
    const last = now >= end;
    if (last || now >= nextShot) {
      nextShot = now + Number(shotEveryS) * 1000;
      try {
        const s = await within(cdp.send('Page.captureScreenshot', { format: 'png' }), 30000);
        row.shot_done = (Date.now() - t0) / 1000;  // the picture is from between t and this
        row.shot = `${shots}/page_${String(n++).padStart(3, '0')}_${row.t.toFixed(0)}s.png`;
        fs.writeFileSync(row.shot, Buffer.from(s.data, 'base64'));
      } catch (e) { row.shot_error = String(e).slice(0, 200); }
    }
    console.log(JSON.stringify(row));
    if (last) break;
    await new Promise(r => setTimeout(r, Math.max(0, 1000 - (Date.now() - now))));
  }
  // The last row's memory is read from /proc when it is printed: not while the browser closes.
  await new Promise(r => setTimeout(r, 2000));
  await within(browser.close(), 10000).catch(() => {});
  process.exit(0);
})();
"""

FOLLOWING = 3
"""PlayState's "following the newest data" in viewer_control.proto."""
PANELS = {"colour": (0.68, 0.10, 0.99, 0.49), "depth": (0.68, 0.56, 0.99, 0.95)}
"""Where the seed's layout puts the pictures, as fractions of the page (left, top, right,
bottom): the right-hand third, colour above depth."""


def panel_filled(shot: Path, box: tuple[float, float, float, float]) -> float:
    """The share of a panel's pixels that are not the viewer's white background."""
    rgb = np.asarray(PILImage.open(shot).convert("RGB"), dtype=np.int16)
    h, w, _ = rgb.shape
    part = rgb[int(box[1] * h) : int(box[3] * h), int(box[0] * w) : int(box[2] * w)].reshape(-1, 3)
    return float(np.mean(part.min(axis=1) < 235))


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (the browser this run started, not anyone else's)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def browser_rss_mb(root: int) -> tuple[float, float]:
    """Resident memory of the browser under ``root``: all its processes, and its renderers."""
    total = renderer = 0
    for pid in descendants(root):
        try:
            status = Path(f"/proc/{pid}/status").read_text()
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if b"chrom" not in cmdline.split(b"\0", 1)[0]:
            continue
        match = re.search(r"^VmRSS:\s+(\d+) kB", status, re.M)
        kb = int(match.group(1)) if match else 0
        total += kb
        if b"--type=renderer" in cmdline:
            renderer += kb
    return total / 1024, renderer / 1024


class Published:
    """The wall-clock time each colour capture's stamp was seen on the bus."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.stamps_ns: list[int] = []
        self.walls: list[float] = []

    def __call__(self, key: str, message: Image) -> None:
        with self._lock:
            if not self.stamps_ns or message.header.stamp_ns > self.stamps_ns[-1]:
                self.stamps_ns.append(message.header.stamp_ns)
                self.walls.append(time.time())

    def newest_ns(self) -> int | None:
        with self._lock:
            return self.stamps_ns[-1] if self.stamps_ns else None

    def wall_of(self, stamp_ns: int) -> float | None:
        """When the newest capture at or before ``stamp_ns`` was published."""
        with self._lock:
            i = bisect.bisect_right(self.stamps_ns, stamp_ns) - 1
            return self.walls[i] if i >= 0 else None


def port_open(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.5):
            return True
    except OSError:
        return False


def load_average() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def median(values: list[float]) -> float:
    return float(np.median(values)) if values else float("nan")


def missing_browser(node_modules: Path) -> str | None:
    """What the browser's side lacks, in one line (with how to get it), or None."""
    if shutil.which("node") is None:
        return "no node on PATH (apt-get install -y nodejs)"
    if not Path("/usr/bin/chromium").exists():
        return "no /usr/bin/chromium (apt-get install -y chromium)"
    if not (node_modules / "playwright-core").is_dir():
        return (
            f"no playwright-core in {node_modules} "
            f"(npm install playwright-core in {node_modules.parent}, or --node-modules DIR)"
        )
    return None


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--late-s", type=float, default=60.0, help="open the page this late")
    parser.add_argument("--watch-s", type=float, default=60.0, help="watch the page this long")
    parser.add_argument("--repo", type=Path, default=Path(__file__).resolve().parent.parent)
    parser.add_argument("--node-modules", type=Path, default=Path("/tmp/pw/node_modules"))
    parser.add_argument("--shots", type=Path, default=Path("/tmp/live_view"))
    parser.add_argument("--shot-every-s", type=float, default=5.0)
    parser.add_argument(
        "--first-shot-s", type=float, default=10.0, help="the first screenshot (the goal's 10 s)"
    )
    parser.add_argument("--label", default="", help="a name for this run in the summary")
    args = parser.parse_args()
    missing = missing_browser(args.node_modules)
    if missing is not None:
        raise SystemExit(f"bench_live_view: {missing}")
    args.shots.mkdir(parents=True, exist_ok=True)
    for old in args.shots.glob("page_*.png"):
        old.unlink()

    published = Published()
    rows: list[dict[str, object]] = []
    gcs: list[float] = []
    """When the page dropped old data to stay within its memory limit."""
    loads = [load_average()]
    with private_router() as endpoint, bus.open_bus(bus_args(endpoint)) as b:
        b.subscribe("camera/image_raw", Image, published)
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "DISPLAY": "", "WAYLAND_DISPLAY": ""}
        env["PYTHONPATH"] = str(args.repo)
        grpc_port, web_port = free_port(), free_port()
        procs = []
        try:
            for cmd in (
                ["sim"],
                ["locator"],
                ["viewer", "--web", "--grpc-port", str(grpc_port), "--web-port", str(web_port)],
            ):
                procs.append(
                    subprocess.Popen(
                        [sys.executable, "-m", "services.cli", *cmd, "--connect", endpoint],
                        cwd=args.repo,
                        env=env,
                        stdout=subprocess.DEVNULL,
                        stderr=subprocess.DEVNULL,
                    )
                )
            started = time.monotonic()
            while time.monotonic() - started < args.late_s:
                time.sleep(1.0)  # the page is opened late on purpose
            deadline = time.monotonic() + 60.0
            while not port_open(web_port):  # the viewer's web server may still be starting
                if time.monotonic() > deadline:
                    raise SystemExit(f"the viewer served nothing on 127.0.0.1:{web_port}")
                time.sleep(0.2)
            url = f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"
            at_open = published.newest_ns() or 0
            print(
                f"pipeline from {args.repo} up {args.late_s:.0f} s, sim at {at_open / 1e9:.1f} s; opening {url}",
                flush=True,
            )
            with tempfile.TemporaryDirectory() as profile:
                script = Path(profile) / "page.js"
                script.write_text(PAGE_SCRIPT)
                node_env = {**os.environ, "NODE_PATH": str(args.node_modules)}
                page = subprocess.Popen(
                    [
                        "node",
                        str(script),
                        url,
                        str(args.watch_s),
                        str(args.shots),
                        str(args.shot_every_s),
                        str(Path(profile) / "profile"),
                        str(args.first_shot_s),
                    ],
                    stdout=subprocess.PIPE,
                    env=node_env,
                    text=True,
                )
                assert page.stdout is not None
                for line in page.stdout:
                    sample = json.loads(line)
                    if sample.get("event") == "console":
                        text = sample["text"].strip()
                        if "GC result" in text:
                            gcs.append(float(sample["t"]))
                        print(f"t {sample['t']:6.1f} s  page: {text[:160]}", flush=True)
                        continue
                    if "t" not in sample:
                        continue
                    rows.append(sample)
                    state = sample.get("state") or {}
                    newest = published.newest_ns()
                    shown = (
                        int(state["time_ns"])
                        if state.get("time_ns") and state.get("timeline") == "sim_time"
                        else None
                    )
                    shown_wall = published.wall_of(shown) if shown is not None else None
                    sample["behind_wall_s"] = (
                        sample["wall"] - shown_wall if shown_wall is not None else None
                    )
                    sample["behind_sim_s"] = (
                        (newest - shown) / 1e9 if shown is not None and newest else None
                    )
                    sample["rss"], sample["renderer"] = browser_rss_mb(page.pid)
                    reports = [
                        f"{v['name']}: {r}" for v in state.get("views", []) for r in v["reports"]
                    ]
                    sample["problems"] = reports + [
                        f"loading {x}" for x in state.get("loading", [])
                    ]
                    if sample.get("shot"):
                        fills = {
                            name: panel_filled(Path(sample["shot"]), box)
                            for name, box in PANELS.items()
                        }
                        sample["fills"] = fills
                        sample["whole"] = bool(
                            shown is not None
                            and not sample["problems"]
                            and min(fills.values()) >= 0.5
                        )
                    if int(sample["t"]) % 10 == 0 or sample.get("shot"):
                        loads.append(load_average())
                    wall = sample["behind_wall_s"]
                    sim = sample["behind_sim_s"]
                    print(
                        f"t {sample['t']:6.1f} s  sim {(newest or 0) / 1e9:7.1f} s  page {'-' if shown is None else f'{shown / 1e9:7.1f} s'}"
                        f"  behind {'   -   ' if wall is None else f'{wall:6.2f} s'} (sim {'  -  ' if sim is None else f'{sim:5.1f}'})"
                        f"  {sample.get('fps', 0):4.1f} fps  heap {(sample.get('heap') or 0) / 2**20:5.1f} MiB  wasm {(sample.get('wasm') or 0) / 2**20:5.0f} MiB"
                        f"  RSS {sample['rss']:6.0f} MiB (renderer {sample['renderer']:5.0f})"
                        + (
                            f"  shot {Path(sample['shot']).name} (taken by {sample['shot_done']:.1f} s) colour {sample['fills']['colour']:.0%} depth {sample['fills']['depth']:.0%}{' WHOLE' if sample['whole'] else ''}"
                            if sample.get("shot")
                            else ""
                        )
                        + (f"  page: {sample['error']}" if sample.get("error") else "")
                        + (
                            f"  [{'; '.join(sample['problems'])[:120]}]"
                            if sample["problems"]
                            else ""
                        ),
                        flush=True,
                    )
                page.wait()
        finally:
            for p in procs:
                p.terminate()
            for p in procs:
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
    summarise(args, rows, loads, gcs)


def summarise(
    args: argparse.Namespace, rows: list[dict[str, object]], loads: list[str], gcs: list[float]
) -> None:
    label = args.label or str(args.repo)
    seen = [r for r in rows if r.get("behind_wall_s") is not None]
    print(f"--- summary: {label}")
    print(
        f"page opened {args.late_s:.0f} s late, watched {args.watch_s:.0f} s; load average {loads[0]} at start, {loads[-1]} at the end"
    )
    if seen:
        print(
            f"first sim time shown after {seen[0]['t']:.1f} s, {seen[0]['behind_wall_s']:.1f} s behind"
        )
        settled = [
            float(r["behind_wall_s"])  # type: ignore[arg-type]
            for r in seen
            if float(r["t"]) >= min(30.0, args.watch_s / 2)  # type: ignore[arg-type]
        ]
        if settled:
            print(
                f"behind (wall) from {min(30.0, args.watch_s / 2):.0f} s on: median {median(settled):.2f} s, worst {max(settled):.2f} s, last {settled[-1]:.2f} s"
            )
        caught = next((r for r in seen if float(r["behind_wall_s"]) < 1.0), None)  # type: ignore[arg-type]
        print("under 1 s behind " + (f"first at {caught['t']:.1f} s" if caught else "never"))
    else:
        print("the page never showed a time on sim_time")
    whole = next((r for r in rows if r.get("whole")), None)
    print(
        "whole scene (pictures in both panels, no view reports) "
        + (
            f"first in the screenshot at {whole['t']:.1f} s (taken by {whole['shot_done']:.1f} s)"
            if whole
            else "never"
        )
    )
    print(
        f"the page dropped old data {len(gcs)} times"
        + (f", first at {gcs[0]:.0f} s" if gcs else "")
    )
    fps = [float(r["fps"]) for r in rows if r.get("fps") is not None]  # type: ignore[arg-type]
    print(f"page frames a second: median {median(fps):.1f}")
    problems = sorted({p for r in rows for p in r.get("problems", [])})  # type: ignore[attr-defined]
    if problems:
        print(f"view reports / loading seen: {'; '.join(problems)[:400]}")
    if rows:
        for name, key in (
            ("JS heap", "heap"),
            ("wasm memory", "wasm"),
            ("browser RSS", "rss"),
            ("renderer RSS", "renderer"),
        ):
            scale = 2**20 if key in ("heap", "wasm") else 1
            values = [float(r.get(key) or 0) / scale for r in rows]  # type: ignore[arg-type]
            minute = [float(r.get(key) or 0) / scale for r in rows if float(r["t"]) >= 60][:1]  # type: ignore[arg-type]
            print(
                f"{name}: start {values[0]:.0f} MiB, at 60 s {minute[0] if minute else float('nan'):.0f}, peak {max(values):.0f}, end {values[-1]:.0f}"
            )
    shots = sorted(args.shots.glob("page_*.png"))
    print(f"screenshots: {args.shots} ({len(shots)}; last {shots[-1].name if shots else '-'})")


if __name__ == "__main__":
    main()
