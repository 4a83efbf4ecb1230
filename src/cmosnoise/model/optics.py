"""The lens between the scene and the pixels: relative illumination across the field and the point spread function.

docs/model.md section 2b is the specification. Both act on the scene's light at the sensor's pixels, before the
colour filter array takes each pixel's channel:

- **the point spread function** (``optics.psf``), one per colour channel: the polychromatic Airy pattern of a
  diffraction-limited lens at its f-number, weighted by the channel's photo-electron spectrum (with light in lux;
  otherwise at :data:`DEFAULT_WAVELENGTHS_NM`), a Gaussian, or a user's 2-D array. Each kernel is the continuous
  PSF averaged over a pixel's square around each offset, so a point PSF leaves the picture as it is; it sums to 1.
  It is convolved directly at each pixel's own channel where it is at most
  :data:`~cmosnoise.engine.convolve.MAX_SIDE` pixels across (:mod:`cmosnoise.engine.convolve`), otherwise by FFT
  in blocks of :data:`BLOCK` pixels on a grid fixed to the whole sensor, each block with a margin of the kernel's
  radius; the picture's edge pixels are repeated beyond it. Either way a tile of a sensor equals that crop of the
  whole bit for bit;
- **the relative illumination** (``optics.relative_illumination``): cos^4 of each pixel's field angle
  (``tan theta = h / f``, h the pixel centre's distance from the sensor's centre), or a table of image height
  against relative illumination. It multiplies each pixel's signal.

With ``psf`` and ``relative_illumination`` at ``none``, :func:`cfa_signal` is :func:`.scene.cfa_signal`.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.model import optics
>>> k = optics.gaussian_kernel(0.8)
>>> k.shape, round(float(k.sum()), 12)
((11, 11), 1.0)
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np

from .. import inputs
from ..engine import convolve, layout, lens
from ..errors import CmosnoiseError
from . import cfa as cfa_mod
from . import scene as scene_mod
from .stages import crosstalk

#: the FFT blocks' side, pixels (a block and its margins make one transform)
BLOCK = 512
#: the wavelengths of a diffraction PSF without light in lux (R, G, B), nm
DEFAULT_WAVELENGTHS_NM = (610.0, 540.0, 465.0)
#: sub-samples a pixel is averaged over along each axis when a continuous PSF becomes a kernel
SUBSAMPLES = 8
#: the radius of an Airy kernel, in first-dark-ring radii of the longest wavelength
AIRY_RINGS = 6
#: the largest PSF kernel, pixels across
MAX_KERNEL = 257
#: the largest PSF file (a float64 array of MAX_KERNEL^2 with room for its header) and relative-illumination table
MAX_FILE_BYTES = 64 * 2**20

__all__ = ["airy", "airy_kernel", "gaussian_kernel", "psf_kernels", "relative_illumination", "incidence",
           "angle_qe", "lean_weights", "leaning_charge", "shade", "cfa_signal", "blur_cfa", "blur", "direct",
           "active", "BLOCK"]


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
        The irradiance relative to the centre's; its first zero lies at ``1.2197 lambda N``.
    """
    from scipy.special import j1

    v = np.pi * np.asarray(r_um, float) / (wavelength_um * f_number)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (2.0 * j1(v) / v) ** 2
    return np.where(v == 0, 1.0, out)


def _pixel_averaged(psf, radius: int, step: float) -> np.ndarray:
    """A continuous PSF ``psf(x, y)`` (pixels) averaged over each pixel's square at offsets -radius..radius, summing
    to 1: (2 radius + 1, 2 radius + 1)."""
    n = 2 * radius + 1
    sub = (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5
    axis = (np.arange(n) - radius)[:, None] + sub[None, :]  # (n, SUBSAMPLES) sample positions, pixels
    x = axis.reshape(-1)
    values = psf(x[None, :] * step, x[:, None] * step)
    k = values.reshape(n, SUBSAMPLES, n, SUBSAMPLES).mean(axis=(1, 3))
    return k / k.sum()


def airy_kernel(wavelengths_nm: np.ndarray, weights: np.ndarray, f_number: float, pitch_um: float) -> np.ndarray:
    """The polychromatic Airy pattern, averaged over each pixel, as a kernel summing to 1.

    Parameters
    ----------
    wavelengths_nm : (n,) array
        Wavelengths, nm.
    weights : (n,) array
        Each wavelength's share of the channel's photo-electrons (any scale).
    f_number : float
        N.
    pitch_um : float
        The pixel pitch, um.

    Returns
    -------
    (k, k) float64 array
        k odd, the kernel's radius :data:`AIRY_RINGS` first dark rings of the longest wavelength (at most
        :data:`MAX_KERNEL` across).
    """
    wl = np.asarray(wavelengths_nm, float) * 1e-3
    w = np.asarray(weights, float)
    keep = w > 0
    wl, w = wl[keep], w[keep] / w[keep].sum()
    ring = 1.22 * wl.max() * f_number / pitch_um
    radius = int(min(max(math.ceil(AIRY_RINGS * ring), 2), (MAX_KERNEL - 1) // 2))
    # each wavelength's Airy pattern carries its share of the power: normalised by its integral, pi/4 (lambda N)^2 * 4/pi
    norms = (wl * f_number) ** 2 / np.pi * 4.0

    # the polychromatic profile on a fine radial grid (1/64 of the shortest first ring), read at each sub-sample
    r_grid = np.linspace(0.0, (radius + 1) * math.sqrt(2) * pitch_um,
                         int((radius + 1) * math.sqrt(2) * pitch_um / (1.22 * wl.min() * f_number / 64)) + 2)
    profile = sum(wi * airy(r_grid, li, f_number) / ni for wi, li, ni in zip(w, wl, norms))

    def psf(x_um, y_um):
        return np.interp(np.hypot(x_um, y_um), r_grid, profile)

    return _pixel_averaged(psf, radius, pitch_um)


def gaussian_kernel(sigma_px: float) -> np.ndarray:
    """A Gaussian of ``sigma_px`` integrated exactly over each pixel (the normal CDF's differences), summing to 1.

    Parameters
    ----------
    sigma_px : float
        sigma, pixels.

    Returns
    -------
    (k, k) float64 array
        Radius ``ceil(4 sigma) + 1`` (at most :data:`MAX_KERNEL` across).
    """
    from scipy.special import ndtr

    radius = int(min(math.ceil(4 * sigma_px) + 1, (MAX_KERNEL - 1) // 2))
    edges = (np.arange(-radius, radius + 2) - 0.5) / sigma_px
    line = np.diff(ndtr(edges))
    k = np.outer(line, line)
    return k / k.sum()


def _file_kernel(path: str, sampling_um: float | None, pitch_um: float) -> np.ndarray:
    """A user's PSF (.npy or FITS, one 2-D array) at the pixel pitch, odd-sized, summing to 1."""
    key = "optics.psf"
    suffix = Path(path).suffix.lower()
    if suffix == ".npy":
        with inputs.open_regular(path, f"{key} file") as f:
            a = np.load(f, allow_pickle=False)
    elif suffix in (".fits", ".fit", ".fts"):
        from astropy.io import fits

        inputs.fits_data_bytes(path, f"{key} file", MAX_FILE_BYTES)
        with fits.open(inputs.check_regular(path, f"{key} file"), memmap=False) as hdus:
            a = next((h.data for h in hdus if h.data is not None), None)
    else:
        raise CmosnoiseError(f"{key} = {path!r}: give none, diffraction, gaussian, or a .npy or .fits file")
    a = np.asarray(a) if a is not None else np.zeros(0)
    if a.ndim != 2 or min(a.shape) < 1 or a.dtype.kind not in "uif":
        raise CmosnoiseError(f"{key} {path}: a PSF is one 2-D array of real numbers; this is {a.shape} {a.dtype}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all() or (a < 0).any() or a.sum() <= 0:
        raise CmosnoiseError(f"{key} {path}: a PSF's values must be finite, >= 0 and sum to more than 0")
    if sampling_um is not None and sampling_um != pitch_um:
        from scipy.ndimage import zoom

        a = np.clip(zoom(a, sampling_um / pitch_um, order=1), 0, None)
    pad = [(0, 1 - s % 2) for s in a.shape]  # odd sides: the centre is the middle sample
    a = np.pad(a, pad)
    if max(a.shape) > MAX_KERNEL:
        raise CmosnoiseError(f"{key} {path}: {a.shape[0]} x {a.shape[1]} samples at the pixel pitch; at most "
                             f"{MAX_KERNEL} across")
    side = max(a.shape)
    a = np.pad(a, [((side - a.shape[0]) // 2,) * 2, ((side - a.shape[1]) // 2,) * 2])
    return a / a.sum()


def psf_kernels(config) -> np.ndarray | None:
    """The configured PSF, one kernel per colour channel (R, G, B), or None for ``optics.psf: none``.

    Parameters
    ----------
    config : Config

    Returns
    -------
    (3, k, k) float64 array or None
        Each kernel sums to 1.
    """
    op = config.optics
    if op.psf.lower() == "none":
        return None
    spectra = None
    if config.light.enabled and op.psf.lower() == "diffraction":  # each channel's photo-electron spectrum
        from . import light as light_mod

        li = light_mod.channel_light(config)
        spectra = (tuple(li.wavelengths), tuple(tuple(li.photon_flux * li.qe[:, ch]) for ch in range(3)))
    parts = json.dumps({"optics": op.model_dump(mode="json"), "pitch": config.sensor.pixel_pitch_um}, sort_keys=True)
    return _psf_kernels(parts, spectra)


@functools.lru_cache(maxsize=8)
def _psf_kernels(parts: str, spectra: tuple | None) -> np.ndarray:
    p = json.loads(parts)
    op, pitch = p["optics"], p["pitch"]
    kind = op["psf"].lower()
    if kind == "gaussian":
        k = gaussian_kernel(op["psf_sigma_px"])
        out = np.stack([k, k, k])
    elif kind == "diffraction":
        if spectra is not None:
            each = [airy_kernel(spectra[0], w, op["f_number"], pitch) for w in spectra[1]]
        else:
            each = [airy_kernel([w], [1.0], op["f_number"], pitch) for w in DEFAULT_WAVELENGTHS_NM]
        side = max(k.shape[0] for k in each)  # one size for the three (each padded with zeros about its centre)
        out = np.stack([np.pad(k, (side - k.shape[0]) // 2) for k in each])
    else:
        k = _file_kernel(op["psf"], op["psf_sampling_um"], pitch)
        out = np.stack([k, k, k])
    out.setflags(write=False)
    return out


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
        ``cos(theta)^4`` for ``cos4``; the table interpolated at each pixel's image height (its end values
        beyond it) for a file.
    """
    op, pitch = config.optics, config.sensor.pixel_pitch_um
    kind = op.relative_illumination
    if kind.lower() == "none":
        return None
    if kind.lower() == "cos4":  # cos(atan(h / f))^4 = 1 / (1 + h^2 / f^2)^2, without the angle
        h2 = _image_height_squared_mm2(shape, region, pitch) / op.focal_length_mm**2
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


def _planes(draw, region) -> tuple[np.ndarray, bool]:
    """The picture over ``region`` as float32 planes: (3, rows, cols), or (3, cols, rows) and True where the scene
    gives its channels transposed (a resampled picture: no interleaved copy is made)."""
    if isinstance(draw, scene_mod.Resampled):
        return draw.transposed_planes(region, np.float32), True
    return np.ascontiguousarray(np.asarray(draw(region)).transpose(2, 0, 1), np.float32), False


def _blocks(draw, shape: tuple[int, int], kernels: np.ndarray, region=None):
    """The blurred picture a block of the sensor's grid at a time: yields ``(q0, q1, p0, p1, planes)``, the part
    of ``region`` in one block (sensor coordinates) and its (3, q1 - q0, p1 - p0) float32 values (a view).

    Each block of :data:`BLOCK` pixels, with a margin of the kernel's radius (the picture's edge pixels repeated
    beyond it), is convolved with one kernel per channel by real FFTs in single precision, every core on each
    transform (pocketfft's threads split the other axes: the same bits on any number). Where the scene gives its
    channels transposed, the blocks are transformed transposed, with the kernels transposed. A tile is made of
    the same blocks as the whole, so it is that crop bit for bit.
    """
    import scipy.fft as sfft

    rows, cols = shape
    r0, r1, c0, c1 = (0, rows, 0, cols) if region is None else tuple(int(v) for v in region)
    m = kernels.shape[1] // 2
    # the blocks the region touches, and the picture under them with their margins, drawn once (each block's part
    # of it is what a draw of the block alone gives: any region of a scene is that crop of the whole)
    b_r0, b_c0 = r0 // BLOCK * BLOCK, c0 // BLOCK * BLOCK
    b_r1, b_c1 = min(-(-r1 // BLOCK) * BLOCK, rows), min(-(-c1 // BLOCK) * BLOCK, cols)
    g0, g1, h0, h1 = max(b_r0 - m, 0), min(b_r1 + m, rows), max(b_c0 - m, 0), min(b_c1 + m, cols)
    picture, transposed = _planes(draw, (g0, g1, h0, h1))
    if transposed:  # (3, cols, rows): each block is cut and padded along the picture's own axes
        picture = picture.transpose(0, 2, 1)
    taps = np.ascontiguousarray(kernels.transpose(0, 2, 1) if transposed else kernels, np.float32)
    spectra = {}
    for br in range(b_r0, r1, BLOCK):
        for bc in range(b_c0, c1, BLOCK):
            be_r, be_c = min(br + BLOCK, rows), min(bc + BLOCK, cols)
            # the block with its margins, clamped to the picture, its edge pixels repeated beyond it
            a0, a1, d0, d1 = max(br - m, 0), min(be_r + m, rows), max(bc - m, 0), min(be_c + m, cols)
            src = picture[:, a0 - g0:a1 - g0, d0 - h0:d1 - h0]
            edges = ((0, 0), (a0 - (br - m), be_r + m - a1), (d0 - (bc - m), be_c + m - d1))
            if any(edges[1] + edges[2]):
                src = np.pad(src, edges, mode="edge")
            if transposed:
                src = src.transpose(0, 2, 1)
            # a linear convolution, zero-padded to a fast size: the wrapped part falls in the first 2m rows and
            # columns, outside the valid part kept
            size = (sfft.next_fast_len(src.shape[1], real=True), sfft.next_fast_len(src.shape[2], real=True))
            if size not in spectra:
                spectra[size] = sfft.rfft2(taps, s=size, axes=(1, 2))
            f = sfft.rfft2(src, s=size, axes=(1, 2), workers=-1)
            f *= spectra[size]
            full = sfft.irfft2(f, s=size, axes=(1, 2), workers=-1)
            if transposed:
                full = full.transpose(0, 2, 1)
            q0, q1, p0, p1 = max(r0, br), min(r1, be_r), max(c0, bc), min(c1, be_c)
            # the 'valid' part starts at 2m: the block's own pixels
            yield q0, q1, p0, p1, full[:, 2 * m + q0 - br:2 * m + q1 - br, 2 * m + p0 - bc:2 * m + p1 - bc]


def direct(kernels: np.ndarray) -> bool:
    """Whether ``kernels`` are convolved directly rather than by FFT blocks.

    Parameters
    ----------
    kernels : (3, k, k) array
        The PSF's kernels (:func:`psf_kernels`).

    Returns
    -------
    bool
        True where k is at most :data:`~cmosnoise.engine.convolve.MAX_SIDE` (:mod:`cmosnoise.engine.convolve`).
    """
    return kernels.shape[1] <= convolve.MAX_SIDE


def _window_planes(draw, shape: tuple[int, int], radius: int, region) -> np.ndarray:
    """The picture over ``region`` and a margin of ``radius`` (its edge pixels repeated beyond the sensor), in the
    layout :func:`cmosnoise.engine.convolve.mosaic` reads: (3, cols + 2 radius, rows + 2 radius) float32."""
    rows, cols = shape
    r0, r1, c0, c1 = region
    ri = convolve.layout_indices(r0, r1, rows, radius, True)
    ci = convolve.layout_indices(c0, c1, cols, radius, False)
    if isinstance(draw, scene_mod.Resampled):  # only the rows and columns asked for, no full-size RGB
        return draw.planes_at(ri, ci, np.float32)
    g0, h0 = max(r0 - radius, 0), max(c0 - radius, 0)
    picture = np.asarray(draw((g0, min(r1 + radius, rows), h0, min(c1 + radius, cols))))
    return np.ascontiguousarray(picture[ri - g0][:, ci - h0].transpose(2, 1, 0), np.float32)


def blur(draw, shape: tuple[int, int], kernels: np.ndarray, region=None) -> np.ndarray:
    """The picture ``draw`` convolved with one kernel per channel, its edge pixels repeated beyond the sensor.

    A kernel of up to :data:`~cmosnoise.engine.convolve.MAX_SIDE` pixels across (a diffraction PSF's, unless the
    f-number is large for the pitch) is convolved directly (:func:`cmosnoise.engine.convolve.mosaic`): the
    picture in float32, each pixel's sum in a fixed order, in float64 by groups of four float32 products (within
    ``5u`` of the value, ``u = 6e-8``: five float32 roundings of each non-negative term at most). A larger one by FFTs in blocks of :data:`BLOCK` on the sensor's grid, in
    single precision: their rounding error is about ``u sqrt(2 log2 n + 1)`` times the block's RMS value (n =
    540^2 points a block with its margins: about 4e-7 times the RMS), a few times the single-precision rounding
    the mean charge is kept in after it and far below shot noise (1e-2 of the charge even at a full well of
    10 000 e-); the tests hold each method to its bound. Either way any region is bit for bit that crop of the
    whole.

    Parameters
    ----------
    draw : callable
        ``region -> (rows, cols, 3)``: a prepared scene (:func:`.scene.prepare`), whose any region is that crop
        of the whole.
    shape : (rows, cols)
        The whole sensor.
    kernels : (3, k, k) array
        One kernel per channel, k odd.
    region : (row0, row1, col0, col1), optional
        The pixels to make (None: all); any region is bit for bit that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
        At least 0 (the transforms' rounding leaves values of about -1e-8 where the picture is black; they are
        taken as 0).
    """
    rows, cols = shape
    r0, r1, c0, c1 = (0, rows, 0, cols) if region is None else tuple(int(v) for v in region)
    out = np.empty((r1 - r0, c1 - c0, 3))
    if direct(kernels):  # each channel at every pixel
        planes = _window_planes(draw, shape, kernels.shape[1] // 2, (r0, r1, c0, c1))
        plane = np.empty((r1 - r0, c1 - c0))
        for c in range(3):
            out[..., c] = convolve.mosaic(planes, kernels, np.full((2, 2), c), np.ones(3), plane)
        return out
    for q0, q1, p0, p1, part in _blocks(draw, shape, kernels, region):
        out[q0 - r0:q1 - r0, p0 - c0:p1 - c0] = part.transpose(1, 2, 0)
    out[~(out > 0.0)] = 0.0
    return out


def blur_cfa(draw, shape: tuple[int, int], kernels: np.ndarray, pattern: str, responsivity,
             region=None) -> np.ndarray:
    """``scene.to_cfa(blur(draw, shape, kernels, region), pattern, responsivity)``, bit for bit, each pixel's own
    channel alone made (a direct kernel) or each block's pixels taken through the CFA as it is made (FFTs): no
    full-size RGB.

    Parameters
    ----------
    draw, shape, kernels, region
        As :func:`blur`.
    pattern : str
        The CFA.
    responsivity : (float, float, float)
        The channels' relative responsivity.

    Returns
    -------
    (rows, cols) float64 array
        Relative signal per pixel.
    """
    rows, cols = shape
    r0, r1, c0, c1 = (0, rows, 0, cols) if region is None else tuple(int(v) for v in region)
    if cfa_mod.is_mono(pattern):  # the luminance of the three blurred channels
        return scene_mod.to_cfa(blur(draw, shape, kernels, region), pattern, responsivity)
    out = np.empty((r1 - r0, c1 - c0))
    gain = np.asarray(responsivity, np.float64)
    if direct(kernels):
        planes = _window_planes(draw, shape, kernels.shape[1] // 2, (r0, r1, c0, c1))
        return convolve.mosaic(planes, kernels, cfa_mod.tile(pattern), gain, out)
    for q0, q1, p0, p1, part in _blocks(draw, shape, kernels, region):
        dst = out[q0 - r0:q1 - r0, p0 - c0:p1 - c0]
        # the block's CFA phase: its first pixel's row and column in the region
        layout.plane_pick(part, cfa_mod.tile(cfa_mod.crop_pattern(pattern, q0 - r0, p0 - c0)), gain, dst)
    return out


def cfa_signal(draw, config, pattern: str, responsivity, shape: tuple[int, int], region=None) -> np.ndarray:
    """A prepared scene through the lens (PSF, relative illumination) and the CFA: relative signal per pixel.

    Parameters
    ----------
    draw : callable
        :func:`.scene.prepare`'s result.
    config : Config
        Its ``optics`` (and ``light``, for a diffraction PSF's spectra).
    pattern : str
        The CFA.
    responsivity : (float, float, float)
        The channels' relative responsivity.
    shape : (rows, cols)
        The whole sensor.
    region : (row0, row1, col0, col1), optional
        The pixels to make.

    Returns
    -------
    (rows, cols) float64 array
        :func:`.scene.cfa_signal` where the lens changes nothing (:func:`active` false), bit for bit.
    """
    if not active(config):  # no lens: the scene's own CFA signal, bit for bit
        return scene_mod.cfa_signal(draw, pattern, responsivity, region)
    if isinstance(draw, scene_mod.RawDraw):
        raise CmosnoiseError("scene: a raw photograph already went through its own lens; set optics.psf, "
                             "optics.relative_illumination and optics.angle_relative_qe to none for it")
    kernels = psf_kernels(config)
    if kernels is None:
        signal = scene_mod.cfa_signal(draw, pattern, responsivity, region)
    else:
        signal = blur_cfa(draw, shape, kernels, pattern, responsivity, region)
    return shade(signal, config, pattern, shape, region)


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
    return lens.shade(signal, y, x, ri_kind, op.focal_length_mm, _ri_table(op.relative_illumination)
                      if ri_kind == lens.RI_TABLE else None, table, qe, cells)
