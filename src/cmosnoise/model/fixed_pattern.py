"""A sensor instance's fixed pattern: every map drawn once from the seed, what each map reads, and a cache.

Each map is a pure function of the seed, the sensor's size and a few parts of
the configuration; :func:`dependencies` is the one table of those parts. Each
is addressed per pixel (per row, per column: :mod:`cmosnoise.engine.fixed_maps`),
so :func:`draw` makes the maps of any rectangle (a tile) alone, equal to that
rectangle of the whole sensor's.
:func:`draw` draws every map of a :class:`~cmosnoise.model.spec.SensorSpec`;
given a :class:`PatternCache`, it takes each map from the cache when a
sensor of the same seed and size with the same inputs drew it before, so
interactive use (the explorer, a slider at a time) and a sweep (many points
of one seed) redraw only what a change touches. A cached map is the map a
fresh draw gives, bit for bit (``tests/test_reproducibility.py``).

The cache also keeps the products an exposure is built from, each keyed by
what it reads (:mod:`cmosnoise.model.sensor` asks for them):

- the scene's signal through the CFA (scene, size, CFA, responsivities);
- the photo mean: the perfect image through PRNU and crosstalk (signal,
  exposure, PRNU map, crosstalk) - not the temperature;
- the dark mean: the dark-current map times the integration time - not the scene;
- each pixel's source-follower sigma (flicker map, thermal sigma).

So a temperature move redraws the dark map alone and reuses the photo mean.

Examples
--------
>>> from cmosnoise import Sensor, fixed_pattern
>>> s = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7)
>>> part = fixed_pattern.draw(s.spec, region=(8, 16, 0, 32))   # any rectangle alone, bit for bit
>>> bool((part.prnu_gain == s.fixed_pattern.prnu_gain[8:16, 0:32]).all())
True
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..engine.telegraph import Telegraphs
from . import physics
from .seeds import fixed_key
from .spec import SensorSpec
from .stages import (
    amplifier_glow,
    column_noise,
    dark_current,
    defects,
    pixel_offset,
    prnu,
    random_telegraph,
    row_noise,
    source_follower,
)


@dataclass(frozen=True)
class FixedPattern:
    """A sensor instance's fixed-pattern maps (None where the stage is off).

    Drawn once by :class:`~cmosnoise.model.sensor.Sensor`; read them through ``sensor.fixed_pattern``.

    Parameters
    ----------
    prnu_gain : (rows, cols) float32 array
        Per-pixel photo gain.
    dark_state : DarkState
        The DCNU's parameters at the sensor's temperature.
    dark_rate : (rows, cols) float32 array, e-/s
        The dark-current map at the sensor's temperature.
    flicker_sigma : (rows, cols) float32 array, e- rms
        Per-pixel flicker sigma.
    row_offset : (rows, 1) array, e-
        Fixed row offsets.
    column_sigma : (1, cols) array, e- rms
        Per-column temporal sigma.
    vfpn : (1, cols) array, e-
        Fixed column offsets.
    column_gain : (1, cols) array
        Fixed column gains.
    pixel_offset : (rows, cols) float32 array, e-
        Per-pixel offsets.
    traps : Telegraphs
        The source follower's random telegraph traps (sizes: amplitudes, e-).
    blinkers : Telegraphs
        Blinking white pixels (sizes: rate steps at the temperature, e-/s).
    defects : Defects
        Dead, stuck and gain pixels, hot clusters, bad lines (stage 15).

    Examples
    --------
    >>> from cmosnoise import Sensor
    >>> fp = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).fixed_pattern
    >>> fp.prnu_gain.shape, fp.prnu_gain.dtype
    ((48, 64), dtype('float32'))
    """

    prnu_gain: np.ndarray | None = None
    dark_state: dark_current.DarkState | None = None
    dark_rate: np.ndarray | None = None
    flicker_sigma: np.ndarray | None = None
    row_offset: np.ndarray | None = None
    column_sigma: np.ndarray | None = None
    vfpn: np.ndarray | None = None
    column_gain: np.ndarray | None = None
    pixel_offset: np.ndarray | None = None
    traps: Telegraphs | None = None
    blinkers: Telegraphs | None = None
    defects: defects.Defects | None = None


def dependencies(spec: SensorSpec) -> dict[str, object]:
    """What draws each fixed-pattern map besides the seed and the size: map -> the configuration's parts.

    The one table of it: :func:`draw` keys its cache by it. A map's entry
    holds every value its drawing function reads (a section switched off
    draws nothing, so its switch is part of the entry).

    Parameters
    ----------
    spec : SensorSpec

    Returns
    -------
    dict of str to object
        For each map's name, the values its drawing reads.
    """
    c = spec.config
    sf, rn = c.source_follower, c.row_noise
    return {
        "prnu_gain": (c.prnu.enabled, c.prnu.sigma_pct),
        "dark_rate": (c.dark_current.enabled, c.dark_current.doubling_c, c.dark_current.tail_doubling_c,
                      spec.dark_points, c.sensor.temperature_c, c.dark_current.glow),
        "flicker_sigma": (sf.enabled, sf.flicker, spec.flicker_cds_factor),
        "row_offset": (rn.enabled, rn.fixed_sigma_e),
        "column": c.column_noise,
        "pixel_offset": (c.pixel_offset.enabled, spec.offsets),
        "traps": (sf.enabled, sf.rts),
        "blinkers": (c.dark_current.enabled, c.dark_current.rts, c.sensor.temperature_c, c.dark_current.tail_doubling_c),
        "defects": c.defects,
    }


def key(*parts) -> str:
    """A cache key: a digest of ``parts`` (pydantic sections and dataclasses by their values).

    Parameters
    ----------
    *parts
        Values, pydantic sections and dataclasses included.

    Returns
    -------
    str
        A SHA-1 hex digest.
    """
    return hashlib.sha1(json.dumps(parts, sort_keys=True, default=_plain).encode()).hexdigest()


def _plain(value):
    if hasattr(value, "model_dump"):
        return value.model_dump(mode="json")
    if hasattr(value, "__dataclass_fields__"):
        return {f: getattr(value, f) for f in value.__dataclass_fields__}
    if isinstance(value, np.ndarray):
        return value.tolist()
    return repr(value)


class PatternCache:
    """Fixed-pattern maps and exposure products by key, least recently used first out; thread-safe.

    Parameters
    ----------
    max_bytes : int
        What the values may hold together (the newest is kept whatever it weighs), bytes.
    max_items : int
        At most this many values.

    Examples
    --------
    Two sensors of one seed that differ in the temperature share their PRNU map (taken from the cache):

    >>> import numpy as np
    >>> from cmosnoise import PatternCache, Sensor
    >>> cache = PatternCache(1e8)
    >>> a = Sensor({"sensor": {"width": 64, "height": 48}}, cache=cache)
    >>> b = Sensor({"sensor": {"width": 64, "height": 48, "temperature_c": 45}}, cache=cache)
    >>> np.array_equal(a.fixed_pattern.prnu_gain, b.fixed_pattern.prnu_gain)
    True
    """

    def __init__(self, max_bytes: int, max_items: int = 64):
        self.max_bytes = int(max_bytes)
        self.max_items = int(max_items)
        self._items: OrderedDict[str, object] = OrderedDict()
        self._weights: dict[str, int] = {}
        self._lock = threading.Lock()

    def get(self, name: str, parts: tuple, make: Callable[[], object]):
        """The value of ``name`` for ``parts``, made by ``make()`` (outside the lock) when not held.

        Parameters
        ----------
        name : str
            Which map or value.
        parts : tuple
            What it depends on (the key it is held under).
        make : callable
            Makes it, with no arguments.

        Returns
        -------
        object
            The held or newly made value.
        """
        k = name + ":" + key(*parts)
        with self._lock:
            if k in self._items:
                self._items.move_to_end(k)
                return self._items[k]
        value = make()
        with self._lock:
            self._items[k] = value
            self._weights[k] = nbytes(value)
            while len(self._items) > 1 and (len(self._items) > self.max_items or self.nbytes() > self.max_bytes):
                old, _ = self._items.popitem(last=False)
                self._weights.pop(old, None)
        return value

    def nbytes(self) -> int:
        """Bytes the held values weigh.

        Returns
        -------
        int
        """
        return sum(self._weights.values())

    def __len__(self) -> int:
        return len(self._items)


def nbytes(value) -> int:
    """Bytes of the arrays in ``value``.

    Parameters
    ----------
    value : array, tuple or list of arrays, or object with ``nbytes``

    Returns
    -------
    int
    """
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, (tuple, list)):
        return sum(nbytes(v) for v in value)
    return int(getattr(value, "nbytes", 0))


def cached(cache: PatternCache | None, name: str, parts: tuple, make: Callable[[], object]):
    """``make()`` through ``cache`` when there is one.

    Parameters
    ----------
    cache : PatternCache or None
    name : str
        The value's name.
    parts : tuple
        What it depends on (the key, with ``name``).
    make : callable
        Makes the value when the cache does not hold it.

    Returns
    -------
    object
        What ``make`` returns, or the cached value it returned before.
    """
    return make() if cache is None else cache.get(name, parts, make)


def draw(spec: SensorSpec, cache: PatternCache | None = None,
         region: tuple[int, int, int, int] | None = None, populations: FixedPattern | None = None,
         engine: str = "auto") -> FixedPattern:
    """Every fixed-pattern map of ``spec`` over ``region``, each from its own counter-based stream of the seed.

    Parameters
    ----------
    spec : SensorSpec
        The resolved sensor.
    cache : PatternCache, optional
        Maps of the same seed, size and region with unchanged :func:`dependencies` are taken from it (and new
        ones put in it).
    region : (row0, row1, col0, col1), optional
        The rectangle of the sensor to make the maps of (a tile; the whole sensor if omitted). Every map is
        addressed per pixel, row or column (:mod:`cmosnoise.engine.fixed_maps`), so a tile's maps are that
        rectangle of the whole sensor's, bit for bit. Row maps then cover the tile's rows, column maps its
        columns. The telegraph populations and the defects are drawn for the whole sensor (they are sparse).
    populations : FixedPattern, optional
        A pattern of the same configuration and seed (another tile's) whose telegraph populations and defects
        are taken as they are, not drawn again (each is a pass over every pixel of the sensor).
    engine : {"auto", "numpy", "compiled", "cuda"}
        Where the per-pixel maps are made (:mod:`cmosnoise.engine.fixed_maps`): "cuda" on the GPU. The same bits
        each way; the cache does not tell them apart.

    Returns
    -------
    FixedPattern
        The maps of ``region``, None where a stage is off.
    """
    c = spec.config
    shape, seed = spec.shape, spec.seed
    rows, cols = shape
    region = (0, rows, 0, cols) if region is None else tuple(int(v) for v in region)
    r0, r1, c0, c1 = region
    if not (0 <= r0 < r1 <= rows and 0 <= c0 < c1 <= cols):
        raise ValueError(f"region {region} is not a rectangle of the {rows} x {cols} sensor")
    deps = dependencies(spec)

    def held(name, make, whole=False):
        if whole and populations is not None:
            return getattr(populations, name)
        return cached(cache, name, (seed, shape, None if whole else region, deps[name]), make)

    maps: dict = {}
    if c.prnu.enabled:
        maps["prnu_gain"] = held("prnu_gain", lambda: prnu.gain_map(region, cols, c.prnu.sigma_pct,
                                                                      fixed_key(seed, "prnu"), engine))
    if c.dark_current.enabled:
        d = c.dark_current
        state = dark_current.at_temperature(list(spec.dark_points), c.sensor.temperature_c, d.doubling_c,
                                            d.tail_doubling_c, physics.white_threshold(c))
        maps["dark_state"] = state

        def dark():
            rates = dark_current.rate_map(state, region, cols, fixed_key(seed, "dark_current"), engine)
            if d.glow.enabled and d.glow.rate_e_per_s > 0:  # stage 4c: the amplifiers' glow on top
                rates = rates + amplifier_glow.glow_map(region, shape, d.glow.rate_e_per_s, d.glow.source,
                                                        d.glow.length_px)
            return rates

        maps["dark_rate"] = held("dark_rate", dark)
    sf = c.source_follower
    if sf.enabled and sf.flicker.enabled:
        factor = spec.flicker_cds_factor  # a 1/f flicker through CDS at another interval than its sigmas'

        def flicker():
            sigma = source_follower.flicker_sigma_map(spec.flicker, region, cols, fixed_key(seed, "source_follower"),
                                                      engine)
            return sigma if factor == 1.0 else (sigma * np.float32(factor)).astype(np.float32)

        maps["flicker_sigma"] = held("flicker_sigma", flicker)
    if c.row_noise.enabled and c.row_noise.fixed_sigma_e > 0:
        maps["row_offset"] = held("row_offset", lambda: row_noise.fixed_offsets(r0, r1, c.row_noise.fixed_sigma_e,
                                                                                 fixed_key(seed, "row_noise")))
    if c.column_noise.enabled:
        maps["column_sigma"], maps["vfpn"], maps["column_gain"] = held("column", lambda: _column_maps(c, c0, c1))
    if c.pixel_offset.enabled and (spec.offsets.sigma_e > 0 or spec.offsets.tail_fraction > 0):
        maps["pixel_offset"] = held("pixel_offset", lambda: pixel_offset.offset_map(
            spec.offsets, fixed_key(seed, "pixel_offset"), region, cols, engine))
    if sf.enabled and sf.rts.enabled:
        maps["traps"] = held("traps", lambda: random_telegraph.draw_traps(
            sf.rts, fixed_key(seed, "source_follower_rts"), shape), whole=True)
    d = c.dark_current
    if d.enabled and d.rts.enabled:
        scale = random_telegraph.step_scale(d.rts.reference_temperature_c, c.sensor.temperature_c, d.tail_doubling_c)
        maps["blinkers"] = held("blinkers", lambda: random_telegraph.draw_blinkers(
            d.rts, scale, fixed_key(seed, "dark_current_rts"), shape), whole=True)
    if c.defects.enabled:
        maps["defects"] = held("defects", lambda: defects.draw(c.defects, fixed_key(seed, "defects"), shape),
                               whole=True)
    return FixedPattern(**maps)


def _column_maps(c, col0: int, col1: int) -> tuple:
    """(temporal sigma, VFPN offsets, gains) of columns ``col0`` to ``col1``, each None where off."""
    cn, seed = c.column_noise, c.seed
    sigma = vfpn = gain = None
    if cn.temporal.enabled:
        sigma = column_noise.temporal_sigma_map(col0, col1, cn.temporal.gumbel_loc_e, cn.temporal.gumbel_scale_e,
                                                fixed_key(seed, "column_noise", 0))
    if cn.vfpn_sigma_e > 0:
        vfpn = column_noise.vfpn_offsets(col0, col1, cn.vfpn_sigma_e, fixed_key(seed, "column_noise", 1))
    alt = cn.alternating
    if alt.enabled and alt.fixed_sigma_e > 0:  # the two banks' offsets join the columns' own
        banks = column_noise.alternating_offsets(col0, col1, alt.fixed_sigma_e, fixed_key(seed, "column_noise", 3))
        vfpn = banks if vfpn is None else vfpn + banks
    if cn.gain_sigma_pct > 0:
        gain = column_noise.gain_map(col0, col1, cn.gain_sigma_pct, fixed_key(seed, "column_noise", 2))
    return sigma, vfpn, gain
