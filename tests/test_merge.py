"""Merging keeps every value a user set, nulls included, on every path that merges a configuration.

A ``source_follower.flicker.tail: null`` (no flicker tail) used to come back
as the default tail when a configuration was merged with anything (a seed,
a scene file, a sweep point, a fit): the merge started from a dump that left
nulls out. Each path below merges such a configuration and must keep it.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from cmosnoise import Sensor, load_config, merge_updates
from cmosnoise.model.spec import resolve

NO_TAIL = {"sensor": {"width": 32, "height": 24}, "source_follower": {"flicker": {"tail": None}},
           "dark_current": {"points": [{"temperature_c": 25, "distribution": "normal", "mean_e_per_s": 5.0,
                                        "std_e_per_s": 1.0, "tail": None}]}}


def _no_tail(cfg) -> bool:
    return cfg.source_follower.flicker.tail is None and cfg.dark_current.points[0].tail is None


@pytest.fixture
def no_tail_file(tmp_path):
    path = tmp_path / "no-tail.yaml"
    path.write_text(yaml.safe_dump(NO_TAIL))
    return path


def test_the_defaults_have_tails_so_that_losing_the_null_would_show():
    default = load_config()
    assert default.source_follower.flicker.tail is not None and default.dark_current.points[0].tail is not None
    assert _no_tail(load_config(extra=NO_TAIL))


def test_merge_updates_keeps_a_null_and_the_keys_it_does_not_touch():
    cfg = load_config(extra=NO_TAIL)
    merged = merge_updates(cfg, {"seed": 3, "prnu": {"sigma_pct": 2.0}})
    assert _no_tail(merged) and merged.seed == 3 and merged.prnu.sigma_pct == 2.0
    assert merged.sensor.width == 32
    # a null given in the update replaces a set value
    assert merge_updates(load_config(), {"source_follower": {"flicker": {"tail": None}}}).source_follower.flicker.tail is None


def test_a_resolved_configuration_merges_again_without_disagreeing():
    """measured_pct solved into sigma_pct, then merged: both are now set and still agree."""
    cfg = resolve(load_config(extra={"prnu": {"measured_pct": 1.2}})).config
    again = resolve(merge_updates(cfg, {"seed": 4})).config
    assert again.prnu.sigma_pct == cfg.prnu.sigma_pct and again.seed == 4


def test_sensor_from_a_file_with_another_seed(no_tail_file):
    s = Sensor(no_tail_file, seed=9)
    assert s.seed == 9 and _no_tail(s.config)
    # the flicker map is drawn from the body alone: no pixel above the default tail's threshold
    assert float(s.fixed_pattern.flicker_sigma.max()) < 5.0


def _run(tmp_path, *args):
    from cmosnoise.app.cli import run

    out = tmp_path / "out"
    assert run(["-q", "simulate", *args, "--out", str(out)]) == 0
    return load_config(out / "config.yaml")


def test_simulate_with_a_scene_file_keeps_the_files_nulls(tmp_path, no_tail_file):
    scene = tmp_path / "scene.npy"
    np.save(scene, np.full((24, 32), 0.3))
    assert _no_tail(_run(tmp_path, "--config", str(no_tail_file), "--scene", str(scene)))


def test_set_null_with_a_scene_file(tmp_path):
    scene = tmp_path / "scene.npy"
    np.save(scene, np.full((24, 32), 0.3))
    cfg = _run(tmp_path, "--set", "sensor.width=32", "--set", "sensor.height=24",
               "--set", "source_follower.flicker.tail=null", "--scene", str(scene))
    assert cfg.source_follower.flicker.tail is None


def test_sweep_points_keep_the_bases_nulls():
    from cmosnoise.app.sweep import point_config

    cfg = point_config(load_config(extra=NO_TAIL), {"sensor.temperature_c": 35.0, "seed": 2})
    assert _no_tail(cfg) and cfg.sensor.temperature_c == 35.0


def test_figures_dark_maps_without_tails_have_none():
    from cmosnoise.app.figures import _dark_maps

    maps = _dark_maps([25.0, 45.0], shape=(40, 50), tails=False)
    assert all(state.tail_fraction == 0 for _, state in maps.values())


def test_a_fit_keeps_what_it_did_not_fit():
    from cmosnoise.analysis.fit import fitted_config

    base = load_config(extra=NO_TAIL)
    result = {"parameters": {"system_gain_K_dn_per_e": {"value": 0.5}, "black_level_dn": {"value": 64.0}},
              "meta": {"bits": 12, "shape": [24, 32], "cfa": "RGGB", "temperature_c": 25.0}, "dark": {}}
    fitted = fitted_config(base, result)
    assert fitted.source_follower.flicker.tail is None
