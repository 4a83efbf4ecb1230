"""The random streams pinned: the bits of frames and fixed maps, per random-number scheme version.

``tests/golden/scheme-N.json`` holds, for scheme version N, a digest (the
first 16 hex digits of SHA-256 over dtype, shape and bytes) of every fixed
map and of frames 0, 1 and 4 000 000 000 of the default sensor and every
preset at 96 x 64, seed 11, looking at the colour checker. A change that
moves any bit fails here unless it also raises
``cmosnoise.engine.samplers.SCHEME_VERSION`` and adds that version's file
(regenerate it with ``python tests/test_golden.py > tests/golden/scheme-N.json``),
so a consistent change to both the samplers and the kernel cannot pass
unnoticed.
"""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ANOTHER_CPU, X86_64

import cmosnoise
from cmosnoise import Sensor
from cmosnoise.config.loading import preset_names
from cmosnoise.engine.samplers import SCHEME_VERSION

GOLDEN = Path(__file__).parent / "golden" / f"scheme-{SCHEME_VERSION}.json"
MAPS = ("prnu_gain", "dark_rate", "flicker_sigma", "row_offset", "column_sigma", "vfpn", "column_gain")
FRAMES = (0, 1, 4_000_000_000)
MAPS = MAPS + ("pixel_offset",)
#: configurations beyond the presets whose bits are pinned too: every stage of measured sensors on
EXTRA = {"measured-stages": {
    "pixel_offset": {"enabled": True, "sigma_e": 4.0, "tail": {"ppm_above": 2000, "threshold_e": 20, "max_e": 200}},
    "nonlinearity": {"enabled": True, "linearity_error_pct": [-1.2, 0.6]},
    "black_level": {"channel_offsets_dn": [1.5, -0.5, 0.25, 2.0], "frame_sigma_dn": 0.3},
    "read_noise": {"enabled": True, "distribution": "tukey_lambda", "scale_dn": 1.2, "shape": -0.05}},
    # the lens: a diffraction PSF (convolved directly), cos^4 shading, the chief-ray angle's QE loss per channel and
    # its leaning crosstalk (a 2 mm lens, so that the 96 x 64 sensor's corners see 1.6 degrees of field)
    "lens": {
    "optics": {"psf": "diffraction", "f_number": 2.8, "relative_illumination": "cos4", "focal_length_mm": 2.0,
               "chief_ray_angle": [[0, 0], [0.1, 25]], "microlens_compensation": 0.4,
               "angle_relative_qe": [[0, 1, 1, 1], [20, 0.7, 0.8, 0.9]]},
    "crosstalk": {"kernel_at_angle_pct": [[0.6, 4, 1.9], [3, 76, 8], [0.6, 4, 1.9]]}},
    # noise in time (#76): the row noise 1/f in readout order, the column amplifiers 1/f over frames, two column
    # banks fixed and per frame, amplifier glow, and each pixel's 1/f flicker level without CDS
    "noise-in-time": {
    "sensor": {"frame_rate_hz": 30},
    "row_noise": {"spectrum": "one_over_f", "sigma_e": 1.5},
    "column_noise": {"temporal": {"spectrum": "one_over_f"},
                     "alternating": {"enabled": True, "fixed_sigma_e": 1.0, "temporal_sigma_e": 0.5}},
    "dark_current": {"glow": {"enabled": True, "rate_e_per_s": 300.0, "source": "top_left", "length_px": 20.0}},
    "source_follower": {"flicker": {"spectrum": "one_over_f"}, "rts": {"cds": False}}}}


def digest(a: np.ndarray) -> str:
    a = np.ascontiguousarray(a)
    return hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()).hexdigest()[:16]


def measure(name: str | None) -> dict:
    sets = ["sensor.width=96", "sensor.height=64"]
    if name in EXTRA:
        sensor = Sensor(cmosnoise.load_config(overrides=sets, extra=EXTRA[name]), seed=11)
    else:
        sensor = Sensor(cmosnoise.load_config(preset=name, overrides=sets), seed=11)
    fp = sensor.fixed_pattern
    maps = {k: digest(getattr(fp, k)) for k in MAPS if getattr(fp, k) is not None}
    shot = sensor.expose("colorchecker")
    return {"maps": maps, "frames": {str(k): digest(shot.frame(k)) for k in FRAMES}}


def test_the_scheme_version_has_its_golden_file():
    assert GOLDEN.is_file(), (f"random-number scheme {SCHEME_VERSION} has no golden file {GOLDEN.name}: "
                              "a new scheme version needs its bits pinned")


@pytest.mark.parametrize("name", [None, *preset_names(), *EXTRA], ids=lambda n: n or "default")
def test_frames_and_maps_have_the_pinned_bits(name):
    expected = json.loads(GOLDEN.read_text())[name or "default"]
    assert measure(name) == expected, (f"the bits moved under scheme version {SCHEME_VERSION}: raise SCHEME_VERSION "
                                       "and pin the new bits in a new golden file, or undo the change")


@pytest.mark.skipif(not X86_64, reason="x86-64 dispatch targets and BLAS kernels")
@pytest.mark.slow
def test_the_pinned_bits_do_not_depend_on_numpys_simd_the_blas_kernel_or_libm():
    """What another CPU would change, changed on this one (conftest.ANOTHER_CPU): every digest made again in a child
    process whose NumPy, OpenBLAS and libm take other code paths is the pinned one. The nonlinearity's cubic,
    solved through LAPACK under scheme 3, gave another machine other frames of the sony-imx900 preset
    (docs/reproducibility.md)."""
    env = {**os.environ, **ANOTHER_CPU}
    out = subprocess.run([sys.executable, __file__], capture_output=True, text=True, env=env, check=True)
    made, pinned = json.loads(out.stdout), json.loads(GOLDEN.read_text())
    moved = [(name, part, key) for name in pinned for part in pinned[name] for key in pinned[name][part]
             if made[name][part].get(key) != pinned[name][part][key]]
    assert not moved, f"bits that depend on NumPy's SIMD or the BLAS kernel: {moved}"


if __name__ == "__main__":
    print(json.dumps({n or "default": measure(n) for n in [None, *preset_names(), *EXTRA]}, indent=1, sort_keys=True))
