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
from typing import Iterable

import numpy as np

from ..errors import CmosnoiseError

#: TIFF/EP CFA colour codes (0 red, 1 green, 2 blue)
_CFA_CODES = {"R": 0, "G": 1, "B": 2}


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


def write_json(path: str | Path, obj) -> None:
    Path(path).write_text(json.dumps(obj, indent=2, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


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


def write_raw_tiff(path: str | Path, frames: Iterable[np.ndarray], n: int, shape: tuple[int, int], metadata: dict) -> None:
    """Write ``n`` uint16 frames of ``shape`` as one (n, rows, cols) TIFF series, frame by frame.

    The CFA pattern also goes into the TIFF/EP ``CFARepeatPatternDim`` and
    ``CFAPattern`` tags so that raw tools can read it.
    """
    import tifffile

    extratags = []
    cfa = metadata.get("cfa", "none")
    if cfa != "none":
        extratags = [
            (33421, "H", 2, (2, 2), True),
            (33422, "B", 4, bytes(_CFA_CODES[c] for c in cfa), True),
        ]
    with tifffile.TiffWriter(path, bigtiff=n * shape[0] * shape[1] * 2 > 2**31) as tw:
        tw.write(
            frames, shape=(n, *shape), dtype="uint16", photometric="minisblack",
            metadata=metadata, extratags=extratags,
        )


def write_float_tiff(path: str | Path, image: np.ndarray, metadata: dict) -> None:
    """A float32 image (e.g. a master dark, DN) with JSON metadata."""
    import tifffile

    tifffile.imwrite(path, image.astype(np.float32), photometric="minisblack", metadata=metadata)


def read_raw_tiff(path: str | Path) -> tuple[np.ndarray, dict]:
    """Read raw frames written by :func:`write_raw_tiff`: (frames, rows, cols) uint16 and metadata."""
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


class VideoWriter:
    """H.264 MP4 written frame by frame (imageio with the ffmpeg binary shipped by imageio-ffmpeg)."""

    def __init__(self, path: str | Path, fps: float):
        import imageio.v2 as iio2

        self._writer = iio2.get_writer(
            str(path), fps=fps, codec="libx264", quality=8, macro_block_size=2, ffmpeg_log_level="error",
            pixelformat="yuv420p",
        )

    def append(self, frame: np.ndarray) -> None:
        if frame.ndim == 2:
            frame = np.repeat(frame[..., None], 3, axis=2)
        rows, cols = frame.shape[:2]
        self._writer.append_data(np.ascontiguousarray(frame[: rows - rows % 2, : cols - cols % 2]))  # yuv420p: even sizes

    def close(self) -> None:
        self._writer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
