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
uploaded once (:class:`DevicePlan`); a batch of frames, or of crops at
different corners of the same exposure, is one launch, and the frames stay
on the device until asked for. A row's and a column's normals and each
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
import types

import numpy as np

from ..errors import CmosnoiseError
from . import dlpack, kernel
from .jit import numba

#: threads per block of the pixel kernel (along a row: coalesced loads of the maps and stores of the frame)
BLOCK = 128
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


def simulated() -> bool:
    """Whether numba's CUDA simulator stands in for a GPU (``NUMBA_ENABLE_CUDASIM=1``)."""
    return numba is not None and bool(numba.config.ENABLE_CUDASIM)


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


def scalar_numpy(cuda) -> types.ModuleType:
    """What ``np`` stands for in the helpers' sources on the device: numpy's scalar types, and its ufuncs as the
    CUDA target's scalar functions with the same IEEE results (libdevice's floor, rint, fabs, sqrt and fmax are
    exact or correctly rounded)."""
    if simulated():
        return np  # the simulator runs the sources as Python on numpy scalars
    shim = types.ModuleType("cmosnoise_cuda_numpy")
    for name in ("uint64", "int64", "uint32", "int32", "uint16", "float64", "float32", "inf"):
        setattr(shim, name, getattr(np, name))
    lib = cuda.libdevice
    shim.floor, shim.rint, shim.abs, shim.sqrt, shim.maximum = lib.floor, lib.rint, lib.fabs, lib.sqrt, lib.fmax
    return shim


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


def dlpack_view(array) -> "dlpack.View":
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


class DevicePlan:
    """A :class:`.kernel.FramePlan` on the GPU: its maps, tables and populations uploaded once.

    Parameters
    ----------
    plan : kernel.FramePlan
        What every frame of an exposure shares (full-frame maps).
    stuck : tuple of ndarray, optional
        The stuck pixels of stage 15 as (flat pixel index (n,) int64, value (n,) float64), each pixel once: a code
        (DN), or e- with the ADC off. They replace the pixel's value after the ADC.

    Every array stays on the device; :meth:`render` launches a batch.
    """

    def __init__(self, plan: kernel.FramePlan, stuck: tuple[np.ndarray, np.ndarray] | None = None):
        if plan.window is not None:
            raise CmosnoiseError(f"a plan of the window {plan.window} (a tile) is made by the CPU kernel; the GPU "
                                 "takes a whole sensor's exposure and makes crops of it")
        check()
        self.k = kernels()
        cuda = self.k.cuda
        #: threads per block of the pixel kernel
        self.block = BLOCK
        self.plan = plan
        rows, cols = plan.shape

        def up(a, dtype=None):
            if a is None:
                return None
            return cuda.to_device(np.ascontiguousarray(a if dtype is None else np.asarray(a, dtype)))

        dummy2, dummy1 = up(np.zeros((1, 1), np.float32)), up(np.zeros(1))
        self.noisy = up(plan.noisy_e, np.float32) if plan.noisy_e is not None else dummy2
        self.exact = up(plan.exact_e, np.float32) if plan.exact_e is not None else dummy2
        self.sf = up(plan.sf_sigma_e, np.float32) if plan.sf_sigma_e is not None else dummy2
        self.offset = up(plan.offset_e, np.float32) if plan.offset_e is not None else dummy2
        self.row_offset = up(plan.row_offset_e, np.float64) if plan.row_offset_e is not None else up(np.zeros(rows))
        self.col_sigma = up(plan.col_sigma_e, np.float64) if plan.col_sigma_e is not None else dummy1
        self.col_offset = up(plan.col_offset_e, np.float64) if plan.col_offset_e is not None else dummy1
        self.col_gain = up(plan.col_gain, np.float64) if plan.col_gain is not None else dummy1
        self.keys = up(plan.keys, np.uint64)
        self.cell_offsets = up(np.asarray(plan.cell_offsets_dn, np.float64))
        nl, self.nl_scale, self.nl_abc = kernel.curve_constants(plan)
        self.nl = up(nl, np.float64)
        self.read_kind, self.read_scale, read_table = kernel.read_constants(plan)
        self.read_table = up(read_table)
        empty_ptr = np.zeros(rows + 1, np.int64)
        # traps (stage 6b): sorted by pixel, then slot; their pixels as a row-sorted list
        self.traps = plan.traps if plan.traps is not None and plan.traps.index.size else None
        if self.traps is not None:
            t = self.traps
            first = np.flatnonzero(np.r_[True, t.index[1:] != t.index[:-1]])
            ptr, col = _rows_of(t.index[first], plan.shape)
            self.trap_arrays = tuple(up(a) for a in (t.up, t.down, t.size, t.index.astype(np.uint64),
                                                     t.slot.astype(np.uint64)))
            self.trap_first = up(np.r_[first, t.index.size].astype(np.int64))
            self.rts_ptr, self.rts_col = up(ptr), up(col)
        else:
            self.rts_ptr, self.rts_col = up(empty_ptr), up(np.zeros(1, np.int64))
        # blinking pixels (stage 4b): one a pixel, sorted
        self.blinkers = plan.blinkers if plan.blinkers is not None and plan.blinkers.index.size else None
        if self.blinkers is not None:
            t = self.blinkers
            if np.any(np.diff(t.index.astype(np.int64)) <= 0):
                raise ValueError("blinkers: expected one blinking pixel per pixel, sorted")
            self.blink_ptr, self.blink_col = (up(a) for a in _rows_of(t.index, plan.shape))
            self.blink_arrays = tuple(up(a) for a in (t.up, t.down, t.size, t.index.astype(np.uint64),
                                                      t.slot.astype(np.uint64)))
        else:
            self.blink_ptr, self.blink_col = up(empty_ptr), up(np.zeros(1, np.int64))
        self.stuck = None
        if stuck is not None and stuck[0].size:
            index = np.asarray(stuck[0], np.int64)
            self.stuck = (up(np.stack([index // cols, index % cols], axis=1)), up(np.asarray(stuck[1], np.float64)))

    def with_means(self, noisy_e=None, exact_e=None) -> "DevicePlan":
        """This plan with the mean charge (the scene) taken from arrays already on the GPU, without a copy.

        Parameters
        ----------
        noisy_e, exact_e : GPU array (rows, cols) float32, e-, optional
            The mean charge shot noise acts on, and that entering without it (the plan's ``noisy_e`` and
            ``exact_e``): anything with ``__cuda_array_interface__`` (a PyTorch or CuPy tensor, a numba device
            array), or a DLPack capsule's owner where PyTorch can read it. None keeps the plan's own; each must be
            given where the plan has one (the plan's stages decide which exist).

        The arrays are read, never copied or kept beyond the plan.
        """
        import copy

        other = copy.copy(self)
        for name, value in (("noisy_e", noisy_e), ("exact_e", exact_e)):
            if value is None:
                continue
            if getattr(self.plan, name) is None:
                raise CmosnoiseError(f"{name}: this plan has no {name} (its stages put the charge elsewhere)")
            arr = as_device_array(value, name)
            if arr.shape != self.plan.shape or np.dtype(arr.dtype) != np.float32:
                raise CmosnoiseError(f"{name}: expected a float32 array of {self.plan.shape}, got {arr.dtype} "
                                     f"{tuple(arr.shape)}")
            setattr(other, "noisy" if name == "noisy_e" else "exact", arr)
        return other

    def nbytes(self) -> int:
        """Bytes this plan holds on the device."""
        arrays = [a for v in vars(self).values() for a in (v if isinstance(v, tuple) else (v,))
                  if hasattr(a, "copy_to_host")]
        return int(sum(a.nbytes for a in arrays))

    def render(self, frames, corners=None, shape=None, electrons: bool = False, stream=0):
        """A batch: item ``b`` is frame ``frames[b]`` at corner ``corners[b] = (row0, col0)``, ``shape = (h, w)``.

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

        Returns
        -------
        raw : device array, (B, h, w)
            uint16 DN, or float32 e- with the ADC off (then ``electrons`` is the same array). Each item equals
            ``kernel.render(plan, frame, region)`` with the stuck pixels set, bit for bit.
        electrons : device array (B, h, w) float32, or None
        """
        cuda = self.k.cuda
        plan = self.plan
        rows, cols = plan.shape
        frames = np.atleast_1d(np.asarray(frames, np.int64))
        if frames.ndim != 1 or frames.size == 0:
            raise ValueError(f"frames: expected one frame number or a list of them, got shape {frames.shape}")
        if frames.min() < 0 or frames.max() > 2**32 - 1:
            raise ValueError("frames: frame numbers must be 0 to 2**32 - 1")
        n = frames.size
        corners = np.zeros((n, 2), np.int64) if corners is None else np.asarray(corners, np.int64).reshape(n, 2)
        h, w = (rows, cols) if shape is None else (int(shape[0]), int(shape[1]))
        if h < 1 or w < 1 or corners.min() < 0 or (corners[:, 0] + h).max() > rows or (corners[:, 1] + w).max() > cols:
            raise ValueError(f"regions of {h} x {w} at corners {corners.tolist()[:4]}... do not fit in {rows} x {cols}")
        flags = kernel.switches(plan, electrons, self.traps is not None, self.blinkers is not None)
        has_row, has_col, adc_on, want_e = (bool(flags[i]) for i in (3, 4, 5, 6))
        d_frames, d_corners = cuda.to_device(frames, stream=stream), cuda.to_device(corners, stream=stream)
        rowval = cuda.device_array((n, h) if has_row else (1, 1), np.float64, stream=stream)
        colterm = cuda.device_array((n, w) if has_col else (1, 1), np.float64, stream=stream)
        cell_black = cuda.device_array((n, 4), np.float64, stream=stream)
        k_adc, black, top = plan.adc if adc_on else (1.0, 0.0, 0)
        with strict_arithmetic():
            span = h + w + 4
            self.k.lines[((span + 63) // 64, n), (64, 1), stream](
                d_frames, d_corners, h, w, plan.sequence, self.keys, has_row, float(plan.row_sigma_e or 0.0),
                self.row_offset, has_col, self.col_sigma, self.col_offset, float(black), self.cell_offsets,
                float(plan.frame_black_sigma_dn), rowval, colterm, cell_black)
            rts_sum = cuda.device_array((1, 1), np.float64, stream=stream)
            if self.traps is not None:
                t = self.traps
                values = cuda.device_array((n, t.index.size), np.float64, stream=stream)
                k0, k1 = (np.uint64(v) for v in plan.trap_key)
                cds = plan.cds_interval_s is not None
                self.k.trap_values[((t.index.size + 127) // 128, n), (128, 1), stream](
                    d_frames, d_corners, h, w, cols, np.uint64(plan.sequence), *self.trap_arrays,
                    float(plan.frame_period_s), float(plan.cds_interval_s or 0.0), cds, k0, k1, values)
                npix = self.rts_col.size
                rts_sum = cuda.device_array((n, npix), np.float64, stream=stream)
                self.k.pixel_sums[((npix + 127) // 128, n), (128, 1), stream](
                    self.trap_first, self.trap_arrays[3], d_corners, h, w, cols, values, rts_sum)
            blink_extra = cuda.device_array((1, 1), np.float64, stream=stream)
            if self.blinkers is not None:
                t = self.blinkers
                blink_extra = cuda.device_array((n, t.index.size), np.float64, stream=stream)
                k0, k1 = (np.uint64(v) for v in plan.blink_key)
                self.k.blink_values[((t.index.size + 127) // 128, n), (128, 1), stream](
                    d_frames, d_corners, h, w, cols, np.uint64(plan.sequence), *self.blink_arrays,
                    float(plan.frame_period_s), float(plan.exposure_s), k0, k1, blink_extra)
            out_dn = cuda.device_array((n, h, w) if adc_on else (1, 1, 1), np.uint16, stream=stream)
            out_e = cuda.device_array((n, h, w) if want_e else (1, 1, 1), np.float32, stream=stream)
            a, b_, c_ = self.nl_abc
            grid = ((w + self.block - 1) // self.block, h, n)
            self.k.pixels[grid, (self.block, 1, 1), stream](
                self.noisy, self.exact, cuda.to_device(flags, stream=stream), float(plan.normal_above_e),
                float(plan.full_well_e), self.sf, rowval, colterm, self.col_gain, self.keys, d_frames, d_corners,
                plan.sequence, h, w, cols, float(k_adc), cell_black, float(top), self.nl, float(self.nl_scale),
                a, b_, c_,
                self.offset, self.read_kind, float(self.read_scale), self.read_table, self.rts_ptr, self.rts_col,
                rts_sum, self.blink_ptr, self.blink_col, blink_extra, out_dn, out_e)
            raw = out_dn if adc_on else out_e
            if self.stuck is not None:
                where, value = self.stuck
                self.k.stick[((value.size + 127) // 128, n), (128, 1), stream](where, value, d_corners, raw)
        return raw, (out_e if want_e else None)
