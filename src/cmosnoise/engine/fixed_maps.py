"""Fixed-pattern maps addressed per pixel: any rectangle of a map made alone (docs/model.md section 1).

A fixed map's value at pixel ``i = r * cols + c`` (or at row ``r``, column
``c`` for a line map) comes from the Philox blocks at counter
``(i, 0, 0, block)`` under the map's own fixed key
(:func:`cmosnoise.model.seeds.fixed_key`), and from nothing else. So a tile,
a crop or a viewport of a map is computed without the rest of the sensor, bit
for bit the same rectangle of the whole map, on any thread count, CPU or GPU,
and the set-up costs the same per pixel at any size.

Two kinds of per-pixel map cover every stage's:

- **a normal map** (PRNU gain): ``max(mean + sigma z, low)`` with ``z`` the
  Box-Muller normal of block 0;
- **a heavy-tailed map** (dark current, flicker sigma; docs/model.md
  section 4): a body quantile ``u_b`` and a tail membership ``u_m`` from
  block 0, a tail magnitude ``u_t`` from block 1; the body's quantile
  function read from its table on a grid uniform in ``logit(u)``
  (:func:`cmosnoise.model.distributions.ppf_table`), linear between nodes;
  ``max(body, 0) * body_scale + (u_m < fraction ? u_t * tail_max * tail_scale : 0)``.
  Between two characterization points, each pixel's rate is
  ``exp((1 - w) ln max(v_lo, floor_lo) + w ln max(v_hi, floor_hi))`` of its two
  points' values (the same variates).

The functions :func:`ppf_cell`, :func:`heavy_tail_value`, :func:`two_point`
and :func:`normal_value` (in :mod:`.map_values`, which the kernel compiles
without importing this dispatcher) are written once, on scalars or NumPy arrays: the
NumPy path (``engine="numpy"``) runs them over arrays, row band by row band,
and is the specification; the compiled path (:mod:`.frame.kernel` compiles the same
sources) runs them pixel by pixel in a parallel loop and must give the same
bits (``tests/test_fixed_maps.py``). Logs and exps are :mod:`.fdmath`'s, so
the bits do not depend on the platform's libm.
"""

from __future__ import annotations

import numpy as np

from .jit import ONE_LAUNCH, compiled, numba
from .map_values import heavy_tail_value, normal_value, offset_value, ppf_cell, two_point  # noqa: F401 - the spec
from .philox import uniform_pair
from .samplers import Stream

_ZERO = np.uint64(0)
_ONE = np.uint64(1)
#: the NumPy path's row bands hold about this many pixels (its temporaries: some tens of bytes a pixel)
BAND_PIXELS = 1 << 18


def _check(region, cols):
    r0, r1, c0, c1 = (int(v) for v in region)
    if not (0 <= r0 <= r1 and 0 <= c0 <= c1 <= cols):
        raise ValueError(f"region {tuple(region)} is not inside a sensor {cols} columns wide")
    return r0, r1, c0, c1


def bands(region):
    """The row bands ``(row0, row1)`` of ``region = (row0, row1, col0, col1)`` that hold about ``BAND_PIXELS``
    pixels each: how a NumPy pass over a large region keeps its temporaries small."""
    r0, r1, c0, c1 = region
    step = max(1, BAND_PIXELS // max(1, c1 - c0))
    for a in range(r0, r1, step):
        yield a, min(r1, a + step)


def pixel_index(region: tuple[int, int, int, int], cols: int) -> np.ndarray:
    """The address of each pixel of ``region = (row0, row1, col0, col1)`` of a sensor ``cols`` wide: ``r * cols + c``,
    (rows, cols) uint64, the counter word a pixel's random numbers are drawn at."""
    r0, r1, c0, c1 = region
    return (np.arange(r0, r1, dtype=np.uint64)[:, None] * np.uint64(cols)
            + np.arange(c0, c1, dtype=np.uint64)[None, :])


def _key(key):
    return np.uint64(key[0]), np.uint64(key[1])


def _blocks(index, k0, k1):
    u_body, u_member = uniform_pair(index, _ZERO, _ZERO, _ZERO, k0, k1)
    u_tail, _ = uniform_pair(index, _ZERO, _ZERO, _ONE, k0, k1)
    return u_body, u_member, u_tail


def variates(region, cols: int, key: tuple[int, int]) -> np.ndarray:
    """A heavy-tailed map's fixed uniforms over ``region``: (3, rows, cols) float64 of (body quantile, tail
    membership, tail magnitude), what :func:`heavy_tail_map` reads (NumPy; for studies over a sensor's pixels)."""
    r0, r1, c0, c1 = _check(region, cols)
    k0, k1 = _key(key)
    return np.stack(_blocks(pixel_index((r0, r1, c0, c1), cols), k0, k1))


def lines(start: int, stop: int, key: tuple[int, int], kind: str = "normal", engine: str = "auto") -> np.ndarray:
    """A line map's draws (rows or columns ``start`` to ``stop``): standard normals or open uniforms, float64.

    Line ``j``'s draw comes from the block at counter (j, 0, 0, 0) of the map's key, as a pixel's. ``engine``:
    "numpy" (the specification), "compiled" or "auto" (the compiled loop where numba is present: the same bits,
    without the NumPy passes' fixed cost, some 0.1 ms a map).
    """
    if kind not in ("normal", "uniform"):
        raise ValueError(f"kind must be 'normal' or 'uniform', got {kind!r}")
    if _compiled(engine):
        out = np.empty(max(0, stop - start))
        _kernels()["lines"](out, start, *_key(key), kind == "normal")
        return out
    stream = Stream(key, 0, 0)
    index = np.arange(start, stop, dtype=np.uint64)
    return stream.normal(index) if kind == "normal" else stream.uniforms(index)[0]


def normal_map(region, cols: int, key: tuple[int, int], mean: float, sigma: float, low: float = -np.inf,
               engine: str = "auto") -> np.ndarray:
    """``max(mean + sigma z, low)`` per pixel over ``region = (row0, row1, col0, col1)`` of a sensor ``cols``
    wide, (rows, cols) float32 (rounded from float64 once).

    ``engine``: "numpy" (the specification), "compiled", "auto" (compiled where numba is present), or "cuda"
    (the GPU's kernel, :func:`.cuda_kernel.fixed_map`; the same bits).
    """
    def spec(index, k0, k1):
        return normal_value(*uniform_pair(index, _ZERO, _ZERO, _ZERO, k0, k1), mean, sigma, low)

    return _made("normal", region, cols, key, lambda: (float(mean), float(sigma), float(low)), spec, engine)


def _made(kind: str, region, cols: int, key, params, spec, engine: str) -> np.ndarray:
    """A map's rectangle, (rows, cols) float32, where ``engine`` says: the GPU's kernel (:func:`_on_device`), the
    compiled loop ``kind`` (:func:`_kernels`), both given the rectangle's corner, the sensor's width, the key and
    ``params()``; or the NumPy specification ``spec(index, k0, k1)`` band by band (a band's pixel addresses)."""
    region = _check(region, cols)
    out = np.empty((region[1] - region[0], region[3] - region[2]), np.float32)
    k0, k1 = _key(key)
    if engine == "cuda" or _compiled(engine):
        args = (region[0], region[2], np.uint64(cols), k0, k1, *params())
        if engine == "cuda":
            return _on_device(kind, out, args)
        with ONE_LAUNCH:
            _kernels()[kind](out, *args)
        return out
    for a, b in bands(region):
        out[a - region[0]:b - region[0]] = spec(pixel_index((a, b, region[2], region[3]), cols), k0, k1)
    return out


def offset_map(region, cols: int, key: tuple[int, int], sigma: float, fraction: float = 0.0, tail_max: float = 0.0,
               engine: str = "auto") -> np.ndarray:
    """``sigma z`` per pixel, plus ``u * tail_max`` where the pixel is in the tail, over ``region = (row0, row1,
    col0, col1)`` of a sensor ``cols`` wide, (rows, cols) float32 (rounded from float64 once): the pixel offsets'
    map (:func:`cmosnoise.model.stages.pixel_offset.offset_map`).

    Block 0 of a pixel's counter gives z (Box-Muller); block 1 its tail membership (first uniform below
    ``fraction``) and ``u`` (second uniform), drawn only where ``fraction > 0``. ``engine``: "numpy" (the
    specification, in row bands), "compiled", "auto" (compiled where numba is present), or "cuda" (the GPU's
    kernel, :func:`.cuda_kernel.fixed_map`; the same bits).
    """
    def spec(index, k0, k1):
        return offset_value(index, k0, k1, sigma, fraction, tail_max)

    return _made("offset", region, cols, key, lambda: (float(sigma), float(fraction), float(tail_max)), spec, engine)


def heavy_tail_values(u_body, u_member, u_tail, grid: tuple[float, float, int], points, w: float = 0.0,
                      body_scale: float = 1.0, tail_scale: float = 1.0) -> np.ndarray:
    """A heavy-tailed map's values for given variates (open uniforms, arrays of any one shape), float64, by NumPy:
    the specification :func:`heavy_tail_map` follows (parameters as there), and what studies over a sensor's
    variates read (:func:`variates`: the same values as the map, before its rounding to float32)."""
    start, step, last = (float(v) for v in grid)
    i, wc = ppf_cell(np.asarray(u_body, np.float64), start, step, last)
    k = i.astype(np.int64)
    two = len(points) == 2
    bs, ts = (1.0, 1.0) if two else (body_scale, tail_scale)
    values = [heavy_tail_value(table[k], table[k + 1], wc, u_member, u_tail, bs, fraction, tail_max, ts)
              for table, fraction, tail_max, _ in points]
    return two_point(values[0], values[1], points[0][3], points[1][3], w) if two else values[0]


def heavy_tail_map(region, cols: int, key: tuple[int, int], grid: tuple[float, float, int], points,
                   w: float = 0.0, body_scale: float = 1.0, tail_scale: float = 1.0,
                   engine: str = "auto") -> np.ndarray:
    """A heavy-tailed map over ``region`` of a sensor ``cols`` wide, (rows, cols) float32.

    Parameters
    ----------
    region : (row0, row1, col0, col1)
    cols : int
        The whole sensor's width (pixel ``(r, c)``'s address is ``r * cols + c``).
    key : (int, int)
        The map's fixed key.
    grid : (start, step, last)
        The logit grid every table is tabulated on.
    points : sequence of one or two (table, fraction, tail_max, floor)
        One: the map at a point (or scaled from it by ``body_scale`` and ``tail_scale``). Two: each pixel
        log-linear between its values at the two points (weight ``w`` of the second; scales not applied).
        ``table``: the body's quantiles on the grid, (last + 1,) float64; ``floor``: the rate floor before the
        log (two points only).
    engine : {"auto", "numpy", "compiled", "cuda"}
        How it is made (the same bits each way); "cuda": on the GPU (:func:`.cuda_kernel.fixed_map`).
    """
    def params():  # the compiled loops' form: the tables and each point's (fraction, tail_max, floor) as arrays
        two = len(points) == 2
        tables = np.ascontiguousarray([np.asarray(p[0], np.float64) for p in points] * (1 if two else 2))
        per_point = np.array([p[1:] for p in points] * (1 if two else 2), np.float64)
        start, step, last = (float(v) for v in grid)
        return start, step, last, tables, per_point, float(w), float(body_scale), float(tail_scale), two

    def spec(index, k0, k1):
        return heavy_tail_values(*_blocks(index, k0, k1), grid, points, w, body_scale, tail_scale)

    return _made("heavy_tail", region, cols, key, params, spec, engine)


def _on_device(kind: str, out: np.ndarray, args: tuple) -> np.ndarray:
    """A map made by the GPU's kernel (:func:`.cuda_kernel.fixed_map`), brought into ``out``."""
    from .frame import cuda_kernel

    cuda_kernel.fixed_map(kind, out.shape, *args).copy_to_host(out)
    return out


def _compiled(engine: str) -> bool:
    if engine not in ("auto", "numpy", "compiled"):
        raise ValueError(f"engine must be 'auto', 'numpy', 'compiled' or 'cuda', got {engine!r}")
    if engine == "compiled" and numba is None:
        raise RuntimeError("the compiled fixed-pattern loops need numba")
    # auto: where numba is present and the loops are compiled, or compile here (jit.compiled: not while a
    # background compile builds them, the NumPy specification runs then)
    return engine == "compiled" or (engine == "auto" and numba is not None
                                    and compiled("the fixed-pattern loops", *_kernels().values()))


_KERNELS: dict = {}


def _kernels() -> dict:
    """The compiled loops (made on first call, loaded from numba's on-disk cache when there)."""
    if not _KERNELS:
        from .frame import kernel

        _KERNELS.update(kernel.fixed_map_kernels())
    return _KERNELS
