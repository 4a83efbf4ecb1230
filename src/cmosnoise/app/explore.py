"""``cmosnoise explore``: a local web page where any parameter's effect shows on the picture at once, two panes side by side.

The server (Starlette, run by uvicorn) renders only what the page shows: a
region of frame k of a pane's sensor, at the zoom the page asks for. The work
itself, and what is kept between requests, is the
:class:`~cmosnoise.app.workbench.Workbench`'s; this module is the HTTP side
and its safety.

Its owner alone: a random token made at start (:func:`new_token`) is in the address the command opens and
writes to a file of the owner's; every route but the page's files refuses a request without it (a cookie after
the first page load, or the ``X-Cmosnoise-Token`` header), and a file key names no file the page did not upload
(:func:`~cmosnoise.app.workbench.client_files`).

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
frames and pages, from the header), sensor size, output size and the pattern
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
import io
import json
import logging
import math
import os
import secrets
import tempfile
import threading
import time
from importlib import resources
from pathlib import Path

import numpy as np
from starlette.requests import Request
from starlette.responses import JSONResponse, PlainTextResponse, RedirectResponse, Response

from .. import inputs
from ..config import Config
from ..config.explain import fields
from ..config.loading import load_config, load_yaml_text, preset_data, preset_names
from ..errors import CmosnoiseError
from ..model import scene as scene_mod
from ..model.spec import resolve
from .workbench import MAX_SENSOR_PIXELS, MAX_UPLOAD, BadRequest, Workbench, _clip_region, validate

#: limits: request bodies, picture sent per request (the workbench bounds uploads and sensors)
MAX_BODY = 1_000_000
MAX_OUT_SIDE = 4096
#: seconds a pane's newest request number stays the mark that older ones are dropped against
LATEST_S = 10.0
#: seconds a connection may take to send a request's headers, and a request's body
HEADER_TIMEOUT_S = 10.0
BODY_TIMEOUT_S = 30.0
#: the header a script may give the explorer's token in (the page itself carries it as a cookie)
TOKEN_HEADER = "x-cmosnoise-token"
#: the environment variable that sets the token (a script's or a test's; a new random one otherwise)
TOKEN_ENV = "CMOSNOISE_EXPLORE_TOKEN"
#: what a browser without the token is shown
LOGIN_PAGE = ("<!doctype html><meta charset=utf-8><title>cmosnoise explore</title><p>This explorer answers only "
              "the address <code>cmosnoise explore</code> opened or wrote, which carries its token. Open that "
              "address (or the file the command named) in this browser.</p>")
#: JSON bodies nested deeper than this are refused
MAX_JSON_DEPTH = 32
#: the custom header every state-changing request carries (a cross-site page cannot send it without a preflight)
CSRF_HEADER = "x-cmosnoise"
LOOPBACK = ("127.0.0.1", "localhost", "::1", "[::1]")
CSP = ("default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; connect-src 'self'; "
       "object-src 'none'; base-uri 'none'; frame-ancestors 'none'; form-action 'none'")


def new_token() -> str:
    """A token no one can guess: 32 random bytes from :mod:`secrets`, URL-safe (43 characters).

    Returns
    -------
    str
    """
    return secrets.token_urlsafe(32)


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



# ------------------------------------------------------------------ the web application
def create_app(bench: Workbench, allowed_hosts: tuple[str, ...] = LOOPBACK, token: str | None = None):
    """The Starlette application serving the page and its API around ``bench``.

    ``token`` (default: a new one from :func:`new_token`) is asked of every request but the page's own files: a
    ``?token=`` on the page's address (answered by a redirect that sets it as a cookie of this port), that cookie,
    or an ``X-Cmosnoise-Token`` header."""
    return _Explorer(bench, token or new_token()).app(allowed_hosts)


class _Explorer:
    """The HTTP side of a workbench: its page, its token, the checks every request passes, one method a route."""

    #: the routes that do work, each (path, method name, HTTP method, the body's media type)
    ROUTES = (("/api/meta", "meta", "GET", None), ("/api/stats", "stats", "GET", None),
              ("/api/preset", "preset", "GET", None), ("/api/check", "check", "POST", None),
              ("/api/render", "render", "POST", None), ("/api/figures", "figures_route", "POST", None),
              ("/api/quality", "quality_route", "POST", None), ("/api/raw", "raw_route", "POST", None),
              ("/api/upload", "upload", "POST", "application/octet-stream"), ("/api/yaml", "to_yaml", "POST", None),
              ("/api/load", "from_yaml", "POST", None))

    def __init__(self, bench: Workbench, token: str):
        self.bench, self.token = bench, token
        self.static = resources.files("cmosnoise.app") / "static"
        self.files = {"/": ("explore.html", "text/html; charset=utf-8"),
                      "/explore.js": ("explore.js", "text/javascript"), "/explore.css": ("explore.css", "text/css")}

    def app(self, allowed_hosts: tuple[str, ...]):
        """The Starlette application: the page's files, the routes of :data:`ROUTES`, the host check."""
        from starlette.applications import Starlette
        from starlette.middleware import Middleware
        from starlette.middleware.trustedhost import TrustedHostMiddleware
        from starlette.routing import Route

        routes = [Route(path, self.page) for path in self.files] + [
            Route(path, self.errors(getattr(self, name), media), methods=[method])
            for path, name, method, media in self.ROUTES]
        hosts = sorted({h.strip("[]") for h in allowed_hosts} | {h for h in allowed_hosts})
        return Starlette(routes=routes, middleware=[Middleware(TrustedHostMiddleware, allowed_hosts=hosts)])

    def cookie_name(self, request: Request) -> str:  # cookies are per host, not per port: two explorers keep theirs
        return f"cmosnoise-token-{request.url.port or 80}"

    def given_token(self, request: Request) -> str:
        return (request.headers.get(TOKEN_HEADER) or request.cookies.get(self.cookie_name(request))
                or request.query_params.get("token") or "")

    def authorised(self, request: Request) -> bool:
        return secrets.compare_digest(self.given_token(request).encode("utf-8", "replace"), self.token.encode())

    def secured(self, resp: Response) -> Response:
        resp.headers["Content-Security-Policy"] = CSP
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Referrer-Policy"] = "no-referrer"
        resp.headers["Cache-Control"] = "no-store"
        return resp

    async def page(self, request: Request):
        name, media = self.files[request.url.path]
        if name == "explore.html":
            if "token" in request.query_params and self.authorised(request):
                # the address the command opened: its token becomes this port's cookie, and leaves the address
                from urllib.parse import urlencode

                rest = urlencode([(k, v) for k, v in request.query_params.multi_items() if k != "token"])
                resp = RedirectResponse("/" + (f"?{rest}" if rest else ""), status_code=303)
                resp.set_cookie(self.cookie_name(request), self.token, httponly=True, samesite="strict", path="/")
                return self.secured(resp)
            if not self.authorised(request):
                return self.secured(Response(LOGIN_PAGE, status_code=403, media_type="text/html; charset=utf-8"))
        return self.secured(Response((self.static / name).read_bytes(), media_type=media))

    async def body(self, request: Request, limit: int) -> bytes:
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

    async def json_body(self, request: Request) -> dict:
        raw = await self.body(request, MAX_BODY)
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

    def same_origin(self, request: Request, endpoint: str, media: str) -> None:
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

    def errors(self, func, media: str | None = None):
        async def wrapped(request: Request):
            try:
                if not self.authorised(request):
                    raise BadRequest("refused: the request lacks this explorer's token (open the address "
                                     "cmosnoise explore gave)", 403)
                if request.method == "POST":
                    self.same_origin(request, request.url.path, media or "application/json")
                    self.bench.count(request.url.path)
                return self.secured(await func(request))
            except BadRequest as exc:
                return self.secured(JSONResponse({"error": exc.message, "errors": exc.errors}, status_code=exc.status))
            except CmosnoiseError as exc:
                return self.secured(JSONResponse({"error": " ".join(str(exc).split())[:400], "errors": {}}, status_code=422))
        return wrapped

    def run_locked(self, lock, func, *args):
        with lock:
            return func(*args)

    async def in_thread(self, func, *args, lock=None):
        from starlette.concurrency import run_in_threadpool

        return await run_in_threadpool(self.run_locked, lock or self.bench.lock, func, *args)

    async def stats(self, request: Request):
        """What the server did and holds: requests that did work, uploads, cache bytes (read by the tests)."""
        return JSONResponse({"served": dict(self.bench.served), "uploads": len(self.bench.uploads),
                             "upload_bytes": self.bench.upload_bytes(), "sensor_cache_bytes": self.bench.cache_bytes()})

    async def meta(self, request: Request):
        from ..analysis.figures_of_merit import FIGURE_NAMES
        from ..analysis.noise_budget import SOURCE_NAMES

        return JSONResponse({"fields": fields(), "presets": preset_names(), "scenes": list(scene_mod.BUILTINS),
                             "names": {"figures": FIGURE_NAMES, "budget": SOURCE_NAMES},
                             "base": self.bench.base.model_dump(mode="json"), "scene": self.bench.scene,
                             "limits": {"upload_mb": MAX_UPLOAD / 1e6, "sensor_mp": MAX_SENSOR_PIXELS / 1e6}})

    async def preset(self, request: Request):
        name = request.query_params.get("name", "")
        if name not in preset_names():
            raise BadRequest(f"unknown preset {name!r}", 404)
        cfg = resolve(load_config(preset=name)).config
        return JSONResponse({"config": cfg.model_dump(mode="json"), "scene": preset_data(name).get("scene", {}).get("source")})

    async def check(self, request: Request):
        data = await self.json_body(request)
        cfg = self.bench.validate(data.get("config")).config
        return JSONResponse({"ok": True, "config": cfg.model_dump(mode="json")})

    async def render(self, request: Request):
        t_in = time.perf_counter()
        data = await self.json_body(request)
        pane, seq = str(data.get("pane", "A"))[:8], data.get("seq", 0)
        if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < 2**53:
            raise BadRequest("seq must be a whole number from 0 to 2**53 - 1 (the page's count of its requests)")
        client = str(data.get("client", ""))[:40]
        pane_key = f"{client}/{pane}"
        now = time.monotonic()
        newest, since = self.bench.latest.get(pane_key, (-1, 0.0))
        if seq >= newest or now - since > LATEST_S:  # a newest seq holds only while it is recent: one huge seq
            self.bench.latest[pane_key] = (seq, now)          # cannot make the pane's later requests look old for ever
        spec = self.bench.validate(data.get("config"))
        rows, cols = spec.shape
        frame, step = data.get("frame", 0), data.get("step", 1)
        if not isinstance(frame, int) or not 0 <= frame <= 2**32 - 1:
            raise BadRequest("frame must be a whole number from 0 to 4294967295")
        if not isinstance(step, int) or not 1 <= step <= 64:
            raise BadRequest("step must be a whole number from 1 to 64")
        r0, r1, c0, c1 = _clip_region(data.get("region") or [0, rows, 0, cols], rows, cols)
        if max(r1 - r0, c1 - c0) / step > MAX_OUT_SIDE:
            raise BadRequest(f"the picture would be larger than {MAX_OUT_SIDE} pixels a side: use a larger step")

        def work():
            if self.bench.latest.get(pane_key, (-1, 0.0))[0] > seq:  # a newer request of this pane came in: drop this one
                return None
            t0 = time.perf_counter()
            img, info = self.bench.picture(spec, self.scene_of(data), str(data.get("view", "pre")), frame,
                                      (r0, r1, c0, c1), step)
            info["ms"] = round(1000 * (time.perf_counter() - t0), 1)
            if data.get("couplets"):
                info["couplets"] = self.bench.couplets(spec, (r0, r1, c0, c1))
            return img, info

        result = await self.in_thread(work)
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

    async def figures_route(self, request: Request):
        data = await self.json_body(request)
        spec = self.bench.validate(data.get("config"))
        scene = self.scene_of(data)
        self.bench.scene_source(scene)
        return JSONResponse(await self.in_thread(self.bench.figures, spec, scene, lock=self.bench.figures_lock))

    async def quality_route(self, request: Request):
        """A pane's image-quality metrics at the page's illuminance (:meth:`Workbench.quality`)."""
        data = await self.json_body(request)
        spec = self.bench.validate(data.get("config"))
        lux = data.get("lux")
        try:  # a 400-digit integer is a number JSON carries and a float cannot hold
            lux = None if isinstance(lux, bool) or not isinstance(lux, (int, float)) else float(lux)
        except OverflowError:
            lux = None
        if lux is None or not math.isfinite(lux):
            raise BadRequest("lux must be a finite number (the illuminance on the charts, lux)")
        return JSONResponse(await self.in_thread(self.bench.quality, spec, lux, lock=self.bench.figures_lock))

    async def raw_route(self, request: Request):
        """Frame k of a pane as .npy (uint16 DN), whole: what ``cmosnoise simulate`` with the exported config writes."""
        data = await self.json_body(request)
        spec = self.bench.validate(data.get("config"))
        frame = data.get("frame", 0)
        if not isinstance(frame, int) or frame < 0:
            raise BadRequest("frame must be a whole number >= 0")
        raw = await self.in_thread(self.bench.raw, spec, self.scene_of(data), frame)
        buf = io.BytesIO()
        np.save(buf, raw, allow_pickle=False)
        return Response(buf.getvalue(), media_type="application/octet-stream")

    def scene_of(self, data: dict) -> str:
        scene = data.get("scene") or self.bench.scene
        if not isinstance(scene, str):
            raise BadRequest("scene must be a built-in name or an uploaded image's id (a string)")
        return scene

    async def upload(self, request: Request):
        data = await self.body(request, MAX_UPLOAD)
        name = request.headers.get("x-filename", "image.png")[:200]
        return JSONResponse(await self.in_thread(self.bench.add_upload, data, name))


    async def to_yaml(self, request: Request):
        data = await self.json_body(request)
        cfg = self.bench.validate(data.get("config")).config
        scene = self.scene_of(data)
        if scene.startswith("upload:") and scene[7:] in self.bench.uploads:
            cfg = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"source": self.bench.uploads[scene[7:]]["name"]})})
        else:
            cfg = cfg.model_copy(update={"scene": cfg.scene.model_copy(update={"source": self.bench.scene_source(scene)})})
        return PlainTextResponse(cfg.to_yaml(), media_type="application/x-yaml")

    async def from_yaml(self, request: Request):
        text = (await self.json_body(request)).get("yaml")
        if not isinstance(text, str):
            raise BadRequest("the body must be {\"yaml\": \"the configuration's text\"}")
        try:
            data = load_yaml_text(text)
        except Exception as exc:  # yaml's errors: one line
            raise BadRequest(f"not a valid configuration YAML: {' '.join(str(exc).split())[:200]}") from None
        cfg = self.bench.validate(data if data is not None else {}).config
        return JSONResponse({"config": cfg.model_dump(mode="json")})


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
        token = os.environ.get(TOKEN_ENV) or new_token()
        if len(token) < 16:
            raise CmosnoiseError(f"{TOKEN_ENV}: a token of {len(token)} characters; give at least 16 (or unset it "
                                 "for a random one)")
        app = create_app(bench, hosts, token)
        url = f"http://{'127.0.0.1' if host in ('0.0.0.0', '::') else host}:{port}/"
        address = Path(tmp) / "address.txt"  # the whole address, for the owner alone (the folder is 0700)
        address.write_text(f"{url}?token={token}\n")
        address.chmod(0o600)
        if host not in LOOPBACK:
            say(f"warning: serving on {host}:{port}: anyone who can reach this port and has the token can use the "
                "explorer (and the machine's CPU)")
        say(f"cmosnoise explore: {url}?token={token[:4]}... (the whole address, token and all, is in {address}, "
            "readable by you alone; Ctrl-C to stop)")
        if open_browser:
            import webbrowser

            threading.Timer(1.0, lambda: webbrowser.open(f"{url}?token={token}")).start()
        _raise_file_limit()
        limiter = _RateLimited()
        for name in ("uvicorn.error", "uvicorn"):
            logging.getLogger(name).addFilter(limiter)
        config = uvicorn.Config(app, host=host, port=port, log_level="warning", access_log=False, http=_guarded_h11())
        server = uvicorn.Server(config)
        server.run()
