"""The resolved sensor specification: a configuration and everything it implies, built once.

A :class:`~cmosnoise.config.Config` is data the schema accepted. A
:class:`SensorSpec` is what the model reads: that configuration with
``prnu.sigma_pct`` solved from ``prnu.measured_pct`` where it was given, the
dark-current characterization points in e-/s, the flicker-sigma
distribution, the PRNU a flat field shows per unit of gain-map sigma, and
the ADC's transfer. :func:`resolve` builds it and raises
:class:`~cmosnoise.errors.CmosnoiseError` for what only the physics can
tell (an unreachable ppm, a body distribution that cannot be computed). It
is immutable: :class:`~cmosnoise.model.sensor.Sensor` and the frame plan
read it and never recompute any of it.

>>> from cmosnoise import load_config
>>> from cmosnoise.model.spec import resolve
>>> spec = resolve(load_config(preset="paper-fig11-full"))
>>> spec.transfer.bits
10
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Config, merge_updates
from . import light as light_mod
from . import one_over_f, physics
from .focal_plane import FocalPlane, focal_plane
from .heavy_tail import HeavyTail
from .stages import adc, random_telegraph
from .stages.dark_current import Point
from .stages.nonlinearity import Curve
from .stages.pixel_offset import OffsetModel


@dataclass(frozen=True, eq=False)
class SensorSpec:
    """A configuration resolved: what the model reads (see the module docstring).

    Parameters
    ----------
    config : Config
        The validated configuration, ``prnu.sigma_pct`` solved.
    dark_points : tuple of Point
        Dark-current characterization points, rates in e-/s (resolved whether the stage is on or off).
    flicker : HeavyTail
        Per-pixel flicker-sigma distribution, e- rms.
    prnu_seen_per_sigma : float
        PRNU a flat field shows per unit of gain-map sigma (crosstalk averages neighbours; 1 without it).
    transfer : adc.Transfer
        The ADC transfer (the ideal one, 1 DN per e-, with the ADC off).
    offsets : OffsetModel
        The pixel offsets' law, e- (its tail fraction solved).
    nonlinearity : nonlinearity.Curve or None
        The charge-to-voltage transfer (:mod:`.stages.nonlinearity`), ``None`` where the configuration gives none.

    Examples
    --------
    >>> from cmosnoise import load_config, resolve
    >>> spec = resolve(load_config(overrides=["prnu.measured_pct=1.5"]))   # PRNU solved from its measured value
    >>> spec.config.prnu.sigma_pct > 0, spec.shape
    (True, (480, 640))
    """

    config: Config
    dark_points: tuple[Point, ...]
    flicker: HeavyTail
    prnu_seen_per_sigma: float
    transfer: adc.Transfer
    offsets: OffsetModel
    nonlinearity: Curve | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the sensor."""
        return self.config.shape

    @property
    def seed(self) -> int:
        return self.config.seed

    @property
    def saturation_e(self) -> float:
        """Charge at saturation: the full well, or the ADC's full scale if that comes first (e-)."""
        t = self.transfer
        return float(min(self.config.sensor.full_well_e, (t.max_code - t.black_level_dn) / t.gain_dn_per_e))

    @property
    def notes(self) -> list[str]:
        """How parts of the configuration read that a user could take otherwise, one sentence each: a linearity
        error (defined on a series to the full well) when the ADC clips first, where an EMVA 1288 series ends
        at the ADC's full scale and reads a different one."""
        from .stages.nonlinearity import SERIES, linearity_error

        out = []
        nl = self.config.nonlinearity
        curve = self.active_nonlinearity
        fw, sat = float(self.config.sensor.full_well_e), self.saturation_e
        if curve is not None and nl.linearity_error_pct is not None and sat < fw:
            x = np.linspace(0.0, sat, SERIES)
            y = curve.apply(x)
            lo, hi = linearity_error(x, y, float(y[-1]))
            out.append(f"nonlinearity.linearity_error_pct = {list(nl.linearity_error_pct)} is defined on a series to "
                       f"the full well ({fw:g} e-); the ADC clips first, at {sat:.0f} e-, and an EMVA 1288 series to "
                       f"there reads [{lo:+.2f}, {hi:+.2f}] %")
        return out

    @property
    def active_nonlinearity(self) -> Curve | None:
        """The nonlinearity's curve when the stage is on (wherever it acts), else None."""
        return self.nonlinearity if self.config.nonlinearity.enabled else None

    def nonlinearity_on(self, acts_on: str) -> Curve | None:
        """The nonlinearity's curve when the stage is on and acts on ``acts_on``.

        Parameters
        ----------
        acts_on : str
            ``"charge"`` (each frame's collected charge, in the frame kernel) or ``"mean"`` (the mean
            photo-charge, in the exposure).

        Returns
        -------
        Curve or None
            The curve, or None where the stage is off or acts on the other.
        """
        return self.active_nonlinearity if self.config.nonlinearity.acts_on == acts_on else None

    @property
    def black_level_varies(self) -> bool:
        """Whether the black level has more than ``adc.black_level_dn``: offsets per CFA cell or a frame error."""
        b = self.config.black_level
        return any(v != 0 for v in b.channel_offsets_dn) or b.frame_sigma_dn > 0

    @property
    def row_sigma_e(self) -> float:
        """The temporal row noise, e- rms: ``row_noise.sigma_e`` and ``row_noise.sigma_dn`` (after the gain) referred
        to e- through K, added in variance (one normal per row and frame carries both)."""
        rn = self.config.row_noise
        if rn.sigma_dn == 0:
            return rn.sigma_e
        return float(np.sqrt(rn.sigma_e**2 + (rn.sigma_dn / self.transfer.gain_dn_per_e) ** 2))

    @property
    def frame_period_s(self) -> float:
        """Seconds between two frames' starts: ``1 / sensor.frame_rate_hz``, or the exposure (back to back)."""
        c = self.config
        return random_telegraph.frame_period_s(c.sensor.frame_rate_hz, c.exposure.integration_time_s)

    @property
    def row_flicker(self) -> one_over_f.Spectrum | None:
        """The 1/f row noise's Lorentzians (``row_noise.spectrum = one_over_f``), or None: white.

        Sampled at the row rate (``rows / frame_period``); ``corner_hz`` null: a thousandth of the frame rate to
        the lesser of half the row rate and a thousand times the frame rate."""
        rn = self.config.row_noise
        if not rn.enabled or rn.spectrum == "white":
            return None
        rate = 1.0 / self.frame_period_s
        default = one_over_f.row_corners(rate, self.config.sensor.height)
        return one_over_f.lorentzians(*one_over_f.corners("row_noise.corner_hz", rn.corner_hz, default, rate))

    @property
    def column_flicker(self) -> one_over_f.Spectrum | None:
        """Each column amplifier's 1/f Lorentzians (``column_noise.temporal.spectrum = one_over_f``), or None.

        Sampled at the frame rate; ``corner_hz`` null: a thousandth of the frame rate to half of it."""
        cn = self.config.column_noise
        if not (cn.enabled and cn.temporal.enabled) or cn.temporal.spectrum == "white":
            return None
        rate = 1.0 / self.frame_period_s
        return one_over_f.lorentzians(*one_over_f.corners("column_noise.temporal.corner_hz", cn.temporal.corner_hz,
                                                          one_over_f.column_corners(rate), rate))

    @property
    def pixel_flicker(self) -> one_over_f.Spectrum | None:
        """Each pixel's flicker Lorentzians (``source_follower.flicker.spectrum = one_over_f``), or None: white.

        ``corner_hz`` null: a thousandth of the frame rate to a thousand times it."""
        sf = self.config.source_follower
        if not (sf.enabled and sf.flicker.enabled) or sf.flicker.spectrum == "white":
            return None
        rate = 1.0 / self.frame_period_s
        return one_over_f.lorentzians(*one_over_f.corners("source_follower.flicker.corner_hz", sf.flicker.corner_hz,
                                                          one_over_f.pixel_corners(rate), rate))

    @property
    def flicker_in_frames(self) -> bool:
        """Whether each frame shows the pixel's 1/f flicker level itself (``one_over_f`` without CDS: drawn per
        frame by its bridges) rather than a white normal of its sigma (white, or ``one_over_f`` through CDS)."""
        return self.pixel_flicker is not None and not self.config.source_follower.rts.cds

    @property
    def flicker_cds_factor(self) -> float:
        """What the flicker sigmas are multiplied by: ``sqrt(D(tau) / D(tau_ref))`` for a 1/f flicker through CDS
        (``D`` the CDS output's variance, :func:`.one_over_f.cds_variance`; ``tau`` the CDS interval, ``tau_ref``
        the one the sigmas hold at); 1 otherwise."""
        spectrum, sf = self.pixel_flicker, self.config.source_follower
        if spectrum is None or not sf.rts.cds or sf.rts.cds_interval_s == sf.flicker.reference_cds_interval_s:
            return 1.0
        ratio = one_over_f.cds_variance(spectrum, sf.rts.cds_interval_s) / one_over_f.cds_variance(
            spectrum, sf.flicker.reference_cds_interval_s)
        return float(math.sqrt(float(ratio)))

    @property
    def focal_plane(self) -> FocalPlane:
        """The optical image of this configuration's light, lens and pixel (:func:`.focal_plane.focal_plane`, made
        once per light and lens): what every scene is drawn into and each pixel integrates."""
        return focal_plane(self.config)

    @property
    def peak_rate_e_per_s(self) -> float:
        """Photo-electrons per second per pixel at a scene value of 1: the configuration's, or its photons times
        the quantum efficiency, or with light in lux the channels' mean (:attr:`channel_responsivity` carries their
        ratios)."""
        return self.focal_plane.peak_rate_e_per_s

    @property
    def signal_unit_e_per_s(self) -> float:
        """The e-/s a scene signal of 1 stands for (:attr:`.focal_plane.FocalPlane.unit_e_per_s`): the peak rate,
        or 1 with light in lux (the signal is then each pixel's rate)."""
        return self.focal_plane.unit_e_per_s

    @property
    def light(self) -> light_mod.ChannelLight | None:
        """The light in lux at the pixels, per channel (made once per light and lens), or None where the light is
        ``exposure``'s peak rate."""
        return self.focal_plane.light if self.config.light.enabled else None

    @property
    def channel_responsivity(self) -> tuple[float, float, float]:
        """Relative R, G, B responsivity: the filters', times each channel's quantum efficiency over their mean
        when light is given in photons with a QE per channel, or each channel's rate over their mean with light
        in lux."""
        fp = self.focal_plane
        if fp.light is None:
            r, g, b = (float(v) for v in fp.cfa_gain)
            return r, g, b
        return fp.responsivity

    @property
    def white_dn(self) -> float:
        """The raw code of scene white: a scene value of 1, or the top code if that is lower."""
        c, t = self.config, self.transfer
        white_e = self.peak_rate_e_per_s * c.exposure.integration_time_s
        return float(min(t.black_level_dn + white_e * t.gain_dn_per_e, t.max_code))

    def with_config(self, config: Config) -> SensorSpec:
        """This spec with ``config`` in place of its own: nothing is solved again; the frame timing an exposure
        meets is checked (:func:`physics.check_timing`).

        Parameters
        ----------
        config : Config
            Differs from this spec's only in what implies nothing (the exposure, the run, the scene, the
            processing).

        Returns
        -------
        SensorSpec
        """
        physics.check_timing(config)
        return SensorSpec(config, self.dark_points, self.flicker, self.prnu_seen_per_sigma, self.transfer,
                          self.offsets, self.nonlinearity)

    def updated(self, updates: dict) -> SensorSpec:
        """A new spec: this configuration with ``updates`` merged in (every value set kept), resolved.

        Parameters
        ----------
        updates : dict
            Sections and keys to change, nested as the configuration is.

        Returns
        -------
        SensorSpec
        """
        return resolve(merge_updates(self.config, updates))


def transfer(config: Config) -> adc.Transfer:
    """The ADC transfer a configuration sets (the ideal one with the ADC off).

    Parameters
    ----------
    config : Config

    Returns
    -------
    cmosnoise.model.stages.adc.Transfer
        K (DN/e-, from ``adc.gain_dn_per_e`` or the full scale over the codes), black level (DN), bits and the
        output's step (``adc.output_bits``).
    """
    a = config.adc
    if not a.enabled:
        return adc.Transfer.ideal()
    if a.gain_dn_per_e is not None:
        return adc.Transfer.from_gain(a.bits, a.black_level_dn, a.gain_dn_per_e, a.output_bits)
    full_scale = a.full_scale_e if a.full_scale_e is not None else config.sensor.full_well_e
    return adc.Transfer.from_settings(a.bits, a.black_level_dn, full_scale, a.output_bits)


def _mean_square(sf, upper: float) -> float:
    """E[X^2] of a non-negative quantity from its survival function: ``int_0^inf 2 x sf(x) dx``."""
    from scipy.integrate import quad

    return float(quad(lambda x: 2.0 * x * float(sf(x)), 0.0, upper, limit=200)[0])


def dark_read_variances(config: Config) -> dict[str, float]:
    """The dark temporal read noise's parts at no exposure, e-^2, as the population of sensor instances expects
    them: ``source_follower.read_noise_e``'s terms (the thermal noise, each pixel's flicker sigma's mean square over
    its distribution, the row noise, each column's temporal sigma's mean square, the ADC's read noise, black-level
    error and quantization referred to e-). An instance's own (:mod:`cmosnoise.analysis.noise_budget`) differs by
    its maps' sampling.

    Parameters
    ----------
    config : Config

    Returns
    -------
    dict of str to float
    """
    from .distributions import gumbel
    from .stages.read_noise import variance_dn2

    out: dict[str, float] = {}
    sf_cfg = config.source_follower
    if sf_cfg.enabled:
        out["thermal"] = sf_cfg.thermal_sigma_e**2
        if sf_cfg.flicker.enabled:
            model = physics.flicker_model(config)
            upper = float(model.tail_max) + max(float(model.body.ppf(1.0 - 1e-12)), 0.0)
            out["flicker"] = _mean_square(model.sf, upper)
    if config.row_noise.enabled:
        rn = config.row_noise
        k = transfer(config).gain_dn_per_e
        out["row"] = rn.sigma_e**2 + (rn.sigma_dn / k) ** 2
    cn = config.column_noise
    if cn.enabled and cn.temporal.enabled:
        col = gumbel(cn.temporal.gumbel_loc_e, cn.temporal.gumbel_scale_e)
        out["column"] = _mean_square(col.sf, abs(cn.temporal.gumbel_loc_e) + 60 * cn.temporal.gumbel_scale_e)
    if cn.enabled and cn.alternating.enabled and cn.alternating.temporal_sigma_e > 0:
        out["column_alternating"] = cn.alternating.temporal_sigma_e**2
    if config.adc.enabled:
        t = transfer(config)
        k2 = t.gain_dn_per_e**2
        if config.read_noise.enabled:
            rd = config.read_noise
            out["read_after_gain"] = variance_dn2(rd.distribution, rd.scale_dn, rd.shape) / k2
        if config.black_level.frame_sigma_dn > 0:
            out["black_level_frame"] = config.black_level.frame_sigma_dn**2 / k2
        out["quantization"] = t.quantization_var_dn2 / k2
    return out


def resolve_read_noise(config: Config) -> Config:
    """``config`` with ``source_follower.thermal_sigma_e`` solved from ``source_follower.read_noise_e`` where that is
    given: ``thermal^2 = read_noise^2 - the other parts of`` :func:`dark_read_variances`.

    Parameters
    ----------
    config : Config

    Returns
    -------
    Config

    Raises
    ------
    CmosnoiseError
        A total below what the other sources already give.
    """
    from ..errors import CmosnoiseError

    sf_cfg = config.source_follower
    if sf_cfg.read_noise_e is None:
        return config
    if not sf_cfg.enabled:
        raise CmosnoiseError(f"source_follower.read_noise_e = {sf_cfg.read_noise_e:g}: the thermal noise it is solved "
                             "for is the source follower's; set source_follower.enabled=true")
    others = {k: v for k, v in dark_read_variances(config).items() if k != "thermal"}
    rest = sum(others.values())
    thermal2 = sf_cfg.read_noise_e**2 - rest
    if thermal2 < 0:
        raise CmosnoiseError(f"source_follower.read_noise_e = {sf_cfg.read_noise_e:g} e-: the other dark sources "
                             f"already give {math.sqrt(rest):.3g} e- ({', '.join(f'{k} {math.sqrt(v):.2g}' for k, v in others.items())}); "
                             f"give at least {math.sqrt(rest):.3g}")
    return merge_updates(config, {"source_follower": {"thermal_sigma_e": math.sqrt(thermal2)}})


def resolve(config: Config | SensorSpec) -> SensorSpec:
    """The :class:`SensorSpec` of ``config``; raises CmosnoiseError on what its values cannot mean.

    A spec passes through unchanged.

    Parameters
    ----------
    config : Config or SensorSpec
        A schema-valid configuration (:func:`cmosnoise.load_config`).

    Returns
    -------
    SensorSpec
        The dark-current points in e-/s, the flicker and offset laws, PRNU solved from its measured value, the
        ADC transfer: what the model reads, computed once.

    Raises
    ------
    CmosnoiseError
        An unreachable ppm, a distribution that cannot be computed, timings out of range.

    Examples
    --------
    >>> from cmosnoise import load_config, resolve
    >>> spec = resolve(load_config())
    >>> spec.shape, spec.transfer.bits
    ((480, 640), 12)
    """
    if isinstance(config, SensorSpec):
        return config
    config = resolve_read_noise(physics.resolve_prnu(physics.apply_gain(config)))
    physics.check_timing(config)
    # every section is checked, those switched off too (a file must stay valid when one is switched on)
    return SensorSpec(config, tuple(physics.dark_points(config)), physics.flicker_model(config),
                      physics.prnu_seen_per_sigma(config), transfer(config), physics.offset_model(config),
                      physics.nonlinearity_curve(config))

