"""One pixel's value of a fixed map, the formulas written once (docs/model.md sections 1 and 4).

On scalars or NumPy arrays: :mod:`.fixed_maps` runs them over arrays (the specification) and dispatches each map
to the compiled loops or the GPU; :mod:`.frame.kernel` compiles these same sources for the CPU and the GPU
(:func:`.kernel.compile_helpers`). They live apart from the dispatcher so that the kernel, which compiles them,
and the dispatcher, which calls the kernel, do not import each other.
"""

from __future__ import annotations

import numpy as np

from .fdmath import exp, floor, log, where
from .philox import uniform_pair
from .samplers import normal_from

_ZERO = np.uint64(0)
_ONE = np.uint64(1)

__all__ = ["ppf_cell", "heavy_tail_value", "two_point", "normal_value", "offset_value"]


def ppf_cell(u, start, step, last):
    """Where an open uniform ``u`` falls on the grid uniform in ``logit(u)`` (``start + j step``, ``j = 0 .. last``):
    (the node below, held as float; the weight of the next node), clipped to the grid's ends."""
    pos = (log(u / (1.0 - u)) - start) / step
    pos = where(pos < 0.0, 0.0, where(pos > last, last, pos))
    i = floor(pos)
    i = where(i > last - 1.0, last - 1.0, i)
    return i, pos - i


def heavy_tail_value(lo, hi, w, u_member, u_tail, body_scale, fraction, tail_max, tail_scale):
    """A heavy-tailed map's value from its body's two table nodes ``lo``, ``hi`` and the weight ``w`` of ``hi``."""
    body = lo * (1.0 - w) + hi * w
    body = where(body > 0.0, body, 0.0) * body_scale
    return body + where(u_member < fraction, u_tail * tail_max * tail_scale, 0.0)


def two_point(v_lo, v_hi, floor_lo, floor_hi, w):
    """A pixel's rate between two characterization points: log-linear between its rates there, each floored."""
    a = log(where(v_lo > floor_lo, v_lo, floor_lo))
    b = log(where(v_hi > floor_hi, v_hi, floor_hi))
    return exp((1.0 - w) * a + w * b)


def normal_value(u1, u2, mean, sigma, low):
    """A normal map's value: ``max(mean + sigma z, low)``, z by Box-Muller from (u1, u2)."""
    v = mean + sigma * normal_from(u1, u2)
    return where(v > low, v, low)


def offset_value(index, k0, k1, sigma, fraction, tail_max):
    """A pixel offset: ``sigma z`` (block 0 of the pixel's counter, Box-Muller), plus ``u * tail_max`` where the
    pixel is in the tail (block 1: its first uniform below ``fraction``, ``u`` its second; drawn only where
    ``fraction > 0``)."""
    u1, u2 = uniform_pair(index, _ZERO, _ZERO, _ZERO, k0, k1)
    v = sigma * normal_from(u1, u2)
    if fraction > 0.0:
        member, u = uniform_pair(index, _ZERO, _ZERO, _ONE, k0, k1)
        v = v + where(member < fraction, u * tail_max, 0.0)
    return v
