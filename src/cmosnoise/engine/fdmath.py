"""log, exp, and cos/sin of a turn, after fdlibm's algorithms, in plain IEEE float64.

The platform's libm differs in its last bits between systems, and its calls
stop LLVM from vectorizing a loop. These are written with operators and a
few exact helpers (``frexp``, ``ldexp``, ``floor``, ``where``) only, so they
give the same bits everywhere: on NumPy arrays as written, and compiled by
numba (:mod:`cmosnoise.engine.frame.kernel` binds the helpers to their scalar
forms). Accuracy: within about 1 ulp of the correctly rounded result on
the ranges the samplers use (tests compare with ``math``).
"""

from __future__ import annotations

import numpy as np

# the helpers; the numba binding replaces them with scalar versions
frexp = np.frexp
floor = np.floor
where = np.where


def ldexp(y, k):
    """y * 2**k, exact; k a whole number held as float."""
    return np.ldexp(y, np.asarray(k).astype(np.int32))

_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_SQRT_HALF = 0.70710678118654752440
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_P1 = 1.66666666666666019037e-01
_P2 = -2.77777777770155933842e-03
_P3 = 6.61375632143793436117e-05
_P4 = -1.65339022054652515390e-06
_P5 = 4.13813679705723846039e-08
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
_PIO2 = 1.57079632679489655800e00


def log(x):
    """Natural log of x > 0 (finite), fdlibm e_log.c."""
    m, e = frexp(x)  # x = m 2^e, m in [0.5, 1)
    low = m < _SQRT_HALF
    m = where(low, m * 2.0, m)  # now in [sqrt(1/2), sqrt(2)): exact
    dk = e - where(low, 1.0, 0.0)
    f = m - 1.0
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    r = t2 + t1
    big = (f > 0.1) | (f < -0.1)
    near = dk * _LN2_HI - ((s * (f - r) - dk * _LN2_LO) - f)
    far = dk * _LN2_HI - ((hfsq - (s * (hfsq + r) + dk * _LN2_LO)) - f)
    return where(big, far, near)


def exp(x):
    """e**x for finite x in about [-700, 700], fdlibm e_exp.c."""
    k = floor(_INV_LN2 * x + 0.5)
    hi = x - k * _LN2_HI
    lo = k * _LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (_P1 + t * (_P2 + t * (_P3 + t * (_P4 + t * _P5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    return ldexp(y, k)


def _kernel_sin(x):
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x + v * (_S1 + z * r)


def _kernel_cos(x):
    z = x * x
    r = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    return 1.0 - (0.5 * z - z * r)


def sincos_turn(u):
    """(cos(2 pi u), sin(2 pi u)) for u in [0, 1): reduced to a quarter turn exactly, then fdlibm's two kernels
    (one reduction for both: Box-Muller's two normals cost little more than one)."""
    v = 4.0 * u
    n = floor(v + 0.5)  # nearest quarter turn
    x = (v - n) * _PIO2  # in [-pi/4, pi/4]
    c = _kernel_cos(x)
    s = _kernel_sin(x)
    q = n - 4.0 * floor(n * 0.25)  # n mod 4
    return (where(q == 0.0, c, where(q == 1.0, -s, where(q == 2.0, -c, s))),
            where(q == 0.0, s, where(q == 1.0, c, where(q == 2.0, -s, -c))))


def cos_turn(u):
    """cos(2 pi u) for u in [0, 1): :func:`sincos_turn`'s first (compiled, the sine is never made)."""
    return sincos_turn(u)[0]


def loggam(x):
    """ln Gamma(x) for whole x >= 1 (numpy's ``random_loggam``: Stirling series, recursion below 7).

    The recursion's logs are taken as one log of their product (exact for
    whole numbers), so the result differs from numpy's in the last bits only.
    """
    n = where(x < 7.0, floor(7.0 - x), 0.0)
    x0 = x + n
    x2 = (1.0 / x0) * (1.0 / x0)
    gl0 = -1.39243221690590e00
    for a in (1.796443723688307e-01, -2.955065359477124e-02, 6.410256410256410e-03, -1.917526917526918e-03,
              8.417508417508418e-04, -5.952380952380952e-04, 7.936507936507937e-04, -2.777777777777778e-03,
              8.333333333333333e-02):
        gl0 = gl0 * x2 + a
    gl = gl0 / x0 + 0.5 * 1.8378770664093453e00 + (x0 - 0.5) * log(x0) - x0
    # numpy subtracts log(x0 - i) for i = 1..n; one log of the product (exact: whole numbers below 2**53)
    prod = 1.0
    for i in range(1, 7):
        prod = where(n >= i, prod * (x0 - i), prod)
    gl = gl - log(prod)
    gl = where(x == 1.0, 0.0, where(x == 2.0, 0.0, gl))
    return gl
