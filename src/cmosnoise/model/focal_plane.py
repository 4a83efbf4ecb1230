"""The optical image at the sensor plane: one object from the light and the lens to what each pixel collects.

docs/model.md section 2b is the specification. A :class:`FocalPlane` is made once per light, lens and pixel
(:func:`focal_plane`, kept for equal configuration sections) and holds every fact of that route:

- **the light**: the illuminant through the camera equation and each channel's spectral QE, integrated once
  (:func:`.light.integrate`), or, with light in lux off, ``exposure``'s peak rate;
- **the fine grid**: the optical image is sampled ``k x k`` finer than the pixels (``optics.oversample``;
  ``auto``: :func:`.optics.oversample`). Every scene draws into it: a picture resampled from its own pixels, a
  chart drawn there (the edge's exact area shares, the zone plate's and the Siemens star's area integrals);
- **the lens**: the PSF point-sampled on the fine grid (:mod:`.optics`), the relative illumination and the
  chief-ray angle's QE loss;
- **the pixel**: its aperture (a square of side ``pitch sqrt(light.fill_factor)``) and the optical low-pass
  filter (``optics.olpf``) as weights on the fine cells (:func:`.optics.aperture`).

A pixel's signal is the optical image integrated over its aperture:
``P(i, j) = sum_(u, v) W(u) W(v) (h * F)(k i + u, k j + v)``, F the scene's fine cells, h the PSF, W the
aperture's weights. With ``G = h * (W x W)`` this is one strided convolution ``P = sum G F``. It is computed without
ever making the fine grid whole: each channel's PSF core is written as a short sum of separable terms
(:func:`cmosnoise.engine.separable.terms`, within :data:`TERM_TOLERANCE` of its peak, its sum kept; a Gaussian
is one term, as is the diffraction PSF's halo), so ``P`` is, per term, a pass along the rows and one along the
columns. For a picture those passes fold into its resampling's own separable weights (the rows' weights times
the picture's, the columns' likewise, :mod:`scipy.sparse`): their cost is the picture's resampling's, whatever
``k``. A chart is drawn on the fine grid band by band and passed through the same weights. The column pass is
made at each pixel's own channel only (:func:`cmosnoise.engine.resample.mosaic_channels`), in a fixed order, so
any region is bit for bit that crop of the whole sensor.

With ``k = 1``, no PSF and no filter the signal is :func:`.scene.cfa_signal`'s, bit for bit.

Examples
--------
>>> from cmosnoise import load_config
>>> from cmosnoise.model.focal_plane import focal_plane
>>> fp = focal_plane(load_config(overrides=["optics.psf=diffraction", "optics.f_number=2.8"]))
>>> fp.k, fp.psf.core.shape[0]
(3, 3)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..engine import resample as resample_engine
from ..engine import separable
from ..errors import CmosnoiseError
from . import cfa as cfa_mod
from . import light as light_mod
from . import optics
from . import scene as scene_mod

#: a PSF core's separable terms: the fewest whose largest error is at most this share of the core's peak
TERM_TOLERANCE = 1e-4
#: the most float64 values a band of the column pass holds (about 48 MB)
BAND_VALUES = 6_000_000

__all__ = ["FocalPlane", "Term", "focal_plane", "axis_illuminance_lux", "TERM_TOLERANCE"]


@dataclass(frozen=True)
class Term:
    """One separable term of a channel's kernel: ``outer(rows, cols)``, each axis's taps at fine-cell offsets from
    ``offset`` on, relative to an output's first fine cell (a pixel's ``k i``, or a fine cell itself)."""

    rows: np.ndarray
    row_offset: int
    cols: np.ndarray
    col_offset: int


@dataclass(frozen=True, eq=False)
class FocalPlane:
    """The optical image at the sensor plane of one light, lens and pixel (see the module docstring).

    Parameters
    ----------
    config : Config
        The configuration it was made from (its ``light``, ``optics`` and ``sensor`` sections are what it reads).
    shape : (rows, cols)
        The sensor's pixels.
    k : int
        Fine cells per pixel along each axis.
    light : ChannelLight or None
        Light in lux at the pixels (None: ``exposure``'s peak rate is the light).
    psf : PointSpread or None
        The PSF on the fine grid.
    cfa_gain : (3,) float64 array
        Each channel's white (a scene value of 1) in the signal's unit, its aperture's share included: with light
        in lux its photo-electron rate, e-/s per pixel; else its relative responsivity.
    unit_e_per_s : float
        The e-/s a pixel signal of 1 stands for: 1 with light in lux (the signal is the rate), else the peak rate.
    pixel_terms, fine_terms : tuple of 3 tuples of Term
        Each channel's separable terms to a pixel (the PSF through the aperture and the filter, stride k) and to a
        fine cell (the PSF alone, stride 1).
    key : tuple
        What it was made from (the configuration's light and optics sections, the pixel, the peak rate, the
        shape): equal keys, the same optical image.
    """

    config: object
    shape: tuple[int, int]
    k: int
    light: light_mod.ChannelLight | None
    psf: optics.PointSpread | None
    cfa_gain: np.ndarray
    unit_e_per_s: float
    pixel_terms: tuple
    fine_terms: tuple
    key: tuple

    # ---------------------------------------------------------------- what it implies
    @property
    def pitch_um(self) -> float:
        return float(self.config.sensor.pixel_pitch_um)

    @property
    def fill_factor(self) -> float:
        """The aperture's share of the pixel's area."""
        return float(self.config.light.fill_factor)

    @property
    def olpf_um(self) -> float | None:
        return self.config.optics.olpf

    @property
    def fine_shape(self) -> tuple[int, int]:
        """The fine grid's cells, (rows, cols)."""
        return self.shape[0] * self.k, self.shape[1] * self.k

    @property
    def trivial(self) -> bool:
        """Whether a pixel's signal is the scene's own (``k = 1``, no PSF, no filter): :func:`.scene.cfa_signal`."""
        return self.k == 1 and self.psf is None and not self.olpf_um

    @property
    def peak_rate_e_per_s(self) -> float:
        """The photo-electron rate of a white, e-/s per pixel: the channels' mean with light in lux (their ratios:
        :attr:`responsivity`), else the configured peak rate."""
        if self.light is not None:
            return float(self.light.rates_e_per_s.mean() * self.fill_factor)
        return float(self.unit_e_per_s)

    @property
    def responsivity(self) -> tuple[float, float, float]:
        """Each channel's white rate over :attr:`peak_rate_e_per_s`: what processing calls the channels' relative
        responsivity."""
        peak = self.peak_rate_e_per_s
        return tuple(float(v / peak) for v in self.white_e_per_s)

    @property
    def focal_plane_lux(self) -> float | None:
        """The focal-plane illuminance on the optical axis from a white (reflectance 1), lux (None without light in
        lux); times the integration time, the focal-plane exposure in lux-seconds."""
        return None if self.light is None else self.light.focal_plane_lux

    @property
    def white_e_per_s(self) -> np.ndarray:
        """Each channel's photo-electron rate from a white, e-/s per pixel."""
        return self.cfa_gain * self.unit_e_per_s

    # ---------------------------------------------------------------- scenes
    def prepare(self, source: str, section):
        """A scene drawn on this optical image's fine grid (:func:`.scene.prepare_configured` with ``cells = k``).

        Parameters
        ----------
        source : str
            A built-in scene or a file.
        section : SceneSection
            ``config.scene``.

        Returns
        -------
        callable
            ``region (fine cells) -> (rows, cols, 3)``: each channel's signal relative to its white.
        """
        return scene_mod.prepare_configured(source, self.shape, section, self.light, self.k)

    def picture(self, rgb: np.ndarray):
        """An array (the sensor's pixels, linear RGB) as a scene on the fine grid: itself at ``k = 1``, resampled
        (bilinearly) to the fine grid otherwise.

        Parameters
        ----------
        rgb : (rows, cols, 3) float64 array
            Each channel's signal relative to its white (:func:`.scene.mixed` applied).

        Returns
        -------
        callable
            As :meth:`prepare`.
        """
        if self.k == 1:
            return lambda region=None: rgb if region is None else rgb[region[0]:region[1], region[2]:region[3]]
        return scene_mod.Resampled(np.ascontiguousarray(rgb, np.float64), self.fine_shape)

    # ---------------------------------------------------------------- what the pixels collect
    def pixel_signal(self, draw, pattern: str, region=None, shade: bool = True) -> np.ndarray:
        """Each pixel's signal: the optical image through the PSF, integrated over the pixel's aperture (its own CFA
        channel), then the relative illumination and the chief-ray angle's QE loss.

        Parameters
        ----------
        draw : callable
            :meth:`prepare`'s or :meth:`picture`'s result (a raw photograph's draw passes through as it is).
        pattern : str
            The CFA.
        region : (row0, row1, col0, col1), optional
            The pixels to make (None: the whole sensor); any region is bit for bit that crop of the whole.
        shade : bool
            Apply the relative illumination and the QE loss.

        Returns
        -------
        (rows, cols) float64 array
            In :attr:`unit_e_per_s`: times it and the integration time, mean photo-electrons. At least 0.
        """
        rows, cols = self.shape
        region = (0, rows, 0, cols) if region is None else tuple(int(v) for v in region)
        if isinstance(draw, scene_mod.RawDraw):
            if optics.active(self.config) or not self.trivial:
                raise CmosnoiseError("scene: a raw photograph already went through its own lens and pixels; set "
                                     "optics.psf, optics.relative_illumination, optics.angle_relative_qe and "
                                     "optics.olpf to none and optics.oversample to 1 for it")
            return scene_mod.cfa_signal(draw, pattern, region=region)
        if self.trivial and cfa_mod.is_mono(pattern) and self.light is not None:
            signal = self.through_cfa(np.asarray(draw(region), np.float64), pattern)
        elif self.trivial:
            signal = scene_mod.cfa_signal(draw, pattern, tuple(self.cfa_gain), region)
        else:
            signal = self._convolved(draw, pattern, region, self.pixel_terms, self.k, self.shape)
        return optics.shade(signal, self.config, pattern, self.shape, region) if shade else signal

    def through_cfa(self, rgb: np.ndarray, pattern: str) -> np.ndarray:
        """An image at the pixels (each channel relative to its white) through the CFA, in the signal's unit: each
        pixel's channel times its :attr:`cfa_gain`; a monochrome sensor's luminance, each channel weighted by its
        gain with light in lux (the luminance alone without: the peak rate is the unit).

        Parameters
        ----------
        rgb : (rows, cols, 3) float64 array
        pattern : str

        Returns
        -------
        (rows, cols) float64 array
        """
        if cfa_mod.is_mono(pattern) and self.light is not None:
            return rgb @ (scene_mod.LUMINANCE * self.cfa_gain)
        return scene_mod.to_cfa(rgb, pattern, tuple(self.cfa_gain))

    def irradiance(self, draw, region=None) -> np.ndarray:
        """The optical image on the fine grid: the scene through the PSF (before the filter and the aperture), each
        channel in the pixel signal's unit per pixel area (a uniform image of value E gives a pixel of full
        aperture E).

        Parameters
        ----------
        draw : callable
            :meth:`prepare`'s or :meth:`picture`'s result.
        region : (row0, row1, col0, col1), optional
            Fine cells (None: all of them).

        Returns
        -------
        (rows, cols, 3) float64 array
            The relative illumination and the QE loss at each cell's centre are not in it.
        """
        fr, fc = self.fine_shape
        region = (0, fr, 0, fc) if region is None else tuple(int(v) for v in region)
        gain = self.cfa_gain / self.fill_factor
        if self.psf is None:
            return np.asarray(draw(region), np.float64) * gain
        out = np.empty((region[1] - region[0], region[3] - region[2], 3))
        for c in range(3):
            out[..., c] = self._convolved(draw, None, region, self.fine_terms, 1, self.fine_shape, channel=c)
        return out * gain

    def _convolved(self, draw, pattern, region, terms, stride: int, shape, channel: int | None = None):
        """``sum_t`` of each term's rows' pass and columns' pass, at each output's own channel (a CFA's, the
        luminance's for ``none``, or ``channel`` for all of them), times the channel's gain."""
        r0, r1, c0, c1 = region
        fr, fc = self.fine_shape
        picture = isinstance(draw, scene_mod.Resampled)
        # the output channels and, for each, its blocks: (the picture's channel, a term, the block's weight)
        if channel is not None:
            outputs = [[(channel, t, 1.0) for t in terms[channel]]]
            gain = np.array([self.cfa_gain[channel] / self.fill_factor])
        elif cfa_mod.is_mono(pattern):
            lum = scene_mod.LUMINANCE * (self.cfa_gain if self.light is not None else 1.0)
            outputs = [[(c, t, float(lum[c])) for c in range(3) for t in terms[c]]]
            gain = np.array([1.0 / self.fill_factor])
        else:
            outputs = [[(c, t, 1.0) for t in terms[c]] for c in range(3)]
            gain = self.cfa_gain / self.fill_factor
        axes = draw.img.shape[:2] if picture else (None, None)
        # each block's weights over the picture's rows (or the fine grid's) and columns, for the whole region
        row_w, col_w = [], []
        for blocks in outputs:
            row_w.append([_weights(t.rows, t.row_offset, stride, r0, r1, fr, axes[0]) for _, t, _ in blocks])
            col_w.append([_weights(t.cols, t.col_offset, stride, c0, c1, fc, axes[1]) * w for _, t, w in blocks])
        b0 = min(int(m.indices.min()) for ws in col_w for m in ws if m.nnz)
        b1 = max(int(m.indices.max()) for ws in col_w for m in ws if m.nnz) + 1
        width = b1 - b0
        nblk = max(len(blocks) for blocks in outputs)
        # each output channel's columns' weights, its blocks side by side (width columns each)
        columns = []
        for ws in col_w:
            cut = [m[:, b0:b1] for m in ws] + [sp.csr_matrix((c1 - c0, width))] * (nblk - len(ws))
            columns.append(sp.csr_matrix(sp.hstack(cut, format="csr")))
        out = np.empty((r1 - r0, c1 - c0))
        band = max(2, BAND_VALUES // max(len(outputs) * nblk * width, 1) // 2 * 2)
        for i0 in range(0, r1 - r0, band):
            i1 = min(i0 + band, r1 - r0)
            cut_rows = [[m[i0:i1] for m in ws] for ws in row_w]
            a0 = min(int(m.indices.min()) for ws in cut_rows for m in ws if m.nnz)
            a1 = max(int(m.indices.max()) for ws in cut_rows for m in ws if m.nnz) + 1
            values = draw.img[a0:a1, b0:b1] if picture else np.asarray(draw((a0, a1, b0, b1)), np.float64)
            # each block's rows' pass, transposed (its rows, even then odd, consecutive): what the columns' pass reads
            planes = np.empty((len(outputs), nblk * width, i1 - i0))
            channels = np.ascontiguousarray(np.moveaxis(values, 2, 0))
            for oc, blocks in enumerate(outputs):
                for n, ((c, _, _), m) in enumerate(zip(blocks, cut_rows[oc])):
                    resample_engine.rows_transposed(channels[c], m[:, a0:a1], planes[oc, n * width:(n + 1) * width])
                planes[oc, len(blocks) * width:] = 0.0
            if channel is not None or cfa_mod.is_mono(pattern):
                cells = np.zeros((2, 2), np.int64)
            else:
                cells = cfa_mod.tile(cfa_mod.crop_pattern(pattern, r0 + i0, c0))
            out[i0:i1] = resample_engine.mosaic_transposed(planes, columns, cells, gain)
        return out


def _weights(taps: np.ndarray, offset: int, stride: int, start: int, stop: int, size: int, source: int | None):
    """One axis of a term as sparse weights, (stop - start, n): output ``o`` (from ``start``) takes ``taps[d]`` of
    the fine cell ``stride o + offset + d``, the fine grid's edge cells repeated beyond it; through a picture's
    resampling of ``source`` pixels to the ``size`` fine cells (:func:`.scene.resample`'s weights) where the scene
    is a picture (``source`` not None). Made once for each geometry (read-only)."""
    return _axis_weights(np.asarray(taps, np.float64).tobytes(), offset, stride, start, stop, size, source)


@functools.lru_cache(maxsize=256)
def _axis_weights(taps: bytes, offset, stride, start, stop, size, source):
    taps = np.frombuffer(taps, np.float64)
    n = stop - start
    d = np.arange(taps.size)
    cells = np.clip(stride * np.arange(start, stop)[:, None] + offset + d[None, :], 0, size - 1)
    m = sp.csr_matrix((np.broadcast_to(taps, cells.shape).ravel(), (np.repeat(np.arange(n), taps.size),
                                                                     cells.ravel())), shape=(n, size))
    m.sum_duplicates()
    if source is not None:
        m = m @ scene_mod.axis_weights(source, size)
        m.sort_indices()
    for a in (m.data, m.indices, m.indptr):
        a.setflags(write=False)
    return m


def _terms(psf: optics.PointSpread, weights: tuple[int, np.ndarray] | None, splits: list) -> tuple:
    """Each channel's separable terms: its core's (``splits``, :func:`_splits`) and its halo's, each axis's taps
    convolved with the aperture's ``weights`` (offset, taps) where given (a pixel's), else alone (a fine
    cell's)."""
    w_off, w = weights if weights is not None else (0, np.ones(1))
    out = []
    for c in range(3):
        core = psf.core[c]
        m = core.shape[0] // 2
        rows, cols = splits[c]
        terms = [Term(np.convolve(r, w), w_off - m, np.convolve(q, w), w_off - m) for r, q in zip(rows, cols)]
        if psf.halo_share[c] > 0:
            sigma = float(psf.halo_sigma_cells[c])
            half = int(math.ceil(optics.GAUSS_SIGMAS * sigma))
            g = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
            g = g / g.sum()
            terms.append(Term(np.convolve(g * psf.halo_share[c], w), w_off - half, np.convolve(g, w), w_off - half))
        out.append(tuple(terms))
    return tuple(out)


def _splits(psf: optics.PointSpread) -> list[tuple[list, list]]:
    """Each channel's core as separable terms (:func:`cmosnoise.engine.separable.terms`): one split for each
    distinct core, which the pixels' terms and the fine cells' share."""
    out: list[tuple[list, list]] = []
    for c in range(3):
        same = [prev for prev in range(c) if np.array_equal(psf.core[prev], psf.core[c])]
        out.append(out[same[0]] if same else separable.terms(psf.core[c], TERM_TOLERANCE))
    return out


def _no_psf_terms(weights: tuple[int, np.ndarray] | None) -> tuple:
    """The terms of a point PSF: the aperture's weights alone (a pixel's), or the identity (a fine cell's)."""
    w_off, w = weights if weights is not None else (0, np.ones(1))
    return tuple((Term(w, w_off, w, w_off),) for _ in range(3))


def axis_illuminance_lux(config) -> float:
    """The focal-plane illuminance on the optical axis from a white (reflectance 1) of the configured light, lux:
    the camera equation (:func:`.light.camera_factor`) of its luminance, whether light in lux is on or not.

    Parameters
    ----------
    config : Config

    Returns
    -------
    float
        lux; times the integration time: the focal-plane exposure in lux-seconds.
    """
    li, op = config.light, config.optics
    luminance = li.luminance_cd_m2 if li.luminance_cd_m2 is not None else (li.illuminance_lux or 0.0) / math.pi
    return light_mod.camera_factor(op.f_number, op.transmittance, op.magnification, op.camera_equation) * luminance


def focal_plane(config, shape: tuple[int, int] | None = None) -> FocalPlane:
    """The optical image of a configuration's light, lens and pixel (kept for equal sections).

    Parameters
    ----------
    config : Config
    shape : (rows, cols), optional
        The sensor's pixels (default: the configuration's).

    Returns
    -------
    FocalPlane

    Raises
    ------
    CmosnoiseError
        What the light, the PSF or the oversampling cannot mean (an unknown illuminant, a PSF file that does not
        divide into the fine grid, ...).
    """
    shape = tuple(config.shape if shape is None else shape)
    sen, ex = config.sensor, config.exposure
    key = (config.light.key(), config.optics.key(), sen.pixel_pitch_um, _hashable(sen.quantum_efficiency),
           tuple(sen.channel_responsivity), ex.peak_rate_e_per_s, ex.peak_rate_photons_per_s, shape)
    return _made(key, config)


class _Keyed:
    """A configuration carried beside its key: the cache compares keys only."""

    def __init__(self, key, config):
        self.key, self.config = key, config

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, _Keyed) and other.key == self.key


def _made(key, config) -> FocalPlane:
    return _build(_Keyed(key, config))


@functools.lru_cache(maxsize=16)
def _build(keyed: _Keyed) -> FocalPlane:
    config = keyed.config
    shape = keyed.key[-1]
    li, op, sen = config.light, config.optics, config.sensor
    pitch = float(sen.pixel_pitch_um)
    optics.check_tables(op)  # every table it names, read now whether or not this configuration uses it
    light = None
    if li.enabled:
        lux = li.illuminance_lux if li.illuminance_lux is not None else math.pi * li.luminance_cd_m2
        k_cam = light_mod.camera_factor(op.f_number, op.transmittance, op.magnification, op.camera_equation)
        light = light_mod.integrate(li.illuminant, lux, li.spectral_qe, li.qe_peak, sen.quantum_efficiency,
                                    li.ir_cut_nm, k_cam, pitch**2)
    if light is not None:  # each channel's rate, e-/s: the signal is the rate
        gain = light.rates_e_per_s * np.asarray(sen.channel_responsivity, np.float64) * li.fill_factor
        unit = 1.0
    else:  # each channel's relative responsivity: the signal is relative to the peak rate
        gain = _responsivity(config)
        unit = _peak_rate(config)
    # the PSF, the fine grid it needs, and the terms
    olpf_px = None if not op.olpf else op.olpf / pitch
    psf = None
    kind = op.psf.lower()
    candidates = None
    if kind == "diffraction":
        if light is not None:
            weights = np.stack([light.photon_flux * light.qe[:, c] for c in range(3)])
            wavelengths = light.wavelengths
        else:
            wavelengths, weights = np.asarray(optics.DEFAULT_WAVELENGTHS_NM), np.eye(3)
        make = functools.partial(optics.diffraction_psf, wavelengths, weights, op.f_number, pitch)
    elif kind == "gaussian":
        make = functools.partial(optics.gaussian_psf, op.psf_sigma_px)
    elif kind != "none":
        candidates = [k for k in range(1, optics.MAX_OVERSAMPLE + 1) if _divides(op, pitch, k)]
        if op.oversample == "auto" and not candidates:
            optics.file_psf(op.psf, op.psf_sampling_um, pitch, 1)  # its one-line error
        make = functools.partial(optics.file_psf, op.psf, op.psf_sampling_um, pitch)
    if kind != "none":
        probe = make(max(candidates) if candidates else 1)
        k = optics.oversample(op.oversample, probe, li.fill_factor, olpf_px, candidates)
        psf = make(k)
    else:
        k = optics.oversample(op.oversample, None, li.fill_factor, olpf_px)
    weight = None if psf is None else (lambda f: psf.mtf(f).max(axis=0))
    aperture = optics.aperture(k, li.fill_factor, None if not op.olpf else op.olpf / (pitch / k), weight)
    if psf is None:
        pixel_terms, fine_terms = _no_psf_terms(aperture), _no_psf_terms(None)
    else:
        splits = _splits(psf)
        pixel_terms, fine_terms = _terms(psf, aperture, splits), _terms(psf, None, splits)
    gain = np.asarray(gain, np.float64)
    gain.setflags(write=False)
    return FocalPlane(config, shape, k, light, psf, gain, float(unit), pixel_terms, fine_terms, keyed.key)


def _divides(op, pitch: float, k: int) -> bool:
    s = pitch if op.psf_sampling_um is None else float(op.psf_sampling_um)
    j = pitch / k / s
    return abs(j - round(j)) <= 1e-9 * max(j, 1) and round(j) >= 1


def _peak_rate(config) -> float:
    """The photo-electron rate of a scene value of 1 without light in lux: the configured one, or its photons
    times the quantum efficiency (the channels' mean)."""
    ex, q = config.exposure, config.sensor.qe_mean()
    return float(ex.peak_rate_e_per_s if ex.peak_rate_photons_per_s is None else ex.peak_rate_photons_per_s * q)


def _responsivity(config) -> np.ndarray:
    """Each channel's relative responsivity without light in lux: the filters', times each channel's quantum
    efficiency over their mean when the light is given in photons with a QE per channel."""
    sen = config.sensor
    r = np.asarray(sen.channel_responsivity, np.float64)
    q = sen.quantum_efficiency
    if config.exposure.peak_rate_photons_per_s is None or q is None or isinstance(q, (int, float)):
        return r
    return r * np.asarray(q, np.float64) / sen.qe_mean()


def _hashable(v):
    return tuple(v) if isinstance(v, (list, tuple)) else v
