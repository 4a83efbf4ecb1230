"""Virtual cameras: configurations sampled from published camera calibrations, for training data.

The learned-denoising literature synthesizes noise from per-camera
calibrations (ELD, Wei et al., CVPR 2020) and pre-trains on "virtual
cameras" sampled across them (LED, Jin et al., ICCV 2023). The families
here are those calibrations, as ``docs/sensor/published-figures.md`` section 2
quotes them (Vandermode/ELD ``camera_params/release/<camera>_params.npy``;
Srameo/LED ``options/base/noise_g/noise_g_virtual.yaml``):

- ``eld:<camera>``: one camera. K (DN/e-) log-uniform in [Kmin, Kmax]; each
  noise scale s (DN) log-linear in K with scatter,
  ``ln s = slope ln K + bias + Normal(0, sigma)``, for the Tukey-lambda read
  noise's scale (G) and the row noise (R); the Tukey-lambda shape uniform in
  the camera's range.
- ``eld``: one of the five cameras at random, then as above.
- ``led``: LED's virtual cameras: K log-uniform in [0.1, 30]; each slope,
  bias and scatter uniform between the five cameras' extremes; the shape in
  [-0.243, 0.2]; channel black-level offsets in [-1.91, 4.08] DN.

Every family gives the ELD noise model as cmosnoise stages: photon shot
noise, Tukey-lambda read noise after the gain, row noise in DN, the four
channels' black-level offsets, quantization; a 14-bit ADC with black level
512 DN (the A7S II's; the cameras' own black levels differ, the noise model
is in DN above black); the full well beyond the ADC's range (the white
level clips). PRNU, crosstalk, dark current, the source follower and column
noise are off: the calibrations hold none of them. A pure function of a
``numpy.random.Generator``: the caller keys it (a sample's index).
"""

from __future__ import annotations

import math

import numpy as np

#: ELD's five cameras: Kmin, Kmax, (slope, bias, sigma) of ln sigma_TL (G) and of ln sigma_row (R), the Tukey-lambda
#: shape's range (published for two cameras; LED's range for the others)
ELD = {
    "sony-a7s2": {"k": (0.0939, 6.011), "G": (0.4621, 0.5657, 0.2634), "R": (0.5275, -0.5917, 0.2943),
                  "shape": (-0.143, 0.114)},
    "nikon-d850": {"k": (0.4150, 26.56), "G": (0.4774, -0.0904, 0.2392), "R": (0.4483, -1.7977, 0.2322),
                   "shape": (-0.24, -0.11)},
    "canon-5d4": {"k": (0.2182, 13.96), "G": (0.6559, 1.0927, 0.2860), "R": (0.4713, -0.8079, 0.2436),
                  "shape": (-0.243, 0.2)},
    "canon-700d": {"k": (0.4476, 28.65), "G": (0.5982, 1.5370, 0.3888), "R": (0.6221, -0.7756, 0.2485),
                   "shape": (-0.243, 0.2)},
    "canon-70d": {"k": (0.4075, 26.08), "G": (0.4868, 1.4643, 0.3820), "R": (0.7292, -0.9371, 0.2502),
                  "shape": (-0.243, 0.2)},
}
#: LED's virtual cameras
LED = {"k": (0.1, 30.0), "shape": (-0.243, 0.2), "colour_bias_dn": (-1.91, 4.08)}
#: the ADC every family uses
BITS, BLACK_LEVEL_DN = 14, 512.0

FAMILIES = ("eld", "led", *(f"eld:{name}" for name in ELD))


def check(family: str) -> str:
    """``family`` if it is one; raises ValueError naming the families otherwise."""
    if family not in FAMILIES:
        raise ValueError(f"virtual camera family {family!r}: choose one of {', '.join(FAMILIES)}")
    return family


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _log_linear(rng: np.random.Generator, law: tuple[float, ...], k: float) -> float:
    slope, bias, sigma = law
    return float(math.exp(slope * math.log(k) + bias + rng.normal(0.0, sigma)))


def _between_cameras(rng: np.random.Generator, term: str) -> tuple[float, float, float]:
    laws = np.array([c[term] for c in ELD.values()])
    lo, hi = laws.min(axis=0), laws.max(axis=0)
    return float(rng.uniform(lo[0], hi[0])), float(rng.uniform(lo[1], hi[1])), float(rng.uniform(lo[2], hi[2]))


def sample(family: str, rng: np.random.Generator) -> tuple[str, dict]:
    """(camera name, configuration updates) of one virtual camera of ``family``."""
    check(family)
    if family == "led":
        name = "led-virtual"
        k = _log_uniform(rng, *LED["k"])
        g: tuple[float, ...] = _between_cameras(rng, "G")
        r: tuple[float, ...] = _between_cameras(rng, "R")
        shape = float(rng.uniform(*LED["shape"]))
        bias = [float(v) for v in rng.uniform(*LED["colour_bias_dn"], size=4)]
    else:
        name = family.partition(":")[2] or list(ELD)[int(rng.integers(len(ELD)))]
        cam = ELD[name]
        k = _log_uniform(rng, *cam["k"])
        g, r = cam["G"], cam["R"]
        shape = float(rng.uniform(cam["shape"][0], cam["shape"][1]))
        bias = [float(v) for v in rng.uniform(*LED["colour_bias_dn"], size=4)]
    top = 2**BITS - 1 - BLACK_LEVEL_DN
    updates = {
        "sensor": {"cfa": "RGGB", "full_well_e": float(min(1e7, 2.0 * top / k))},
        "prnu": {"enabled": False}, "crosstalk": {"enabled": False}, "dark_current": {"enabled": False},
        "source_follower": {"enabled": False}, "column_noise": {"enabled": False},
        "shot_noise": {"enabled": True},
        "row_noise": {"enabled": True, "sigma_e": 0.0, "fixed_sigma_e": 0.0, "sigma_dn": _log_linear(rng, r, k)},
        "adc": {"enabled": True, "bits": BITS, "black_level_dn": BLACK_LEVEL_DN, "gain_dn_per_e": k},
        "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": _log_linear(rng, g, k),
                       "shape": shape},
        "black_level": {"channel_offsets_dn": bias, "frame_sigma_dn": 0.0},
    }
    return name, updates
