"""The frame kernel on an NVIDIA GPU, with the CPU kernel's bits.

One thread per pixel of a batch of frames: for each, the chain of
:func:`.kernel._render_rows` in the same order and the same IEEE float64
operations, from the same sources: Philox, :mod:`.fdmath` and the samplers
are compiled for the device by :func:`.kernel.compile_helpers` with numba's
CUDA target, exactly as for the CPU. Three things keep the bits:

- **no fused multiply-add.** NVVM contracts ``a * b + c`` into one ``fma``
  by default, even without fast-math; every compile of this module's kernels
  passes NVVM ``-fma=0`` (:func:`strict_arithmetic`; a test reads the PTX);
  ``fastmath`` stays off, so division and square root are IEEE and
  denormals are kept;
- the math is the package's own (fdmath's log, exp, cosine): no libdevice
  call whose last bits differ from the CPU's;
- sampling is per pixel and never shared between threads.

What each frame shares (maps, the scene's mean charge, the tables) is
uploaded once (:class:`DevicePlan`); a batch of frames, of crops at
different corners of the same exposure, or of frames of different sensors
of one shape (a data set's samples: their plans stacked in one
:class:`DevicePlan`, each item naming its own), is one launch, and the
frames stay on the device until asked for. A row's and a column's normals and each
frame's black level are drawn once per frame by a small kernel before the
pixels, and so are the random telegraph traps' states and the blinking
pixels' dark charge, per item (:func:`.cuda_device.occupancy`: telegraph's
occupancy with its two arrays local to the thread).

Where ``NUMBA_ENABLE_CUDASIM=1`` is set before numba is imported, the same
kernels run in numba's CUDA simulator (slow, pure Python: small frames), and
the tests compare them with the CPU kernel there.
"""

from __future__ import annotations

import contextlib
import threading

import numpy as np

from ...errors import CmosnoiseError
from .. import dlpack
from ..jit import numba
from . import (
    cuda_table,  # the per-plan table's columns, by name (cuda_device reads the same)
    kernel,
)
from .cuda_table import scalar_numpy, simulated  # noqa: F401 - callers ask cuda_kernel

#: threads per block of the pixel kernel (along a row: coalesced loads of the maps and stores of the frame), and of
#: the kernels over lists (lines, traps, blinking pixels, stuck pixels). In numba's CUDA simulator every thread is a
#: Python thread, started and polled, and a block's idle threads past a small frame's edge cost as much as working
#: ones: blocks of 16 there. Each thread makes its own pixel or item (no shared memory, no barrier), so the bits do
#: not depend on the block's size.
BLOCK, ITEMS, LINES = (16, 16, 16) if simulated() else (128, 128, 64)
_LOCK = threading.Lock()


def _cuda():
    """numba's CUDA module, or a one-line error naming what is missing."""
    if numba is None:
        raise CmosnoiseError("device = 'cuda': numba is not installed; install cmosnoise[cuda]")
    try:
        from numba import cuda
    except ImportError as exc:  # pragma: no cover - numba without its CUDA target
        raise CmosnoiseError(f"device = 'cuda': numba's CUDA target cannot be imported ({exc}); "
                             "install cmosnoise[cuda]") from None
    return cuda


def check() -> None:
    """Raise a one-line :class:`CmosnoiseError` where no CUDA GPU can run the kernel here."""
    cuda = _cuda()
    if simulated():
        return
    try:
        ok = cuda.is_available()
    except Exception as exc:  # a driver that fails to load
        raise CmosnoiseError(f"device = 'cuda': the CUDA driver did not load ({str(exc).splitlines()[0]}); "
                             "use device = 'cpu'") from None
    if not ok:
        raise CmosnoiseError("device = 'cuda': no CUDA GPU or driver is available here; use device = 'cpu' "
                             "(the default)")


def describe() -> str:
    """The device the kernel runs on, in words (``"NVIDIA H100 80GB HBM3 (compute 9.0)"``, or the simulator)."""
    cuda = _cuda()
    if simulated():
        return "numba's CUDA simulator"
    dev = cuda.get_current_device()
    name = dev.name.decode() if isinstance(dev.name, bytes) else str(dev.name)
    return f"{name} (compute {dev.compute_capability[0]}.{dev.compute_capability[1]})"


@contextlib.contextmanager
def strict_arithmetic():
    """While inside: every NVVM compile in this process runs with ``-fma=0`` (no multiply-add contraction), IEEE
    division and square root, denormals kept.

    numba's CUDA target gives NVVM no such switch (``fastmath=False`` leaves
    NVVM's default contraction on), so its one entry to NVVM,
    ``numba.cuda.cudadrv.nvvm.compile_ir``, is wrapped for the duration.
    PTX ``mul.rn``/``add.rn`` carry an explicit rounding, which ptxas does
    not fuse either. The kernels of this module compile only inside it.
    """
    from numba.cuda.cudadrv import nvvm

    with _LOCK:
        original = nvvm.compile_ir

        def compile_ir(llvmir, **options):
            options.update(fastmath=False, fma=False, ftz=False, prec_div=True, prec_sqrt=True)
            return original(llvmir, **options)

        nvvm.compile_ir = compile_ir
        try:
            yield
        finally:
            nvvm.compile_ir = original


def kernels():
    """The device functions and kernels (:mod:`.cuda_device`), imported (and their helpers compiled) on first use."""
    _cuda()
    from . import cuda_device

    return cuda_device


def as_device_array(value, name: str = "array"):
    """A GPU array as numba's device array, without a copy: anything with ``__cuda_array_interface__`` (CuPy,
    PyTorch, numba), or with ``__dlpack__`` (JAX, and any DLPack producer: read by :mod:`.dlpack`, no framework
    needed); a numba device array as it is."""
    cuda = _cuda()
    if hasattr(value, "copy_to_host"):  # numba's own (the simulator's too)
        return value
    if not hasattr(value, "__cuda_array_interface__") and hasattr(value, "__dlpack__"):  # JAX, and any DLPack array
        taken = dlpack.read(value)
        if taken.device[0] == dlpack.CUDA and not simulated():
            return cuda.from_cuda_array_interface(taken.__cuda_array_interface__, owner=taken)
        if taken.device[0] == dlpack.CPU and simulated():  # the simulator's "GPU" is host memory
            return cuda.to_device(np.asarray(taken))
        raise CmosnoiseError(f"{name}: a DLPack array on device type {taken.device[0]} (1: host memory, 2: an NVIDIA "
                             "GPU); expected one on the GPU")
    if not hasattr(value, "__cuda_array_interface__"):
        raise CmosnoiseError(f"{name}: expected an array on the GPU (__cuda_array_interface__ or __dlpack__), got "
                             f"{type(value).__name__}")
    return cuda.as_cuda_array(value)


def crops(source, corners, shape: tuple[int, int]):
    """A batch of crops of one array on the GPU, in one launch: device array (B, h, w) of ``source``'s dtype.

    Parameters
    ----------
    source : GPU array (rows, cols) (see :func:`as_device_array`), or a NumPy array (uploaded first)
        A map of the exposure: its truth (expected raw, mask), a mean charge.
    corners : array_like (B, 2)
        Each crop's top-left pixel, as :meth:`DevicePlan.render` takes them (the frames' crops match).
    shape : (h, w)
    """
    k = kernels()
    cuda = k.cuda
    src = cuda.to_device(np.ascontiguousarray(source)) if isinstance(source, np.ndarray) else as_device_array(source)
    corners = np.asarray(corners, np.int64).reshape(-1, 2)
    h, w = int(shape[0]), int(shape[1])
    rows, cols = src.shape
    if corners.size == 0 or corners.min() < 0 or (corners[:, 0] + h).max() > rows or (corners[:, 1] + w).max() > cols:
        raise ValueError(f"crops of {h} x {w} at corners {corners.tolist()[:4]}... do not fit in {rows} x {cols}")
    out = cuda.device_array((corners.shape[0], h, w), src.dtype)
    with strict_arithmetic():
        k.gather[((w + BLOCK - 1) // BLOCK, h, corners.shape[0]), (BLOCK, 1, 1)](src, cuda.to_device(corners), out)
    return out


def fixed_map(kind: str, shape: tuple[int, int], *args):
    """A fixed map's rectangle made on the GPU, left there: device array (h, w) float32, bit for bit the CPU's.

    Parameters
    ----------
    kind : {"normal", "heavy_tail", "offset"}
        Which of :mod:`.fixed_maps`' compiled loops (``kernel._normal_map``, ``kernel._heavy_tail_map``,
        ``kernel._offset_map``).
    shape : (h, w)
        The rectangle's size.
    *args
        That loop's arguments after ``out`` (the rectangle's corner, the sensor's width, the key, the map's
        parameters), as :func:`.fixed_maps.normal_map`, :func:`.fixed_maps.heavy_tail_map` and
        :func:`.fixed_maps.offset_map` give them.

    Returns
    -------
    device array (h, w) float32
    """
    k = kernels()
    cuda = k.cuda
    out = cuda.device_array(tuple(int(v) for v in shape), np.float32)
    args = tuple(cuda.to_device(np.ascontiguousarray(a)) if isinstance(a, np.ndarray) and a.ndim else a for a in args)
    grid = ((out.shape[1] + BLOCK - 1) // BLOCK, out.shape[0])
    with strict_arithmetic():
        {"normal": k.normal_map, "heavy_tail": k.heavy_tail_map, "offset": k.offset_map}[kind][grid, (BLOCK, 1)](
            out, *args)
    return out


def dlpack_view(array) -> dlpack.View:
    """A device array (a frame left on the GPU) offered by the DLPack protocol, without a copy:
    ``jax.dlpack.from_dlpack``, ``cupy.from_dlpack``, ``torch.from_dlpack`` take it; no framework is needed to make
    it (:mod:`.dlpack`, ctypes alone).

    Parameters
    ----------
    array : numba device array
        What :meth:`DevicePlan.render` returns (``frames_on_device``).

    Returns
    -------
    dlpack.View
        Keeps ``array`` alive until its consumer is done. In numba's simulator (no GPU) it offers the host memory
        that stands for the device's (device type CPU).
    """
    if simulated():
        host = np.asarray(array)  # the simulator's device array over its host array: the same memory
        return dlpack.View(host.ctypes.data, host.shape, host.strides, host.dtype, (dlpack.CPU, 0), array)
    desc = array.__cuda_array_interface__
    dtype = np.dtype(desc["typestr"])
    shape = tuple(desc["shape"])
    strides = desc.get("strides") or tuple(int(np.prod(shape[i + 1:], dtype=np.int64)) * dtype.itemsize
                                           for i in range(len(shape)))
    device = _cuda().get_current_device().id
    return dlpack.View(desc["data"][0], shape, strides, dtype, (dlpack.CUDA, device), array)


def to_torch(array):
    """A device array as a PyTorch CUDA tensor over the same memory (no copy)."""
    import torch

    return torch.as_tensor(array, device="cuda")


def _rows_of(index: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A sorted list of pixel indices as row pointers over the whole frame (rows + 1,) and columns, int64."""
    rows, cols = shape
    index = np.asarray(index).astype(np.int64)
    ptr = np.searchsorted(index // cols, np.arange(rows + 1)).astype(np.int64)
    return ptr, (index % cols).astype(np.int64)


def _row_lists(indices: list, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each plan's sorted list of pixel indices, concatenated plan after plan: (row pointers (P, rows + 1) into the
    concatenated list, its columns (n + 1,) int64 (one padding entry), where each plan's part starts (P + 1,))."""
    start = _spans([i.size for i in indices])
    parts = [_rows_of(i, shape) for i in indices]
    return (np.stack([ptr + s for (ptr, _), s in zip(parts, start)]),
            np.concatenate([col for _, col in parts] + [np.zeros(1, np.int64)]), start)


def _spans(counts) -> np.ndarray:
    """Where each plan's part of a concatenated list starts, and the total: (P + 1,) int64."""
    return np.r_[0, np.cumsum(np.asarray(counts, np.int64))].astype(np.int64)


class DevicePlan:
    """One or several :class:`.kernel.FramePlan` of the same shape on the GPU: maps, tables and populations
    uploaded once, every frame made from them in one launch.

    Parameters
    ----------
    plan : kernel.FramePlan, or a sequence of them (P,)
        What every frame of an exposure shares (full-frame maps). Several plans (each its own sensor, exposure
        and seed: the samples of a data set) share the device arrays, stacked (P, rows, cols), and a batch takes
        any of them per item.
    stuck : tuple of ndarray, or a sequence of them (one per plan, or None), optional
        The stuck pixels of stage 15 as (flat pixel index (n,) int64, value (n,) float64), each pixel once: a code
        (DN), or e- with the ADC off. They replace the pixel's value after the ADC.

    Every array stays on the device; :meth:`render` launches a batch. Each plan's scalars sit in a row of
    :attr:`numbers` (float64, columns ``NORMAL_ABOVE`` ... ``EXPOSURE`` of this module) and :attr:`ints`;
    variable-length lists (traps, blinking and stuck pixels) are concatenated plan after plan, with each plan's
    start.
    """

    def __init__(self, plan, stuck=None):
        one = isinstance(plan, kernel.FramePlan)
        plans = [plan] if one else list(plan)
        stucks = [stuck] if one else (list(stuck) if stuck is not None else [None] * len(plans))
        if not plans or len(stucks) != len(plans):
            raise ValueError(f"DevicePlan: expected one or more plans and a stuck-pixel list (or None) for each, got "
                             f"{len(plans)} plans and {len(stucks)} lists")
        shape = tuple(plans[0].shape)
        for q, p in enumerate(plans):
            if p.window is not None:
                raise CmosnoiseError(f"a plan of the window {p.window} (a tile) is made by the CPU kernel; the GPU "
                                     "takes a whole sensor's exposure and makes crops of it")
            if tuple(p.shape) != shape or (p.adc is None) != (plans[0].adc is None):
                raise CmosnoiseError(f"plans in one batch: plan {q} is {p.shape} with the ADC "
                                     f"{'off' if p.adc is None else 'on'}, plan 0 {shape} with it "
                                     f"{'off' if plans[0].adc is None else 'on'}; expected one shape and one ADC "
                                     "setting (the frames of a batch are one array)")
        check()
        self.k = kernels()
        cuda = self.k.cuda
        #: threads per block of the pixel kernel
        self.block = BLOCK
        #: the plans, (P,)
        self.plans = plans
        self.plan = plans[0]
        self.shape = shape
        rows, cols = shape

        def up(a, dtype=None):
            return cuda.to_device(np.ascontiguousarray(a if dtype is None else np.asarray(a, dtype)))

        def stacked(name, dtype, size):
            """Each plan's array ``name`` (None: zeros), stacked (P, *size); a dummy (1, ...) where no plan has
            one (its switch keeps it unread)."""
            arrays = [getattr(p, name) for p in plans]
            if all(a is None for a in arrays):
                return up(np.zeros((1,) * (len(size) + 1), dtype))
            if len(arrays) == 1:  # a view of the plan's own array: no copy on the host
                return up(np.asarray(arrays[0], dtype)[None])
            out = np.zeros((len(arrays), *size), dtype)
            for q, a in enumerate(arrays):
                if a is not None:
                    out[q] = a
            return up(out)

        self.noisy = stacked("noisy_e", np.float32, shape)
        self.exact = stacked("exact_e", np.float32, shape)
        self.sf = stacked("sf_sigma_e", np.float32, shape)
        self.offset = stacked("offset_e", np.float32, shape)
        self.row_offset = up(np.stack([np.zeros(rows) if p.row_offset_e is None else np.asarray(p.row_offset_e)
                                       for p in plans]), np.float64)
        self.col_sigma = stacked("col_sigma_e", np.float64, (cols,))
        self.col_offset = stacked("col_offset_e", np.float64, (cols,))
        self.col_gain = stacked("col_gain", np.float64, (cols,))
        self.keys = up(np.stack([p.keys for p in plans]), np.uint64)
        self.seqs = up(np.array([p.sequence for p in plans], np.uint64))
        self.cell_offsets = up(np.array([p.cell_offsets_dn for p in plans], np.float64))
        numbers = np.zeros((len(plans), len(cuda_table.NUMBERS)))
        ints = np.zeros((len(plans), len(cuda_table.INTS)), np.int64)
        nl_tables, read_tables = [], []
        for q, p in enumerate(plans):
            table, nl_scale, (a, b, c) = kernel.curve_constants(p)
            read_kind, read_scale, read_table = kernel.read_constants(p)
            k_adc, black, top, step = p.adc if p.adc is not None else (1.0, 0.0, 0, 1)
            numbers[q] = cuda_table.row(cuda_table.NUMBERS, {
                "normal_above": p.normal_above_e, "full_well": p.full_well_e, "k_adc": k_adc, "black": black,
                "top": top, "step": step, "nl_scale": nl_scale, "nl_a": a, "nl_b": b, "nl_c": c,
                "read_scale": read_scale, "row_sigma": p.row_sigma_e or 0.0,
                "frame_black_sigma": p.frame_black_sigma_dn, "frame_period": p.frame_period_s,
                "cds_interval": p.cds_interval_s or 0.0, "exposure": p.exposure_s})
            ints[q] = cuda_table.row(cuda_table.INTS, {"read_kind": read_kind, "nl_size": table.size,
                                                       "cds": p.cds_interval_s is not None})
            nl_tables.append(table)
            read_tables.append(read_table)
        #: each plan's scalars (P, len(NUMBERS)) float64 and (P, len(INTS)) int64 (cuda_table's named columns)
        self.numbers, self.ints = up(numbers), up(ints)
        self.nl = up(self._padded(nl_tables))
        self.read_table = up(self._padded(read_tables))
        # traps (stage 6b): sorted by pixel, then slot, plan after plan; their pixels as row-sorted lists
        traps = [p.traps if p.traps is not None and p.traps.index.size else None for p in plans]
        firsts = [np.zeros(0, np.int64) if t is None else np.flatnonzero(np.r_[True, t.index[1:] != t.index[:-1]])
                  for t in traps]
        self.has_traps = [t is not None for t in traps]
        self.trap_start = _spans([0 if t is None else t.index.size for t in traps])
        ptr, col, self.trap_groups = _row_lists([f if t is None else t.index[f] for t, f in zip(traps, firsts)],
                                                shape)
        self.rts_ptr, self.rts_col = up(ptr), up(col)
        self.d_trap_start, self.d_trap_groups = up(self.trap_start), up(self.trap_groups)
        if any(self.has_traps):
            self.trap_arrays = self._concatenated([t for t in traps if t is not None])
            self.trap_first = up(np.r_[np.concatenate([f + self.trap_start[q] for q, f in enumerate(firsts)]),
                                       self.trap_start[-1]].astype(np.int64))
            self.trap_keys = up(np.array([p.trap_key for p in plans], np.uint64))
        # blinking pixels (stage 4b): one a pixel, sorted, plan after plan
        blinkers = [p.blinkers if p.blinkers is not None and p.blinkers.index.size else None for p in plans]
        for t in blinkers:
            if t is not None and np.any(np.diff(t.index.astype(np.int64)) <= 0):
                raise ValueError("blinkers: expected one blinking pixel per pixel, sorted")
        self.has_blinkers = [t is not None for t in blinkers]
        ptr, col, self.blink_start = _row_lists([np.zeros(0, np.int64) if t is None else t.index for t in blinkers],
                                                shape)
        self.blink_ptr, self.blink_col, self.d_blink_start = up(ptr), up(col), up(self.blink_start)
        if any(self.has_blinkers):
            self.blink_arrays = self._concatenated([t for t in blinkers if t is not None])
            self.blink_keys = up(np.array([p.blink_key for p in plans], np.uint64))
        # stuck pixels (stage 15), plan after plan
        stucks = [(np.zeros(0, np.int64), np.zeros(0)) if s is None else (np.asarray(s[0], np.int64),
                                                                          np.asarray(s[1], np.float64))
                  for s in stucks]
        self.stuck_start = _spans([s[0].size for s in stucks])
        self.stuck = None
        if self.stuck_start[-1]:
            index = np.concatenate([s[0] for s in stucks])
            self.stuck = (up(np.stack([index // cols, index % cols], axis=1)),
                          up(np.concatenate([s[1] for s in stucks])), up(self.stuck_start))
        #: the kernels' switches of each plan (P, 13), without and with the charge at the ADC input asked for
        self.flags = {e: up(np.stack([kernel.switches(p, e, t, bl) for p, t, bl in
                                      zip(plans, self.has_traps, self.has_blinkers)]))
                      for e in (False, True)}

    @property
    def shared(self) -> cuda_table.Shared:
        """What the line and pixel kernels read of this plan, by name (:data:`.cuda_table.Shared`)."""
        return cuda_table.Shared(
            noisy=self.noisy, exact=self.exact, sf=self.sf, ints=self.ints, numbers=self.numbers,
            row_offset=self.row_offset, col_sigma=self.col_sigma, col_offset=self.col_offset, col_gain=self.col_gain,
            cell_offsets=self.cell_offsets, keys=self.keys, seqs=self.seqs, nl=self.nl, offset=self.offset,
            read_table=self.read_table, rts_ptr=self.rts_ptr, rts_col=self.rts_col, trap_groups=self.d_trap_groups,
            blink_ptr=self.blink_ptr, blink_col=self.blink_col, blink_start=self.d_blink_start)

    def _offsets(self, frames: np.ndarray, which: np.ndarray, stream=0):
        """What a launch's items read of the row, column and pixel offsets: :attr:`shared` and each item's plan,
        or, where a plan's offsets change from frame to frame (1/f row, column or pixel noise, the column banks'
        temporal offsets), each item's own offsets of its frame: the plan's ``row_offsets(frame)``,
        ``col_offsets(frame)`` and ``offsets(frame)``, made on the host by the exact bridges every copy of the
        chain uses (so the same bits as the CPU kernel), and uploaded for the launch, one row an item."""
        plans = [self.plans[q] for q in which]
        if not any(p.row_flicker is not None or p.col_flicker is not None or p.pixel_flicker is not None
                   for p in plans):
            return self.shared, self.k.cuda.to_device(which, stream=stream)
        rows, cols = self.shape

        def each(name, method, dtype, size, always=False):  # zeros where a plan has none (as in __init__)
            if not always and all(getattr(p, name) is None for p in plans):
                return self.k.cuda.to_device(np.zeros((1,) * (len(size) + 1), dtype), stream=stream)
            out = np.zeros((len(plans), *size), dtype)
            for b, (p, k) in enumerate(zip(plans, frames)):
                if getattr(p, name) is not None:
                    out[b] = getattr(p, method)(int(k))
            return self.k.cuda.to_device(out, stream=stream)

        shared = self.shared._replace(row_offset=each("row_offset_e", "row_offsets", np.float64, (rows,), True),
                                      col_offset=each("col_offset_e", "col_offsets", np.float64, (cols,)),
                                      offset=each("offset_e", "offsets", np.float32, (rows, cols)))
        return shared, self.k.cuda.to_device(np.arange(len(plans), dtype=np.int64), stream=stream)

    @staticmethod
    def _padded(tables: list) -> np.ndarray:
        """Tables of different lengths as the rows of one (P, longest) array (the rest zeros, never read)."""
        out = np.zeros((len(tables), max(t.size for t in tables)))
        for q, t in enumerate(tables):
            out[q, :t.size] = t
        return out

    def _concatenated(self, populations: list) -> tuple:
        """The populations' (up, down, size, index, slot) arrays, plan after plan, on the device."""
        cuda = self.k.cuda
        return tuple(cuda.to_device(np.ascontiguousarray(np.concatenate([getattr(t, name) for t in populations])
                                                         .astype(dtype)))
                     for name, dtype in (("up", np.float64), ("down", np.float64), ("size", np.float64),
                                         ("index", np.uint64), ("slot", np.uint64)))

    def with_means(self, noisy_e=None, exact_e=None) -> DevicePlan:
        """This plan with the mean charge (the scene) taken from arrays already on the GPU, without a copy.

        Parameters
        ----------
        noisy_e, exact_e : GPU array (rows, cols), or (P, rows, cols) for P plans, float32, e-, optional
            The mean charge shot noise acts on, and that entering without it (the plan's ``noisy_e`` and
            ``exact_e``): anything with ``__cuda_array_interface__`` (a PyTorch or CuPy tensor, a numba device
            array), or a DLPack capsule's owner where PyTorch can read it. None keeps the plan's own; each must be
            given where the plans have one (the plans' stages decide which exist).

        The arrays are read, never copied or kept beyond the plan.
        """
        import copy

        other = copy.copy(self)
        for name, value in (("noisy_e", noisy_e), ("exact_e", exact_e)):
            if value is None:
                continue
            if all(getattr(p, name) is None for p in self.plans):
                raise CmosnoiseError(f"{name}: this plan has no {name} (its stages put the charge elsewhere)")
            arr = as_device_array(value, name)
            want = (len(self.plans), *self.shape)
            if arr.ndim == 2 and len(self.plans) == 1:
                arr = arr.reshape(want)
            if tuple(arr.shape) != want or np.dtype(arr.dtype) != np.float32:
                raise CmosnoiseError(f"{name}: expected a float32 array of {self.shape if len(self.plans) == 1 else want}, "
                                     f"got {arr.dtype} {tuple(arr.shape)}")
            setattr(other, "noisy" if name == "noisy_e" else "exact", arr)
        return other

    def nbytes(self) -> int:
        """Bytes this plan holds on the device."""
        found = []

        def walk(v):
            if hasattr(v, "copy_to_host"):
                found.append(v)
            elif isinstance(v, (tuple, list, dict)):
                for x in (v.values() if isinstance(v, dict) else v):
                    walk(x)

        walk(list(vars(self).values()))
        return int(sum(a.nbytes for a in found))

    def render(self, frames, corners=None, shape=None, electrons: bool = False, stream=0, plans=None):
        """A batch: item ``b`` is frame ``frames[b]`` of plan ``plans[b]`` at corner ``corners[b] = (row0, col0)``,
        ``shape = (h, w)``.

        Parameters
        ----------
        frames : int or sequence of int, (B,)
            Frame numbers (0 to 2**32 - 1).
        corners : array_like, (B, 2), optional
            Each item's top-left pixel; default (0, 0).
        shape : (int, int), optional
            Each item's rows and columns; default the whole frame.
        electrons : bool
            Also return the charge at the ADC input (float32 e-).
        plans : sequence of int, (B,), optional
            Which of this object's plans each item is made from; default plan 0 for every item where there is one
            plan, and item ``b`` from plan ``b`` where there are several (then B is their number).

        Returns
        -------
        raw : device array, (B, h, w)
            uint16 DN, or float32 e- with the ADC off (then ``electrons`` is the same array). Each item equals
            ``kernel.render(plans[b], frame, region)`` with the stuck pixels set, bit for bit.
        electrons : device array (B, h, w) float32, or None
        """
        cuda = self.k.cuda
        rows, cols = self.shape
        count = len(self.plans)
        frames = np.atleast_1d(np.asarray(frames, np.int64))
        if frames.ndim != 1 or frames.size == 0:
            raise ValueError(f"frames: expected one frame number or a list of them, got shape {frames.shape}")
        if frames.min() < 0 or frames.max() > 2**32 - 1:
            raise ValueError("frames: frame numbers must be 0 to 2**32 - 1")
        n = frames.size
        if plans is None:
            if count > 1 and n != count:
                raise ValueError(f"plans: {n} items of {count} plans; give each item's plan")
            plans = np.zeros(n, np.int64) if count == 1 else np.arange(n)
        which = np.asarray(plans, np.int64).reshape(-1)
        if which.size != n or which.min() < 0 or which.max() >= count:
            raise ValueError(f"plans: expected {n} plan numbers from 0 to {count - 1}, got {which.tolist()[:8]}")
        corners = np.zeros((n, 2), np.int64) if corners is None else np.asarray(corners, np.int64).reshape(n, 2)
        h, w = (rows, cols) if shape is None else (int(shape[0]), int(shape[1]))
        if h < 1 or w < 1 or corners.min() < 0 or (corners[:, 0] + h).max() > rows or (corners[:, 1] + w).max() > cols:
            raise ValueError(f"regions of {h} x {w} at corners {corners.tolist()[:4]}... do not fit in {rows} x {cols}")
        used = [self.plans[q] for q in np.unique(which)]
        has_row = any(p.row_sigma_e is not None for p in used)
        has_col = any(p.col_gain is not None for p in used)
        adc_on = self.plan.adc is not None
        want_e = electrons or not adc_on
        flags = self.flags[bool(electrons)]
        d_frames, d_corners = cuda.to_device(frames, stream=stream), cuda.to_device(corners, stream=stream)
        d_which = cuda.to_device(which, stream=stream)
        rowval = cuda.device_array((n, h) if has_row else (1, 1), np.float64, stream=stream)
        colterm = cuda.device_array((n, w) if has_col else (1, 1), np.float64, stream=stream)
        cell_black = cuda.device_array((n, 4), np.float64, stream=stream)

        def most(start):  # the longest of the plans' lists, at least 1 (a grid is never empty)
            return max(1, int(np.diff(start).max()))

        has_traps, has_blinkers = any(self.has_traps), any(self.has_blinkers)
        groups, blinks = most(self.trap_groups), most(self.blink_start)
        rts_sum = cuda.device_array((n, groups) if has_traps else (1, 1), np.float64, stream=stream)
        blink_extra = cuda.device_array((n, blinks) if has_blinkers else (1, 1), np.float64, stream=stream)
        shared, offsets_of = self._offsets(frames, which, stream)
        items = cuda_table.Items(frames=d_frames, which=d_which, corners=d_corners, h=h, w=w, cols=cols, flags=flags,
                                 rowval=rowval, colterm=colterm, cell_black=cell_black, rts_sum=rts_sum,
                                 blink_extra=blink_extra, offsets_of=offsets_of)
        with strict_arithmetic():
            span = h + w + 4
            self.k.lines[((span + LINES - 1) // LINES, n), (LINES, 1), stream](shared, items)
            if has_traps:
                traps = most(self.trap_start)
                values = cuda.device_array((n, traps), np.float64, stream=stream)
                self.k.trap_values[((traps + ITEMS - 1) // ITEMS, n), (ITEMS, 1), stream](
                    d_frames, d_which, d_corners, h, w, cols, self.seqs, self.d_trap_start, *self.trap_arrays,
                    self.numbers, self.ints, self.trap_keys, values)
                self.k.pixel_sums[((groups + ITEMS - 1) // ITEMS, n), (ITEMS, 1), stream](
                    d_which, self.d_trap_groups, self.d_trap_start, self.trap_first, self.trap_arrays[3], d_corners,
                    h, w, cols, values, rts_sum)
            if has_blinkers:
                self.k.blink_values[((blinks + ITEMS - 1) // ITEMS, n), (ITEMS, 1), stream](
                    d_frames, d_which, d_corners, h, w, cols, self.seqs, self.d_blink_start, *self.blink_arrays,
                    self.numbers, self.blink_keys, blink_extra)
            out_dn = cuda.device_array((n, h, w) if adc_on else (1, 1, 1), np.uint16, stream=stream)
            out_e = cuda.device_array((n, h, w) if want_e else (1, 1, 1), np.float32, stream=stream)
            grid = ((w + self.block - 1) // self.block, h, n)
            self.k.pixels[grid, (self.block, 1, 1), stream](shared, items, out_dn, out_e)
            raw = out_dn if adc_on else out_e
            if self.stuck is not None:
                where, value, start = self.stuck
                stuck = most(self.stuck_start)
                self.k.stick[((stuck + ITEMS - 1) // ITEMS, n), (ITEMS, 1), stream](d_which, start, where, value, d_corners,
                                                                          raw)
        return raw, (out_e if want_e else None)
