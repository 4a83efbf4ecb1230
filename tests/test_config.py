"""The configuration contract: names, validation, presets, overrides."""

import pytest
import yaml

from cmosnoise import CmosnoiseError, load_config, preset_names


def test_defaults_validate_and_round_trip_through_yaml():
    cfg = load_config()
    again = load_config(extra=yaml.safe_load(cfg.to_yaml()))
    assert again == cfg


@pytest.mark.parametrize(
    "override,needle",
    [
        ("prnu.sigmapct=2", "unknown key 'prnu.sigmapct'"),
        ("prnu.sigma_pct=-1", "prnu.sigma_pct = -1"),
        ("adc.bits=7", "adc.bits = 7"),
        ("adc.bits=17", "adc.bits = 17"),
        ("sensor.cfa=RGBW", "sensor.cfa = 'RGBW'"),
        ("crosstalk.kernel_pct=[[10,10,10],[10,40,10],[10,10,10]]", "sums to 120 %"),
        ("crosstalk.kernel_pct=[[1,1],[1,1]]", "3 x 3"),
        ("sensor.width=abc", "sensor.width = 'abc'"),
        ("adc.black_level_dn=5000", "black_level_dn"),
        ("exposure.integration_time_s=0", "integration_time_s = 0"),
    ],
)
def test_bad_values_name_the_key_and_value(override, needle):
    with pytest.raises(CmosnoiseError) as info:
        load_config(overrides=[override])
    assert needle in str(info.value)


def test_set_parses_yaml_values_and_nested_keys():
    cfg = load_config(overrides=["prnu.sigma_pct=2.5", "sensor.cfa=BGGR", "crosstalk.enabled=false", "seed=9"])
    assert cfg.prnu.sigma_pct == 2.5 and cfg.sensor.cfa == "BGGR" and not cfg.crosstalk.enabled and cfg.seed == 9
    with pytest.raises(CmosnoiseError, match="KEY=VALUE"):
        load_config(overrides=["prnu.sigma_pct"])


def test_per_colour_kernel_is_accepted_and_needs_all_colours():
    k = [[0, 1, 0], [1, 90, 1], [0, 1, 0]]
    cfg = load_config(extra={"crosstalk": {"kernel_pct": {"R": k, "G": k, "B": k}}})
    assert set(cfg.crosstalk.kernel_pct) == {"R", "G", "B"}
    with pytest.raises(CmosnoiseError, match="missing"):
        load_config(extra={"crosstalk": {"kernel_pct": {"R": k, "G": k}}})


def test_presets_exist_and_resolve():
    names = preset_names()
    for name in ["paper-fig3-prnu", "paper-fig4-crosstalk"]:
        assert name in names
    for name in names:
        assert load_config(preset=name).description
    with pytest.raises(CmosnoiseError, match="unknown preset"):
        load_config(preset="nope")


def test_config_file_errors(tmp_path):
    with pytest.raises(CmosnoiseError, match="does not exist"):
        load_config(tmp_path / "none.yaml")
    (tmp_path / "bad.yaml").write_text("prnu: [1, 2\n")
    with pytest.raises(CmosnoiseError, match="not valid YAML"):
        load_config(tmp_path / "bad.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(CmosnoiseError, match="mapping"):
        load_config(tmp_path / "list.yaml")


def test_a_typo_in_a_key_gets_a_suggestion(tmp_path):
    """An unknown key names the section's nearest keys (difflib), nested sections and list items included;
    a key with nothing near gets none."""
    from conftest import cli

    for key, near in [("sensor.temprature_c=30", "'temperature_c'"), ("sensr.width=3", "'sensor'"),
                      ("dark_current.points.0.mean_e_per_sec=3", "'mean_e_per_s'"),
                      ("source_follower.flicker.gumbel_loc=2", "'gumbel_loc_e'")]:
        r = cli("simulate", "--set", key, "--out", tmp_path / "o")
        assert r.returncode == 2 and f"did you mean {near}" in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
    r = cli("simulate", "--set", "sensor.zzzz=1", "--out", tmp_path / "o")
    assert r.returncode == 2 and "unknown key 'sensor.zzzz'" in r.stderr and "did you mean" not in r.stderr


def test_the_yaml_made_by_sections_is_the_whole_documents():
    """Config.to_yaml writes each top-level section on its own (kept by its value: a data set writes one
    configuration per sample); the text equals PyYAML's dump of the whole document, for the default, every
    preset and sampled virtual cameras, and reads back to the same configuration."""
    import yaml

    from cmosnoise.app import dataset as ds
    from cmosnoise.config.loading import preset_names

    configs = [load_config()] + [load_config(preset=name) for name in preset_names()]
    recipe = ds.Recipe(samples=8, crop=(64, 64), cameras=("led", "sony-imx900"), seed=3)
    sources = ds.Sources()
    configs += [ds.settings(recipe, i, sources).config for i in range(8)]
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    for c in configs:
        whole = yaml.dump(c.model_dump(mode="json"), Dumper=dumper, sort_keys=False, default_flow_style=None,
                          width=100)
        assert c.to_yaml() == whole
        assert ds.load_sample_config(c.to_yaml()) == c


def _whole_validation(config, updates):
    """merge_updates as the whole merged data validated (what it was before it validated by section)."""
    from cmosnoise.config.loading import config_values, deep_merge, validate_data

    return validate_data(deep_merge(config_values(config), updates))


def test_merge_updates_by_section_is_the_whole_validation():
    """merge_updates validates only the sections an update names (a data set's sample and a gain row change a
    few of 25): over every preset, a data set's sample keys, single sections, every gain row, and updates that
    must fail, it gives the configuration the whole merged data's validation gives (values, set keys at every
    depth, YAML) and the same error."""
    from cmosnoise.config.loading import config_values, merge_updates
    from cmosnoise.model.physics import gain_updates

    compared = 0
    for name in preset_names():
        base = load_config(preset=name)
        updates = [{"sensor": {"temperature_c": 41.5, "width": 64, "height": 48}, "seed": 7,
                    "run": {"frames": 1, "first_frame": 0}},
                   {"scene": {"source": "zoneplate", "window": [2, 4]}, "exposure": {"integration_time_s": 0.01}},
                   {"prnu": {"sigma_pct": 2}}, {"dark_current": {"white_threshold_e_per_s": 50.0}},
                   {"gain_table": []} if not base.gain_table else {"description": "changed"}]
        updates += [gain_updates(row) for row in base.gain_table]
        for u in updates:
            fast, whole = merge_updates(base, u), _whole_validation(base, u)
            assert fast == whole, (name, u)
            assert config_values(fast) == config_values(whole), (name, u)  # the set keys, at every depth
            assert fast.to_yaml() == whole.to_yaml(), (name, u)
            compared += 1
    assert compared > 60
    base = load_config(preset="sony-imx900")
    for bad in ({"adc": {"black_level_dn": 1e9}}, {"sensor": {"no_such_key": 1}}, {"seed": True},
                {"no_such_section": {}}, {"sensor": {"iso": 123456}}):
        with pytest.raises(CmosnoiseError) as fast:
            merge_updates(base, bad)
        with pytest.raises(CmosnoiseError) as whole:
            _whole_validation(base, bad)
        assert str(fast.value) == str(whole.value)
