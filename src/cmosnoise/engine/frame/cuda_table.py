"""The GPU kernel's table of per-plan numbers, by column name, and what the device's sources call ``np``.

Shared by the host side (:mod:`.cuda_kernel`, which fills :attr:`DevicePlan.numbers` and ``ints`` column by
column) and the device side (:mod:`.cuda_device`, whose kernels read them by the same names), so that neither
imports the other for them.
"""

from __future__ import annotations

import collections
import types

import numpy as np

from ..jit import numba
from .plan import INTS, NUMBERS

#: the indices of :attr:`DevicePlan.numbers`' columns, each plan's scalars (float64), by name (:data:`.plan.NUMBERS`,
#: derived from the stages' table). The host fills a row by these names (:func:`row`); the device reads the indices.
_NUMBER = {name: i for i, name in enumerate(NUMBERS)}
NORMAL_ABOVE, FULL_WELL, K_ADC, BLACK = _NUMBER["normal_above"], _NUMBER["full_well"], _NUMBER["k_adc"], _NUMBER["black"]
TOP, STEP, NL_SCALE, NL_A = _NUMBER["top"], _NUMBER["step"], _NUMBER["nl_scale"], _NUMBER["nl_a"]
NL_B, NL_C, READ_SCALE, ROW_SIGMA = _NUMBER["nl_b"], _NUMBER["nl_c"], _NUMBER["read_scale"], _NUMBER["row_sigma"]
FRAME_BLACK_SIGMA, FRAME_PERIOD = _NUMBER["frame_black_sigma"], _NUMBER["frame_period"]
CDS_INTERVAL, EXPOSURE = _NUMBER["cds_interval"], _NUMBER["exposure"]
#: the indices of :attr:`DevicePlan.ints`' columns (int64), by name (:data:`.plan.INTS`)
_INT = {name: i for i, name in enumerate(INTS)}
READ_KIND, NL_SIZE, CDS = _INT["read_kind"], _INT["nl_size"], _INT["cds"]


#: What the line and pixel kernels read of a :class:`.cuda_kernel.DevicePlan`, by name: its plans' arrays on the
#: GPU, stacked (P, ...), uploaded once: the means ``noisy``, ``exact`` and the source follower's ``sf`` (float32
#: (P, rows, cols)); the table's ``ints`` and ``numbers``; the row offsets, the columns' sigma, offset and gain
#: (float64); the black level's ``cell_offsets`` (P, 4); the ``keys`` (P, len(KEY_ROWS), 2) and each plan's frame
#: series ``seqs``; the curve and read-noise tables ``nl`` and ``read_table``; the pixel ``offset`` map; the
#: traps' and the blinking pixels' row lists (``rts_ptr``, ``rts_col``, ``trap_groups``; ``blink_ptr``,
#: ``blink_col``, ``blink_start``). numba passes a named tuple of device arrays to a kernel field by field, as it
#: passes arguments.
Shared = collections.namedtuple("Shared", (
    "noisy", "exact", "sf", "ints", "numbers", "row_offset", "col_sigma", "col_offset", "col_gain", "cell_offsets",
    "keys", "seqs", "nl", "offset", "read_table", "rts_ptr", "rts_col", "trap_groups", "blink_ptr", "blink_col",
    "blink_start"))
#: What they read of one launch, by name: each item's ``frames``, plan (``which``) and ``corners`` (B, 2); the
#: items' ``h`` x ``w`` of a frame ``cols`` wide; the plans' ``flags`` (P, len(SWITCHES)) for this launch; the
#: items' row terms ``rowval`` (B, h), column terms ``colterm`` (B, w) and ``cell_black`` (B, 4) that the line
#: kernel makes for the pixel kernel; the trapped pixels' sums ``rts_sum`` and the blinking pixels'
#: ``blink_extra`` (B, ...), made by the telegraph kernels; ``offsets_of`` (B,): the row of ``Shared``'s
#: ``row_offset``, ``col_offset`` and ``offset`` each item reads (its plan's, or, where offsets change from frame
#: to frame, the item's own row of a launch's arrays: :meth:`.cuda_kernel.DevicePlan.render`).
Items = collections.namedtuple("Items", (
    "frames", "which", "corners", "h", "w", "cols", "flags", "rowval", "colterm", "cell_black", "rts_sum",
    "blink_extra", "offsets_of"))


def row(columns: tuple[str, ...], values: dict) -> list:
    """One plan's row of a table: ``values`` (name -> value) in the order of ``columns`` (:data:`NUMBERS` or
    :data:`INTS`).

    Parameters
    ----------
    columns : tuple of str
        The table's column names.
    values : dict
        A value for each of them, and no other.

    Returns
    -------
    list
        The values in the columns' order.
    """
    if values.keys() != set(columns):  # a column added to one of the two and not the other
        raise RuntimeError(f"a GPU table row gives {sorted(values)}, its columns are {sorted(columns)}")
    return [values[name] for name in columns]


def simulated() -> bool:
    """Whether numba's CUDA simulator stands in for a GPU (``NUMBA_ENABLE_CUDASIM=1``)."""
    return numba is not None and bool(numba.config.ENABLE_CUDASIM)  # type: ignore[attr-defined]


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
    for name, function in (("floor", lib.floor), ("rint", lib.rint), ("abs", lib.fabs), ("sqrt", lib.sqrt),
                           ("maximum", lib.fmax)):
        setattr(shim, name, function)
    return shim
