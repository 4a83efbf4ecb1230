"""Fixed-pattern maps addressed per pixel (docs/model.md section 1, engine/fixed_maps.py).

Any rectangle of every fixed map equals that rectangle of the whole map; the compiled loops equal the NumPy
specification bit for bit and do not depend on the thread count; the maps follow their laws.
"""

import numpy as np
import pytest
from conftest import on_threads
from scipy import stats

from cmosnoise import load_config, resolve
from cmosnoise.engine import fixed_maps
from cmosnoise.model import fixed_pattern
from cmosnoise.model.distributions import LOGIT_GRID, body, gumbel, ppf_table
from cmosnoise.model.heavy_tail import HeavyTail
from cmosnoise.model.seeds import fixed_key

#: every map a sensor can hold, the dark current between two characterization points (50 C)
EVERY_MAP = {
    "sensor": {"width": 97, "height": 61, "temperature_c": 50},
    "row_noise": {"fixed_sigma_e": 1.5},
    "column_noise": {"gain_sigma_pct": 0.7},
    "pixel_offset": {"enabled": True, "sigma_e": 2.0},
    "source_follower": {"rts": {"enabled": True, "ppm": 20000}},
    "dark_current": {"rts": {"enabled": True, "ppm": 20000}},
    "defects": {"enabled": True, "dead_ppm": 5000, "stuck_ppm": 5000},
}
PER_PIXEL = ("prnu_gain", "dark_rate", "flicker_sigma", "pixel_offset")
PER_ROW = ("row_offset",)
PER_COLUMN = ("column_sigma", "vfpn", "column_gain")


def _spec(**over):
    return resolve(load_config(extra={**EVERY_MAP, **over}))


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint32)


def test_every_map_of_any_rectangle_is_that_rectangle_of_the_whole_map():
    spec = _spec()
    whole = fixed_pattern.draw(spec)
    for name in PER_PIXEL + PER_ROW + PER_COLUMN:
        assert getattr(whole, name) is not None, name
    rows, cols = spec.shape
    rng = np.random.default_rng(7)
    rects = [(0, rows, 0, cols), (0, 1, 0, 1), (rows - 1, rows, cols - 1, cols), (0, rows, cols - 3, cols),
             (rows - 5, rows, 0, cols)]  # the whole, corners, edges
    for _ in range(12):  # random rectangles of odd sizes
        r0, r1 = sorted(rng.choice(rows + 1, 2, replace=False))
        c0, c1 = sorted(rng.choice(cols + 1, 2, replace=False))
        rects.append((int(r0), int(r1), int(c0), int(c1)))
    for r0, r1, c0, c1 in rects:
        tile = fixed_pattern.draw(spec, region=(r0, r1, c0, c1))
        for name in PER_PIXEL:
            np.testing.assert_array_equal(_bits(getattr(tile, name)), _bits(getattr(whole, name)[r0:r1, c0:c1]),
                                          err_msg=f"{name} {r0, r1, c0, c1}")
        for name in PER_ROW:
            np.testing.assert_array_equal(getattr(tile, name), getattr(whole, name)[r0:r1], err_msg=name)
        for name in PER_COLUMN:
            np.testing.assert_array_equal(getattr(tile, name), getattr(whole, name)[:, c0:c1], err_msg=name)
        assert tile.traps.index.size == whole.traps.index.size  # sparse populations: the whole sensor's
        assert tile.dark_state == whole.dark_state


def test_a_region_outside_the_sensor_is_refused():
    with pytest.raises(ValueError, match="not a rectangle"):
        fixed_pattern.draw(_spec(), region=(0, 62, 0, 10))


def _grid_points(two: bool):
    lo = HeavyTail(body("lognormal", 5.0, 3.0), 2e-3, 400.0)
    hi = HeavyTail(body("gamma", 20.0, 6.0), 4e-3, 900.0)
    pts = [(ppf_table(lo.body), lo.tail_fraction, lo.tail_max, 5e-6)]
    if two:
        pts.append((ppf_table(hi.body), hi.tail_fraction, hi.tail_max, 2e-5))
    return pts


@pytest.mark.parametrize("kind", ["normal", "one point", "scaled", "two points", "offset", "offset with tail"])
def test_the_compiled_loops_equal_the_numpy_specification_on_any_thread_count(kind):
    # 601 rows: more than the heavy-tailed loop's 256 bands, and not a multiple of them (bands of 2 and 3 rows)
    region, cols, key = (3, 604, 5, 106), 311, fixed_key(4, "dark_current")

    def make(engine):
        if kind == "normal":
            return fixed_maps.normal_map(region, cols, key, 1.0, 0.02, 0.0, engine=engine)
        if kind.startswith("offset"):  # a tail of 2 % of the pixels, up to 50 e-: many members in 60 000 pixels
            tail = (0.02, 50.0) if kind.endswith("tail") else (0.0, 0.0)
            return fixed_maps.offset_map(region, cols, key, 3.5, *tail, engine=engine)
        scales = dict(body_scale=1.7, tail_scale=1.3) if kind == "scaled" else {}
        return fixed_maps.heavy_tail_map(region, cols, key, LOGIT_GRID, _grid_points(kind == "two points"), w=0.35,
                                         engine=engine, **scales)

    spec = make("numpy")
    one = on_threads(1, lambda: make("compiled"))
    two = on_threads(2, lambda: make("compiled"))
    assert spec.dtype == one.dtype == np.float32 and spec.shape == (601, 101)
    np.testing.assert_array_equal(_bits(one), _bits(spec))
    np.testing.assert_array_equal(_bits(two), _bits(spec))


def test_between_two_points_each_pixel_is_log_linear_between_its_own_rates():
    region, cols, key, w = (0, 50, 0, 80), 80, fixed_key(2, "dark_current"), 0.3
    pts = _grid_points(True)
    between = fixed_maps.heavy_tail_map(region, cols, key, LOGIT_GRID, pts, w=w).astype(np.float64)
    lo, hi = (np.maximum(fixed_maps.heavy_tail_map(region, cols, key, LOGIT_GRID, [p]).astype(np.float64), p[3])
              for p in pts)
    # the one-point maps are rounded to float32 (relative 6e-8 each); the log-linear mix keeps that order
    np.testing.assert_allclose(between, np.exp((1 - w) * np.log(lo) + w * np.log(hi)), rtol=1e-6)


def test_a_normal_map_follows_its_law():
    # KS of 120 000 pixels against Normal(1, 0.02): a correct map fails below p = 1e-6 once in a million runs
    g = fixed_maps.normal_map((0, 300, 0, 400), 400, fixed_key(1, "prnu"), 1.0, 0.02).astype(np.float64)
    assert stats.kstest(g.ravel(), stats.norm(1.0, 0.02).cdf).pvalue > 1e-6
    low = fixed_maps.normal_map((0, 300, 0, 400), 400, fixed_key(1, "prnu"), 0.0, 1.0, 0.0)
    assert low.min() == 0.0 and np.mean(low == 0.0) == pytest.approx(0.5, abs=5 * 0.5 / np.sqrt(low.size))


@pytest.mark.parametrize("law", [HeavyTail(gumbel(0.5, 0.3), 0.01, 40.0), HeavyTail(body("lognormal", 5.0, 3.0), 0.02, 400.0)])
def test_a_heavy_tailed_map_follows_its_law(law):
    # KS of 200 000 pixels against the law's cdf (body clipped at 0, plus the tail); float32 and the tabulated
    # quantile (relative error 1e-6) move the cdf far less than KS resolves at this size (1 / sqrt(n) = 2e-3)
    v = law.map((0, 400, 0, 500), 500, fixed_key(3, "source_follower")).astype(np.float64).ravel()
    assert stats.kstest(v, law.cdf).pvalue > 1e-6
    # the tail, which KS barely sees: the share above thresholds in it is Binomial(n, sf(x)) / n; 5 standard errors
    for x in law.body.ppf(1 - 1e-9) + np.array([0.1, 0.5, 0.9]) * law.tail_max:
        p = float(law.sf(x))
        assert abs(np.mean(v > x) - p) <= 5 * np.sqrt(p * (1 - p) / v.size), x


def test_line_maps_are_addressed_by_their_line():
    key = fixed_key(5, "column_noise", 1)
    np.testing.assert_array_equal(fixed_maps.lines(7, 19, key), fixed_maps.lines(0, 40, key)[7:19])
    z = fixed_maps.lines(0, 50000, key)
    assert stats.kstest(z, "norm").pvalue > 1e-6
    # the first uniforms: KS against U(0, 1), as sensitive as the normals' (a correct map fails once in a million)
    assert stats.kstest(fixed_maps.lines(0, 50000, key, "uniform"), "uniform").pvalue > 1e-6


@pytest.mark.parametrize("kind", ["normal", "uniform"])
def test_the_compiled_line_maps_equal_the_numpy_specification(kind):
    key = fixed_key(9, "column_noise", 0)
    for start, stop in ((0, 1), (0, 4000), (17, 1170), (2**31 - 3, 2**31 + 5), (5, 5)):  # past 32-bit indices too
        spec = fixed_maps.lines(start, stop, key, kind, engine="numpy")
        compiled = fixed_maps.lines(start, stop, key, kind, engine="compiled")
        assert compiled.dtype == spec.dtype == np.float64 and compiled.shape == spec.shape == (stop - start,)
        np.testing.assert_array_equal(compiled.view(np.uint64), spec.view(np.uint64), err_msg=f"{start, stop}")
    with pytest.raises(ValueError, match="kind must be"):
        fixed_maps.lines(0, 3, key, "gumbel")


@pytest.mark.parametrize("kind", ["one point", "scaled", "two points"])
def test_the_values_of_a_sensors_variates_are_its_map_before_rounding(kind):
    """What studies over a sensor's pixels read (the variates, then values(); e.g. the cooling fraction) is the
    map itself: one inversion for both."""
    region, cols, key = (2, 40, 3, 77), 90, fixed_key(6, "dark_current")
    scales = dict(body_scale=1.7, tail_scale=1.3) if kind == "scaled" else {}
    pts = _grid_points(kind == "two points")
    u = fixed_maps.variates(region, cols, key)
    values = fixed_maps.heavy_tail_values(*u, LOGIT_GRID, pts, w=0.35, **scales)
    np.testing.assert_array_equal(_bits(values.astype(np.float32)),
                                  _bits(fixed_maps.heavy_tail_map(region, cols, key, LOGIT_GRID, pts, w=0.35, **scales)))


@pytest.mark.parametrize("family", ["logistic", "lognormal", "gamma", "inverse_gaussian"])
def test_the_tabulated_quantile_is_within_1e_6_of_scipys(family):
    """The body's quantile read from its logit table, linear between nodes (8193 nodes over logit 30 to -30,
    a step of 0.0073 in logit: the interpolation error of a smooth quantile is h^2/8 of its curvature there,
    below 1e-6 relative for these families), against scipy.stats' ppf clipped at 0 (as the maps are) from 1e-12
    to 1 - 1e-12; where the quantile crosses 0, 1e-6 of the body's std (12) instead."""
    b = body(family, 50.0, 12.0)
    u = np.r_[1e-12, 1e-9, 1e-6, (np.arange(20000) + 0.5) / 20000, 1 - 1e-6, 1 - 1e-9]
    law = HeavyTail(b, 0.0, 0.0)
    np.testing.assert_allclose(law.values(u, np.ones_like(u), np.zeros_like(u)), np.maximum(b.scipy.ppf(u), 0.0),
                               rtol=1e-6, atol=12e-6)


