"""Raw frames as TIFF: uint16 stacks with the CFA in TIFF/EP tags and JSON metadata."""

from __future__ import annotations

import contextlib
import errno
import io
import mmap
import os
import queue
import threading
from collections.abc import Iterable
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError

#: TIFF/EP tags for the colour filter array
TAG_CFA_REPEAT_PATTERN_DIM = 33421
TAG_CFA_PATTERN = 33422
#: TIFF/EP CFA colour codes (0 red, 1 green, 2 blue)
CFA_CODES = {"R": 0, "G": 1, "B": 2}
#: where a tiled raw's tiles start (:func:`create_tiled_raw_tiff`): the alignment ``O_DIRECT`` asks of a write's
#: offset, length and buffer on Linux (a memory page; a multiple of any disk's logical block)
DIRECT_ALIGN = 4096


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
                   shape: tuple[int, int], metadata: dict, dtype: str = "uint16", tile: int | None = None,
                   align: int = 16) -> None:
    """Write ``n`` frames of ``shape`` as one (n, rows, cols) TIFF series, frame by frame, to the file ``path``
    (or an open binary file).

    ``dtype`` is uint16 for raw codes, float32 for the ideal readout (e-, ADC off). With ``tile`` (a multiple of
    16), the TIFF is tiled and ``frames`` yields its tiles instead, each frame's row by row (those at the right
    and bottom edges cut; the TIFF pads them). ``frames`` None: every page's place is kept and nothing written
    in it (:func:`create_tiled_raw_tiff`). Each page's image data starts at a multiple of ``align`` bytes
    (tifffile's ``align``; its own default, 16, unless asked).

    The CFA pattern also goes into the TIFF/EP ``CFARepeatPatternDim`` and
    ``CFAPattern`` tags so that raw tools can read it.
    """
    import tifffile

    extratags = cfa_tags(metadata.get("cfa", "none"))
    size = n * shape[0] * shape[1] * np.dtype(dtype).itemsize
    with tifffile.TiffWriter(path, bigtiff=size > 2**31) as tw:
        tw.write(
            frames, shape=(n, *shape), dtype=dtype, photometric="minisblack",
            metadata=metadata, extratags=extratags, tile=None if tile is None else (tile, tile), align=align,
        )


def create_tiled_raw_tiff(path: str | Path, n: int, shape: tuple[int, int], metadata: dict, dtype: str,
                          tile: int) -> np.ndarray:
    """A tiled raw TIFF of ``n`` frames whose tiles are all in place but not yet written: the file
    :func:`write_raw_tiff` makes (the same tags and layout, each page's tiles from a multiple of
    :data:`DIRECT_ALIGN` bytes), its tiles' bytes left as holes (zeros when read; a sparse file where the file
    system has them: nothing written for them), for :class:`TileWriter` to fill in any order.

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
        write_raw_tiff(fh, None, n, shape, metadata, dtype, tile=tile, align=DIRECT_ALIGN)
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


class TileWriter:
    """Writes tiles into a raw TIFF laid out by :func:`create_tiled_raw_tiff`, around the page cache where it can.

    Each tile is copied into a page-aligned buffer of this writer's (an edge tile padded with zeros to the full
    tile, as TIFF stores it) and written from there. Where the system has ``O_DIRECT`` (Linux), the file system
    takes it and a tile's bytes are a multiple of :data:`DIRECT_ALIGN` (uint16 tiles whose side is a multiple of
    64, float32 ones of 32), it goes to the file directly, not through the page cache. Copying a 400 MP frame's
    800 MB into the page cache took this project's 2-core machine some 1.2 to 1.5 s of system time a frame
    (``perf``: mostly ``copy_folio_from_iter_atomic``; a 4-frame run's system time 7.4 s, 1.3 to 2.8 s direct;
    see ``docs/sensor/large-sensors.md``; 12 % of that run's CPU time: ``docs/performance.md``). Anywhere else,
    or where the file system refuses a direct write (``EINVAL``), or at an offset off the :data:`DIRECT_ALIGN`
    grid, through the page cache: the same bytes.

    Parameters
    ----------
    path : str or Path
        A file laid out by :func:`create_tiled_raw_tiff`.
    tile : int
        Its tile side.
    dtype : str or numpy.dtype
        Its pixels' type ("uint16" or "float32").
    direct : bool
        Try ``O_DIRECT`` (False: always through the page cache).

    Examples
    --------
    >>> import numpy as np, tempfile, tifffile
    >>> from pathlib import Path
    >>> from cmosnoise.io.raw_tiff import TileWriter, create_tiled_raw_tiff
    >>> from cmosnoise.model.tiles import grid
    >>> path = Path(tempfile.mkdtemp()) / "raw.tiff"
    >>> offsets = create_tiled_raw_tiff(path, 1, (100, 70), {"cfa": "RGGB", "bits": 12}, "uint16", 64)
    >>> frame = np.arange(7000, dtype=np.uint16).reshape(100, 70)
    >>> with TileWriter(path, 64, "uint16") as out:  # 4 tiles of 64 x 64, 3 of them cut at the edges
    ...     for t, (r0, r1, c0, c1) in enumerate(grid(frame.shape, 64)):
    ...         out.write(int(offsets[0, t]), frame[r0:r1, c0:c1])
    >>> bool(np.array_equal(tifffile.imread(path)[0], frame))  # frame 0 of a stack of 1
    True
    """

    def __init__(self, path: str | Path, tile: int, dtype, direct: bool = True):
        self._path = path
        dtype = np.dtype(dtype)
        self._map = mmap.mmap(-1, tile * tile * dtype.itemsize)  # page-aligned, as O_DIRECT asks
        self._stage = np.frombuffer(self._map, dtype).reshape(tile, tile)
        self._fd = _open_direct(path) if direct and len(self._map) % DIRECT_ALIGN == 0 else -1
        #: whether the tiles go to the file directly (False: through the page cache)
        self.direct = self._fd >= 0
        if not self.direct:
            self._fd = os.open(path, _WRITE)

    def write(self, offset: int, data: np.ndarray) -> None:
        """Write one tile's pixels, (rows, cols) with rows, cols <= the tile side, at ``offset``."""
        rows, cols = data.shape
        if (rows, cols) != self._stage.shape:
            self._stage[...] = 0
        self._stage[:rows, :cols] = data
        if self.direct and offset % DIRECT_ALIGN:  # not laid out for it (create_tiled_raw_tiff aligns every tile)
            self._buffered()
        try:
            _pwrite_all(self._fd, memoryview(self._map), offset)
        except OSError as exc:
            if not (self.direct and exc.errno == errno.EINVAL):
                raise
            self._buffered()  # the file system opened the file so but refuses the write
            _pwrite_all(self._fd, memoryview(self._map), offset)

    def _buffered(self) -> None:
        """Through the page cache from now on."""
        os.close(self._fd)
        self._fd, self.direct = os.open(self._path, _WRITE), False

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
        if self._map is not None:
            self._stage = None
            self._map.close()
            self._map = None

    def __enter__(self) -> TileWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def create_raw_tiff(path: str | Path, n: int, shape: tuple[int, int], metadata: dict, dtype: str) -> int:
    """A raw TIFF of ``n`` frames (not tiled) with every frame's place kept but not yet written: the file
    :func:`write_raw_tiff` makes (the same tags), its pixels from a multiple of :data:`DIRECT_ALIGN` bytes and
    left as holes, for :class:`SeriesWriter` to fill frame after frame.

    Parameters
    ----------
    path, n, shape, metadata, dtype
        As :func:`create_tiled_raw_tiff`'s.

    Returns
    -------
    int
        The byte offset of frame 0's pixels; frame k's follow at ``k * rows * cols * itemsize`` after them
        (tifffile lays a series' pages out back to back).
    """
    import tifffile

    with _HolesForZeros(path) as fh:
        write_raw_tiff(fh, None, n, shape, metadata, dtype, align=DIRECT_ALIGN)
    with tifffile.TiffFile(path) as tf:
        offset = tf.series[0].dataoffset
    if offset is None:  # pragma: no cover - tifffile keeps an uncompressed series contiguous
        raise RuntimeError(f"{path}: tifffile did not lay the {n} frames out back to back")
    return int(offset)


class SeriesWriter:
    """Writes the frames of a raw TIFF laid out by :func:`create_raw_tiff`, one after another, from a thread of
    its own and around the page cache where it can.

    :meth:`write` hands a frame over and returns (it waits only while ``depth`` frames are still being
    written): the writing runs beside the caller's next frame. The writer's thread copies each frame's bytes,
    up to :data:`CHUNK` at a time, into a page-aligned buffer behind what is left of the frame before it and
    writes every whole :data:`DIRECT_ALIGN`-byte block with ``O_DIRECT`` where the system and the file system
    take it (as :class:`TileWriter`); the last few bytes of the series, and everything where direct writing is
    refused, go through the page cache: the same bytes either way. A 1920 x 1080 frame's 4 MB took this
    project's 2-core machine 5 to 11 ms to copy into the page cache (``simulate``'s frame loop, measured), a
    third of a frame; written directly from here, the disk takes them while the next frame is made.

    Parameters
    ----------
    path : str or Path
        A file laid out by :func:`create_raw_tiff`.
    offset : int
        Its frame 0's byte offset (what :func:`create_raw_tiff` returns).
    shape : (rows, cols)
        A frame's.
    dtype : str or numpy.dtype
        Its pixels' type ("uint16" or "float32").
    direct : bool
        Try ``O_DIRECT`` (False: always through the page cache).
    depth : int
        Frames handed over and not yet written, at most (each is held until written).

    Examples
    --------
    >>> import numpy as np, tempfile, tifffile
    >>> from pathlib import Path
    >>> from cmosnoise.io.raw_tiff import SeriesWriter, create_raw_tiff
    >>> path = Path(tempfile.mkdtemp()) / "raw.tiff"
    >>> frames = np.arange(3 * 100 * 70, dtype=np.uint16).reshape(3, 100, 70)
    >>> offset = create_raw_tiff(path, 3, (100, 70), {"cfa": "RGGB", "bits": 12}, "uint16")
    >>> with SeriesWriter(path, offset, (100, 70), "uint16") as out:
    ...     for frame in frames:
    ...         out.write(frame)
    >>> bool(np.array_equal(tifffile.imread(path), frames))
    True
    """

    #: the most bytes of a frame written at once (the buffer's size): a 50 MP frame's 100 MB in 13 writes
    CHUNK = 8 << 20

    def __init__(self, path: str | Path, offset: int, shape: tuple[int, int], dtype, direct: bool = True,
                 depth: int = 2):
        self._path = path
        self._frame = (tuple(shape), np.dtype(dtype))
        size = min(shape[0] * shape[1] * np.dtype(dtype).itemsize, self.CHUNK)
        self._map = mmap.mmap(-1, -(-(size + DIRECT_ALIGN) // DIRECT_ALIGN) * DIRECT_ALIGN)  # page-aligned
        self._stage = np.frombuffer(self._map, np.uint8)
        self._held = 0  # bytes at the buffer's start not written yet (the last frame's tail)
        self._at = offset  # where the buffer's start goes in the file
        self._fd = _open_direct(path) if direct and offset % DIRECT_ALIGN == 0 else -1
        #: whether the frames go to the file directly (False: through the page cache)
        self.direct = self._fd >= 0
        self._cached = os.open(path, _WRITE)  # the series' last bytes (and all of it where not direct)
        self._error: BaseException | None = None  # the writer's thread's, until raised in the caller's
        self._failed = False  # whether the thread stopped writing (it lets the frames still handed over go)
        self._queue: queue.Queue = queue.Queue(max(1, depth))
        self._thread = threading.Thread(target=self._run, name="cmosnoise-raw-writer", daemon=True)
        self._thread.start()

    def write(self, frame: np.ndarray) -> None:
        """Hand over the next frame, (rows, cols) of the series' shape and type; it must not change until
        written (the caller's frames are fresh arrays)."""
        if (frame.shape, frame.dtype) != self._frame:
            raise ValueError(f"frame {frame.shape} {frame.dtype}: this series holds {self._frame[0]} "
                             f"{self._frame[1]}")
        self._raise()
        self._queue.put(frame)

    def _raise(self) -> None:
        """Raise the writer's thread's error (once)."""
        error, self._error = self._error, None
        if error is not None:
            raise error

    def _run(self) -> None:
        while (frame := self._queue.get()) is not None:
            if not self._failed:
                try:
                    self._append(np.ascontiguousarray(frame).reshape(-1).view(np.uint8))
                except BaseException as exc:  # noqa: BLE001 - raised in the caller's thread
                    self._error = exc.with_traceback(None)  # its frames held views of the buffer
                    self._failed = True

    def _append(self, data: np.ndarray) -> None:
        """Write a frame's bytes after those held, a buffer's worth at a time."""
        room = self._stage.size - DIRECT_ALIGN  # what follows the held bytes (fewer than DIRECT_ALIGN)
        for start in range(0, data.size, room):
            self._write(data[start:start + room])

    def _write(self, data: np.ndarray) -> None:
        end = self._held + data.size
        self._stage[self._held:end] = data
        whole = end - end % DIRECT_ALIGN if self.direct else end
        if whole:
            try:
                _pwrite_all(self._fd if self.direct else self._cached, memoryview(self._map)[:whole], self._at)
            except OSError as exc:
                if not (self.direct and exc.errno == errno.EINVAL):
                    raise
                self.direct = False  # the file system opened the file so but refuses the write
                whole = end
                _pwrite_all(self._cached, memoryview(self._map)[:whole], self._at)
        self._stage[:end - whole] = self._stage[whole:end]
        self._held, self._at = end - whole, self._at + whole

    def close(self) -> None:
        """Write what is left and close the file; raise what went wrong in the writer's thread."""
        if self._map is None:
            return
        self._queue.put(None)
        self._thread.join()
        try:
            if not self._failed and self._held:
                _pwrite_all(self._cached, memoryview(self._map)[:self._held], self._at)
                self._held = 0
        finally:
            for fd in (self._fd, self._cached):
                if fd >= 0:
                    os.close(fd)
            self._fd = self._cached = -1
            self._stage = None
            self._map.close()
            self._map = None
        self._raise()

    def __enter__(self) -> SeriesWriter:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
            return
        with contextlib.suppress(Exception):  # the caller's error is the one that counts
            self.close()


def _open_direct(path: str | Path) -> int:
    """``path`` opened for writing with ``O_DIRECT``, or -1 where the system has no such flag or the file system
    refuses it (``EINVAL``)."""
    flag = getattr(os, "O_DIRECT", 0)
    if not flag:
        return -1
    try:
        return os.open(path, _WRITE | flag)
    except OSError as exc:
        if exc.errno != errno.EINVAL:  # a file system without O_DIRECT refuses it so
            raise
        return -1


#: how the writers open a file: for writing, in binary mode (Windows translates line ends without O_BINARY)
_WRITE = os.O_WRONLY | getattr(os, "O_BINARY", 0)


def _pwrite_all(fd: int, view: memoryview, offset: int) -> None:
    """All of ``view`` at ``offset`` (pwrite may write less than asked). Where the system has no ``pwrite``
    (Windows), a seek and a write: each writer writes its descriptor from one thread."""
    pwrite = getattr(os, "pwrite", None)
    done = 0
    while done < len(view):
        if pwrite is not None:
            done += pwrite(fd, view[done:], offset + done)
        else:
            os.lseek(fd, offset + done, os.SEEK_SET)
            done += os.write(fd, view[done:])


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
