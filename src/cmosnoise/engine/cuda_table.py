"""The GPU kernel's table of per-plan numbers, by column name, and what the device's sources call ``np``.

Shared by the host side (:mod:`.cuda_kernel`, which fills :attr:`DevicePlan.numbers` and ``ints`` column by
column) and the device side (:mod:`.cuda_device`, whose kernels read them by the same names), so that neither
imports the other for them.
"""

from __future__ import annotations

import types

import numpy as np

from .jit import numba

#: the columns of :attr:`DevicePlan.numbers`, each plan's scalars (float64): the Poisson draw's normal
#: approximation from, the full well (e-); K (DN/e-), black level (DN), the ADC's top code and the output DN per ADC
#: code; the curve's charge scale and cubic; the read noise's scale (DN); the row noise's sigma (e-), the black
#: level's error per frame (DN); the frame period, CDS interval and exposure (s; telegraph noise and blinking pixels)
(NORMAL_ABOVE, FULL_WELL, K_ADC, BLACK, TOP, STEP, NL_SCALE, NL_A, NL_B, NL_C, READ_SCALE, ROW_SIGMA,
 FRAME_BLACK_SIGMA, FRAME_PERIOD, CDS_INTERVAL, EXPOSURE) = range(16)
#: the columns of :attr:`DevicePlan.ints` (int64): the read noise's law (0 normal, 1 Tukey-lambda), the curve
#: table's length (2: the cubic), whether the traps are read by CDS
READ_KIND, NL_SIZE, CDS = range(3)


def simulated() -> bool:
    """Whether numba's CUDA simulator stands in for a GPU (``NUMBA_ENABLE_CUDASIM=1``)."""
    return numba is not None and bool(numba.config.ENABLE_CUDASIM)


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
