"""Writing results: an output folder that appears whole or not at all.

Everything is written into a temporary folder beside the target and moved
into place only when the run has succeeded, so an error never leaves a
half-written output behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import CmosnoiseError

class OutputFolder:
    """Context manager: ``with OutputFolder(out) as tmp: write into tmp`` then it is moved to ``out``.

    Files already in ``out`` that the run does not write are left alone; the
    ones it writes are replaced atomically (``os.replace``). On an exception
    the temporary folder is removed and ``out`` is untouched.
    """

    def __init__(self, out: str | Path):
        self.out = Path(out)
        if self.out.exists() and not self.out.is_dir():
            raise CmosnoiseError(f"--out {str(out)!r} is a file; give a folder to write the results into")
        anchor = self.out.parent
        while not anchor.exists():
            anchor = anchor.parent
        if not anchor.is_dir():
            raise CmosnoiseError(
                f"--out {str(out)!r} cannot be written: {str(anchor)!r} is a file, not a folder"
            )
        try:
            self.tmp = Path(tempfile.mkdtemp(prefix=".cmosnoise-tmp-", dir=anchor))
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(self.tmp, 0o777 & ~umask)  # mkdtemp makes it private; the result is an ordinary folder
        except OSError as exc:
            raise CmosnoiseError(f"--out {str(out)!r} cannot be written: {exc.strerror or exc}") from None

    def __enter__(self) -> Path:
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return False
        try:
            if not self.out.exists():
                self.out.parent.mkdir(parents=True, exist_ok=True)
                os.rename(self.tmp, self.out)
                return False
            for item in self.tmp.iterdir():
                target = self.out / item.name
                if target.is_dir() and not item.is_dir():
                    raise CmosnoiseError(f"cannot replace folder {str(target)!r} with a file")
                if item.is_dir() and target.exists():
                    shutil.rmtree(target)
                os.replace(item, target)
        except OSError as exc:
            raise CmosnoiseError(f"--out {str(self.out)!r} cannot be written: {exc.strerror or exc}") from None
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)
        return False


@contextlib.contextmanager
def atomic_file(path: str | Path):
    """Yield a temporary path beside ``path``; rename it to ``path`` on success, remove it on error."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_png(path: str | Path, image: np.ndarray) -> None:
    """An 8-bit picture as PNG, zlib level 1: a 1080p picture in about 0.15 s instead of 0.9 s, some 10 % larger."""
    import imageio.v3 as iio

    iio.imwrite(path, image, extension=".png", compress_level=1)


def write_json(path: str | Path, obj) -> None:
    Path(path).write_text(json.dumps(obj, indent=2, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
