"""DNG output that raw tools (LibRaw, through rawpy) open and decode.

Written with tifffile: a CFA image (PhotometricInterpretation 32803) for a
Bayer sensor, LinearRaw with one sample for a monochrome one, with the CFA
pattern, black and white levels, colour metadata (ColorMatrix1 for D65
and AsShotNeutral) describing the simulated sensor's colour space, and the
shot's settings where given: ExposureTime (33434) and ISOSpeedRatings
(34855) in IFD0, as TIFF/EP puts them (ISO 12234-2, on which DNG builds).
:func:`read_settings` reads them back, from IFD0 or from a camera's EXIF
IFD (where cameras write them), so a folder of a camera's bursts says each
file's ISO and exposure time.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np

from .output import atomic_file
from .raw_tiff import cfa_tags

#: CIE XYZ (D65) to linear sRGB
XYZ_TO_SRGB = np.array(
    [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]]
)


def _rationals(values, signed: bool) -> list[int]:
    out = []
    for v in values:
        f = Fraction(float(v)).limit_denominator(1_000_000)
        num, den = f.numerator, f.denominator
        if not signed:
            num = max(num, 0)
        out += [num, den]
    return out


def camera_matrices(mixing: np.ndarray | None, responsivity=(1.0, 1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """(ColorMatrix1: XYZ -> camera, AsShotNeutral) of a sensor whose filters see linear sRGB.

    The camera's native space is linear sRGB scaled by the channel
    responsivities and mixed by crosstalk (``mixing``). ColorMatrix1 is
    normalised so that the D65 white maps to a maximum channel of 1.
    """
    cam = np.diag(responsivity) @ (mixing if mixing is not None else np.eye(3)) @ XYZ_TO_SRGB
    white_xyz = np.array([0.95047, 1.0, 1.08883])
    neutral = cam @ white_xyz
    cam = cam / neutral.max()
    return cam, neutral / neutral.max()


def write_dng(path: str | Path, raw: np.ndarray, cfa: str, black_level_dn: float, white_level_dn: int,
              mixing: np.ndarray | None = None, responsivity=(1.0, 1.0, 1.0), iso: float | None = None,
              exposure_s: float | None = None) -> None:
    """Write one raw frame (uint16) as a DNG, via a temporary file and rename.

    Parameters
    ----------
    path : str or Path
    raw : ndarray, (rows, cols)
        The codes, DN.
    cfa : str
        The CFA pattern (RGGB, ...) or "none".
    black_level_dn, white_level_dn : float, int
        The codes' black and white levels.
    mixing, responsivity
        The colour metadata's sources (:func:`camera_matrices`).
    iso : float, optional
        The shot's ISO, written as ISOSpeedRatings (a SHORT; above 65535 that value, as EXIF 2.3 does, with the
        whole value as ISOSpeed, 34867).
    exposure_s : float, optional
        The exposure time, s, written as ExposureTime.
    """
    import tifffile

    path = Path(path)
    tags = [
        (50706, 1, 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, 1, 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, 2, 0, "cmosnoise simulated sensor", True),  # UniqueCameraModel
        (50713, 3, 2, (1, 1), True),  # BlackLevelRepeatDim
        (50714, 5, 1, _rationals([black_level_dn], False), True),  # BlackLevel
        (50717, 4, 1, (int(white_level_dn),), True),  # WhiteLevel
    ]
    if exposure_s is not None:
        tags.append((33434, 5, 1, _rationals([exposure_s], False), True))  # ExposureTime
    if iso is not None:
        tags.append((34855, 3, 1, (min(int(round(iso)), 65535),), True))  # ISOSpeedRatings
        if iso > 65535:
            tags.append((34867, 4, 1, (int(round(iso)),), True))  # ISOSpeed
    if cfa != "none":
        cm, neutral = camera_matrices(mixing, responsivity)
        tags += [
            *cfa_tags(cfa),  # CFARepeatPatternDim, CFAPattern
            (50710, 1, 3, (0, 1, 2), True),  # CFAPlaneColor
            (50721, 10, 9, _rationals(cm.ravel(), True), True),  # ColorMatrix1
            (50778, 3, 1, (21,), True),  # CalibrationIlluminant1: D65
            (50728, 5, 3, _rationals(neutral, False), True),  # AsShotNeutral
        ]
    with atomic_file(path) as tmp:
        photometric = 32803 if cfa != "none" else "minisblack"
        tifffile.imwrite(tmp, np.ascontiguousarray(raw, dtype=np.uint16), photometric=photometric,
                         subfiletype=0, extratags=tags, metadata=None, software="cmosnoise")
        if cfa == "none":
            # DNG's monochrome raw is LinearRaw with one sample; tifffile will
            # not write that combination, so the tag is set afterwards
            with tifffile.TiffFile(tmp, mode="r+b") as tif:
                tif.pages[0].tags["PhotometricInterpretation"].overwrite(34892)


def read_settings(path: str | Path) -> tuple[float | None, float | None]:
    """A DNG's (ISO, exposure time in s), each None where the file does not say it.

    Read from IFD0 (as :func:`write_dng` and TIFF/EP put them) or from the
    EXIF IFD a camera writes (ISOSpeedRatings, or its EXIF 2.3 name
    PhotographicSensitivity, with ISOSpeed where that holds the whole value;
    ExposureTime), by tifffile.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (float or None, float or None)
    """
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        found: dict = {}
        for tag in page.tags.values():
            found.setdefault(tag.name, tag.value)
        exif = found.get("ExifTag")
        if isinstance(exif, dict):
            for k, v in exif.items():
                found.setdefault(k, v)
    iso = found.get("ISOSpeed") or found.get("ISOSpeedRatings") or found.get("PhotographicSensitivity")
    if isinstance(iso, (tuple, list)):
        iso = iso[0] if iso else None
    t = found.get("ExposureTime")
    if isinstance(t, (tuple, list)):
        t = t[0] / t[1] if len(t) == 2 and t[1] else None
    iso = float(iso) if isinstance(iso, (int, float)) and iso > 0 else None
    t = float(t) if isinstance(t, (int, float)) and t > 0 else None
    return iso, t
