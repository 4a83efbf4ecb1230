"""Gain settings (docs/model.md stage 9b): a table of ISO or dB rows sets K and what else changes with the
setting; the Sony A7S II preset reproduces its published calibration per ISO."""

import json
import math

import numpy as np
import pytest
from conftest import assert_close, cli, quiet_config
from scipy import stats

from cmosnoise import Sensor, load_config

#: docs/sensor/published-figures.md section 1: ISO -> (K DN/e-, lam, sigTL DN, sigR DN)
A7S2 = {100: (0.09563, 0.14875287, 0.70181876, 0.1391465), 1600: (1.53008, -0.0441045, 3.2283993, 0.988786),
        2000: (1.9126, -0.012963797, 1.4356787, 0.33124214), 6400: (6.12032, -0.07517104, 3.4502964, 0.7218788)}


@pytest.mark.parametrize("iso", list(A7S2))
def test_sony_a7s2_characterizes_as_published(iso, tmp_path):
    """characterize of the preset at four ISOs (the step to the high conversion gain at 2000 among them): K within
    2 % of the table, the temporal dark noise within 3 % of what the read-noise parameters imply,
    sqrt(var(Tukey-lambda(lam)) sigTL^2 + sigR^2) / K (the variance from scipy.stats; EMVA 1288's dark noise
    leaves quantization out)."""
    k, lam, s_tl, s_row = A7S2[iso]
    r = cli("-q", "characterize", "-p", "sony-a7s2", "--set", f"sensor.iso={iso}", "--set", "sensor.width=256",
            "--set", "sensor.height=192", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "c" / "characterization.json").read_text())["measured"]
    implied = math.sqrt(stats.tukeylambda(lam).var() * s_tl**2 + s_row**2) / k
    assert m["system_gain_K_dn_per_e"] == pytest.approx(k, rel=0.02)
    assert m["temporal_dark_noise_e"] == pytest.approx(implied, rel=0.03)


def test_read_noise_floor_drops_at_the_conversion_gain_step():
    """The published floor in e-: 4.1 at ISO 1600, 1.4 at ISO 2000 (the sensor's high conversion gain)."""
    from cmosnoise import noise_budget

    floors = {}
    for iso in (1600, 2000):
        sensor = Sensor(load_config(preset="sony-a7s2", overrides=[f"sensor.iso={iso}", "sensor.width=64",
                                                                     "sensor.height=48"]))
        assert sensor.transfer.gain_dn_per_e == A7S2[iso][0]
        parts = noise_budget.temporal_variances(sensor, 0.0)
        floors[iso] = math.sqrt(parts["read_after_gain"] + parts["row"])
    assert floors[1600] == pytest.approx(4.19, abs=0.01) and floors[2000] == pytest.approx(1.40, abs=0.01)


def test_noise_in_electrons_follows_k_and_noise_in_dn_stays():
    """A table of two gains on a sensor whose source follower is 3 e- and whose read noise after the gain is 2 DN:
    the frames' temporal variance in DN^2 is (3 K)^2 + 2^2 + 1/12 at each (two-frame difference over n pixels:
    standard error var sqrt(2/n))."""
    table = [{"gain_db": 0, "k_dn_per_e": 0.5}, {"gain_db": 12, "k_dn_per_e": 2.0}]
    for db, k in ((0, 0.5), (12, 2.0)):
        cfg = quiet_config(sensor={"width": 256, "height": 192},
                           source_follower={"enabled": True, "thermal_sigma_e": 3.0, "flicker": {"enabled": False}},
                           read_noise={"enabled": True, "scale_dn": 2.0})
        cfg = load_config(extra={**cfg.model_dump(), "gain_table": table, "sensor": {**cfg.sensor.model_dump(),
                                                                                     "gain_db": db}})
        shot = Sensor(cfg, seed=1).expose("flat:0")
        a, b = (shot.frame(i).astype(np.float64) for i in (0, 1))
        v = np.var(a - b) / 2
        expected = (3 * k) ** 2 + 4 + 1 / 12
        assert_close(v, expected, expected * math.sqrt(2 / a.size), f"{db} dB")


def test_a_gain_not_in_the_table_is_one_line(tmp_path):
    r = cli("simulate", "-p", "sony-a7s2", "--set", "sensor.iso=1700", "--out", tmp_path / "o")
    assert r.returncode == 2 and "sensor.iso = 1700 is not in the gain table" in r.stderr and "1600" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "o").exists()
    r = cli("simulate", "--set", "sensor.iso=100", "--out", tmp_path / "o")
    assert r.returncode == 2 and "gain_table" in r.stderr


def test_a_row_sets_its_keys_and_wins_over_the_base():
    cfg = load_config(preset="sony-a7s2", overrides=["sensor.iso=6400", "read_noise.scale_dn=99"])
    spec = Sensor(cfg.model_copy(update={"sensor": cfg.sensor.model_copy(update={"width": 64, "height": 48})})).spec
    assert spec.config.read_noise.scale_dn == pytest.approx(3.4502964)  # the row's
    assert spec.config.black_level.channel_offsets_dn == (-2.254,) * 4
    assert spec.transfer.max_code == 16383 and spec.transfer.black_level_dn == 512


@pytest.mark.slow
def test_fit_builds_a_gain_table_from_stacks_at_several_settings(tmp_path):
    """A lab's stacks of the sony-a7s2 at ISO 1600 and 2000 in one manifest (each stack names its iso): the fit
    makes one fit per setting, each K's 95 % interval holds the table's, the conversion-gain step is found at
    2000 (the read floor falls from 4.2 to 1.4 e-), the configuration's gain table reproduces both settings
    (characterize at 2000: K within 2 %, dark noise within 3 % of the implied 1.40 e-), and the round trip of
    every setting agrees."""
    import yaml

    manifest = {"cfa": "RGGB", "bits": 14, "black_level_dn": 512.0, "stacks": []}
    for iso in (1600, 2000):
        r = cli("-q", "measure", "-p", "sony-a7s2", "--set", f"sensor.iso={iso}", "--set", "sensor.width=192",
                "--set", "sensor.height=128", "--long-frames", "48", "--levels", "12", "--out", tmp_path / f"iso{iso}")
        assert r.returncode == 0, r.stderr
        for st in yaml.safe_load((tmp_path / f"iso{iso}" / "manifest.yaml").read_text())["stacks"]:
            manifest["stacks"].append({**st, "iso": iso, "files": [f"iso{iso}/{f}" for f in st["files"]]})
    (tmp_path / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    r = cli("fit", "--frames-from", tmp_path / "manifest.yaml", "--out", tmp_path / "fit")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    for iso in (1600, 2000):
        lo, hi = doc["settings"][str(iso)]["parameters"]["system_gain_K_dn_per_e"]["ci95"]
        assert lo <= A7S2[iso][0] <= hi, (iso, lo, hi)
    assert doc["settings"]["1600"]["mode"] == "LCG" and doc["settings"]["2000"]["mode"] == "HCG"
    assert all(row["agree"] is not False for row in doc["round_trip"]), [r for r in doc["round_trip"] if r["agree"] is False]
    r = cli("-q", "characterize", "--config", tmp_path / "fit" / "config.yaml", "--set", "sensor.iso=2000",
            "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "c" / "characterization.json").read_text())["measured"]
    k, lam, s_tl, s_row = A7S2[2000]
    assert m["system_gain_K_dn_per_e"] == pytest.approx(k, rel=0.02)
    implied = math.sqrt(stats.tukeylambda(lam).var() * s_tl**2 + s_row**2) / k
    assert m["temporal_dark_noise_e"] == pytest.approx(implied, rel=0.03)


#: docs/sensor/published-figures.md section 3: gain_db -> EMVA 1288 figures of the Sony IMX900 data sheet
IMX900 = {0: {"system_gain_K_dn_per_e": 0.399, "temporal_dark_noise_e": 5.560, "saturation_capacity_e": 9458,
              "dsnu_e": 3.7, "prnu_pct": 0.7, "snr_max_db": 39.76, "dynamic_range_db": 63.8},
          3: {"system_gain_K_dn_per_e": 1.673, "temporal_dark_noise_e": 1.954, "saturation_capacity_e": 2183,
              "dsnu_e": 1.3, "prnu_pct": 0.8, "snr_max_db": 33.39, "dynamic_range_db": 59.0}}


@pytest.mark.parametrize("gain_db", list(IMX900))
def test_sony_imx900_characterizes_as_its_data_sheet_in_both_conversion_gains(gain_db, tmp_path):
    """characterize of the preset in each mode against the sheet. Relative tolerances: K 4 % and saturation 6 %
    (EMVA's photon-transfer K and saturation read through the sheet's linearity error, which the preset
    reproduces as a curve: -3.4 % and -4.7 % in LCG), dark noise 4 %, DSNU and PRNU 10 % (on 256 x 192 pixels
    a spatial sigma's 5-sigma sampling error is 5 / sqrt(2 49152) = 1.6 %; the rest is the dark current's share),
    SNR max and dynamic range within 1 dB. The HCG row's saturation 11 %: its cubic meets the sheet's linearity
    error (-0.55, 0.294) exactly since scheme 4 (MINPACK's fit; the trust-region fit stopped at (-0.56, 0.27)),
    and EMVA's saturation read through that curve at the series' point 28 is 6.6 % below the sheet's 2183 e-
    (2040, measured; a cubic cannot give both of the sheet's figures at once), plus one step of the series
    (3.6 %: the variance maximum falls on point 27 with other seeds, 1959 e- measured at seed 1)."""
    r = cli("-q", "characterize", "-p", "sony-imx900", "--set", f"sensor.gain_db={gain_db}", "--set",
            "sensor.width=256", "--set", "sensor.height=192", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "c" / "characterization.json").read_text())["measured"]
    sheet = IMX900[gain_db]
    for key, rel in (("system_gain_K_dn_per_e", 0.04), ("temporal_dark_noise_e", 0.04),
                     ("saturation_capacity_e", 0.06 if gain_db == 0 else 0.11), ("dsnu_e", 0.10), ("prnu_pct", 0.10)):
        assert m[key] == pytest.approx(sheet[key], rel=rel), key
    for key in ("snr_max_db", "dynamic_range_db"):
        assert m[key] == pytest.approx(sheet[key], abs=1.0), key
