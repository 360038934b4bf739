"""How the live web viewer keeps up in a real, software-rendered browser.

Runs a private pipeline (router, sim, locator, viewer with the web viewer, all on free ports),
waits --late-s seconds, then opens the viewer's page in headless Chromium (SwiftShader, no GPU)
driven by playwright-core, and prints once a second for --watch-s seconds:

  - lag: the sim's newest capture stamp minus the time the page shows. The page's time is read
    from the web viewer's own state (``window._handle.viewer_state()``, the Viewer Control API's
    encoded GetStateResponse): the largest duration in it that the sim has reached, i.e. the
    time cursor on ``sim_time``, which follows the newest data in live mode;
  - the page's JS heap (CDP Performance.getMetrics) and the browser's resident memory (every
    Chromium process, from /proc).

Then it prints when the page first showed data, how far behind it was at the start and at the
end, and the memory's start, peak and end; a screenshot (CDP Page.captureScreenshot) goes to
--screenshot.

  .venv/bin/python benchmarks/bench_live_view.py --late-s 60 --watch-s 60
  .venv/bin/python benchmarks/bench_live_view.py --repo /tmp/before    # the code before

Needs /usr/bin/chromium (apt-get install -y chromium) and playwright-core from npm in
--node-modules (npm install playwright-core in that folder's parent).
"""

# The page script and the report lines read best unwrapped.
# ruff: noqa: E501

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from onebox import bus
from onebox.testing.processes import bus_args, free_port, private_router
from schemas import Image

PAGE_SCRIPT = r"""
const { chromium } = require('playwright-core');
const [url, watchS, shot, profile] = process.argv.slice(2);
function varints(bytes, out, depth) {
  // Every varint of a protobuf message, nested messages included (best effort).
  let i = 0;
  while (i < bytes.length) {
    let key = 0n, shift = 0n, b;
    do { b = bytes[i++]; key |= BigInt(b & 0x7f) << shift; shift += 7n; } while (b & 0x80 && i < bytes.length);
    const wire = Number(key & 7n);
    if (wire === 0) {
      let v = 0n; shift = 0n;
      do { b = bytes[i++]; v |= BigInt(b & 0x7f) << shift; shift += 7n; } while (b & 0x80 && i < bytes.length);
      out.push(v);
    } else if (wire === 2) {
      let len = 0n; shift = 0n;
      do { b = bytes[i++]; len |= BigInt(b & 0x7f) << shift; shift += 7n; } while (b & 0x80 && i < bytes.length);
      const sub = bytes.slice(i, i + Number(len));
      if (depth < 12) { try { varints(sub, out, depth + 1); } catch (e) {} }
      i += Number(len);
    } else if (wire === 1) { i += 8; } else if (wire === 5) { i += 4; } else { return; }
  }
}
(async () => {
  // A new profile folder each run (playwright's form of --user-data-dir).
  const browser = await chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium',
    viewport: { width: 1280, height: 720 },
    args: ['--headless', '--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
           '--disable-gpu-sandbox', '--disable-background-networking', '--disable-component-update',
           '--disable-sync', '--no-first-run'],
  });
  const page = await browser.newPage();
  const cdp = await browser.newCDPSession(page);
  await cdp.send('Performance.enable');
  const t0 = Date.now();
  await page.goto(url, { timeout: 120000 });
  const end = t0 + Number(watchS) * 1000;
  while (Date.now() < end) {
    let values = [];
    try {
      const raw = await page.evaluate(() => window._handle ? Array.from(window._handle.viewer_state()) : null);
      if (raw) { const out = []; varints(Uint8Array.from(raw), out, 0); values = out.map(String); }
    } catch (e) {}
    let heap = null;
    try {
      const m = await cdp.send('Performance.getMetrics');
      heap = (m.metrics.find(x => x.name === 'JSHeapUsedSize') || {}).value;
    } catch (e) {}
    console.log(JSON.stringify({ t: (Date.now() - t0) / 1000, values, heap }));
    await new Promise(r => setTimeout(r, 1000));
  }
  try {
    const s = await cdp.send('Page.captureScreenshot', { format: 'png' });
    require('fs').writeFileSync(shot, Buffer.from(s.data, 'base64'));
  } catch (e) { console.error('no screenshot: ' + e); }
  await browser.close();
})();
"""


def chromium_rss_mb() -> float:
    total = 0
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            text = status.read_text()
        except OSError:
            continue
        if re.search(r"^Name:\s+(chromium|chrome)", text, re.M):
            match = re.search(r"^VmRSS:\s+(\d+) kB", text, re.M)
            total += int(match.group(1)) if match else 0
    return total / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--late-s", type=float, default=60.0, help="open the page this late")
    parser.add_argument("--watch-s", type=float, default=60.0, help="watch the page this long")
    parser.add_argument("--repo", type=Path, default=Path(__file__).resolve().parent.parent)
    parser.add_argument("--node-modules", type=Path, default=Path("/tmp/pw/node_modules"))
    parser.add_argument("--screenshot", type=Path, default=Path("/tmp/live_view.png"))
    args = parser.parse_args()

    newest = {"stamp_ns": 0}
    with private_router() as endpoint, bus.open_bus(bus_args(endpoint)) as b:
        b.subscribe(
            "camera/image_raw",
            Image,
            lambda key, m: newest.__setitem__(
                "stamp_ns", max(newest["stamp_ns"], m.header.stamp_ns)
            ),
        )
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
            url = f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"
            print(
                f"pipeline up {args.late_s:.0f} s, sim at {newest['stamp_ns'] / 1e9:.1f} s; opening {url}"
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
                        str(args.screenshot),
                        str(Path(profile) / "profile"),
                    ],
                    stdout=subprocess.PIPE,
                    env=node_env,
                    text=True,
                )
                rows = []
                assert page.stdout is not None
                for line in page.stdout:
                    sample = json.loads(line)
                    sim_ns = newest["stamp_ns"]
                    shown = [int(v) for v in sample["values"] if 5e8 <= int(v) <= sim_ns + 5e9]
                    page_ns = max(shown) if shown else None
                    lag_s = (sim_ns - page_ns) / 1e9 if page_ns is not None else None
                    rss = chromium_rss_mb()
                    heap = (sample["heap"] or 0) / 2**20
                    rows.append((sample["t"], lag_s, heap, rss))
                    lag = f"{lag_s:6.2f} s" if lag_s is not None else "  none "
                    print(
                        f"t {sample['t']:6.1f} s  sim {sim_ns / 1e9:7.1f} s  behind {lag}  JS heap {heap:6.1f} MiB  chromium RSS {rss:7.1f} MiB",
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
    seen = [r for r in rows if r[1] is not None]
    print("--- summary")
    print(f"page opened {args.late_s:.0f} s late, watched {args.watch_s:.0f} s")
    if seen:
        print(f"first data shown after {seen[0][0]:.1f} s, {seen[0][1]:.2f} s behind the sim")
        tail = [r[1] for r in seen[-10:]]
        print(
            f"behind over the last {len(tail)} samples: median {sorted(tail)[len(tail) // 2]:.2f} s, worst {max(tail):.2f} s"
        )
    else:
        print("the page never showed the sim's time")
    if rows:
        print(
            f"JS heap start {rows[0][2]:.0f} MiB, peak {max(r[2] for r in rows):.0f}, end {rows[-1][2]:.0f}"
        )
        print(
            f"chromium RSS start {rows[0][3]:.0f} MiB, peak {max(r[3] for r in rows):.0f}, end {rows[-1][3]:.0f}"
        )
    print(f"screenshot: {args.screenshot}")


if __name__ == "__main__":
    main()
