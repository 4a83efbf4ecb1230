"""Raw frames as TIFF: uint16 stacks with the CFA in TIFF/EP tags and JSON metadata."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from ..errors import CmosnoiseError

#: TIFF/EP tags for the colour filter array
TAG_CFA_REPEAT_PATTERN_DIM = 33421
TAG_CFA_PATTERN = 33422
#: TIFF/EP CFA colour codes (0 red, 1 green, 2 blue)
CFA_CODES = {"R": 0, "G": 1, "B": 2}


def cfa_tags(cfa: str) -> list[tuple]:
    """tifffile ``extratags`` for a Bayer pattern's CFARepeatPatternDim and CFAPattern (none for mono)."""
    if cfa == "none":
        return []
    return [
        (TAG_CFA_REPEAT_PATTERN_DIM, "H", 2, (2, 2), True),
        (TAG_CFA_PATTERN, "B", 4, bytes(CFA_CODES[c] for c in cfa), True),
    ]


def raw_metadata(cfa: str, black_level_dn: float, bits: int, gain_dn_per_e: float, **extra) -> dict:
    """The metadata recorded with raw frames (TIFF ImageDescription, JSON)."""
    return {
        "cfa": cfa,
        "black_level_dn": float(black_level_dn),
        "bits": int(bits),
        "white_level_dn": 2**bits - 1,
        "gain_dn_per_e": float(gain_dn_per_e),
        **extra,
    }


def write_raw_tiff(path: str | Path, frames: Iterable[np.ndarray], n: int, shape: tuple[int, int], metadata: dict,
                   dtype: str = "uint16") -> None:
    """Write ``n`` frames of ``shape`` as one (n, rows, cols) TIFF series, frame by frame.

    ``dtype`` is uint16 for raw codes, float32 for the ideal readout (e-, ADC off).

    The CFA pattern also goes into the TIFF/EP ``CFARepeatPatternDim`` and
    ``CFAPattern`` tags so that raw tools can read it.
    """
    import tifffile

    extratags = cfa_tags(metadata.get("cfa", "none"))
    size = n * shape[0] * shape[1] * np.dtype(dtype).itemsize
    with tifffile.TiffWriter(path, bigtiff=size > 2**31) as tw:
        tw.write(
            frames, shape=(n, *shape), dtype=dtype, photometric="minisblack",
            metadata=metadata, extratags=extratags,
        )


def write_float_tiff(path: str | Path, image: np.ndarray, metadata: dict) -> None:
    """A float32 image (e.g. a master dark, DN) with JSON metadata."""
    import tifffile

    tifffile.imwrite(path, image.astype(np.float32), photometric="minisblack", metadata=metadata)


def read_raw_tiff(path: str | Path) -> tuple[np.ndarray, dict]:
    """Read raw frames written by :func:`write_raw_tiff`: (frames, rows, cols) and metadata."""
    import tifffile

    try:
        with tifffile.TiffFile(path) as tf:
            data = tf.asarray()
            meta = dict(tf.shaped_metadata[0]) if tf.shaped_metadata else {}
    except FileNotFoundError:
        raise CmosnoiseError(f"raw file {str(path)!r} does not exist") from None
    except Exception as exc:
        raise CmosnoiseError(f"raw file {str(path)!r} cannot be read as TIFF: {exc}") from None
    meta.pop("shape", None)
    if data.ndim == 2:
        data = data[None]
    return data, meta
