"""DNG output that raw tools (LibRaw, through rawpy) open and decode.

Written with tifffile: a CFA image (PhotometricInterpretation 32803) for a
Bayer sensor, LinearRaw with one sample for a monochrome one, with the CFA
pattern, black and white levels, and colour metadata (ColorMatrix1 for D65
and AsShotNeutral) describing the simulated sensor's colour space.
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
              mixing: np.ndarray | None = None, responsivity=(1.0, 1.0, 1.0)) -> None:
    """Write one raw frame (uint16) as a DNG, via a temporary file and rename."""
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
