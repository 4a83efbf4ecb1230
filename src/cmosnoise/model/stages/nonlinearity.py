"""Stage 5b, photo-response nonlinearity: the charge-to-voltage transfer, docs/model.md stage 5b.

The collected charge (after the full-well clip) passes through a monotone
transfer ``f`` before the readout noise is added: the sense node's
capacitance grows with its swing, so a real pixel's output compresses near
saturation. ``f`` is given in e- in and e- out (output referred to the
small-signal conversion gain), as one of:

- the EMVA 1288 linearity error ``[LE_min, LE_max]`` (%): ``f(x) = x (1 + a s
  + b s**2 + c s**3)``, ``s = x / full_well``, with ``a``, ``b``, ``c`` solved
  so that the EMVA 1288 evaluation of ``f`` (:func:`linearity_error`, on 101
  equally spaced exposures up to the full well) comes nearest those two
  numbers (within 0.25 points; :func:`solve_polynomial` says how near);
- a curve: points ``(charge, output)``, strictly increasing, linear between
  them (and past the last one, along its last segment).

- the cubic's coefficients ``[a, b, c]`` themselves (what ``fit`` writes).

The cubic is evaluated as written in every pixel (:class:`Curve`; SIMD in
the kernel); a curve is tabulated once on 4096 equal steps from 0 to the
full well and interpolated linearly. Off, the stage is skipped: the exact
identity.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

#: intervals of the tabulated transfer
STEPS = 4096
#: exposures of the EMVA 1288 series a linearity error is defined on here (0 to the full well)
SERIES = 101


def linearity_error(x: np.ndarray, y: np.ndarray, y_sat: float) -> tuple[float, float]:
    """EMVA 1288's linearity error (min, max), %: the relative deviation of the mean signal ``y`` from a line
    in ``x`` (photons, or any quantity proportional to the exposure), fitted with weights ``1/y`` over the
    points from 5 to 95 % of ``y_sat``, as the standard and its reference implementation do.

    Parameters
    ----------
    x, y : ndarray (n,)
        Exposure (photons per pixel) and dark-subtracted mean signal (DN or e-), in series order.
    y_sat : float
        The mean signal at saturation.
    """
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    ok = np.nonzero((y >= 0.05 * y_sat) & (y <= 0.95 * y_sat))[0]
    if ok.size < 3:
        raise ValueError(f"a linearity error needs 3 points from 5 to 95 % of saturation, got {ok.size}")
    i0, i1 = ok.min(), ok.max() + 1  # the reference takes the span between the first and the last
    X, Y = x[i0:i1], y[i0:i1]
    xy, xy2, x2y2 = np.sum(X / Y), np.sum(X / Y**2), np.sum((X / Y) ** 2)
    _y, _y2 = np.sum(1.0 / Y), np.sum(1.0 / Y**2)
    b = (xy * xy2 - x2y2 * _y) / (xy2**2 - x2y2 * _y2)
    a = (xy - b * xy2) / x2y2
    dev = 100.0 * (Y - (a * X + b)) / (a * X + b)
    return float(dev.min()), float(dev.max())


def residual_pct(x: np.ndarray, y: np.ndarray, lo: float, hi: float) -> float:
    """A laboratory's linearity residual (the ITL reports' "maximum residual"), %: the largest deviation of the
    mean signal ``y`` from a straight line in ``x`` fitted (least squares, unweighted, with an intercept) over the
    points with ``lo <= y <= hi``, relative to the line at each point. Not EMVA 1288's linearity error
    (:func:`linearity_error`: weights ``1/y``, 5 to 95 % of saturation).

    Parameters
    ----------
    x, y : ndarray (n,)
        Exposure (any quantity proportional to it) and mean signal (DN, black included, as a report's range is).
    lo, hi : float
        The fit's range of ``y``.

    Returns
    -------
    float
        %, >= 0.
    """
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    use = (y >= lo) & (y <= hi)
    if use.sum() < 3:
        raise ValueError(f"a linearity residual needs 3 points from {lo:g} to {hi:g}, got {int(use.sum())}")
    slope, intercept = np.polyfit(x[use], y[use], 1)
    line = intercept + slope * x[use]
    return float(100.0 * np.max(np.abs((y[use] - line) / line)))


def polynomial(coefficients: tuple[float, ...], full_well_e: float):
    """``f(x) = x (1 + s (a + s (b + s c)))``, ``s = x / full_well_e`` (as ``x * (1 / full_well_e)``, the
    kernel's arithmetic), for ``coefficients = (a, b, c)``."""
    a, b, c = coefficients
    inv = 1.0 / full_well_e

    def f(x):
        x = np.asarray(x, np.float64)
        s = x * inv
        return x * (1.0 + s * (a + s * (b + s * c)))

    return f


#: how far from the asked EMVA 1288 linearity error (percentage points) a transfer may land
LE_TOLERANCE = 0.25


@functools.lru_cache(maxsize=32)
def solve_polynomial(le_min: float, le_max: float, full_well_e: float) -> tuple[tuple[float, float, float],
                                                                            tuple[float, float]]:
    """The cubic transfer closest to EMVA 1288 linearity error ``(le_min, le_max)`` %, and the error it has.

    Among the monotone cubics ``x (1 + a s + b s**2 + c s**3)`` the one whose
    :func:`linearity_error` on the series (101 equal exposures up to the full
    well) is nearest the pair, the smallest coefficients breaking ties. A
    smooth transfer cannot give every pair on every series: a compressive
    one whose maximum is above about 0.55 of its minimum's size is met
    only approximately (``(-1.25, 0.85)`` lands at ``(-1.33, 0.68)``), as
    the number depends on the series it was measured on.

    Returns
    -------
    ((a, b, c), (le_min, le_max) reached)

    Raises
    ------
    ValueError
        When the nearest monotone transfer is more than ``LE_TOLERANCE`` points away.
    """
    from scipy.optimize import least_squares

    x = np.linspace(0.0, full_well_e, SERIES)

    def reached(p):
        y = polynomial(tuple(p), full_well_e)(x)
        return linearity_error(x, y, float(y[-1]))

    def residual(p):
        lo, hi = reached(p)
        return [lo - le_min, hi - le_max, 1e-6 * p[0], 1e-6 * p[1], 1e-6 * p[2]]

    # MINPACK's Levenberg-Marquardt (method="lm"): its QR and steps are its own compiled code, so the coefficients
    # are the same bits on every CPU. The default trust-region method solves through LAPACK, whose OpenBLAS kernels
    # differ by CPU: its coefficients moved by 1.6e-6 (relative) between two kernels of one machine
    # (OPENBLAS_CORETYPE), and by some 3e-5 between an AVX2 and an AVX-512 machine, enough to move a pixel of a
    # frame. Each start's cost is summed here (five squares, in order), not taken from least_squares (a BLAS dot).
    best, best_cost = None, math.inf
    for start in ((-0.05, 0.0, 0.0), (0.05, 0.0, 0.0), (0.0, -0.05, 0.0), (0.0, 0.0, -0.05), (0.0, 0.0, 0.05)):
        x_end = least_squares(residual, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        cost = sum(float(v) ** 2 for v in residual(x_end))
        if cost < best_cost:
            best, best_cost = x_end, cost
    coefficients = tuple(float(v) for v in best)
    lo, hi = reached(best)
    s = np.linspace(0.0, 1.0, 1001)
    a, b, c = coefficients
    monotone = bool(np.all(1.0 + 2 * a * s + 3 * b * s * s + 4 * c * s**3 > 0))
    if max(abs(lo - le_min), abs(hi - le_max)) > LE_TOLERANCE or not monotone:
        raise ValueError(f"nonlinearity.linearity_error_pct = [{le_min:g}, {le_max:g}]: the nearest smooth monotone "
                         f"transfer has [{lo:.3g}, {hi:.3g}], more than {LE_TOLERANCE} points away; give curve_e instead")
    return coefficients, (lo, hi)


@dataclass(frozen=True, eq=False)
class Curve:
    """A resolved transfer: the cubic ``x (1 + s (a + s (b + s c)))``, ``s = x / full_well_e``, where
    ``coefficients`` is set (evaluated directly: SIMD in the kernel), else the ``table`` of ``STEPS + 1``
    values from 0 to the full well, linear between (a measured curve)."""

    full_well_e: float
    coefficients: tuple[float, float, float] | None = None
    table: np.ndarray | None = None

    def apply(self, charge_e) -> np.ndarray:
        """The transfer at ``charge_e`` (e-), float64: the kernel's arithmetic."""
        if self.coefficients is not None:
            return polynomial(self.coefficients, self.full_well_e)(charge_e)
        q = np.asarray(charge_e, np.float64) * (STEPS / self.full_well_e)
        i = np.minimum(np.floor(q), STEPS - 1).astype(np.int64)
        lo = self.table[i]
        return lo + (q - i) * (self.table[i + 1] - lo)

    def slope(self, charge_e: float) -> float:
        """Output e- per collected e- at ``charge_e``."""
        if self.coefficients is not None:
            a, b, c = self.coefficients
            s = charge_e / self.full_well_e
            return 1.0 + s * (2 * a + s * (3 * b + s * 4 * c))
        i = min(max(int(charge_e * STEPS / self.full_well_e), 0), STEPS - 1)
        return float(self.table[i + 1] - self.table[i]) * STEPS / self.full_well_e


def curve(full_well_e: float, linearity_error_pct=None, curve_e=None, coefficients=None) -> Curve:
    """The transfer a configuration gives: from the EMVA 1288 linearity error (solved to a cubic), the cubic's
    coefficients, or a curve of points (tabulated, linear between and past the last point along its last segment).

    Raises
    ------
    ValueError
        A linearity error no monotone transfer of this form has; coefficients not increasing up to the full well.
    """
    if linearity_error_pct is not None:
        coefficients, _ = solve_polynomial(float(linearity_error_pct[0]), float(linearity_error_pct[1]),
                                           float(full_well_e))
    if coefficients is not None:
        a, b, c = (float(v) for v in coefficients)
        s = np.linspace(0.0, 1.0, 1001)
        if not np.all(1.0 + s * (2 * a + s * (3 * b + s * 4 * c)) > 0):
            raise ValueError(f"nonlinearity.coefficients = {[a, b, c]}: the transfer must increase up to the full "
                             "well (its slope 1 + 2a s + 3b s^2 + 4c s^3 > 0 for s in [0, 1])")
        return Curve(float(full_well_e), (a, b, c))
    grid = np.linspace(0.0, full_well_e, STEPS + 1)
    pts = np.asarray(curve_e, np.float64)
    xs, ys = pts[:, 0], pts[:, 1]
    out = np.interp(grid, xs, ys)
    past = grid > xs[-1]  # past the last point: along the last segment
    out[past] = ys[-1] + (grid[past] - xs[-1]) * (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
    out.flags.writeable = False
    return Curve(float(full_well_e), table=out)
