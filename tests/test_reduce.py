"""The compiled reductions a run's summary takes from its maps (engine/reduce.py): statistics in one pass, the
sums, the positions above a threshold; and the flat response's statistics made in bands."""

import numpy as np
import pytest

from cmosnoise import Sensor
from cmosnoise.engine import reduce

RNG = np.random.default_rng(20261124)


def _maps():
    yield RNG.standard_normal((700, 500)).astype(np.float32) * 3 + 1e3   # an offset far from 0: cancellation
    yield RNG.lognormal(size=(1001, 301))                                  # float64, skewed
    yield (RNG.integers(-3, 4, (512, 512)) * 0.5).astype(np.float32)       # many ties, negatives and zeros
    yield np.full((300, 300), 2.5, np.float32)                             # constant


def test_statistics_agree_with_numpy_to_float64_rounding():
    """Mean, variance and mean square within a few n eps of NumPy's (two summation orders of n float64 terms each
    differ from the exact sum by at most n eps of the absolute sum: 2 n eps relative for the sums of squares, and
    the variance's deviations are relative to the variance itself, so 2 n eps of mean_square / var); extremes exact."""
    for a in _maps():
        got = reduce.statistics(a)
        x = a.astype(np.float64)
        n, eps = x.size, np.finfo(np.float64).eps
        want = {"mean": x.mean(), "var": x.var(), "mean_square": np.mean(x * x), "min": x.min(), "max": x.max()}
        assert got["min"] == want["min"] and got["max"] == want["max"]
        scale = {"mean": np.mean(np.abs(x)), "mean_square": want["mean_square"], "var": want["mean_square"]}
        for k, s in scale.items():
            assert abs(got[k] - want[k]) <= 2 * n * eps * s, k


def test_statistics_joined_from_parts_equal_those_of_the_whole():
    """combine joins bands' statistics: within float64 rounding of the whole's (same bound as above)."""
    a = RNG.standard_normal((900, 333)) * 5 + 40
    parts = [(a[r0:r0 + 250].size, reduce.statistics(a[r0:r0 + 250])) for r0 in range(0, 900, 250)]
    got, want = reduce.combine(parts), reduce.statistics(a)
    tol = 2 * a.size * np.finfo(np.float64).eps * want["mean_square"]
    for k in reduce.STATISTICS:
        assert abs(got[k] - want[k]) <= tol, k


def test_total_agrees_with_numpys_sum_on_views_and_threads():
    """The sum of a map or a strided view of it (a tile's part of its window), within 2 n eps of the absolute sum
    of NumPy's (two summation orders, as above); the same bits on 1 and 2 threads (each row summed by one thread,
    the rows' sums added after)."""
    import numba

    for a in _maps():
        for view in (a, a[3:-2, 5:-1]):
            x = view.astype(np.float64)
            got = reduce.total(view)
            assert abs(got - x.sum()) <= 2 * x.size * np.finfo(np.float64).eps * np.abs(x).sum()
            before = numba.get_num_threads()
            try:
                numba.set_num_threads(1)
                assert reduce.total(view) == got
            finally:
                numba.set_num_threads(before)
    assert reduce.total(np.arange(6.0).reshape(2, 3)) == 15.0  # small: NumPy's own


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint16])
def test_positions_above_are_numpys_nonzero_of_the_comparison(dtype):
    a = (RNG.lognormal(size=(700, 500)) * 300).astype(dtype)
    for threshold in [16.02, 100.0, 1000.5, 1e9]:
        r, c = reduce.positions_above(a, threshold)
        r0, c0 = np.nonzero(a > threshold)
        assert np.array_equal(r, r0) and np.array_equal(c, c0)


def test_excess_positions_evaluate_the_expression_as_numpy_does():
    charge = RNG.normal(100, 30, (700, 500)).astype(np.float32)
    photo = (RNG.random((700, 500)) * 50).astype(np.float32)
    for lit in (True, False):
        p = photo if lit else np.zeros_like(photo)
        r, c, seen = reduce.excess_positions(charge, p, 3.0, 5.0, 0.01, 100.0)
        p64 = p.astype(np.float64)
        r0, c0 = np.nonzero((charge - p64 - 5.0 * np.sqrt(p64 + 3.0)) / 0.01 > 100.0)
        assert np.array_equal(r, r0) and np.array_equal(c, c0) and seen == lit and len(r) > 0


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_the_flat_response_statistics_made_in_bands_are_the_maps(cfa):
    """Sensor.flat_statistics makes the flat response band by band (each band's rows bit for bit the map's): its
    figures equal reduce.statistics of the whole map to float64 rounding (scaled by the mean: a few eps more)."""
    kernels = {"R": [[0, 1, 0], [2, 90, 1], [0, 3, 0]], "G": [[1, 1, 1], [1, 92, 1], [1, 1, 1]],
               "B": [[0, 0, 0], [0, 100, 0], [0, 0, 0]]}
    sensor = Sensor({"sensor": {"width": 1000, "height": 701, "cfa": cfa}, "crosstalk": {"kernel_pct": kernels}})
    got = sensor.flat_statistics()
    want = reduce.statistics(sensor.flat_response)
    tol = 4 * 701 * 1000 * np.finfo(np.float64).eps
    for k in reduce.STATISTICS:
        assert got[k] == pytest.approx(want[k], rel=tol, abs=tol * want["mean_square"]), k
