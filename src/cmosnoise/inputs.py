"""The input gate: every file a command reads passes here before a library sees it.

A file must be a regular file (a FIFO would block, a device such as
``/dev/zero`` never ends, and ``stat`` reports size 0 for both), it is read
with a byte limit that does not trust ``stat``, and an image is bounded by
its total decoded pixels over all its frames and pages, read from its header
before any pixel is decoded.

Every refusal is a :class:`~cmosnoise.errors.CmosnoiseError` whose message
names the file, what it is and what is allowed.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from .errors import CmosnoiseError

#: pixels of one decoded frame or page (400 MP: a 20000 x 20000 sensor), and of a whole file read frame by frame
#: (20 gigapixels: 50 000 frames of 400 kP; beyond that a file is decoding time, not data)
MAX_FRAME_PIXELS = 400_000_000
MAX_STREAM_PIXELS = 20_000_000_000
#: pixels of a file read into memory at once (a dark stack: 2 bytes a pixel as uint16, 8 while averaged)
MAX_LOADED_PIXELS = 500_000_000

__all__ = ["check_regular", "open_regular", "read_bytes", "read_text", "image_planes", "check_image_pixels"]


def _kind(mode: int) -> str:
    if stat.S_ISFIFO(mode):
        return "a pipe (FIFO)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISDIR(mode):
        return "a folder"
    return "not a regular file"


def check_regular(path: str | Path, what: str) -> Path:
    """``path`` if it names a regular file (symbolic links followed); else a one-line error.

    For files a library opens by name (TIFF, PNG, DNG readers): this check
    comes first, so a FIFO never blocks the reader and a device is never read.
    """
    p = Path(path)
    try:
        mode = os.stat(p).st_mode
    except FileNotFoundError:
        raise CmosnoiseError(f"{what} {str(p)!r} does not exist") from None
    except OSError as exc:
        raise CmosnoiseError(f"{what} {str(p)!r} cannot be read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        raise CmosnoiseError(f"{what} {str(p)!r} is {_kind(mode)}; give a regular file")
    return p


def open_regular(path: str | Path, what: str):
    """Open a regular file for binary reading without ever blocking on a FIFO (checked on the open descriptor)."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise CmosnoiseError(f"{what} {str(p)!r} does not exist") from None
    except IsADirectoryError:
        raise CmosnoiseError(f"{what} {str(p)!r} is a folder; give a regular file") from None
    except OSError as exc:
        raise CmosnoiseError(f"{what} {str(p)!r} cannot be read: {exc.strerror or exc}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise CmosnoiseError(f"{what} {str(p)!r} is {_kind(mode)}; give a regular file")
    return os.fdopen(fd, "rb")


def read_bytes(path: str | Path, what: str, limit: int) -> bytes:
    """At most ``limit`` bytes of a regular file; a longer file is refused (its size from reading, not ``stat``)."""
    with open_regular(path, what) as fh:
        try:
            data = fh.read(limit + 1)
        except OSError as exc:
            raise CmosnoiseError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise CmosnoiseError(f"{what} {str(path)!r} is larger than {_size(limit)}; at most {_size(limit)} are read")
    return data


def read_text(path: str | Path, what: str, limit: int) -> str:
    """A UTF-8 text file of at most ``limit`` bytes (see :func:`read_bytes`)."""
    data = read_bytes(path, what, limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise CmosnoiseError(f"{what} {str(path)!r} is not a text file (not UTF-8)") from None


def _size(n: int) -> str:
    return f"{n / 1e9:g} GB" if n >= 1e9 else (f"{n / 1e6:g} MB" if n >= 1e6 else f"{n / 1e3:g} kB")


def image_planes(path: str | Path) -> tuple[int, int, int]:
    """(rows, cols, planes) of an image file from its header alone: planes counts every frame and page.

    ``rows`` and ``cols`` are the largest plane's (a TIFF's pages may differ
    in size), so ``rows * cols * planes`` bounds the decoded pixels of the
    whole file. Raises whatever the header reader raises for a file it cannot
    read.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".npy":
        import numpy as np

        shape = np.load(p, mmap_mode="r", allow_pickle=False).shape
        return _from_shape(tuple(int(x) for x in shape))
    if suffix in (".tif", ".tiff", ".dng"):
        import tifffile

        with tifffile.TiffFile(p) as tf:
            sizes = [(int(getattr(page, "imagelength", 0)),  # page headers only: no pixel is decoded
                      int(getattr(page, "imagewidth", 0)) * max(int(getattr(page, "imagedepth", 1)), 1))
                     for page in tf.pages]
        rows, cols = max(sizes, key=lambda rc: rc[0] * rc[1], default=(0, 0))
        return rows, cols, len(sizes)
    import warnings

    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # our own limit says it better
            with Image.open(p) as im:
                frames = int(getattr(im, "n_frames", 1) or 1)  # APNG: acTL chunk; GIF, multi-page TIFF: headers
                return im.size[1], im.size[0], frames
    except Image.DecompressionBombError:
        return 10**6, 10**6, 1  # beyond any limit
    except Exception:  # a format Pillow does not know: imageio's own header reader
        import imageio.v3 as iio

        props = iio.improps(p)
        shape = tuple(int(x) for x in props.shape)
        if getattr(props, "is_batch", False) and len(shape) >= 3:
            rows, cols, _ = _from_shape(shape[1:])
            return rows, cols, shape[0]
        return _from_shape(shape)


def _from_shape(shape: tuple[int, ...]) -> tuple[int, int, int]:
    """(rows, cols, planes) of an array shape: (rows, cols), (rows, cols, channels) or (planes, rows, cols[, ch])."""
    if len(shape) < 2:
        return (shape[0] if shape else 0), 1, 1
    if len(shape) >= 3 and shape[-1] <= 4:
        shape = shape[:-1]
    planes = 1
    for s in shape[:-2]:
        planes *= s
    return shape[-2], shape[-1], planes


def decoder_message(exc: Exception) -> str:
    """An image decoder's failure in one line; imageio's "Could not find a backend" (with its stray backticks)
    said as what it means."""
    first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    if "Could not find a backend" in first:
        return "no image reader knows its format (give a PNG, JPEG, TIFF or another picture Pillow reads, or a .npy array)"
    return first


def check_image_pixels(path: str | Path, what: str, max_pixels: int, max_plane_pixels: int | None = None,
                       hint: str = "") -> tuple[int, int, int]:
    """Refuse an image whose frames or pages hold more than ``max_pixels`` pixels in all (or one plane more
    than ``max_plane_pixels``), from its header, after :func:`check_regular`; returns (rows, cols, planes).
    ``hint`` ends a refusal for size (what to do instead)."""
    p = check_regular(path, what)
    try:
        rows, cols, planes = image_planes(p)
    except CmosnoiseError:
        raise
    except Exception as exc:
        raise CmosnoiseError(f"{what} {str(p)!r} cannot be read as an image: {decoder_message(exc)}") from None
    if max_plane_pixels is not None and rows * cols > max_plane_pixels:
        raise CmosnoiseError(f"{what} {str(p)!r} has a {cols} x {rows} frame; at most {max_plane_pixels / 1e6:g} "
                             f"megapixels a frame are read{hint}")
    total = rows * cols * planes
    if total > max_pixels:
        many = f" in {planes} frames or pages" if planes > 1 else ""
        raise CmosnoiseError(f"{what} {str(p)!r} is {cols} x {rows} pixels{many} ({total / 1e6:.0f} megapixels "
                             f"decoded); at most {max_pixels / 1e6:g} megapixels are read{hint}")
    return rows, cols, planes
