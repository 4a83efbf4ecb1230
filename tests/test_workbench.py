"""The explorer's workbench without HTTP: validation, and what a slider move reuses and redraws."""

import numpy as np
import pytest

from cmosnoise import CmosnoiseError, Sensor
from cmosnoise.app.workbench import BadRequest, Workbench, validate

BASE = {"sensor": {"width": 96, "height": 64, "temperature_c": 30.0}, "scene": {"source": "photo"}}


def _with(**sensor):
    return {**BASE, "sensor": {**BASE["sensor"], **sensor}}


def test_validate_names_the_bad_field_and_resolves():
    with pytest.raises(BadRequest) as info:
        validate({"prnu": {"sigma_pct": -1}})
    assert info.value.status == 422 and "prnu.sigma_pct" in info.value.errors
    with pytest.raises(BadRequest) as info:  # schema-valid, but no tail reaches 1e-3 ppm: the physics says no
        validate({"source_follower": {"flicker": {"tail": {"ppm_above": 0.001, "threshold_e": 1.0, "max_e": 5}}}})
    assert "ppm_above" in info.value.message
    spec = validate({"prnu": {"measured_pct": 1.2}})
    assert spec.config.prnu.sigma_pct > 1.2  # solved through crosstalk


def test_a_temperature_move_reuses_the_photo_mean_and_gives_a_fresh_sensors_frame(tmp_path):
    bench = Workbench(tmp_path, validate(BASE).config)
    first = bench.exposure(validate(BASE), "photo")
    warmer = validate(_with(temperature_c=38.0))
    moved = bench.exposure(warmer, "photo")
    assert moved.photo_mean_e is first.photo_mean_e  # the cache's product, not recomputed
    assert moved.dark_mean_e is not first.dark_mean_e and not np.array_equal(moved.dark_mean_e, first.dark_mean_e)
    fresh = Sensor(warmer).expose("photo")
    assert np.array_equal(moved.dark_mean_e, fresh.dark_mean_e)
    assert np.array_equal(moved.frame(2), fresh.frame(2))
    # a picture of a crop: the region asked for, one pixel per sensor pixel at step 1
    img, info = bench.picture(warmer, "photo", "raw", 2, [8, 40, 16, 80], 1)
    assert img.shape == (32, 64) and info["region"] == [8, 40, 16, 80]


def test_a_temporal_move_redraws_no_map(tmp_path):
    bench = Workbench(tmp_path, validate(BASE).config)
    a = bench.sensor(validate(BASE))
    b = bench.sensor(validate({**BASE, "source_follower": {"thermal_sigma_e": 7.0}}))
    for name in ("prnu_gain", "dark_rate", "flicker_sigma"):
        assert getattr(b.fixed_pattern, name) is getattr(a.fixed_pattern, name), name
    assert not np.array_equal(a.source_follower_sigma, b.source_follower_sigma)


def test_one_region_rule_refuses_in_the_model_and_clips_in_the_viewer():
    """model.sensor.region_of is the one region check: an Exposure refuses a region outside the sensor,
    the workbench cuts it to the sensor (panning past an edge), both refuse what is not four numbers."""
    from cmosnoise.app.workbench import _clip_region
    from cmosnoise.model.sensor import region_of

    assert region_of(None, (48, 64)) == (0, 48, 0, 64)
    assert region_of((-5, 100, 60, 200), (48, 64), clip=True) == (0, 48, 60, 64)
    assert _clip_region((47, 47, 70, 80), 48, 64) == (47, 48, 63, 64)  # at least one pixel
    with pytest.raises(CmosnoiseError, match=r"0 <= row0 < row1 <= 48"):
        region_of((0, 49, 0, 64), (48, 64))
    with pytest.raises(BadRequest, match="whole numbers"):
        _clip_region(("a", 1, 2, 3), 48, 64)
