"""Stage 1, the perfect image: a scene becomes mean photo-electrons per pixel.

A scene is linear RGB light, shape (rows, cols, 3), values in [0, 1] (1 is
the sensor's peak rate). It comes from a file or a built-in:

========================  ===================================================
``photo``                 bundled photograph (coffee cup, CC0, see data/)
``flat:LEVEL``            uniform grey at LEVEL in [0, 1]
``ramp``                  horizontal linear ramp 0 -> 1
``colorchecker``          the 24 patches of the ColorChecker Classic
``zoneplate[:F]``         circular zone plate, a frequency sweep to F cycles per pixel (0.5, Nyquist) at
                          the middle of the shorter edge; each cell its exact area average
``siemens``               Siemens star with 36 spokes, each cell its area share of white
``steps:N``               N horizontal bands, light levels 4**-(N-1) .. 1/16, 1/4, 1
                          from top to bottom (N = 4 by default)
``spot``                  one lit pixel (value 1) at the centre, on black:
                          the crosstalk measurement of the paper's Fig. 4
``edge:ANGLE:LOW:HIGH``   a slanted edge, 5 degrees, 4:1 by default (``edge``, ``edge:ANGLE``;
                          ISO 12233 e-SFR; :mod:`.charts`)
``greys[:N]``             N grey patches from 1 to 0.001 in equal density steps (:mod:`.charts`)
a ``.npz`` cube           ``reflectance`` (rows, cols, n) spectra and ``wavelengths_nm`` (n,): a
                          multispectral scene, each pixel's spectrum through the light and the QE
                          (light in lux only)
a path                    8-bit PNG/JPEG/TIFF: sRGB-encoded, decoded to linear;
                          16-bit or float TIFF/PNG and ``.npy``: already linear,
                          scaled by the file's maximum (or a given ``scale``)
========================  ===================================================

File scenes are resampled to the sensor with area averaging (each sensor
pixel collects the light falling on its area), or bilinear interpolation
where the sensor has more pixels than the scene. The CFA then keeps each
pixel's channel (times the channel's relative responsivity); a monochrome
sensor takes the luminance.

With light in lux (``light.enabled``, :mod:`.light`) a scene's values are
reflectances: ``prepare(..., light=...)`` turns each RGB value into the
colour channels' relative signal through the light's 3 x 3 ``mix`` (for a
picture, at its own resolution, before it is resampled), and the
ColorChecker's patches come from their reflectance spectra.

Examples
--------
>>> from cmosnoise import scene
>>> scene.render("flat:0.5", (4, 6)).shape
(4, 6, 3)
"""

from __future__ import annotations

import functools
from importlib import resources
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .. import inputs
from ..engine import layout
from ..engine import resample as resample_engine
from ..errors import CmosnoiseError
from . import cfa as cfa_mod
from . import charts, raw_scene
from .charts import COLORCHECKER_SRGB8, colorchecker, colorchecker_patches  # noqa: F401 (the scene's names)
from .encoding import linear_to_srgb, srgb_to_linear  # noqa: F401 (the scene's names)
from .encoding import span as _span

#: Rec. 709 / sRGB luminance weights for linear RGB
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

BUILTINS = ("photo", "flat:LEVEL", "ramp", "colorchecker", "zoneplate:F", "siemens", "steps:N", "spot", "edge",
            "greys:N")

# ------------------------------------------------------------------ built-ins
def flat(shape: tuple[int, int], level: float, region=None) -> np.ndarray:
    """Uniform grey at ``level`` (fraction of the peak rate).

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.
    level : float
        The grey level, 0 to 1.
    region : (row0, row1, col0, col1), optional
        The rectangle of the picture to draw (a tile), the same values as that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1 (1: the peak rate); a read-only view of the one value (copy it to write into it).
    """
    r0, r1, c0, c1 = _span(shape, region)
    return np.broadcast_to(float(level), (r1 - r0, c1 - c0, 3))  # one value: a read-only view, no array of it


def ramp(shape: tuple[int, int], region=None) -> np.ndarray:
    """Horizontal ramp, linear light from 0 at the left edge to 1 at the right.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.

    region : (row0, row1, col0, col1), optional
        The rectangle of the picture to draw (a tile), the same values as that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1 (1: the peak rate).
    """
    rows, cols = shape
    r0, r1, c0, c1 = _span(shape, region)
    x = (np.arange(c0, c1) + 0.5) / cols
    return np.broadcast_to(x[None, :, None], (r1 - r0, c1 - c0, 3)).copy()


def steps(shape: tuple[int, int], n: int = 4, region=None) -> np.ndarray:
    """``n`` horizontal bands at levels ``4**-(n-1-i)``, darkest at the top.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, pixels.
    n : int
        The number of bands.

    region : (row0, row1, col0, col1), optional
        The rectangle of the picture to draw (a tile), the same values as that crop of the whole.

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1 (1: the peak rate).
    """
    rows, cols = shape
    r0, r1, c0, c1 = _span(shape, region)
    band = np.minimum((np.arange(r0, r1) * n) // rows, n - 1)
    return np.broadcast_to(steps_levels(n)[band][:, None, None], (r1 - r0, c1 - c0, 3)).copy()


def steps_levels(n: int = 4) -> np.ndarray:
    """The light levels of the ``steps:n`` bands, top to bottom: ``4**-(n-1)`` to ``1/4``, ``1``.

    Parameters
    ----------
    n : int
        The number of bands.

    Returns
    -------
    (n,) float64 array
        The levels, 0 to 1.
    """
    return 4.0 ** -(n - 1 - np.arange(n))


def spot(shape: tuple[int, int], region=None, cells: int = 1) -> np.ndarray:
    """One lit pixel (value 1) at ``(rows // 2, cols // 2)`` of the pixels, all else black.

    Parameters
    ----------
    shape : (rows, cols)
        The picture's size, cells (``cells`` to a pixel along each axis).
    region : (row0, row1, col0, col1), optional
        The rectangle of the picture to draw (a tile), the same values as that crop of the whole.
    cells : int
        Cells per pixel: the pixel's ``cells x cells`` cells are lit.

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1 (1: the peak rate).
    """
    r0, r1, c0, c1 = _span(shape, region)
    img = np.zeros((r1 - r0, c1 - c0, 3))
    r, c = shape[0] // cells // 2 * cells, shape[1] // cells // 2 * cells
    img[max(r - r0, 0):max(r + cells - r0, 0), max(c - c0, 0):max(c + cells - c0, 0)] = 1.0
    return img


def bundled_photo_path() -> Path:
    return Path(str(resources.files("cmosnoise") / "data" / "coffee.jpg"))


# ------------------------------------------------------------------ files
def _decode_array(a: np.ndarray, name: str, scale: float | None) -> np.ndarray:
    """Turn a decoded file array into linear RGB, (rows, cols, 3), float64."""
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4):
        raise CmosnoiseError(f"scene {name!r}: expected a (rows, cols) or (rows, cols, 3) image, got shape {a.shape}")
    if a.shape[2] in (2, 4):  # drop alpha
        a = a[..., :-1]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    if a.dtype == np.uint8:
        lin = srgb_to_linear(a / 255.0)
        if scale is not None:
            lin = lin * (255.0 / scale)
        return lin
    if a.dtype.kind not in "uif" or a.dtype == np.bool_:
        raise CmosnoiseError(f"scene {name!r}: unsupported pixel type {a.dtype}")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        raise CmosnoiseError(f"scene {name!r}: {int(bad.sum())} values are NaN or infinite; a scene must be finite light levels >= 0")
    if (a < 0).any():
        raise CmosnoiseError(f"scene {name!r}: {int((a < 0).sum())} values are negative (min {a.min():g}); light levels must be >= 0")
    denom = scale if scale is not None else a.max()
    if denom <= 0:
        return np.zeros_like(a)
    return a / denom


#: scene files larger than this many bytes or pixels are refused before decoding
MAX_SCENE_BYTES = 2_000_000_000
MAX_SCENE_PIXELS = 64_000_000


def check_file(path: str | Path, max_pixels: int = MAX_SCENE_PIXELS) -> None:
    """The input gate alone for a scene file (its structure and decoded size from its header), so that a command
    refuses a bad scene before any other work (a sensor's maps, a compile).

    Parameters
    ----------
    path : str or Path
        The scene file.
    max_pixels : int
        The most decoded pixels over all its frames and pages.

    Raises
    ------
    CmosnoiseError
        Not a regular file, a damaged or hostile structure, or too many pixels.
    """
    p = inputs.check_regular(path, "scene")
    if raw_scene.is_raw(p):  # a raw photograph: read whole here, so a damaged one is refused before any work
        raw_scene.read(p)
        return
    if p.suffix.lower() == ".npz":  # a multispectral cube: its members' sizes from the zip directory
        from .light import MAX_CUBE_BYTES

        inputs.npz_members(p, "scene cube", MAX_CUBE_BYTES)
        return
    inputs.check_image_pixels(path, "scene", max_pixels,
                              hint=" (a scene is resampled to the sensor anyway: scale it down first)")


#: camera raw formats, read as raw photographs (:mod:`.raw_scene`)
RAW_SUFFIXES = raw_scene.RAW_SUFFIXES


def load_file(path: str | Path, scale: float | None = None, max_pixels: int = MAX_SCENE_PIXELS) -> np.ndarray:
    """Read an image file as linear RGB in [0, 1] (see module docstring).

    The file passes the input gate first (:mod:`cmosnoise.inputs`): a regular
    file, at most ``MAX_SCENE_BYTES``, and at most ``max_pixels`` decoded
    pixels over all its frames and pages, read from its header. Only the
    first frame or page is decoded.

    Parameters
    ----------
    path : str or Path
        An image file (PNG, JPEG, TIFF, ... or a .npy array).
    scale : float, optional
        The value that is white: an 8-bit picture's code (default 255), another type's value (default: the
        largest in the file).
    max_pixels : int
        The most decoded pixels read.

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1.
    """
    p = Path(path)
    name = str(path)
    if not p.exists() and not p.is_symlink():
        raise CmosnoiseError(f"scene {name!r}: no such file (built-in scenes: {', '.join(BUILTINS)})")
    if p.is_dir():
        raise CmosnoiseError(f"scene {name!r} is a folder, not an image file")
    if raw_scene.is_raw(p):
        raise CmosnoiseError(f"scene {name!r} is a camera raw (a colour-filter mosaic above a black level), not a "
                             "picture of linear RGB: it is read as a raw photograph (scene.prepare), at its own "
                             "resolution, not resampled")
    check_file(p, max_pixels)
    if p.stat().st_size > MAX_SCENE_BYTES:
        raise CmosnoiseError(f"scene {name!r} is {p.stat().st_size / 1e9:.1f} GB; images up to "
                             f"{MAX_SCENE_BYTES / 1e9:g} GB are read")
    suffix = p.suffix.lower()
    try:
        if suffix == ".npy":
            a = inputs.read_npy(p, "scene", MAX_SCENE_BYTES, kinds="uifb")  # the header checked, then read
            if a.ndim == 4 or (a.ndim == 3 and a.shape[-1] > 4):  # a stack: its first plane
                a = a[0]
        elif suffix in (".tif", ".tiff"):
            import tifffile

            a = tifffile.imread(p, key=0)
        else:
            import imageio.v3 as iio

            a = iio.imread(p, index=0)
    except CmosnoiseError:
        raise
    except Exception as exc:  # any decoder failure is the file's fault
        raise CmosnoiseError(f"scene {name!r} cannot be read as an image: {inputs.decoder_message(exc)}") from None
    a = np.asarray(a)
    if a.size == 0:
        raise CmosnoiseError(f"scene {name!r} is empty")
    return _decode_array(a, name, scale)


# ------------------------------------------------------------------ resampling
@functools.lru_cache(maxsize=32)
def axis_weights(n_in: int, n_out: int) -> sp.csr_matrix:
    """The weights that resample ``n_in`` pixels to ``n_out`` along one axis (:func:`resample`'s: area averages
    down, linear interpolation up), made once for each pair of sizes: (n_out, n_in) CSR, read-only.

    Parameters
    ----------
    n_in, n_out : int

    Returns
    -------
    scipy.sparse.csr_matrix
    """
    m = _axis_matrix(n_in, n_out)
    for a in (m.data, m.indices, m.indptr):
        a.setflags(write=False)
    return m


def _axis_matrix(n_in: int, n_out: int) -> sp.csr_matrix:
    """(n_out, n_in) weights: area average when shrinking, linear interpolation when growing."""
    if n_out == n_in:
        return sp.identity(n_in, format="csr")
    rows_idx, cols_idx, vals = [], [], []
    if n_out < n_in:
        s = n_in / n_out
        start = np.arange(n_out) * s
        end = start + s
        first = np.floor(start).astype(int)
        for k in range(int(np.ceil(s)) + 1):
            j = first + k
            overlap = np.minimum(end, j + 1) - np.maximum(start, j)
            ok = (overlap > 1e-12) & (j < n_in)
            rows_idx.append(np.nonzero(ok)[0])
            cols_idx.append(j[ok])
            vals.append(overlap[ok] / s)
    else:
        x = (np.arange(n_out) + 0.5) * n_in / n_out - 0.5
        x = np.clip(x, 0, n_in - 1)
        j0 = np.minimum(np.floor(x).astype(int), n_in - 2) if n_in > 1 else np.zeros(n_out, int)
        w = x - j0
        idx = np.arange(n_out)
        rows_idx += [idx, idx]
        cols_idx += [j0, np.minimum(j0 + 1, n_in - 1)]
        vals += [1 - w, w]
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows_idx), np.concatenate(cols_idx))), shape=(n_out, n_in)
    )


def resample(img: np.ndarray, shape: tuple[int, int], region=None) -> np.ndarray:
    """Resample (rows, cols, C) to ``shape``: area averaging down, bilinear up.

    Area averaging conserves the mean light level exactly, so a scene's
    exposure does not depend on the sensor's resolution.

    Parameters
    ----------
    img : (rows, cols, C) array
        A picture.
    shape : (rows, cols)
        The size to resample to.
    region : (row0, row1, col0, col1), optional
        The rectangle of the result to make (a tile): the same rows of the axes' weights, so the same values as
        that crop of the whole.

    Returns
    -------
    (rows, cols, C) float64 array
        ``shape``, or the region's size.
    """
    return _columns_pass(*_row_pass(img, shape, region))


def _columns_pass(planes: np.ndarray, wc) -> np.ndarray:
    """The second half of :func:`resample`: each channel as scipy's sparse products give it, (cols, rows),
    interleaved into (rows, cols, C) by a blocked, compiled copy."""
    return layout.interleave_transposed([wc @ plane.T for plane in planes])


def _row_pass(img: np.ndarray, shape: tuple[int, int], region, axes: tuple | None = None) -> tuple:
    """The first half of :func:`resample`: each channel after the rows' weights, (C, rows, n), and the columns'
    weights (cols, n), both cut to the ``n`` source columns the region reads. ``axes``: the two axes' whole
    weights (:func:`_axis_matrix`) where they are kept (:class:`Resampled`, asked for a region per tile)."""
    r0, r1, c0, c1 = _span(shape, region)
    rows_w, cols_w = axes or (_axis_matrix(img.shape[0], shape[0]), _axis_matrix(img.shape[1], shape[1]))
    wr, (a0, a1) = _band(rows_w[r0:r1])
    wc, (b0, b1) = _band(cols_w[c0:c1])
    part = img[a0:a1, b0:b1]  # only the source pixels the region reads: the same terms of each sum, in order
    return np.stack([wr @ part[..., c] for c in range(img.shape[2])]), wc


class Resampled:
    """A picture resampled to a sensor's ``shape``: any region of it, as linear RGB or through a CFA.

    Parameters
    ----------
    img : (rows, cols, 3) float64 array
        The picture (cropped to the sensor's aspect ratio where it is fitted by cropping).
    shape : (rows, cols)
        The sensor's size.

    Examples
    --------
    >>> import numpy as np
    >>> from cmosnoise import scene
    >>> picture = scene.Resampled(np.random.default_rng(1).random((30, 40, 3)), (60, 80))
    >>> mosaic = picture.cfa("RGGB", region=(0, 20, 10, 40))
    >>> bool((mosaic == scene.to_cfa(picture((0, 20, 10, 40)), "RGGB")).all())
    True
    """

    def __init__(self, img: np.ndarray, shape: tuple[int, int]):
        self.img = img
        self.shape = tuple(shape)
        #: the two axes' whole weights, made once for every region asked for
        self.axes = (axis_weights(img.shape[0], self.shape[0]), axis_weights(img.shape[1], self.shape[1]))

    def __call__(self, region=None) -> np.ndarray:
        """:func:`resample` of the picture: (rows, cols, 3) float64, the region's size (None: the whole)."""
        return _columns_pass(*_row_pass(self.img, self.shape, region, self.axes))

    def cfa(self, pattern: str, responsivity=(1.0, 1.0, 1.0), region=None) -> np.ndarray:
        """``to_cfa(self(region), pattern, responsivity)``, bit for bit, without making the three channels at the
        sensor's size: the columns' weights are applied only for each pixel's own channel
        (:func:`cmosnoise.engine.resample.mosaic`).

        Parameters
        ----------
        pattern : str
            RGGB, BGGR, GRBG, GBRG, or none (monochrome: the luminance of the three channels).
        responsivity : (float, float, float)
            The R, G and B pixels' relative responsivity.
        region : (row0, row1, col0, col1), optional
            The rectangle to make (None: the whole).

        Returns
        -------
        (rows, cols) float64 array
            Relative signal per pixel.
        """
        if cfa_mod.is_mono(pattern) or self.img.shape[2] != 3:
            return to_cfa(self(region), pattern, responsivity)
        planes, wc = _row_pass(self.img, self.shape, region, self.axes)
        return resample_engine.mosaic(planes, wc, cfa_mod.tile(pattern), np.asarray(responsivity, np.float64))


class RawDraw:
    """A raw photograph prepared as a scene (:mod:`.raw_scene`): its mosaic at the sensor's pixels.

    Parameters
    ----------
    photo : RawPhoto
    corner : (row, col)
        Where the sensor's pixel (0, 0) lies in the photograph (``scene.window``; (0, 0) without one).
    shape : (rows, cols)
        The sensor's size.
    """

    def __init__(self, photo, corner: tuple[int, int], shape: tuple[int, int]):
        self.photo, self.corner, self.shape = photo, corner, shape
        if corner == (0, 0) and photo.signal.shape != shape:
            rows, cols = photo.signal.shape
            raise CmosnoiseError(f"scene: the raw photograph is {rows} x {cols} pixels, the sensor {shape[0]} x "
                                 f"{shape[1]}; a raw scene is used at its own resolution: set sensor.height={rows} "
                                 f"and sensor.width={cols}, or take a scene.window of it")

    def signal(self, pattern: str, region=None) -> np.ndarray:
        """The relative signal of the sensor's pixels in ``region`` (None: all), checked against its ``pattern``."""
        whole = self.photo.window(self.corner, self.shape, pattern)
        r0, r1, c0, c1 = _span(self.shape, region)
        return np.array(whole[r0:r1, c0:c1])

    def __call__(self, region=None) -> np.ndarray:
        r0, r1, c0, c1 = _span(self.shape, region)
        r, c = self.corner
        return np.array(self.photo.signal[r + r0:r + r1, c + c0:c + c1])


def cfa_signal(draw, pattern: str, responsivity=(1.0, 1.0, 1.0), region=None) -> np.ndarray:
    """A prepared scene (:func:`prepare`) through the CFA: ``to_cfa(draw(region), pattern, responsivity)``, made
    without the full-size RGB where the scene is a resampled picture (:meth:`Resampled.cfa`).

    Parameters
    ----------
    draw : callable
        :func:`prepare`'s result.
    pattern : str
        RGGB, BGGR, GRBG, GBRG, or none (monochrome).
    responsivity : (float, float, float)
        The R, G and B pixels' relative responsivity.
    region : (row0, row1, col0, col1), optional
        The rectangle to make (None: the whole).

    Returns
    -------
    (rows, cols) float64 array
        Relative signal per pixel.

    Examples
    --------
    >>> from cmosnoise import scene
    >>> draw = scene.prepare("photo", (60, 80))
    >>> bool((scene.cfa_signal(draw, "GRBG") == scene.to_cfa(draw(), "GRBG")).all())
    True
    """
    if isinstance(draw, Resampled):
        return draw.cfa(pattern, responsivity, region)
    if isinstance(draw, RawDraw):  # a mosaic already: its own colours, no responsivity
        return draw.signal(pattern, region)
    return to_cfa(draw(region), pattern, responsivity)


def _band(w) -> tuple:
    """Weights ``w`` (CSR, output x source) cut to the source indices they read: (the cut weights, (first, end))."""
    if w.nnz == 0:
        return w[:, :0], (0, 0)
    lo, hi = int(w.indices.min()), int(w.indices.max()) + 1
    # made from its arrays, each row's terms keep their stored order (no re-sorting): the same sums, bit for bit
    return sp.csr_matrix((w.data, w.indices - lo, w.indptr), shape=(w.shape[0], hi - lo)), (lo, hi)


def crop_to_aspect(img: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Centre crop of ``img`` with the aspect ratio of ``shape``.

    Parameters
    ----------
    img : (rows, cols, ...) array
        A picture.
    shape : (rows, cols)
        The aspect ratio to crop to.

    Returns
    -------
    array
        The centre crop, ``img``'s dtype and channels.
    """
    h, w = img.shape[:2]
    target = shape[1] / shape[0]
    if w / h > target:
        new_w = max(1, int(round(h * target)))
        c0 = (w - new_w) // 2
        return img[:, c0 : c0 + new_w]
    new_h = max(1, int(round(w / target)))
    r0 = (h - new_h) // 2
    return img[r0 : r0 + new_h]


# ------------------------------------------------------------------ public
def builtin_name(source: str) -> str | None:
    """The built-in scene ``source`` names (``flat`` for ``flat:0.5``, ``steps`` for ``steps:8``, ``photo``, ...),
    or None for a file.

    Parameters
    ----------
    source : str
        A scene: a built-in's name or a file's path.

    Returns
    -------
    str or None
    """
    low = str(source).strip().lower()
    head = low.partition(":")[0]
    if head in ("flat", "steps", "edge", "greys", "zoneplate") or (low == head and low in (
            "photo", "ramp", "colorchecker", "siemens", "spot")):
        return head
    return None


def is_builtin(source: str) -> bool:
    """Whether ``source`` names a built-in scene rather than a file (:func:`builtin_name`).

    Parameters
    ----------
    source : str
        A scene: a built-in's name or a file's path.

    Returns
    -------
    bool
    """
    return builtin_name(source) is not None


def render(source: str, shape: tuple[int, int], scale: float | None = None, fit: str = "crop",
           window: tuple[int, int] | None = None, source_size: tuple[int, int] | None = None,
           region: tuple[int, int, int, int] | None = None, light=None) -> np.ndarray:
    """The scene ``source`` as linear RGB at the sensor's ``shape``, (rows, cols, 3), float64.

    With ``window = (row, col)``: the ``shape`` of the source at that corner, at the source's own resolution
    (an image file's pixels; a built-in, the photo included, drawn at ``source_size``, default ``shape``).

    Parameters
    ----------
    source : str
        A built-in (:data:`BUILTINS`) or an image file's path.
    shape : (rows, cols)
        The sensor's size.
    scale : float, optional
        The value that is white in an image file (:func:`load_file`).
    fit : str
        "crop": a picture of another aspect ratio is cropped to the sensor's at its centre; else it is stretched.
    window : (row, col), optional
        The corner of a window at the source's own resolution.
    source_size : (rows, cols), optional
        The size a built-in is drawn at, with ``window``.
    region : (row0, row1, col0, col1), optional
        The rectangle of the sensor to render (a tile): bit for bit that crop of the whole, without making the
        whole (a built-in draws only the region; a picture is resampled only there).
    light : cmosnoise.model.light.ChannelLight, optional
        Light in lux: the values become the colour channels' relative signals (see the module docstring).

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1: ``shape``, or the region's size.
    """
    return prepare(source, shape, scale, fit, window, source_size, light)(region)


def prepare(source: str, shape: tuple[int, int], scale: float | None = None, fit: str = "crop",
            window: tuple[int, int] | None = None, source_size: tuple[int, int] | None = None, light=None,
            raw: tuple | None = None, cells: int = 1):
    """:func:`render` in two steps: the source read (an image file decoded, cropped; a built-in's name checked)
    once, then any region rendered from it. What a sensor made in tiles uses, so that a picture is decoded once,
    not once a tile.

    Parameters
    ----------
    source, shape, scale, fit, window, source_size, light
        As :func:`render` takes them.
    raw : (raw_cfa, raw_black_dn, raw_white_dn), optional
        ``scene``'s keys for a ``.npy`` mosaic (a camera raw carries its own).
    cells : int
        The optical image's fine cells per pixel along each axis (:mod:`.focal_plane`): the scene is drawn on a
        grid ``cells`` times finer than ``shape``, regions in its cells (a picture resampled from its own
        pixels to it, a chart drawn there: the edge's exact area shares, the zone plate's area integrals).

    Returns
    -------
    callable
        ``region -> (rows, cols, 3) float64 array``: :func:`render`'s result for that region (None: the whole),
        a :class:`Resampled` picture or a chart's drawing function.

    Examples
    --------
    >>> from cmosnoise import scene
    >>> draw = scene.prepare("photo", (60, 80))
    >>> part = draw((10, 20, 30, 45))
    >>> part.shape, bool((part == scene.render("photo", (60, 80))[10:20, 30:45]).all())
    ((10, 15, 3), True)
    """
    if isinstance(source, str) and not is_builtin(source) and raw_scene.is_raw(source, (raw or (None,))[0]):
        if cells != 1:
            raise CmosnoiseError(f"scene {source!r} is a raw photograph, already sampled by its camera's pixels: "
                                 f"set optics.oversample to 1 (or auto) for it, not {cells}")
        return RawDraw(raw_scene.read(source, *(raw or ())), tuple(window or (0, 0)), tuple(shape))
    if window is None:
        return _fitted(source, shape, scale, fit, light, cells)
    img = source_image(source, source_size or shape, scale, fit, light)
    _check_window(img.shape, window, shape)  # the whole window must lie in the source (checked, not copied)
    if cells != 1:  # the window's own pixels, the sensor's, resampled to the fine grid
        return Resampled(window_of(img, tuple(window), tuple(shape)), (shape[0] * cells, shape[1] * cells))

    def draw(region=None):
        r0, r1, c0, c1 = _span(shape, region)
        return window_of(img, (window[0] + r0, window[1] + c0), (r1 - r0, c1 - c0))

    return draw


def prepare_configured(source: str, shape: tuple[int, int], section, light=None, cells: int = 1):
    """:func:`prepare` with a configuration's ``scene`` section's settings (its scale, fit, window, source size and
    a ``.npy`` mosaic's raw keys): what a sensor and a tiling draw from.

    Parameters
    ----------
    source : str
        The scene.
    shape : (rows, cols)
        The whole sensor.
    section : SceneSection
        ``config.scene``.
    light : cmosnoise.model.light.ChannelLight, optional
        Light in lux.
    cells : int
        The optical image's fine cells per pixel.

    Returns
    -------
    callable
        As :func:`prepare`.
    """
    return prepare(source, shape, section.scale, section.fit, section.window, section.source_size, light,
                   (section.raw_cfa, section.raw_black_dn, section.raw_white_dn), cells)


def source_image(source: str, size: tuple[int, int], scale: float | None = None, fit: str = "crop",
                 light=None) -> np.ndarray:
    """The whole source, linear RGB (rows, cols, 3) float64: an image file's own pixels, or a built-in (the
    bundled photo included) drawn at ``size``. What :func:`render` takes a window of.

    Parameters
    ----------
    source : str
        A built-in (:data:`BUILTINS`) or an image file's path.
    size : (rows, cols)
        The size a built-in is drawn at.
    scale : float, optional
        The value that is white in an image file (:func:`load_file`).
    fit : str
        "crop": a picture of another aspect ratio is cropped to ``size``'s at its centre; else it is stretched.
    light : cmosnoise.model.light.ChannelLight, optional
        Light in lux (see the module docstring).

    Returns
    -------
    (rows, cols, 3) float64 array
        Linear light, 0 to 1.
    """
    if is_builtin(source):
        return _fitted(source, tuple(size), scale, fit, light)()
    if raw_scene.is_raw(source):  # a mosaic: each pixel's relative signal in its own colour (no light mix)
        return raw_scene.read(source).signal
    return mixed(load_file(source, scale), light)


def window_of(img: np.ndarray, window: tuple[int, int], shape: tuple[int, int]) -> np.ndarray:
    """The ``shape`` of ``img`` at the corner ``window = (row, col)``, float64, or a one-line error where it leaves it.

    Parameters
    ----------
    img : (rows, cols, 3) array
        The whole source (:func:`source_image`).
    window : (row, col)
        The window's corner.
    shape : (rows, cols)
        The window's size.

    Returns
    -------
    (rows, cols, 3) float64 array
    """
    r, c = window
    _check_window(img.shape, window, shape)
    return np.ascontiguousarray(img[r:r + shape[0], c:c + shape[1]], dtype=np.float64)


def window_cfa(img: np.ndarray, window: tuple[int, int], shape: tuple[int, int], pattern: str,
               responsivity=(1.0, 1.0, 1.0)) -> np.ndarray:
    """``to_cfa(window_of(img, window, shape), pattern, responsivity)``, bit for bit, without the window's float64
    copy: each pixel's channel is read from the source where it lies.

    Parameters
    ----------
    img : (rows, cols, 3) array, or (rows, cols)
        The whole source (:func:`source_image`), or a mosaic (relative signal per pixel, returned as it is).
    window : (row, col)
        The window's corner.
    shape : (rows, cols)
        The window's size.
    pattern : str
        RGGB, BGGR, GRBG, GBRG, or none (monochrome).
    responsivity : (float, float, float)
        The R, G and B pixels' relative responsivity.

    Returns
    -------
    (rows, cols) float64 array
        Relative signal per pixel.

    Examples
    --------
    >>> from cmosnoise import scene
    >>> img = scene.source_image("photo", (60, 80))
    >>> a = scene.window_cfa(img, (10, 20), (32, 40), "RGGB")
    >>> bool((a == scene.to_cfa(scene.window_of(img, (10, 20), (32, 40)), "RGGB")).all())
    True
    """
    if img.ndim == 2:  # a mosaic already (a user's clean raw): the window is the signal
        return window_of(img, window, shape)
    if cfa_mod.is_mono(pattern):  # the luminance is a matrix product: on the contiguous window, as there
        return to_cfa(window_of(img, window, shape), pattern, responsivity)
    r, c = window
    _check_window(img.shape, window, shape)
    return to_cfa(np.asarray(img[r:r + shape[0], c:c + shape[1]], dtype=np.float64), pattern, responsivity)


def _check_window(source_shape, window: tuple[int, int], shape: tuple[int, int]) -> None:
    """A one-line error where a ``shape`` window at ``window`` leaves a source of ``source_shape``."""
    r, c = window
    if r + shape[0] > source_shape[0] or c + shape[1] > source_shape[1]:
        raise CmosnoiseError(f"scene.window = [{r}, {c}]: a {shape[0]} x {shape[1]} window there leaves the source "
                             f"({source_shape[0]} x {source_shape[1]}); the corner must be at most "
                             f"[{source_shape[0] - shape[0]}, {source_shape[1] - shape[1]}]")


def mixed(rgb: np.ndarray, light=None) -> np.ndarray:
    """Linear-sRGB reflectances as the colour channels' relative signals under ``light``.

    Parameters
    ----------
    rgb : (rows, cols, 3) array
        Linear sRGB, read as reflectances.
    light : cmosnoise.model.light.ChannelLight, optional
        Its 3 x 3 ``mix`` turns each RGB value into the channels' signals; None: ``rgb`` itself.

    Returns
    -------
    (rows, cols, 3) float64 array
        Each channel's signal relative to a white's.
    """
    if light is None:
        return rgb
    return np.ascontiguousarray(np.asarray(rgb, np.float64) @ light.mix.T)


def _fitted(source: str, shape: tuple[int, int], scale: float | None = None, fit: str = "crop", light=None,
            cells: int = 1):
    """The source at ``shape`` (pixels) on a grid ``cells`` times finer, prepared: a function of a region (fine
    cells; None: the whole) that draws it there."""
    if not isinstance(source, str) or not source:
        raise CmosnoiseError(f"scene.source = {source!r}: give a built-in ({', '.join(BUILTINS)}) or an image path")
    name = source.strip()
    low = name.lower()
    fine = (shape[0] * cells, shape[1] * cells)
    if light is not None and low == "colorchecker":  # the patches' reflectance spectra under the light
        from . import light as light_mod

        wl, refl = light_mod.colorchecker_reflectances()
        values = light.reflectance_channels(refl, wl)
        surround = float(srgb_to_linear(np.array(charts.SURROUND_SRGB8 / 255.0)))
        return lambda region=None: colorchecker(fine, region, values, surround)
    if low.endswith(".npz"):  # a multispectral cube: each pixel's spectrum through the light and each channel's QE
        from . import light as light_mod

        if light is None:
            raise CmosnoiseError(f"scene {name!r} is a multispectral cube of reflectance spectra: it needs light in "
                                 "lux (light.enabled=true, light.illuminance_lux) to be seen through the QE")
        wl, cube = light_mod.read_cube(name)
        if fit == "crop":
            cube = crop_to_aspect(cube, shape)
        return Resampled(np.ascontiguousarray(cube @ light_mod.spectral_channels(light, wl).T), fine)
    if not is_builtin(name) or low == "photo":
        if low == "photo":
            img = load_file(bundled_photo_path())
        else:
            img = load_file(name, scale)
        if fit == "crop":
            img = crop_to_aspect(img, shape)
        return Resampled(mixed(img, light), fine)
    draw = _builtin(name, fine, cells)
    if light is None:
        return draw
    return lambda region=None: mixed(draw(region), light)


def _builtin(name: str, shape: tuple[int, int], cells: int = 1):
    """A built-in scene other than the photo, prepared: a function of a region that draws it (``shape`` and the
    regions in cells, ``cells`` to a pixel)."""
    low = name.lower()
    if low.startswith("flat:") or low == "flat":
        text = name.partition(":")[2]
        if not text.strip():
            raise CmosnoiseError(f"scene {name!r}: give the level, flat:LEVEL with LEVEL in [0, 1] (fraction of the peak rate), "
                                 "e.g. flat:0.5")
        try:
            level = float(text)
        except ValueError:
            raise CmosnoiseError(f"scene 'flat:{text}': LEVEL must be a number in [0, 1]") from None
        if not (0.0 <= level <= 1.0):
            raise CmosnoiseError(f"scene 'flat:{text}': LEVEL = {level:g} is outside [0, 1] (fraction of the peak rate)")
        return lambda region=None: flat(shape, level, region)
    if low == "ramp":
        return lambda region=None: ramp(shape, region)
    if low == "colorchecker":
        return lambda region=None: colorchecker(shape, region)
    if low.startswith("zoneplate"):
        edge_f = charts.zoneplate_frequency(low)
        return lambda region=None: charts.zoneplate(shape, region, edge_f, cells)
    if low == "siemens":
        return lambda region=None: charts.siemens(shape, region=region)
    if low == "spot":
        return lambda region=None: spot(shape, region, cells)
    if low.startswith("edge"):
        angle, lo, hi = charts.edge_parameters(low)
        return lambda region=None: charts.edge(shape, angle, lo, hi, region)
    if low.startswith("greys"):
        n = charts.greys_count(low)
        return lambda region=None: charts.greys(shape, n, region)
    text = name.partition(":")[2] or "4"  # steps
    if not text.isdigit() or not 1 <= int(text) <= 16:
        raise CmosnoiseError(f"scene 'steps:{text}': N must be a whole number of bands from 1 to 16")
    return lambda region=None: steps(shape, int(text), region)


def to_cfa(rgb: np.ndarray, pattern: str, responsivity=(1.0, 1.0, 1.0)) -> np.ndarray:
    """Sample linear RGB (rows, cols, 3) through the CFA: (rows, cols) relative signal.

    Each pixel keeps its own channel times that channel's relative
    responsivity; a monochrome sensor (``pattern='none'``) takes the luminance.

    Parameters
    ----------
    rgb : (rows, cols, 3) array
        Linear light, 0 to 1.
    pattern : str
        RGGB, BGGR, GRBG, GBRG, or none (monochrome).
    responsivity : (float, float, float)
        The R, G and B pixels' relative responsivity.

    Returns
    -------
    (rows, cols) array
        Relative signal per pixel.
    """
    if cfa_mod.is_mono(pattern):
        return rgb @ LUMINANCE
    # each pixel's channel times its responsivity, in one compiled pass (engine/layout.py)
    return layout.cfa_pick(rgb, cfa_mod.tile(pattern), np.asarray(responsivity, dtype=np.float64))


#: the most mean photo-charge a pixel's scene may ask for, e- (a million times a large full well): the frame kernel's
#: samplers and the ADC take any charge up to it; beyond it (or NaN) a scene is refused before any compiled loop runs
MAX_CHARGE_E = 1e12


def check_charge(charge: np.ndarray, full_well_e: float) -> None:
    """Refuse a mean photo-charge that is not finite or exceeds :data:`MAX_CHARGE_E` (a scene of 1e308, a rate
    that overflows), in one line.

    Parameters
    ----------
    charge : array, e-
        The mean photo-charge per pixel (:func:`photo_electrons`).
    full_well_e : float
        The pixel's full well, for the message.

    Raises
    ------
    CmosnoiseError
    """
    top = float(np.max(charge)) if np.size(charge) else 0.0
    if not top <= MAX_CHARGE_E:  # NaN too
        raise CmosnoiseError(f"scene: a pixel's mean charge would be {top:g} e-; give a scene (its values, the light, "
                             f"the integration time) whose charge stays under {MAX_CHARGE_E:g} e- (the full well is "
                             f"{full_well_e:g} e-)")


def photo_electrons(signal: np.ndarray, peak_rate_e_per_s: float, integration_time_s: float) -> np.ndarray:
    """Mean photo-electrons per pixel: ``signal * peak_rate * t_int`` (e-), float32.

    Parameters
    ----------
    signal : (rows, cols) array
        Relative signal per pixel, 0 to 1 (:func:`to_cfa`).
    peak_rate_e_per_s : float
        The photo-electron rate of signal 1, e-/s.
    integration_time_s : float
        The integration time, s.

    Returns
    -------
    (rows, cols) float32 array, e-
    """
    out = np.empty(np.shape(signal), np.float32)  # the float64 product rounded once, without a float64 copy
    return np.multiply(signal, peak_rate_e_per_s * integration_time_s, out=out, casting="same_kind")
