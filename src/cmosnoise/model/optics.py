"""The lens between the scene and the pixels: its point spread function on the optical image's fine grid, the
optical low-pass filter and the pixel's aperture, the relative illumination across the field and the chief-ray
angle.

docs/model.md section 2b is the specification. The optical image (:mod:`.focal_plane`) is sampled ``k x k`` finer
than the pixels (``optics.oversample``); what acts on it is defined here as numbers on that grid:

- **the point spread function** (``optics.psf``), one per colour channel, point-sampled at the fine cells'
  centres: the polychromatic Airy pattern of a diffraction-limited lens at its f-number, weighted by the channel's
  photo-electron spectrum (:func:`diffraction_psf`), a Gaussian (:func:`gaussian_psf`), or a user's 2-D array
  binned onto the fine grid (:func:`file_psf`). The Airy pattern's core is kept out to the radius that holds
  :data:`CORE_ENERGY` of its light (its outer half tapered by a cosine); the rest of its light, the pattern's slowly
  falling rings, is a Gaussian halo of :data:`HALO_WIDTH` times that radius, so every kernel sums to 1 and the MTF
  is the full pattern's (within 0.01 of it from 0.03 cycles per pixel up);
- **the pixel's aperture** (``light.fill_factor``: a centred square of side ``pitch sqrt(fill factor)``) and the
  **optical low-pass filter** (``optics.olpf``: a birefringent four-spot filter, each spot a quarter of the light,
  ``d`` um apart along the rows and the columns): as weights on the fine cells a pixel integrates
  (:func:`aperture`), MTF ``sinc(a f) |cos(pi d f)|`` per axis;
- **k itself** (:func:`oversample`): ``auto`` takes the smallest ``k`` (1 to :data:`MAX_OVERSAMPLE`) at which the
  PSF's transfer folded back from beyond the fine grid's Nyquist frequency, weighted by the aperture's, is at most
  :data:`ALIAS_LIMIT`; 1 without a PSF;
- **the relative illumination** (``optics.relative_illumination``): cos^4 of each pixel's field angle
  (``tan theta = h / (f (1 + m))``, h the pixel centre's image height, f (1 + m) the image distance), or a table
  of image height against relative illumination; and **the chief-ray angle**'s QE loss and leaning crosstalk.
  These act on each pixel's signal (they change by far less than a part in a million over a pixel).

Examples
--------
>>> from cmosnoise.model import optics
>>> psf = optics.gaussian_psf(0.8, 2)
>>> psf.core.shape, round(float(psf.core[0].sum()), 12)
((3, 15, 15), 1.0)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import inputs
from ..engine import lens
from ..errors import CmosnoiseError
from . import cfa as cfa_mod
from .stages import crosstalk

#: the wavelengths of a diffraction PSF without light in lux (R, G, B), nm
DEFAULT_WAVELENGTHS_NM = (610.0, 540.0, 465.0)
#: the most fine cells a pixel is split into along each axis (``optics.oversample``)
MAX_OVERSAMPLE = 4
#: ``auto``'s bound on the PSF's transfer aliased from beyond the fine grid's Nyquist frequency (times the
#: aperture's transfer where it lands): the error it leaves in the system MTF
ALIAS_LIMIT = 0.01
#: the share of a diffraction PSF's light its core holds (its encircled energy at the core's radius)
CORE_ENERGY = 0.95
#: the share of the core's radius over which it is tapered to 0 by a raised cosine (fewer separable terms)
CORE_TAPER = 0.5
#: the halo's sigma, in core radii: the light outside the core spread as a Gaussian (its MTF is the Airy tail's
#: within 0.01 from 0.03 cycles per pixel up, measured in docs/model.md)
HALO_WIDTH = 1.5
#: a Gaussian's taps (a PSF's or the halo's) out to this many sigmas (its light beyond: 6e-5 of it, put back by
#: normalising)
GAUSS_SIGMAS = 4.0
#: the widest PSF core, fine cells across
MAX_CORE = 257
#: the largest PSF file (a float64 array of 1024^2 with room for its header) and relative-illumination table
MAX_FILE_BYTES = 8 * 2**20 + 4096

__all__ = ["PointSpread", "airy", "encircled_energy", "diffraction_otf", "diffraction_psf", "gaussian_psf",
           "file_psf", "aperture", "aperture_error", "oversample", "alias_error", "relative_illumination", "incidence", "angle_qe",
           "lean_weights", "leaning_charge", "shade", "active", "psf_active", "image_distance_mm"]


# ------------------------------------------------------------------ point spread functions
def airy(r_um: np.ndarray, wavelength_um: float, f_number: float) -> np.ndarray:
    """The Airy pattern of a circular pupil: ``(2 J1(v) / v)^2``, ``v = pi r / (lambda N)``; 1 at the centre.

    Parameters
    ----------
    r_um : array
        Distance from the centre in the image plane, um.
    wavelength_um : float
        lambda, um.
    f_number : float
        N.

    Returns
    -------
    array
        The irradiance relative to the centre's; its first zero lies at ``1.2197 lambda N``; its integral over the
        plane is ``4 (lambda N)^2 / pi`` um^2 (Goodman, *Introduction to Fourier Optics*).
    """
    from scipy.special import j1

    v = np.pi * np.asarray(r_um, float) / (wavelength_um * f_number)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (2.0 * j1(v) / v) ** 2
    return np.where(v == 0, 1.0, out)


def encircled_energy(r_um, wavelengths_um, weights, f_number: float) -> np.ndarray:
    """The share of a polychromatic Airy pattern's light within radius ``r``: ``sum_l w_l (1 - J0(v)^2 - J1(v)^2)``,
    ``v = pi r / (lambda_l N)`` (Lord Rayleigh's formula; Born and Wolf, *Principles of Optics*, 8.5.2).

    Parameters
    ----------
    r_um : array
        Radii, um.
    wavelengths_um : (n,) array
    weights : (n,) array
        Each wavelength's share of the light (summing to 1).
    f_number : float

    Returns
    -------
    array
        0 to 1, the shape of ``r_um``.
    """
    from scipy.special import j0, j1

    r = np.asarray(r_um, float)[..., None]
    v = np.pi * r / (np.asarray(wavelengths_um, float) * f_number)
    return ((1.0 - j0(v) ** 2 - j1(v) ** 2) * np.asarray(weights, float)).sum(axis=-1)


def diffraction_otf(f_cy_per_um, wavelengths_um, weights, f_number: float) -> np.ndarray:
    """The OTF of a diffraction-limited circular pupil, averaged over a spectrum:
    ``sum_l w_l (2 / pi) (acos(x) - x sqrt(1 - x^2))``, ``x = f lambda_l N`` (0 beyond ``x = 1``; Goodman).

    Parameters
    ----------
    f_cy_per_um : array
        Spatial frequencies in the image plane, cycles per um.
    wavelengths_um, weights : (n,) arrays
    f_number : float

    Returns
    -------
    array
        The shape of ``f_cy_per_um``; 1 at 0.
    """
    x = np.clip(np.abs(np.asarray(f_cy_per_um, float))[..., None] * np.asarray(wavelengths_um, float) * f_number,
                0.0, 1.0)
    return ((2.0 / np.pi) * (np.arccos(x) - x * np.sqrt(1.0 - x * x)) * np.asarray(weights, float)).sum(axis=-1)


@dataclass(frozen=True, eq=False)
class PointSpread:
    """A PSF per colour channel on the optical image's fine grid.

    Parameters
    ----------
    kind : str
        ``diffraction``, ``gaussian`` or the file's path.
    core : (3, s, s) float64 array
        Each channel's core, point-sampled (or binned, for a file) at the fine cells' offsets ``-(s // 2)`` to
        ``s // 2``: the share of a point's light each fine cell receives. Each sums to ``1 - halo_share``.
    halo_share : (3,) float64 array
        The light outside each core, spread as a Gaussian halo (0 but for a diffraction PSF).
    halo_sigma_cells : (3,) float64 array
        The halo's sigma, fine cells.
    transfer : callable
        ``f (cycles per pixel) -> (3, n)``: each channel's MTF, for :func:`oversample`.
    """

    kind: str
    core: np.ndarray
    halo_share: np.ndarray
    halo_sigma_cells: np.ndarray
    transfer: object

    def mtf(self, f_cy_per_px) -> np.ndarray:
        """Each channel's MTF at ``f_cy_per_px`` (cycles per pixel): (3, n)."""
        return self.transfer(np.atleast_1d(np.asarray(f_cy_per_px, float)))


def _core_radius(wl_um: np.ndarray, w: np.ndarray, f_number: float) -> float:
    """The radius (um) within which a polychromatic Airy pattern holds :data:`CORE_ENERGY` of its light."""
    lo, hi = 0.0, 2.0 * wl_um.max() * f_number
    while encircled_energy(hi, wl_um, w, f_number) < CORE_ENERGY:
        hi *= 2.0
    for _ in range(60):  # bisection: the encircled energy rises with r
        mid = 0.5 * (lo + hi)
        if encircled_energy(mid, wl_um, w, f_number) < CORE_ENERGY:
            lo = mid
        else:
            hi = mid
    return hi


def _airy_core(wl_um: np.ndarray, w: np.ndarray, f_number: float, cell_um: float, radius_um: float,
               half: int) -> np.ndarray:
    """The polychromatic Airy pattern's light per fine cell (its density at the cell's centre times the cell's
    area), out to ``radius_um`` with a raised-cosine taper over the outer :data:`CORE_TAPER` of it:
    (2 half + 1, 2 half + 1)."""
    x = (np.arange(-half, half + 1) * cell_um)
    r = np.hypot(x[:, None], x[None, :])
    density = np.zeros_like(r)
    for li, wi in zip(wl_um, w):  # each wavelength's pattern normalised to unit light: its integral 4 (l N)^2 / pi
        density += wi * airy(r, li, f_number) / (4.0 * (li * f_number) ** 2 / np.pi)
    r1 = radius_um * (1.0 - CORE_TAPER)
    taper = np.where(r <= r1, 1.0, np.where(r >= radius_um, 0.0,
                                            0.5 + 0.5 * np.cos(np.pi * (r - r1) / (radius_um - r1))))
    return density * taper * cell_um**2


def diffraction_psf(wavelengths_nm: np.ndarray, weights: np.ndarray, f_number: float, pitch_um: float,
                    k: int) -> PointSpread:
    """The diffraction-limited PSF of each channel on the fine grid: the Airy core and its halo.

    Parameters
    ----------
    wavelengths_nm : (n,) array
        Wavelengths, nm.
    weights : (3, n) array
        Each channel's photo-electrons per wavelength (any scale).
    f_number : float
        N.
    pitch_um : float
        The pixel pitch, um.
    k : int
        Fine cells per pixel along each axis: the cells' pitch is ``pitch_um / k``.

    Returns
    -------
    PointSpread
        Cores of one common size (the largest channel's, at most :data:`MAX_CORE` cells across), each the
        pattern's light in each cell out to its :data:`CORE_ENERGY` radius; the halo holds the rest (one minus the
        core's sum, so each channel's PSF sums to exactly 1), its sigma :data:`HALO_WIDTH` core radii.
    """
    cell_um = pitch_um / k
    wl = np.asarray(wavelengths_nm, float) * 1e-3
    spectra = []
    for w in np.atleast_2d(np.asarray(weights, float)):
        keep = w > 0
        spectra.append((wl[keep], w[keep] / w[keep].sum()))
    radii = [_core_radius(li, wi, f_number) for li, wi in spectra]
    half = min(int(math.ceil(max(radii) / cell_um)), (MAX_CORE - 1) // 2)
    cores = np.stack([_airy_core(li, wi, f_number, cell_um, ri, half) for (li, wi), ri in zip(spectra, radii)])
    share = 1.0 - cores.sum(axis=(1, 2))
    sigma = HALO_WIDTH * np.asarray(radii) / cell_um

    def transfer(f_px):
        return np.stack([diffraction_otf(f_px / pitch_um, li, wi, f_number) for li, wi in spectra])

    return PointSpread("diffraction", cores, share, sigma, transfer)


def gaussian_psf(sigma_px: float, k: int) -> PointSpread:
    """A Gaussian PSF of ``sigma_px`` pixels point-sampled on a grid ``k`` times finer, out to
    :data:`GAUSS_SIGMAS` sigmas, normalised to sum 1.

    Parameters
    ----------
    sigma_px : float
        sigma, pixels.
    k : int
        Fine cells per pixel along each axis.

    Returns
    -------
    PointSpread
        The same core for the three channels, no halo.
    """
    sigma = sigma_px * k
    half = int(min(math.ceil(GAUSS_SIGMAS * sigma), (MAX_CORE - 1) // 2))
    line = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
    core = np.outer(line, line)
    core = core / core.sum()

    def transfer(f_px):
        return np.repeat(np.exp(-2.0 * np.pi**2 * sigma_px**2 * f_px**2)[None, :], 3, axis=0)

    return PointSpread("gaussian", np.stack([core] * 3), np.zeros(3), np.zeros(3), transfer)


def _bins(n: int, j: int) -> np.ndarray:
    """(cells, n) weights binning ``n`` samples (odd, centred) into cells of ``j`` samples centred on the middle
    sample: each sample's share of each cell (1, or 1/2 where an even ``j`` puts a cell's edge through it)."""
    centre = (n - 1) / 2.0
    # cell c covers [centre + c j - j / 2, centre + c j + j / 2] of the line the samples' centres lie on (sample s
    # spans [s - 1/2, s + 1/2]); the outermost cell that still reaches a sample: c < (n + j) / (2 j)
    reach = int(math.ceil((n + j) / (2.0 * j))) - 1
    cells = np.arange(-reach, reach + 1)
    lo = centre + cells * j - j / 2.0
    hi = lo + j
    s0 = np.arange(n) - 0.5
    s1 = s0 + 1.0
    return np.clip(np.minimum(hi[:, None], s1[None, :]) - np.maximum(lo[:, None], s0[None, :]), 0.0, 1.0)


def file_psf(path: str, sampling_um: float | None, pitch_um: float, k: int) -> PointSpread:
    """A user's PSF (one 2-D array in a ``.npy`` or FITS file) binned onto the fine grid, normalised to sum 1.

    Parameters
    ----------
    path : str
        The file: samples of a PSF on a square grid of ``sampling_um``, its middle sample (odd sides; an even side
        is padded with a zero) the PSF's centre.
    sampling_um : float or None
        The samples' spacing, um; None: the pixel pitch.
    pitch_um : float
        The pixel pitch, um.
    k : int
        Fine cells per pixel: the fine grid's pitch ``pitch / k`` must be a whole number ``j`` of samples, each
        fine cell then the sum of ``j x j`` samples.

    Returns
    -------
    PointSpread
        The same core for the three channels, no halo.
    """
    a = _file_array(path)
    j = _samples_per_cell(path, sampling_um, pitch_um, k)
    if max(a.shape) / j > MAX_CORE:
        raise CmosnoiseError(f"optics.psf {path}: {a.shape[0]} x {a.shape[1]} samples make "
                             f"{-(-max(a.shape) // j)} fine cells across; at most {MAX_CORE}")
    a = np.pad(a, [(0, 1 - s % 2) for s in a.shape])
    binned = _bins(a.shape[0], j) @ a @ _bins(a.shape[1], j).T
    side = max(binned.shape)
    binned = np.pad(binned, [((side - binned.shape[0]) // 2,) * 2, ((side - binned.shape[1]) // 2,) * 2])
    core = binned / binned.sum()
    s_um = pitch_um if sampling_um is None else sampling_um
    spectrum = np.abs(np.fft.fft2(a / a.sum(), s=(4 * a.shape[0], 4 * a.shape[1])))
    # cycles per pixel: the samples are s_um / pitch_um pixels apart
    step = s_um / pitch_um
    freq = np.hypot(np.fft.fftfreq(4 * a.shape[0], step)[:, None], np.fft.fftfreq(4 * a.shape[1], step)[None, :])
    order = np.argsort(freq.ravel())
    f_sorted = freq.ravel()[order]
    envelope = np.maximum.accumulate(spectrum.ravel()[order][::-1])[::-1]  # the largest MTF at f or beyond
    top = f_sorted[-1]

    def transfer(f):
        return np.repeat(np.where(f > top, envelope[-1], np.interp(f, f_sorted, envelope))[None, :], 3, axis=0)

    return PointSpread(path, np.stack([core] * 3), np.zeros(3), np.zeros(3), transfer)


def _samples_per_cell(path: str, sampling_um: float | None, pitch_um: float, k: int) -> int:
    """How many of a PSF file's samples make a fine cell: ``pitch / k / sampling``, a whole number, or a one-line
    error."""
    s = pitch_um if sampling_um is None else float(sampling_um)
    j = pitch_um / k / s
    if abs(j - round(j)) > 1e-9 * max(j, 1) or round(j) < 1:
        raise CmosnoiseError(
            f"optics.psf {path}: samples {s:g} um apart (optics.psf_sampling_um) do not divide into the fine grid's "
            f"{pitch_um / k:g} um cells (the pitch over optics.oversample = {k}); give samples pitch / k / j apart "
            "for a whole j, or an optics.oversample that makes them so")
    return int(round(j))


@functools.lru_cache(maxsize=8)
def _file_array(path: str) -> np.ndarray:
    """A PSF file's one 2-D array, through the input gate, checked: finite, >= 0, summing to more than 0."""
    key = "optics.psf"
    suffix = Path(path).suffix.lower()
    if suffix == ".npy":
        a = inputs.read_npy(path, f"{key} file", MAX_FILE_BYTES)
    elif suffix in (".fits", ".fit", ".fts"):
        from astropy.io import fits

        inputs.fits_data_bytes(path, f"{key} file", MAX_FILE_BYTES)
        try:
            with fits.open(inputs.check_regular(path, f"{key} file"), memmap=False) as hdus:
                a = next((np.array(h.data) for h in hdus if h.data is not None), None)
        except (OSError, ValueError, TypeError, IndexError) as exc:
            raise CmosnoiseError(f"{key} {path!r} is not a readable FITS file: {exc}") from None
    else:
        raise CmosnoiseError(f"{key} = {path!r}: give none, diffraction, gaussian, or a .npy or .fits file")
    a = np.asarray(a) if a is not None else np.zeros(0)
    if a.ndim != 2 or min(a.shape) < 1 or a.dtype.kind not in "uif":
        raise CmosnoiseError(f"{key} {path}: a PSF is one 2-D array of real numbers; this is {a.shape} {a.dtype}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all() or (a < 0).any():
        raise CmosnoiseError(f"{key} {path}: a PSF's values must be finite and >= 0")
    top = float(a.max())
    if not top > 0:
        raise CmosnoiseError(f"{key} {path}: a PSF's values must be somewhere above 0 (they are all 0)")
    a = a / top  # its scale is free: kept away from overflow in the sums that follow (1e308 everywhere is flat)
    if not np.isfinite(a).all() or float(a.max()) != 1.0:  # a subnormal peak loses its digits in the division
        raise CmosnoiseError(f"{key} {path}: a PSF's largest value is {top:g}, too small to be scaled (give values "
                             f"of at least {np.finfo(np.float64).tiny:g})")
    a.setflags(write=False)
    return a


def psf_active(config) -> bool:
    """Whether a PSF is configured.

    Parameters
    ----------
    config : Config

    Returns
    -------
    bool
        ``optics.psf`` is other than ``none``.
    """
    return config.optics.psf.lower() != "none"


# ------------------------------------------------------------------ the pixel's aperture and the OLPF
#: the aperture's taps beyond the pixel's own cells on each side, where it is fitted (a fill factor below 1, a
#: filter)
APERTURE_MARGIN = 2


def aperture(k: int, fill_factor: float, olpf_cells: float | None = None, weight=None) -> tuple[int, np.ndarray]:
    """The weights a pixel integrates the optical image's fine cells with, along one axis.

    The fine cells hold averages of the optical image over each cell, so their sum over the pixel's ``k`` cells
    is the integral over the pixel exactly (transfer ``sinc(f)``, f in cycles per pixel): the weights of a full
    aperture are ``1 / k`` each. A smaller aperture (side ``a = sqrt(fill_factor)`` pixels, centred) and a
    four-spot optical low-pass filter (``d`` pixels between spots) have the transfer
    ``T(f) = a sinc(a f) cos(pi d f)``; on cell averages the weights must give ``T(f) / sinc(f / k)``, which no
    set of whole cells gives. They are then the least-squares fit of a symmetric set of taps (the pixel's cells
    and :data:`APERTURE_MARGIN` on each side) to it over the fine grid's band, 0 to ``k / 2`` cycles per pixel,
    weighted by ``weight(f)`` (the PSF's MTF, where the image has its detail; 1 without one); their sum is
    ``a`` exactly. Beyond 1 cycle per pixel (where detail aliases into the pixels' band from the second order on)
    the weight is a tenth. The 2-D weights are the outer product of two of these.

    Parameters
    ----------
    k : int
        Fine cells per pixel.
    fill_factor : float
        The aperture's area over the pixel's, (0, 1].
    olpf_cells : float, optional
        The filter's spot separation, fine cells; None or 0: no filter.
    weight : callable, optional
        ``f (cycles per pixel) -> weight``, the fit's weight at each frequency.

    Returns
    -------
    offset : int
        The first weight's cell, relative to the pixel's first cell.
    weights : (n,) float64 array
        Summing to ``sqrt(fill_factor)`` (one axis of the aperture's area, in pixels).

    Examples
    --------
    >>> from cmosnoise.model.optics import aperture
    >>> offset, weights = aperture(3, 1.0)
    >>> offset, weights.round(4).tolist()
    (0, [0.3333, 0.3333, 0.3333])
    """
    if fill_factor == 1.0 and not olpf_cells:
        return 0, np.full(k, 1.0 / k)
    a = math.sqrt(fill_factor)
    d = (olpf_cells or 0.0) / k  # pixels
    n = np.arange(-APERTURE_MARGIN, k + APERTURE_MARGIN)
    x = (n + 0.5 - k / 2.0) / k  # the taps' centres from the pixel's, pixels (symmetric about 0)
    half = n.size // 2
    f = np.linspace(0.0, k / 2.0, 64 * k + 1)
    target = a * np.sinc(a * f) * np.cos(np.pi * d * f) / np.sinc(f / k)
    w = (np.ones_like(f) if weight is None else np.asarray(weight(f), float) + 1e-3) * np.where(f <= 1.0, 1.0, 0.1)
    # symmetric pairs: tap i and its mirror n.size - 1 - i share a weight; the design is cos(2 pi f x_i) of each
    basis = np.stack([2.0 * np.cos(2.0 * np.pi * f * x[i]) for i in range(half)], axis=1)
    if n.size % 2:
        basis = np.column_stack([basis, np.ones_like(f)])
    # the sum fixed at a: the last pair's weight follows from the others'
    pair_sum = np.full(basis.shape[1], 2.0)
    if n.size % 2:
        pair_sum[-1] = 1.0
    last = basis.shape[1] - 1
    reduced = basis[:, :last] - np.outer(basis[:, last] / pair_sum[last], pair_sum[:last])
    rhs = target - basis[:, last] * a / pair_sum[last]
    sol = _least_squares(reduced * w[:, None], rhs * w)
    coef = np.append(sol, (a - math.fsum((pair_sum[:last] * sol).tolist())) / pair_sum[last])
    taps = np.empty(n.size)
    taps[:half] = coef[:half]
    taps[n.size - half:] = coef[:half][::-1]
    if n.size % 2:
        taps[half] = coef[-1]
    return int(n[0]), taps


def _least_squares(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The least-squares solution of ``a x = b`` (a few unknowns) by its normal equations, every sum correctly
    rounded (``math.fsum``) and Gaussian elimination with partial pivoting in plain floats: the same bits on any
    machine (LAPACK's would be its BLAS's)."""
    m = a.shape[1]
    g = [[math.fsum((a[:, i] * a[:, j]).tolist()) for j in range(m)] + [math.fsum((a[:, i] * b).tolist())]
         for i in range(m)]
    for col in range(m):
        pivot = max(range(col, m), key=lambda r: (abs(g[r][col]), -r))
        g[col], g[pivot] = g[pivot], g[col]
        if g[col][col] == 0.0:
            continue
        for r in range(col + 1, m):
            factor = g[r][col] / g[col][col]
            g[r] = [x - factor * y for x, y in zip(g[r], g[col])]
    x = [0.0] * m
    for r in range(m - 1, -1, -1):
        x[r] = 0.0 if g[r][r] == 0.0 else (g[r][m] - math.fsum(g[r][c] * x[c] for c in range(r + 1, m))) / g[r][r]
    return np.asarray(x)


def aperture_error(k: int, fill_factor: float, olpf_px: float | None = None, weight=None) -> float:
    """How far :func:`aperture`'s weights on cell averages fall from the aperture's and the filter's transfer
    ``a sinc(a f) cos(pi d f)`` (over ``a``: relative to it at 0), the largest up to 1 cycle per pixel, weighted by
    ``weight(f)`` (the PSF's MTF; 1 without one): 0 for a full aperture without a filter.

    Parameters
    ----------
    k : int
    fill_factor : float
    olpf_px : float, optional
        The filter's separation, pixels.
    weight : callable, optional

    Returns
    -------
    float
    """
    if fill_factor == 1.0 and not olpf_px:
        return 0.0
    offset, taps = aperture(k, fill_factor, None if not olpf_px else olpf_px * k, weight)
    x = (np.arange(offset, offset + taps.size) + 0.5 - k / 2.0) / k
    f = np.linspace(0.0, 1.0, 201)
    got = (taps[None, :] * np.cos(2 * np.pi * f[:, None] * x[None, :])).sum(axis=1) * np.sinc(f / k)
    a = math.sqrt(fill_factor)
    want = a * np.sinc(a * f) * np.cos(np.pi * (olpf_px or 0.0) * f)
    w = np.ones_like(f) if weight is None else np.asarray(weight(f), float)
    return float((np.abs(got - want) * w).max() / a)


def aperture_transfer(f_cy_per_px, fill_factor: float, olpf_px: float | None) -> np.ndarray:
    """The aperture's and the filter's MTF along one axis.

    Parameters
    ----------
    f_cy_per_px : array
        Frequencies, cycles per pixel.
    fill_factor : float
        The aperture's area over the pixel's: its side is ``a = sqrt(fill_factor)`` pixels.
    olpf_px : float or None
        The four-spot filter's separation ``d``, pixels.

    Returns
    -------
    array
        ``|sinc(a f) cos(pi d f)|``.
    """
    f = np.asarray(f_cy_per_px, float)
    out = np.abs(np.sinc(math.sqrt(fill_factor) * f))
    if olpf_px:
        out = out * np.abs(np.cos(np.pi * olpf_px * f))
    return out


# ------------------------------------------------------------------ the fine grid's sampling
def alias_error(psf: PointSpread, k: int, fill_factor: float, olpf_px: float | None = None) -> float:
    """The largest error the fine grid's sampling of ``psf`` leaves in the system MTF: the PSF's transfer at
    ``|g - m k / pitch|`` (m = +-1, +-2: what folds onto frequency ``g`` of the fine grid) times the aperture's
    transfer at ``g``, the largest over ``0 < g <= k / (2 pitch)`` and the channels.

    Parameters
    ----------
    psf : PointSpread
    k : int
        Fine cells per pixel.
    fill_factor : float
    olpf_px : float, optional
        The filter's separation, pixels.

    Returns
    -------
    float
    """
    g = np.linspace(1e-6, k / 2.0, 400)  # cycles per pixel
    folded = np.zeros((3, g.size))
    for m in (1, 2):
        for sign in (-1.0, 1.0):
            f = np.abs(g + sign * m * k)
            folded += np.abs(psf.mtf(f))
    return float((folded * aperture_transfer(g, fill_factor, olpf_px)[None, :]).max())


def oversample(setting, psf: PointSpread | None, fill_factor: float, olpf_px: float | None = None,
               candidates=None) -> int:
    """``optics.oversample`` resolved: a number is itself; ``auto`` is the smallest k of 1 to
    :data:`MAX_OVERSAMPLE` (among ``candidates``) whose :func:`alias_error` (the PSF's sampling) and
    :func:`aperture_error` (the aperture's and the filter's weights) are both at most :data:`ALIAS_LIMIT`, or the
    largest: 1 without a PSF, a smaller aperture or a filter.

    Parameters
    ----------
    setting : int or "auto"
    psf : PointSpread or None
        The PSF, made at any k (its transfer does not depend on it).
    fill_factor, olpf_px
        The pixel's aperture and its filter's separation (pixels).
    candidates : iterable of int, optional
        The k that a PSF file's sampling allows; default 1 to :data:`MAX_OVERSAMPLE`.

    Returns
    -------
    int
    """
    if setting != "auto":
        return int(setting)
    if psf is None and fill_factor == 1.0 and not olpf_px:
        return 1
    ks = list(candidates) if candidates is not None else list(range(1, MAX_OVERSAMPLE + 1))
    weight = None if psf is None else (lambda f: psf.mtf(f).max(axis=0))
    for k in ks:
        if ((psf is None or alias_error(psf, k, fill_factor, olpf_px) <= ALIAS_LIMIT)
                and aperture_error(k, fill_factor, olpf_px, weight) <= ALIAS_LIMIT):
            return k
    return ks[-1]


# ------------------------------------------------------------------ relative illumination
def _offsets_mm(shape, region, pitch_um: float) -> tuple[np.ndarray, np.ndarray]:
    """The pixel centres' offsets from the sensor's centre, mm: (rows,) down and (cols,) across ``region``."""
    rows, cols = shape
    r0, r1, c0, c1 = (0, rows, 0, cols) if region is None else region
    return ((np.arange(r0, r1) + 0.5 - rows / 2.0) * pitch_um * 1e-3,
            (np.arange(c0, c1) + 0.5 - cols / 2.0) * pitch_um * 1e-3)


def _image_height_squared_mm2(shape, region, pitch_um: float) -> np.ndarray:
    """Each pixel's squared image height (its centre's squared distance from the sensor's centre), mm^2."""
    y, x = _offsets_mm(shape, region, pitch_um)
    return np.add.outer(y * y, x * x)


@functools.lru_cache(maxsize=8)
def _ri_table(path: str) -> tuple[np.ndarray, np.ndarray]:
    """A relative-illumination table: image heights (mm) and relative illumination in (0, 1]."""
    key = f"optics.relative_illumination {path}"
    t = _rows(path, key, (2,))
    if (t[:, 1] <= 0).any() or (t[:, 1] > 1).any():
        raise CmosnoiseError(f"{key}: each relative illumination must be in (0, 1]; this table spans "
                             f"{t[:, 1].min():g} to {t[:, 1].max():g}")
    return t[:, 0], t[:, 1]


def image_distance_mm(op) -> float:
    """The lens's image distance, ``f (1 + m)`` mm (a thin lens focused at magnification m): what a field angle's
    tangent divides the image height by.

    Parameters
    ----------
    op : OpticsSection

    Returns
    -------
    float
    """
    return op.focal_length_mm * (1.0 + op.magnification)


def relative_illumination(config, shape: tuple[int, int], region=None) -> np.ndarray | None:
    """The relative illumination of each pixel (1 on the axis), or None for ``none``.

    Parameters
    ----------
    config : Config
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1), optional
        The pixels to give.

    Returns
    -------
    (rows, cols) float64 array or None
        ``cos(theta)^4`` for ``cos4`` (``tan theta = h / i``, :func:`image_distance_mm`); the table interpolated at each pixel's image height (its end values
        beyond it) for a file.
    """
    op, pitch = config.optics, config.sensor.pixel_pitch_um
    kind = op.relative_illumination
    if kind.lower() == "none":
        return None
    if kind.lower() == "cos4":  # cos(atan(h / i))^4 = 1 / (1 + h^2 / i^2)^2, without the angle
        h2 = _image_height_squared_mm2(shape, region, pitch) / image_distance_mm(op) ** 2
        h2 += 1.0
        np.multiply(h2, h2, out=h2)
        return np.divide(1.0, h2, out=h2)
    h, ri = _ri_table(kind)
    return np.interp(np.sqrt(_image_height_squared_mm2(shape, region, pitch)), h, ri)


# ------------------------------------------------------------------ chief-ray angle
def _rows(value, key: str, widths: tuple[int, ...]) -> np.ndarray:
    """A table given inline (rows) or as a CSV file, checked: finite, first column increasing and >= 0."""
    if isinstance(value, str):
        from .light import read_table

        t = read_table(value, key)
    else:
        t = np.asarray(value, np.float64)
    if t.ndim != 2 or t.shape[1] not in widths or t.shape[0] < 2:
        raise CmosnoiseError(f"{key}: give at least two rows of {' or '.join(map(str, widths))} columns")
    if not np.isfinite(t).all() or (np.diff(t[:, 0]) <= 0).any() or t[0, 0] < 0:
        raise CmosnoiseError(f"{key}: the first column must be finite, >= 0 and increasing")
    return t


def _angle_table(op) -> np.ndarray | None:
    """``optics.chief_ray_angle`` checked, (n, 2): image height (mm) and angle (deg); None where no angle reaches
    the photodiodes (none configured, or the microlenses take all of it back)."""
    if op.chief_ray_angle is None or op.microlens_compensation >= 1:
        return None
    t = _rows(op.chief_ray_angle, "optics.chief_ray_angle", (2,))
    if (np.abs(t[:, 1]) > 60).any():
        raise CmosnoiseError("optics.chief_ray_angle: angles must be from -60 to 60 degrees")
    return t


def check_tables(op) -> None:
    """Read and check every lens table the optics section names, used or not (a chief-ray angle without an
    angle QE or a leaning crosstalk is read too): a file that cannot be a table is one line at once, not accepted
    in silence.

    Parameters
    ----------
    op : OpticsSection

    Raises
    ------
    CmosnoiseError
    """
    if op.relative_illumination.lower() not in ("none", "cos4"):
        _ri_table(op.relative_illumination)
    if op.chief_ray_angle is not None:
        t = _rows(op.chief_ray_angle, "optics.chief_ray_angle", (2,))
        if (np.abs(t[:, 1]) > 60).any():
            raise CmosnoiseError("optics.chief_ray_angle: angles must be from -60 to 60 degrees")
    if op.angle_relative_qe is not None:
        _qe_table(op)


def _lean_table(config) -> np.ndarray | None:
    """The chief-ray angle's table where crosstalk's kernel leans with it (:func:`_angle_table`), else None."""
    if config.crosstalk.kernel_at_angle_pct is None or not config.crosstalk.enabled:
        return None
    return _angle_table(config.optics)


def _qe_table(op) -> np.ndarray:
    """``optics.angle_relative_qe`` checked, (n, 2) or (n, 4): angle (deg) and relative QE (one, or R, G, B)."""
    t = _rows(op.angle_relative_qe, "optics.angle_relative_qe", (2, 4))
    if (t[:, 1:] <= 0).any() or (t[:, 1:] > 1).any():
        raise CmosnoiseError("optics.angle_relative_qe: each relative QE must be in (0, 1]")
    return t


def incidence(config, shape: tuple[int, int], region=None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Each pixel's angle of incidence after the microlenses, and its direction from the optical centre.

    The chief ray's angle ``optics.chief_ray_angle`` at the pixel's image height (the table interpolated, held at
    its ends), times ``1 - optics.microlens_compensation``.

    Parameters
    ----------
    config : Config
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1), optional
        The pixels to give.

    Returns
    -------
    (angle_deg, cos_phi, sin_phi), each (rows, cols) float64, or None
        None where no chief-ray angle is configured or the microlenses take all of it back. ``phi`` is the
        pixel's direction from the centre (cos: along the columns, sin: along the rows, down).
    """
    op, pitch = config.optics, config.sensor.pixel_pitch_um
    t = _angle_table(op)
    if t is None:
        return None
    y, x = _offsets_mm(shape, region, pitch)
    h = np.sqrt(np.add.outer(y * y, x * x))
    angle = np.interp(h, t[:, 0], t[:, 1])
    angle *= 1.0 - op.microlens_compensation
    # h is 0 only where a pixel's centre is the sensor's (an odd size): its direction is then 0
    inv = np.divide(1.0, h, out=np.zeros_like(h), where=h > 0)
    return angle, x[None, :] * inv, y[:, None] * inv


def angle_qe(config, pattern: str, shape: tuple[int, int], region=None) -> np.ndarray | None:
    """Each pixel's QE at its angle of incidence relative to normal incidence (its own CFA channel's), or None.

    Parameters
    ----------
    config : Config
    pattern : str
        The CFA.
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1), optional
        The pixels to give.

    Returns
    -------
    (rows, cols) float64 array or None
        ``optics.angle_relative_qe`` interpolated at each pixel's angle (:func:`incidence`); None without one.
    """
    op = config.optics
    if op.angle_relative_qe is None:
        return None
    seen = incidence(config, shape, region)
    if seen is None:
        return None
    t = _qe_table(op)
    angle = np.abs(seen[0])
    if t.shape[1] == 2 or cfa_mod.is_mono(pattern):
        return np.interp(angle, t[:, 0], t[:, 1])
    out = np.empty_like(angle)
    r0, c0 = (0, 0) if region is None else (region[0], region[2])
    cells = cfa_mod.tile(cfa_mod.crop_pattern(pattern, r0, c0))
    for dr in (0, 1):  # each cell of the 2 x 2 pattern at once, by its own channel's column
        for dc in (0, 1):
            out[dr::2, dc::2] = np.interp(angle[dr::2, dc::2], t[:, 0], t[:, 1 + int(cells[dr, dc])])
    return out


def lean_weights(config, shape: tuple[int, int], region=None) -> tuple[np.ndarray, np.ndarray] | None:
    """The signed shares of crosstalk's lean along the columns and the rows per pixel (:func:`.stages.crosstalk.lean`),
    or None where the kernel does not lean (no ``crosstalk.kernel_at_angle_pct`` or no angle).

    Parameters
    ----------
    config : Config
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1), optional
        The pixels to give.

    Returns
    -------
    (toward_col, toward_row), each (rows, cols) float64
        ``min(|angle| / reference_angle, 1) * cos(phi)`` and ``* sin(phi)``, the sign of the angle kept.
    """
    t = _lean_table(config)
    if t is None:
        return None
    if lens.ready():  # the same expressions pixel by pixel, without the maps between them
        y, x = _offsets_mm(shape, region, config.sensor.pixel_pitch_um)
        return lens.lean_shares(y, x, t[:, 0], t[:, 1], 1.0 - config.optics.microlens_compensation,
                                config.crosstalk.reference_angle_deg)
    angle, cos_phi, sin_phi = incidence(config, shape, region)
    share = np.clip(angle / config.crosstalk.reference_angle_deg, -1.0, 1.0)
    return share * cos_phi, share * sin_phi


# ------------------------------------------------------------------ the picture through the lens
def leaning_charge(q: np.ndarray, config, shape: tuple[int, int], region, leans: tuple) -> np.ndarray | None:
    """The charge crosstalk's lean moves (:func:`.stages.crosstalk.lean`) with each pixel's shares of
    :func:`lean_weights`, or None where the kernel does not lean.

    Compiled (:func:`cmosnoise.engine.lens.leaning_spread`), each pixel's shares are made where its charge is
    scattered, without the two maps: the same bits as ``crosstalk.lean(q, leans, *lean_weights(...))``.

    Parameters
    ----------
    q : (rows, cols) array, e-
        The charge over ``region``, before diffusion.
    config : Config
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1)
        The pixels ``q`` holds.
    leans : tuple of four (3, 3) arrays
        :func:`.stages.crosstalk.lean_kernels`.

    Returns
    -------
    (rows, cols) float64 array or None
        To add to the crosstalk's result.
    """
    t = _lean_table(config)
    if t is None:
        return None
    if not lens.ready():
        return crosstalk.lean(q, leans, *lean_weights(config, shape, region), row0=region[0])
    y, x = _offsets_mm(shape, region, config.sensor.pixel_pitch_um)
    return lens.leaning_spread(q, y, x, t[:, 0], t[:, 1], 1.0 - config.optics.microlens_compensation,
                               config.crosstalk.reference_angle_deg, leans, region[0])


def active(config) -> bool:
    """Whether the lens changes the picture: a PSF, a relative illumination or an angle-dependent QE configured.

    Parameters
    ----------
    config : Config

    Returns
    -------
    bool
        False: :func:`cfa_signal` is :func:`.scene.cfa_signal`, bit for bit.
    """
    op = config.optics
    return (op.psf.lower() != "none" or op.relative_illumination.lower() != "none"
            or (op.angle_relative_qe is not None and op.chief_ray_angle is not None))


def shade(signal: np.ndarray, config, pattern: str, shape: tuple[int, int], region=None) -> np.ndarray:
    """``signal`` times each pixel's relative illumination, then times its QE at its angle of incidence.

    Parameters
    ----------
    signal : (rows, cols) float64 array
        The region's relative signal; changed in place where it is writeable.
    config : Config
    pattern : str
        The CFA.
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1), optional
        The pixels ``signal`` holds.

    Returns
    -------
    (rows, cols) float64 array
        ``signal * relative_illumination(...) * angle_qe(...)`` (each factor where it is configured): with the
        compiled loops (:mod:`cmosnoise.engine.lens`) in one pass, the same bits.
    """
    op = config.optics
    kind = op.relative_illumination.lower()
    angles = _angle_table(op) if op.angle_relative_qe is not None else None
    if kind == "none" and angles is None:
        return signal
    if not lens.ready():  # the specification: each factor's map, multiplied in
        for factor in (relative_illumination(config, shape, region), angle_qe(config, pattern, shape, region)):
            if factor is not None:
                signal = np.multiply(signal, factor, out=signal if signal.flags.writeable else None)
        return signal
    if not (signal.flags.writeable and signal.flags.c_contiguous and signal.dtype == np.float64):
        signal = np.array(signal, np.float64)
    y, x = _offsets_mm(shape, region, config.sensor.pixel_pitch_um)
    ri_kind = {"none": lens.RI_NONE, "cos4": lens.RI_COS4}.get(kind, lens.RI_TABLE)
    table = qe = None
    cells = np.zeros((2, 2), np.int64)
    if angles is not None:
        t = _qe_table(op)
        if t.shape[1] == 2 or cfa_mod.is_mono(pattern):
            qe = t[:, :2]
        else:
            r0, c0 = (0, 0) if region is None else (region[0], region[2])
            qe, cells = t, cfa_mod.tile(cfa_mod.crop_pattern(pattern, r0, c0))
        table = (angles[:, 0], angles[:, 1], 1.0 - op.microlens_compensation)
    return lens.shade(signal, y, x, ri_kind, image_distance_mm(op), _ri_table(op.relative_illumination)
                      if ri_kind == lens.RI_TABLE else None, table, qe, cells)
