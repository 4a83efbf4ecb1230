"""Samplers on counter-based uniforms: the NumPy implementation, which is the specification.

Every draw of a pixel (or a row, or a column) comes from Philox blocks at
counter ``(index, frame, sequence, attempt)`` under the stage's key, and
from nothing else: its value depends on that pixel's own mean and on no other
pixel. ``attempt`` advances only inside a rejection sampler.

- Normal: Box-Muller on the two uniforms of block 0 (the cosine branch; the
  read noise after the gain takes the sine branch of the source follower's
  block, :func:`normal_pair_from`).
- Poisson: inversion of the CDF below a mean of 10 (one uniform of block 0);
  from 10 up, PTRS (Hoermann 1993) with numpy's constants and order of tests,
  each try taking its own block. Given the same uniforms, the inversion equals
  ``scipy.stats.poisson.ppf`` and PTRS numpy's ``random_poisson_ptrs``.

All arithmetic is IEEE float64 with :mod:`.fdmath`'s log and exp, so the
fused kernel (:mod:`.frame.kernel`) reproduces these results bit for bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .fdmath import cos_turn, exp, floor, log, loggam, sincos_turn, where
from .philox import uniform_pair

#: generator scheme version, written into every output's metadata
SCHEME_VERSION = 4
#: below this mean, Poisson by inversion; from it up, PTRS
PTRS_FROM = 10.0
#: inversion never goes past this count (P(k > 100 | mean < 10) < 1e-60)
INVERSION_MAX = 100.0


def normal_from(u1, u2):
    """Box-Muller: a standard normal from two open uniforms."""
    return np.sqrt(-2.0 * log(u1)) * cos_turn(u2)


def normal_pair_from(u1, u2):
    """Box-Muller: two independent standard normals from two open uniforms, (cosine branch, sine branch).

    The first is :func:`normal_from`'s, bit for bit; the second costs a
    multiplication more (:func:`.fdmath.sincos_turn` reduces the angle once).
    """
    r = np.sqrt(-2.0 * log(u1))
    c, s = sincos_turn(u2)
    return r * c, r * s


#: the Tukey-lambda variate tabulated against a standard normal: equal steps of ``|z|`` from 0 to TUKEY_Z_MAX
TUKEY_Z_STEPS = 8192
#: above the largest ``|z|`` Box-Muller makes from open uniforms, ``sqrt(-2 log 2**-53) = 8.5717``
TUKEY_Z_MAX = 8.6
_TUKEY_Z_SCALE = TUKEY_Z_STEPS / TUKEY_Z_MAX  # steps per unit of |z|
#: the normal's upper tail is integrated from here down (Phi(-12) = 1.8e-33: 5e-16 of Phi(-8.6) = 4e-18)
_TUKEY_Z_TAIL = 12.0


@functools.lru_cache(maxsize=1)
def normal_tail_nodes() -> np.ndarray:
    """``Phi(-z)`` at :func:`tukey_lambda_table`'s nodes ``z_k = k TUKEY_Z_MAX / TUKEY_Z_STEPS``, (TUKEY_Z_STEPS + 1,).

    The normal density is integrated over each step with 5-point
    Gauss-Legendre (exact to rounding at steps of 0.001) using :mod:`.fdmath`'s
    exp, out to ``z = 12``, and the steps are summed from the far end in order:
    the same bits everywhere, with no libm ``erfc``. Relative error below 1e-12
    (tests compare with ``scipy.special.ndtr``). Read-only.
    """
    h = TUKEY_Z_MAX / TUKEY_Z_STEPS
    steps = int(np.ceil(_TUKEY_Z_TAIL / h))
    left = np.arange(steps, dtype=np.float64) * h
    s = np.sqrt(10.0 / 7.0)
    nodes = (0.0, np.sqrt(5.0 - 2.0 * s) / 3.0, -np.sqrt(5.0 - 2.0 * s) / 3.0, np.sqrt(5.0 + 2.0 * s) / 3.0,
             -np.sqrt(5.0 + 2.0 * s) / 3.0)
    w70 = 13.0 * np.sqrt(70.0)
    weights = (128.0 / 225.0, (322.0 + w70) / 900.0, (322.0 + w70) / 900.0, (322.0 - w70) / 900.0,
               (322.0 - w70) / 900.0)
    area = np.zeros(steps)
    for x, w in zip(nodes, weights):
        t = left + (0.5 * h) * (1.0 + x)
        area = area + w * exp(-0.5 * (t * t))
    area = area * (0.5 * h / np.sqrt(2.0 * np.pi))
    tail = np.cumsum(area[::-1])[::-1]  # tail[k]: from z_k to 12, summed from the far end
    out = np.ascontiguousarray(tail[:TUKEY_Z_STEPS + 1])
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=1)
def tukey_node_logs() -> tuple[np.ndarray, np.ndarray]:
    """``log(v)`` and ``log(1 - v)`` at :func:`tukey_lambda_table`'s nodes (``v = Phi(-z_k)``): the same for every
    shape, made once (a data set of virtual cameras asks for a new shape every sample). Read-only."""
    v = normal_tail_nodes()
    a, b = log(v), log(1.0 - v)
    a.flags.writeable = b.flags.writeable = False
    return a, b


@functools.lru_cache(maxsize=16)
def tukey_lambda_table(lam: float) -> np.ndarray:
    """The standard Tukey-lambda variate as a function of a standard normal ``z >= 0``: ``TUKEY_Z_STEPS + 1`` values.

    Node ``k`` holds ``Q(Phi(z_k)) = -q(v)``, ``v = Phi(-z_k)``
    (:func:`normal_tail_nodes`), ``q(v) = (v**lam - (1 - v)**lam) / lam``
    (``lam = 0``: ``log(v) - log(1 - v)``), at ``z_k = k TUKEY_Z_MAX /
    TUKEY_Z_STEPS``: a normal through this table is Tukey-lambda distributed.
    Computed with :mod:`.fdmath`'s log and exp (the same bits everywhere);
    node 0 is 0 (the law is odd); read-only.
    """
    a, b = tukey_node_logs()
    q = a - b if lam == 0.0 else (exp(lam * a) - exp(lam * b)) / lam
    out = np.ascontiguousarray(0.0 - q)
    out[0] = 0.0
    out.flags.writeable = False
    return out


def tukey_lambda_cell(z):
    """Where a standard normal ``z`` falls in :func:`tukey_lambda_table`: (the index of its node, held as float;
    the weight of the next node). Arithmetic only (the kernel runs it as a SIMD pass, the table's loads apart)."""
    t = where(z < 0.0, 0.0 - z, z) * _TUKEY_Z_SCALE
    i = floor(t)
    return i, t - i


def tukey_lambda_from(z, table):
    """A standard Tukey-lambda variate from a standard normal ``z``: ``Q(Phi(z))``, linear in
    :func:`tukey_lambda_table` between the nodes :func:`tukey_lambda_cell` finds; odd in ``z``. Relative error
    below 1e-5 (tests compare with scipy.stats.tukeylambda); the bits are the kernel's (a lookup instead of
    ``Phi``, two logs and two exps a pixel).
    """
    k, w = tukey_lambda_cell(z)
    return tukey_lambda_at(table, k, w, z)


def tukey_lambda_at(table, kf, w, z):
    """The table's value between node ``kf`` (held as float) and the next at weight ``w`` (what
    :func:`tukey_lambda_cell` gives for ``z``), with ``z``'s sign: :func:`tukey_lambda_from`'s lookup, on arrays
    or (compiled, the GPU's kernel) one pixel."""
    k = np.int64(kf)
    lo = table[k]
    q = lo + w * (table[k + 1] - lo)
    return where(z < 0.0, 0.0 - q, q)


def poisson_inversion(lam, u):
    """Poisson(lam) by inversion of the CDF at ``u`` (lam < 10): the smallest k with F(k) >= u."""
    lam = np.asarray(lam, np.float64)
    p = exp(-lam)
    total = p.copy()
    k = np.zeros_like(lam)
    active = u > total
    while active.any():
        i = np.nonzero(active)
        k[i] = k[i] + 1.0
        p[i] = p[i] * lam[i] / k[i]
        total[i] = total[i] + p[i]
        active[i] = (u[i] > total[i]) & (k[i] < INVERSION_MAX)
    return k


def ptrs_constants(lam):
    """PTRS's per-mean constants (numpy's): slam, loglam, a, b, invalpha, vr."""
    slam = np.sqrt(lam)
    loglam = log(lam)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    vr = 0.9277 - 3.6224 / (b - 2.0)
    return loglam, a, b, invalpha, vr


def ptrs_candidate(lam, a, b, u1, u2):
    """A PTRS try's candidate from uniforms (u1, u2): (k, us, V), numpy's ``random_poisson_ptrs``."""
    U = u1 - 0.5
    V = u2
    us = 0.5 - np.abs(U)
    k = np.floor((2.0 * a / us + b) * U + lam + 0.43)
    return k, us, V


def ptrs_quick_accept(us, V, vr):
    """PTRS's quick acceptance of a candidate, before any log (numpy's first test)."""
    return (us >= 0.07) & (vr >= V)


def ptrs_early_reject(k, us, V):
    """PTRS's rejection of a negative candidate and of the corners, before any log (numpy's second test)."""
    return (k < 0.0) | ((us < 0.013) & (us < V))


def ptrs_log_test(lam, loglam, a, b, log_invalpha, kk, us, V, loggam_k1):
    """PTRS's final test given ``log(invalpha)`` and ``loggam(kk + 1)``, both functions of the pixel's mean and
    count alone (the fused kernel takes the first once per pixel and the second from :func:`loggam_table`)."""
    lhs = log(V) + log_invalpha - log(a / (us * us) + b)
    rhs = -lam + kk * loglam - loggam_k1
    return lhs <= rhs


def ptrs_log_accept(lam, loglam, a, b, invalpha, k, us, V):
    """PTRS's final test (after the quick accept and the rejection of k < 0 and the corners)."""
    kk = np.maximum(k, 0.0)
    return ptrs_log_test(lam, loglam, a, b, log(invalpha), kk, us, V, loggam(kk + 1.0))


#: the counts a loggam table holds are rounded up to a multiple of this (so similar scenes share one table) ...
_TABLE_STEP = 4096
#: ... and never more than this many (16 MB); a log test meeting a higher count computes loggam instead
TABLE_MAX = 1 << 21


@functools.lru_cache(maxsize=4)
def _loggam_table(size: int) -> np.ndarray:
    n = np.arange(size, dtype=np.float64)
    n[0] = 1.0  # loggam(0) is not defined and never asked for: counts start at 0, so n = k + 1 at 1
    table = loggam(n)
    table.flags.writeable = False
    return table


def loggam_table(mean_max: float) -> np.ndarray:
    """``table[n] = loggam(n)`` (the same bits) for every count PTRS's log test meets at means up to ``mean_max``.

    A try reaches the log test only with ``us >= 0.013`` (or, in 1.7 tries
    in 10 000, with ``V <= us`` below it), so its count is within
    ``(2 a / 0.013 + b) / 2 + 1``, under ``6.2 sqrt(mean) + 2``, of the
    mean; the table goes to ``mean_max + 8 sqrt(mean_max) + 64``, rounded up
    to a multiple of 4096 and at most :data:`TABLE_MAX` counts. float64,
    read-only, shared between calls of the same size.
    """
    top = max(float(mean_max), 0.0)
    need = top + 8.0 * np.sqrt(top) + 64.0 if np.isfinite(top) else np.inf
    size = TABLE_MAX if need >= TABLE_MAX else int(-(-need // _TABLE_STEP)) * _TABLE_STEP
    return _loggam_table(min(size, TABLE_MAX))


def ptrs_try(lam, loglam, a, b, invalpha, vr, u1, u2):
    """One PTRS try, vectorized: (k, accepted), numpy's order of tests."""
    k, us, V = ptrs_candidate(lam, a, b, u1, u2)
    quick, reject = ptrs_quick_accept(us, V, vr), ptrs_early_reject(k, us, V)
    return k, quick | (~reject & ptrs_log_accept(lam, loglam, a, b, invalpha, k, us, V))


def poisson_one(m, index, frame, sequence, k0, k1, normal_above):
    """One pixel's count as :meth:`Stream.poisson_or_normal` draws it, for scalars: the compiled kernels' (CPU and
    GPU) form of the same draw (the rounded normal above ``normal_above``, PTRS from 10, else inversion)."""
    u1, u2 = uniform_pair(index, frame, sequence, np.uint64(0), k0, k1)
    if m > normal_above:
        return max(np.rint(m + np.sqrt(m) * normal_from(u1, u2)), 0.0)
    if m >= PTRS_FROM:
        loglam, a, b, invalpha, vr = ptrs_constants(m)
        attempt = np.uint64(0)
        while True:
            if attempt > 0:
                u1, u2 = uniform_pair(index, frame, sequence, attempt, k0, k1)
            attempt += np.uint64(1)
            k, ok = ptrs_try(m, loglam, a, b, invalpha, vr, u1, u2)
            if ok:
                return k
    p = exp(-m)  # poisson_inversion, one pixel
    total = p
    k = 0.0
    while u1 > total and k < INVERSION_MAX:
        k = k + 1.0
        p = p * m / k
        total = total + p
    return k


@dataclass(frozen=True)
class Stream:
    """The temporal random numbers of one stage in one frame of one frame series.

    ``key`` is the stage's two key words (:func:`cmosnoise.model.seeds.stream_key`);
    ``index`` arguments are pixel indices ``r * cols + c`` (or row / column
    numbers), any shape.
    """

    key: tuple[int, int]
    frame: int
    sequence: int = 0

    def uniforms(self, index, attempt: int = 0):
        index = np.asarray(index, dtype=np.uint64)
        c = [np.full(index.shape, v, np.uint64) for v in (self.frame, self.sequence, attempt)]
        k0, k1 = (np.uint64(w) for w in self.key)
        return uniform_pair(index, c[0], c[1], c[2], k0, k1)

    def normal(self, index):
        """One standard normal per index (float64)."""
        return normal_from(*self.uniforms(index))

    def poisson(self, lam, index):
        """One Poisson draw per index with mean ``lam`` (float64 counts)."""
        lam = np.asarray(lam, np.float64)
        index = np.broadcast_to(np.asarray(index, np.uint64), lam.shape)
        out = np.empty(lam.shape)
        small = lam < PTRS_FROM
        u, _ = self.uniforms(index[small])
        out[small] = poisson_inversion(lam[small], u)
        big = np.nonzero(~small)
        lb, ib = lam[big], index[big]
        consts = ptrs_constants(lb)
        result = np.empty(lb.shape)
        pending = np.arange(lb.size)
        attempt = 0
        while pending.size:
            u1, u2 = self.uniforms(ib[pending], attempt)
            k, ok = ptrs_try(lb[pending], *(c[pending] for c in consts), u1, u2)
            result[pending[ok]] = k[ok]
            pending = pending[~ok]
            attempt += 1
        out[big] = result
        return out

    def poisson_or_normal(self, lam, index, normal_above: float):
        """Poisson, or the rounded normal approximation where ``lam > normal_above`` (a speed option)."""
        lam = np.asarray(lam, np.float64)
        out = self.poisson(np.where(lam > normal_above, 0.0, lam), index)
        big = lam > normal_above
        if big.any():
            lb = lam[big]
            z = self.normal(np.broadcast_to(np.asarray(index, np.uint64), lam.shape)[big])
            out[big] = np.maximum(np.rint(lb + np.sqrt(lb) * z), 0.0)
        return out
