"""Stage 9: the ADC follows docs/model.md's formula exactly."""

import numpy as np
import pytest
from conftest import quiet_config

from cmosnoise import Sensor
from cmosnoise.model.stages.adc import Transfer, convert


def reference(n, bits, black, full_scale):
    top = 2**bits - 1
    k = (top - black) / full_scale
    return np.clip(np.rint(n.astype(np.float64) * k + black), 0, top).astype(np.uint16)


@pytest.mark.parametrize("bits,black,fs", [(8, 0, 255.0), (10, 16, 6000.0), (12, 64, 10000.0), (16, 1000, 33333.3)])
def test_formula_black_level_rounding_and_clipping(bits, black, fs):
    rng = np.random.default_rng(bits)
    n = rng.uniform(-0.2 * fs, 1.3 * fs, 200_000).astype(np.float32)
    t = Transfer.from_settings(bits, black, fs)
    out = convert(n, t)
    np.testing.assert_array_equal(out, reference(n, bits, black, fs))
    assert out.min() == 0 and out.max() == 2**bits - 1
    assert t.gain_dn_per_e == pytest.approx((2**bits - 1 - black) / fs)


def test_half_codes_round_to_even_and_negative_charge_stays_above_zero():
    t = Transfer.from_settings(12, 64, 4031.0)  # K = 1 DN/e- exactly
    n = np.array([0.5, 1.5, 2.5, -63.6, -64.4, -200, 4031.0, 5000.0], np.float32)
    assert convert(n, t).tolist() == [64, 66, 66, 0, 0, 0, 4095, 4095]


def test_ideal_readout_when_adc_is_off():
    cfg = quiet_config(adc={"enabled": False}, sensor={"width": 8, "height": 8, "cfa": "none"},
                       exposure={"integration_time_s": 1, "peak_rate_e_per_s": 1234.4})
    raw = Sensor(cfg).capture(scene="flat:1.0")
    # docs/model.md stage 9: the ideal readout is the charge itself, float32 e-, unquantized
    assert raw.dtype == np.float32 and (raw == np.float32(1234.4)).all()


def test_all_stages_off_gives_the_perfect_image_quantized():
    cfg = quiet_config(sensor={"width": 32, "height": 24})
    sensor = Sensor(cfg)
    shot = sensor.expose("colorchecker")
    raw = shot.frame(0)
    np.testing.assert_array_equal(raw, convert(shot.perfect_e, sensor.transfer))


def test_full_scale_defaults_to_full_well():
    cfg = quiet_config(sensor={"full_well_e": 5000}, adc={"bits": 10, "black_level_dn": 0})
    assert Sensor(cfg).transfer.gain_dn_per_e == pytest.approx(1023 / 5000)
    cfg = quiet_config(sensor={"full_well_e": 5000}, adc={"bits": 10, "black_level_dn": 0, "full_scale_e": 2000})
    assert Sensor(cfg).transfer.gain_dn_per_e == pytest.approx(1023 / 2000)


def test_full_well_clips_before_the_adc():
    cfg = quiet_config(sensor={"width": 8, "height": 8, "full_well_e": 1000, "cfa": "none"},
                       adc={"bits": 12, "black_level_dn": 0, "full_scale_e": 4095},
                       exposure={"integration_time_s": 1, "peak_rate_e_per_s": 3000})
    raw = Sensor(cfg).capture(scene="flat:1.0")
    assert (raw == 1000).all()  # 1 DN/e-, charge stopped at the full well, not at the ADC top


@pytest.mark.parametrize("sigma", [0.0, 0.02, 0.1, 0.3, 0.6, 1.5])
def test_expected_code_is_the_mean_of_the_rounded_noisy_value(sigma):
    """E[round(mu + sigma Z)] against a Monte Carlo mean, within 5 standard errors of that mean."""
    from cmosnoise.model.stages.adc import expected_code

    rng = np.random.default_rng(7)
    mu = np.linspace(10.0, 11.0, 41)  # every position between two codes, the half-codes included
    n = 100_000
    x = np.round(mu[:, None] + sigma * rng.standard_normal((mu.size, n)))
    mc = x.mean(axis=1)
    se = np.sqrt(np.maximum(x.var(axis=1), 1.0 / n) / n)  # floor: a rare code (p ~ 1/n) may not be drawn at all
    got = expected_code(mu, np.full(mu.size, sigma))
    if sigma == 0.0:
        assert np.array_equal(got, np.rint(mu))  # as the ADC rounds: half codes to even
    else:
        assert np.all(np.abs(got - mc) <= 5 * se + 1e-12)
    if sigma >= 1.0:  # dithered: the quantizer adds no bias
        assert np.allclose(got, mu, atol=1e-8)


# ------------------------------------------------------------------ an ADC's codes scaled to a wider range
def test_an_adc_in_a_wider_range_writes_its_codes_times_the_step():
    """docs/model.md stage 9: DN = step * clip(round((e K + black) / step), 0, 2^bits - 1), step = 2^(out - bits)."""
    rng = np.random.default_rng(14)
    n = rng.uniform(-500, 16000, 200_000).astype(np.float32)
    t = Transfer.from_gain(14, 642.7, 4.545, output_bits=16)
    assert (t.step, t.max_code, t.output_bits) == (4, 65532, 16)
    out = convert(n, t)
    assert (out % 4 == 0).all() and out.max() == 65532 and out.min() == 0
    # the same codes as the ADC counted in its own codes (K and black divided by 4), times 4
    np.testing.assert_array_equal(out, 4 * convert(n, t.adc_codes()).astype(np.uint32))
    # without output_bits the step is 1: the transfer of before, bit for bit
    assert Transfer.from_gain(14, 642.7, 4.545) == Transfer(4.545, 642.7, 14, 1)


def test_the_quantizer_adds_a_step_squared_over_12():
    """The rounding error of a charge spread over many codes is uniform over one step: variance step^2 / 12.
    Its sample variance over n values has standard error sqrt((mu4 - sigma^4) / n), mu4 = step^4 / 80 for a
    uniform; the test allows 5 of them."""
    rng = np.random.default_rng(3)
    n = rng.uniform(100, 2_000, 400_000)  # below the top code of each (12 bits: 4095 DN at 2371 e-)
    for bits, out_bits in ((12, 12), (12, 16), (10, 16)):
        t = Transfer.from_gain(bits, 64.0, 1.7, output_bits=out_bits)
        err = convert(n, t).astype(np.float64) - (n * t.gain_dn_per_e + t.black_level_dn)
        s = t.step
        se = np.sqrt((s**4 / 80 - (s**2 / 12) ** 2) / n.size)
        assert abs(err.var() - t.quantization_var_dn2) < 5 * se, (s, err.var())
        assert abs(err.mean()) < 5 * s / np.sqrt(12 * n.size)


def test_an_output_range_narrower_than_the_adc_is_refused_with_its_keys():
    from cmosnoise import load_config
    from cmosnoise.errors import CmosnoiseError

    with pytest.raises(CmosnoiseError, match=r"adc.output_bits = 12 is below adc.bits = 14"):
        load_config(extra={"adc": {"bits": 14, "output_bits": 12}})
    with pytest.raises(CmosnoiseError, match=r"adc.black_level_dn = 65533 .*top code 65532"):
        load_config(extra={"adc": {"bits": 14, "output_bits": 16, "black_level_dn": 65533}})


@pytest.mark.parametrize("sigma", [0.0, 0.3, 1.2, 6.0])
def test_the_expected_output_code_rounds_in_the_adcs_codes(sigma):
    """E[step round((mu + sigma Z) / step)] against a Monte Carlo mean, within 5 standard errors."""
    from cmosnoise.model.stages.adc import expected_output

    t = Transfer.from_gain(14, 0.0, 1.0, output_bits=16)
    rng = np.random.default_rng(11)
    mu = np.linspace(40.0, 44.0, 33)  # one ADC code's span, at every eighth of an output DN
    x = 4 * np.round((mu[:, None] + sigma * rng.standard_normal((mu.size, 100_000))) / 4)
    se = np.sqrt(np.maximum(x.var(axis=1), 16.0 / 100_000) / 100_000)
    got = expected_output(mu, np.full(mu.size, sigma), t)
    assert np.all(np.abs(got - x.mean(axis=1)) <= 5 * se + 1e-12)


def test_the_step_is_read_from_the_codes():
    from cmosnoise.model.stages.adc import code_grid, code_step

    rng = np.random.default_rng(2)
    codes = 4 * rng.integers(100, 16000, 5000)
    assert code_step(code_grid(codes)) == 4
    assert code_step(code_grid(codes) | code_grid(codes + 2)) == 2  # ORed over frames: the finest spacing
    assert code_step(code_grid(np.full(100, 64))) == 1  # all one code: it cannot tell
    assert code_step(code_grid(codes + 0.5)) == 1  # not codes
