"""Philox4x32-10, the counter-based generator of docs/model.md section 1 (Salmon et al. 2011).

A block of four 32-bit words is a pure function of a 128-bit counter and a
64-bit key: no state, so any pixel's random numbers can be made alone, in any
order, on any thread or machine. The functions here use only integer and
IEEE float64 operators, so the same source runs vectorized on NumPy arrays
(``uint64`` holding 32-bit words) and compiled by numba on scalars, with the
same bits. Checked against the Random123 known-answer vectors.
"""

from __future__ import annotations

import numpy as np

_M0 = np.uint64(0xD2511F53)
_M1 = np.uint64(0xCD9E8D57)
_W0 = np.uint64(0x9E3779B9)
_W1 = np.uint64(0xBB67AE85)
_MASK32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_S20 = np.uint64(20)
_S12 = np.uint64(12)
_ONE_BITS = np.uint64(0x3FF0000000000000)  # the bits of 1.0
_TWO_M53 = 2.0**-53

#: counter layout: (pixel or row or column index, frame, sequence, try)
ROUNDS = 10


def philox4x32(c0, c1, c2, c3, k0, k1):
    """Philox4x32-10 of counter (c0, c1, c2, c3) under key (k0, k1): four 32-bit words (as uint64)."""
    # the words are 32-bit: saying so lets the compiler multiply 32 x 32 -> 64 bits (one SIMD instruction)
    c0, c1, c2, c3 = c0 & _MASK32, c1 & _MASK32, c2 & _MASK32, c3 & _MASK32
    k0, k1 = k0 & _MASK32, k1 & _MASK32
    for _ in range(ROUNDS):
        p0 = _M0 * c0
        p1 = _M1 * c2
        hi0 = p0 >> _S32
        lo0 = p0 & _MASK32
        hi1 = p1 >> _S32
        lo1 = p1 & _MASK32
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
        k0 = (k0 + _W0) & _MASK32
        k1 = (k1 + _W1) & _MASK32
    return c0, c1, c2, c3


def open_uniform(hi, lo):
    """A float64 in the open interval (0, 1) from two 32-bit words: ``(m + 0.5) * 2**-52``, m of 52 bits.

    Never 0 or 1, so ``log(u)`` is finite and PTRS's ``0.5 - |u - 0.5|`` is
    never 0; every step is exact. ``m * 2**-52`` is read as the float whose
    bits are 1.0's with m as mantissa, less 1 (exact): no 64-bit integer to
    float conversion, which AVX2 has no vector instruction for (LLVM would
    convert lane by lane). ``(2m + 1) * 2**-53`` has 53 significant bits,
    so adding ``2**-53`` is exact too: the same value as ``(m + 0.5) * 2**-52``.
    """
    m = ((hi << _S20) | (lo >> _S12)) & np.uint64(0xFFFFFFFFFFFFF)
    return (np.uint64(m | _ONE_BITS).view(np.float64) - 1.0) + _TWO_M53


def uniform_pair(index, frame, sequence, attempt, k0, k1):
    """Two open uniforms from the block at counter (index, frame, sequence, attempt)."""
    w0, w1, w2, w3 = philox4x32(index, frame, sequence, attempt, k0, k1)
    return open_uniform(w0, w1), open_uniform(w2, w3)
