"""The random telegraph signal: a two-state continuous-time Markov chain, read at any time from counter-based uniforms.

A trap (or a blinking pixel) is empty (state 0) or filled (state 1). It
leaves state 0 at rate ``up = 1 / tau_low`` and state 1 at rate
``down = 1 / tau_high`` (the mean dwell times, s). Over a time ``t`` with
``s = up + down`` and ``d = exp(-s t)``:

    P(0 -> 1) = pi1 (1 - d)      P(0 -> 0) = pi0 + pi1 d
    P(1 -> 0) = pi0 (1 - d)      P(1 -> 1) = pi1 + pi0 d

with the stationary law ``pi1 = up / s = tau_high / (tau_low + tau_high)``.
Each is a sum of non-negative terms and ``1 - d`` is taken without
cancellation (:func:`one_minus`), so a trap of any speed keeps its
precision.

**Random access** (docs/model.md section 6b). Frames are ``dt`` apart; frame
``k``'s state is that at ``k dt``. The state at frame 0 is drawn from the
stationary law and that at frame ``2**LEVELS`` from frame 0's; the state at
the middle of a dyadic interval ``[lo, hi]`` is then drawn from the chain's
bridge between its ends, each midpoint with its own counter. Frame ``k``
descends from ``[0, 2**LEVELS]`` to ``[k, k + 1]``: ``LEVELS`` draws give
the states at frames ``k`` and ``k + 1`` together, and frame 10**6 costs what
frame 0 costs. A midpoint is the midpoint of exactly one dyadic interval, so
the same node is drawn with the same uniform whichever frame asks for it:
every frame of a sequence agrees with every other.

Counters: ``(index, node, sequence, word)`` under the stage's temporal key,
``word = slot | purpose << 4 | draw << 8`` (``slot``: the trap's number in its
pixel). ``node`` is the frame number (a midpoint, or the frame whose
interior is drawn); the two ends of the whole range use node 0 with their own
purposes.

Every function is written for NumPy arrays and for scalars alike, with
:mod:`.fdmath`'s exp and IEEE operators only, so :mod:`.frame.kernel` compiles them
from this source with the same bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fdmath import exp, where
from .philox import uniform_pair


@dataclass(frozen=True)
class Telegraphs:
    """A population of two-state signals, one per trap (or blinking pixel), sorted by pixel then slot.

    ``index`` (n,) uint64 pixel index ``r * cols + c``; ``slot`` (n,) uint64
    the trap's number in its pixel; ``size`` (n,) float64 the amplitude (e-)
    or the rate step (e-/s); ``tau_low_s``, ``tau_high_s`` (n,) float64 the
    mean dwell times in state 0 (empty, low rate) and state 1.
    """

    index: np.ndarray
    slot: np.ndarray
    size: np.ndarray
    tau_low_s: np.ndarray
    tau_high_s: np.ndarray

    @property
    def up(self) -> np.ndarray:
        """Rate of leaving state 0, 1/s."""
        return 1.0 / self.tau_low_s

    @property
    def down(self) -> np.ndarray:
        """Rate of leaving state 1, 1/s."""
        return 1.0 / self.tau_high_s

    @property
    def pixels(self) -> np.ndarray:
        """The affected pixels' indices, each once, ascending (uint64)."""
        return np.unique(self.index)

    @property
    def occupancy(self) -> np.ndarray:
        """Each signal's stationary probability of state 1: ``tau_high / (tau_low + tau_high)``."""
        return self.tau_high_s / (self.tau_low_s + self.tau_high_s)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.index, self.slot, self.size, self.tau_low_s, self.tau_high_s))

    def within(self, region: tuple[int, int, int, int], cols: int) -> Telegraphs:
        """Those of the pixels in ``region = (row0, row1, col0, col1)`` of a sensor ``cols`` wide."""
        _, _, keep = in_region(self.index, region, cols)
        return Telegraphs(*(a[keep] for a in (self.index, self.slot, self.size, self.tau_low_s, self.tau_high_s)))


def positions(index: np.ndarray, region: tuple[int, int, int, int], cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Where the pixels ``index`` (``r * cols + c``) sit relative to ``region``'s corner: (rows, cols) int64."""
    i = np.asarray(index).astype(np.int64)
    return i // cols - region[0], i % cols - region[2]


def in_region(index: np.ndarray, region: tuple[int, int, int, int], cols: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols relative to ``region``'s corner, which) of the pixels ``index`` that lie in ``region``."""
    r, c = positions(index, region, cols)
    keep = (r >= 0) & (r < region[1] - region[0]) & (c >= 0) & (c < region[3] - region[2])
    return r[keep], c[keep], keep


#: frames 0 .. 2**LEVELS are reachable: the frame counter's whole 32-bit range, plus one
LEVELS = 32
#: counter word purposes
START, END, NODE, INSIDE, OCCUPANCY = 0, 1, 2, 3, 4
#: below this, 1 - exp(-x) by its series (relative error under x**3 / 24 < 5e-17 there)
_SERIES_BELOW = 1e-5


#: exp(-x) is taken at min(x, this): fdmath's exp holds to about 700, and exp(-700) = 1e-304 is 0 beside the
#: chain's probabilities (each term it meets is at least pi0 or pi1 times it)
_DECAY_FLOOR = 700.0


def decay(x):
    """``exp(-x)`` for ``x >= 0`` (1e-304 past :data:`_DECAY_FLOOR`)."""
    return exp(0.0 - where(x > _DECAY_FLOOR, _DECAY_FLOOR, x))


def one_minus(x, d):
    """``1 - d`` for ``d = exp(-x)``, ``x >= 0``, without the subtraction's cancellation at small ``x``."""
    series = x * (1.0 - x * (0.5 - x * (1.0 / 6.0)))
    return where(x < _SERIES_BELOW, series, 1.0 - d)


def transition(up, down, t):
    """The chain's transition law over ``t`` seconds: (P(0->1), P(0->0), P(1->0), P(1->1)); one exp."""
    s = up + down
    pi1 = up / s
    pi0 = down / s
    x = s * t
    d = decay(x)
    q = one_minus(x, d)
    return pi1 * q, pi0 + pi1 * d, pi0 * q, pi1 + pi0 * d


def _bridge_weights(x, y, a, b, u):
    """The bridge's draw from the transition laws ``a`` (to the time asked) and ``b`` (from it to the end)."""
    a01, a00, a10, a11 = a
    b01, b00, b10, b11 = b
    w1 = where(x > 0.5, a11, a01) * where(y > 0.5, b11, b10)
    w0 = where(x > 0.5, a10, a00) * where(y > 0.5, b01, b00)
    return where(u * (w0 + w1) < w1, 1.0, 0.0)


def bridge(x, y, up, down, t1, t2, u):
    """The state at ``t1`` of a chain in state ``x`` at 0 and ``y`` at ``t1 + t2``, from the uniform ``u``.

    ``P(1 | x, y) = P_t1(x -> 1) P_t2(1 -> y) / P_t1+t2(x -> y)``; ``t2 = 0`` gives ``y``.
    """
    return _bridge_weights(x, y, transition(up, down, t1), transition(up, down, t2), u)


def midpoint(x, y, up, down, h, u):
    """:func:`bridge` at the middle of an interval ``2 h`` long (one transition law for both halves)."""
    half = transition(up, down, h)
    return _bridge_weights(x, y, half, half, u)


def _uniform(index, node, sequence, word, k0, k1):
    """The first uniform of the block at counter (index, node, sequence, word)."""
    return uniform_pair(index, node, sequence, word, k0, k1)[0]


def frame_states(frame: int, up, down, dt: float, index, slot, sequence, k0, k1):
    """The states at frames ``frame`` and ``frame + 1`` (0. or 1.): ``LEVELS`` bridge draws (see the module text).

    ``frame`` is one whole number for every trap; ``up``, ``down`` (1/s),
    ``index`` (uint64 pixel index) and ``slot`` (uint64) are per trap.
    """
    s = up + down
    pi1 = up / s
    span = float(2**LEVELS) * dt
    seq = np.uint64(sequence)
    start_word = slot | np.uint64(START << 4)
    end_word = slot | np.uint64(END << 4)
    node_word = slot | np.uint64(NODE << 4)
    zero = np.uint64(0)
    lo_state = where(_uniform(index, zero, seq, start_word, k0, k1) < pi1, 1.0, 0.0)
    a01, a00, a10, a11 = transition(up, down, span)
    p_end = where(lo_state > 0.5, a11, a01)
    hi_state = where(_uniform(index, zero, seq, end_word, k0, k1) < p_end, 1.0, 0.0)
    lo = 0
    half = 2**LEVELS
    for _ in range(LEVELS):
        half = half // 2
        mid = lo + half
        h = float(half) * dt
        m = midpoint(lo_state, hi_state, up, down, h, _uniform(index, np.uint64(mid), seq, node_word, k0, k1))
        if frame < mid:
            hi_state = m
        else:
            lo_state = m
            lo = mid
    return lo_state, hi_state


def inside(frame: int, x, y, up, down, dt: float, t: float, index, slot, sequence, k0, k1):
    """The state at ``t`` seconds after frame ``frame`` (``0 <= t <= dt``), between its states ``x`` there and ``y``
    at the next frame."""
    word = slot | np.uint64(INSIDE << 4)
    u = _uniform(index, np.uint64(frame), np.uint64(sequence), word, k0, k1)
    return bridge(x, y, up, down, t, dt - t, u)


#: the uniformization's event count never goes past this (the configuration keeps up and down times t under
#: MAX_RATE_TIME, where the count's law is far below it)
MAX_EVENTS = 2000
MAX_RATE_TIME = 500.0


def occupancy_uniform(index, node, sequence, word0, j, k0, k1):
    """The j-th uniform of a pixel's occupancy draws (two a Philox block)."""
    u1, u2 = uniform_pair(index, node, sequence, word0 | np.uint64((j // 2) << 8), k0, k1)
    return u1 if j % 2 == 0 else u2


def occupancy_r_n(mun, a, b, pi0, pi1):
    """``R^n[a, b]`` of the uniformized chain, given ``mu^n`` (the stationary law ``(pi0, pi1)``)."""
    pib = pi1 if b == 1 else pi0
    return pib + mun * ((1.0 if a == b else 0.0) - pib)


def occupancy_events(x, y, up: float, down: float, t: float, u: float) -> int:
    """:func:`occupancy`'s event count ``n`` given both ends, by inversion at ``u`` (at most :data:`MAX_EVENTS`)."""
    lam = max(up, down)
    s = up + down
    pi0, pi1 = down / s, up / s
    mu = 1.0 - s / lam
    xi, yi = (1 if x > 0.5 else 0), (1 if y > 0.5 else 0)
    a01, a00, a10, a11 = transition(up, down, t)
    p_end = (a00 if yi == 0 else a01) if xi == 0 else (a10 if yi == 0 else a11)
    m = lam * t
    p = exp(0.0 - m)  # Pois(0; m); m <= MAX_RATE_TIME
    n = 0
    mun = 1.0
    total = p * occupancy_r_n(mun, xi, yi, pi0, pi1) / p_end
    while u > total and n < MAX_EVENTS:
        n += 1
        p = p * m / n
        mun = mun * mu
        total = total + p * occupancy_r_n(mun, xi, yi, pi0, pi1) / p_end
    return n


def occupancy_walk(x, y, up: float, down: float, t: float, n: int, powers, times, index, node, sequence, word0,
                   k0, k1) -> float:
    """:func:`occupancy`'s time in state 1, given ``n`` events at the sorted ``times`` (``powers[i] = mu**i``)."""
    lam = max(up, down)
    s = up + down
    pi0, pi1 = down / s, up / s
    yi = 1 if y > 0.5 else 0
    state = 1 if x > 0.5 else 0
    last = 0.0
    busy = 0.0
    for i in range(n):
        ti = times[i]
        if state == 1:
            busy = busy + (ti - last)
        last = ti
        left = n - 1 - i
        # R[state, 1] R^left[1, y] against R[state, 0] R^left[0, y]
        step1 = (up / lam) if state == 0 else (1.0 - down / lam)
        step0 = (1.0 - up / lam) if state == 0 else (down / lam)
        w1 = step1 * occupancy_r_n(powers[left], 1, yi, pi0, pi1)
        w0 = step0 * occupancy_r_n(powers[left], 0, yi, pi0, pi1)
        u = occupancy_uniform(index, node, sequence, word0, 1 + n + i, k0, k1)
        state = 1 if u * (w0 + w1) < w1 else 0
    if state == 1:
        busy = busy + (t - last)
    return busy


def occupancy(frame, x, y, up: float, down: float, t: float, index, slot, sequence, k0, k1) -> float:
    """Time (s) a chain in state ``x`` at 0 and ``y`` at ``t`` spends in state 1 over ``[0, t]``: one trap, scalars.

    Exact, by uniformization (Hobolth and Stone 2009): with ``lam = max(up,
    down)`` the chain is a discrete chain ``R = I + Q / lam`` stepped at the
    events of a Poisson process of rate ``lam``. Given both ends, the count
    ``n`` of events has ``P(n) ~ Pois(n; lam t) R^n[x, y]``
    (:func:`occupancy_events`); the event times are ``n`` sorted uniforms;
    the states between them are the discrete bridge (:func:`occupancy_walk`).
    ``R^n[x, y] = pi_y + mu^n (delta_xy - pi_y)``, ``mu = 1 - (up + down) / lam``.
    The GPU's form (``cuda_device.occupancy``) calls the same two parts with
    arrays of its own.
    """
    word0 = slot | np.uint64(OCCUPANCY << 4)
    node, seq = np.uint64(frame), np.uint64(sequence)
    n = occupancy_events(x, y, up, down, t, occupancy_uniform(index, node, seq, word0, 0, k0, k1))
    if n == 0:
        return t if x > 0.5 else 0.0
    mu = 1.0 - (up + down) / max(up, down)
    powers = np.empty(n + 1)
    powers[0] = 1.0
    for i in range(n):
        powers[i + 1] = powers[i] * mu
    times = np.empty(n)
    for i in range(n):
        times[i] = occupancy_uniform(index, node, seq, word0, 1 + i, k0, k1) * t
    times.sort()
    return occupancy_walk(x, y, up, down, t, n, powers, times, index, node, seq, word0, k0, k1)


def per_pixel(index: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sums of ``values`` per pixel: (pixels uint64, sums float64).

    ``index`` is sorted with a pixel's entries in slot order; each sum starts
    from its first value and adds the others in order (the kernel's order).
    """
    if index.size == 0:
        return index, np.asarray(values, np.float64)
    first = np.flatnonzero(np.r_[True, index[1:] != index[:-1]])
    counts = np.diff(np.r_[first, index.size])
    sums = values[first].astype(np.float64)
    for extra in range(1, int(counts.max())):
        ok = counts > extra
        sums[ok] = sums[ok] + values[first[ok] + extra]
    return index[first], sums


# ------------------------------------------------------------------ a population's values as a frame's kernels take them
#: the column array of a region that holds none of a population's pixels (a compiled loop takes no empty array)
_NO_COLUMN = np.zeros(1, np.int64)


def plus_charge(mean_e: np.ndarray, index: np.ndarray, extra: np.ndarray, origin=(0, 0),
                cols: int | None = None) -> np.ndarray:
    """``mean_e`` (float32, (h, w), its first pixel at ``origin`` of a frame ``cols`` wide) at the pixels ``index``
    (the frame's) plus ``extra`` (e-), rounded to float32 as every mean charge is: the one place a blinking
    pixel's mean of a frame is made."""
    index = index.astype(np.int64)
    if tuple(origin) != (0, 0):
        index = (index // cols - origin[0]) * mean_e.shape[1] + (index % cols - origin[1])
    return (mean_e.ravel()[index].astype(np.float64) + extra).astype(np.float32)


def sparse_rows(index: np.ndarray, values: np.ndarray, region, cols: int):
    """Per-pixel values at sorted pixel indices inside ``region``, by region row: (row pointers (h + 1,) int64,
    region columns int64, values)."""
    r, c = positions(index, region, cols)
    ptr = np.searchsorted(r, np.arange(region[1] - region[0] + 1)).astype(np.int64)
    return ptr, (np.ascontiguousarray(c) if c.size else _NO_COLUMN), np.ascontiguousarray(values)
