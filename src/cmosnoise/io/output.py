"""Writing results: an output folder that appears whole or not at all.

Everything is written into a temporary folder beside the target and moved
into place only when the run has succeeded, so an error never leaves a
half-written output behind, and an existing folder is replaced as a whole
(with ``--overwrite``) or not at all.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import os
import shutil
import socket
import tempfile
from pathlib import Path

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError, Terminated, check_terminated, note_written, on_hard_exit, signals_deferred

_logger = logging.getLogger(__name__)  # cmosnoise.*: the command line shows it on stderr (app/logs.said)

#: names of the helpers beside an output folder: a run's temporary folder, the old folder being replaced, the lock
_TMP, _OLD, _LOCK = ".cmosnoise-tmp-", ".cmosnoise-old-", ".cmosnoise-lock-"


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def _helper_name(kind: str) -> str:
    """The prefix of a helper folder of this process: KIND-HOST-PID- (HOST without dashes)."""
    return f"{kind}{socket.gethostname().replace('-', '_')}-{os.getpid()}-"


def _helper_owner(name: str) -> tuple[str, int] | None:
    """(host, pid) of a helper's name ``.cmosnoise-KIND-HOST-PID-random``; None for other names."""
    parts = name.split("-")
    try:
        return parts[2], int(parts[3])
    except (IndexError, ValueError):
        return None


class FolderLock:
    """An exclusive lock (``flock``) on an output folder, in a file beside it: one cmosnoise run per folder.

    ``with FolderLock(out, anchor, option):``; a second run gets a one-line
    error naming the holder. The lock file is removed on release; one left by
    a killed run is removed by the next run beside it (:func:`remove_stale_locks`).
    """

    def __init__(self, out: Path, anchor: Path, option: str = "--out"):
        self.out, self.anchor, self.option = Path(out), Path(anchor), option
        self._fh = None

    @property
    def path(self) -> Path:
        digest = hashlib.sha1(str(self.out.resolve()).encode()).hexdigest()[:16]
        return self.anchor / f"{_LOCK}{digest}"

    def acquire(self) -> None:
        import fcntl

        for _ in range(20):
            fh = open(self.path, "a+")  # noqa: SIM115 - held open as long as the lock: release() closes it
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                fh.seek(0)
                holder = fh.read().strip() or "another process"
                fh.close()
                raise CmosnoiseError(f"{self.option} {str(self.out)!r} is being written by another cmosnoise run "
                                     f"({holder}); wait for it to finish or choose another folder") from None
            try:  # the file we locked must still be the lock: a run that released it unlinked it meanwhile
                same = os.stat(self.path).st_ino == os.fstat(fh.fileno()).st_ino
            except FileNotFoundError:
                same = False
            if same:
                fh.seek(0)
                fh.truncate()
                fh.write(f"pid {os.getpid()} on {socket.gethostname()}")
                fh.flush()
                self._fh = fh
                return
            fh.close()
        raise CmosnoiseError(f"{self.option} {str(self.out)!r}: its lock keeps changing hands; try again")

    def release(self) -> None:
        if self._fh is not None:
            with contextlib.suppress(OSError):
                self.path.unlink()
            self._fh.close()
            self._fh = None

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()
        return False


def remove_stale_locks(anchor: Path) -> None:
    """Lock files beside outputs whose run was killed (nobody holds them): removed."""
    import fcntl

    for item in anchor.iterdir():
        if not item.name.startswith(_LOCK) or not item.is_file():
            continue
        try:
            with open(item, "a+") as fh:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                item.unlink()  # under its lock: a run that opened it meanwhile sees another inode and retries
        except OSError:
            continue


def check_folder_name(out: Path, option: str) -> None:
    """A one-line error for an output name the file system cannot hold (too long), before anything runs (a path
    with such a name makes even ``Path.exists`` raise)."""
    anchor = Path(os.path.abspath(out)).parent
    while not os.path.isdir(anchor):  # os.path.isdir is False, never an error, for a name too long
        anchor = anchor.parent
    try:
        name_max = os.pathconf(anchor, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    for part in out.parts:
        if len(part.encode()) > name_max:
            raise CmosnoiseError(f"{option} {str(out)!r}: the name {part[:40]!r}... is {len(part.encode())} bytes long; "
                                 f"this file system takes names of at most {name_max}")


class OutputFolder:
    """Context manager: ``with OutputFolder(out) as tmp: write into tmp``; on success ``tmp`` becomes ``out``, whole.

    The rule for an existing ``out``: an empty folder is replaced; a
    non-empty one is refused unless ``overwrite``, and then replaced as a
    whole (the old one is moved aside and removed only after the new one is
    in place), never merged. ``out`` must not be the current folder or
    contain it. While a run writes, a lock (:class:`FolderLock`) beside
    ``out`` stops a second run on the same folder with a clear message. On an
    exception (Ctrl-C, SIGTERM and SIGHUP included, see
    :mod:`cmosnoise.app.cli`) the temporary folder is removed and ``out`` is
    untouched.

    The replacement is made recoverable: the temporary folder
    ``.cmosnoise-tmp-HOST-PID-*`` holds the results in ``out/`` and, once they
    are complete, a file ``target`` naming the destination; the old folder
    goes to ``.cmosnoise-old-HOST-PID-*/out`` with its own ``target``. A run
    killed between the two renames (``out`` missing) is repaired by the next
    run beside it: the completed results, else the old folder, are put back
    in place, and it says so. Helpers of killed runs that hold nothing to
    restore are removed (and listed), and so are lock files nobody holds.

    Nothing is created before ``__enter__``: a run that fails on its inputs
    leaves nothing behind.
    """

    def __init__(self, out: str | Path, overwrite: bool = False, option: str = "--out"):
        self.option = option
        text = str(out)
        if text.strip() in ("", "."):
            raise CmosnoiseError(f"{option} {text!r}: give a new folder's name (for example {option} results); "
                                 "the current folder itself is never written into")
        self.out = Path(out)
        self.overwrite = overwrite
        check_folder_name(self.out, option)
        resolved = self.out.resolve()
        cwd = Path.cwd().resolve()
        if resolved == cwd or resolved in cwd.parents:
            raise CmosnoiseError(f"{option} {text!r} is the current folder or contains it; give a new folder's name")
        if self.out.exists() and not self.out.is_dir():
            raise CmosnoiseError(f"{option} {text!r} is a file; give a folder to write the results into")
        anchor = resolved.parent
        while not anchor.exists():
            anchor = anchor.parent
        if not anchor.is_dir():
            raise CmosnoiseError(f"{option} {text!r} cannot be written: {str(anchor)!r} is a file, not a folder")
        if not os.access(anchor, os.W_OK | os.X_OK):
            raise CmosnoiseError(f"{option} {text!r} cannot be written: no permission to create anything in {str(anchor)!r}")
        self.anchor = anchor
        self._check_existing()
        self.tmp: Path | None = None
        self._wrapper: Path | None = None
        self.lock = FolderLock(self.out, anchor, option)  #: the folder's lock, for writers that write in place
        self.removed_stale: list[str] = []
        self.restored: list[str] = []

    def check_space(self, needed: int) -> None:
        """A one-line refusal when the file system ``out`` goes to has less free space than ``needed`` bytes."""
        try:
            usage = shutil.disk_usage(self.anchor)
        except OSError:
            return  # unknown: the write itself will say
        if usage.total == 0:  # a pseudo file system (/sys, /proc) reports no size: the write itself will say
            return
        if needed > usage.free:
            raise CmosnoiseError(f"{self.option} {str(self.out)!r}: this run writes about {needed / 1e9:.2f} GB; the "
                                 f"file system of {str(self.anchor)!r} has {usage.free / 1e9:.2f} GB free (fewer "
                                 "--frames, a smaller sensor, or another place)")

    def _check_existing(self) -> None:
        if self.out.is_dir() and not self.overwrite and any(self.out.iterdir()):
            raise CmosnoiseError(f"{self.option} {str(self.out)!r} already exists and is not empty; give --overwrite to "
                                 "replace it as a whole, or another folder")

    def _remove_stale(self) -> None:
        """Helpers of runs on this machine whose process is gone (killed): what they can restore is put back
        where its destination is missing; the rest removed. Both listed on stderr."""
        host = socket.gethostname().replace("-", "_")
        dead = []
        for item in self.anchor.iterdir():
            owner = _helper_owner(item.name)
            if (item.name.startswith(_TMP) or item.name.startswith(_OLD)) and item.is_dir() and owner \
                    and owner[0] == host and not _pid_alive(owner[1]):
                dead.append(item)
        # completed results first: where both a run's new results and the folder they replaced survive, the new win
        for item in sorted(dead, key=lambda i: not i.name.startswith(_TMP)):
            target_file, results = item / "target", item / "out"
            if target_file.is_file() and results.is_dir():
                target = Path(target_file.read_text())
                if not target.exists() and not target.is_symlink() and target.parent.is_dir():
                    os.rename(results, target)
                    what = "the completed results" if item.name.startswith(_TMP) else "the previous results"
                    self.restored.append(f"{what} of an interrupted run into {str(target)!r}")
            shutil.rmtree(item, ignore_errors=True)
            if not item.exists():
                self.removed_stale.append(str(item))
        remove_stale_locks(self.anchor)
        for line in self.restored:
            _logger.warning(f"restored {line}")
        if self.removed_stale:
            _logger.info(f"removed {len(self.removed_stale)} temporary folder(s) left by interrupted runs: "
                      + ", ".join(self.removed_stale))

    def __enter__(self) -> Path:
        try:
            self.lock.acquire()
            try:
                self._remove_stale()
                self._check_existing()  # again, under the lock: a run may have finished (or been restored) meanwhile
                self._wrapper = Path(tempfile.mkdtemp(prefix=_helper_name(_TMP), dir=self.anchor))
                os.chmod(self._wrapper, 0o700)
                self.tmp = self._wrapper / "out"
                wrapper, lock = self._wrapper, self.lock

                def hard_exit():  # what a signal's watchdog does before it ends the process: nothing left behind
                    shutil.rmtree(wrapper, ignore_errors=True)
                    lock.release()

                on_hard_exit(id(self), hard_exit)
                self.tmp.mkdir(mode=0o777 & ~_umask())
            except BaseException:
                on_hard_exit(id(self))
                if self._wrapper is not None:
                    shutil.rmtree(self._wrapper, ignore_errors=True)
                self.lock.release()
                raise
        except OSError as exc:
            raise CmosnoiseError(f"{self.option} {str(self.out)!r} cannot be written: {exc.strerror or exc}") from None
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        try:
            return self._finish(exc_type)
        finally:
            on_hard_exit(id(self))

    def _finish(self, exc_type):
        try:
            if exc_type is None:
                try:  # an interrupt whose exception a library swallowed still means: no output
                    check_terminated()
                except Terminated:
                    shutil.rmtree(self._wrapper, ignore_errors=True)
                    raise
            if exc_type is not None:
                shutil.rmtree(self._wrapper, ignore_errors=True)
                return False
            old = None
            target = str(Path(os.path.abspath(self.out)))
            # a signal during the renames is acted on after them, not between them
            with signals_deferred():
                try:
                    _write_marker(self._wrapper / "target", target)  # complete: from here on, a kill is recoverable
                    if self.out.exists():  # empty, or --overwrite: moved aside, removed once the new one is in place
                        old = Path(tempfile.mkdtemp(prefix=_helper_name(_OLD), dir=self.out.resolve().parent))
                        _write_marker(old / "target", target)
                        os.rename(self.out, old / "out")
                    self.out.parent.mkdir(parents=True, exist_ok=True)
                    try:
                        os.rename(self.tmp, self.out)
                    except OSError:
                        if old is not None:
                            os.rename(old / "out", self.out)  # put the old one back
                        raise
                except OSError as exc:
                    shutil.rmtree(self._wrapper, ignore_errors=True)
                    raise CmosnoiseError(f"{self.option} {str(self.out)!r} cannot be written: {exc.strerror or exc}") from None
                finally:
                    if old is not None:
                        shutil.rmtree(old, ignore_errors=True)
            note_written(self.out)
            shutil.rmtree(self._wrapper, ignore_errors=True)
            return False
        finally:
            self.lock.release()


def _write_marker(path: Path, text: str) -> None:
    """A small file written whole (a temporary name, then a rename)."""
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(text)
    os.replace(tmp, path)


@contextlib.contextmanager
def atomic_file(path: str | Path):
    """Yield a temporary path beside ``path``; rename it to ``path`` on success, remove it on error."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private (0600); the result is an ordinary file
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


#: pictures of at least this many pixels are encoded in row bands on every core (:func:`png_bands`)
BANDED_PNG_PIXELS = 4_000_000


def png_bytes(image: np.ndarray, compress_level: int = 6) -> bytes:
    """An 8-bit picture (rows, cols) or (rows, cols, 3|4) as PNG bytes.

    Pillow directly, with the format named: it loads its five common plugins, not all 45 of them, as imageio's
    Pillow plugin does (0.2 s of every run). A picture of :data:`BANDED_PNG_PIXELS` or more goes to
    :func:`png_bands` instead: Pillow's encoder runs on one core (3.8 s for a 50 MP preview at level 1).
    """
    image = np.ascontiguousarray(image)
    if image.shape[0] * image.shape[1] >= BANDED_PNG_PIXELS and image.dtype == np.uint8:
        return png_bands(image, compress_level)
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG", compress_level=compress_level)
    return buf.getvalue()


def png_bands(image: np.ndarray, compress_level: int = 1, workers: int | None = None) -> bytes:
    """An 8-bit picture as PNG bytes, its rows deflated in bands on every core.

    The PNG is the standard one (8-bit grey, RGB or RGBA; every row with filter type 2, "Up": its bytes less
    the row above's, which NumPy makes at once); the image data is one zlib stream whose deflate blocks come from
    independent compressors, one a band of rows, each ended by a full flush (byte-aligned, its window reset) but
    the last, and the Adler-32 of all the filtered rows. ``zlib`` releases the GIL while it compresses, so the
    bands run in threads. Why not Pillow: its encoder is one thread with adaptive filters, 3.8 s for a 50 MP
    preview here; this is a fraction of it, some files a few percent larger. The tests decode the result with
    Pillow and imageio.

    Parameters
    ----------
    image : (rows, cols) or (rows, cols, 3|4) uint8 array
        The picture.
    compress_level : int
        zlib's level, 0 to 9.
    workers : int, optional
        Threads (default: the core count).

    Returns
    -------
    bytes
        The PNG file.

    Examples
    --------
    >>> import io
    >>> import numpy as np
    >>> from PIL import Image
    >>> from cmosnoise.io.output import png_bands
    >>> picture = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    >>> bool((np.asarray(Image.open(io.BytesIO(png_bands(picture)))) == picture).all())
    True
    """
    import struct
    import zlib
    from concurrent.futures import ThreadPoolExecutor

    image = np.ascontiguousarray(image, dtype=np.uint8)
    rows, cols = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    colour = {1: 0, 3: 2, 4: 6}[channels]
    flat = image.reshape(rows, cols * channels)
    filtered = np.empty((rows, 1 + cols * channels), np.uint8)
    filtered[:, 0] = 2  # "Up"
    filtered[0, 1:] = flat[0]  # the row above the first is zeros
    np.subtract(flat[1:], flat[:-1], out=filtered[1:, 1:])  # modulo 256, as the filter is
    workers = workers or os.cpu_count() or 1
    step = max(1, -(-rows // (4 * workers)))
    bands = [filtered[a:a + step] for a in range(0, rows, step)]

    def deflate(i: int) -> bytes:
        c = zlib.compressobj(compress_level, zlib.DEFLATED, -15)  # raw deflate: the zlib wrapper is made below
        return c.compress(bands[i]) + c.flush(zlib.Z_FINISH if i == len(bands) - 1 else zlib.Z_FULL_FLUSH)

    with ThreadPoolExecutor(min(workers, len(bands))) as pool:
        parts = list(pool.map(deflate, range(len(bands))))
    adler = 1
    for band in bands:
        adler = zlib.adler32(band, adler)
    data = b"\x78\x01" + b"".join(parts) + struct.pack(">I", adler)

    def chunk(kind: bytes, payload: bytes) -> bytes:
        return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))

    header = struct.pack(">IIBBBBB", cols, rows, 8, colour, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", data) + chunk(b"IEND", b"")


def write_png(path: str | Path, image: np.ndarray) -> None:
    """An 8-bit picture as PNG, zlib level 1: a 1080p picture in about 0.15 s instead of 0.9 s, some 10 % larger."""
    Path(path).write_bytes(png_bytes(image, compress_level=1))


def write_json(path: str | Path, obj) -> None:
    """``obj`` as strict JSON: NaN and infinities (which JSON has no numbers for) are written as null."""
    Path(path).write_text(json.dumps(finite(obj), indent=2, default=_json_default, allow_nan=False) + "\n")


def finite(obj):
    """``obj`` with every non-finite float (NaN, inf; NumPy's too) replaced by None, for strict JSON."""
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    return obj


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def resumable_mode(out: Path, record: str, expected: str, resume: bool, overwrite: bool, what: str) -> str:
    """How a resumable job (a sweep, a data set) treats ``out``: "new" (no folder, or an empty one), "resume"
    (``resume``, and the folder's ``record`` file holds ``expected``: the same job) or "replace" (``overwrite``).
    Anything else is a one-line refusal naming ``what`` the folder holds."""
    out = Path(out)
    if not (out.is_dir() and any(out.iterdir())):
        return "new"
    if resume:
        old = None
        if (out / record).is_file():  # through the gate: at most a little more than the record this job writes
            data = inputs.read_bytes(out / record, f"--resume {record}", len(expected.encode()) + 4096)
            old = data.decode("utf-8", "replace")
        if old != expected:
            raise CmosnoiseError(f"--resume: {str(out)!r} holds another {what} (its {record} differs); resume with the "
                                 "same options")
        return "resume"
    if not overwrite:
        raise CmosnoiseError(f"--out {str(out)!r} already exists and is not empty; give --resume to continue that "
                             f"{what}, --overwrite to start again, or another folder")
    return "replace"
