"""Sums of stationary Gauss-Markov (Ornstein-Uhlenbeck) processes, sampled at any instants by exact bridges.

A process ``x(t)`` with ``E x = 0``, ``Var x = 1`` and autocorrelation
``exp(-rate |tau|)`` is sampled on the grid ``t_n = n dt``. Its value at
grid point ``n`` is a pure function of (key, sequence, component, n): any
block ``[n0, n1)`` is made alone, and two blocks that overlap agree where
they overlap, bit for bit, as the random numbers of docs/model.md
section 1 require.

How: a dyadic bridge. At a component's top level ``L`` (``2**L dt`` at
least :data:`INDEPENDENT_AFTER` correlation times, so the process's
correlation across a top interval is below ``exp(-40)`` = 4e-18 and is
taken as zero) the values at multiples of ``2**L`` are independent
standard normals. Each finer level fills the midpoints of the coarser one
from their two neighbours with the Gauss-Markov bridge's exact law:
for half-interval ``h`` and ``a = exp(-rate h)``,

``x_mid | x_left, x_right ~ Normal(a (x_left + x_right) / (1 + a^2), (1 - a^2) / (1 + a^2))``

(the conditional of three points of the process; the Brownian bridge's
construction of Levy, as the telegraph stage's dyadic bridges do for
Markov chains). A block costs about ``2 (n1 - n0) + 2 L`` normals per
component. Every coefficient is made with the project's own ``exp``
(:mod:`.fdmath`) and each value with ``+``, ``*`` and ``sqrt``, so every
machine gives the same bits.

Examples
--------
>>> import numpy as np
>>> from cmosnoise.engine import gauss_markov as gm
>>> x = gm.sample(np.array([2.0]), np.array([1.0]), 0.01, 0, 1000, (1, 2), 0)
>>> bool(np.array_equal(x[500:], gm.sample(np.array([2.0]), np.array([1.0]), 0.01, 500, 1000, (1, 2), 0)))
True
"""

from __future__ import annotations

import math

import numpy as np

from . import fdmath
from .philox import uniform_pair
from .samplers import normal_from

#: rate x top interval above which two values are taken as independent (their correlation exp(-40) = 4e-18)
INDEPENDENT_AFTER = 40.0
#: the most components one process may have (the counter's tag word holds component x 64 + level)
MAX_COMPONENTS = 1 << 20
_MASK32 = np.uint64(0xFFFFFFFF)


def top_level(rate_per_s: float, dt_s: float) -> int:
    """The bridge's top level of a component: the least ``L >= 0`` with ``rate 2**L dt >= 40``.

    Parameters
    ----------
    rate_per_s : float
        The component's decay rate, 1/s (``2 pi`` times its corner frequency).
    dt_s : float
        The grid's step, s.

    Returns
    -------
    int
        ``L``, at most 62.
    """
    span = INDEPENDENT_AFTER / (rate_per_s * dt_s)
    return int(min(62, max(0, math.ceil(math.log2(span))))) if span > 1 else 0


def one_minus_a2(x: float) -> float:
    """``1 - exp(-2 x)`` for ``x >= 0`` without cancellation: a series below 0.1, fdmath's exp above."""
    if x < 0.1:  # 1 - e^{-y} = y - y^2/2 + y^3/6 - ...: the terms past y^10/10! are below 1e-17 of y for y < 0.2
        y, term, total = 2.0 * x, 2.0 * x, 0.0
        for n in range(1, 12):
            total += term
            term *= -y / (n + 1)
        return total
    a = float(fdmath.exp(np.float64(-x)))
    return 1.0 - a * a


def bridge_constants(rate_per_s: float, dt_s: float, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """The bridge's two coefficients at each level below the top: (mean weight, noise sigma), (levels,) float64.

    Level ``l`` fills midpoints at odd multiples of ``2**l`` from neighbours ``2**l`` steps away on each side:
    ``h = 2**l dt``, weight ``a / (1 + a^2)``, sigma ``sqrt((1 - a^2) / (1 + a^2))``, ``a = exp(-rate h)``.
    """
    weight, sigma = np.empty(levels), np.empty(levels)
    for level in range(levels):
        x = rate_per_s * dt_s * float(2**level)
        b = one_minus_a2(x)  # 1 - a^2
        a = math.sqrt(1.0 - b)
        weight[level] = a / (2.0 - b)
        sigma[level] = math.sqrt(b / (2.0 - b))
    return weight, sigma


#: the counter's second word: a node index's high bits, and the lane (one process each) in its top LANE_BITS bits
#: (16 by default: grid points to 2**48; a call may give the lane up to 32 bits, its grid points then below 2**32)
LANE_BITS = 16


def _normals(index: np.ndarray, lane: np.ndarray, sequence: int, tag: np.ndarray, key: tuple[int, int],
             lane_bits: int = LANE_BITS) -> np.ndarray:
    """One standard normal per node: ``index``, ``lane`` and ``tag`` (uint64) broadcast together; the counter is
    (index's low word, its high bits with the lane in the top ``lane_bits`` bits, sequence, tag) under ``key``."""
    index, lane, tag = np.broadcast_arrays(*(np.asarray(a, np.uint64) for a in (index, lane, tag)))
    k0, k1 = (np.uint64(w) for w in key)
    word1 = (index >> np.uint64(32)) | (lane << np.uint64(32 - lane_bits))
    return normal_from(*uniform_pair(index & _MASK32, word1, np.full(index.shape, sequence, np.uint64), tag, k0, k1))


def sample(rates_per_s: np.ndarray, weights: np.ndarray, dt_s: float, n0: int, n1: int, key: tuple[int, int],
           sequence: int, lanes=None, lane_bits: int = LANE_BITS) -> np.ndarray:
    """A sum of Gauss-Markov components, ``sum_j sqrt(w_j) x_j(n dt)``, at grid points ``n0 <= n < n1``.

    The components are bridged together, level by level (one array of every component and lane per level),
    component ``j`` from its own top level down; its nodes draw from tag ``64 j + level``.

    Parameters
    ----------
    rates_per_s : (J,) float64
        Each component's decay rate, 1/s: its autocorrelation is ``exp(-rate |tau|)``.
    weights : (J,) float64
        Each component's variance; the sum's variance is their sum.
    dt_s : float
        Grid step, s.
    n0, n1 : int
        The grid points, ``0 <= n0 < n1 <= 2**48``.
    key : (int, int)
        The stream's two key words.
    sequence : int
        The frame series (each has its own process).
    lanes : (m,) int array, optional
        Independent processes (a column's number, say), each below ``2**lane_bits``; default one, lane 0.
    lane_bits : int
        The counter's bits for the lane, 16 (the grid points then reach ``2**48``) to 32 (a pixel's index; the
        grid points then stay below ``2**32``).

    Returns
    -------
    (n1 - n0,) float64, or (m, n1 - n0) with ``lanes``
        The process's values.
    """
    rates, weights = np.asarray(rates_per_s, np.float64).ravel(), np.asarray(weights, np.float64).ravel()
    if not LANE_BITS <= lane_bits <= 32:
        raise ValueError(f"lane_bits = {lane_bits}: need {LANE_BITS} to 32")
    top_point = 2 ** (64 - lane_bits)
    if not 0 <= n0 < n1 <= top_point:
        raise ValueError(f"grid points {n0}..{n1}: need 0 <= n0 < n1 <= 2**{64 - lane_bits}")
    if not 0 < rates.size <= MAX_COMPONENTS or weights.shape != rates.shape:
        raise ValueError(f"{rates.size} rates and {weights.size} weights: need 1 to {MAX_COMPONENTS}, as many of each")
    lane = np.zeros(1, np.uint64) if lanes is None else np.asarray(lanes, np.int64).ravel()
    if lanes is not None and (lane.size == 0 or lane.min() < 0 or lane.max() >= 2**lane_bits):
        raise ValueError(f"lanes: need 0 <= lane < 2**{lane_bits}")
    lane = lane.astype(np.uint64)[None, :, None]
    tops = np.array([top_level(float(r), float(dt_s)) for r in rates])
    constants = [bridge_constants(float(r), float(dt_s), int(t)) for r, t in zip(rates, tops)]
    which = (np.arange(rates.size, dtype=np.uint64) * np.uint64(64))[:, None, None]
    last = n1 - 1
    # first the nodes each level needs, then all their normals in one call (they do not depend on the values:
    # a call's cost was its many small calls), then the bridges level by level
    plan, index_parts, tag_parts = [], [], []
    for level in range(int(tops.max()), -1, -1):
        lo_l = n0 >> level
        index = np.arange(lo_l, -((-last) >> level) + 1, dtype=np.uint64)
        going, starting = np.nonzero(tops > level)[0], np.nonzero(tops == level)[0]
        odd = np.nonzero((index & np.uint64(1)) == 1)[0]
        for comps, at in ((going, odd), (starting, np.arange(index.size))):
            if comps.size and at.size:
                index_parts.append(np.broadcast_to(index[at][None, :], (comps.size, at.size)).ravel())
                tag_parts.append(np.repeat(which[comps, 0, 0] + np.uint64(level), at.size))
        plan.append((level, lo_l, index, going, starting, odd))
    z_all = _normals(np.concatenate(index_parts)[None, :], lane[0], sequence, np.concatenate(tag_parts)[None, :],
                     key, lane_bits)  # (lanes, nodes)
    used = 0

    def take(comps, count):
        nonlocal used
        z = z_all[:, used:used + comps * count].reshape(lane.shape[1], comps, count)
        used += comps * count
        return np.moveaxis(z, 0, 1)  # (comps, lanes, count)

    values, lo = None, 0
    for level, new_lo, index, going, starting, odd in plan:
        out = np.zeros((rates.size, lane.shape[1], index.size))
        if values is not None and going.size:  # the components already started: midpoints from the coarser level
            even = np.nonzero((index & np.uint64(1)) == 0)[0]
            parent = (index >> np.uint64(1)).astype(np.int64) - lo
            past = values[going]
            out[going[:, None], :, even[None, :]] = np.moveaxis(past[:, :, parent[even]], 1, 2)
            if odd.size:
                weight = np.array([constants[j][0][level] for j in going])[:, None, None]
                sigma = np.array([constants[j][1][level] for j in going])[:, None, None]
                mid = (weight * (past[:, :, parent[odd]] + past[:, :, parent[odd] + 1])
                       + sigma * take(going.size, odd.size))
                out[going[:, None], :, odd[None, :]] = np.moveaxis(mid, 1, 2)
        if starting.size:  # a component's top nodes: independent standard normals
            out[starting] = take(starting.size, index.size)
        values, lo = out, new_lo
    total = np.zeros(values.shape[1:2] + (n1 - n0,))
    for j in range(rates.size):  # in the components' order: the same sum in any block
        total += math.sqrt(float(weights[j])) * values[j, :, n0 - lo:n0 - lo + (n1 - n0)]
    return total[0] if lanes is None else total
