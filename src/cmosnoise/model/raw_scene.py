"""A raw photograph as the scene: a camera's mosaic, black subtracted and scaled, its colour-filter phase kept.

A camera raw (a DNG, or any format LibRaw reads through rawpy: NEF, CR2, ARW, ...) or a 2-D ``.npy`` mosaic with
``scene.raw_cfa`` set becomes the perfect image's relative signal, pixel for pixel:

    signal = max(raw - black, 0) / (white - black)

with ``black`` the black level of each pixel's cell of the 2 x 2 pattern and ``white`` the white level (a
``.npy``'s from ``scene.raw_black_dn`` and ``scene.raw_white_dn``, the array's maximum by default). The signal is
already through the photograph's colour filters: it is used at its own resolution (the sensor's size, or a
``scene.window`` of it at an even corner), on a sensor of the same CFA pattern, without a channel responsivity,
a light mix or a lens (the photograph went through its own). So a photograph taken at ISO 100 is shot again on
another sensor, at another gain, in less light: ``exposure`` (or ``light``) sets how many electrons its white is.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.model import raw_scene
>>> photo = raw_scene.from_array(np.array([[64, 1088], [576, 4095]]), "RGGB", black=64, white=4095)
>>> photo.pattern
'RGGB'
>>> [round(float(v), 4) for v in photo.signal.ravel()]
[0.0, 0.254, 0.127, 1.0]
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError
from . import cfa as cfa_mod

#: camera raw formats: a mosaic of codes above a black level (read through rawpy / LibRaw)
RAW_SUFFIXES = (".dng", ".nef", ".nrw", ".cr2", ".cr3", ".crw", ".arw", ".srf", ".sr2", ".raf", ".orf", ".rw2",
                ".pef", ".srw", ".3fr", ".erf", ".kdc", ".mos", ".mrw", ".x3f", ".iiq", ".raw")
#: the largest raw file read, bytes (a 150 MP 16-bit raw is 300 MB)
MAX_RAW_BYTES = 1_000_000_000

__all__ = ["RawPhoto", "is_raw", "read", "from_array", "RAW_SUFFIXES"]


@dataclass(frozen=True, eq=False)
class RawPhoto:
    """A raw photograph as a scene.

    Parameters
    ----------
    signal : (rows, cols) float64 array
        Relative signal per pixel, 0 to 1 (1: the white level).
    pattern : str
        Its CFA pattern at (0, 0): RGGB, BGGR, GRBG or GBRG.
    black : (2, 2) float64 array
        The black level of each cell of the pattern, DN.
    white : float
        The white level, DN.
    """

    signal: np.ndarray
    pattern: str
    black: np.ndarray
    white: float

    def window(self, corner: tuple[int, int], shape: tuple[int, int], pattern: str) -> np.ndarray:
        """The ``shape`` of the signal at ``corner``, checked against a sensor's ``pattern`` and size.

        Parameters
        ----------
        corner : (row, col)
            The window's top-left pixel in the photograph.
        shape : (rows, cols)
            The sensor's (or its window's) size.
        pattern : str
            The sensor's CFA.

        Returns
        -------
        (rows, cols) float64 array, a view
        """
        r, c = corner
        rows, cols = self.signal.shape
        if r + shape[0] > rows or c + shape[1] > cols:
            raise CmosnoiseError(f"scene: the raw photograph is {rows} x {cols} pixels; a {shape[0]} x {shape[1]} "
                                 f"sensor at [{r}, {c}] leaves it. A raw scene is used at its own resolution: set "
                                 f"sensor.height={rows} and sensor.width={cols}, or take a scene.window of it")
        seen = cfa_mod.crop_pattern(self.pattern, r, c)
        if pattern != seen:
            raise CmosnoiseError(f"scene: the raw photograph's colour filters are {seen} there, the sensor's "
                                 f"sensor.cfa is {pattern}: set sensor.cfa={seen} (a mosaic keeps its colours)")
        return self.signal[r:r + shape[0], c:c + shape[1]]


def from_array(codes: np.ndarray, pattern: str, black=0.0, white: float | None = None) -> RawPhoto:
    """A raw photograph from its codes.

    Parameters
    ----------
    codes : (rows, cols) array
        The mosaic, DN.
    pattern : str
        Its CFA pattern at (0, 0).
    black : float or (2, 2) array
        The black level, DN (one, or one per cell of the pattern).
    white : float, optional
        The white level, DN; default: the codes' maximum.

    Returns
    -------
    RawPhoto
    """
    a = np.asarray(codes)
    if a.ndim != 2 or a.dtype.kind not in "uif" or min(a.shape) < 2:
        raise CmosnoiseError(f"scene: a raw mosaic is one 2-D array of codes; this is {a.shape} {a.dtype}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        raise CmosnoiseError("scene: the raw mosaic has NaN or infinite codes")
    if pattern not in cfa_mod.BAYER_PATTERNS:
        raise CmosnoiseError(f"scene: a raw photograph needs a Bayer pattern ({', '.join(cfa_mod.BAYER_PATTERNS)}); "
                             f"got {pattern!r}")
    cells = np.broadcast_to(np.asarray(black, np.float64), (2, 2)).copy()
    top = float(a.max()) if white is None else float(white)
    if not (top > cells.max()):
        raise CmosnoiseError(f"scene: the white level ({top:g} DN) must be above the black level ({cells.max():g} DN)")
    rows, cols = a.shape
    b = np.tile(cells, ((rows + 1) // 2, (cols + 1) // 2))[:rows, :cols]
    signal = np.clip(a - b, 0.0, None) / (top - b)
    signal.setflags(write=False)
    return RawPhoto(signal, pattern, cells, top)


def is_raw(path: str | Path, raw_cfa: str | None = None) -> bool:
    """Whether a scene file is a raw photograph: a camera raw's suffix, a TIFF with DNG tags or a CFA mosaic, or a
    ``.npy`` when ``scene.raw_cfa`` is given.

    Parameters
    ----------
    path : str or Path
    raw_cfa : str, optional
        ``scene.raw_cfa``.

    Returns
    -------
    bool
    """
    p = Path(path)
    if p.suffix.lower() in RAW_SUFFIXES:
        return True
    if p.suffix.lower() == ".npy":
        return raw_cfa is not None
    try:
        with inputs.open_regular(p, "scene") as fh:
            tiff = fh.read(4) in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+")
    except CmosnoiseError:
        return False
    if not tiff:
        return False
    import tifffile

    try:
        with tifffile.TiffFile(p) as tf:
            page = tf.pages.first
            return "DNGVersion" in page.tags or int(page.photometric) in (32803, 34892)
    except Exception:  # the decoder's own refusal comes when the picture is read
        return False


def read(path: str | Path, raw_cfa: str | None = None, raw_black_dn: float = 0.0,
         raw_white_dn: float | None = None) -> RawPhoto:
    """Read a raw photograph (rawpy for camera raws, NumPy for a ``.npy`` mosaic), through the input gate.

    Parameters
    ----------
    path : str or Path
    raw_cfa, raw_black_dn, raw_white_dn
        A ``.npy`` mosaic's pattern and levels (``scene.raw_cfa``, ...); a camera raw carries its own.

    Returns
    -------
    RawPhoto

    Raises
    ------
    CmosnoiseError
        Not readable, no Bayer colour filter array (a Foveon, an X-Trans or a linear DNG), too large.
    """
    p = inputs.check_regular(path, "scene")
    st = p.stat()
    # a command checks its scene before any work and reads it again to draw it: one decode, kept while the file is
    # the same (its size and modification time)
    return _read(str(p.resolve()), st.st_size, st.st_mtime_ns, raw_cfa, raw_black_dn, raw_white_dn)


@functools.lru_cache(maxsize=2)
def _read(path: str, size: int, mtime_ns: int, raw_cfa, raw_black_dn, raw_white_dn) -> RawPhoto:
    """:func:`read` of a checked file (its size and time are the cache's key, not read here)."""
    p = Path(path)
    if p.suffix.lower() == ".npy":
        if raw_cfa is None:
            raise CmosnoiseError(f"scene {str(path)!r}: a .npy mosaic needs scene.raw_cfa (its pattern at (0, 0))")
        # the header's size, as the float64 mosaic it becomes (a sparse file of few bytes on disk is no smaller)
        codes = inputs.read_npy(p, "scene", MAX_RAW_BYTES, kinds="uif", max_elements=MAX_RAW_BYTES // 8)
        return from_array(codes, raw_cfa, raw_black_dn, raw_white_dn)
    if size > MAX_RAW_BYTES:
        raise CmosnoiseError(f"scene {str(path)!r}: {size} bytes; a raw photograph is read up to "
                             f"{MAX_RAW_BYTES} bytes")
    import rawpy

    try:
        with rawpy.imread(str(p)) as r:
            codes = np.array(r.raw_image_visible)
            desc = r.color_desc.decode("ascii", "replace")
            pat = r.raw_pattern
            black = np.asarray(r.black_level_per_channel, np.float64)
            white = float(r.white_level)
    except (rawpy.LibRawError, OSError, ValueError) as exc:
        raise CmosnoiseError(f"scene {str(path)!r}: not a raw photograph LibRaw reads ({type(exc).__name__})") from None
    if pat is None or np.asarray(pat).shape != (2, 2) or len(desc) < 3:
        raise CmosnoiseError(f"scene {str(path)!r}: this raw has no 2 x 2 Bayer colour filter array (a monochrome, "
                             "Foveon, X-Trans or linear DNG); a raw scene needs one")
    pattern = "".join("G" if desc[i] in "GG" else desc[i] for i in np.asarray(pat).reshape(-1))
    if pattern not in cfa_mod.BAYER_PATTERNS:
        raise CmosnoiseError(f"scene {str(path)!r}: its colour filters {pattern!r} are not a Bayer pattern")
    cells = black[np.asarray(pat)] if black.size == 4 else np.full((2, 2), float(black.reshape(-1)[0]))
    return from_array(codes, pattern, cells, white)
