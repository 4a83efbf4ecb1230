"""Latency of `cmosnoise explore`: from a slider change to the new pixels on the canvas, in headless Chromium.

A 1920 x 1080 sensor shown whole in a 960 x 540 viewport (pane A). For a
temporal parameter (source follower thermal noise) and for fixed-pattern
ones (PRNU sigma, the dark-current temperature), it moves the slider, then
waits until the page has drawn the answer to that very request. Median and
worst of --repeats moves each, the server's own render time beside them.

    python benchmarks/bench_explore.py [--repeats 15] [--json docs/numbers/explore.json]
    python benchmarks/bench_explore.py --quality-picture docs/img/explore_quality.png

The second form only makes the docs' picture of the image-quality box (docs/sensor/explore.md): A the default
sensor, B with 6 e- of column FPN, both at QE 0.6, measured at 10 lux.

Needs the system Chromium (`chromium` on the PATH), as the browser tests do.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import time
import urllib.request


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def explore_server(*sets: str):
    """``cmosnoise explore`` on a free loopback port, with ``--set`` of each of ``sets``, stopped by its pid after:
    yields its URL once it answers."""
    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "cmosnoise", "explore", "--no-browser", "--port", str(port),
                             *[a for s in sets for a in ("--set", s)]],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}/"
    try:
        for _ in range(600):
            try:
                urllib.request.urlopen(url + "api/meta", timeout=2).read()
                break
            except OSError:
                time.sleep(0.2)
        yield url
    finally:
        os.kill(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)


def _browser(p):
    return p.chromium.launch(executable_path=shutil.which("chromium"), args=["--no-sandbox"])


def quality_picture(path: str) -> None:
    """The image-quality box under the panes: A the default sensor, B with 6 e- of column FPN, both at QE 0.6,
    measured at 10 lux (the picture of docs/sensor/explore.md)."""
    from playwright.sync_api import sync_playwright

    with explore_server() as url, sync_playwright() as p:
        browser = _browser(p)
        page = browser.new_page(viewport={"width": 1440, "height": 1000})
        page.goto(url)
        while not page.evaluate("() => typeof S !== 'undefined' && S.panes.B !== null && S.seq.B > 0"):
            page.wait_for_timeout(50)
        page.evaluate("() => { S.panes.A.config.sensor.quantum_efficiency = 0.6; "
                      "S.panes.B.config.sensor.quantum_efficiency = 0.6; "
                      "S.panes.B.config.column_noise.vfpn_sigma_e = 6; }")
        page.fill("#qLux", "10")
        page.click("#qMeasure")
        while not page.evaluate("() => document.querySelectorAll('#qTable tbody tr').length > 0"):
            page.wait_for_timeout(50)
        page.locator("#quality").screenshot(path=path)
        browser.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--json", help="also write the results here")
    ap.add_argument("--screenshot", help="also save a screenshot of the page here (PNG)")
    ap.add_argument("--quality-picture", help="only save the image-quality box's picture here (PNG), no timing")
    args = ap.parse_args()
    if args.quality_picture:
        quality_picture(args.quality_picture)
        return

    from playwright.sync_api import sync_playwright

    rows = []
    with explore_server("sensor.width=1920", "sensor.height=1080") as url, sync_playwright() as p:
        browser = _browser(p)
        page = browser.new_page(viewport={"width": 2000, "height": 1100})
        page.goto(url)
        while not page.evaluate("() => typeof S !== 'undefined' && S.panes.A !== null && S.seq.A > 0"):
            page.wait_for_timeout(20)
        page.evaluate("""() => { for (const id of ['canvasA', 'canvasB']) {
            const c = document.getElementById(id); c.width = 960; c.height = 540; }
            S.zoom = null; geometry(); redraw(); scheduleAll(); }""")

        def settled():
            while not page.evaluate("() => S.shown.A === S.seq.A && S.shown.B === S.seq.B && !S.busy.A && !S.busy.B"):
                page.wait_for_timeout(10)

        page.wait_for_timeout(300)
        settled()
        # every move sets a new value: nothing comes from a cache of an earlier answer
        cases = [("temporal: source_follower.thermal_sigma_e", "source_follower.thermal_sigma_e", 2.0, 0.05),
                 ("fixed pattern: prnu.sigma_pct", "prnu.sigma_pct", 1.0, 0.05),
                 ("fixed pattern: sensor.temperature_c", "sensor.temperature_c", 25.0, 0.5)]
        for label, key, start, inc in cases:
            times, server = [], []
            for i in range(args.repeats + 1):
                value = round(start + inc * (i + 1), 4)
                seq = page.evaluate("S.seq.A")
                t = page.evaluate("""([key, value]) => { const t0 = performance.now();
                    const e = document.querySelector(`#fields input[type=number][data-key="${key}"]`);
                    e.value = value; e.dispatchEvent(new Event('change')); return t0; }""", [key, str(value)])
                # the page notes when the picture reached the canvas: the wait here polls gently, so it
                # neither adds to the time nor takes the CPU from the server and the page
                while not page.evaluate(f"() => S.shown.A > {seq} && S.shown.A === S.seq.A"):
                    page.wait_for_timeout(25)
                done = page.evaluate("S.drawnAt.A")
                ms_server = float(page.inner_text("#statusA").split(",")[1].split("ms")[0])
                if os.environ.get("BENCH_VERBOSE"):
                    print(label, value, round(done - t), page.evaluate("S.lastInfo && JSON.stringify([S.lastInfo.ms, S.lastInfo.ms_handler, S.lastInfo.ms_parts])"))
                settled()
                if i:  # the first move of each case warms its caches
                    times.append(done - t)
                    server.append(ms_server)
            rows.append({"label": label, "median_ms": statistics.median(times), "max_ms": max(times),
                         "server_median_ms": statistics.median(server)})
        if args.screenshot:
            # A: the default sensor at 25 C, B: at 65 C; 0.25 s exposures (as the paper's Fig. 9), 2:1,
            # couplets circled
            page.evaluate("""() => { for (const id of ['canvasA', 'canvasB']) {
                const c = document.getElementById(id); c.width = 640; c.height = 420; }
                const base = clone(S.meta.base);
                base.exposure.integration_time_s = 0.25; base.exposure.peak_rate_e_per_s = 12000;
                S.panes.A.config = base; S.panes.B = clone(S.panes.A);
                S.panes.B.config.sensor.temperature_c = 65; S.couplets = true;
                document.getElementById('couplets').checked = true;
                S.zoom = 2; S.cx = 1000; S.cy = 520; setEdit('B'); saveUrl(); redraw(); scheduleAll(); }""")
            page.set_viewport_size({"width": 1700, "height": 1000})
            page.wait_for_timeout(500)
            settled()
            page.wait_for_timeout(3000)  # the key figures follow once the sliders rest
            page.screenshot(path=args.screenshot)
        browser.close()
    print("cmosnoise explore: slider change to new pixels, 1920 x 1080 sensor in a 960 x 540 viewport, headless Chromium")
    print(f"  {'parameter':46s} {'median ms':>10s} {'worst ms':>9s} {'server ms':>10s}")
    for r in rows:
        print(f"  {r['label']:46s} {r['median_ms']:10.0f} {r['max_ms']:9.0f} {r['server_median_ms']:10.0f}")
    if args.json:
        data = {"machine": f"{os.cpu_count()} cores", "command": f"python benchmarks/bench_explore.py --repeats {args.repeats}",
                "rows": rows}
        with open(args.json, "w") as fh:
            json.dump(data, fh, indent=2)
            fh.write("\n")


if __name__ == "__main__":
    main()
