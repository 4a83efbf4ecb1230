"""Every temporal stage of the frame chain, switched on alone, held to each copy of the chain (#75): the compiled
kernel, the NumPy reference and the GPU kernel (numba's CUDA simulator here) give the same bits, and the measured
temporal variance is the noise budget's prediction (the analytic twin that summary.json reports) within its
standard error. The stages are plan.STAGES: a stage added to the kernels without a row in CONFIGS below fails
here, and a stage added to the kernels and not to noise_budget fails its variance."""

import math

import numpy as np
import pytest

from cmosnoise import Sensor, load_config
from cmosnoise.analysis import noise_budget
from cmosnoise.engine.frame import plan as frame_plan

Z = 5.0  # standard errors
QUIET = {"prnu": {"enabled": False}, "crosstalk": {"enabled": False}, "shot_noise": {"enabled": False},
         "dark_current": {"enabled": False}, "source_follower": {"enabled": False}, "row_noise": {"enabled": False},
         "column_noise": {"enabled": False}, "read_noise": {"enabled": False}, "pixel_offset": {"enabled": False},
         "nonlinearity": {"enabled": False}, "defects": {"enabled": False},
         "adc": {"enabled": True, "bits": 16, "gain_dn_per_e": 4.0, "black_level_dn": 1000},
         "exposure": {"peak_rate_e_per_s": 1000.0, "integration_time_s": 0.5}}
#: the shot noise of a 500 e- grey carries the stages that have no randomness of their own (the ADC's rounding,
#: the charge-to-voltage curve, fixed offsets): their effect on the temporal variance is what is predicted
SHOT = {"shot_noise": {"enabled": True}}
#: each stage of plan.STAGES: the configuration that switches it on alone (over QUIET), and what its temporal
#: noise is common to ("pixel": independent pixels; "row", "column", "frame": one value a row, a column, a frame)
CONFIGS = {
    "shot_noise": (SHOT, "pixel"),
    "source_follower": ({"source_follower": {"enabled": True, "thermal_sigma_e": 3.0,
                                             "flicker": {"enabled": True}}}, "pixel"),
    "row_noise": ({"row_noise": {"enabled": True, "sigma_e": 2.0}}, "row"),
    "column_noise": ({"column_noise": {"enabled": True, "vfpn_sigma_e": 0.0,
                                       "temporal": {"enabled": True, "gumbel_loc_e": 2.0, "gumbel_scale_e": 0.3}}},
                     "column"),
    "adc": ({**SHOT, "adc": {"enabled": True, "bits": 12, "gain_dn_per_e": 0.3, "black_level_dn": 100}}, "pixel"),
    "nonlinearity": ({**SHOT, "nonlinearity": {"enabled": True, "linearity_error_pct": [-1.133, 0.595]}}, "pixel"),
    "pixel_offset": ({**SHOT, "pixel_offset": {"enabled": True, "sigma_e": 5.0}}, "pixel"),
    "read_noise": ({"read_noise": {"enabled": True, "distribution": "normal", "scale_dn": 3.0}}, "pixel"),
    "source_follower_rts": ({"source_follower": {"enabled": True, "thermal_sigma_e": 0.5,
                                                 "flicker": {"enabled": False},
                                                 "rts": {"enabled": True, "ppm": 300000}}}, "pixel"),
    "dark_current_rts": ({"dark_current": {"enabled": True, "shot_noise": False,
                                           "rts": {"enabled": True, "ppm": 300000}}}, "pixel"),
    "black_level": ({"black_level": {"frame_sigma_dn": 3.0}}, "frame"),
}
ROWS, COLS, FRAMES = 48, 64, 96


def _merged(extra: dict) -> dict:
    out = {k: dict(v) for k, v in QUIET.items()}
    for k, v in extra.items():
        out[k] = {**out.get(k, {}), **v}
    return {**out, "sensor": {"width": COLS, "height": ROWS}}


def test_every_stage_of_the_table_has_a_configuration_here():
    names = [s.name for s in frame_plan.STAGES]
    missing = [n for n in names if n not in CONFIGS]
    assert not missing, f"stages of plan.STAGES that no configuration switches on alone here: {missing}"
    assert set(CONFIGS) == set(names)


@pytest.mark.parametrize("stage", [s.name for s in frame_plan.STAGES])
def test_a_stage_alone_is_the_same_bits_in_the_kernel_and_the_reference_and_the_budgets_variance(stage):
    extra, common = CONFIGS[stage]
    sensor = Sensor(load_config(extra=_merged(extra)), seed=21)
    scene = "flat:0.0" if "shot_noise" not in extra else "flat:1.0"
    shot = sensor.expose(scene)
    for k in (0, 1000):
        np.testing.assert_array_equal(shot.frame(k), shot.frame(k, detail=True).raw, err_msg=f"{stage}, frame {k}")
    frames = np.stack(list(shot.frames(FRAMES))).astype(np.float64)
    per_pixel = frames.var(axis=0, ddof=1)
    measured = float(per_pixel.mean())
    signal = float(shot.photo_mean_e.mean()) if "shot_noise" in extra else 0.0
    k2 = sensor.transfer.gain_dn_per_e ** 2
    parts = noise_budget.temporal_variances(sensor, signal)
    predicted = sum(parts.values()) * k2
    # the standard error of the mean of per-pixel variances over FRAMES - 1 degrees of freedom: independent pixels
    # give the spread of their variances over their number; a noise common to a row (column, frame) has as many
    # independent samples as rows (columns, 1), each of variance 2 v^2 / dof
    dof = FRAMES - 1
    if common == "pixel":
        se = float(per_pixel.std(ddof=1)) / math.sqrt(per_pixel.size)
    else:
        n = {"row": ROWS, "column": COLS, "frame": 1}[common]
        se = math.sqrt(2.0 * predicted**2 / dof / n + 2.0 * (k2 / 12.0) ** 2 / dof / per_pixel.size)
    assert predicted > 0, (stage, parts)
    assert abs(measured - predicted) <= Z * se, (stage, measured, predicted, se, parts)
    # and the ground truth's expected raw is the frames' mean: over pixels, within the mean's standard error (its
    # noise common to a row, a column or a frame has that many independent samples)
    from cmosnoise.analysis import ground_truth

    offset = float((frames.mean(axis=0) - ground_truth.expected_raw(shot)).mean())
    n = {"pixel": per_pixel.size, "row": ROWS, "column": COLS, "frame": 1}[common]
    assert abs(offset) <= Z * math.sqrt(measured / FRAMES / n) + 1e-3, (stage, offset)


@pytest.mark.gpu
@pytest.mark.slow
@pytest.mark.parametrize("stage", [s.name for s in frame_plan.STAGES])
def test_a_stage_alone_is_the_same_bits_on_the_gpu(stage):
    # numba's CUDA simulator runs each thread in Python: a small sensor, one frame far from the first
    extra, _ = CONFIGS[stage]
    config = load_config(extra={**_merged(extra), "sensor": {"width": 16, "height": 12}})
    scene = "flat:0.0" if "shot_noise" not in extra else "flat:1.0"
    cpu = Sensor(config, seed=21).expose(scene).frame(1000)
    gpu = Sensor(config, seed=21, device="cuda").expose(scene).frame(1000)
    np.testing.assert_array_equal(cpu, np.asarray(gpu), err_msg=stage)
