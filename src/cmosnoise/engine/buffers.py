"""Uninitialised arrays for the fixed maps, in transparent huge pages where Linux lends them.

NumPy asks the kernel for huge pages (``madvise(MADV_HUGEPAGE)``) for its
own allocations of 4 MiB and more. A map just under that size then fills in
4 KiB pages, one page fault at a time: a 1 MP sensor's float32 map is
3.8 MiB, and its three maps took 2 900 faults, some 5 ms of a 16 ms set-up
(measured: ``docs/random-numbers.md``). :func:`empty` puts an array of
:data:`HUGE_FROM` bytes up to NumPy's threshold in a private anonymous
mapping of its own, aligned to 2 MiB and advised for huge pages, so each
2 MiB of it faults once; the mapping is unmapped when the array (its last
view) is freed. Other arrays, and systems without ``madvise`` (not Linux),
take :func:`numpy.empty`: from 4 MiB NumPy's memory is in huge pages
already, and the C library hands memory freed by one tile to the next
without the kernel clearing it again, where a mapping of its own is cleared
every time (a 400 MP run in 2048-pixel tiles took about 1 s longer with its
16 MiB maps here). What the array holds is the same either way: only where
its memory comes from differs.

The cost: the resident memory of such an array is rounded up to whole huge
pages (at most 2 MiB more an array), and Python's ``tracemalloc`` does not
see it (it traces NumPy's own allocations).
"""

from __future__ import annotations

import contextlib
import mmap

import numpy as np

#: the huge page's size on x86-64 and arm64 Linux (4 KiB base pages), bytes
HUGE_PAGE = 2 << 20
#: arrays of at least this many bytes, and fewer than :data:`NUMPY_HUGE_FROM`, are placed in huge pages
HUGE_FROM = HUGE_PAGE
#: from this many bytes NumPy advises its own allocations for huge pages (``numpy/_core/src/multiarray/alloc.c``)
NUMPY_HUGE_FROM = 4 << 20
#: where the platform has what :func:`empty` needs (private anonymous mappings and madvise)
AVAILABLE = all(hasattr(mmap, name) for name in ("MAP_PRIVATE", "MAP_ANONYMOUS", "MADV_HUGEPAGE"))


def empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised C-contiguous array, in huge pages of its own from :data:`HUGE_FROM` bytes up to
    :data:`NUMPY_HUGE_FROM` where :data:`AVAILABLE`.

    Parameters
    ----------
    shape : tuple of int
        The array's shape.
    dtype : data-type
        Its element type.

    Returns
    -------
    ndarray
        Writable, of ``shape`` and ``dtype``; a view of its own mapping (freed with its last view) when it is
        placed in huge pages, else :func:`numpy.empty`'s array.

    Examples
    --------
    >>> from cmosnoise.engine import buffers
    >>> a = buffers.empty((864, 1152), "float32")  # 3.8 MiB: a 1 MP sensor's map
    >>> a.shape, a.dtype, a.flags.c_contiguous, a.flags.writeable
    ((864, 1152), dtype('float32'), True, True)
    """
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if not AVAILABLE or not HUGE_FROM <= nbytes < NUMPY_HUGE_FROM:
        return np.empty(shape, dtype)
    # a mapping one huge page longer than the array, so that the array can start on a huge page's boundary
    block = mmap.mmap(-1, nbytes + HUGE_PAGE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    with contextlib.suppress(OSError):  # a kernel without transparent huge pages: 4 KiB pages, as np.empty's
        block.madvise(mmap.MADV_HUGEPAGE)
    whole = np.frombuffer(block, np.uint8)
    start = -whole.ctypes.data % HUGE_PAGE
    return whole[start:start + nbytes].view(dtype).reshape(shape)
