"""What a configuration implies: the physics objects built from its values.

The configuration layer validates types and ranges; this module turns a
:class:`~cmosnoise.config.Config` into the model's objects (dark-current
characterization points in e-/s, the flicker-sigma distribution) and checks
what only the physics can tell: that every ppm is reachable and every body
distribution valid. :func:`cmosnoise.model.spec.resolve` calls them once per
configuration and keeps what they give in a
:class:`~cmosnoise.model.spec.SensorSpec`.
"""

from __future__ import annotations

import functools

from ..config import Config
from ..errors import CmosnoiseError
from . import one_over_f
from .heavy_tail import HeavyTail, UnreachablePpm
from .stages.dark_current import Point
from .stages.random_telegraph import check as _check_timing
from .stages.random_telegraph import frame_period_s as _frame_period_s
from .stages.source_follower import flicker_model as _flicker_model
from .units import aa_to_e_per_s, na_per_cm2_to_e_per_s

_RATE_CONVERSIONS = (
    ("e_per_s", lambda v, pitch: v),
    ("aA", lambda v, pitch: aa_to_e_per_s(v)),
    ("nA_per_cm2", na_per_cm2_to_e_per_s),
)


def rate_e_per_s(section, base: str, pixel_pitch_um: float) -> float | None:
    """The rate ``base`` of a config section in e-/s, whichever unit it was given in (None if absent)."""
    for unit, conv in _RATE_CONVERSIONS:
        v = getattr(section, f"{base}_{unit}", None)
        if v is not None:
            return float(conv(v, pixel_pitch_um))
    return None


def _invalid(message: str) -> CmosnoiseError:
    return CmosnoiseError(f"invalid configuration: {message}")


def flicker_model(config: Config) -> HeavyTail:
    """The per-pixel flicker-sigma distribution (e- rms) of ``config``; raises on an unreachable ppm."""
    f = config.source_follower.flicker
    try:
        if f.tail is None:
            return _flicker_model(f.gumbel_loc_e, f.gumbel_scale_e)
        return _flicker_model(f.gumbel_loc_e, f.gumbel_scale_e, f.tail.ppm_above, f.tail.threshold_e, f.tail.max_e)
    except UnreachablePpm as exc:
        raise _invalid(f"source_follower.flicker.tail.ppm_above = {f.tail.ppm_above:g}: {exc}") from None


def gain_row(config: Config):
    """The gain_table row ``sensor.iso`` or ``sensor.gain_db`` selects, of ``sensor.binning``'s rows (a row
    without a binning serves every one), or None."""
    sen = config.sensor
    index = "iso" if sen.iso is not None else "gain_db" if sen.gain_db is not None else None
    if index is None:
        return None
    rows = [r for r in config.gain_table if getattr(r, index) == getattr(sen, index) and r.binning in (None, sen.binning)]
    return next((r for r in rows if r.binning == sen.binning), rows[0])


def gain_updates(row) -> dict:
    """What a gain table's row sets, as a (partial) configuration: its K (``adc.gain_dn_per_e``, the full scale
    then from it) and its ``set`` keys (dotted) as nested sections."""
    updates: dict = {"adc": {"gain_dn_per_e": row.k_dn_per_e, "full_scale_e": None}}
    for dotted, value in row.set.items():
        node = updates
        *parents, leaf = dotted.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return updates


def apply_gain(config: Config) -> Config:
    """``config`` at its gain setting: the selected row's K (``adc.gain_dn_per_e``) and its ``set`` keys merged in
    (docs/model.md stage 9b); unchanged without a setting. The row wins over the keys it sets."""
    from ..config import merge_updates

    row = gain_row(config)
    if row is None:
        return config
    updates = gain_updates(row)
    where = (f"iso {row.iso:g}" if row.iso is not None else f"gain_db {row.gain_db:g}") + (
        f", binning {row.binning}" if row.binning is not None else "")
    try:
        return merge_updates(config, updates)
    except CmosnoiseError as exc:
        raise _invalid(f"gain_table row at {where}: {str(exc).removeprefix('invalid configuration: ')}") from None


def offset_model(config: Config):
    """The pixel offsets' law (e-) of ``config``; raises on an unreachable ppm."""
    from .stages.pixel_offset import offset_model as model

    o = config.pixel_offset
    try:
        if o.tail is None:
            return model(o.sigma_e)
        return model(o.sigma_e, o.tail.ppm_above, o.tail.threshold_e, o.tail.max_e)
    except ValueError as exc:
        raise _invalid(str(exc)) from None


def nonlinearity_curve(config: Config):
    """The charge-to-voltage transfer of ``config`` (a :class:`~.stages.nonlinearity.Curve`; None when no form
    is given)."""
    from .stages import nonlinearity

    n = config.nonlinearity
    if n.linearity_error_pct is None and n.curve_e is None and n.coefficients is None:
        return None
    try:
        return nonlinearity.curve(config.sensor.full_well_e, n.linearity_error_pct, n.curve_e, n.coefficients)
    except ValueError as exc:
        raise _invalid(str(exc)) from None


#: a dark-current body's std, relative to its mean (to 1 e-/s for the families that allow 0 or below)
MIN_CV, MAX_CV = 1e-6, 1e3


def white_threshold(config: Config) -> tuple[float, str] | None:
    """The fixed white-pixel threshold of ``config`` in e-/s and the key that gave it, or None (each temperature
    then counts against its nearest characterization point's tail threshold)."""
    d = config.dark_current
    rate = rate_e_per_s(d, "white_threshold", config.sensor.pixel_pitch_um)
    if rate is None:
        return None
    unit = next(u for u, _ in _RATE_CONVERSIONS if getattr(d, f"white_threshold_{u}") is not None)
    return rate, f"dark_current.white_threshold_{unit} = {getattr(d, f'white_threshold_{unit}'):g}"


def dark_points(config: Config) -> list[Point]:
    """The dark-current characterization points in e-/s; raises on an invalid body or unreachable ppm."""
    pitch = config.sensor.pixel_pitch_um
    out = []
    for i, p in enumerate(config.dark_current.points):
        where = f"dark_current.points[{i}]"
        tail = p.tail
        point = Point(
            p.temperature_c, p.distribution,
            rate_e_per_s(p, "mean", pitch), rate_e_per_s(p, "std", pitch),
            tail.ppm_above if tail else 0.0,
            rate_e_per_s(tail, "threshold", pitch) if tail else None,
            rate_e_per_s(tail, "max", pitch) if tail else 0.0,
        )
        if point.family in ("inverse_gaussian", "lognormal", "gamma") and point.mean <= 0:
            raise _invalid(f"{where}: a {point.family} body needs a mean > 0, got {point.mean:g} e-/s")
        scale = point.mean if point.family in ("inverse_gaussian", "lognormal", "gamma") else max(abs(point.mean), 1.0)
        if not MIN_CV <= point.std / scale <= MAX_CV:
            raise _invalid(f"{where}: std {point.std:g} e-/s with mean {point.mean:g} e-/s: the std must be "
                           f"{MIN_CV:g} to {MAX_CV:g} times the mean (the distribution cannot be computed beyond)")
        try:
            point.model()
        except UnreachablePpm as exc:
            raise _invalid(f"{where}.tail.ppm_above = {tail.ppm_above:g}: {exc}") from None
        except (ValueError, ArithmeticError) as exc:  # what SciPy could not compute for these parameters
            raise _invalid(f"{where}: the {point.family} body with mean {point.mean:g} and std {point.std:g} e-/s "
                           f"cannot be computed ({type(exc).__name__}: {str(exc)[:80]})") from None
        out.append(point)
    return out


def prnu_seen_per_sigma(config: Config) -> float:
    """The PRNU frames show per unit of gain-map sigma: crosstalk averages neighbouring gains.

    For each pixel of the CFA's 2 x 2 cell, its charge under a flat field is
    a weighted sum of its neighbours' gains; with independent gains the
    relative std is ``sigma * sqrt(sum w^2) / sum w``. The weights are read by
    spreading a single pixel's charge with the configured kernel(s); the
    result is the root mean square over the cell. 1 without crosstalk.
    """
    import json

    if not config.crosstalk.enabled:
        return 1.0
    return _seen_per_sigma(json.dumps(config.crosstalk.kernel_pct, sort_keys=True), config.sensor.cfa)


@functools.lru_cache(maxsize=64)  # a pure function of its two arguments: a memo, not state (36 spreads a Sensor())
def _seen_per_sigma(kernel_json: str, cfa: str) -> float:
    import json

    import numpy as np

    from .stages import crosstalk

    kernel = crosstalk.kernel_fractions(json.loads(kernel_json))
    n = 8
    ratios = []
    for pr, pc in [(4, 4), (4, 5), (5, 4), (5, 5)]:
        w = []
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                delta = np.zeros((n, n))
                delta[pr + dr, pc + dc] = 1.0
                w.append(crosstalk.apply(delta, kernel, cfa)[pr, pc])
        w = np.array(w)
        ratios.append(float(np.sum(w**2) / np.sum(w) ** 2))
    return float(np.sqrt(np.mean(ratios)))


def resolve_prnu(config: Config) -> Config:
    """``config`` with ``prnu.sigma_pct`` solved from ``prnu.measured_pct`` when that is given."""
    p = config.prnu
    if p.measured_pct is None:
        return config
    sigma = p.measured_pct / prnu_seen_per_sigma(config)
    if "sigma_pct" in p.model_fields_set and abs(p.sigma_pct - sigma) > 1e-6 * max(sigma, 1e-9):
        raise CmosnoiseError(
            f"prnu.sigma_pct = {p.sigma_pct:g} and prnu.measured_pct = {p.measured_pct:g} disagree (through this "
            f"crosstalk {p.measured_pct:g} % measured means a gain-map sigma of {sigma:.6g} %): give one of them"
        )
    if sigma > 100:
        raise CmosnoiseError(f"prnu.measured_pct = {p.measured_pct:g}: needs a gain-map sigma of {sigma:.4g} %, above 100 %")
    return config.model_copy(update={"prnu": p.model_copy(update={"sigma_pct": float(round(sigma, 9))})})


def check_timing(config: Config) -> None:
    """What random telegraph noise needs of the frame timing (:func:`.stages.random_telegraph.check`)."""
    try:
        _check_timing(config)
        rate = 1.0 / _frame_period_s(config.sensor.frame_rate_hz, config.exposure.integration_time_s)
        for key, corner in (("row_noise.corner_hz", config.row_noise.corner_hz),
                            ("column_noise.temporal.corner_hz", config.column_noise.temporal.corner_hz),
                            ("source_follower.flicker.corner_hz", config.source_follower.flicker.corner_hz)):
            one_over_f.corners(key, corner, (0.0, 0.0), rate)
    except ValueError as exc:
        raise _invalid(str(exc)) from None
