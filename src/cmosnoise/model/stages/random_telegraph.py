"""Stages 6b and 4b, random telegraph noise in time: source-follower traps and blinking white pixels.

**Source-follower traps (6b).** A fraction of the pixels carry one or more
traps at the source follower's gate. A trap is a two-state chain
(:mod:`cmosnoise.engine.telegraph`): empty for a mean ``tau_capture`` s,
filled for a mean ``tau_emission`` s; filled, it shifts the pixel's output by
its amplitude ``A`` (e- at the source follower's input). Correlated double
sampling subtracts the reset sample from the signal sample ``cds_interval``
later, so a frame shows ``A (X(signal) - X(reset))``: a trap much faster than
the interval gives three levels (-A, 0, +A), one much slower is zero in all
but a few frames. Without CDS (the reset level from another frame) a frame
shows the level ``A X(t_k)`` itself, held over frames.

**Blinking white pixels (4b).** A fraction of the pixels have a dark current
that switches between their map's rate and that plus a step (e-/s), with
their own mean dwell times (seconds to minutes). A frame's dark charge
integrates the rate over its exposure ``[t_k, t_k + T]``: the map's mean
plus ``step`` times the time spent high (exact, by uniformization).

Which pixels, how many traps, each trap's amplitude and dwell times are a
fixed pattern drawn per pixel from Philox under the stage's fixed key
(docs/model.md section 1): pixel ``i`` is affected when the first uniform of
its block (i, 0, 0, 0) is below ``ppm * 1e-6``; trap ``slot``'s amplitude
comes from block (i, 1 + slot, 0, 0), its dwell times from block
(i, 1 + slot, 0, 1). The states in time come from the stage's temporal key,
any frame alone (:func:`cmosnoise.engine.telegraph.frame_states`).
"""

from __future__ import annotations

import math

import numpy as np

from ...engine import telegraph
from ...engine.fdmath import exp, log
from ...engine.philox import uniform_pair
from ...engine.samplers import Stream, normal_from
from ...engine.telegraph import Telegraphs

#: a pixel holds at most this many traps (the rest of a Poisson count is cut; see :func:`trap_counts`)
MAX_TRAPS = 4
#: pixels drawn at a time when choosing the affected ones (bounds the memory of the draw)
_CHUNK = 1 << 20


def affected(ppm: float, key: tuple[int, int], shape: tuple[int, int], word: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The pixels whose selection uniform is below ``ppm * 1e-6``: (index uint64, that uniform), ascending.

    Pixel ``i``'s uniform is the first of Philox block (i, ``word``, 0, 0) under ``key``.
    """
    rows, cols = shape
    total = rows * cols
    stream = Stream(key, word, 0)
    p = ppm * 1e-6
    found, draws = [], []
    for start in range(0, total, _CHUNK):
        index = np.arange(start, min(total, start + _CHUNK), dtype=np.uint64)
        u = stream.uniforms(index)[0]
        hit = u < p
        found.append(index[hit])
        draws.append(u[hit])
    return np.concatenate(found), np.concatenate(draws)


def trap_counts(u: np.ndarray, ppm: float, mode: str) -> np.ndarray:
    """Traps per affected pixel from its selection uniform ``u`` (< ppm 1e-6): 1, or a Poisson count.

    ``poisson``: the count ``k`` is Poisson's inverse CDF at ``1 - u`` with the
    mean ``-log(1 - ppm 1e-6)`` that puts ``ppm`` of the pixels at one or more,
    so the affected pixels are those of ``one``; counts past
    :data:`MAX_TRAPS` are cut (at 1000 ppm, one pixel in 4e17 has more).
    """
    if mode == "one":
        return np.ones(u.shape, np.int64)
    lam = -math.log1p(-ppm * 1e-6)
    v = 1.0 - u
    k = np.zeros(u.shape, np.int64)
    p = math.exp(-lam)
    total = p
    for n in range(1, MAX_TRAPS + 1):  # k = how many of F(0) .. F(MAX_TRAPS - 1) lie below v
        k = k + (v > total)
        p = p * lam / n
        total = total + p
    return np.maximum(k, 1)  # F(0) = 1 - ppm 1e-6 up to rounding: an affected pixel has a trap


def spread(law, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """A positive quantity across traps from two uniforms: lognormal ``median exp(sigma_log z)`` (z by Box-Muller)
    or exponential ``-mean log(u1)`` (a :class:`~cmosnoise.config.schema.SpreadLaw`)."""
    if law.distribution == "lognormal":
        return law.median * exp(law.sigma_log * normal_from(u1, u2))
    return law.mean * (0.0 - log(u1))


def log_uniform(times, u: np.ndarray) -> np.ndarray:
    """Mean dwell times log-uniform from ``times.min_s`` to ``times.max_s`` (a :class:`~cmosnoise.config.schema.DwellTimes`)."""
    return times.min_s * exp(u * log(np.float64(times.max_s / times.min_s)))


def draw(ppm: float, mode: str, size_law, tau_low, tau_high, key: tuple[int, int], shape: tuple[int, int]) -> Telegraphs:
    """A population: the affected pixels of ``shape``, their traps (``mode``: one or poisson), each trap's size
    (``size_law``) and mean dwell times in state 0 (``tau_low``) and 1 (``tau_high``)."""
    pixels, u = affected(ppm, key, shape)
    counts = trap_counts(u, ppm, mode)
    index = np.repeat(pixels, counts)
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    slot = (np.arange(index.size) - starts).astype(np.uint64)
    k0, k1 = (np.uint64(w) for w in key)
    zero = np.zeros(index.shape, np.uint64)
    a1, a2 = uniform_pair(index, slot + np.uint64(1), zero, zero, k0, k1)
    t1, t2 = uniform_pair(index, slot + np.uint64(1), zero, zero + np.uint64(1), k0, k1)
    return Telegraphs(index, slot, spread(size_law, a1, a2), log_uniform(tau_low, t1), log_uniform(tau_high, t2))


def trap_output(traps: Telegraphs, frame: int, sequence: int, dt: float, cds_interval_s: float | None,
                key: tuple[int, int]) -> np.ndarray:
    """What each trap adds to frame ``frame`` (e-), (n,) float64: ``A (X(t_k + cds_interval) - X(t_k))``, or
    with ``cds_interval_s=None`` (no CDS) the level ``A X(t_k)``. ``dt``: the frame period, s."""
    k0, k1 = (np.uint64(w) for w in key)
    up, down = traps.up, traps.down
    x, y = telegraph.frame_states(frame, up, down, dt, traps.index, traps.slot, sequence, k0, k1)
    if cds_interval_s is None:
        return traps.size * x
    signal = telegraph.inside(frame, x, y, up, down, dt, cds_interval_s, traps.index, traps.slot, sequence, k0, k1)
    return traps.size * (signal - x)


def blink_charge(pixels: Telegraphs, frame: int, sequence: int, dt: float, exposure_s: float,
                 key: tuple[int, int]) -> np.ndarray:
    """Each blinking pixel's extra dark charge in frame ``frame`` (e-), (n,) float64: its step (e-/s) times the
    time it spends high over the exposure ``[t_k, t_k + exposure_s]``."""
    k0, k1 = (np.uint64(w) for w in key)
    up, down = pixels.up, pixels.down
    x, y = telegraph.frame_states(frame, up, down, dt, pixels.index, pixels.slot, sequence, k0, k1)
    end = telegraph.inside(frame, x, y, up, down, dt, exposure_s, pixels.index, pixels.slot, sequence, k0, k1)
    busy = np.array([telegraph.occupancy(frame, x[i], end[i], up[i], down[i], exposure_s, pixels.index[i],
                                         pixels.slot[i], sequence, k0, k1) for i in range(pixels.index.size)])
    return pixels.size * busy.reshape(pixels.index.shape)


def trap_moments(traps: Telegraphs, cds_interval_s: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Each trap's stationary mean (e-) and temporal variance (e-^2) in a frame, (n,) float64 each.

    With CDS (``cds_interval_s``): ``A (X(tau) - X(0))`` has mean 0 and
    variance ``A^2 P(X(tau) != X(0)) = 2 A^2 pi0 pi1 (1 - e^(-s tau))``;
    without (``None``): the level ``A X`` has mean ``A pi1`` and variance
    ``A^2 pi0 pi1``, its frames correlated over the dwell times.
    """
    pi1 = traps.occupancy
    pi0 = 1.0 - pi1
    a2 = traps.size * traps.size
    if cds_interval_s is None:
        return traps.size * pi1, a2 * pi0 * pi1
    p01, _, p10, _ = telegraph.transition(traps.up, traps.down, cds_interval_s)
    return np.zeros(traps.size.shape), a2 * (pi0 * p01 + pi1 * p10)


def blink_moments(pixels: Telegraphs, exposure_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Each blinking pixel's extra dark charge over an exposure ``T``: stationary mean (e-) and the variance of
    its rate's time high (e-^2, before the charge's own shot noise), (n,) float64 each.

    ``step pi1 T`` and ``step^2 Var(time high) = 2 step^2 pi0 pi1 T^2 (x - 1 + e^-x) / x^2`` with ``x = s T``
    (the occupation time of a stationary two-state chain; ``T^2 pi0 pi1`` when ``x`` is 0, the level held over
    the exposure; ``2 T pi0 pi1 / s`` when large).
    """
    pi1 = pixels.occupancy
    pi0 = 1.0 - pi1
    x = (pixels.up + pixels.down) * exposure_s
    # (x - 1 + e^-x) / x^2 by its series where the difference cancels (relative error under x**4 / 720 there)
    small = x < 1e-4
    xs = np.where(small, 1.0, x)
    shape = np.where(small, 0.5 - x / 6.0 + x * x / 24.0 - x**3 / 120.0, (xs + np.expm1(-xs)) / (xs * xs))
    step = pixels.size
    return step * pi1 * exposure_s, 2.0 * step * step * pi0 * pi1 * exposure_s**2 * shape


def frame_period_s(frame_rate_hz: float | None, exposure_s: float) -> float:
    """Seconds from one frame's start to the next: ``1 / frame_rate_hz``, or the exposure (frames back to back)."""
    return exposure_s if frame_rate_hz is None else 1.0 / frame_rate_hz


def check(config) -> None:
    """What the random telegraph sections need of the timing; raises ValueError naming the key and the value.

    The frame period must hold the exposure (frames do not overlap), the CDS
    interval must fit in a frame, and a blinking pixel may switch at most
    :data:`~cmosnoise.engine.telegraph.MAX_RATE_TIME` times an exposure on
    average (the exact integral's cost grows with it).
    """
    sf, dc = config.source_follower.rts, config.dark_current.rts
    sf_on = config.source_follower.enabled and sf.enabled
    dc_on = config.dark_current.enabled and dc.enabled
    if not (sf_on or dc_on):
        return
    exposure = config.exposure.integration_time_s
    rate = config.sensor.frame_rate_hz
    period = frame_period_s(rate, exposure)
    if rate is not None and period < exposure:
        raise ValueError(f"sensor.frame_rate_hz = {rate:g}: its frame period {period:g} s is shorter than "
                         f"exposure.integration_time_s = {exposure:g} s; give at most {1.0 / exposure:g}")
    if sf_on and sf.cds and not sf.cds_interval_s < period:
        raise ValueError(f"source_follower.rts.cds_interval_s = {sf.cds_interval_s:g}: the CDS interval must be "
                         f"shorter than the frame period, {period:g} s")
    if dc_on:
        fastest = 1.0 / min(dc.tau_low_s.min_s, dc.tau_high_s.min_s)
        if fastest * exposure > telegraph.MAX_RATE_TIME:
            shortest = exposure / telegraph.MAX_RATE_TIME
            raise ValueError(f"dark_current.rts: a mean dwell time of {1.0 / fastest:g} s switches "
                             f"{fastest * exposure:.3g} times in the {exposure:g} s exposure; give dwell times of at "
                             f"least {shortest:g} s (blinking is seconds to minutes)")


def step_scale(reference_c: float, temperature_c: float, doubling_c: float) -> float:
    """The blinking step at ``temperature_c`` per unit at ``reference_c``: it doubles every ``doubling_c``."""
    return 2.0 ** ((temperature_c - reference_c) / doubling_c)


def draw_traps(section, key: tuple[int, int], shape: tuple[int, int]) -> Telegraphs:
    """The source follower's traps of a ``source_follower.rts`` section (sizes: amplitudes, e-)."""
    return draw(section.ppm, section.traps_per_pixel, section.amplitude_e, section.tau_capture_s,
                section.tau_emission_s, key, shape)


def draw_blinkers(section, scale: float, key: tuple[int, int], shape: tuple[int, int]) -> Telegraphs:
    """The blinking pixels of a ``dark_current.rts`` section (sizes: rate steps at the sensor's temperature, e-/s,
    ``scale`` times those at the reference temperature)."""
    pixels = draw(section.ppm, "one", section.step_e_per_s, section.tau_low_s, section.tau_high_s, key, shape)
    return Telegraphs(pixels.index, pixels.slot, pixels.size * scale, pixels.tau_low_s, pixels.tau_high_s)
