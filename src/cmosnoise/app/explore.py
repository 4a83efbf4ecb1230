"""``cmosnoise explore``: a local web page where any parameter's effect shows on the picture at once, two panes side by side.

The server (Starlette, run by uvicorn) renders only what the page shows: a
region of frame k of a pane's sensor, at the zoom the page asks for. It keeps
what does not change between requests:

- the sensor's fixed pattern, keyed by the parameters that draw it (seed,
  size, temperature, PRNU, dark current, flicker, row and column maps), so a
  temporal or exposure slider never redraws it;
- the scene's signal through the CFA, keyed by scene and sensor geometry;
- the exposure (mean charge per pixel), reused on a sensor whose temporal
  or readout parameters changed (:meth:`Exposure.rebind`).

Both panes use the same seed streams, so with the same parameters they give
the same picture, and with one parameter changed their difference is that
parameter's effect alone (common random numbers, MODEL.md section 1).

Safety: it binds 127.0.0.1 unless told otherwise; requests must name a
loopback host (or the one given with ``--host``). A request that does work
(every POST) must come from the page itself: ``Sec-Fetch-Site`` same-origin
(or absent), an ``Origin`` (if sent) equal to the page's, the custom header
``X-Cmosnoise: 1`` that a cross-site page cannot send without a CORS
preflight this server never grants, and the content type the endpoint takes
(``application/json``; an upload ``application/octet-stream``); anything else
is refused with 403 or 415 before any work. Request bodies (and the time to
send them), request headers (the time to send them), uploads (each, their
number and their total bytes: the oldest go first), decoded images (all
frames and pages, from the header), sensor size, output size and the sensor
cache (weighed in bytes against the memory this machine has) are capped;
the page never sends a path (scenes are built-in names or uploads the server
stored in its own temporary folder); a Content-Security-Policy allows only
the page's origin. Bad requests get a 4xx with a one-line reason; the
server's own warnings are rate-limited, so a flood of bad connections cannot
fill the log.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import io
import json
import logging
import secrets
import tempfile
import threading
import time
from collections import OrderedDict
from importlib import resources
from pathlib import Path

import numpy as np

from .. import inputs
from ..config import Config, format_validation_error
from ..config.explain import fields
from ..config.loading import load_yaml_text, preset_data, preset_names, resolve_config
from ..errors import CmosnoiseError
from ..isp import calibration
from ..isp.process import Processor
from ..model import footprint, physics
from ..model import scene as scene_mod
from ..model.seeds import SEQ_DARK_CALIBRATION
from ..model.sensor import Exposure, Sensor, fixed_pattern_inputs

#: limits: request bodies, uploads, decoded upload size, sensor size, picture sent per request
MAX_BODY = 1_000_000
MAX_UPLOAD = 50_000_000
MAX_UPLOAD_PIXELS = 50_000_000
MAX_SENSOR_PIXELS = 50_000_000
MAX_OUT_SIDE = 4096
#: uploads kept at once, and their total bytes: past either the oldest upload is removed
MAX_UPLOADS = 16
MAX_UPLOADS_BYTES = 200_000_000
#: seconds a connection may take to send a request's headers, and a request's body
HEADER_TIMEOUT_S = 10.0
BODY_TIMEOUT_S = 30.0
#: JSON bodies nested deeper than this are refused
MAX_JSON_DEPTH = 32
#: the custom header every state-changing request carries (a cross-site page cannot send it without a preflight)
CSRF_HEADER = "x-cmosnoise"
#: the region rendered is extended by this many pixels on each side (even: the CFA phase is kept), so that
#: demosaicing and defect correction see real neighbours at the viewport's edges
MARGIN = 4
VIEWS = ("raw", "pre", "processed")
LOOPBACK = ("127.0.0.1", "localhost", "::1", "[::1]")
CSP = ("default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; connect-src 'self'; "
       "object-src 'none'; base-uri 'none'; frame-ancestors 'none'; form-action 'none'")


class BadRequest(Exception):
    """A request the server refuses: HTTP ``status``, a one-line ``message`` and per-field ``errors``."""

    def __init__(self, message: str, status: int = 400, errors: dict | None = None):
        super().__init__(message)
        self.message = " ".join(str(message).split())[:400]
        self.status = status
        self.errors = errors or {}


# ------------------------------------------------------------------ configuration
def validate(data) -> Config:
    """A pane's configuration (a full or partial dict) validated as the CLI does; BadRequest names each bad field."""
    if not isinstance(data, dict):
        raise BadRequest("config must be an object of sections")
    from pydantic import ValidationError

    from ..config.loading import build_config

    try:
        cfg = build_config(data)
    except CmosnoiseError as exc:
        try:  # only on the error path: pydantic's own errors, to show each next to its field
            Config.model_validate(data)
        except ValidationError as verr:
            errors = {}
            for e in verr.errors():
                key = ".".join(str(p) for p in e.get("loc", ()))
                errors.setdefault(key or "config", e.get("msg", "invalid").removeprefix("Value error, "))
            raise BadRequest(format_validation_error(verr), 422, errors) from None
        raise BadRequest(str(exc), 422, {"config": str(exc)}) from None
    try:
        cfg = physics.check(cfg)
    except CmosnoiseError as exc:
        raise BadRequest(str(exc), 422, {"config": str(exc)}) from None
    if cfg.sensor.width * cfg.sensor.height > MAX_SENSOR_PIXELS:
        msg = f"the explorer takes sensors up to {MAX_SENSOR_PIXELS / 1e6:g} MP; use cmosnoise simulate for larger ones"
        raise BadRequest(msg, 422, {"sensor.width": msg})
    return cfg


def _check_json(data, depth: int = 0) -> None:
    """Refuse what JSON can carry but no request needs: nesting past MAX_JSON_DEPTH, lone surrogates."""
    if depth > MAX_JSON_DEPTH:
        raise BadRequest(f"the request body is nested more than {MAX_JSON_DEPTH} levels deep")
    if isinstance(data, dict):
        for k, v in data.items():
            _check_json(k, depth + 1)
            _check_json(v, depth + 1)
    elif isinstance(data, list):
        for v in data:
            _check_json(v, depth + 1)
    elif isinstance(data, str):
        try:
            data.encode("utf-8")
        except UnicodeEncodeError:
            raise BadRequest("the request body holds a string that is not valid Unicode (a lone surrogate)") from None


def _key(obj) -> str:
    return hashlib.sha1(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def fixed_key(cfg: Config) -> str:
    """What draws the fixed pattern: the seed, the size and each map's inputs (sensor.fixed_pattern_inputs)."""
    inputs = {name: _dump(v) for name, v in fixed_pattern_inputs(cfg).items()}
    return _key({"seed": cfg.seed, "size": [cfg.sensor.width, cfg.sensor.height], **inputs})


def _dump(value):
    if hasattr(value, "model_dump"):
        return value.model_dump(mode="json")
    if isinstance(value, tuple):
        return [_dump(v) for v in value]
    return value


def exposure_key(cfg: Config, scene: str) -> str:
    """What the mean charge depends on beyond the fixed pattern."""
    d = cfg.model_dump(mode="json")
    return _key({"fixed": fixed_key(cfg), "scene": scene, "scene_cfg": d["scene"], "sensor": d["sensor"],
                 "exposure": d["exposure"], "crosstalk": d["crosstalk"], "shot": d["shot_noise"]["enabled"]})


class _Lru:
    """A small least-recently-used cache, safe across threads (the value is made outside its lock).

    At most ``size`` items and, with ``weigh``, at most ``max_bytes`` by their
    weights (the newest item is always kept, whatever it weighs).
    """

    def __init__(self, size: int, max_bytes: int | None = None, weigh=None):
        self.size = size
        self.max_bytes = max_bytes
        self.weigh = weigh
        self._items: OrderedDict = OrderedDict()
        self._weights: dict = {}
        self._lock = threading.Lock()

    def get_or(self, key, make):
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        value = make()
        weight = self.weigh(value) if self.weigh else 0
        with self._lock:
            self._items[key] = value
            self._weights[key] = weight
            while len(self._items) > self.size or (
                    self.max_bytes is not None and len(self._items) > 1 and self.nbytes() > self.max_bytes):
                old, _ = self._items.popitem(last=False)
                self._weights.pop(old, None)
        return value

    def nbytes(self) -> int:
        return sum(self._weights.values())


def _cache_budget() -> int:
    """Bytes the sensor cache may hold: a quarter of the memory available at start, at most 4 GB."""
    avail = footprint.available_bytes()
    return int(min(4e9, 0.25 * avail)) if avail else int(1e9)


def _sensor_weight(sensor: Sensor) -> int:
    """A cached sensor's maps, bytes (the workbench keeps the dark map's draws: keep_draws=True)."""
    return footprint.sensor_bytes(sensor.config, keep_draws=True)


# ------------------------------------------------------------------ the work
class Workbench:
    """Sensors, exposures and pictures for the page, with caches; thread-safe (one lock)."""

    def __init__(self, folder: Path, base: Config, scene: str | None = None):
        self.folder = Path(folder)
        self.base = base
        self.scene = scene or base.scene.source
        self.uploads: OrderedDict[str, dict] = OrderedDict()
        self.served: dict[str, int] = {}  # requests that did work, by endpoint (the tests read it at /api/stats)
        budget = _cache_budget()
        self._sensors = _Lru(4, max_bytes=budget, weigh=_sensor_weight)
        self._signals = _Lru(4)
        self._exposures = _Lru(6)
        self._masters = _Lru(4)
        self._figures = _Lru(8)
        self._last: Sensor | None = None  # the last sensor made: its maps are reused where their inputs did not change
        self.lock = threading.Lock()  # pictures, one at a time (the kernel uses every core)
        self.figures_lock = threading.Lock()  # figures beside them: never in a picture's way
        self.latest: dict[str, int] = {}

    # scenes: built-in names, or uploads stored here; never a path from the page
    def scene_source(self, scene: str) -> str:
        if not isinstance(scene, str) or not scene:
            raise BadRequest("scene must be a built-in name or an uploaded image")
        if scene.startswith("upload:"):
            item = self.uploads.get(scene[7:])
            if item is None:
                raise BadRequest(f"no uploaded scene {scene[7:]!r} (uploads last as long as the server)", 404)
            return str(item["path"])
        if not scene_mod.is_builtin(scene):
            raise BadRequest(f"scene {scene!r}: use a built-in ({', '.join(scene_mod.BUILTINS)}) or upload an image")
        return scene

    def add_upload(self, data: bytes, filename: str) -> dict:
        """Store an uploaded image (checked: size, decoded size, decodable) and return its id."""
        if len(data) > MAX_UPLOAD:
            raise BadRequest(f"the upload is {len(data) / 1e6:.1f} MB; images up to {MAX_UPLOAD / 1e6:g} MB are taken", 413)
        suffix = Path(filename or "image").suffix.lower()
        if suffix not in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".npy", ".bmp", ".webp"):
            raise BadRequest(f"upload {filename!r}: use a PNG, JPEG, TIFF, BMP, WebP or .npy image", 415)
        uid = secrets.token_hex(8)
        path = self.folder / f"upload-{uid}{suffix}"
        path.write_bytes(data)
        try:  # refuses bombs from the header, then decodes once to check
            scene_mod.load_file(path, max_pixels=min(scene_mod.MAX_SCENE_PIXELS, MAX_UPLOAD_PIXELS))
        except CmosnoiseError as exc:
            path.unlink(missing_ok=True)
            msg = str(exc).replace(str(path), filename or "upload")
            raise BadRequest(msg, 413 if "megapixels" in msg else 400) from None
        self.uploads[uid] = {"path": path, "name": Path(filename or "image").name, "bytes": len(data)}
        self._trim_uploads(keep=uid)
        return {"id": uid, "scene": f"upload:{uid}", "name": self.uploads[uid]["name"]}

    def upload_bytes(self) -> int:
        return sum(item["bytes"] for item in self.uploads.values())

    def _trim_uploads(self, keep: str) -> None:
        """The oldest uploads removed (never the start scene, nor ``keep``) until both caps hold."""
        pinned = {keep, self.scene[7:] if self.scene.startswith("upload:") else None}
        for uid in list(self.uploads):
            if len(self.uploads) <= MAX_UPLOADS and self.upload_bytes() <= MAX_UPLOADS_BYTES:
                break
            if uid in pinned:
                continue
            item = self.uploads.pop(uid)
            Path(item["path"]).unlink(missing_ok=True)

    def count(self, endpoint: str) -> None:
        self.served[endpoint] = self.served.get(endpoint, 0) + 1

    def cache_bytes(self) -> int:
        return self._sensors.nbytes()

    def sensor(self, cfg: Config) -> Sensor:
        """A sensor of ``cfg``: its fixed pattern from the cache, or drawn reusing the last sensor's unchanged maps."""
        def make():
            return Sensor(cfg, reuse=self._last, keep_draws=True)

        base = self._sensors.get_or(fixed_key(cfg), make)
        self._last = base
        return base if base.config == cfg else Sensor(cfg, fixed_pattern=base.fixed_pattern)

    def exposure(self, cfg: Config, scene: str) -> Exposure:
        sensor = self.sensor(cfg)
        source = self.scene_source(scene)
        key = exposure_key(cfg, scene)

        def make():
            sn = cfg.sensor  # what the scene's signal through the CFA depends on (not the temperature, say)
            sig_key = _key([source, sn.width, sn.height, sn.cfa, list(sn.channel_responsivity), cfg.scene.scale, cfg.scene.fit])
            signal = self._signals.get_or(sig_key, lambda: sensor.scene_signal(source))
            return Exposure(sensor, signal)

        return self._exposures.get_or(key, make).rebind(sensor)

    def master_dark(self, cfg: Config, region) -> np.ndarray | None:
        n = cfg.processing.dark_frames
        if n <= 0:
            return None
        key = _key([exposure_key(cfg, "flat:0"), n, list(region), cfg.model_dump(mode="json")])

        def make():
            dark = self.sensor(cfg).expose("flat:0", sequence=SEQ_DARK_CALIBRATION)
            return calibration.master_dark(dark.frame(k, region=region) for k in range(n))

        return self._masters.get_or(key, make)

    def picture(self, cfg: Config, scene: str, view: str, frame: int, region, step: int) -> tuple[np.ndarray, dict]:
        """An 8-bit picture of ``region`` (row0, row1, col0, col1) of frame ``frame``, one pixel per ``step`` sensor pixels."""
        if view not in VIEWS:
            raise BadRequest(f"view {view!r}: use one of {', '.join(VIEWS)}")
        rows, cols = cfg.sensor.height, cfg.sensor.width
        r0, r1, c0, c1 = _clip_region(region, rows, cols)
        # extend by the margin and align to the CFA's 2 x 2 cell (the pattern's phase is kept)
        e0, e1 = max(0, (r0 - MARGIN) // 2 * 2), min(rows, r1 + MARGIN)
        f0, f1 = max(0, (c0 - MARGIN) // 2 * 2), min(cols, c1 + MARGIN)
        t0 = time.perf_counter()
        shot = self.exposure(cfg, scene)
        t1 = time.perf_counter()
        raw = shot.frame(frame, region=(e0, e1, f0, f1))
        t2 = time.perf_counter()
        sensor = shot.sensor
        info = sensor.raw_info()
        half = step >= 2 and view != "raw"
        if view == "raw":
            t = sensor.transfer
            img = np.clip((raw.astype(np.float32) - t.black_level_dn) / max(t.max_code - t.black_level_dn, 1), 0, 1)
            img = (img ** (1 / 2.2) * 255 + 0.5).astype(np.uint8)
        else:
            master = self.master_dark(cfg, (e0, e1, f0, f1)) if view == "processed" else None
            proc = Processor(cfg.processing, info, master)
            img = proc.render(raw, pre=(view == "pre"), half=half)
        # back to the region asked for (in the picture's own pixels), then down to one pixel per step
        scale = 2 if half else 1
        a0, a1 = (r0 - e0) // scale, (r1 - e0) // scale
        b0, b1 = (c0 - f0) // scale, (c1 - f0) // scale
        img = img[a0:a1, b0:b1]
        img = _bin(img, max(1, step // scale))
        t3 = time.perf_counter()
        return np.ascontiguousarray(img), {"region": [r0, r1, c0, c1], "step": step,
                                           "ms_parts": {"sensor_exposure": round(1000 * (t1 - t0), 1),
                                                        "frame": round(1000 * (t2 - t1), 1),
                                                        "picture": round(1000 * (t3 - t2), 1)}}

    def raw(self, cfg: Config, scene: str, frame: int) -> np.ndarray:
        return self.exposure(cfg, scene).frame(frame)

    def figures(self, cfg: Config, scene: str) -> dict:
        """Key figures, the noise budget and the dark-current figures of a pane (cached per configuration)."""
        from ..analysis import noise_budget, white_pixels

        key = _key([cfg.model_dump(mode="json"), scene])

        def make():
            sensor = self.sensor(cfg)
            kf = noise_budget.key_figures(sensor)
            shot = self.exposure(cfg, scene)
            b = noise_budget.budget(sensor, photo_e=shot.photo_mean_e)
            out = {"key_figures": kf, "budget": {"temporal_e": b["temporal_rms_e"], "fixed_e": b["fixed_pattern_rms_e"],
                                                 "temporal_total_e": b["temporal_total_e"],
                                                 "fixed_total_e": b["fixed_pattern_total_e"]}}
            state, rate = sensor.dark_state, sensor.dark_rate
            if state is not None:
                out["dark"] = {"mean_e_per_s": float(rate.mean()), "threshold_e_per_s": state.threshold}
                if state.threshold is not None:
                    rep = white_pixels.report(rate, state.threshold, sensor.cfa)
                    out["dark"].update({k: rep[k] for k in rep if isinstance(rep[k], (int, float))})
            return out

        return self._figures.get_or(key, make)

    def couplets(self, cfg: Config, region) -> list:
        """Couplets of the dark map (both white pixels) inside ``region``: [[r1, c1, r2, c2], ...]."""
        from ..analysis import white_pixels

        sensor = self.sensor(cfg)
        state, rate = sensor.dark_state, sensor.dark_rate
        if state is None or state.threshold is None:
            return []
        r0, r1, c0, c1 = _clip_region(region, *sensor.shape)
        pairs = white_pixels.couplet_pairs(rate > state.threshold, sensor.cfa)
        inside = [(int(a[0]), int(a[1]), int(b[0]), int(b[1])) for a, b in pairs
                  if r0 <= a[0] < r1 and c0 <= a[1] < c1]
        return inside[:2000]


def _clip_region(region, rows: int, cols: int) -> tuple[int, int, int, int]:
    try:
        r0, r1, c0, c1 = (int(v) for v in region)
    except (TypeError, ValueError, OverflowError):
        raise BadRequest("region must be [row0, row1, col0, col1] of whole numbers") from None
    r0, c0 = max(0, min(r0, rows - 1)), max(0, min(c0, cols - 1))
    r1, c1 = max(r0 + 1, min(r1, rows)), max(c0 + 1, min(c1, cols))
    return r0, r1, c0, c1


def _bin(img: np.ndarray, f: int) -> np.ndarray:
    """Mean over f x f blocks (the last partial blocks dropped)."""
    if f <= 1:
        return img
    r, c = img.shape[0] // f * f, img.shape[1] // f * f
    if r == 0 or c == 0:
        return img[:1, :1]
    shape = (r // f, f, c // f, f) + img.shape[2:]
    return (img[:r, :c].reshape(shape).mean(axis=(1, 3)) + 0.5).astype(np.uint8)


# ------------------------------------------------------------------ the web application
def create_app(bench: Workbench, allowed_hosts: tuple[str, ...] = LOOPBACK):
    """The Starlette application serving the page and its API around ``bench``."""
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.middleware.trustedhost import TrustedHostMiddleware
    from starlette.requests import Request
    from starlette.responses import JSONResponse, PlainTextResponse, Response
    from starlette.routing import Route

    static = resources.files("cmosnoise.app") / "static"
    files = {"/": ("explore.html", "text/html; charset=utf-8"), "/explore.js": ("explore.js", "text/javascript"),
             "/explore.css": ("explore.css", "text/css")}

    def secured(resp: Response) -> Response:
        resp.headers["Content-Security-Policy"] = CSP
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Referrer-Policy"] = "no-referrer"
        resp.headers["Cache-Control"] = "no-store"
        return resp

    async def page(request: Request):
        name, media = files[request.url.path]
        return secured(Response((static / name).read_bytes(), media_type=media))

    async def body(request: Request, limit: int) -> bytes:
        declared = request.headers.get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            raise BadRequest(f"request body of {int(declared) / 1e6:.1f} MB; at most {limit / 1e6:g} MB", 413)

        async def read() -> bytes:
            chunks, size = [], 0
            async for chunk in request.stream():
                size += len(chunk)
                if size > limit:
                    raise BadRequest(f"request body larger than {limit / 1e6:g} MB", 413)
                chunks.append(chunk)
            return b"".join(chunks)

        try:  # a body sent a byte at a time holds a connection and a task: it has BODY_TIMEOUT_S in all
            return await asyncio.wait_for(read(), BODY_TIMEOUT_S)
        except asyncio.TimeoutError:
            raise BadRequest(f"the request body took longer than {BODY_TIMEOUT_S:g} s to arrive", 408) from None

    async def json_body(request: Request) -> dict:
        raw = await body(request, MAX_BODY)
        try:
            data = json.loads(raw)
        except RecursionError:
            raise BadRequest(f"the request body is nested more than {MAX_JSON_DEPTH} levels deep") from None
        except (ValueError, UnicodeDecodeError):
            raise BadRequest("the request body is not JSON") from None
        if not isinstance(data, dict):
            raise BadRequest("the request body must be a JSON object")
        _check_json(data)
        return data

    def same_origin(request: Request, endpoint: str, media: str) -> None:
        """Refuse, before any work, a request that does not come from the page itself (see the module docstring)."""
        site = request.headers.get("sec-fetch-site")
        if site is not None and site not in ("same-origin", "none"):
            raise BadRequest(f"refused: a {site} request (the explorer answers only its own page)", 403)
        origin = request.headers.get("origin")
        if origin is not None and origin != f"{request.url.scheme}://{request.headers.get('host', '')}":
            raise BadRequest("refused: the request comes from another origin (the explorer answers only its own page)", 403)
        if request.headers.get(CSRF_HEADER) != "1":
            raise BadRequest(f"refused: the request lacks the header {CSRF_HEADER.title()}: 1 that the explorer's page "
                             "sends", 403)
        ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
        if ctype != media:
            raise BadRequest(f"{endpoint} takes {media}, not {ctype or 'a body without a content type'}", 415)

    def errors(func, media: str | None = None):
        async def wrapped(request: Request):
            try:
                if request.method == "POST":
                    same_origin(request, request.url.path, media or "application/json")
                    bench.count(request.url.path)
                return secured(await func(request))
            except BadRequest as exc:
                return secured(JSONResponse({"error": exc.message, "errors": exc.errors}, status_code=exc.status))
            except CmosnoiseError as exc:
                return secured(JSONResponse({"error": " ".join(str(exc).split())[:400], "errors": {}}, status_code=422))
        return wrapped

    def run_locked(lock, func, *args):
        with lock:
            return func(*args)

    async def in_thread(func, *args, lock=None):
        from starlette.concurrency import run_in_threadpool

        return await run_in_threadpool(run_locked, lock or bench.lock, func, *args)

    @errors
    async def stats(request: Request):
        """What the server did and holds: requests that did work, uploads, cache bytes (read by the tests)."""
        return JSONResponse({"served": dict(bench.served), "uploads": len(bench.uploads),
                             "upload_bytes": bench.upload_bytes(), "sensor_cache_bytes": bench.cache_bytes()})

    @errors
    async def meta(request: Request):
        return JSONResponse({"fields": fields(), "presets": preset_names(), "scenes": list(scene_mod.BUILTINS),
                             "base": bench.base.model_dump(mode="json"), "scene": bench.scene,
                             "limits": {"upload_mb": MAX_UPLOAD / 1e6, "sensor_mp": MAX_SENSOR_PIXELS / 1e6}})

    @errors
    async def preset(request: Request):
        name = request.query_params.get("name", "")
        if name not in preset_names():
            raise BadRequest(f"unknown preset {name!r}", 404)
        cfg = physics.check(resolve_config(preset=name))
        return JSONResponse({"config": cfg.model_dump(mode="json"), "scene": preset_data(name).get("scene", {}).get("source")})

    @errors
    async def check(request: Request):
        data = await json_body(request)
        cfg = validate(data.get("config"))
        return JSONResponse({"ok": True, "config": cfg.model_dump(mode="json")})

    @errors
    async def render(request: Request):
        t_in = time.perf_counter()
        data = await json_body(request)
        pane, seq = str(data.get("pane", "A"))[:8], data.get("seq", 0)
        if not isinstance(seq, int):
            raise BadRequest("seq must be an integer")
        client = str(data.get("client", ""))[:40]
        token = f"{client}/{pane}"
        bench.latest[token] = max(bench.latest.get(token, -1), seq)
        cfg = validate(data.get("config"))
        frame, step = data.get("frame", 0), data.get("step", 1)
        if not isinstance(frame, int) or not 0 <= frame <= 2**32 - 1:
            raise BadRequest("frame must be a whole number from 0 to 4294967295")
        if not isinstance(step, int) or not 1 <= step <= 64:
            raise BadRequest("step must be a whole number from 1 to 64")
        region = data.get("region") or [0, cfg.sensor.height, 0, cfg.sensor.width]
        r0, r1, c0, c1 = _clip_region(region, cfg.sensor.height, cfg.sensor.width)
        if max(r1 - r0, c1 - c0) / step > MAX_OUT_SIDE:
            raise BadRequest(f"the picture would be larger than {MAX_OUT_SIDE} pixels a side: use a larger step")

        def work():
            if bench.latest.get(token, -1) > seq:  # a newer request of this pane is waiting: drop this one
                return None
            t0 = time.perf_counter()
            img, info = bench.picture(cfg, scene_of(data), str(data.get("view", "pre")), frame,
                                      (r0, r1, c0, c1), step)
            info["ms"] = round(1000 * (time.perf_counter() - t0), 1)
            if data.get("couplets"):
                info["couplets"] = bench.couplets(cfg, (r0, r1, c0, c1))
            return img, info

        result = await in_thread(work)
        if result is None:  # not an error: a newer request of this pane came in (a browser logs 4xx as errors)
            return Response(status_code=204, headers={"X-Dropped": "a newer request of this pane came in"})
        img, info = result
        # raw 8-bit RGBA, what the page's ImageData takes as it is: encoding a PNG would cost more than the
        # picture (75 ms at 960 x 540), and this is loopback
        rgba = np.empty(img.shape[:2] + (4,), np.uint8)
        rgba[..., :3] = img[..., :3] if img.ndim == 3 else img[..., None]
        rgba[..., 3] = 255
        info["shape"] = list(rgba.shape)
        info["ms_handler"] = round(1000 * (time.perf_counter() - t_in), 1)
        return Response(rgba.tobytes(), media_type="application/octet-stream", headers={"X-Render": json.dumps(info)})

    @errors
    async def figures_route(request: Request):
        data = await json_body(request)
        cfg = validate(data.get("config"))
        scene = scene_of(data)
        bench.scene_source(scene)
        return JSONResponse(await in_thread(bench.figures, cfg, scene, lock=bench.figures_lock))

    @errors
    async def raw_route(request: Request):
        """Frame k of a pane as .npy (uint16 DN), whole: what ``cmosnoise simulate`` with the exported config writes."""
        data = await json_body(request)
        cfg = validate(data.get("config"))
        frame = data.get("frame", 0)
        if not isinstance(frame, int) or frame < 0:
            raise BadRequest("frame must be a whole number >= 0")
        raw = await in_thread(bench.raw, cfg, scene_of(data), frame)
        buf = io.BytesIO()
        np.save(buf, raw, allow_pickle=False)
        return Response(buf.getvalue(), media_type="application/octet-stream")

    def scene_of(data: dict) -> str:
        scene = data.get("scene") or bench.scene
        if not isinstance(scene, str):
            raise BadRequest("scene must be a built-in name or an uploaded image's id (a string)")
        return scene

    async def upload(request: Request):
        data = await body(request, MAX_UPLOAD)
        name = request.headers.get("x-filename", "image.png")[:200]
        return JSONResponse(await in_thread(bench.add_upload, data, name))

    upload = errors(upload, "application/octet-stream")

    @errors
    async def to_yaml(request: Request):
        data = await json_body(request)
        cfg = validate(data.get("config"))
        scene = scene_of(data)
        if scene.startswith("upload:") and scene[7:] in bench.uploads:
            cfg = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"source": bench.uploads[scene[7:]]["name"]})})
        else:
            cfg = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"source": bench.scene_source(scene)})})
        return PlainTextResponse(cfg.to_yaml(), media_type="application/x-yaml")

    @errors
    async def from_yaml(request: Request):
        text = (await json_body(request)).get("yaml")
        if not isinstance(text, str):
            raise BadRequest("the body must be {\"yaml\": \"the configuration's text\"}")
        try:
            data = load_yaml_text(text)
        except Exception as exc:  # yaml's errors: one line
            raise BadRequest(f"not a valid configuration YAML: {' '.join(str(exc).split())[:200]}") from None
        cfg = validate(data if data is not None else {})
        return JSONResponse({"config": cfg.model_dump(mode="json")})

    routes = [Route(path, page) for path in files] + [
        Route("/api/meta", meta), Route("/api/stats", stats), Route("/api/preset", preset), Route("/api/check", check, methods=["POST"]),
        Route("/api/render", render, methods=["POST"]), Route("/api/figures", figures_route, methods=["POST"]),
        Route("/api/raw", raw_route, methods=["POST"]), Route("/api/upload", upload, methods=["POST"]),
        Route("/api/yaml", to_yaml, methods=["POST"]), Route("/api/load", from_yaml, methods=["POST"]),
    ]
    hosts = sorted({h.strip("[]") for h in allowed_hosts} | {h for h in allowed_hosts})
    return Starlette(routes=routes, middleware=[Middleware(TrustedHostMiddleware, allowed_hosts=hosts)])


class _RateLimited(logging.Filter):
    """At most ``limit`` records every ``window_s`` seconds; the next one let through says how many were dropped."""

    def __init__(self, limit: int = 20, window_s: float = 10.0):
        super().__init__()
        self.limit, self.window_s = limit, window_s
        self.start, self.count, self.dropped = time.monotonic(), 0, 0

    def filter(self, record: logging.LogRecord) -> bool:
        now = time.monotonic()
        if now - self.start > self.window_s:
            self.start, self.count = now, 0
        self.count += 1
        if self.count > self.limit:
            self.dropped += 1
            return False
        if self.dropped:
            record.msg = f"{record.msg} ({self.dropped} similar messages dropped)"
            self.dropped = 0
        return True


def _guarded_h11():
    """uvicorn's h11 protocol with a header timeout: a connection that has not sent a whole request's headers
    within HEADER_TIMEOUT_S of opening (or of its last response) is closed. uvicorn has no such setting; its
    keep-alive timeout starts only after a first response, so idle or trickling connections were kept forever."""
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class GuardedH11(H11Protocol):
        def connection_made(self, transport):
            super().connection_made(transport)
            self._idle_since = self.loop.time()
            self._guard = self.loop.call_later(1.0, self._check_idle)

        def _check_idle(self):
            waiting = self.cycle is None or self.cycle.response_complete
            if not waiting:  # a request is being answered: its body has its own timeout
                self._idle_since = self.loop.time()
            elif self.loop.time() - self._idle_since > HEADER_TIMEOUT_S:
                self.transport.close()
                return
            self._guard = self.loop.call_later(1.0, self._check_idle)

        def connection_lost(self, exc):
            self._guard.cancel()
            super().connection_lost(exc)

    return GuardedH11


def _raise_file_limit() -> None:
    """The soft limit on open files raised to the hard one: many idle connections must not use up descriptors."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = max(soft, 65536) if hard == resource.RLIM_INFINITY else hard
    if soft < target:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))


def serve(base: Config, scene: str | None, host: str = "127.0.0.1", port: int = 8765, open_browser: bool = True,
          say=print) -> None:
    """Run the explorer until Ctrl-C (or SIGTERM); its temporary folder is removed on the way out.

    The base configuration and the start scene are checked as every request
    would check them, before the server starts: a setting every request would
    refuse is one line and exit status 2, not a page that shows only errors.
    """
    import uvicorn

    try:
        validate(base.model_dump(mode="json"))
    except BadRequest as exc:
        raise CmosnoiseError(f"explore: {exc.message}") from None
    with tempfile.TemporaryDirectory(prefix="cmosnoise-explore-") as tmp:
        bench = Workbench(Path(tmp), base)
        try:
            if scene is not None:
                if Path(scene).exists() or Path(scene).is_symlink():  # a path: taken in as an upload
                    item = bench.add_upload(inputs.read_bytes(scene, "--scene", MAX_UPLOAD), Path(scene).name)
                    bench.scene = item["scene"]
                else:
                    bench.scene = bench.scene_source(scene)
            else:
                bench.scene_source(bench.scene)
        except BadRequest as exc:
            raise CmosnoiseError(f"--scene {scene if scene is not None else bench.scene}: {exc.message}") from None
        hosts = LOOPBACK if host in LOOPBACK else (*LOOPBACK, host)
        app = create_app(bench, hosts)
        url = f"http://{'127.0.0.1' if host in ('0.0.0.0', '::') else host}:{port}/"
        if host not in LOOPBACK:
            say(f"warning: serving on {host}:{port}: anyone who can reach this port can use the explorer "
                "(and the machine's CPU); there is no login")
        say(f"cmosnoise explore: {url} (Ctrl-C to stop)")
        if open_browser:
            import webbrowser

            threading.Timer(1.0, lambda: webbrowser.open(url)).start()
        _raise_file_limit()
        limiter = _RateLimited()
        for name in ("uvicorn.error", "uvicorn"):
            logging.getLogger(name).addFilter(limiter)
        config = uvicorn.Config(app, host=host, port=port, log_level="warning", access_log=False, http=_guarded_h11())
        server = uvicorn.Server(config)
        server.run()
