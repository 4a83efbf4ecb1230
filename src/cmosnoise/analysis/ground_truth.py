"""Ground truth of a simulated frame, defined once: the perfect image, the expected raw, and the defect mask.

What a denoiser, a defect corrector or an ISP pipeline is scored against
(docs/model.md, "Ground truth"):

- **perfect image**: the mean photo-electrons of the scene on an ideal
  pixel (stage 1: no PRNU, crosstalk, dark current or defects), e-; and the
  same through the ideal ADC: ``black level + K min(perfect, full well)``,
  clipped to the code range, not rounded (DN, float32). A denoiser that
  also undoes the fixed pattern aims at it.
- **expected raw**: what infinitely many frames of this sensor average to,
  DN (float32): every fixed pattern (PRNU, crosstalk, dark current, pixel,
  row and column offsets, column gains, the black level's cell offsets,
  defects, the random telegraph pixels at their stationary means), no
  temporal noise, the full-well and ADC clips and the quantizer included
  (:func:`cmosnoise.analysis.noise_budget.clipped_moments`). A denoiser
  that keeps the fixed pattern (a temporal-noise remover) aims at it. With
  the ADC off, e-.
- **each stage's contribution** to one frame: ``exposure.frame(k,
  detail=True).contributions`` (e-, they add up to the electrons at the ADC
  input); it runs the stages one by one, so it costs more than a frame.
- **the defect mask**: uint16 bits, one per kind (:data:`MASK_BITS`). A
  pixel that is two things has both bits.

The perfect image, the expected raw and the mask together cost 0.9 to 1.9
frames' time (measured at 512 x 512, VGA and 1080p).

Examples
--------
>>> from cmosnoise import Sensor, ground_truth
>>> s = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7)
>>> ground_truth.white_threshold(s)   # e-/s: the nearest characterization point's
100.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..engine.jit import ONE_LAUNCH, compiled, numba
from ..engine.telegraph import in_region
from ..model import cfa as cfa_mod
from ..model.sensor import Exposure, region_of
from ..model.stages import defects as defects_mod
from ..model.stages.adc import DITHER_SERIES_FROM, expected_code, series_terms
from . import noise_budget
from .white_pixels import couplet_pairs

#: the defect mask's bits
MASK_BITS = {
    "white": 1,  #: dark current above the white-pixel threshold
    "couplet": 2,  #: a white pixel with a white same-colour neighbour
    "cluster": defects_mod.CLUSTER,  #: a pixel of a hot cluster (stage 15)
    "dead": defects_mod.DEAD,
    "stuck": defects_mod.STUCK,
    "low_gain": defects_mod.LOW_GAIN,
    "high_gain": defects_mod.HIGH_GAIN,
    "bad_column": defects_mod.BAD_COLUMN,  #: any kind: offset, gain or stuck
    "bad_row": defects_mod.BAD_ROW,
    "telegraph": 512,  #: a source-follower random telegraph pixel (stage 6b)
    "blinking": 1024,  #: a blinking white pixel (stage 4b)
}


@dataclass(frozen=True)
class Truth:
    """The ground truth of one exposure over a region (arrays (rows, cols)).

    Parameters
    ----------
    perfect_e : (rows, cols) float32 array, e-
        Mean photo-electrons of the perfect image.
    perfect_dn : (rows, cols) float32 array, DN
        The perfect image through the ideal ADC (e- with the ADC off).
    expected_raw : (rows, cols) float32 array, DN
        What infinitely many frames average to (e- with the ADC off).
    mask : (rows, cols) uint16 array
        The defect mask, bits of :data:`MASK_BITS`.
    white_threshold_e_per_s : float or None
        The dark current above which a pixel is white, e-/s (None: no dark current).
    """

    perfect_e: np.ndarray
    perfect_dn: np.ndarray
    expected_raw: np.ndarray
    mask: np.ndarray
    white_threshold_e_per_s: float | None


def white_threshold(sensor, threshold_e_per_s: float | None = None) -> float | None:
    """The white-pixel threshold: the one given, else the dark-current model's own (``dark_current.white_threshold_*``,
    else its nearest characterization point's tail threshold), else 10 times the mean dark current.

    Parameters
    ----------
    sensor : Sensor
    threshold_e_per_s : float, optional
        A threshold to use instead, e-/s.

    Returns
    -------
    float or None
        e-/s; None without dark current.
    """
    state = sensor.dark_state
    if state is None:
        return None
    if threshold_e_per_s is not None:
        return float(threshold_e_per_s)
    if state.threshold is not None:
        return float(state.threshold)
    return 10.0 * float(sensor.dark_rate.mean())


def mask(sensor, region=None, white_threshold_e_per_s: float | None = None) -> np.ndarray:
    """The defect mask of ``region``: white pixels above the threshold (:func:`white_threshold`) and their
    couplets, the defects of stage 15, the random telegraph pixels.

    Parameters
    ----------
    sensor : Sensor
    region : (row0, row1, col0, col1), optional
        The rectangle (the whole sensor if omitted).
    white_threshold_e_per_s : float, optional
        The white-pixel threshold, e-/s (default: :func:`white_threshold`'s).

    Returns
    -------
    (row1 - row0, col1 - col0) uint16 array
        Bits of :data:`MASK_BITS`.
    """
    rows, cols = sensor.shape
    r0, r1, c0, c1 = region_of(region, sensor.shape)
    out = np.zeros((r1 - r0, c1 - c0), np.uint16)
    fp = sensor.fixed_pattern
    thr = white_threshold(sensor, white_threshold_e_per_s)
    if fp.dark_rate is not None:
        # couplets need the same-colour neighbours 2 pixels beyond the region (an even margin keeps the CFA phase)
        m0, m1, n0, n1 = max(r0 - 2, 0), min(r1 + 2, rows), max(c0 - 2, 0), min(c1 + 2, cols)
        white = fp.dark_rate[m0:m1, n0:n1] > thr
        couplet = np.zeros_like(white)
        pairs = couplet_pairs(white, cfa_mod.crop_pattern(sensor.cfa, m0, n0))
        couplet[pairs[:, :, 0].ravel(), pairs[:, :, 1].ravel()] = True
        inner = (slice(r0 - m0, r1 - m0), slice(c0 - n0, c1 - n0))
        out[white[inner]] |= MASK_BITS["white"]
        out[couplet[inner]] |= MASK_BITS["couplet"]

    def mark(index, bit):
        r, c, _ = in_region(index, (r0, r1, c0, c1), cols)
        out[r, c] |= np.uint16(bit)

    d = fp.defects
    if d is not None:
        for kind in (defects_mod.DEAD, defects_mod.STUCK, defects_mod.LOW_GAIN, defects_mod.HIGH_GAIN):
            mark(d.kind_of(kind)[0], kind)
        mark(d.cluster_index, MASK_BITS["cluster"])
        at = d.columns.index[(d.columns.index >= c0) & (d.columns.index < c1)] - c0
        out[:, at] |= np.uint16(MASK_BITS["bad_column"])
        at = d.rows.index[(d.rows.index >= r0) & (d.rows.index < r1)] - r0
        out[at, :] |= np.uint16(MASK_BITS["bad_row"])
    if fp.traps is not None:
        mark(fp.traps.index, MASK_BITS["telegraph"])
    if fp.blinkers is not None:
        mark(fp.blinkers.index, MASK_BITS["blinking"])
    return out


def expected_raw(exposure: Exposure) -> np.ndarray:
    """What infinitely many frames of ``exposure`` average to, (rows, cols) float32: DN (e- with the ADC off).

    The charge's mean with every fixed pattern, through the clips as normal
    approximations (:func:`~cmosnoise.analysis.noise_budget.clipped_moments`,
    where they are exact below the clips), then the quantizer's expectation
    (:func:`~cmosnoise.model.stages.adc.expected_code`: exact for a normal
    noise, and ``rint`` without noise); stuck pixels and lines read their
    code. Not followed: the nonlinearity's curvature (its first order, the
    curve at the mean, is not applied either: leave the nonlinearity off for
    an exact expectation).

    The pixels no clip comes near (within 10 sigma) take one compiled pass
    (``_far_pixels``), the others another (``_near_pixels``): the same
    formulas, per pixel (without numba, the NumPy functions make every pixel).

    Parameters
    ----------
    exposure : Exposure
        A scene on a sensor (:meth:`Sensor.expose`).

    Returns
    -------
    (rows, cols) float32 array, DN (e- with the ADC off)
    """
    sensor = exposure.sensor
    c = sensor.config
    t = sensor.transfer.adc_codes()  # the quantizer's own codes; times the output's step at the end
    step = sensor.transfer.step
    if c.adc.enabled and _far_pixels is not None and compiled("the ground truth's expected raw", _far_pixels,
                                                              _near_pixels):
        terms = noise_budget.readout_terms(sensor, exposure=exposure)
        shape = sensor.shape
        out = np.empty(shape, np.float32)
        near = np.zeros(shape, np.bool_)
        parts = [np.broadcast_to(np.asarray(terms[k], np.float64), shape)
                 for k in ("mean_n", "shot", "read", "col_read", "row_off", "col_off", "gain")]
        with ONE_LAUNCH:
            _far_pixels(*parts, terms["fw"], terms["top"], float(t.gain_dn_per_e), float(t.black_level_dn),
                        float(t.max_code), out, near)
        if near.any():
            idx = np.nonzero(near)
            if _near_pixels is not None:
                with ONE_LAUNCH:
                    _near_pixels(*parts, terms["fw"], terms["top"], float(t.gain_dn_per_e),
                                 float(t.black_level_dn), float(t.max_code), idx[0], idx[1], out)
            else:
                out[idx] = _codes(noise_budget.near_moments(sensor, terms, idx, codes=True), t)
        top = t.max_code
    elif c.adc.enabled:
        out = _codes(noise_budget.clipped_moments(sensor, exposure=exposure, codes=True), t)
        top = t.max_code
    else:
        step = 1
        out = noise_budget.clipped_moments(sensor, exposure=exposure)["mean"].astype(np.float32)
        top = c.sensor.full_well_e
    if step != 1:
        out *= np.float32(step)  # exact: a power of two
        top *= step
    if sensor.fixed_pattern.defects is not None and sensor.fixed_pattern.defects.has_stuck:
        defects_mod.stick(out, sensor.fixed_pattern.defects, (0, sensor.shape[0], 0, sensor.shape[1]), top,
                          rounded=c.adc.enabled)
    return out


def _codes(moments: dict, t) -> np.ndarray:
    """The expected codes (float32) of the charge's clipped ``moments`` (mean, var e-; ``quantized``: where the
    mean is already the quantizer's expectation near the top code, referred to e-), in the codes of ``t`` (the
    ADC's own: :meth:`~cmosnoise.model.stages.adc.Transfer.adc_codes`)."""
    mean_dn = t.black_level_dn + t.gain_dn_per_e * moments["mean"]
    code = expected_code(mean_dn, t.gain_dn_per_e * np.sqrt(moments["var"]))
    if moments["quantized"] is not None:
        code = np.where(moments["quantized"], mean_dn, code)
    return np.clip(code, 0, t.max_code).astype(np.float32)


# the compiled passes of expected_raw (module level: numba caches them across processes; a closure's would miss)
_ROOT_2, _ROOT_2PI = math.sqrt(2.0), math.sqrt(2 * math.pi)  # divided by, as the NumPy functions do
_far_pixels = _near_pixels = None
if numba is not None:
    _inline = numba.njit(inline="always", cache=True, nogil=True)

    _series_terms = _inline(series_terms)

    @_inline
    def _ndtr(a):
        """The standard normal's cdf (scipy.special.ndtr's value to an ulp or two)."""
        return 0.5 * math.erfc(-a / _ROOT_2)

    @_inline
    def _expected_code(mu, sd):
        """adc.expected_code of one pixel: the mean from 1 DN of noise, rint without, the Fourier series or the
        codes' tails between (as many terms as that pixel's noise needs)."""
        if sd == 0.0:
            return np.rint(mu)
        if sd >= 1.0:
            return mu
        centre = np.rint(mu)
        f = mu - centre
        acc = 0.0
        if sd >= DITHER_SERIES_FROM:
            q = -2.0 * math.pi**2 * sd * sd
            for k in range(1, _series_terms(sd) + 1):
                acc += (-1.0) ** k * math.sin(2.0 * math.pi * k * f) * math.exp(q * k * k) / (math.pi * k)
            return mu + acc
        for d in range(1, _series_terms(sd) + 1):
            acc += _ndtr((f - d + 0.5) / sd) - _ndtr((-f - d + 0.5) / sd)
        return centre + acc

    @_inline
    def _clipped_normal(m, v, top):
        """noise_budget._clipped_normal of one pixel: mean, variance and P(X > top) of min(X, top)."""
        if math.isinf(top):
            return m, v, 0.0
        s = math.sqrt(max(v, 1e-300))
        a = (top - m) / s
        cdf = _ndtr(a)
        pdf = math.exp(-0.5 * a * a) / _ROOT_2PI
        mean = m * cdf - s * pdf + top * (1 - cdf)
        second = (m * m + v) * cdf - s * (m + top) * pdf + top * top * (1 - cdf)
        return mean, max(second - mean * mean, 0.0), 1 - cdf

    @_inline
    def _top_within(m, v, k, black, top):
        """Whether the top code is within 10 sigma and 2 codes of Y ~ Normal(black + K m, K^2 v) (noise_budget's
        ``near`` of _top_code)."""
        return top - (black + k * m) < 10 * (k * math.sqrt(max(v, 0.0))) + 2

    @_inline
    def _top_code(m, v, k, black, top):
        """noise_budget._top_code of one pixel: (E[min(round(Y), top)] DN, whether the top is within reach)."""
        if not _top_within(m, v, k, black, top):
            return 0.0, False
        mu = black + k * m
        sd = k * math.sqrt(max(v, 0.0))
        if sd == 0.0:
            return min(np.rint(mu), top), True
        if sd < 2.0:
            acc = 0.0
            for j in range(1, int(math.ceil(top - mu + 10 * sd)) + 3):
                acc += _ndtr((top - j + 0.5 - mu) / sd)
            return top - acc, True
        mean, _, above = _clipped_normal(mu, sd * sd, top + 0.5)
        return mean - 0.5 * above, True

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _far_pixels(mean_n, shot, read, col_read, row_off, col_off, gain, fw, top_e, k, black, max_code, out, near):
        """The expected code of every pixel no clip comes within 10 sigma of; ``near`` marks the others. The
        formulas of noise_budget.clipped_moments (mean and variance at the ADC input) and adc.expected_code,
        one pass."""
        rows, cols = out.shape
        for i in numba.prange(rows):
            for j in range(cols):
                mn = mean_n[i, j]
                sh = shot[i, j]
                g = gain[i, j]
                m = (mn + row_off[i, j]) * g + col_off[i, j]
                v = (sh + read[i, j]) * (g * g) + col_read[i, j]
                if mn + 10.0 * np.sqrt(sh) + 1.0 >= fw or m + 10.0 * np.sqrt(v) + 1.0 >= top_e:
                    near[i, j] = True
                    continue
                code = _expected_code(black + k * m, k * np.sqrt(v))
                out[i, j] = np.float32(min(max(code, 0.0), max_code))

    @_inline
    def _above_top(mn, sh, rd, cr, ro, co, g, fw, k, black, max_code):
        """Whether both of _near_pixels' cases (charge at the full well, and below it) lie 10 sigma and 2 codes
        above the top code, from bounds alone (no erfc): the charge below the full well has a mean of at least
        ``min(mn, fw) - 0.8 sqrt(sh)`` (a normal's mean truncated above at ``fw`` lies within ``phi(0) / Phi(0)
        = 0.798`` sigma of the nearer of its mean and ``fw``) and a variance of at most ``sh``. Then
        _top_code's sum is empty (or its clipped normal's mean the top code to 1e-18) for both, and the pixel's
        expected code is the top code in float32: the same bits as the whole formula."""
        clipped = (black + k * ((fw + ro) * g + co)) - 10.0 * k * math.sqrt(rd * g * g + cr)
        below = (black + k * ((min(mn, fw) - 0.8 * math.sqrt(sh) + ro) * g + co)) - 10.0 * k * math.sqrt(
            (sh + rd) * g * g + cr)
        return clipped >= max_code + 2.0 and below >= max_code + 2.0

    @_inline
    def _far_below_fw(a, mn, s):
        """Whether the charge ``Normal(mn, s^2)`` lies ``a >= 9`` sigma below the full well, with ``mn > 0.05 s``:
        then _near_pixels' formulas give p_fw = 0, m_below = mn and v_below = s^2 exactly, and need no erfc or exp.
        The cdf rounds to 1.0 there (``0.5 erfc(a / sqrt 2) < 2**-54``, in libm's erfc and in scipy's ndtr, the
        NumPy path's); the truncation's ratio is at most phi(9) = 1.03e-18, so ``a ratio + ratio^2 < 1e-17``
        leaves ``1 - a ratio - ratio^2`` at 1.0 (half an ulp below 1 is 2**-54 = 5.6e-17), and ``s ratio <
        2.1e-17 mn`` leaves ``mn - s ratio`` at mn (half an ulp of mn is at least ``2**-54 mn``)."""
        return a >= 9.0 and mn > 0.05 * s

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _near_pixels(mean_n, shot, read, col_read, row_off, col_off, gain, fw, top_e, k, black, max_code, rows,
                    cols, out):
        """The expected code of the pixels ``(rows[e], cols[e])`` a clip comes near: the formulas of
        noise_budget.near_moments (with codes) and ground_truth._codes, one pass. The charge, a normal, is
        clipped at the full well with probability p_fw; each of the two cases passes the readout and the ADC's
        top as a clipped normal, or as the quantizer's expectation where the top code is within reach."""
        for e in numba.prange(rows.size):
            i, j = rows[e], cols[e]
            mn, sh, rd, cr = mean_n[i, j], shot[i, j], read[i, j], col_read[i, j]
            ro, co, g = row_off[i, j], col_off[i, j], gain[i, j]
            s = math.sqrt(max(sh, 1e-300))
            if _above_top(mn, sh, rd, cr, ro, co, g, fw, k, black, max_code):
                out[i, j] = np.float32(max_code)
                continue
            a = (fw - mn) / s
            if _far_below_fw(a, mn, s):
                p_fw, m_below, v_below = 0.0, mn, sh
            else:
                below_fw = _ndtr(a)
                p_fw = 1.0 - below_fw
                # N given N < FW (noise_budget._truncated_below)
                ratio = math.exp(-0.5 * a * a) / _ROOT_2PI / max(below_fw, 1e-300)
                m_below = mn - s * ratio
                v_below = sh * min(max(1 - a * ratio - ratio * ratio, 0.0), 1.0)
            mc, vc = (fw + ro) * g + co, rd * g * g + cr
            mu, vu = (m_below + ro) * g + co, (v_below + rd) * g * g + cr
            if p_fw == 0.0:  # the full well out of reach (a > 8.3): the clipped case is weighed by an exact 0, so
                e_c = 0.0  # only whether it reaches the top code counts (the same bits)
                at_c = _top_within(mc, vc, k, black, max_code)
            else:
                e_c, at_c = _top_code(mc, vc, k, black, max_code)
            e_u, at_u = _top_code(mu, vu, k, black, max_code)
            if at_c or at_u:  # either case within reach of the top code: the code expectation for both (the
                if not at_c:  # clipped normals' moments below are not needed)
                    e_c = black + k * mc
                if not at_u:
                    e_u = black + k * mu
                m = ((p_fw * e_c + (1 - p_fw) * e_u) - black) / k
                code = black + k * m
            else:
                m_c, v_c = 0.0, 0.0
                if p_fw != 0.0:
                    m_c, v_c, _ = _clipped_normal(mc, vc, top_e)
                m_u, v_u, _ = _clipped_normal(mu, vu, top_e)
                m = p_fw * m_c + (1 - p_fw) * m_u
                second = p_fw * (v_c + m_c**2) + (1 - p_fw) * (v_u + m_u**2)
                var = max(second - m**2, 0.0)
                code = _expected_code(black + k * m, k * math.sqrt(var))
            out[i, j] = np.float32(min(max(code, 0.0), max_code))




def truth(exposure: Exposure, white_threshold_e_per_s: float | None = None) -> Truth:
    """The ground truth of ``exposure``: perfect image (e-, DN), expected raw and defect mask.

    Parameters
    ----------
    exposure : Exposure
        A scene on a sensor (:meth:`Sensor.expose`).
    white_threshold_e_per_s : float, optional
        The mask's white-pixel threshold, e-/s (default: :func:`white_threshold`'s).

    Returns
    -------
    Truth
    """
    sensor = exposure.sensor
    c = sensor.config
    t = sensor.transfer
    perfect = exposure.perfect_e.astype(np.float32)
    if c.adc.enabled:
        ideal = t.black_level_dn + t.gain_dn_per_e * np.minimum(perfect.astype(np.float64), c.sensor.full_well_e)
        perfect_dn = np.clip(ideal, 0, t.max_code).astype(np.float32)
    else:
        perfect_dn = np.minimum(perfect, np.float32(c.sensor.full_well_e))
    return Truth(perfect, perfect_dn, expected_raw(exposure), mask(sensor, None, white_threshold_e_per_s),
                 white_threshold(sensor, white_threshold_e_per_s))
