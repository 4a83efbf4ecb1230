"""Colour error: CIEDE2000 per ColorChecker patch after a 3 x 3 colour matrix fitted by least squares.

A camera's RGB (each patch's mean in each colour channel, linear, black subtracted) is mapped to linear sRGB by
the matrix ``M`` that minimises ``sum |M cam - ref|^2`` over the 24 patches, then each patch is compared with its
reference in CIELAB (sRGB's D65 white, colour-science's conversions) by CIEDE2000
(``colour.delta_E(..., method="CIE 2000")``). About 1 is one just-noticeable difference for colour patches.

The reference (:data:`REFERENCES`):

- ``spectral`` (the default): the chart's own colours, from the same reflectance spectra the simulated chart is
  drawn from (Ohta's ColorChecker, colour-science's "ColorChecker N Ohta"), under the same illuminant, seen by the
  CIE 1931 2 degree observer (colour-science's ``sd_to_XYZ``, the ASTM E308 integration), adapted to D65 by
  Bradford (a camera white-balanced to the scene's white) and expressed in linear sRGB. A camera whose spectral
  sensitivities are a linear combination of the observer's (a Luther camera) then scores 0, whatever the light:
  the error measures the camera, not the reference;
- ``xrite``: X-Rite's published sRGB values (post-2014) of a ColorChecker Classic, decoded to linear: another
  chart's measured colours under D65, which a perfect camera viewing Ohta's chart misses by about 0.7 dE00.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.analysis import colour_error
>>> ref = colour_error.reference_linear_srgb()
>>> cam = ref @ np.array([[0.8, 0.1, 0.0], [0.1, 0.9, 0.1], [0.0, 0.2, 0.7]]).T   # a camera: a linear mix of sRGB
>>> r = colour_error.colour_error(cam, ref)
>>> round(r["mean_de2000"], 6), r["matrix"].shape
(0.0, (3, 3))
"""

from __future__ import annotations

import numpy as np

from ..errors import CmosnoiseError
from ..model import charts
from ..model.encoding import srgb_to_linear

#: the references :func:`reference` gives
REFERENCES = ("spectral", "xrite")
#: the observer and the adaptation of the spectral reference
OBSERVER, ADAPTATION = "CIE 1931 2 Degree Standard Observer", "Bradford"

__all__ = ["reference_linear_srgb", "spectral_reference", "reference", "fit_matrix", "ciede2000", "colour_error",
           "mosaic_patch_means", "REFERENCES"]


def reference_linear_srgb() -> np.ndarray:
    """The ColorChecker's 24 patches in linear sRGB (its published sRGB values decoded), row by row.

    Returns
    -------
    (24, 3) float64 array
    """
    return srgb_to_linear(charts.COLORCHECKER_SRGB8 / 255.0)


def spectral_reference(illuminant: str = "D65") -> np.ndarray:
    """The ColorChecker's 24 patches in linear sRGB from their reflectance spectra under ``illuminant``, seen by
    :data:`OBSERVER` and adapted to D65 by :data:`ADAPTATION` (see the module docstring).

    Parameters
    ----------
    illuminant : str
        As ``light.illuminant`` takes it (a CIE name, ``blackbody:K``, a CSV file).

    Returns
    -------
    (24, 3) float64 array
        Linear sRGB (the illuminant's white 1; a patch outside sRGB's gamut has a negative component).

    Raises
    ------
    CmosnoiseError
        An illuminant without light from 380 to 780 nm (the observer's range): no white to adapt from.
    """
    from .. import colour_lib
    from ..model import light

    colour = colour_lib.colour()
    wl, power = light.illuminant_spectrum(illuminant)
    grid = np.arange(380.0, 781.0, 5.0)
    inside = (grid >= wl[0]) & (grid <= wl[-1])
    if inside.sum() < 2 or not (np.interp(grid[inside], wl, power) > 0).any():
        raise CmosnoiseError(f"colour reference: light.illuminant = {illuminant!r} has no light from 380 to 780 nm "
                             "(the observer's range); the spectral reference cannot be seen under it: give one that "
                             "does, or --colour-reference xrite")
    sd_illuminant = colour.SpectralDistribution(dict(zip(grid, np.interp(grid, wl, power, left=0.0, right=0.0))))
    cmfs = colour.MSDS_CMFS[OBSERVER]
    patches = colour.SDS_COLOURCHECKERS[light.COLORCHECKER_SPECTRA]
    xyz = np.stack([colour.sd_to_XYZ(sd.copy().align(colour.SpectralShape(380, 780, 5)), cmfs, sd_illuminant)
                    for sd in patches.values()]) / 100.0
    white = np.asarray(colour.sd_to_XYZ(colour.sd_ones(colour.SpectralShape(380, 780, 5)), cmfs, sd_illuminant),
                       float) / 100.0
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    d65 = np.asarray(colour.xy_to_XYZ(srgb.whitepoint), float)
    adapt = colour.adaptation.matrix_chromatic_adaptation_VonKries(white, d65, transform=ADAPTATION)
    return (xyz @ np.asarray(adapt, float).T) @ np.asarray(srgb.matrix_XYZ_to_RGB, float).T


def reference(kind: str = "spectral", illuminant: str = "D65") -> np.ndarray:
    """The reference colours :func:`colour_error` compares with.

    Parameters
    ----------
    kind : {"spectral", "xrite"}
        :func:`spectral_reference` under ``illuminant``, or X-Rite's published values (:func:`reference_linear_srgb`).
    illuminant : str
        The scene's illuminant (the spectral reference's).

    Returns
    -------
    (24, 3) float64 array
        Linear sRGB.
    """
    if kind not in REFERENCES:
        raise CmosnoiseError(f"colour reference = {kind!r} is not known; give one of {', '.join(REFERENCES)}")
    return spectral_reference(illuminant) if kind == "spectral" else reference_linear_srgb()


def fit_matrix(camera: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The 3 x 3 matrix M minimising ``sum |M camera_i - reference_i|^2`` (least squares).

    Parameters
    ----------
    camera : (n, 3) array
        The patches' camera RGB, linear.
    reference : (n, 3) array
        Their linear sRGB.

    Returns
    -------
    (3, 3) float64 array
        ``reference ~ camera @ M.T``.
    """
    cam, ref = np.asarray(camera, float), np.asarray(reference, float)
    if cam.shape != ref.shape or cam.ndim != 2 or cam.shape[1] != 3 or cam.shape[0] < 3:
        raise CmosnoiseError(f"colour error: give (n, 3) camera and reference values, n >= 3; got {cam.shape} and "
                             f"{ref.shape}")
    if not (np.isfinite(cam).all() and np.isfinite(ref).all()):
        raise CmosnoiseError("colour error: the patch values must be finite")
    solution, *_ = np.linalg.lstsq(cam, ref, rcond=None)
    return solution.T


def ciede2000(linear_srgb: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """CIEDE2000 between linear sRGB values and their references, through CIELAB under D65.

    Parameters
    ----------
    linear_srgb, reference : (n, 3) arrays
        Linear sRGB (1: white).

    Returns
    -------
    (n,) float64 array
    """
    from .. import colour_lib

    colour = colour_lib.colour()

    def lab(x):
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(np.asarray(x, float), colour.RGB_COLOURSPACES["sRGB"],
                                                   apply_cctf_decoding=False))

    return np.asarray(colour.delta_E(lab(linear_srgb), lab(reference), method="CIE 2000"), float)


def colour_error(camera: np.ndarray, reference: np.ndarray | None = None) -> dict:
    """CIEDE2000 per patch after the least-squares colour matrix (see the module docstring).

    Parameters
    ----------
    camera : (24, 3) array
        The patches' camera RGB means, linear (:func:`mosaic_patch_means`), any scale: the matrix absorbs it.
    reference : (24, 3) array, optional
        Their linear sRGB; default: :func:`reference_linear_srgb` (:func:`reference` gives the spectral one).

    Returns
    -------
    dict
        ``de2000`` (24,) per patch, ``mean_de2000``, ``max_de2000``, ``matrix`` (3, 3), ``corrected`` (24, 3):
        the camera's values through the matrix.
    """
    ref = reference_linear_srgb() if reference is None else np.asarray(reference, float)
    m = fit_matrix(camera, ref)
    corrected = np.asarray(camera, float) @ m.T
    de = ciede2000(corrected, ref)  # outside sRGB's gamut too: CIELAB of the linear values, negatives included
    return {"de2000": de, "mean_de2000": float(de.mean()), "max_de2000": float(de.max()), "matrix": m,
            "corrected": corrected}


def mosaic_patch_means(raw: np.ndarray, pattern: str, patches, black: float = 0.0) -> np.ndarray:
    """Each patch's mean in each colour channel of a raw mosaic, black subtracted: a camera's RGB without
    demosaicing.

    Parameters
    ----------
    raw : (rows, cols) array
        A raw frame (DN or e-).
    pattern : str
        Its CFA pattern (RGGB, BGGR, GRBG, GBRG).
    patches : list of (row0, row1, col0, col1) or (slice, slice)
        The patches (:func:`cmosnoise.model.charts.truth`).
    black : float
        The black level to subtract.

    Returns
    -------
    (n, 3) float64 array
    """
    from ..model import cfa as cfa_mod

    a = np.asarray(raw, float) - black
    channels = cfa_mod.channel_map(pattern, a.shape)
    rows, cols = a.shape
    out = []
    for p in patches:
        r, c = (p if isinstance(p[0], slice) else (slice(p[0], p[1]), slice(p[2], p[3])))
        if not (0 <= (r.start or 0) < (r.stop or rows) <= rows and 0 <= (c.start or 0) < (c.stop or cols) <= cols):
            raise CmosnoiseError(f"colour error: a patch ({r.start}:{r.stop}, {c.start}:{c.stop}) is outside the "
                                 f"{rows} x {cols} image")
        block, ch = a[r, c], channels[r, c]
        out.append([block[ch == k].mean() for k in range(3)])
    return np.asarray(out)
