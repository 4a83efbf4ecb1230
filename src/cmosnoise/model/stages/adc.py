"""Stage 9, analogue-to-digital conversion: electrons to digital numbers (DN).

A linear ramp ADC (docs/model.md stage 9)::

    step = 2**(output_bits - bits)                              # output DN per ADC code
    K  = (step * (2**bits - 1) - black_level_dn) / full_scale_e  # output DN per e-
    DN = step * clip(round((N_total * K + black_level_dn) / step), 0, 2**bits - 1)

``round`` is round-half-to-even (``numpy.rint``). The black level keeps
negative noise excursions visible, as real sensors do. K, the black level and
every noise after the gain are in the output's DN, as a camera's files give
them; the ADC resolves ``bits`` of them: a 14-bit ADC written in a 16-bit
range (``output_bits`` 16) has codes 0, 4, 8, ... 65532, and its quantization
adds ``step**2 / 12`` DN^2 to the variance. Without ``output_bits`` the step is
1 DN (the codes are the ADC's).

Examples
--------
>>> from cmosnoise import Sensor
>>> t = Sensor({"sensor": {"width": 64, "height": 48}}).transfer
>>> t.bits, t.black_level_dn, t.max_code
(12, 64.0, 4095)
>>> t14 = Sensor({"sensor": {"width": 64, "height": 48}, "adc": {"bits": 14, "output_bits": 16}}).transfer
>>> t14.step, t14.max_code, t14.quantization_var_dn2
(4, 65532, 1.3333333333333333)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Transfer:
    """The ADC's transfer function: ``DN = step * round((e- * gain_dn_per_e + black_level_dn) / step)``, clipped
    to the codes.

    Parameters
    ----------
    gain_dn_per_e : float
        K, the conversion gain, output DN per electron.
    black_level_dn : float
        The code of no charge, output DN.
    bits : int
        The ADC's resolution: ``2**bits`` codes.
    step : int
        Output DN per ADC code, ``2**(output_bits - bits)``: 1 where the output is the ADC's codes.
    """

    gain_dn_per_e: float  #: K, output DN per electron
    black_level_dn: float
    bits: int
    step: int = 1  #: output DN per ADC code

    @property
    def max_code(self) -> int:
        """The top output code, DN: ``step * (2**bits - 1)``."""
        return self.step * (2**self.bits - 1)

    @property
    def output_bits(self) -> int:
        """The bits of the output's range (``bits`` where the step is 1)."""
        return self.bits + self.step.bit_length() - 1

    @property
    def quantization_var_dn2(self) -> float:
        """The quantizer's variance, DN^2: ``step**2 / 12`` (a uniform error over one step)."""
        return self.step**2 / 12.0

    def adc_codes(self) -> Transfer:
        """This transfer counted in the ADC's own codes (K, black level and top divided by the step): what the
        quantizer rounds. Exact: the step is a power of two."""
        return Transfer(self.gain_dn_per_e / self.step, self.black_level_dn / self.step, self.bits, 1)

    @staticmethod
    def _step(bits: int, output_bits: int | None) -> int:
        if not 8 <= bits <= 16:
            raise ValueError(f"bits must be in 8..16, got {bits}")
        out = bits if output_bits is None else output_bits
        if not bits <= out <= 16:
            raise ValueError(f"output_bits must be in {bits}..16 (at least the ADC's bits), got {out}")
        return 2 ** (out - bits)

    @classmethod
    def from_settings(cls, bits: int, black_level_dn: float, full_scale_e: float,
                      output_bits: int | None = None) -> Transfer:
        """The transfer whose top code is at ``full_scale_e`` e- (``output_bits``: the output's range, default
        ``bits``)."""
        step = cls._step(bits, output_bits)
        top = step * (2**bits - 1)
        if not 0 <= black_level_dn < top:
            raise ValueError(f"black_level_dn must be in [0, {top}), got {black_level_dn}")
        if full_scale_e <= 0:
            raise ValueError(f"full_scale_e must be > 0, got {full_scale_e}")
        return cls((top - black_level_dn) / full_scale_e, float(black_level_dn), bits, step)

    @classmethod
    def from_gain(cls, bits: int, black_level_dn: float, gain_dn_per_e: float,
                  output_bits: int | None = None) -> Transfer:
        """The transfer of a given system gain K (output DN per e-): its top code at ``(max_code - black) / K``
        e-."""
        cls.from_settings(bits, black_level_dn, 1.0, output_bits)  # the same checks
        if not gain_dn_per_e > 0:
            raise ValueError(f"gain_dn_per_e must be > 0, got {gain_dn_per_e}")
        return cls(float(gain_dn_per_e), float(black_level_dn), bits, cls._step(bits, output_bits))

    @classmethod
    def ideal(cls) -> Transfer:
        """1 DN per electron, no black level, 16-bit range (ADC switched off)."""
        return cls(1.0, 0.0, 16)

    def to_electrons(self, dn: np.ndarray) -> np.ndarray:
        """Invert the transfer (ignoring quantization and clipping): DN -> e-."""
        return (np.asarray(dn, dtype=np.float64) - self.black_level_dn) / self.gain_dn_per_e


def convert(electrons: np.ndarray, transfer: Transfer, black_dn: np.ndarray | None = None,
            read_dn: np.ndarray | None = None) -> np.ndarray:
    """Quantize charge (e-, float) to raw codes (DN, uint16).

    Parameters
    ----------
    electrons : (rows, cols) array, e-
        Charge at the ADC's input.
    transfer : Transfer
        Gain, black level and bits.
    black_dn : (rows, cols) array, DN, optional
        Each pixel's black level (the CFA cell's offsets and the frame's error included,
        :func:`.read_noise.black_map`), else the transfer's.
    read_dn : (rows, cols) array, DN, optional
        Read noise after the gain, added before the rounding.

    Returns
    -------
    (rows, cols) uint16 array, DN
        The raw codes: the ADC's (``0 .. 2**bits - 1``) times the step.
    """
    # float64 so that rounding at .5 boundaries is the formula's, not float32's
    v = electrons.astype(np.float64) * transfer.gain_dn_per_e
    v += transfer.black_level_dn if black_dn is None else black_dn
    if read_dn is not None:
        v += read_dn
    if transfer.step != 1:  # the ADC rounds its own codes (exact: a power of two)
        v *= 1.0 / transfer.step
    np.rint(v, out=v)
    np.clip(v, 0, 2**transfer.bits - 1, out=v)
    if transfer.step != 1:
        v *= transfer.step
    return v.astype(np.uint16)


def expected_output(mean_dn: np.ndarray, sigma_dn: np.ndarray, transfer: Transfer) -> np.ndarray:
    """:func:`expected_code` for ``transfer``'s quantizer, in output DN: the ADC rounds ``mean / step`` (with
    noise ``sigma / step``), and its codes are multiplied by the step. Clipping is not included.

    Parameters
    ----------
    mean_dn : array, output DN
        The code's mean before rounding.
    sigma_dn : array or float, output DN
        Its temporal noise.
    transfer : Transfer
        The quantizer: its step.

    Returns
    -------
    float64 array, output DN, ``mean_dn``'s shape
    """
    if transfer.step == 1:
        return expected_code(mean_dn, sigma_dn)
    s = float(transfer.step)
    return s * expected_code(np.asarray(mean_dn, np.float64) / s, np.asarray(sigma_dn, np.float64) / s)


#: below this noise (DN) the expected code is a sum over codes' edges; from it to 1 DN a Fourier series
DITHER_SERIES_FROM = 0.25
#: the Fourier series' terms times the noise in DN: term k is left out where ``exp(-2 pi^2 k^2 sigma^2)`` is
#: below ``exp(-41.4) = 1e-18``, i.e. from ``k > sqrt(41.4 / (2 pi^2)) / sigma``
SERIES_TERMS_DN = math.sqrt(41.4 / (2.0 * math.pi**2))
#: the codes' tails reach this many sigma: ``Phi(-8.5) = 9.5e-18``
TAIL_Z = 8.5


def expected_code(mean_dn: np.ndarray, sigma_dn: np.ndarray) -> np.ndarray:
    """Expected value of ``round(x)`` for x ~ Normal(mean_dn, sigma_dn^2), elementwise (DN, float64).

    With a DN of noise or more this is ``mean_dn`` (within 3e-9 DN: the
    noise dithers the quantizer); without noise ``rint(mean_dn)``; in
    between, with ``c = rint(mean_dn)`` and ``f = mean_dn - c``, exactly (to
    1e-17 DN) one of two series: from :data:`DITHER_SERIES_FROM` the
    sawtooth's Fourier series,
    ``mean_dn + sum_k (-1)^k sin(2 pi k f) exp(-2 pi^2 k^2 sigma^2) / (pi k)``
    (at most 5 terms), and below it the codes' tails,
    ``c + sum_d [Phi((f - d + 1/2) / sigma) - Phi((-f - d + 1/2) / sigma)]``
    (at most 3 terms). The quantization pattern then adds to the fixed
    pattern a frame shows. Clipping is not included here.

    Parameters
    ----------
    mean_dn : array, DN
        The code's mean before rounding.
    sigma_dn : array or float, DN
        Its temporal noise (broadcast to ``mean_dn``'s shape).

    Returns
    -------
    float64 array, DN, ``mean_dn``'s shape

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.model.stages.adc import expected_code
    >>> [round(float(v), 4) for v in expected_code(np.array([10.2, 10.2, 10.2]), np.array([0.0, 0.3, 1.0]))]
    [10.0, 10.1488, 10.2]
    """
    from scipy.special import ndtr

    mean_dn = np.asarray(mean_dn, np.float64)
    sigma_dn = np.broadcast_to(np.asarray(sigma_dn, np.float64), mean_dn.shape)
    out = mean_dn.copy()
    exact = sigma_dn == 0.0
    out[exact] = np.rint(mean_dn[exact])  # as the ADC rounds (half codes to even)
    series = (sigma_dn >= DITHER_SERIES_FROM) & (sigma_dn < 1.0)
    if series.any():
        mu, sd = mean_dn[series], sigma_dn[series]
        f = mu - np.rint(mu)
        acc = np.zeros(mu.shape)
        q = -2.0 * math.pi**2 * sd * sd
        for k in range(1, series_terms(float(sd.min())) + 1):
            acc += (-1.0) ** k * np.sin(2.0 * math.pi * k * f) * np.exp(q * k * k) / (math.pi * k)
        out[series] = mu + acc
    tails = (sigma_dn < DITHER_SERIES_FROM) & ~exact
    if tails.any():
        mu, sd = mean_dn[tails], sigma_dn[tails]
        centre = np.rint(mu)
        f = mu - centre
        acc = np.zeros(mu.shape)
        for d in range(1, series_terms(float(sd.max())) + 1):
            acc += ndtr((f - d + 0.5) / sd) - ndtr((-f - d + 0.5) / sd)
        out[tails] = centre + acc
    return out


def series_terms(sigma_dn: float) -> int:
    """How many terms :func:`expected_code` sums at a noise of ``sigma_dn`` DN (below 1): from
    :data:`DITHER_SERIES_FROM`, the Fourier series' terms whose ``exp(-2 pi^2 k^2 sigma^2)`` is at least 1e-18
    (at least one); below it, the codes each side whose edge can lie within 8.5 sigma of the mean.

    Parameters
    ----------
    sigma_dn : float
        The noise, DN.

    Returns
    -------
    int

    Examples
    --------
    >>> from cmosnoise.model.stages.adc import series_terms
    >>> series_terms(0.05), series_terms(0.2), series_terms(0.25), series_terms(0.5), series_terms(0.9)
    (1, 2, 5, 2, 1)
    """
    if sigma_dn >= DITHER_SERIES_FROM:
        return max(int(SERIES_TERMS_DN / sigma_dn), 1)
    return int(TAIL_Z * sigma_dn) + 1


#: the largest output step :func:`code_step` reports (2^8: an 8-bit ADC in a 16-bit range)
MAX_STEP = 256


def code_grid(codes: np.ndarray) -> int:
    """The bitwise OR of integer codes: :func:`code_step`'s input, which accumulates over frames with ``|``.

    0 where every code is the same (they say nothing of the step), -1 where some code is not an integer (or
    negative): the step is then unknown, and stays so when ORed with others.

    Parameters
    ----------
    codes : array
        Raw codes, DN.

    Returns
    -------
    int
    """
    x = np.asarray(codes).ravel()
    if x.size == 0:
        return 0
    if x.dtype.kind == "f" and not np.all(x == np.rint(x)):
        return -1
    x = x.astype(np.int64)
    if x.min() < 0:
        return -1
    if x.min() == x.max():
        return 0
    return int(np.bitwise_or.reduce(x))


def code_step(grid: int) -> int:
    """The output DN per ADC code that data show: the lowest bit set in :func:`code_grid`'s OR of the codes (every
    code is a multiple of it), at most :data:`MAX_STEP`; 1 where the data cannot tell (all codes equal, or codes
    that are not integers).

    Parameters
    ----------
    grid : int
        :func:`code_grid`'s OR of the codes (of one frame, or ORed over many).

    Returns
    -------
    int
        Output DN per ADC code, a power of two.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise.model.stages.adc import code_grid, code_step
    >>> code_step(code_grid(np.array([512, 516, 540, 1024]))), code_step(code_grid(np.array([3, 4])))
    (4, 1)
    """
    if grid <= 0:
        return 1
    return min(grid & -grid, MAX_STEP)
