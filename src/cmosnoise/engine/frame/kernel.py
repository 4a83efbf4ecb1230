"""The fused frame kernel: one pass from mean charge to raw codes, compiled by numba.

For each pixel of a frame (or of a region of it): the Poisson draw of photo
plus dark charge (or its mean where shot noise is off), the full-well clip,
one normal with the pixel's fixed source-follower sigma, the row term, the
column gain and column term, and the ADC, in one loop, parallel over rows.
The arithmetic is that of :mod:`.samplers` and the stage modules, in the same
order, so the result equals the NumPy implementation bit for bit; the
helpers of :mod:`.fdmath` and :mod:`.samplers` are compiled from their own
source (see :func:`compile_helpers`), not copied. Where numba is not installed,
:func:`render` falls back to the NumPy implementation (slower, same bits).

numba's own ``np.random`` keeps per-thread state inside a parallel loop, so
its results would depend on the thread count: hence the counter-based
generator. ``fastmath`` is off: no fused multiply-add, no reordering.
"""

from __future__ import annotations

import collections
import functools
import logging
import time
import types
from typing import Any

import numpy as np

from .. import fdmath, jit, map_values, philox, samplers, telegraph
from ..jit import ONE_LAUNCH, announce, numba  # None where numba is not installed
from . import plan as _stages  # the module of the stages' table (numba's cache of the kernel is keyed on it)
from .plan import (  # the plan, and the switches' and key rows' indices its table derives by name
    KEY_BLACK,
    KEY_COL,
    KEY_ROW,
    KEY_ROWS,
    KEY_SF,
    KEY_SHOT,
    N_SWITCHES,
    S_ADC,
    S_BLINK_EXACT,
    S_BLINKERS,
    S_COL,
    S_ELECTRONS,
    S_EXACT,
    S_NL,
    S_NOISY,
    S_OFFSET,
    S_READ,
    S_ROW,
    S_SF,
    S_TRAPS,
    FramePlan,
    switches,
)

_logger = logging.getLogger(__name__)  # cmosnoise.*: the command line shows it on stderr (app/logs.said)

#: whether the compiled kernel can run here
AVAILABLE = numba is not None


#: The frame kernel's inputs from a plan, by name: what every frame of an exposure shares (the mean charges, the
#: maps, the tables, the ADC) and the frame's sparse telegraph pixels, one value a field (:func:`render` fills it
#: from a :class:`FramePlan`). The compiled loops read each by its name; numba passes a named tuple's fields as it
#: passes arguments. The fields: the means (``noisy`` and ``exact`` e-, float32 (h, w)); ``flags`` (:data:`.plan.SWITCHES`);
#: shot noise's ``normal_above`` and the ``full_well`` (e-); ``sf`` (the source follower's sigma map); the row
#: noise's ``row_sigma`` and ``row_offset``; the columns' ``col_sigma``, ``col_offset`` and ``col_gain``; ``keys``
#: (:data:`.plan.KEY_ROWS`); the ADC's ``k_adc`` (DN/e-), ``black`` (DN), ``top`` (its largest code) and ``step``; the
#: Poisson sampler's ``loggam_table``; the charge's nonlinearity (``nl_table``, ``nl_scale``, ``nl_a``, ``nl_b``,
#: ``nl_c``); the pixel ``offset`` map; the black level's ``cell_offsets`` and ``frame_black_sigma``; the read noise
#: (``read_kind``, ``read_scale``, ``read_table``); the traps' and the blinking pixels' sparse rows (``rts_ptr``,
#: ``rts_col``, ``rts_val``; ``blink_ptr``, ``blink_col``, ``blink_mean``).
Inputs = collections.namedtuple("Inputs", (
    "noisy", "exact", "flags", "normal_above", "full_well", "sf", "row_sigma", "row_offset", "col_sigma",
    "col_offset", "col_gain", "keys", "k_adc", "black", "top", "step", "loggam_table", "nl_table", "nl_scale",
    "nl_a", "nl_b", "nl_c", "offset", "cell_offsets", "frame_black_sigma", "read_kind", "read_scale", "read_table",
    "rts_ptr", "rts_col", "rts_val", "blink_ptr", "blink_col", "blink_mean"))
#: Where a call of the frame kernel draws: the ``frame`` and the frame series (``seq``), the region (``r0``, ``r1``,
#: ``c0``, ``c1``) of a frame ``cols`` wide, and the plan arrays' first row and column in the frame (``ar0``,
#: ``ac0``: a tile's window).
Where = collections.namedtuple("Where", ("frame", "seq", "r0", "r1", "c0", "c1", "cols", "ar0", "ac0"))


# ------------------------------------------------------------------ compiled helpers
#: the helpers compiled from their own source, module by module, callees first
HELPERS = [(philox, ["philox4x32", "open_uniform", "uniform_pair"]),
           (fdmath, ["log", "exp", "_kernel_sin", "_kernel_cos", "sincos_turn", "cos_turn", "loggam"]),
           (telegraph, ["decay", "one_minus", "transition", "_bridge_weights", "bridge", "midpoint", "_uniform",
                        "frame_states", "inside", "occupancy_uniform", "occupancy_r_n", "occupancy_events",
                        "occupancy_walk", "occupancy"]),
           (samplers, ["normal_from", "normal_pair_from", "tukey_lambda_cell", "tukey_lambda_at", "ptrs_constants",
                       "ptrs_candidate", "ptrs_quick_accept", "ptrs_early_reject", "ptrs_log_test", "ptrs_log_accept",
                       "ptrs_try", "poisson_one"]),
           (map_values, ["ppf_cell", "heavy_tail_value", "two_point", "normal_value", "offset_value"])]


def compile_helpers(jit, numpy=np, skip=()) -> dict:
    """The helpers of fdmath, philox, telegraph and samplers compiled by ``jit`` from their own source.

    Each function is re-created with its module's globals, where the exact
    array helpers (``frexp``, ``ldexp``, ``where``) are replaced by their
    scalar forms and every callee by its compiled version. ``jit`` is the
    target's decorator: numba's ``njit`` for the CPU (``inline="always"``
    for the hot loops: inlined into numba's IR before typing, so LLVM
    vectorizes them; ``"never"`` for the rare paths), or ``cuda.jit(device=True)``
    for the GPU (:mod:`.cuda_kernel`). ``numpy`` stands for ``np`` in their
    sources: the CUDA target has no scalar ufuncs and passes a namespace of
    scalar equivalents (the same IEEE results). ``skip``: names the target
    cannot compile (the GPU has no ``occupancy``: it allocates). Inlining does
    not change IEEE arithmetic, so the bits are the same either way.
    """
    space: dict = {}

    def where(c, a, b):
        return a if c else b

    def ldexp(y, k):  # y * 2**k for whole |k| < 1023 and y in [0.5, 2): build 2**k from its bits
        # k + 1023 + 2**52 is exact and holds k + 1023 in its low mantissa bits; shifted up 52 they are 2**k's
        # exponent field. No float-to-integer conversion, which AVX2 lacks for 64-bit lanes.
        biased = np.float64(k + 4503599627371519.0).view(np.uint64)  # 2**52 + 1023
        return y * np.uint64(biased << np.uint64(52)).view(np.float64)

    def frexp(x):  # x = m 2**e, m in [0.5, 1), for positive normal x: read the bits, no libm call
        bits = np.float64(x).view(np.uint64)
        e = np.int64((bits >> np.uint64(52)) & np.uint64(0x7FF)) - 1022
        m = np.uint64((bits & np.uint64(0x000FFFFFFFFFFFFF)) | np.uint64(0x3FE0000000000000)).view(np.float64)
        return m, e

    scalar = {"frexp": jit(frexp), "ldexp": jit(ldexp), "where": jit(where), "floor": numpy.floor, "np": numpy}

    for module, names in HELPERS:
        for name in names:
            if name in skip:
                continue
            f = getattr(module, name)
            g = {**module.__dict__, **scalar, **space}
            space[name] = jit(types.FunctionType(f.__code__, g, name, f.__defaults__))
    return space


if numba is not None:
    _h = compile_helpers(numba.njit(inline="always", fastmath=False, error_model="numpy"))
    _cold = compile_helpers(numba.njit(inline="never", fastmath=False, error_model="numpy"))  # for the tries past the vectorized ones, a few pixels in 10 000
    _cold_uniform_pair, _cold_normal_from, _cold_constants, _cold_ptrs_try = (
        _cold[name] for name in ("uniform_pair", "normal_from", "ptrs_constants", "ptrs_try"))
    _uniform_pair, _normal_from, _exp, _log = _h["uniform_pair"], _h["normal_from"], _h["exp"], _h["log"]
    _normal_pair_from, _tukey_lambda_cell = _h["normal_pair_from"], _h["tukey_lambda_cell"]
    _ptrs_constants, _ptrs_candidate, _ptrs_log_test = _h["ptrs_constants"], _h["ptrs_candidate"], _h["ptrs_log_test"]
    _ptrs_quick_accept, _ptrs_early_reject = _h["ptrs_quick_accept"], _h["ptrs_early_reject"]
    _INV_MAX, _PTRS_FROM = samplers.INVERSION_MAX, samplers.PTRS_FROM

    @numba.njit(inline="always", fastmath=False, error_model="numpy")
    def _tukey_parts(z, scale):
        """samplers.tukey_lambda_from's arithmetic for a normal ``z``, its table's loads apart: (node, the next
        node's weight, ``scale`` carrying ``z``'s sign). The signed scale times the table's value equals the
        specification's ``scale * (0 - q)`` up to the sign of a zero, which the rounding to a code does not see."""
        kf, w = _tukey_lambda_cell(z)
        return np.int64(kf), w, (0.0 - scale if z < 0.0 else scale)

    @numba.njit(fastmath=False, error_model="numpy")
    def _normal(index, frame, seq, k0, k1):
        """One normal: a row's or a column's (once a row or column, so called, not inlined)."""
        u1, u2 = _cold_uniform_pair(np.uint64(index), frame, seq, np.uint64(0), k0, k1)
        return _cold_normal_from(u1, u2)

    @numba.njit(fastmath=False, error_model="numpy")
    def _ptrs_from(lam, index, frame, seq, k0, k1, attempt):
        """PTRS from try ``attempt`` on (samplers.Stream.poisson's loop of samplers.ptrs_try); a rare path, its
        helpers called, not inlined."""
        loglam, a, b, invalpha, vr = _cold_constants(lam)
        while True:
            u1, u2 = _cold_uniform_pair(index, frame, seq, attempt, k0, k1)
            attempt += np.uint64(1)
            k, ok = _cold_ptrs_try(lam, loglam, a, b, invalpha, vr, u1, u2)
            if ok:
                return k

    _JIT: dict[str, Any] = dict(fastmath=False, error_model="numpy")
    _ROWS_PER_BLOCK = 8
    _frame_states, _inside, _occupancy, _cold_exp = (_cold[name] for name in ("frame_states", "inside", "occupancy",
                                                                              "exp"))

    @numba.njit(parallel=True, cache=True, nogil=True, **_JIT)
    def _trap_values(frame, seq, up, down, size, index, slot, dt, interval, cds, k0, k1, out):
        """random_telegraph.trap_output, compiled: what each trap adds to frame ``frame`` (e-)."""
        for t in numba.prange(out.size):
            x, y = _frame_states(frame, up[t], down[t], dt, index[t], slot[t], seq, k0, k1)
            if cds:
                sig = _inside(frame, x, y, up[t], down[t], dt, interval, index[t], slot[t], seq, k0, k1)
                out[t] = size[t] * (sig - x)
            else:
                out[t] = size[t] * x

    @numba.njit(parallel=True, cache=True, nogil=True, **_JIT)
    def _blink_values(frame, seq, up, down, size, index, slot, dt, exposure, k0, k1, out):
        """random_telegraph.blink_charge, compiled: each blinking pixel's extra dark charge in frame ``frame`` (e-)."""
        for t in numba.prange(out.size):
            x, y = _frame_states(frame, up[t], down[t], dt, index[t], slot[t], seq, k0, k1)
            end = _inside(frame, x, y, up[t], down[t], dt, exposure, index[t], slot[t], seq, k0, k1)
            out[t] = size[t] * _occupancy(frame, x, end, up[t], down[t], exposure, index[t], slot[t], seq, k0, k1)

    #: one pixel's count (samplers.poisson_one: a blinking pixel's mean of this frame), a call
    _poisson_one = _cold["poisson_one"]

    #: a try the branch-free pass leaves undecided (its log test met a count past the loggam table)
    _REDO = -2.0

    @numba.njit(inline="always", **_JIT)
    def _ptrs_count(m, a, b, u1, u2):
        """A PTRS try's candidate count: the first of the try's passes, which store it (the last pass takes the
        candidate again: a division more per try, and the candidate's arithmetic kept in one place)."""
        return _ptrs_candidate(m, a, b, u1, u2)[0]

    @numba.njit(inline="always", **_JIT)
    def _ptrs_loggam(k, table):
        """``loggam(max(k, 0) + 1)`` from ``table`` (:func:`samplers.loggam_table`), the table's last entry past it.

        Its own pass, a load per try: LLVM does not vectorize a loop that
        indexes a table, so the passes on either side are kept free of it.
        """
        return table[np.uint32(min(max(k, 0.0) + 1.0, np.float64(table.size - 1)))]

    @numba.njit(inline="always", **_JIT)
    def _ptrs_test(m, loglam, a, b, log_invalpha, vr, u1, u2, loggam_k1, last):
        """One whole PTRS try, branch-free (samplers.ptrs_try), the pixel's constants given: the count if
        accepted, -1 if rejected, _REDO if undecided.

        ``loggam_k1`` is :func:`_ptrs_loggam`'s: a load instead of loggam's
        log, two divisions and series, the same bits. A try whose log test
        meets a count past the table's ``last`` (about one in a million) is
        _REDO, for :func:`_ptrs_test_exact`.
        """
        k, us, V = _ptrs_candidate(m, a, b, u1, u2)
        quick, reject = _ptrs_quick_accept(us, V, vr), _ptrs_early_reject(k, us, V)
        kk = max(k, 0.0)
        ok = quick | (~reject & _ptrs_log_test(m, loglam, a, b, log_invalpha, kk, us, V, loggam_k1))
        decided = quick | reject | (kk + 1.0 <= last)
        return (k if ok else -1.0) if decided else _REDO

    @numba.njit(**_JIT)
    def _ptrs_test_exact(m, u1, u2):
        """One whole PTRS try with loggam computed (samplers.ptrs_try): the count if accepted, else -1."""
        loglam, a, b, invalpha, vr = _cold_constants(m)
        k, ok = _cold_ptrs_try(m, loglam, a, b, invalpha, vr, u1, u2)
        return k if ok else -1.0

    @numba.njit(inline="always", **_JIT)
    def _shot_row(noisy_row, base, frame, seq, k0, k1, lam, u1, u2, res, small, big, normal_above):
        """Shot noise of one row, first pass: every pixel's first PTRS quick test, branch-free (SIMD).

        Leaves the count in ``res`` where the quick test accepts (or the normal
        approximation applies), -1 elsewhere; the positions left go to
        ``small`` (mean below 10: inversion) and ``big`` (PTRS retries).
        Returns how many of each.
        """
        w = lam.size
        zero = np.uint64(0)
        for j in range(w):
            m = np.float64(noisy_row[j])
            v1, v2 = _uniform_pair(base + np.uint64(j), frame, seq, zero, k0, k1)
            lam[j] = m
            u1[j] = v1
            u2[j] = v2
            loglam, a, b, invalpha, vr = _ptrs_constants(m)
            k, us, V = _ptrs_candidate(m, a, b, v1, v2)
            quick = _ptrs_quick_accept(us, V, vr) & (m >= _PTRS_FROM)
            res[j] = k if quick else -1.0
        if normal_above < np.inf:
            for j in range(w):
                m = lam[j]
                z = _normal_from(u1[j], u2[j])
                approx = max(np.rint(m + np.sqrt(m) * z), 0.0)
                res[j] = approx if m > normal_above else res[j]
        ns = 0
        nb = 0
        for j in range(w):  # branch-free compaction: write always, advance where it belongs
            left = res[j] < 0.0
            low = lam[j] < _PTRS_FROM
            small[ns] = j
            big[nb] = j
            ns += 1 if (left & low) else 0
            nb += 1 if (left & ~low) else 0
        return ns, nb

    _LANES = 16
    _VECTOR_TRIES = np.uint64(3)  # PTRS tries made in SIMD passes over the pixels left; then one by one

    @numba.njit(inline="always", **_JIT)
    def _inversion_lanes(m, u, out, p, total):
        """Poisson by inversion (samplers.poisson_inversion) for _LANES pixels at once, until all are done.

        ``p`` and ``total`` are scratch lanes of the caller's (an array made here, at every call, cost a heap
        allocation per _LANES pixels: a third of the inversion's time, measured)."""
        for q in range(_LANES):
            p[q] = _exp(-m[q])
            total[q] = p[q]
            out[q] = 0.0
        kk = 0.0
        while kk < _INV_MAX:
            kk = kk + 1.0
            busy = False
            for q in range(_LANES):
                on = u[q] > total[q]
                pn = p[q] * m[q] / kk
                tn = total[q] + pn
                p[q] = pn if on else p[q]
                total[q] = tn if on else total[q]
                out[q] = kk if on else out[q]
                busy = busy | on
            if not busy:
                break

    @numba.njit(inline="always", **_JIT)
    def _shot_rest(lam, u1, u2, res, small, ns, big, nb, buf, lanes, table, base, frame, seq, k0, k1):
        """The pixels the first pass left: inversion below 10 in SIMD lanes; PTRS: all of try 0, tries 1 and 2, then one by one.

        Pixels are copied into the contiguous rows of ``buf`` (10, width)
        before the branch-free passes: LLVM vectorizes a pass over contiguous
        memory, not one through an index list. PTRS's per-pixel constants
        (two logs, a square root, two divisions) are taken once there, not
        at every try.
        """
        bl, bu1, bu2, bk, bll, ba, bb, blia, bvr, bg = (buf[0], buf[1], buf[2], buf[3], buf[4], buf[5], buf[6],
                                                        buf[7], buf[8], buf[9])
        last = np.float64(table.size - 1)
        m, u, got, p, total = lanes[0], lanes[1], lanes[2], lanes[3], lanes[4]
        for t0 in range(0, ns, _LANES):  # inversion, _LANES pixels at a time (the last lanes padded)
            for q in range(_LANES):
                t = min(t0 + q, ns - 1)
                m[q] = lam[small[t]]
                u[q] = u1[small[t]]
            _inversion_lanes(m, u, got, p, total)
            for q in range(min(_LANES, ns - t0)):
                res[small[t0 + q]] = got[q]
        for t in range(nb):
            j = big[t]
            bl[t] = lam[j]
            bu1[t] = u1[j]
            bu2[t] = u2[j]
        for t in range(nb):
            loglam, a, b, invalpha, vr = _ptrs_constants(bl[t])
            bll[t] = loglam
            ba[t] = a
            bb[t] = b
            blia[t] = _log(invalpha)
            bvr[t] = vr
        attempt = np.uint64(0)
        while nb:  # PTRS: the whole of try 0 where the quick test did not accept, then tries 1 and 2
            if attempt > 0:
                for t in range(nb):
                    bu1[t], bu2[t] = _uniform_pair(base + np.uint64(big[t]), frame, seq, attempt, k0, k1)
            for t in range(nb):  # one whole try, branch-free, in three passes
                bk[t] = _ptrs_count(bl[t], ba[t], bb[t], bu1[t], bu2[t])
            for t in range(nb):
                bg[t] = _ptrs_loggam(bk[t], table)
            for t in range(nb):
                bk[t] = _ptrs_test(bl[t], bll[t], ba[t], bb[t], blia[t], bvr[t], bu1[t], bu2[t], bg[t], last)
            for t in range(nb):  # the few it left undecided, exactly
                if bk[t] == _REDO:
                    bk[t] = _ptrs_test_exact(bl[t], bu1[t], bu2[t])
            attempt += np.uint64(1)
            nf = 0
            for t in range(nb):  # keep the pixels still without a count (branch-free compaction)
                j = big[t]
                res[j] = bk[t]
                big[nf] = j
                bl[nf] = bl[t]
                bll[nf] = bll[t]
                ba[nf] = ba[t]
                bb[nf] = bb[t]
                blia[nf] = blia[t]
                bvr[nf] = bvr[t]
                nf += 1 if bk[t] < 0.0 else 0
            nb = nf
            if attempt == _VECTOR_TRIES:
                break
        for t in range(nb):  # further tries, one pixel at a time (a few in 10 000)
            res[big[t]] = _ptrs_from(bl[t], base + np.uint64(big[t]), frame, seq, k0, k1, attempt)

    @numba.njit(**_JIT)
    def _render_rows(i0, i1, p, at, colterm, gain, fr, sq, cell_black, out_dn, out_e):  # noqa: C901 - one fused pass
        """Rows ``i0`` to ``i1`` of the region (one thread's block): every stage of each row, in order.

        Compiled on its own, not inside :func:`_render`'s parallel loop: numba's
        parfor passes then see a loop of calls, not the inlined samplers, which
        saves some 30 s of the first compile (measured); LLVM vectorizes this
        function's loops alike. ``p`` (:data:`Inputs`) and ``at`` (:data:`Where`) are read by name; ``colterm``,
        ``gain`` and ``cell_black`` are the frame's, made once by :func:`_render`.
        """
        noisy, exact, flags, normal_above, full_well, sf = p.noisy, p.exact, p.flags, p.normal_above, p.full_well, p.sf
        row_sigma, row_offset, keys, k_adc, top, step = p.row_sigma, p.row_offset, p.keys, p.k_adc, p.top, p.step
        loggam_table, nl_table, nl_scale, nl_a, nl_b, nl_c = (p.loggam_table, p.nl_table, p.nl_scale, p.nl_a, p.nl_b,
                                                              p.nl_c)
        offset, read_kind, read_scale, read_table = p.offset, p.read_kind, p.read_scale, p.read_table
        rts_ptr, rts_col, rts_val, blink_ptr, blink_col, blink_mean = (p.rts_ptr, p.rts_col, p.rts_val, p.blink_ptr,
                                                                       p.blink_col, p.blink_mean)
        r0, c0, c1, cols, ar0, ac0 = at.r0, at.c0, at.c1, at.cols, at.ar0, at.ac0
        has_noisy, has_exact, has_sf, has_row, has_col, adc_on, want_e = (
            flags[S_NOISY], flags[S_EXACT], flags[S_SF], flags[S_ROW], flags[S_COL], flags[S_ADC], flags[S_ELECTRONS])
        has_nl, has_offset, has_read = flags[S_NL], flags[S_OFFSET], flags[S_READ]
        has_rts, has_blink, blink_exact = flags[S_TRAPS], flags[S_BLINKERS], flags[S_BLINK_EXACT]
        nl_last = np.float64(nl_table.size - 2)
        inv_step = 1.0 / step  # exact: the step is a power of two
        zero = np.uint64(0)
        w = c1 - c0
        s0, s1, f0, f1 = keys[KEY_SHOT, 0], keys[KEY_SHOT, 1], keys[KEY_SF, 0], keys[KEY_SF, 1]
        one_black = cell_black[0] == cell_black[1] == cell_black[2] == cell_black[3]
        laid_out = 0 if (one_black and not has_read) else w  # only the per-pixel ADC pass reads them
        black_even = np.empty(laid_out)  # the black level of each pixel of an even row, and of an odd one (CFA cells)
        black_odd = np.empty(laid_out)
        for j in range(laid_out):
            black_even[j] = cell_black[(c0 + j) & 1]
            black_odd[j] = cell_black[2 + ((c0 + j) & 1)]
        lam = np.empty(w)
        u1 = np.empty(w)
        u2 = np.empty(w)
        small = np.empty(w, np.int64)
        big = np.empty(w, np.int64)
        buf = np.empty((10, w))
        lanes = np.empty((5, _LANES))  # _shot_rest's inversion lanes: means, uniforms, counts, and two scratch
        n = np.zeros(w)
        saved = np.empty(w if (has_blink and blink_exact) else 0)  # a row's counts of its blinking pixels
        noise = np.empty(w)
        tukey = has_read and read_kind == 1
        partner = np.empty(w if has_read and not tukey else 0)  # normal read noise, DN: the scale times the sine
        #                                                         normals of the source follower's blocks
        cell = np.empty(w if tukey else 0, np.int64)  # Tukey-lambda read noise: each sine normal's table node,
        weight = np.empty(w if tukey else 0)  # the next node's weight,
        scale = np.empty(w if tukey else 0)  # and the scale with the normal's sign
        a0, a1 = c0 - ac0, c1 - ac0  # the region's columns in the arrays
        for i in range(i0, i1):
            r = r0 + i
            ra = r - ar0  # the row in the arrays
            base = np.uint64(r * cols + c0)
            if has_noisy:
                ns, nb = _shot_row(noisy[ra, a0:a1], base, fr, sq, s0, s1, lam, u1, u2, n, small, big, normal_above)
                _shot_rest(lam, u1, u2, n, small, ns, big, nb, buf, lanes, loggam_table, base, fr, sq, s0, s1)
                if has_blink and not blink_exact:  # stage 4b: a blinking pixel's count at this frame's mean
                    for e in range(blink_ptr[i], blink_ptr[i + 1]):
                        j = blink_col[e]
                        n[j] = _poisson_one(np.float64(blink_mean[e]), base + np.uint64(j), fr, sq, s0, s1,
                                            normal_above)
            if has_exact:
                if has_blink and blink_exact:
                    for e in range(blink_ptr[i], blink_ptr[i + 1]):
                        saved[e - blink_ptr[i]] = n[blink_col[e]]
                for j in range(w):
                    n[j] = n[j] + np.float64(exact[ra, a0 + j])
                if has_blink and blink_exact:  # stage 4b: a blinking pixel's mean dark charge of this frame
                    for e in range(blink_ptr[i], blink_ptr[i + 1]):
                        n[blink_col[e]] = saved[e - blink_ptr[i]] + np.float64(blink_mean[e])
            if has_nl and nl_table.size > 2:  # the full well, then stage 5b (nonlinearity.Curve.apply): a
                for j in range(w):  # measured curve, linear in its table
                    q = min(n[j], full_well) * nl_scale
                    t = np.int64(min(np.floor(q), nl_last))
                    lo = nl_table[t]
                    n[j] = lo + (q - t) * (nl_table[t + 1] - lo)
            elif has_nl:  # the cubic, as written (in the full well's pass: one pass over the row fewer)
                for j in range(w):
                    x = min(n[j], full_well)
                    sx = x * nl_scale
                    n[j] = x * (1.0 + sx * (nl_a + sx * (nl_b + sx * nl_c)))
            else:
                for j in range(w):
                    n[j] = min(n[j], full_well)
            if has_offset and not has_sf:  # stage 5c (with the source follower: in its last pass, same order)
                for j in range(w):
                    n[j] = n[j] + np.float64(offset[ra, a0 + j])
            if has_sf or has_read:  # the source follower's block: uniforms, then Box-Muller (25 % faster than one
                for j in range(w):  # loop, measured); its cosine normal is stage 6's, its sine normal stage 9a's
                    u1[j], u2[j] = _uniform_pair(base + np.uint64(j), fr, sq, zero, f0, f1)
                # the two loops below differ in their last line only; written out, not shared through an inlined
                # helper writing either array: that helper stopped LLVM vectorizing them (the measured stages
                # +116 % a frame instead of +12 %, bench_measured_stages.py)
                if has_sf and tukey:  # samplers.tukey_lambda_from's arithmetic here (SIMD), its loads in stage 9a
                    for j in range(w):
                        z, z2 = _normal_pair_from(u1[j], u2[j])
                        if has_offset:
                            n[j] = (n[j] + np.float64(offset[ra, a0 + j])) + np.float64(sf[ra, a0 + j]) * z
                        else:
                            noise[j] = np.float64(sf[ra, a0 + j]) * z
                        cell[j], weight[j], scale[j] = _tukey_parts(z2, read_scale)
                elif has_sf and has_read:  # the read noise in DN made here (stage 9a's product, the same bits)
                    for j in range(w):
                        z, z2 = _normal_pair_from(u1[j], u2[j])
                        if has_offset:
                            n[j] = (n[j] + np.float64(offset[ra, a0 + j])) + np.float64(sf[ra, a0 + j]) * z
                        else:
                            noise[j] = np.float64(sf[ra, a0 + j]) * z
                        partner[j] = read_scale * z2
                elif has_sf and has_offset:
                    for j in range(w):
                        n[j] = (n[j] + np.float64(offset[ra, a0 + j])) + (np.float64(sf[ra, a0 + j])
                                                                          * _normal_from(u1[j], u2[j]))
                elif has_sf:
                    for j in range(w):
                        noise[j] = np.float64(sf[ra, a0 + j]) * _normal_from(u1[j], u2[j])
                elif tukey:
                    for j in range(w):
                        cell[j], weight[j], scale[j] = _tukey_parts(_normal_pair_from(u1[j], u2[j])[1], read_scale)
                else:
                    for j in range(w):
                        partner[j] = read_scale * _normal_pair_from(u1[j], u2[j])[1]
            if has_sf and not has_offset:
                for j in range(w):
                    n[j] = n[j] + noise[j]
            if has_rts:  # stage 6b: the traps of this row's pixels
                for e in range(rts_ptr[i], rts_ptr[i + 1]):
                    j = rts_col[e]
                    n[j] = n[j] + rts_val[e]
            if has_row:
                rowval = row_sigma * _normal(r, fr, sq, keys[KEY_ROW, 0], keys[KEY_ROW, 1]) + row_offset[ra]
                for j in range(w):
                    n[j] = n[j] + rowval
            if has_col:
                for j in range(w):
                    n[j] = n[j] * gain[j] + colterm[j]
            if want_e:
                for j in range(w):
                    out_e[i, j] = n[j]
            if adc_on:
                if tukey:  # stage 9a: read noise after the gain, DN (read_noise.noise): the table's loads (a loop
                    for j in range(w):  # that indexes a table is not vectorized; an unsigned node is not tested for
                        k = np.uint64(cell[j])  # wraparound: 25 % faster, measured)
                        lo = read_table[k]
                        noise[j] = scale[j] * (lo + weight[j] * (read_table[k + np.uint64(1)] - lo))
                read = noise if tukey else partner  # stage 9a's noise, DN
                # the ADC rounds its own codes: output DN times 1 / step (exact, a power of two; 1.0 without an
                # output scaling), clipped to its top code, then times the step (adc.convert)
                if one_black and not has_read:  # the paper's ADC: one black level, nothing after the gain
                    b0 = cell_black[0]
                    for j in range(w):
                        v = np.rint((n[j] * k_adc + b0) * inv_step)
                        out_dn[i, j] = np.uint16(min(max(v, 0.0), top) * step)
                else:
                    row_black = black_even if (r & 1) == 0 else black_odd  # this row's cell black levels, laid out
                    for j in range(w):
                        v = n[j] * k_adc + row_black[j]
                        if has_read:
                            v = v + read[j]
                        v = np.rint(v * inv_step)
                        out_dn[i, j] = np.uint16(min(max(v, 0.0), top) * step)
            if not has_noisy:
                n[:] = 0.0

    @numba.njit(parallel=True, cache=True, nogil=True, **_JIT)
    def _render(p, at, out_dn, out_e):
        flags, keys, black, cell_offsets, frame_black_sigma = p.flags, p.keys, p.black, p.cell_offsets, p.frame_black_sigma
        col_sigma, col_offset, col_gain = p.col_sigma, p.col_offset, p.col_gain
        r0, r1, c0, c1, ac0 = at.r0, at.r1, at.c0, at.c1, at.ac0
        fr = np.uint64(at.frame)
        sq = np.uint64(at.seq)
        # the black level of each 2 x 2 cell position in this frame (read_noise.cell_black)
        err = frame_black_sigma * _normal(0, fr, sq, keys[KEY_BLACK, 0], keys[KEY_BLACK, 1]) if frame_black_sigma > 0.0 else 0.0
        cell_black = np.empty(4)
        for q in range(4):
            cell_black[q] = (black + cell_offsets[q]) + err
        w = c1 - c0
        h = r1 - r0
        has_col = flags[S_COL]
        colterm = np.zeros(w)
        gain = np.ones(w)
        if has_col:
            for j in range(w):
                c = c0 + j
                colterm[j] = col_offset[c - ac0] + col_sigma[c - ac0] * _normal(c, fr, sq, keys[KEY_COL, 0], keys[KEY_COL, 1])
                gain[j] = col_gain[c - ac0]
        nblocks = (h + _ROWS_PER_BLOCK - 1) // _ROWS_PER_BLOCK
        for blk in numba.prange(nblocks):
            _render_rows(blk * _ROWS_PER_BLOCK, min(h, (blk + 1) * _ROWS_PER_BLOCK), p, at, colterm, gain, fr, sq,
                         cell_black, out_dn, out_e)

    jit.keyed_on(_render, _stages)  # its switches' and key rows' indices are the stages' table's (plan.py)


if numba is not None:
    _ppf_cell, _heavy_tail_value, _two_point, _normal_value, _offset_value = (
        _h[name] for name in ("ppf_cell", "heavy_tail_value", "two_point", "normal_value", "offset_value"))
    _Z64, _ONE64 = np.uint64(0), np.uint64(1)
    _SCRATCH_BANDS = 256  # bands of rows a heavy-tailed map's parallel loop hands out (each its scratch rows)

    # Each map's row is a function of its own, called (not inlined) from the parallel loop over rows: LLVM
    # vectorizes a row's loops there, and not inside the parallel region (the heavy-tailed map: 12.5 ns a pixel
    # inlined, 6.1 called, one thread). The same arithmetic, so the same bits.
    @numba.njit(**_JIT)
    def _normal_row(out, base, k0, k1, mean, sigma, low):
        for j in range(out.size):
            u1, u2 = _uniform_pair(base + np.uint64(j), _Z64, _Z64, _Z64, k0, k1)
            out[j] = np.float32(_normal_value(u1, u2, mean, sigma, low))

    @numba.njit(parallel=True, cache=True, nogil=True, **_JIT)
    def _normal_map(out, r0, c0, cols, k0, k1, mean, sigma, low):
        """fixed_maps.normal_map, compiled: a rectangle of a normal map, parallel over its rows."""
        for i in numba.prange(out.shape[0]):
            _normal_row(out[i], np.uint64(r0 + i) * cols + np.uint64(c0), k0, k1, mean, sigma, low)

    @numba.njit(cache=True, nogil=True, **_JIT)
    def _line_draws(out, start, k0, k1, normal):
        """fixed_maps.lines, compiled, on one thread (a line map is a single row of draws: a parallel launch would
        cost more than it): line ``start + j``'s standard normal, or its block's first open uniform."""
        for j in range(out.size):
            u1, u2 = _uniform_pair(np.uint64(start) + np.uint64(j), _Z64, _Z64, _Z64, k0, k1)
            out[j] = _normal_from(u1, u2) if normal else u1

    @numba.njit(**_JIT)
    def _offset_row(out, base, k0, k1, sigma, fraction, tail_max):
        for j in range(out.size):
            out[j] = np.float32(_offset_value(base + np.uint64(j), k0, k1, sigma, fraction, tail_max))

    @numba.njit(parallel=True, cache=True, nogil=True, **_JIT)
    def _offset_map(out, r0, c0, cols, k0, k1, sigma, fraction, tail_max):
        """fixed_maps.offset_map, compiled: a rectangle of the pixel offsets, parallel over its rows."""
        for i in numba.prange(out.shape[0]):
            _offset_row(out[i], np.uint64(r0 + i) * cols + np.uint64(c0), k0, k1, sigma, fraction, tail_max)

    @numba.njit(**_JIT)
    def _heavy_tail_row(out, base, k0, k1, start, step, last, tables, params, w, bs, ts, two, top, node, weight,
                        member):
        """A row of a heavy-tailed map: a branch-free pass (block 0, the body's cell: vectorized), then the table
        reads and the tail; block 1 (the tail magnitude) is drawn only for the tail's members (the bits as if
        drawn for all)."""
        width = out.size
        for j in range(width):
            u_body, u_member = _uniform_pair(base + np.uint64(j), _Z64, _Z64, _Z64, k0, k1)
            node[j], weight[j] = _ppf_cell(u_body, start, step, last)
            member[j] = u_member
        for j in range(width):
            u_tail = 0.5  # read only by the tail's members
            if member[j] < top:
                u_tail, _ = _uniform_pair(base + np.uint64(j), _Z64, _Z64, _ONE64, k0, k1)
            k = int(node[j])
            v = _heavy_tail_value(tables[0, k], tables[0, k + 1], weight[j], member[j], u_tail, bs, params[0, 0],
                                  params[0, 1], ts)
            if two:
                v1 = _heavy_tail_value(tables[1, k], tables[1, k + 1], weight[j], member[j], u_tail, 1.0,
                                       params[1, 0], params[1, 1], 1.0)
                v = _two_point(v, v1, params[0, 2], params[1, 2], w)
            out[j] = np.float32(v)

    @numba.njit(parallel=True, cache=True, nogil=True, **_JIT)
    def _heavy_tail_map(out, r0, c0, cols, k0, k1, start, step, last, tables, params, w, body_scale, tail_scale,
                        two):
        """fixed_maps.heavy_tail_map, compiled: a rectangle of a heavy-tailed map, parallel over its rows
        (:func:`_heavy_tail_row`)."""
        bs = 1.0 if two else body_scale
        ts = 1.0 if two else tail_scale
        rows, width = out.shape
        top = max(params[0, 0], params[1, 0]) if two else params[0, 0]
        # the rows in bands, each band's scratch rows made once (made per row, they cost a 1 MP map some 0.3 ns
        # a pixel more than a 12 MP one's: its rows are shorter)
        bands = min(rows, _SCRATCH_BANDS)
        for b in numba.prange(bands):
            node, weight, member = np.empty(width), np.empty(width), np.empty(width)
            for i in range(b * rows // bands, (b + 1) * rows // bands):
                _heavy_tail_row(out[i], np.uint64(r0 + i) * cols + np.uint64(c0), k0, k1, start, step, last,
                                tables, params, w, bs, ts, two, top, node, weight, member)


if numba is not None:
    @numba.njit(cache=True, nogil=True, **_JIT)
    def _tukey_nodes(log_v, log_1mv, lam, out):  # pragma: no cover - compiled
        """samplers.tukey_lambda_table's arithmetic, one node at a time (fdmath's exp: the same bits)."""
        for k in range(out.size):
            q = log_v[k] - log_1mv[k] if lam == 0.0 else (_exp(lam * log_v[k]) - _exp(lam * log_1mv[k])) / lam
            out[k] = 0.0 - q
        out[0] = 0.0


@functools.lru_cache(maxsize=16)
def tukey_table(lam: float) -> np.ndarray:
    """:func:`samplers.tukey_lambda_table` (its specification), compiled: the same bits in 0.08 ms against 0.69
    (measured on an AVX2 machine; a data set of virtual cameras asks for a new shape at every sample). Read-only.

    Parameters
    ----------
    lam : float
        The Tukey-lambda shape.

    Returns
    -------
    (samplers.TUKEY_Z_STEPS + 1,) float64 array
    """
    if numba is None:  # pragma: no cover
        return samplers.tukey_lambda_table(lam)
    a, b = samplers.tukey_node_logs()
    out = np.empty(a.size)
    announce("the Tukey-lambda table", _tukey_nodes)
    _tukey_nodes(a, b, float(lam), out)
    out.flags.writeable = False
    return out


def fixed_map_kernels() -> dict:
    """The compiled loops of :mod:`.fixed_maps` (:func:`.jit.compiled` says when they are compiled rather than
    loaded)."""
    return {"normal": _normal_map, "heavy_tail": _heavy_tail_map, "offset": _offset_map, "lines": _line_draws}


def _version_of(package: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def generator_info(device: str = "cpu") -> dict:
    """What made the random numbers, for every output's metadata (docs/model.md section 1); ``device``: where the
    frames were made (``"cuda"``: the GPU kernel, the same bits)."""
    return {
        "scheme": "philox4x32-10; counter (index, frame, sequence, try); Box-Muller normals (read noise after "
                  "the gain: the source follower's sine branch); "
                  "Poisson by inversion below 10, PTRS from 10",
        "scheme_version": samplers.SCHEME_VERSION,
        "numpy": np.__version__,
        "numba": numba.__version__ if numba is not None else None,
        # the fixed maps' quantiles are scipy's (docs/reproducibility.md); read without importing scipy
        "scipy": _version_of("scipy"),
        "frame_kernel": "numba-cuda" if device == "cuda" else "numba" if AVAILABLE else "numpy",
    }


_DUMMY2 = np.zeros((1, 1), np.float32)
_DUMMY1 = np.zeros(1)
_DUMMY_TABLE = np.zeros(1)
_DUMMY_TABLE.flags.writeable = False  # as the tables are: numba types a read-only array apart
_DUMMY_NL = np.zeros(2)
_DUMMY_NL.flags.writeable = False
_DUMMY_PTR = np.zeros(2, np.int64)
_DUMMY_COL = np.zeros(1, np.int64)
_DUMMY_F32 = np.zeros(1, np.float32)


def _needs_compile() -> int:
    """How many variants of the kernel this process holds (-1 without numba); says first that it compiles when
    nothing is cached for this machine and vector width."""
    if numba is None:
        return -1
    held = len(_render.overloads)  # the compiled variants (.signatures lists them: 15 us a call)
    if not held and not jit.cached_for_this_machine(_render):
        _logger.info(f"compiling the frame kernel for this machine ({jit.vectors()}; once; about half a minute on idle cores, up to two minutes on a busy machine) ...")
    return held


def ready() -> bool:
    """Whether :func:`render` makes frames now: numba installed, and the kernel in memory, in numba's on-disk cache,
    or to be compiled at its first call (:func:`.jit.compiled`, the foreground mode). False where the NumPy
    specification makes them instead (the same bits): without numba, and while a background compile builds the
    kernel."""
    return AVAILABLE and jit.compiled("the frame kernel", _render, say=False)  # render says it compiles, and times it


def preload() -> bool:
    """Load the compiled kernel from numba's on-disk cache now, if it is there; returns whether it did.

    A run calls this in a second thread while it makes the sensor's fixed
    pattern, so the 0.2 s of loading overlaps that work instead of delaying
    the first frame. It never compiles: with nothing cached for this
    machine and these argument types, the first frame compiles, and says so
    (:func:`render`). It loads without calling the kernel: a call would start
    a parallel region from this thread, and the OpenMP layer would keep a
    second team of threads for it beside the main thread's.
    """
    if numba is None or _render.overloads:
        return False
    flags = np.zeros(N_SWITCHES, np.bool_)
    inputs = Inputs(noisy=_DUMMY2, exact=_DUMMY2, flags=flags, normal_above=0.0, full_well=1.0, sf=_DUMMY2,
                    row_sigma=0.0, row_offset=_DUMMY1, col_sigma=_DUMMY1, col_offset=_DUMMY1, col_gain=_DUMMY1,
                    keys=np.zeros((len(KEY_ROWS), 2), np.uint64), k_adc=1.0, black=0.0, top=0.0, step=1.0,
                    loggam_table=_DUMMY_TABLE, nl_table=_DUMMY_NL, nl_scale=0.0, nl_a=0.0, nl_b=0.0, nl_c=0.0,
                    offset=_DUMMY2, cell_offsets=_DUMMY1, frame_black_sigma=0.0, read_kind=0, read_scale=0.0,
                    read_table=_DUMMY_NL, rts_ptr=_DUMMY_PTR, rts_col=_DUMMY_COL, rts_val=_DUMMY1,
                    blink_ptr=_DUMMY_PTR, blink_col=_DUMMY_COL, blink_mean=_DUMMY_F32)
    args = (inputs, Where(0, 0, 0, 1, 0, 1, 1, 0, 0), np.empty((1, 1), np.uint16), np.empty((1, 1), np.float32))
    sig = tuple(numba.typeof(a) for a in args)
    try:
        index = _render._cache._cache_file._load_index()  # {(signature, target, ...): file}
        magic = _render.targetctx.codegen().magic_tuple()
        cached = any(key[0] == sig and key[1] == magic for key in index)
    except Exception:  # numba's internals moved: leave it to the first frame
        return False
    if not cached:
        return False
    _render.compile(sig)
    return True



def curve_constants(plan: FramePlan) -> tuple[np.ndarray, float, tuple[float, float, float]]:
    """The charge-to-voltage curve (stage 5b) as the kernels take it, nonlinearity.Curve.apply's constants:
    (table, or a 2-long dummy for the cubic; the scale of the charge; the cubic's three coefficients)."""
    curve: Any = plan.nonlinearity  # a nonlinearity.Curve (the engine does not import the model)
    if curve is None:
        return _DUMMY_NL, 0.0, (0.0, 0.0, 0.0)
    if curve.coefficients is not None:
        a, b, c = (float(v) for v in curve.coefficients)
        return _DUMMY_NL, 1.0 / curve.full_well_e, (a, b, c)
    return curve.table, (curve.table.size - 1) / curve.full_well_e, (0.0, 0.0, 0.0)


def read_constants(plan: FramePlan) -> tuple[int, float, np.ndarray]:
    """The read noise (stage 9a) as the kernels take it: (0 normal or 1 Tukey-lambda, scale DN, the Tukey-lambda
    variate's table against a normal, or a 2-long dummy)."""
    if plan.read_noise is None:
        return 0, 0.0, _DUMMY_NL
    kind, scale, shape = plan.read_noise
    if kind == "normal":
        return 0, float(scale), _DUMMY_NL
    return 1, float(scale), tukey_table(float(shape))


def render(plan: FramePlan, frame: int, region=None, electrons: bool = False, timings: dict | None = None):
    """Frame ``frame`` of ``plan``: (raw, electrons or None).

    ``region = (row0, row1, col0, col1)`` renders that rectangle alone
    (bit-identical to the same crop of the whole frame). ``raw`` is uint16 DN,
    or float32 e- with the ADC off; ``electrons`` (float32 e- at the ADC
    input) only when asked for. ``timings`` (a ``defaultdict(float)``, s) gets
    ``kernel_compile``: the time of a call that compiled the kernel, which is
    not a frame's time.
    """
    rows, cols = plan.shape
    ar0, ar1, ac0, ac1 = plan.region
    r0, r1, c0, c1 = region if region is not None else (ar0, ar1, ac0, ac1)
    if not (ar0 <= r0 < r1 <= ar1 and ac0 <= c0 < c1 <= ac1):
        raise ValueError(f"region {region} is not inside the plan's window (rows {ar0}..{ar1}, cols {ac0}..{ac1})")
    if numba is None:  # pragma: no cover
        raise RuntimeError("numba is not installed: use the NumPy implementation (the model does so by itself)")
    h, w = r1 - r0, c1 - c0
    adc_on = plan.adc is not None
    out_dn = np.empty((h, w) if adc_on else (1, 1), np.uint16)
    out_e = np.empty((h, w) if (electrons or not adc_on) else (1, 1), np.float32)
    rts_ptr, rts_col, rts_val = _DUMMY_PTR, _DUMMY_COL, _DUMMY1
    if plan.traps is not None:
        rts_ptr, rts_col, rts_val = telegraph.sparse_rows(*telegraph.per_pixel(*trap_values(plan, frame, (r0, r1, c0, c1))),
                                                (r0, r1, c0, c1), cols)
    blink_ptr, blink_col, blink_mean = _DUMMY_PTR, _DUMMY_COL, _DUMMY_F32
    if plan.blinkers is not None:
        pixels, means = blink_means(plan, frame, (r0, r1, c0, c1))
        blink_ptr, blink_col, blink_mean = telegraph.sparse_rows(pixels, means, (r0, r1, c0, c1), cols)
    flags = switches(plan, electrons, rts_val.size > 0 and plan.traps is not None,
                     blink_mean.size > 0 and plan.blinkers is not None)
    k_adc, black, top, step = plan.adc if plan.adc is not None else (1.0, 0.0, 0, 1)
    nl, nl_scale, (nl_a, nl_b, nl_c) = curve_constants(plan)
    read_kind, read_scale, read_table = read_constants(plan)
    held = _needs_compile()
    t0 = time.perf_counter()
    with ONE_LAUNCH:
        inputs = Inputs(
            noisy=plan.noisy_e if plan.noisy_e is not None else _DUMMY2,
            exact=plan.exact_e if plan.exact_e is not None else _DUMMY2, flags=flags,
            normal_above=float(plan.normal_above_e), full_well=float(plan.full_well_e),
            sf=plan.sf_sigma_e if plan.sf_sigma_e is not None else _DUMMY2, row_sigma=float(plan.row_sigma_e or 0.0),
            row_offset=plan.row_offsets(frame) if plan.row_offset_e is not None else _DUMMY1,
            col_sigma=plan.col_sigma_e if plan.col_sigma_e is not None else _DUMMY1,
            col_offset=plan.col_offsets(frame) if plan.col_offset_e is not None else _DUMMY1,
            col_gain=plan.col_gain if plan.col_gain is not None else _DUMMY1, keys=plan.keys, k_adc=float(k_adc),
            black=float(black), top=float(top), step=float(step), loggam_table=plan.loggam_table, nl_table=nl,
            nl_scale=float(nl_scale), nl_a=nl_a, nl_b=nl_b, nl_c=nl_c,
            offset=plan.offsets(frame) if plan.offset_e is not None else _DUMMY2,
            cell_offsets=np.asarray(plan.cell_offsets_dn, np.float64),
            frame_black_sigma=float(plan.frame_black_sigma_dn), read_kind=read_kind, read_scale=float(read_scale),
            read_table=read_table, rts_ptr=rts_ptr, rts_col=rts_col, rts_val=rts_val, blink_ptr=blink_ptr,
            blink_col=blink_col, blink_mean=blink_mean)
        _render(inputs, Where(int(frame), int(plan.sequence), r0, r1, c0, c1, cols, ar0, ac0), out_dn, out_e)
    elapsed = time.perf_counter() - t0
    if len(_render.overloads) > held and elapsed > 2.0:  # a cache load takes well under a second: a compile
        what = "the frame kernel" if held == 0 else "a variant of the frame kernel for these switches' types"
        _logger.info(f"compiled {what} in {elapsed:.0f} s ({jit.vectors()}); later runs reuse it")
        if timings is not None:
            timings["kernel_compile"] += elapsed
    raw = out_dn if adc_on else out_e
    return raw, (out_e if electrons or not adc_on else None)


#: how the compile message names the random telegraph noise's loops (the traps' and the blinking pixels')
_TELEGRAPH_LOOPS = "the random telegraph loops"


def trap_values(plan: FramePlan, frame: int, region) -> tuple[np.ndarray, np.ndarray]:
    """(pixel index, what the trap adds in e-) of each trap of ``plan`` inside ``region`` in frame ``frame``
    (random_telegraph.trap_output, compiled)."""
    if plan.traps is None:
        raise ValueError("trap_values: the plan has no traps")
    traps = plan.traps.within(region, plan.shape[1])
    out = np.empty(traps.index.size)
    k0, k1 = (np.uint64(w) for w in plan.trap_key)
    cds = plan.cds_interval_s is not None
    announce(_TELEGRAPH_LOOPS, _trap_values, _blink_values)
    with ONE_LAUNCH:
        _trap_values(int(frame), np.uint64(plan.sequence), traps.up, traps.down, traps.size, traps.index, traps.slot,
                     float(plan.frame_period_s), float(plan.cds_interval_s or 0.0), cds, k0, k1, out)
    return traps.index, out


def blink_means(plan: FramePlan, frame: int, region) -> tuple[np.ndarray, np.ndarray]:
    """(pixel index, this frame's mean charge, float32 e-) of each blinking pixel inside ``region``: its mean (the
    plan's, whichever of the noisy or exact means holds the dark charge) plus its extra dark charge."""
    if plan.blinkers is None:
        raise ValueError("blink_means: the plan has no blinking pixels")
    pixels = plan.blinkers.within(region, plan.shape[1])
    extra = np.empty(pixels.index.size)
    k0, k1 = (np.uint64(w) for w in plan.blink_key)
    announce(_TELEGRAPH_LOOPS, _trap_values, _blink_values)
    with ONE_LAUNCH:
        _blink_values(int(frame), np.uint64(plan.sequence), pixels.up, pixels.down, pixels.size, pixels.index,
                      pixels.slot, float(plan.frame_period_s), float(plan.exposure_s), k0, k1, extra)
    return pixels.index, telegraph.plus_charge(plan.blink_mean_e, pixels.index, extra, plan.origin, plan.shape[1])

