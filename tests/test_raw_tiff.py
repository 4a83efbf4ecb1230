"""A raw TIFF's frames written one after another from the writer's own thread (SeriesWriter), directly or
through the page cache: the file tifffile writes from the same frames, byte for byte."""

import errno
import os

import numpy as np
import pytest
import tifffile
from conftest import refuse_direct_writes, takes_o_direct

from cmosnoise.io import raw_tiff
from cmosnoise.model.tiles import grid

META = {"cfa": "RGGB", "bits": 12}


def _frames(dtype, n, shape):
    rng = np.random.default_rng(3)
    data = rng.integers(0, 4096, (n, *shape)) if dtype == "uint16" else rng.normal(500, 30, (n, *shape))
    return data.astype(dtype)


def _fill(path, frames, direct=True, depth=2):
    offset = raw_tiff.create_raw_tiff(path, len(frames), frames.shape[1:], META, frames.dtype.name)
    with raw_tiff.SeriesWriter(path, offset, frames.shape[1:], frames.dtype, direct=direct, depth=depth) as out:
        for frame in frames:
            out.write(frame.copy())  # fresh arrays, as a run's frames are
    return path.read_bytes(), out.direct  # read once closed: the writer's thread may switch it


# 1080 x 1920 uint16 (4 MB a frame, not a multiple of 4096 bytes: each frame's tail is carried to the next),
# 600 x 512 float32 (1.2 MB, a multiple: nothing carried) and a frame smaller than a block
@pytest.mark.parametrize("dtype, shape, n", [("uint16", (1080, 1920), 3), ("float32", (600, 512), 2),
                                             ("uint16", (10, 30), 5)])
def test_a_series_written_directly_or_through_the_page_cache_is_tifffiles_file(tmp_path, monkeypatch, dtype,
                                                                              shape, n):
    frames = _frames(dtype, n, shape)
    tries = takes_o_direct(tmp_path) and frames.nbytes >= raw_tiff.DIRECT_ALIGN  # a whole block to write
    made = tmp_path / "tifffile.tiff"
    raw_tiff.write_raw_tiff(made, iter(frames), n, shape, META, dtype, align=raw_tiff.DIRECT_ALIGN)
    expected = made.read_bytes()
    through, used = _fill(tmp_path / "cache.tiff", frames, direct=False)
    assert through == expected and not used
    direct, used = _fill(tmp_path / "direct.tiff", frames)
    assert direct == expected
    assert used == takes_o_direct(tmp_path)  # direct where the file system takes it (ext4, xfs, tmpfs >= 6.6)
    assert np.array_equal(tifffile.imread(tmp_path / "direct.tiff"), frames)
    # a frame in pieces of 8 KiB (the buffer's room after the 4 KiB it may hold over): the same file
    monkeypatch.setattr(raw_tiff.SeriesWriter, "CHUNK", 5000)
    assert _fill(tmp_path / "pieces.tiff", frames)[0] == expected
    monkeypatch.undo()
    # a file system refusing O_DIRECT at the first write: everything through the page cache, the same bytes
    refused = refuse_direct_writes(monkeypatch)
    after, used = _fill(tmp_path / "refused.tiff", frames, depth=1)
    assert after == expected
    # one refused write where a direct one was tried; 5 frames of 600 B never hold a whole block: no direct write
    # was tried, and the writer would still try one
    assert len(refused) == int(tries) and used == (takes_o_direct(tmp_path) and not tries)


def test_the_writers_errors_reach_the_caller_and_nothing_hangs(tmp_path, monkeypatch):
    frames = _frames("uint16", 4, (64, 64))
    path = tmp_path / "raw.tiff"
    offset = raw_tiff.create_raw_tiff(path, 4, (64, 64), META, "uint16")

    def full(*_):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "pwrite", full)
    out = raw_tiff.SeriesWriter(path, offset, (64, 64), "uint16", depth=1)
    with pytest.raises(OSError, match="No space"):  # at a later write or at the close, not lost in the thread
        for frame in frames:
            out.write(frame)
        out.close()
    out.close()  # closing again is harmless
    # a frame of another shape or type: named
    with raw_tiff.SeriesWriter(path, offset, (64, 64), "uint16") as out, pytest.raises(ValueError,
                                                                                       match=r"\(64, 64\) uint16"):
        out.write(frames[0, :10])
    # the caller's own error wins over the writer's
    with pytest.raises(KeyError), raw_tiff.SeriesWriter(path, offset, (64, 64), "uint16") as out:
        out.write(frames[0])
        raise KeyError("the caller's")


def test_a_system_without_pwrite_writes_the_same_file(tmp_path, monkeypatch):
    """Windows has no os.pwrite: the writers seek and write instead (one thread a descriptor), the same bytes."""
    frames = _frames("uint16", 3, (100, 70))
    made = tmp_path / "tifffile.tiff"
    raw_tiff.write_raw_tiff(made, iter(frames), 3, (100, 70), META, "uint16", align=raw_tiff.DIRECT_ALIGN)
    monkeypatch.delattr(os, "pwrite")
    assert _fill(tmp_path / "series.tiff", frames, direct=False)[0] == made.read_bytes()
    offsets = raw_tiff.create_tiled_raw_tiff(tmp_path / "tiled.tiff", 1, (100, 70), META, "uint16", 64)
    with raw_tiff.TileWriter(tmp_path / "tiled.tiff", 64, "uint16", direct=False) as out:
        for t, (r0, r1, c0, c1) in enumerate(grid((100, 70), 64)):  # 4 tiles, 3 of them cut
            out.write(int(offsets[0, t]), frames[0, r0:r1, c0:c1])
    assert np.array_equal(tifffile.imread(tmp_path / "tiled.tiff")[0], frames[0])  # a stack of one
