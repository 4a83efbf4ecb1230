"""Stage 15, manufacturing defects: each kind at its rate, clusters of their sizes, what each does to a frame."""

import numpy as np
import pytest
from conftest import assert_close, quiet_config
from scipy import stats

from cmosnoise import Sensor
from cmosnoise.config.schema import SensorDefectsSection
from cmosnoise.model.stages import defects

KEY = (12345, 678)

ALL = {"enabled": True, "dead_ppm": 2000, "stuck_ppm": 2000, "low_gain_ppm": 2000, "high_gain_ppm": 2000,
       "clusters": {"ppm": 500}, "columns": {"offset_ppm": 5000, "gain_ppm": 5000, "stuck_ppm": 5000},
       "rows": {"offset_ppm": 5000, "gain_ppm": 5000, "stuck_ppm": 3000}}


def binomial_ok(count, n, ppm, what):
    p = ppm * 1e-6
    assert_close(count, n * p, np.sqrt(n * p * (1 - p)), what)


def test_each_pixel_kind_at_its_ppm_within_the_binomial_interval():
    section = SensorDefectsSection(enabled=True, dead_ppm=300, stuck_ppm=200, low_gain_ppm=500, high_gain_ppm=100)
    shape = (2000, 2000)
    d = defects.draw(section, KEY, shape)
    n = shape[0] * shape[1]
    for kind, ppm in ((defects.DEAD, 300), (defects.STUCK, 200), (defects.LOW_GAIN, 500), (defects.HIGH_GAIN, 100)):
        binomial_ok(int(np.sum(d.pixel_kind == kind)), n, ppm, f"kind {kind}")
    assert np.all(np.diff(d.pixel_index.astype(np.int64)) > 0)


def test_gain_factors_and_stuck_levels_follow_their_laws():
    section = SensorDefectsSection(enabled=True, stuck_ppm=2000, low_gain_ppm=2000, high_gain_ppm=2000,
                                   low_gain=(0.3, 0.6), stuck_levels=[0.0, 0.5, 1.0])
    d = defects.draw(section, KEY, (1000, 1000))
    _, low = d.kind_of(defects.LOW_GAIN)
    _, high = d.kind_of(defects.HIGH_GAIN)
    # KS at the 5-sigma level (p = 5.7e-7): a uniform law between the bounds
    assert stats.kstest(low, stats.uniform(0.3, 0.3).cdf).pvalue > 5.7e-7
    assert stats.kstest(high, stats.uniform(1.25, 0.75).cdf).pvalue > 5.7e-7
    _, levels = d.kind_of(defects.STUCK)
    counts = np.array([np.sum(levels == v) for v in (0.0, 0.5, 1.0)])
    assert counts.sum() == levels.size  # nothing but the levels given
    assert stats.chisquare(counts).pvalue > 5.7e-7


def test_clusters_have_their_size_distribution_and_are_connected():
    weights = [0.4, 0.3, 0.2, 0.1]
    section = SensorDefectsSection(enabled=True, clusters={"ppm": 2000, "size_weights": weights})
    shape = (1000, 1000)
    d = defects.draw(section, KEY, shape)
    binomial_ok(d.cluster_sizes.size, shape[0] * shape[1], 2000, "clusters")
    counts = np.array([np.sum(d.cluster_sizes == s) for s in range(2, 6)])
    assert counts.sum() == d.cluster_sizes.size
    expected = np.asarray(weights) * counts.sum()
    assert stats.chisquare(counts, expected).pvalue > 5.7e-7, (counts, expected)
    cols = shape[1]
    for start in np.unique(d.cluster_id)[:200]:  # every pixel of a cluster touches another (4-neighbours)
        members = d.cluster_index[d.cluster_id == start].astype(np.int64)
        r, c = members // cols, members % cols
        if members.size > 1:
            near = np.abs(r[:, None] - r[None, :]) + np.abs(c[:, None] - c[None, :]) == 1
            assert near.any(axis=1).all()


def test_bad_lines_at_their_ppm_with_their_kinds():
    section = SensorDefectsSection(enabled=True, columns={"offset_ppm": 1000, "gain_ppm": 3000, "stuck_ppm": 500})
    cols = 2_000_000
    d = defects.draw(section, KEY, (2, cols))
    for kind, ppm in ((defects.LINE_OFFSET, 1000), (defects.LINE_GAIN, 3000), (defects.LINE_STUCK, 500)):
        binomial_ok(int(np.sum(d.columns.kind == kind)), cols, ppm, f"line kind {kind}")
    _, offsets = d.columns.of(defects.LINE_OFFSET)
    assert np.all((np.abs(offsets) >= 20) & (np.abs(offsets) <= 100))
    binomial_ok(int(np.sum(offsets > 0)), offsets.size, 5e5, "positive offsets")


def test_off_or_at_zero_rates_every_frame_is_bit_identical():
    plain = Sensor({}).expose("photo").frame(2)
    assert np.array_equal(plain, Sensor({"defects": {"enabled": True}}).expose("photo").frame(2))


@pytest.mark.parametrize("off", [[], ["row_noise", "column_noise"]])
def test_a_region_and_the_numpy_path_equal_the_whole_frame(off):
    cfg = {"defects": ALL, **{s: {"enabled": False} for s in off}}
    shot = Sensor(cfg).expose("photo")
    whole = shot.frame(5)
    region = (37, 201, 55, 300)
    assert np.array_equal(shot.frame(5, region=region), whole[37:201, 55:300])
    detail = shot.frame(5, detail=True)
    assert np.array_equal(detail.raw, whole)
    parts = sum(v for k, v in detail.contributions.items() if k not in ("black_level", "read_noise", "quantization", "stuck"))
    # float32 parts of charges below 2e4 e-: each rounds by at most 2^-24 of 2e4, over about 12 terms
    assert np.abs(parts - detail.electrons).max() < 12 * 2e4 * 2.0**-24


def test_offset_columns_alone_give_no_row_part_and_their_own():
    cfg = {"defects": {"enabled": True, "columns": {"offset_ppm": 50000}}, "row_noise": {"enabled": False},
           "column_noise": {"enabled": False}}
    shot = Sensor(cfg).expose("photo")
    detail = shot.frame(1, detail=True)
    at, offset = shot.sensor.fixed_pattern.defects.columns.of(defects.LINE_OFFSET)
    assert at.size > 0 and "row_noise" not in detail.contributions
    np.testing.assert_array_equal(detail.contributions["column_noise"], 0.0)  # the column stage ran at sigma 0
    np.testing.assert_array_equal(detail.contributions["defects"][:, at], np.broadcast_to(
        offset.astype(np.float32), (shot.sensor.shape[0], at.size)))
    assert np.array_equal(detail.raw, shot.frame(1))


def test_each_defect_does_what_it_says():
    cfg = quiet_config(defects=ALL, shot_noise={"enabled": True})
    sensor = Sensor(cfg)
    d = sensor.fixed_pattern.defects
    cols = sensor.shape[1]
    shot = sensor.expose("flat:0.5")
    clean = Sensor(quiet_config(shot_noise={"enabled": True})).expose("flat:0.5")
    mean, plain = shot.mean_charge_e, clean.mean_charge_e
    for kind in (defects.DEAD, defects.LOW_GAIN, defects.HIGH_GAIN):
        index, factor = d.kind_of(kind)
        r, c = index.astype(np.int64) // cols, index.astype(np.int64) % cols
        other = (np.isin(r, d.rows.of(defects.LINE_GAIN)[0]) | np.isin(c, d.columns.of(defects.LINE_GAIN)[0])
                 | np.isin(index, d.cluster_index))
        np.testing.assert_allclose(mean[r, c][~other], (plain[r, c] * factor)[~other], rtol=1e-6)
    raw = np.stack([shot.frame(k) for k in range(3)])
    top = sensor.transfer.max_code
    index, level = d.kind_of(defects.STUCK)
    r, c = index.astype(np.int64) // cols, index.astype(np.int64) % cols
    assert np.all(raw[:, r, c] == np.rint(level * top))
    at, level = d.columns.of(defects.LINE_STUCK)
    stuck_rows = d.rows.of(defects.LINE_STUCK)[0]
    free = np.setdiff1d(np.arange(sensor.shape[0]), stuck_rows)
    on_column = raw[:, free[:, None], at[None, :]] == np.rint(level * top)[None, None, :]
    pixel_stuck = np.isin(free[:, None] * cols + at[None, :], index)  # a stuck pixel reads its own code
    assert np.all(on_column | pixel_stuck[None])
    # an offset column, away from other defects: its mean minus its neighbours' is its offset (K e- in DN)
    at, offset = d.columns.of(defects.LINE_OFFSET)
    detail = shot.frame(0, detail=True)
    part = detail.contributions["defects"]
    plain_rows = np.setdiff1d(free, d.rows.of(defects.LINE_OFFSET)[0])  # no offset row crosses
    for c, o in zip(at, offset):
        np.testing.assert_allclose(part[plain_rows, c] - mean[plain_rows, c] + plain[plain_rows, c], o, atol=1e-3)
    # hot clusters: their rate times the exposure on top of the mean
    hot = d.cluster_index[~np.isin(d.cluster_index, d.pixel_index)].astype(np.int64)
    r, c = hot // cols, hot % cols
    alone = ~(np.isin(r, d.rows.of(defects.LINE_GAIN)[0]) | np.isin(c, d.columns.of(defects.LINE_GAIN)[0]))
    assert alone.sum() > 10
    np.testing.assert_allclose(mean[r, c][alone] - plain[r, c][alone],
                               d.hot_e_per_s * cfg.exposure.integration_time_s, rtol=1e-5)
