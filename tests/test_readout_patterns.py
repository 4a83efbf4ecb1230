"""The readout's other patterns (#76): two-phase column amplifiers (the even and the odd columns' banks, fixed and
per frame) and amplifier glow (a dark rate rising from a corner or an edge). Statistics as statistics: each
tolerance names the estimator's spread it is five standard errors of."""

import math

import numpy as np
import pytest
from conftest import cli
from scipy import stats
from test_flicker_in_time import QUIET  # one quiet sensor for the tests of noise in time

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import noise_budget
from cmosnoise.model.seeds import fixed_key
from cmosnoise.model.stages import amplifier_glow, column_noise


def _config(extra: dict, rows: int = 32, cols: int = 48):
    out = {k: dict(v) for k, v in QUIET.items()}
    for k, v in extra.items():
        out[k] = {**out.get(k, {}), **v}
    out["sensor"] = {"width": cols, "height": rows}
    return load_config(extra=out)


def _alternating(fixed: float, temporal: float) -> dict:
    return {"column_noise": {"enabled": True, "vfpn_sigma_e": 0.0, "temporal": {"enabled": False},
                             "alternating": {"enabled": True, "fixed_sigma_e": fixed, "temporal_sigma_e": temporal}}}


# ------------------------------------------------------------------ two-phase column amplifiers
def test_each_bank_has_one_fixed_offset_drawn_from_its_normal():
    sigma = 3.0
    banks = np.array([column_noise.alternating_offsets(0, 2, sigma, fixed_key(seed, "column_noise", 3))[0]
                      for seed in range(2000)], np.float64)
    # KS of 4000 draws (two banks of 2000 instances) against Normal(0, sigma): p below 1e-4 would fail by chance
    # once in ten thousand runs; the seeds are fixed, so it is one draw
    assert stats.kstest(banks.ravel() / sigma, "norm").pvalue > 1e-4
    assert abs(np.corrcoef(banks[:, 0], banks[:, 1])[0, 1]) < 5 / math.sqrt(2000)  # the banks are independent
    vfpn = Sensor(_config(_alternating(sigma, 0.0)), seed=7).fixed_pattern.vfpn.ravel()
    assert np.all(vfpn[0::2] == vfpn[0]) and np.all(vfpn[1::2] == vfpn[1]) and vfpn[0] != vfpn[1]
    with_vfpn = _alternating(sigma, 0.0)
    with_vfpn["column_noise"]["vfpn_sigma_e"] = 1.0  # the banks join each column's own offset
    both = Sensor(_config(with_vfpn), seed=7).fixed_pattern.vfpn.ravel()
    own = Sensor(_config({"column_noise": {**with_vfpn["column_noise"], "alternating": {"enabled": False}}}),
                 seed=7).fixed_pattern.vfpn.ravel()
    np.testing.assert_allclose(both - own, vfpn, atol=1e-5)


def test_the_banks_offsets_per_frame_have_their_variance_and_every_copy_of_the_chain_agrees():
    sigma, frames = 1.5, 400
    sensor = Sensor(_config(_alternating(0.0, sigma)), seed=4)
    shot = sensor.expose("flat:0.0")
    for k in (0, 1, 1000, 10**6):
        np.testing.assert_array_equal(shot.frame(k), shot.frame(k, detail=True).raw, err_msg=f"frame {k}")
    np.testing.assert_array_equal(shot.frame(9, region=(4, 20, 6, 30)), shot.frame(9)[4:20, 6:30])
    tile = Sensor(_config(_alternating(0.0, sigma)), seed=4, window=(4, 20, 6, 30)).expose("flat:0.0")
    np.testing.assert_array_equal(tile.frame(9), shot.frame(9)[4:20, 6:30])
    stack = (np.stack(list(shot.frames(frames))).astype(np.float64) - 1000.0) / 4.0  # e-
    d = stack[:, :, 0::2].mean(axis=(1, 2)) - stack[:, :, 1::2].mean(axis=(1, 2))
    # each frame's even-minus-odd difference: 2 sigma^2 plus the quantizer's share (1/12 DN^2 per pixel, averaged
    # over each bank's pixels); its variance over 400 frames has a standard error of v sqrt(2 / 399)
    q = (1 / 12) / 16.0  # e-^2 a pixel
    want = 2 * sigma**2 + 2 * q / (stack[0].size / 2)
    assert abs(d.var(ddof=1) - want) < 5 * want * math.sqrt(2 / (frames - 1))
    # the noise budget carries it: a pixel's temporal variance is sigma^2 (plus the quantizer's); the pixels of a
    # bank share it, so the spread is that of one variance over 400 frames
    parts = noise_budget.temporal_variances(sensor, 0.0)
    assert parts["column_alternating"] == pytest.approx(sigma**2)
    measured = float(stack.var(axis=0, ddof=1).mean())
    assert abs(measured - sum(parts.values())) < 5 * sigma**2 * math.sqrt(2 / (frames - 1))


@pytest.mark.gpu
def test_the_gpu_gives_the_cpus_bits_with_the_banks_offsets_per_frame():
    """The banks' offsets of each frame are made on the host and uploaded with the batch (the GPU refused them
    before #76's last step): frames far apart, the CPU kernel's bits (numba's CUDA simulator without a GPU)."""
    cfg = _config(_alternating(0.5, 1.0), 8, 12)  # small: the simulator's time is its pixels'
    cpu = Sensor(cfg, seed=1).expose("flat:0.2")
    gpu = Sensor(cfg, seed=1, device="cuda").expose("flat:0.2")
    frames = [0, 5, 1_000_000]
    raw, _ = gpu.frames_on_device(frames)
    for b, k in enumerate(frames):
        np.testing.assert_array_equal(raw.copy_to_host()[b], cpu.frame(k), err_msg=f"frame {k}")


# ------------------------------------------------------------------ amplifier glow
def _glow(source: str = "top_right", rate: float = 2000.0, length: float = 10.0, temperature: float = 25.0,
          shot: bool = True) -> dict:
    return {"dark_current": {"enabled": True, "shot_noise": shot,
                             "glow": {"enabled": True, "rate_e_per_s": rate, "source": source, "length_px": length}},
            "sensor": {"temperature_c": temperature}}


@pytest.mark.parametrize("source", amplifier_glow.SOURCES)
def test_the_glow_falls_exponentially_from_its_source(source):
    rows, cols, rate, length = 20, 30, 500.0, 7.0
    g = amplifier_glow.glow_map((0, rows, 0, cols), (rows, cols), rate, source, length).astype(np.float64)
    r = np.arange(rows)[:, None] + 0.5
    c = np.arange(cols)[None, :] + 0.5
    dr = r if "top" in source else rows - r
    dc = c if "left" in source else cols - c
    d = {"top": dr + 0 * c, "bottom": dr + 0 * c, "left": dc + 0 * r, "right": dc + 0 * r}.get(
        source, np.sqrt(dr**2 + dc**2))
    np.testing.assert_allclose(g, rate * np.exp(-d / length), rtol=2e-7)  # float32 of fdmath's exp
    np.testing.assert_array_equal(amplifier_glow.glow_map((4, 11, 9, 25), (rows, cols), rate, source, length),
                                  g[4:11, 9:25].astype(np.float32))
    assert np.all(amplifier_glow.glow_map((0, 2, 0, 2), (2, 2), 1e7, source, 1e-6) >= 0)  # no overflow


def test_the_glow_is_a_dark_rate_that_integrates_and_does_not_follow_the_temperature():
    cfg = _config(_glow())
    sensor = Sensor(cfg, seed=3)
    plain = Sensor(_config({"dark_current": {"enabled": True}}), seed=3)
    glow = sensor.dark_rate.astype(np.float64) - plain.dark_rate.astype(np.float64)
    np.testing.assert_allclose(glow, amplifier_glow.glow_map((0, 32, 0, 48), (32, 48), 2000.0, "top_right", 10.0),
                               rtol=1e-5, atol=1e-3)
    hot = Sensor(_config(_glow(temperature=65.0)), seed=3)
    hot_plain = Sensor(_config({"dark_current": {"enabled": True}, "sensor": {"temperature_c": 65.0}}), seed=3)
    np.testing.assert_allclose(hot.dark_rate.astype(np.float64) - hot_plain.dark_rate.astype(np.float64), glow,
                               rtol=1e-4, atol=1e-2)
    # a 1 s dark frame: the corner pixel's mean over frames is its rate times the exposure, within 5 standard
    # errors of a Poisson mean (sqrt(mean / frames))
    long = Sensor(load_config(extra={**{k: dict(v) for k, v in QUIET.items()}, **_glow(),
                                     "exposure": {"integration_time_s": 1.0}, "sensor": {"width": 48, "height": 32}}),
                  seed=3)
    stack = (np.stack(list(long.expose("flat:0.0").frames(64))).astype(np.float64) - 1000.0) / 4.0
    mean = float(long.dark_rate[0, -1])
    assert abs(stack[:, 0, -1].mean() - mean) < 5 * math.sqrt(mean / 64)
    shot = long.expose("flat:0.0")
    np.testing.assert_array_equal(shot.frame(5), shot.frame(5, detail=True).raw)


@pytest.mark.parametrize("key, value, needle", [
    ("dark_current.glow.source", "middle", "top_right"),
    ("dark_current.glow.length_px", "0", "greater than 0"),
    ("dark_current.glow.rate_e_per_s", "-1", "greater than or equal to 0"),
    ("column_noise.alternating.temporal_sigma_e", "-2", "greater than or equal to 0"),
])
def test_a_bad_glow_or_bank_setting_is_one_line(tmp_path, key, value, needle):
    r = cli("simulate", "--set", "sensor.width=64", "--set", "sensor.height=48", "--set", f"{key}={value}",
            "--out", tmp_path / "o")
    lines = [x for x in r.stderr.strip().splitlines() if " compil" not in x]
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert key in lines[0] and needle in lines[0], lines[0]
    assert not (tmp_path / "o").exists()
