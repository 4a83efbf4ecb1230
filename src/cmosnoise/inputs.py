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

import numpy as np

from .errors import CmosnoiseError

#: pixels of one decoded frame or page (400 MP: a 20000 x 20000 sensor), and of a whole file read frame by frame
#: (20 gigapixels: 50 000 frames of 400 kP; beyond that a file is decoding time, not data)
MAX_FRAME_PIXELS = 400_000_000
MAX_STREAM_PIXELS = 20_000_000_000
#: pixels of a file read into memory at once (a dark stack: 2 bytes a pixel as uint16, 8 while averaged)
MAX_LOADED_PIXELS = 500_000_000

#: the largest magnitude of a raw code the API takes (a 32-bit sensor's): beyond it float32 arithmetic overflows
MAX_CODE = float(2**32)
#: pages (image file directories, sub-IFDs included) of one TIFF or DNG walked before it is refused: a raw series of
#: 100 000 frames is a long video; 300 000 one-pixel pages are a file built to keep a reader busy
MAX_TIFF_PAGES = 100_000

__all__ = ["check_regular", "open_regular", "read_bytes", "read_text", "read_json", "image_planes", "tiff_planes",
           "check_image_pixels", "available_bytes", "check_memory", "check_decoded", "npz_members",
           "fits_data_bytes", "check_frame", "MAX_TIFF_PAGES"]


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


def _named(path: str | Path, what: str) -> Path:
    """``path`` as a Path; a name no file system takes (a NUL byte in it) is a one-line error, not the
    ``ValueError`` the system call would raise."""
    p = Path(path)
    if "\0" in str(p):
        raise CmosnoiseError(f"{what} {str(p)!r}: a file name cannot hold a NUL byte")
    return p


def check_regular(path: str | Path, what: str) -> Path:
    """``path`` if it names a regular file (symbolic links followed); else a one-line error.

    For files a library opens by name (TIFF, PNG, DNG readers): this check
    comes first, so a FIFO never blocks the reader and a device is never read.
    """
    p = _named(path, what)
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
    p = _named(path, what)
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
        try:  # in pieces: one read of limit + 1 bytes would allocate all of them for a file of a few
            buf = bytearray()
            while len(buf) <= limit:
                part = fh.read(min(1 << 20, limit + 1 - len(buf)))
                if not part:
                    break
                buf += part
        except OSError as exc:
            raise CmosnoiseError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    if len(buf) > limit:
        raise CmosnoiseError(f"{what} {str(path)!r} is larger than {_size(limit)}; at most {_size(limit)} are read")
    return bytes(buf)


def read_text(path: str | Path, what: str, limit: int) -> str:
    """A UTF-8 text file of at most ``limit`` bytes (see :func:`read_bytes`)."""
    data = read_bytes(path, what, limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise CmosnoiseError(f"{what} {str(path)!r} is not a text file (not UTF-8)") from None


def available_bytes() -> int | None:
    """Memory the system can give without swapping (Linux MemAvailable), or None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(need: int, what: str, hint: str = "") -> None:
    """Refuse work that would need ``need`` bytes where the machine has fewer available (one line naming
    ``what`` and both sizes); nothing happens where the available memory is unknown."""
    have = available_bytes()
    if have is not None and need > have:
        raise CmosnoiseError(f"{what} needs about {_size(need)} of memory; this machine has {_size(have)} "
                             f"available{hint}")


def check_decoded(nbytes: int, path: str | Path, what: str, limit: int) -> None:
    """Refuse a file whose header promises more than ``limit`` decoded bytes (or more than the machine's
    available memory), before a byte of it is decoded."""
    if nbytes > limit:
        raise CmosnoiseError(f"{what} {str(path)!r} decodes to {_size(nbytes)}; at most {_size(limit)} are read "
                             "from one file")
    check_memory(nbytes, f"{what} {str(path)!r}")


def npz_members(path: str | Path, what: str, limit: int) -> dict[str, int]:
    """The members of an .npz file and their decoded sizes (bytes) from its zip directory, all checked against
    ``limit`` together before anything is inflated (a zip bomb is refused by what it says it holds; zipfile
    never inflates a member past the size its directory gives)."""
    import zipfile

    p = check_regular(path, what)
    try:
        with zipfile.ZipFile(p) as z:
            members = {i.filename: int(i.file_size) for i in z.infolist()}
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
        raise CmosnoiseError(f"{what} {str(p)!r} is not a readable .npz file: {exc}") from None
    check_decoded(sum(members.values()), p, what, limit)
    return members


def fits_data_bytes(path: str | Path, what: str, limit: int) -> int:
    """Bytes of a FITS file's data units from their headers alone (NAXISn, BITPIX, PCOUNT, GCOUNT), each
    checked against what the file holds (a header promising more than is there is refused) and all against
    ``limit``."""
    p = check_regular(path, what)
    size = os.stat(p).st_size
    total, at = 0, 0
    with open_regular(p, what) as fh:
        while at < size:
            cards, ended = {}, False
            while not ended:  # the header: 2880-byte blocks of 36 cards of 80 characters
                block = fh.read(2880)
                at += len(block)
                if len(block) < 2880:
                    raise CmosnoiseError(f"{what} {str(p)!r}: a FITS header runs past the file's end (a truncated "
                                         "file)")
                for k in range(36):
                    card = block[80 * k:80 * k + 80].decode("ascii", "replace")
                    key = card[:8].strip()
                    if key == "END":
                        ended = True
                        break
                    if card[8:10] == "= ":
                        cards[key] = card[10:].split("/")[0].strip()
                if len(cards) > 100_000:
                    raise CmosnoiseError(f"{what} {str(p)!r}: a FITS header of more than 100 000 cards")
            try:
                naxis = int(cards.get("NAXIS", "0"))
                bits = abs(int(cards.get("BITPIX", "8")))
                n = 1 if naxis else 0
                for i in range(1, naxis + 1):
                    n *= int(cards.get(f"NAXIS{i}", "0"))
                n = (n + int(cards.get("PCOUNT", "0"))) * int(cards.get("GCOUNT", "1"))
            except ValueError:
                raise CmosnoiseError(f"{what} {str(p)!r}: a FITS header with a size that is not a number") from None
            if naxis < 0 or naxis > 999 or n < 0:
                raise CmosnoiseError(f"{what} {str(p)!r}: a FITS header with an impossible size")
            nbytes = n * bits // 8
            decoded = _tile_compressed_bytes(cards, p, what)  # a tile-compressed image decodes to its ZNAXISn
            if decoded is not None:
                total += decoded - nbytes
            padded = -(-nbytes // 2880) * 2880
            if at + nbytes > size:
                raise CmosnoiseError(f"{what} {str(p)!r}: a FITS header promises {_size(nbytes)} of data that the "
                                     "file does not hold (a truncated file)")
            total += nbytes
            if total > limit:
                check_decoded(total, p, what, limit)
            at += padded
            fh.seek(at)
    check_decoded(total, p, what, limit)
    return total


def _tile_compressed_bytes(cards: dict, p: Path, what: str) -> int | None:
    """The decoded bytes of a tile-compressed FITS image (``ZIMAGE = T``: ``ZNAXISn`` by ``ZBITPIX``), or None for
    an ordinary header: its data unit's size is the compressed tiles', not what it decodes to."""
    if cards.get("ZIMAGE", "").strip().upper() not in ("T", "'T'"):
        return None
    try:
        znaxis = int(cards.get("ZNAXIS", "0"))
        zbits = abs(int(cards.get("ZBITPIX", "0")))
        n = 1 if znaxis else 0
        for i in range(1, znaxis + 1):
            n *= int(cards.get(f"ZNAXIS{i}", "0"))
    except ValueError:
        raise CmosnoiseError(f"{what} {str(p)!r}: a tile-compressed FITS header with a size that is not a "
                             "number") from None
    if znaxis < 0 or znaxis > 999 or n < 0 or zbits not in (8, 16, 32, 64):
        raise CmosnoiseError(f"{what} {str(p)!r}: a tile-compressed FITS header with an impossible size")
    return n * zbits // 8


def read_npy(path: str | Path, what: str, limit: int, kinds: str = "uif", max_elements: int | None = None) -> np.ndarray:
    """A ``.npy`` array, read after its header is checked: a regular file, a dtype of the ``kinds`` given (no
    objects, no pickles), non-negative dimensions whose bytes are at most ``limit`` and are all in the file (a
    truncated file is refused before it is read, a sparse one is read only as far as its header says).

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        The key it was given for, named in errors.
    limit : int
        The most bytes the array may hold.
    kinds : str
        The dtype kinds allowed (``numpy.dtype.kind``).
    max_elements : int, optional
        The most elements (what a reader that casts it, to float64 say, will hold).

    Returns
    -------
    ndarray
        The array, read whole.
    """
    from numpy.lib import format as npformat

    p = check_regular(path, what)
    size = os.stat(p).st_size
    with open_regular(p, what) as fh:
        try:
            version = npformat.read_magic(fh)
            if version == (1, 0):
                shape, fortran, dtype = npformat.read_array_header_1_0(fh, max_header_size=10_000)
            else:
                shape, fortran, dtype = npformat.read_array_header_2_0(fh, max_header_size=10_000)
        except (ValueError, OSError, EOFError, SyntaxError) as exc:
            raise CmosnoiseError(f"{what} {str(p)!r} is not a readable .npy file: {exc}") from None
        if dtype.hasobject or dtype.kind not in kinds or dtype.fields is not None:
            raise CmosnoiseError(f"{what} {str(p)!r} holds {dtype}; give an array of "
                                 f"{' or '.join({'u': 'unsigned integers', 'i': 'integers', 'f': 'reals', 'b': 'booleans'}.get(k, k) for k in kinds)}")
        if any((not isinstance(d, int)) or d < 0 for d in shape):
            raise CmosnoiseError(f"{what} {str(p)!r}: an impossible shape {shape}")
        count = int(np.prod(shape, dtype=object))
        nbytes = count * dtype.itemsize
        check_decoded(nbytes, p, what, limit)
        if max_elements is not None and count > max_elements:
            raise CmosnoiseError(f"{what} {str(p)!r}: {count} values; at most {max_elements} are read (each becomes "
                                 f"{limit // max_elements} bytes)")
        if fh.tell() + nbytes > size:
            raise CmosnoiseError(f"{what} {str(p)!r}: its header promises {_size(nbytes)} of data that the file does "
                                 "not hold (a truncated file)")
        data = np.fromfile(fh, dtype=dtype, count=int(np.prod(shape, dtype=object)))
    return data.reshape(shape, order="F" if fortran else "C")


def check_frame(a, name: str, finite: bool = True):
    """``a`` as an array if it is one frame (rows, cols) of at least 2 x 2 integer or real values (every value
    finite where ``finite``); else one :class:`CmosnoiseError` naming ``name``, what it got and what is allowed.
    The API's frames (a raw to process, an output to score) pass here, as a file passes the gate."""
    import numpy as np

    try:
        arr = np.asarray(a)
    except (TypeError, ValueError):
        raise CmosnoiseError(f"{name}: expected an array of codes, got {type(a).__name__}") from None
    if arr.dtype.kind not in "uif":
        raise CmosnoiseError(f"{name}: an array of {arr.dtype}; expected integer or real codes (DN)")
    if arr.ndim != 2 or min(arr.shape) < 2:
        raise CmosnoiseError(f"{name}: an array of shape {arr.shape}; expected one frame (rows, cols), at least 2 x 2")
    if finite and arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise CmosnoiseError(f"{name}: {int((~np.isfinite(arr)).sum())} NaN or infinite values; codes are finite")
    if arr.size and arr.dtype.kind in "if" and (float(arr.max()) > MAX_CODE or float(arr.min()) < -MAX_CODE):
        raise CmosnoiseError(f"{name}: codes from {float(arr.min()):g} to {float(arr.max()):g}; a raw code lies "
                             f"within +-{MAX_CODE:g} DN (32 bits)")
    return arr


def read_json(path: str | Path, what: str, limit: int, kind: type | None = dict):
    """A JSON file of at most ``limit`` bytes, parsed; one line for a file that is not JSON, nested beyond what
    the parser takes, or (``kind``) not a JSON object."""
    import json

    text = read_text(path, what, limit)
    try:
        value = json.loads(text)
    except RecursionError:
        raise CmosnoiseError(f"{what} {str(path)!r} is nested too deeply to read") from None
    except ValueError as exc:
        raise CmosnoiseError(f"{what} {str(path)!r} is not JSON: {exc}") from None
    if kind is not None and not isinstance(value, kind):
        raise CmosnoiseError(f"{what} {str(path)!r} holds a JSON {type(value).__name__}; expected a JSON "
                             f"{'object' if kind is dict else kind.__name__}")
    return value


def _size(n: int) -> str:
    return f"{n / 1e9:g} GB" if n >= 1e9 else (f"{n / 1e6:g} MB" if n >= 1e6 else f"{n / 1e3:g} kB")


def image_planes(path: str | Path, what: str = "image") -> tuple[int, int, int]:
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
    with open_regular(p, what) as fh:
        head = fh.read(4)
    if head[:4] in _TIFF_MAGIC:  # by its bytes, whatever its name: a TIFF named .png is walked as a TIFF
        return tiff_planes(p, what)
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


_TIFF_MAGIC = (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+")
#: bytes of one value of a TIFF field type (BYTE, ASCII, SHORT, LONG, RATIONAL, ..., IFD, LONG8, SLONG8, IFD8)
_TIFF_TYPE_BYTES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4, 16: 8, 17: 8, 18: 8}
_TIFF_INTS = {1: "B", 3: "H", 4: "I", 13: "I", 16: "Q", 18: "Q"}
#: the fields the walk reads: ImageWidth, ImageLength, SubIFDs, ImageDepth
_TIFF_WANTED = frozenset((256, 257, 330, 32997))


def tiff_planes(path: str | Path, what: str) -> tuple[int, int, int]:
    """(rows, cols, planes) of a TIFF or DNG from its chain of image file directories alone.

    The chain is walked by hand (classic and BigTIFF, either byte order,
    sub-IFDs included: a DNG's raw lies in one), each directory read once
    from a read-only map of the file: a chain that loops back on itself, a
    directory past the file's end, or more than :data:`MAX_TIFF_PAGES`
    directories is refused in one line before any library walks it (tifffile
    follows a looping chain for ever). ``rows`` and ``cols`` are the largest
    directory's, ``planes`` their number.
    """
    import mmap
    import struct

    p = Path(path)
    name = f"{what} {str(p)!r}"
    with open_regular(p, what) as fh:
        size = os.fstat(fh.fileno()).st_size
        if size < 8:
            raise CmosnoiseError(f"{name} is not a TIFF file (it is {size} bytes long)")
        m = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    try:
        order = {b"II": "<", b"MM": ">"}.get(m[:2])
        magic = struct.unpack_from(order + "H", m, 2)[0] if order else None
        if magic not in (42, 43):
            raise CmosnoiseError(f"{name} is not a TIFF file (no TIFF header)")
        big = magic == 43
        count_fmt, entry, off_fmt, value_bytes = ("Q", 20, "Q", 8) if big else ("H", 12, "I", 4)
        first = struct.unpack_from(order + off_fmt, m, 8 if big else 4)[0]
        len_next = struct.calcsize(off_fmt)
        seen: set[int] = set()
        sizes: list[tuple[int, int]] = []
        chains = [first]
        while chains:
            off = chains.pop()
            while off:
                if off in seen:
                    raise CmosnoiseError(f"{name}: its chain of pages loops back to an earlier page (a damaged file)")
                if len(seen) >= MAX_TIFF_PAGES:
                    raise CmosnoiseError(f"{name} has more than {MAX_TIFF_PAGES} pages; at most {MAX_TIFF_PAGES} "
                                         "pages of a TIFF are read")
                head = struct.calcsize(count_fmt)
                if off + head > size:
                    raise CmosnoiseError(f"{name}: a page lies past the file's end (a truncated or damaged file)")
                seen.add(off)
                n = struct.unpack_from(order + count_fmt, m, off)[0]
                end = off + head + n * entry + struct.calcsize(off_fmt)
                if end > size:
                    raise CmosnoiseError(f"{name}: a page's {n} fields run past the file's end (a truncated or "
                                         "damaged file)")
                fields: dict[int, list[int]] = {}
                entries = struct.iter_unpack(order + ("HH16x" if big else "HH8x"), m[off + head:end - len_next])
                for k, (tag, typ) in enumerate(entries):
                    if tag not in _TIFF_WANTED or typ not in _TIFF_INTS:
                        continue
                    at = off + head + k * entry
                    cnt = struct.unpack_from(order + ("Q" if big else "I"), m, at + 4)[0]
                    cnt = min(cnt, MAX_TIFF_PAGES + 1)
                    nbytes = cnt * _TIFF_TYPE_BYTES[typ]
                    where = at + 4 + (8 if big else 4)
                    if nbytes > value_bytes:
                        where = struct.unpack_from(order + off_fmt, m, where)[0]
                        if where + nbytes > size:
                            raise CmosnoiseError(f"{name}: a field points past the file's end (a damaged file)")
                    fields[tag] = list(struct.unpack_from(f"{order}{cnt}{_TIFF_INTS[typ]}", m, where))
                width, length = (fields.get(t, [0])[0] for t in (256, 257))
                sizes.append((int(length), int(width) * max(int(fields.get(32997, [1])[0]), 1)))
                chains += [int(v) for v in fields.get(330, [])]  # sub-IFDs: each a chain of its own
                off = struct.unpack_from(order + off_fmt, m, end - struct.calcsize(off_fmt))[0]
    finally:
        m.close()
    rows, cols = max(sizes, key=lambda rc: rc[0] * rc[1], default=(0, 0))
    return rows, cols, len(sizes)


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
        rows, cols, planes = image_planes(p, what)
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
