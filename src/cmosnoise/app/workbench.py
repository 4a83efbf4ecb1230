"""The explorer's workbench: sensors, exposures, pictures and figures for the page, without HTTP.

:mod:`cmosnoise.app.explore` serves it; tests drive it directly. What does
not change between requests is kept: fixed-pattern maps and the exposure's
mean images in a :class:`~cmosnoise.model.fixed_pattern.PatternCache` (each
keyed by what it reads, so a temperature move redraws the dark map alone and
reuses the photo mean, and a temporal slider redraws nothing), master darks
and figures in small caches of their own.

Both panes use the same seed streams, so with the same parameters they give
the same picture, and with one parameter changed their difference is that
parameter's effect alone (common random numbers, ``docs/model.md`` section 1).
Every input is bounded: sensor size, uploads (each, their number and their
total bytes: the oldest go first), decoded images (all frames and pages,
from the header); the page never sends a path.
"""

from __future__ import annotations

import secrets
import threading
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from .. import inputs
from ..analysis import figures_of_merit as fom
from ..analysis import white_pixels
from ..config import Config, format_validation_error, load_config
from ..errors import CmosnoiseError
from ..isp import calibration
from ..isp.process import Processor
from ..model import footprint
from ..model import scene as scene_mod
from ..model.fixed_pattern import PatternCache
from ..model.seeds import SEQ_DARK_CALIBRATION
from ..model.sensor import Exposure, Sensor, region_of
from ..model.spec import SensorSpec, resolve

#: limits: uploads, decoded upload size, sensor size
MAX_UPLOAD = 50_000_000
MAX_UPLOAD_PIXELS = 50_000_000
MAX_SENSOR_PIXELS = 50_000_000
#: the dark frames a pane's master dark averages (each render holds the lock while they are made): at most this
#: many, and this many pixels of them in all (64 frames of a 3 MP sensor, about 2 s)
MAX_DARK_FRAMES = 256
MAX_DARK_PIXELS = 200_000_000
#: uploads kept at once, and their total bytes: past either the oldest upload is removed
MAX_UPLOADS = 16
MAX_UPLOADS_BYTES = 200_000_000
#: the region rendered is extended by this many pixels on each side (even: the CFA phase is kept), so that
#: demosaicing and defect correction see real neighbours at the viewport's edges
MARGIN = 4
VIEWS = ("raw", "pre", "processed")
#: the charts' frames a pane's image quality averages (a 640 x 480 default sensor's: about 0.2 s on 2 cores)
QUALITY_FRAMES = 8
#: the illuminances the page may ask quality at, lux (the measurement's own range)
from ..analysis.quality import LUX_RANGE as QUALITY_LUX  # noqa: E402


class BadRequest(Exception):
    """A request the server refuses: HTTP ``status``, a one-line ``message`` and per-field ``errors``."""

    def __init__(self, message: str, status: int = 400, errors: dict | None = None):
        super().__init__(message)
        self.message = " ".join(str(message).split())[:400]
        self.status = status
        self.errors = errors or {}


# ------------------------------------------------------------------ configuration
#: the configuration keys whose text may name a file, and the words each takes that are not files
FILE_KEYS = {("light", "illuminant"): "illuminant", ("light", "spectral_qe"): "camera",
             ("optics", "relative_illumination"): ("none", "cos4"), ("optics", "psf"): ("none", "diffraction", "gaussian"),
             ("optics", "chief_ray_angle"): (), ("optics", "angle_relative_qe"): ()}
#: what a table upload may be (a spectrum, a lens table, a PSF): stored as sent, read by the key's own reader
TABLE_SUFFIXES = (".csv", ".txt", ".tsv", ".fits", ".fit", ".fts")


def _is_name(value: str, words) -> bool:
    """Whether a file key's text is one of its words (an illuminant or camera set colour-science ships), not a
    file."""
    low = value.strip().lower()
    if words == "illuminant":
        from ..colour_lib import colour

        return low.startswith("blackbody") or low in {k.lower() for k in colour().SDS_ILLUMINANTS}
    if words == "camera":
        from ..colour_lib import colour

        return low in {k.lower() for k in colour().MSDS_CAMERA_SENSITIVITIES}
    return low in words


def client_files(data: dict, uploads: dict, base: Config) -> dict:
    """A page's configuration with every file key checked: a name it takes, the base configuration's own value
    (the owner's, from the command line), or ``upload:ID`` of a file this page uploaded (replaced by where the
    server stored it). Anything else would make the server read a file the requester names: BadRequest.

    Parameters
    ----------
    data : dict
        The configuration's sections, as the page sent them.
    uploads : dict
        The workbench's uploads (id -> {"path", ...}).
    base : Config
        The configuration the server was started with.

    Returns
    -------
    dict
        ``data`` with uploads' ids replaced by their stored paths (a copy where anything changed).
    """
    out = data
    for (section, key), words in FILE_KEYS.items():
        part = data.get(section)
        value = part.get(key) if isinstance(part, dict) else None
        if not isinstance(value, str) or _is_name(value, words) or value == getattr(getattr(base, section), key):
            continue
        if value.startswith("upload:") and value[7:] in uploads:
            out = {**out, section: {**out[section], key: str(uploads[value[7:]]["path"])}}
            continue
        msg = (f"{section}.{key} = {value[:80]!r}: the explorer reads no file a page names; upload it (a CSV, .npy "
               "or FITS file) and give upload:ID, or start the explorer with --set " f"{section}.{key}=FILE")
        raise BadRequest(msg, 422, {f"{section}.{key}": msg})
    return out


def validate(data) -> SensorSpec:
    """A pane's configuration (a full or partial dict) validated and resolved as the CLI does; BadRequest names
    each bad field. The workbench takes the :class:`SensorSpec` it returns (resolved once a request)."""
    if not isinstance(data, dict):
        raise BadRequest("config must be an object of sections")
    from pydantic import ValidationError

    try:
        cfg = load_config(extra=data)
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
    if cfg.sensor.width * cfg.sensor.height > MAX_SENSOR_PIXELS:
        msg = f"the explorer takes sensors up to {MAX_SENSOR_PIXELS / 1e6:g} MP; use cmosnoise simulate for larger ones"
        raise BadRequest(msg, 422, {"sensor.width": msg})
    n = cfg.processing.dark_frames
    if n > MAX_DARK_FRAMES or n * cfg.sensor.width * cfg.sensor.height > MAX_DARK_PIXELS:
        msg = (f"processing.dark_frames = {n}: the explorer averages at most {MAX_DARK_FRAMES} dark frames and "
               f"{MAX_DARK_PIXELS / 1e6:g} megapixels of them ({max(1, MAX_DARK_PIXELS // (cfg.sensor.width * cfg.sensor.height))} "
               "frames of this sensor); cmosnoise simulate --dark-frames takes more")
        raise BadRequest(msg, 422, {"processing.dark_frames": msg})
    try:
        return resolve(cfg)
    except CmosnoiseError as exc:
        raise BadRequest(str(exc), 422, {"config": str(exc)}) from None


def _cache_budget() -> int:
    """Bytes the pattern cache may hold: a quarter of the memory available at start, at most 4 GB."""
    avail = footprint.available_bytes()
    return int(min(4e9, 0.25 * avail)) if avail else int(1e9)


# ------------------------------------------------------------------ the work
class Workbench:
    """Sensors, exposures and pictures for the page, with caches; thread-safe (one lock)."""

    def __init__(self, folder: Path, base: Config, scene: str | None = None):
        self.folder = Path(folder)
        self.base = base
        self.scene = scene or base.scene.source
        self.uploads: OrderedDict[str, dict] = OrderedDict()
        self.served: dict[str, int] = {}  # requests that did work, by endpoint (the tests read it at /api/stats)
        #: fixed-pattern maps, scene signals and exposure products, each keyed by what it reads
        self.patterns = PatternCache(_cache_budget())
        self._masters = PatternCache(int(2e9), max_items=4)  # master darks of a viewport
        self._figures = PatternCache(int(1e8), max_items=8)  # figures of a pane's configuration and scene
        self.lock = threading.Lock()  # pictures, one at a time (the kernel uses every core)
        self.figures_lock = threading.Lock()  # figures beside them: never in a picture's way
        #: each pane's newest render request: (the page's number for it, when it came)
        self.latest: dict[str, tuple[int, float]] = {}

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
        if suffix not in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".npy", ".bmp", ".webp", *TABLE_SUFFIXES):
            raise BadRequest(f"upload {filename!r}: use a PNG, JPEG, TIFF, BMP, WebP or .npy image, or a CSV or "
                             "FITS table or PSF", 415)
        uid = secrets.token_hex(8)
        path = self.folder / f"upload-{uid}{suffix}"
        path.write_bytes(data)
        try:  # refuses bombs from the header, then decodes once to check (a table or a .npy PSF: its own reader,
            # through the input gate, when a key names it)
            if suffix == ".npy":
                inputs.read_npy(path, "upload", MAX_UPLOAD_PIXELS * 8)
            elif suffix not in TABLE_SUFFIXES:
                scene_mod.load_file(path, max_pixels=min(scene_mod.MAX_SCENE_PIXELS, MAX_UPLOAD_PIXELS))
        except CmosnoiseError as exc:
            path.unlink(missing_ok=True)
            msg = str(exc).replace(str(path), filename or "upload")
            raise BadRequest(msg, 413 if "megapixels" in msg else 400) from None
        self.uploads[uid] = {"path": path, "name": Path(filename or "image").name, "bytes": len(data)}
        self._trim_uploads(keep=uid)
        return {"id": uid, "scene": f"upload:{uid}", "name": self.uploads[uid]["name"]}

    def validate(self, data) -> SensorSpec:
        """:func:`validate` of a page's configuration, its file keys first checked by :func:`client_files`."""
        if isinstance(data, dict):
            data = client_files(data, self.uploads, self.base)
        return validate(data)

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
        return self.patterns.nbytes()

    def sensor(self, spec: SensorSpec) -> Sensor:
        """A sensor of ``spec``, its maps from the pattern cache where their inputs are unchanged."""
        return Sensor(spec, cache=self.patterns)

    def exposure(self, spec: SensorSpec, scene: str) -> Exposure:
        """The exposure of ``scene`` on ``spec``'s sensor (its signal, photo mean and dark mean from the cache)."""
        return self.sensor(spec).expose(self.scene_source(scene))

    def master_dark(self, spec: SensorSpec, region) -> np.ndarray | None:
        cfg = spec.config
        n = cfg.processing.dark_frames
        if n <= 0:
            return None

        def make():
            dark = self.sensor(spec).expose("flat:0", sequence=SEQ_DARK_CALIBRATION)
            return calibration.master_dark(dark.frame(k, region=region) for k in range(n))

        return self._masters.get("master", (cfg, list(region)), make)

    def picture(self, spec: SensorSpec, scene: str, view: str, frame: int, region, step: int) -> tuple[np.ndarray, dict]:
        """An 8-bit picture of ``region`` (row0, row1, col0, col1) of frame ``frame``, one pixel per ``step`` sensor pixels."""
        if view not in VIEWS:
            raise BadRequest(f"view {view!r}: use one of {', '.join(VIEWS)}")
        cfg = spec.config
        rows, cols = cfg.sensor.height, cfg.sensor.width
        r0, r1, c0, c1 = _clip_region(region, rows, cols)
        # extend by the margin and align to the CFA's 2 x 2 cell (the pattern's phase is kept)
        e0, e1 = max(0, (r0 - MARGIN) // 2 * 2), min(rows, r1 + MARGIN)
        f0, f1 = max(0, (c0 - MARGIN) // 2 * 2), min(cols, c1 + MARGIN)
        t0 = time.perf_counter()
        shot = self.exposure(spec, scene)
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
            master = self.master_dark(spec, (e0, e1, f0, f1)) if view == "processed" else None
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

    def raw(self, spec: SensorSpec, scene: str, frame: int) -> np.ndarray:
        return self.exposure(spec, scene).frame(frame)

    def figures(self, spec: SensorSpec, scene: str) -> dict:
        """Key figures, the noise budget and the dark-current figures of a pane (:func:`figures_of_merit.pane`)."""
        def make():
            shot = self.exposure(spec, scene)
            return fom.pane(shot.sensor, shot)

        return self._figures.get("figures", (spec.config, scene), make)

    def quality(self, spec: SensorSpec, lux: float) -> dict:
        """A pane's image quality at ``lux`` (:func:`cmosnoise.analysis.quality.measure` of its configuration and
        seed, :data:`QUALITY_FRAMES` frames of each chart): each metric's value, name, unit and better direction,
        and the visibility threshold of visual noise in L*.

        Parameters
        ----------
        spec : SensorSpec
            The pane's sensor (its light switched on at ``lux`` where it is off).
        lux : float
            The illuminance on the charts, lux.

        Returns
        -------
        dict
            ``lux``, ``metrics`` (name -> value or None), ``labels`` (name -> [label, unit, better]),
            ``visual_threshold_l``, ``notes``, ``frames``.
        """
        from ..analysis import quality

        lux = float(lux)
        if not QUALITY_LUX[0] <= lux <= QUALITY_LUX[1]:
            raise BadRequest(f"lux = {lux:g}: give an illuminance from {QUALITY_LUX[0]:g} to {QUALITY_LUX[1]:g} lux")

        def make():
            r = quality.measure(spec.config, [lux], frames=QUALITY_FRAMES, seed=spec.seed)
            return {"lux": lux, "frames": QUALITY_FRAMES, "visual_threshold_l": r["visual_threshold_l"],
                    "metrics": {k: v[0] for k, v in r["metrics"].items()},
                    "labels": {m.name: [m.label, m.unit, m.better] for m in quality.METRICS},
                    "notes": sorted(set(r["notes"]))}

        return self._figures.get("quality", (spec.config, lux), make)

    def couplets(self, spec: SensorSpec, region) -> list:
        """Couplets of the dark map (both white pixels) inside ``region``: [[r1, c1, r2, c2], ...]."""
        sensor = self.sensor(spec)
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
        return region_of(region, (rows, cols), clip=True)
    except CmosnoiseError as e:
        raise BadRequest(str(e)) from None


def _bin(img: np.ndarray, f: int) -> np.ndarray:
    """Mean over f x f blocks (the last partial blocks dropped)."""
    if f <= 1:
        return img
    r, c = img.shape[0] // f * f, img.shape[1] // f * f
    if r == 0 or c == 0:
        return img[:1, :1]
    shape = (r // f, f, c // f, f) + img.shape[2:]
    return (img[:r, :c].reshape(shape).mean(axis=(1, 3)) + 0.5).astype(np.uint8)


