"""docs/model.md section 1: same seed, same sensor; frame k does not depend on batching."""

import tracemalloc

import numpy as np
import pytest

from cmosnoise import Sensor, load_config
from cmosnoise.io.raw_tiff import write_raw_tiff


def _cfg():
    return load_config(extra={"sensor": {"width": 64, "height": 48}})


def test_same_config_and_seed_give_identical_frames():
    a = Sensor(_cfg(), seed=11).capture(frames=4)
    b = Sensor(_cfg(), seed=11).capture(frames=4)
    c = Sensor(_cfg(), seed=12).capture(frames=4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_frames_3_to_5_equal_a_run_of_only_those_frames():
    full = Sensor(_cfg(), seed=3).capture(frames=10)
    part = Sensor(_cfg(), seed=3).capture(frames=3, first_frame=3)
    np.testing.assert_array_equal(full[3:6], part)
    shot = Sensor(_cfg(), seed=3).expose()
    np.testing.assert_array_equal(shot.frame(7), full[7])  # out of order, one at a time
    assert not np.array_equal(full[3], full[4])  # temporal noise is fresh every frame


def test_a_stages_fixed_pattern_does_not_depend_on_other_stages():
    base = {"sensor": {"width": 64, "height": 48}}
    g1 = Sensor(load_config(extra=base), seed=5).fixed_pattern.prnu_gain
    g2 = Sensor(load_config(extra={**base, "crosstalk": {"enabled": False}, "shot_noise": {"enabled": False}}), seed=5).fixed_pattern.prnu_gain
    np.testing.assert_array_equal(g1, g2)
    assert Sensor(load_config(extra={**base, "prnu": {"enabled": False}}), seed=5).fixed_pattern.prnu_gain is None


def test_fixed_pattern_on_one_thread_is_the_pattern_on_two():
    """Every fixed map (compiled, parallel over rows) is the same bits on any thread count."""
    from conftest import on_threads

    cfg = load_config(extra={"sensor": {"width": 64, "height": 48, "temperature_c": 50}})
    a = on_threads(1, lambda: Sensor(cfg, seed=9).fixed_pattern)
    b = on_threads(2, lambda: Sensor(cfg, seed=9).fixed_pattern)
    for name in ("dark_rate", "prnu_gain", "flicker_sigma", "column_sigma", "vfpn"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.dark_state == b.dark_state


def test_contributions_sum_to_the_electron_image():
    d = Sensor(_cfg(), seed=1).expose("zoneplate").frame(0, detail=True)
    parts = sum(v for k, v in d.contributions.items() if k != "quantization")
    np.testing.assert_allclose(parts, d.electrons, atol=1e-2)


def test_frames_are_written_one_at_a_time_with_bounded_memory(tmp_path):
    cfg = load_config(extra={"sensor": {"width": 320, "height": 240}})
    shot = Sensor(cfg).expose()
    shot.frame(0)  # the kernel compiled or loaded first: its compile under tracemalloc takes 300 MB and 100 s
    n = 150
    frame_bytes = 320 * 240 * 2
    tracemalloc.start()
    write_raw_tiff(tmp_path / "r.tiff", shot.frames(n), n, (320, 240)[::-1], {"cfa": "RGGB"})
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # a handful of frames' worth of float work arrays, never the whole run (n frames = 23 MB)
    assert peak < 40 * frame_bytes, f"peak {peak / 1e6:.1f} MB"
    assert (tmp_path / "r.tiff").stat().st_size >= n * frame_bytes


def test_switching_one_stage_off_leaves_every_other_stages_noise_unchanged():
    """seeds.py's promise: each stage has its own streams, so turning one off changes nothing else."""
    import pytest

    base = {"sensor": {"width": 48, "height": 40}}
    full = Sensor(load_config(extra=base), seed=11).expose("ramp").frame(2, detail=True).contributions
    temporal = ["shot_noise", "source_follower", "row_noise", "column_noise"]
    for off in ["prnu", "crosstalk", "dark_current", "source_follower", "row_noise", "column_noise"]:
        cfg = load_config(extra={**base, off: {"enabled": False}})
        part = Sensor(cfg, seed=11).expose("ramp").frame(2, detail=True).contributions
        assert off not in part or not np.any(part[off])
        for stage in temporal:
            if stage == off or stage not in part:
                continue
            if stage == "shot_noise" and off in ("prnu", "crosstalk", "dark_current"):
                continue  # its mean changed, so its value does (its random numbers do not: the engine tests)
            if stage == "column_noise" and off in ("prnu", "crosstalk", "dark_current", "source_follower", "row_noise"):
                # column gain multiplies the charge, so the column part moves with it; the column's own term does not
                continue
            np.testing.assert_array_equal(part[stage], full[stage], err_msg=f"{stage} changed when {off} went off")
    with pytest.raises(AssertionError):  # the comparison can fail: a different seed changes the noise
        other = Sensor(load_config(extra=base), seed=12).expose("ramp").frame(2, detail=True).contributions
        np.testing.assert_array_equal(other["source_follower"], full["source_follower"])


@pytest.mark.parametrize("change", [
    {"prnu": {"sigma_pct": 2.5}},
    {"sensor": {"temperature_c": 41.0}},
    {"dark_current": {"doubling_c": 6.0}},
    {"source_follower": {"flicker": {"gumbel_scale_e": 0.2}}},
    {"source_follower": {"thermal_sigma_e": 7.0}},
    {"column_noise": {"vfpn_sigma_e": 3.0}},
    {"row_noise": {"fixed_sigma_e": 1.0}},
    {"seed": 9},
])
@pytest.mark.parametrize("temperature", [25.0, 33.0, 60.0])  # at a point, between two, beyond the last
def test_a_sensor_from_the_pattern_cache_is_the_sensor_drawn_afresh(change, temperature):
    """Sensor(config, cache=cache) (the explorer's and the sweep's path) takes only maps whose inputs did not
    change from an earlier sensor's, and its exposure's photo and dark means too: every map and mean image
    equals a fresh sensor's, bit for bit, at a characterization point, between two and beyond them."""
    from dataclasses import fields

    from cmosnoise import PatternCache, Sensor, load_config

    base = {"sensor": {"width": 64, "height": 48, "temperature_c": temperature}, "scene": {"source": "photo"}}
    cache = PatternCache(10**9)
    first = Sensor(load_config(extra=base), cache=cache)
    first.expose()
    cfg = load_config(extra={**base, **change} if "sensor" not in change
                      else {"sensor": {**base["sensor"], **change["sensor"]}})
    held, fresh = Sensor(cfg, cache=cache), Sensor(cfg)
    for f in fields(fresh.fixed_pattern):
        a, b = getattr(held.fixed_pattern, f.name), getattr(fresh.fixed_pattern, f.name)
        if isinstance(b, np.ndarray):
            assert np.array_equal(a, b), f.name
        else:
            assert a == b, f.name
    for name in ("perfect_e", "after_prnu_e", "photo_mean_e", "dark_mean_e"):
        assert np.array_equal(getattr(held.expose(), name), getattr(fresh.expose(), name)), name
    assert np.array_equal(held.expose().frame(3), fresh.expose().frame(3))
    assert np.array_equal(held.source_follower_sigma, fresh.source_follower_sigma)
