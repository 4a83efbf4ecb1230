"""`cmosnoise explore` in the system Chromium (pytest-playwright), against a real server process.

The server is started as `python -m cmosnoise explore --no-browser` on a free loopback port and
stopped by its process id. Every request the page makes that does not go to that server is aborted
and fails the test.
"""

import hashlib
import io
import json
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
import tifffile
from conftest import EXPLORE_TOKEN, cli, free_port, stop_process


@pytest.fixture(scope="module")
def server():
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "cmosnoise", "explore", "--no-browser", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    url = f"http://127.0.0.1:{port}/"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise RuntimeError(f"explore exited: {proc.stderr.read()}")
            try:
                urllib.request.urlopen(url + "api/meta", timeout=2).read()
                break
            except OSError:
                time.sleep(0.2)
        yield url
    finally:
        stop_process(proc)


@pytest.fixture
def app_page(page, server):
    """The page loaded, with every off-server request aborted and recorded, and console errors collected."""
    foreign, errors = [], []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))

    def gate(route):
        if route.request.url.startswith(server) or route.request.url.startswith("data:") or route.request.url.startswith("blob:"):
            route.continue_()
        else:
            foreign.append(route.request.url)
            route.abort()

    page.route("**/*", gate)
    page.set_viewport_size({"width": 1700, "height": 1000})
    page.goto(server + "?token=" + EXPLORE_TOKEN)  # the address the command opens: a cookie, and the token leaves it
    assert "token" not in page.url
    _wait_rendered(page, "A")
    _wait_rendered(page, "B")
    yield page
    assert foreign == [], f"the page asked other origins: {foreign}"
    # a value the test made invalid on purpose is answered 422, which Chromium logs as a failed load
    errors = [e for e in errors if "status of 422" not in e]
    assert errors == [], f"console errors: {errors}"


def _wait(page, expr: str, timeout_s: float = 60):
    """Poll a JavaScript expression until it is true (page.wait_for_function evaluates strings with eval,
    which the page's Content-Security-Policy forbids, as it should)."""
    deadline = time.monotonic() + timeout_s
    while not page.evaluate(f"() => !!({expr})"):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {expr}")
        page.wait_for_timeout(50)


def _settle(page):
    """Every scheduled render has run and its picture is shown (renders start 15 ms after a change)."""
    page.wait_for_timeout(120)
    _wait(page, "S.shown.A === S.seq.A && S.shown.B === S.seq.B && !S.busy.A && !S.busy.B")
    page.wait_for_timeout(50)


def _wait_rendered(page, pane, after=-1):
    _wait(page, f"S.shown['{pane}'] > {after} && S.shown['{pane}'] === S.seq['{pane}']")


def _pixels(page, canvas):
    """A digest of the canvas's pixels (its lossless PNG encoding)."""
    data = page.evaluate(f"() => document.getElementById('{canvas}').toDataURL('image/png')")
    return hashlib.sha1(data.encode()).hexdigest()


def _set(page, key, value, kind="range"):
    """Move a control as a user does: set its value and send the event it sends."""
    event = "input" if kind == "range" else "change"
    sel = f'#fields input[type={kind}][data-key="{key}"]'
    page.eval_on_selector(sel, f"(e, v) => {{ e.value = v; e.dispatchEvent(new Event('{event}')); }}", str(value))


#: what the page sends with every request that does work (the server refuses requests without it)
PAGE_HEADERS = {"Content-Type": "application/json", "X-Cmosnoise": "1"}


def _post(url, body: bytes, headers=None):
    req = urllib.request.Request(url, data=body, headers={**PAGE_HEADERS, **(headers or {})}, method="POST")
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        return e.code, e.read(), dict(e.headers)


def test_page_loads_offline_with_a_csp_and_identical_panes(app_page, server):
    # A and B start as the same sensor: the same picture, bit for bit
    assert _pixels(app_page, "canvasA") == _pixels(app_page, "canvasB")
    with urllib.request.urlopen(server) as r:
        csp = r.headers["Content-Security-Policy"]
    assert "default-src 'self'" in csp and "script-src 'self'" in csp


def test_a_slider_changes_the_picture_and_an_invalid_value_keeps_it(app_page):
    page = app_page
    before = _pixels(page, "canvasA")
    seq = page.evaluate("S.seq.A")
    _set(page, "source_follower.thermal_sigma_e", 400)  # the slider's top end
    _wait_rendered(page, "A", seq)
    moved = _pixels(page, "canvasA")
    assert moved != before
    assert _pixels(page, "canvasB") == before  # only A's parameter moved
    seq = page.evaluate("S.seq.A")
    _set(page, "prnu.sigma_pct", -5, kind="number")
    _wait(page, f"S.seq.A > {seq} && !S.busy.A")
    _wait(page, "document.querySelector('.field .err[data-key=\"prnu.sigma_pct\"]').textContent.length > 0")
    msg = page.text_content('.field .err[data-key="prnu.sigma_pct"]')
    assert page.is_visible('.field .err[data-key="prnu.sigma_pct"]')  # its section opened to show it
    assert "greater than or equal to 0" in msg
    assert "invalid" in page.inner_text("#statusA")
    assert _pixels(page, "canvasA") == moved  # the last valid picture stays
    # and the URL keeps the last valid state: a shared link opens the picture that is shown, not the error
    state = page.evaluate("JSON.parse(decodeURIComponent(escape(atob(location.hash.slice(1).replace(/-/g, '+')"
                          ".replace(/_/g, '/')))))")
    thermal = page.evaluate("S.panes.A.config.source_follower.thermal_sigma_e")
    assert state["A"]["source_follower"]["thermal_sigma_e"] == thermal and "prnu" not in state["A"]
    assert page.evaluate("S.panes.A.config.prnu.sigma_pct") == -5  # the field keeps what was typed, to correct


def test_zoom_and_pan_stay_locked_and_the_url_keeps_the_view(app_page, server):
    page = app_page
    fit = _pixels(page, "canvasA")
    seq_a, seq_b = page.evaluate("S.seq.A"), page.evaluate("S.seq.B")
    page.click("#zoom1")
    page.click("#zoomIn")
    box = page.locator("#canvasA").bounding_box()
    page.mouse.move(box["x"] + 300, box["y"] + 200)
    page.mouse.down()
    page.mouse.move(box["x"] + 200, box["y"] + 150, steps=5)
    page.mouse.up()
    _wait(page, f"S.seq.A > {seq_a + 1} && S.seq.B > {seq_b + 1}")
    _settle(page)
    a, b = _pixels(page, "canvasA"), _pixels(page, "canvasB")
    assert a == b and a != fit  # the same region of two identical sensors, at 2:1
    assert page.evaluate("S.zoom") == pytest.approx(2.0)
    url = page.url
    again = page.context.new_page()
    again.route("**/*", lambda route: route.continue_() if route.request.url.startswith(server) else route.abort())
    again.set_viewport_size({"width": 1700, "height": 1000})
    again.goto(url)
    _wait_rendered(again, "A")
    _settle(again)
    assert again.evaluate("[S.zoom, S.cx, S.cy]") == page.evaluate("[S.zoom, S.cx, S.cy]")
    assert _pixels(again, "canvasA") == a
    again.close()


def test_difference_view_shows_only_the_changed_parameter(app_page, server):
    """Row noise changed in B: B - A is one offset per row, nothing else (common random numbers)."""
    page = app_page
    page.click("#editB")
    _set(page, "row_noise.sigma_e", 30, kind="number")
    page.select_option("#mode", "diff")
    _settle(page)
    grey = page.evaluate("""() => { const c = document.getElementById('canvasDiff');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; let n = 0;
        for (let i = 0; i < d.length; i += 4) if (Math.abs(d[i] - 128) > 2 && d[i] !== 17) n++; return n; }""")
    assert grey > 1000  # the difference view shows the rows
    raws = []
    for pane in "AB":
        body = page.evaluate(f"JSON.stringify({{config: S.panes.{pane}.config, scene: S.panes.{pane}.scene, frame: 0}})")
        status, data, _ = _post(server + "api/raw", body.encode(), {"Content-Type": "application/json"})
        assert status == 200
        raws.append(np.load(io.BytesIO(data)).astype(np.int64))
    a, b = raws
    d = b - a
    ok = (a > 0) & (a < 4095) & (b > 0) & (b < 4095)
    spread = [np.ptp(row[m]) for row, m in zip(d, ok) if m.sum() > 10]
    assert max(spread) <= 1  # within a row: the same offset, up to the quantizer's rounding
    assert np.std(np.median(d, axis=1)) > 5  # between rows: the row noise (30 e- at 0.4 DN/e-)


def test_exported_config_reproduces_the_panes_raw_frame(app_page, server, tmp_path):
    page = app_page
    seq = page.evaluate("S.seq.A")
    _set(page, "sensor.temperature_c", 45, kind="number")
    _wait_rendered(page, "A", seq)
    with page.expect_download() as dl:
        page.click("#export")
    path = tmp_path / "config-A.yaml"
    dl.value.save_as(path)
    body = page.evaluate("JSON.stringify({config: S.panes.A.config, scene: S.panes.A.scene, frame: 0})")
    status, data, _ = _post(server + "api/raw", body.encode(), {"Content-Type": "application/json"})
    assert status == 200
    pane_raw = np.load(io.BytesIO(data))
    r = cli("simulate", "--config", path, "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert np.array_equal(tifffile.imread(tmp_path / "run" / "raw.tiff").reshape(pane_raw.shape), pane_raw)


def test_the_server_refuses_bad_requests_and_keeps_serving(server, tmp_path):
    # a request naming another host (DNS rebinding): refused
    req = urllib.request.Request(server + "api/meta", headers={"Host": "attacker.example"})
    with pytest.raises(urllib.error.HTTPError) as info:
        urllib.request.urlopen(req, timeout=10)
    assert info.value.code == 400
    # an oversized upload: refused from its declared length, before the body is read
    import http.client

    conn = http.client.HTTPConnection("127.0.0.1", int(server.rsplit(":", 1)[1].strip("/")), timeout=30)
    conn.putrequest("POST", "/api/upload")
    conn.putheader("Content-Length", str(51 * 10**6))
    conn.putheader("X-Filename", "big.png")
    conn.putheader("X-Cmosnoise", "1")
    conn.putheader("X-Cmosnoise-Token", EXPLORE_TOKEN)
    conn.putheader("Content-Type", "application/octet-stream")
    conn.endheaders()
    conn.send(b"x" * 1000)
    resp = conn.getresponse()
    assert resp.status == 413 and "at most 50 MB" in json.loads(resp.read())["error"]
    conn.close()
    # a decompression bomb: a small PNG of 9000 x 8000 pixels, refused from its header
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.zeros((9000, 8000), np.uint8)).save(buf, format="PNG")
    status, body, _ = _post(server + "api/upload", buf.getvalue(), {"X-Filename": "bomb.png",
                                                                        "Content-Type": "application/octet-stream"})
    assert status == 413 and "8000 x 9000 pixels" in json.loads(body)["error"]
    # a path instead of a scene, bad JSON, an invalid value, a too large picture: 4xx with one line
    cfg = json.loads(urllib.request.urlopen(server + "api/meta").read())["base"]
    for payload, code, needle in [
        ({"config": cfg, "scene": "/etc/passwd"}, 400, "built-in"),
        ({"config": cfg, "scene": "flatland"}, 400, "built-in"),
        ({"config": {**cfg, "prnu": {**cfg["prnu"], "sigma_pct": "abc"}}}, 422, "prnu.sigma_pct"),
        ({"config": cfg, "region": [0, 480, 0, 640], "step": 0}, 400, "step"),
        ({"config": {**cfg, "sensor": {**cfg["sensor"], "width": 30000, "height": 30000}}}, 422, "50 MP"),
        # a file key naming a file on the server (#79): the server reads no file a page names
        ({"config": {**cfg, "light": {**cfg["light"], "illuminant": "/etc/passwd"}}}, 422, "reads no file a page names"),
        ({"config": {**cfg, "optics": {**cfg["optics"], "psf": str(tmp_path / "p.npy")}}}, 422, "upload it"),
        ({"config": {**cfg, "optics": {**cfg["optics"], "chief_ray_angle": "upload:nosuch"}}}, 422, "optics.chief_ray_angle"),
    ]:
        status, body, _ = _post(server + "api/render", json.dumps(payload).encode(), {"Content-Type": "application/json"})
        assert status == code and needle in json.loads(body)["error"], (payload.get("scene"), status, body[:200])
    status, body, _ = _post(server + "api/render", b"{not json", {"Content-Type": "application/json"})
    assert status == 400
    # a file the page uploaded is one a file key may name: a PSF as .npy, by its id
    buf = io.BytesIO()
    np.save(buf, np.outer([1, 2, 1], [1, 2, 1]).astype(float))
    status, body, _ = _post(server + "api/upload", buf.getvalue(), {"X-Filename": "psf.npy",
                                                                        "Content-Type": "application/octet-stream"})
    assert status == 200, body
    psf = {**cfg, "optics": {**cfg["optics"], "psf": "upload:" + json.loads(body)["id"]}}
    status, body, _ = _post(server + "api/render", json.dumps({"config": psf, "step": 4}).encode())
    assert status == 200, body[:300]
    # a request made stale by a newer one of the same pane is dropped, not queued
    newer = {"config": cfg, "pane": "A", "client": "t", "seq": 10}
    assert _post(server + "api/render", json.dumps(newer).encode())[0] == 200
    status, body, headers = _post(server + "api/render", json.dumps({**newer, "seq": 9}).encode())
    assert status == 204 and body == b"" and "newer request" in {k.lower(): v for k, v in headers.items()}.get("x-dropped", "")
    # every built-in scene the page offers is taken
    for scene in ("flat:0.5", "steps:8", "ramp", "spot"):
        status, body, _ = _post(server + "api/render", json.dumps({"config": cfg, "scene": scene, "step": 4}).encode())
        assert status == 200, (scene, body[:200])
    # still serving
    assert urllib.request.urlopen(server + "api/meta", timeout=10).status == 200


def test_explore_refuses_a_port_in_use():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = cli("explore", "--no-browser", "--port", str(port))
    assert r.returncode == 2 and "cannot be used" in r.stderr


def test_another_host_is_served_only_when_asked_and_with_a_warning():
    """Without --host the server answers only requests naming a loopback host; `--host 127.0.0.2` (another
    address, still on the loopback interface: tests never listen on a network) binds there, warns on the
    terminal that anyone who can reach the port can use it, and accepts that host."""
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "cmosnoise", "explore", "--no-browser", "--host", "127.0.0.2",
                             "--port", str(port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = []
        deadline = time.monotonic() + 120
        while not any("Ctrl-C to stop" in line for line in lines):
            assert time.monotonic() < deadline and proc.poll() is None, lines
            lines.append(proc.stdout.readline())
        text = "".join(lines)
        assert "warning: serving on 127.0.0.2" in text and "anyone who can reach this port" in text
        while True:  # the line comes as the server starts listening
            try:
                assert urllib.request.urlopen(f"http://127.0.0.2:{port}/api/meta", timeout=30).status == 200
                break
            except urllib.error.URLError:
                assert time.monotonic() < deadline and proc.poll() is None
                time.sleep(0.2)
        with pytest.raises(OSError):  # not listening on 127.0.0.1
            urllib.request.urlopen(f"http://127.0.0.1:{port}/api/meta", timeout=5)
        req = urllib.request.Request(f"http://127.0.0.2:{port}/api/meta", headers={"Host": "attacker.example"})
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(req, timeout=10)
        assert info.value.code == 400
        stop_process(proc)  # SIGTERM: a server stops; it had nothing to write, and does not say it wrote nothing
        rest = proc.stdout.read()
        assert "cmosnoise: stopped (SIGTERM)" in rest and "nothing was written" not in rest, rest
    finally:
        stop_process(proc)


@pytest.mark.parametrize("width, height", [(1280, 800), (1440, 900), (1920, 1080)])
def test_both_panes_and_their_key_figures_show_without_scrolling(app_page, tmp_path, width, height):
    """A laptop's and a desktop's window: the panes side by side, each with its key figures (named, with units)
    above the fold, nothing wider than the window. The screenshots are kept beside the test's files."""
    page = app_page
    page.set_viewport_size({"width": width, "height": height})
    page.reload()
    _wait_rendered(page, "A")
    _wait_rendered(page, "B")
    _wait(page, "document.querySelectorAll('#figuresA table tr').length > 10 && "
                "document.querySelectorAll('#figuresB table tr').length > 10")
    page.screenshot(path=str(tmp_path / f"explore_{width}x{height}.png"))
    box = page.evaluate("""() => {
        const r = (e) => e.getBoundingClientRect();
        const rows = (p) => [...document.querySelectorAll(`#figures${p} table`)[0].rows];
        return {A: r(document.getElementById('canvasA')), B: r(document.getElementById('canvasB')),
                lastA: r(rows('A').at(-1)).bottom, lastB: r(rows('B').at(-1)).bottom,
                names: rows('A').map((row) => row.cells[0].textContent),
                scrollWidth: document.documentElement.scrollWidth};
    }""")
    assert box["A"]["top"] == box["B"]["top"] and box["A"]["right"] <= box["B"]["left"]  # side by side
    assert box["B"]["right"] <= width and box["scrollWidth"] <= width
    assert max(box["A"]["bottom"], box["B"]["bottom"], box["lastA"], box["lastB"]) <= height
    assert "dynamic range (dB)" in box["names"] and "SNR with fixed pattern, at 100 e- (dB)" in box["names"]
    assert not [n for n in box["names"] if "_" in n]  # no JSON names


@pytest.mark.slow
def test_a_cameras_gain_table_gives_an_iso_menu(app_page):
    """Loading the sony-a7s2 preset into pane A: its ISO is a menu of the table's settings (with the conversion
    gain's name), and picking one redraws the pane with that setting's noise."""
    page = app_page
    page.select_option("#preset", "sony-a7s2")
    _wait(page, "document.querySelector('#fields select[data-key=\"sensor.iso\"]') !== null")
    options = page.eval_on_selector('#fields select[data-key="sensor.iso"]', "e => [...e.options].map(o => o.textContent)")
    assert "2000 (HCG)" in options and "1600 (LCG)" in options and "1700" not in " ".join(options)
    _settle(page)
    before = page.evaluate("() => S.seq.A")
    page.select_option('#fields select[data-key="sensor.iso"]', "2000")
    _wait_rendered(page, "A", before)
    assert page.evaluate("() => S.panes.A.config.sensor.iso") == 2000


@pytest.mark.slow
def test_the_play_view_shows_random_telegraph_pixels_flip_and_blink(app_page, server, tmp_path):
    """Pane B with both random telegraph stages on (traps read without CDS, large amplitudes; blinking pixels with
    a large step), pane A without: with common random numbers B - A is zero except at those pixels, and frame by
    frame (what play steps through) their difference takes two or more levels. The difference view changes from
    frame to frame; a screenshot of it is kept beside the test's files."""
    page = app_page
    page.set_viewport_size({"width": 1440, "height": 900})
    page.click("#editB")
    for key in ("source_follower.rts.enabled", "dark_current.rts.enabled"):
        page.check(f'#fields input[type=checkbox][data-key="{key}"]')
        _settle(page)
    # in its section's closed panel: set as the checkbox's own change would
    page.eval_on_selector('#fields input[type=checkbox][data-key="source_follower.rts.cds"]',
                          "e => { e.checked = false; e.dispatchEvent(new Event('change')); }")
    for key, value in (("source_follower.rts.ppm", 20000), ("source_follower.rts.amplitude_e.median", 60),
                       ("dark_current.rts.ppm", 20000), ("dark_current.rts.step_e_per_s.median", 5000),
                       ("dark_current.rts.tau_low_s.min_s", 0.01), ("dark_current.rts.tau_high_s.min_s", 0.01),
                       ("dark_current.rts.tau_low_s.max_s", 0.1), ("dark_current.rts.tau_high_s.max_s", 0.1)):
        _set(page, key, value, kind="number")
    page.select_option("#mode", "diff")
    _settle(page)
    assert page.evaluate("() => S.panes.B.config.source_follower.rts.cds") is False
    digests = []
    for frame in range(3):  # as the play button does: the frame number moves, both panes are made again
        page.eval_on_selector("#frame", f"e => {{ e.value = {frame}; e.dispatchEvent(new Event('change')); }}")
        _settle(page)
        digests.append(_pixels(page, "canvasDiff"))
        if frame == 1:
            page.screenshot(path=str(tmp_path / "rts_difference_frame1.png"))
    assert len(set(digests)) == 3, "the difference view does not change from frame to frame"
    diffs = []
    for frame in range(8):
        raws = []
        for pane in "AB":
            body = page.evaluate(f"JSON.stringify({{config: S.panes.{pane}.config, scene: S.panes.{pane}.scene, "
                                 f"frame: {frame}}})")
            status, data, _ = _post(server + "api/raw", body.encode(), {"Content-Type": "application/json"})
            assert status == 200
            raws.append(np.load(io.BytesIO(data)).astype(np.int64))
        diffs.append(raws[1] - raws[0])
    d = np.stack(diffs)  # (frames, rows, cols)
    moved = np.any(d != 0, axis=0)
    n = moved.size
    # both populations at 2 % each: about 4 % of the pixels differ somewhere (Binomial: far inside 1 % .. 8 %)
    assert 0.01 * n < moved.sum() < 0.08 * n, moved.sum() / n
    levels = np.array([np.unique(d[:, r, c]).size for r, c in zip(*np.nonzero(moved))])
    assert np.mean(levels >= 2) > 0.5  # they flip and blink: most take two or more values over 8 frames


def test_the_quick_settings_show_whole_names_and_light_in_lux_renders(app_page):
    """#63: the quick settings' labels were cut off; #60: lux, f-number and the light's switch are among them."""
    page = app_page
    labels = page.eval_on_selector_all(
        "#fields details:first-of-type .field.whole .name",
        "els => els.map(e => [e.textContent, e.scrollWidth <= e.clientWidth + 1, e.offsetWidth > 0])")
    names = [t for t, _, _ in labels]
    assert any(t.startswith("light.illuminance_lux [lux]") for t in names), names
    assert any(t.startswith("optics.f_number") for t in names) and any(t.startswith("light.enabled") for t in names)
    assert all(whole and shown for _, whole, shown in labels), [t for t, w, s in labels if not (w and s)]
    before = _pixels(page, "canvasA")
    seq = page.evaluate("S.seq.A")
    page.eval_on_selector('#fields input[type=checkbox][data-key="light.enabled"]',
                          "e => { e.checked = true; e.dispatchEvent(new Event('change')); }")
    _wait(page, f"S.seq.A > {seq} && !S.busy.A")
    # light in lux needs a QE: the explorer says so in one line and keeps the picture, until one is given
    seq = page.evaluate("S.seq.A")
    page.evaluate("S.panes.A.config.sensor.quantum_efficiency = 0.6")
    _set(page, "light.illuminance_lux", 30, kind="number")
    _wait(page, f"S.seq.A > {seq} && !S.busy.A")
    _wait_rendered(page, "A")
    assert _pixels(page, "canvasA") != before


@pytest.mark.slow
def test_image_quality_of_both_panes_and_their_difference_in_jnd(app_page, server, tmp_path):
    """#61: the explorer measures each pane's image quality at one illuminance (quality's metric registry) and
    shows A - B, in JND for banding; the numbers are `quality.measure`'s for the pane's configuration and seed."""
    from cmosnoise.analysis import quality
    from cmosnoise.config import Config

    page = app_page
    page.evaluate("S.panes.A.config.sensor.quantum_efficiency = 0.6; S.panes.B.config.sensor.quantum_efficiency = 0.6;"
                  "S.panes.B.config.column_noise.vfpn_sigma_e = 6")
    page.fill("#qLux", "10")
    page.click("#qMeasure")
    _wait(page, "document.querySelectorAll('#qTable tbody tr').length > 0")
    rows = page.eval_on_selector_all("#qTable tbody tr", "rs => rs.map(r => [r.dataset.metric, "
                                                          "...[...r.cells].map(c => c.textContent)])")
    assert [r[0] for r in rows] == [m.name for m in quality.METRICS]
    got = {r[0]: r[1:] for r in rows}
    # the page's numbers are the server's, and the server's are quality.measure's, for each pane
    for pane in "AB":
        body = page.evaluate(f"JSON.stringify({{config: S.panes.{pane}.config, lux: 10}})")
        status, data, _ = _post(server + "api/quality", body.encode())
        assert status == 200
        served = json.loads(data)
        config = Config.model_validate(json.loads(body)["config"])
        want = quality.measure(config, [10.0], frames=served["frames"], seed=config.seed)
        assert served["metrics"] == {k: v[0] for k, v in want["metrics"].items()}, pane
    # six times the column FPN in B: B's banding is the larger, A - B is negative in JND, and A is the better
    label, a, b, diff = got["banding_columns"]
    assert label == "column banding, print (JND)" and float(b) > float(a)
    assert diff.startswith("-") and "JND" in diff and diff.endswith("A better")
    assert "thresholds" in got["visual_noise_l"][3]
    page.screenshot(path=str(tmp_path / "quality.png"), full_page=True)
    # a bad illuminance is one line in the box, no table
    page.fill("#qLux", "-3")
    page.click("#qMeasure")
    _wait(page, "document.getElementById('qStatus').classList.contains('err')")
    assert "lux" in page.text_content("#qStatus") and page.eval_on_selector_all("#qTable tbody tr", "r => r.length") == 0


@pytest.mark.slow
def test_only_the_token_opens_the_explorer_and_the_command_never_prints_it_whole(browser):
    """Jupyter's model (#79): a random token made at start, in the address the command opens and writes to a file
    of the owner's alone; every route but the page's own files refuses a request without it (403, one line); the
    page without it is a note saying where the address is. Chromium with the address drives the page; a browser
    without it is refused."""
    import os
    import re
    import stat

    port = free_port()
    env = {k: v for k, v in os.environ.items() if k != "CMOSNOISE_EXPLORE_TOKEN"}  # the command's own token
    proc = subprocess.Popen([sys.executable, "-m", "cmosnoise", "explore", "--no-browser", "--port", str(port),
                             "--set", "sensor.width=96", "--set", "sensor.height=64"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        lines = []
        deadline = time.monotonic() + 120
        while not any("Ctrl-C to stop" in line for line in lines):
            assert time.monotonic() < deadline and proc.poll() is None, lines
            lines.append(proc.stdout.readline())
        said = "".join(lines)
        path = re.search(r"is in (\S+), readable by you alone", said).group(1)
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
        with open(path) as fh:
            address = fh.read().strip()
        token = address.split("token=", 1)[1]
        assert len(token) >= 43 and token not in said  # 32 random bytes, never printed whole
        bare = urllib.request.build_opener()  # no token: what another local user has
        base = f"http://127.0.0.1:{port}/"
        while True:
            try:
                bare.open(base + "explore.js", timeout=5).read()  # the page's own files need no token
                break
            except OSError:
                assert time.monotonic() < deadline and proc.poll() is None
                time.sleep(0.2)
        for route, body in [("api/meta", None), ("api/stats", None), ("api/preset?name=x", None),
                            ("api/render", b"{}"), ("api/check", b"{}"), ("api/quality", b"{}"), ("api/upload", b"x")]:
            req = urllib.request.Request(base + route, data=body, method="POST" if body else "GET",
                                         headers={**PAGE_HEADERS, "X-Cmosnoise-Token": "guess" * 9} if body else {})
            with pytest.raises(urllib.error.HTTPError) as info:
                bare.open(req, timeout=10)
            message = json.loads(info.value.read())["error"]
            assert info.value.code == 403 and "token" in message and "\n" not in message, (route, message)
        with pytest.raises(urllib.error.HTTPError) as info:
            bare.open(base, timeout=10)
        assert info.value.code == 403 and b"address" in info.value.read()
        # Chromium with the address: the token becomes a cookie and leaves the address; the page renders
        context = browser.new_context()
        page = context.new_page()
        page.goto(address)
        assert "token" not in page.url
        _wait_rendered(page, "A")
        assert page.evaluate("fetch('api/meta').then(r => r.status)") == 200
        context.close()
        # another browser, without it: the note, and the API refused
        other = browser.new_context()
        page = other.new_page()
        page.goto(base)
        assert "carries its token" in page.content()
        assert page.evaluate("fetch('api/meta').then(r => r.status)") == 403
        other.close()
    finally:
        stop_process(proc)
