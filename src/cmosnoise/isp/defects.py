"""Defect correction on the CFA image (docs/model.md section 5).

Two correctors, so users can compare them, and a hook for one's own
(:func:`load_corrector`: ``module:function``, as ``evaluate --method`` and
``processing.defects.corrector`` take it):

- :func:`correct_isolated` is the single-defect corrector of a typical ISP: a
  pixel that lies outside the range of its same-colour neighbours by more
  than a threshold (far from their median, and supported by none of them) is
  replaced by their median. It removes single white pixels. It cannot remove
  a **couplet**: each pixel of the pair has the other among its neighbours,
  which makes its high value look plausible (the paper's Fig. 9 point).
- :func:`correct_with_map` replaces the pixels of a defect map (from the
  master dark) by the median of their non-defective same-colour neighbours,
  which removes couplets too.

Same-colour neighbours are those of :mod:`cmosnoise.cfa` (8 per pixel).
Edges reflect, which keeps the CFA phase.

Examples
--------
>>> import numpy as np
>>> from cmosnoise import defects
>>> dark = np.zeros((8, 8)); dark[3, 4] = 500.0   # one hot pixel in a master dark's signal
>>> np.argwhere(defects.defect_map(dark, threshold_dn=100.0)).tolist()
[[3, 4]]
"""

from __future__ import annotations

import importlib
import inspect
import sys
from collections.abc import Callable

import numpy as np

from ..errors import CmosnoiseError
from ..estimators import robust_sigma
from ..model import cfa as cfa_mod


def load_corrector(spec: str, name: str = "processing.defects.corrector") -> Callable[[np.ndarray, dict], np.ndarray]:
    """One's own corrector or denoiser, ``module:function``, as a callable ``(raw, meta) -> output``.

    The function takes a raw frame (rows, cols) in DN, black level included, and returns one of its shape:
    ``f(raw)``, or ``f(raw, meta)`` with ``meta`` a dict that holds at least ``cfa`` (the pattern),
    ``black_level_dn`` and ``white_level_dn`` (``evaluate`` gives each sample's settings). The module is imported
    as ``python -m`` finds one: the current folder first.

    Parameters
    ----------
    spec : str
        ``module:function`` (``mypkg.fix:correct``).
    name : str
        The option or key the spec came from, for the message.

    Returns
    -------
    callable
        ``(raw, meta) -> output``.

    Raises
    ------
    CmosnoiseError
        ``spec`` is not ``module:function``, does not import, or is not callable.
    """
    module, _, attr = str(spec).partition(":")
    if not module or not attr:
        raise CmosnoiseError(f"{name} {spec!r}: expected module:function (a callable raw -> raw, or raw, meta -> "
                             "raw)")
    if "" not in sys.path:
        sys.path.insert(0, "")  # a module in the current folder, as `python -m` finds it
    try:
        fn = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise CmosnoiseError(f"{name} {spec!r}: cannot load it ({type(exc).__name__}: {exc})") from None
    if not callable(fn):
        raise CmosnoiseError(f"{name} {spec!r} is not callable")
    try:
        takes_meta = len(inspect.signature(fn).parameters) >= 2
    except (TypeError, ValueError):
        takes_meta = False
    return (lambda raw, meta: fn(raw, meta)) if takes_meta else (lambda raw, meta: fn(raw))



def run_corrector(fn: Callable[[np.ndarray, dict], np.ndarray], raw: np.ndarray, meta: dict, what: str) -> np.ndarray:
    """``fn(raw, meta)`` (a :func:`load_corrector` callable) as float64, checked: what it raises or a result of
    another shape is one :class:`CmosnoiseError` that starts with ``what`` (the method or key it came from).

    Parameters
    ----------
    fn : callable
        ``(raw, meta) -> output``.
    raw : ndarray, (rows, cols)
        Its input, DN.
    meta : dict
        Its settings.
    what : str
        Names the corrector in the message (``method 'mine:fix' on sample 3``).

    Returns
    -------
    ndarray, (rows, cols) float64
    """
    try:
        out = np.asarray(fn(raw, meta), np.float64)
    except CmosnoiseError:
        raise
    except Exception as exc:
        raise CmosnoiseError(f"{what} failed: {type(exc).__name__}: {exc}") from None
    if out.shape != raw.shape:
        raise CmosnoiseError(f"{what} returned shape {out.shape}; the raw frame is {raw.shape}")
    return out

def _offsets(pattern: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(R/B or mono offsets, G offsets or None) as arrays (8, 2)."""
    if cfa_mod.is_mono(pattern):
        return np.array(cfa_mod.MONO_NEIGHBOURS), None
    return np.array(cfa_mod.RB_NEIGHBOURS), np.array(cfa_mod.G_NEIGHBOURS)


def _neighbour_views(img: np.ndarray, pattern: str, step: int = 1):
    """The 8 same-colour neighbours of every ``step``-th row, one (rows', cols) array at a time."""
    rows, cols = img.shape
    pad = np.pad(img, 2, mode="reflect")
    rb, g = _offsets(pattern)
    green = None if g is None else (cfa_mod.channel_map(pattern, img.shape) == 1)[::step]
    for q in range(8):
        view_rb = pad[2 + rb[q, 0]: 2 + rb[q, 0] + rows: step, 2 + rb[q, 1]: 2 + rb[q, 1] + cols]
        if green is None:
            yield view_rb
        else:
            view_g = pad[2 + g[q, 0]: 2 + g[q, 0] + rows: step, 2 + g[q, 1]: 2 + g[q, 1] + cols]
            yield np.where(green, view_g, view_rb)


def neighbours(img: np.ndarray, pattern: str) -> np.ndarray:
    """The 8 same-colour neighbours of every pixel: array (8, rows, cols).

    Parameters
    ----------
    img : (rows, cols) array
        A CFA image, DN.
    pattern : str
        RGGB, BGGR, GRBG or GBRG, or none.

    Returns
    -------
    (8, rows, cols) array
        Mirrored at the edges.
    """
    return np.stack(list(_neighbour_views(img, pattern)))


def neighbours_at(img: np.ndarray, pattern: str, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The 8 same-colour neighbours of the pixels (r, c) only: array (8, len(r)).

    Parameters
    ----------
    img : (rows, cols) array
        A CFA image, DN.
    pattern : str
        RGGB, BGGR, GRBG or GBRG, or none.
    r, c : (n,) int arrays
        The pixels' rows and columns.

    Returns
    -------
    (8, n) array
    """
    pad = np.pad(img, 2, mode="reflect")
    rb, g = _offsets(pattern)
    offs = np.broadcast_to(rb[:, None, :], (8, len(r), 2)).copy()
    if g is not None:
        green = cfa_mod.channel_map(pattern, img.shape)[r, c] == 1
        offs[:, green] = g[:, None, :]
    return pad[2 + r[None] + offs[..., 0], 2 + c[None] + offs[..., 1]]


def correct_isolated(img: np.ndarray, pattern: str, threshold_sigma: float = 6.0,
                     threshold_dn: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Replace pixels outside their neighbours' range by more than the threshold.

    The threshold is ``threshold_dn`` if given, else ``threshold_sigma``
    times the robust spread of (pixel - neighbour median), estimated on
    every 4th row. Returns (corrected image, mask of replaced pixels).

    Parameters
    ----------
    img : (rows, cols) array
        A CFA image, DN.
    pattern : str
        RGGB, BGGR, GRBG or GBRG, or none.
    threshold_sigma : float
        The threshold in robust standard deviations.
    threshold_dn : float, optional
        The threshold in DN instead.

    Returns
    -------
    (corrected, replaced) : ((rows, cols) array, (rows, cols) bool array)
        The image with the outliers replaced by their neighbours' median, and which pixels were.
    """
    if threshold_dn is None:
        sample = img[::4] - np.median(np.stack(list(_neighbour_views(img, pattern, step=4))), axis=0)
        threshold_dn = threshold_sigma * robust_sigma(sample)
    hi = lo = None
    for v in _neighbour_views(img, pattern):  # running max and min: one frame-sized array at a time, not eight
        hi = v.copy() if hi is None else np.maximum(hi, v, out=hi)
        lo = v.copy() if lo is None else np.minimum(lo, v, out=lo)
    mask = (img > hi + threshold_dn) | (img < lo - threshold_dn)
    del hi, lo
    out = img.copy()
    r, c = np.nonzero(mask)
    out[r, c] = np.median(neighbours_at(img, pattern, r, c), axis=0)
    return out, mask


def defect_map(master_dark_signal: np.ndarray, threshold_sigma: float = 6.0, threshold_dn: float | None = None) -> np.ndarray:
    """Defective (leaky) pixels of a master dark (signal above black, DN): bool map.

    A pixel is defective if it exceeds the median by more than
    ``threshold_dn``, or by ``threshold_sigma`` times the dark's robust spread.

    Parameters
    ----------
    master_dark_signal : (rows, cols) array, DN
        A master dark's signal above black.
    threshold_sigma : float
        The threshold in robust standard deviations above the median.
    threshold_dn : float, optional
        The threshold in DN above the median instead.

    Returns
    -------
    (rows, cols) bool array
    """
    med = float(np.median(master_dark_signal))
    thr = threshold_dn if threshold_dn is not None else threshold_sigma * robust_sigma(master_dark_signal)
    return master_dark_signal > med + thr


def correct_with_map(img: np.ndarray, pattern: str, defects: np.ndarray) -> np.ndarray:
    """Replace mapped defects by the median of their non-defective same-colour neighbours.

    A defect whose 8 neighbours are all defective keeps its value.

    Parameters
    ----------
    img : (rows, cols) array
        A CFA image, DN.
    pattern : str
        RGGB, BGGR, GRBG or GBRG, or none.
    defects : (rows, cols) bool array
        The defect map (:func:`defect_map`).

    Returns
    -------
    (rows, cols) array
        The image with its defects replaced.
    """
    out = img.copy()
    r, c = np.nonzero(defects)
    if len(r) == 0:
        return out
    vals = neighbours_at(img, pattern, r, c).astype(np.float64)
    vals[neighbours_at(defects, pattern, r, c)] = np.nan
    ok = np.isfinite(vals).any(axis=0)
    out[r[ok], c[ok]] = np.nanmedian(vals[:, ok], axis=0)
    return out
