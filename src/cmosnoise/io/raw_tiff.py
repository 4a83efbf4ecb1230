"""Raw frames as TIFF: uint16 stacks with the CFA in TIFF/EP tags and JSON metadata."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import BinaryIO, Iterable

import numpy as np

from .. import inputs
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


def write_raw_tiff(path: str | Path | BinaryIO, frames: Iterable[np.ndarray] | None, n: int,
                   shape: tuple[int, int], metadata: dict, dtype: str = "uint16", tile: int | None = None) -> None:
    """Write ``n`` frames of ``shape`` as one (n, rows, cols) TIFF series, frame by frame, to the file ``path``
    (or an open binary file).

    ``dtype`` is uint16 for raw codes, float32 for the ideal readout (e-, ADC off). With ``tile`` (a multiple of
    16), the TIFF is tiled and ``frames`` yields its tiles instead, each frame's row by row (those at the right
    and bottom edges cut; the TIFF pads them). ``frames`` None: every page's place is kept and nothing written
    in it (:func:`create_tiled_raw_tiff`).

    The CFA pattern also goes into the TIFF/EP ``CFARepeatPatternDim`` and
    ``CFAPattern`` tags so that raw tools can read it.
    """
    import tifffile

    extratags = cfa_tags(metadata.get("cfa", "none"))
    size = n * shape[0] * shape[1] * np.dtype(dtype).itemsize
    with tifffile.TiffWriter(path, bigtiff=size > 2**31) as tw:
        tw.write(
            frames, shape=(n, *shape), dtype=dtype, photometric="minisblack",
            metadata=metadata, extratags=extratags, tile=None if tile is None else (tile, tile),
        )


def create_tiled_raw_tiff(path: str | Path, n: int, shape: tuple[int, int], metadata: dict, dtype: str,
                          tile: int) -> np.ndarray:
    """A tiled raw TIFF of ``n`` frames whose tiles are all in place but not yet written: the file
    :func:`write_raw_tiff` makes (the same tags and layout), its tiles' bytes left as holes (zeros when read; a
    sparse file where the file system has them: nothing written for them), for :func:`write_tile` to fill in any
    order.

    How a tiled run writes each tile's frames as they are made: with several frames, frame-major writing would
    hold or spool every tile's frames until the last tile of the first frame is made.

    Parameters
    ----------
    path : str or Path
    n : int
        Frames (pages).
    shape : (rows, cols)
    metadata : dict
        As :func:`write_raw_tiff`'s.
    dtype : str
        "uint16" or "float32".
    tile : int
        The tile side, a multiple of 16.

    Returns
    -------
    (n, tiles) int64 array
        Byte offset of each frame's tiles in the file, the tiles row by row.
    """
    import tifffile

    with _HolesForZeros(path) as fh:  # tifffile writes an empty tiled page's tiles as zeros: holes here
        write_raw_tiff(fh, None, n, shape, metadata, dtype, tile=tile)
    with tifffile.TiffFile(path) as tf:
        return np.array([page.dataoffsets for page in tf.pages], np.int64)


class _HolesForZeros(io.FileIO):
    """A file opened for writing in which a long block of zeros is skipped, not written: a hole, which reads as
    zeros (the file system stores nothing there, or zeros where it has no holes).

    tifffile writes an empty tiled page by writing each tile's bytes of zeros (``bytes(n)``, the same object
    every tile); handed this file, it lays out a 400 MP, 4-frame raw in milliseconds where writing 3.2 GB of zeros
    took some 3 s, before the first tile was made. The file ends where the last write or hole ends.
    """

    #: blocks shorter than this are written (headers, tags): checking them would cost more than writing
    MIN_HOLE = 1 << 16

    def __init__(self, path: str | Path):
        super().__init__(path, "wb")
        self._zeros: bytes | None = None  # the last block found to be zeros (tifffile passes the same one)
        self._end = 0  # where the furthest hole ends (written bytes extend the file by themselves)

    def write(self, b) -> int:
        if not (isinstance(b, bytes) and len(b) >= self.MIN_HOLE and (b is self._zeros or b == bytes(len(b)))):
            return super().write(b)
        self._zeros = b
        self._end = max(self._end, self.seek(len(b), os.SEEK_CUR))
        return len(b)

    def close(self) -> None:
        if not self.closed and os.fstat(self.fileno()).st_size < self._end:
            self.truncate(self._end)  # a hole at the end: the file is extended to it (with zeros, stored as none)
        super().close()


def write_tile(fd: int, offset: int, data: np.ndarray, tile: int) -> None:
    """Write one tile's pixels, (rows, cols) with rows, cols <= ``tile``, at ``offset`` of an open file made by
    :func:`create_tiled_raw_tiff` (an edge tile padded with zeros to the full tile, as TIFF stores it)."""
    if data.shape != (tile, tile):
        padded = np.zeros((tile, tile), data.dtype)
        padded[:data.shape[0], :data.shape[1]] = data
        data = padded
    view = memoryview(np.ascontiguousarray(data)).cast("B")
    done = 0
    while done < len(view):  # pwrite may write less than asked
        done += os.pwrite(fd, view[done:], offset + done)


def write_float_tiff(path: str | Path, image: np.ndarray, metadata: dict) -> None:
    """A float32 image (e.g. a master dark, DN) with JSON metadata."""
    import tifffile

    tifffile.imwrite(path, image.astype(np.float32), photometric="minisblack", metadata=metadata)


def read_raw_tiff(path: str | Path, what: str = "raw file") -> tuple[np.ndarray, dict]:
    """Read raw frames written by :func:`write_raw_tiff`: (frames, rows, cols) and metadata.

    The whole file is read into memory, so it is bounded first, from its
    header, by :data:`cmosnoise.inputs.MAX_LOADED_PIXELS` (``what`` names the
    file in messages: "raw file", "dark file").
    """
    import tifffile

    inputs.check_image_pixels(path, what, inputs.MAX_LOADED_PIXELS, inputs.MAX_FRAME_PIXELS)
    try:
        with tifffile.TiffFile(path) as tf:
            data = tf.asarray()
            meta = dict(tf.shaped_metadata[0]) if tf.shaped_metadata else {}
    except Exception as exc:
        raise CmosnoiseError(f"{what} {str(path)!r} cannot be read as TIFF: {' '.join(str(exc).split())[:200]}") from None
    meta.pop("shape", None)
    if data.ndim == 2:
        data = data[None]
    return data, meta


class RawTiffReader:
    """Raw frames of a TIFF, one at a time: ``len(reader)`` frames of ``reader.shape`` (rows, cols), ``reader.meta``.

    For files of any size (``cmosnoise process`` streams them): only the
    header is read on opening. The first series must be (rows, cols) or
    (frames, rows, cols) of one sample per pixel; an RGB picture is refused.
    Use as a context manager.
    """

    def __init__(self, path: str | Path):
        import tifffile

        self.name = str(path)
        # a regular file, no frame larger than a sensor, not endless: from the header, before a frame is decoded
        inputs.check_image_pixels(path, "raw file", inputs.MAX_STREAM_PIXELS, inputs.MAX_FRAME_PIXELS)
        try:
            self._tf = tifffile.TiffFile(path)
        except Exception as exc:
            raise CmosnoiseError(f"raw file {self.name!r} cannot be read as TIFF: {' '.join(str(exc).split())[:200]}") from None
        try:
            self._check()
        except BaseException:
            self._tf.close()
            raise

    def _check(self) -> None:
        tf = self._tf
        if not tf.series:
            raise CmosnoiseError(f"raw file {self.name!r} holds no image")
        series = tf.series[0]
        page = tf.pages[0]
        if getattr(page, "samplesperpixel", 1) != 1:
            raise CmosnoiseError(f"raw file {self.name!r} is a {page.samplesperpixel}-sample (RGB) picture of shape "
                                 f"{series.shape}; raw frames have one CFA sample per pixel")
        shape = tuple(int(x) for x in series.shape)
        if len(shape) == 2:
            shape = (1, *shape)
        if len(shape) != 3 or shape[1] < 2 or shape[2] < 2:
            raise CmosnoiseError(f"raw file {self.name!r}: shape {series.shape} is not raw frames; expected (rows, cols) "
                                 "or (frames, rows, cols)")
        self.dtype = np.dtype(series.dtype)
        if self.dtype not in (np.uint8, np.uint16):
            raise CmosnoiseError(f"raw file {self.name!r}: pixel type {self.dtype} is not raw data; expected uint8 or "
                                 "uint16 codes")
        self.frames, self.shape = shape[0], shape[1:]
        self._pages = len(tf.pages)
        meta = dict(tf.shaped_metadata[0]) if tf.shaped_metadata else {}
        meta.pop("shape", None)
        self.meta = meta

    def __len__(self) -> int:
        return self.frames

    def frame(self, k: int) -> np.ndarray:
        """Frame ``k`` as uint16 (rows, cols)."""
        try:
            if self._pages >= self.frames:  # one page per frame (as cmosnoise writes them)
                data = self._tf.pages[k].asarray()
            else:  # one page holding every frame
                data = self._tf.series[0].asarray()[k]
        except Exception as exc:
            raise CmosnoiseError(f"raw file {self.name!r}, frame {k}, cannot be read: {' '.join(str(exc).split())[:200]}") from None
        return np.asarray(data).reshape(self.shape).astype(np.uint16, copy=False)

    def __iter__(self):
        for k in range(self.frames):
            yield self.frame(k)

    def close(self) -> None:
        self._tf.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
