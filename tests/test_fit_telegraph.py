"""The random telegraph fit: found pixels, amplitudes and dwell times from a dark stack, and its round trip.

The coverage over 20 sensors (#29: ppm within its binomial interval, medians within 10 %, 95 % intervals
holding the truth at least 17 times in 20) is benchmarks/fit_telegraph_coverage.py's; here one sensor, whose
every check is a property of the fit that a regression breaks.
"""

import math

import numpy as np
import pytest
from conftest import Z

from cmosnoise import Sensor
from cmosnoise.analysis import fit_telegraph
from cmosnoise.model.stages import random_telegraph

#: a sensor whose traps are read without CDS (levels held over frames), amplitudes well above the read noise and
#: dwell times of a few frames, so that every trap switches many times in the stack
CONFIG = {"sensor": {"width": 192, "height": 128, "frame_rate_hz": 30},
          "exposure": {"integration_time_s": 0.01},
          "source_follower": {"rts": {"enabled": True, "ppm": 3000, "cds": False,
                                      "amplitude_e": {"median": 20, "sigma_log": 0.3},
                                      "tau_capture_s": {"min_s": 0.15, "max_s": 0.35},
                                      "tau_emission_s": {"min_s": 0.15, "max_s": 0.35}}}}
FRAMES = 600


def stack(config, seed):
    sensor = Sensor(config, seed=seed)
    return sensor, np.stack(list(sensor.expose("flat:0").frames(FRAMES)))


@pytest.fixture(scope="module")
def fitted():
    sensor, frames = stack(CONFIG, 5)
    return sensor, fit_telegraph.fit(frames, sensor.transfer.gain_dn_per_e, 1 / 30)


@pytest.mark.slow
def test_the_fit_finds_exactly_the_trap_pixels_and_their_amplitudes(fitted):
    """Every trap pixel and no other (the flicker tail's noisy but white pixels included: the default config
    has them); each amplitude within 5 standard errors of its level difference (se of two level means over
    their frames: sigma sqrt(1/n0 + 1/n1) >= sigma sqrt(4 / F), in e-)."""
    sensor, r = fitted
    traps = sensor.fixed_pattern.traps
    assert sorted(r["pixels"]) == traps.pixels.tolist()
    truth = dict(zip(traps.index.tolist(), traps.size))
    sigma_e = r["noise_dn"] / sensor.transfer.gain_dn_per_e
    for p, a in zip(r["pixels"], r["amplitude_e"]):
        # the levels' means have se sigma sqrt(1/n0 + 1/n1); n0, n1 >= F/8 here (occupancy 0.3 to 0.7); the
        # codes are rounded, which moves a mean of codes by at most half a code (0.5 / K e-) from the charge's
        assert abs(a - truth[p]) <= Z * sigma_e * math.sqrt(16 / FRAMES) + 0.5 / sensor.transfer.gain_dn_per_e, p


@pytest.mark.slow
def test_dwell_times_per_pixel_are_unbiased_and_the_ppm_interval_holds_the_truth(fitted):
    """The ratio of the estimated to the true dwell time, over the pixels found, has mean 1 within 5 se (its
    sample std over sqrt(n)); the Clopper-Pearson interval holds the configured ppm."""
    sensor, r = fitted
    traps = sensor.fixed_pattern.traps
    low = dict(zip(traps.index.tolist(), traps.tau_low_s))
    high = dict(zip(traps.index.tolist(), traps.tau_high_s))
    for name, truth in (("tau_low_s", low), ("tau_high_s", high)):
        ratio = np.array(r[name]) / np.array([truth[p] for p in r["pixels"]])
        assert abs(ratio.mean() - 1) <= 5 * ratio.std(ddof=1) / math.sqrt(ratio.size), (name, ratio.mean())
    lo, hi = r["ppm_ci95"]
    assert lo <= CONFIG["source_follower"]["rts"]["ppm"] <= hi


@pytest.mark.slow
def test_round_trip_a_sensor_made_from_the_fit_fits_alike(fitted):
    """The fitted section, simulated on a sensor of another seed, fits again to medians within each other's
    95 % intervals and a ppm within the first fit's interval."""
    sensor, first = fitted
    sec = fit_telegraph.section(first)
    config = {**CONFIG, "source_follower": {"rts": sec}}
    again_sensor, frames = stack(config, 6)
    again = fit_telegraph.fit(frames, again_sensor.transfer.gain_dn_per_e, 1 / 30)
    lo, hi = first["ppm_ci95"]
    assert lo <= again["ppm"] <= hi or again["ppm_ci95"][0] <= first["ppm"] <= again["ppm_ci95"][1]
    for name in ("amplitude_e", "tau_low_s", "tau_high_s"):
        a, b = first[f"median_{name}_ci95"], again[f"median_{name}_ci95"]
        assert a[0] <= b[1] and b[0] <= a[1], (name, a, b)


def test_a_short_stack_is_refused_in_one_line():
    with pytest.raises(ValueError, match="at least 50"):
        fit_telegraph.fit(np.zeros((10, 4, 4)), 1.0, 0.03)


# ------------------------------------------------------------------ cmosnoise fit
@pytest.mark.slow
def test_cmosnoise_fit_finds_the_random_telegraph_pixels_of_a_measurement_and_its_round_trip_agrees(tmp_path):
    """``measure`` writes a 300-frame dark stack with its frame period; ``fit`` reads it again, finds the trap
    pixels (ppm interval holding the sensor's own count, Clopper-Pearson), puts a ``source_follower.rts`` section
    in config.yaml, leaves those pixels out of the pixel offsets and the source follower (else their held levels
    come back twice: a pixel-offset tail of about the traps' ppm in the round trip), and its round trip agrees."""
    import yaml

    from cmosnoise import load_config
    from cmosnoise.app import fitting

    rts = {"enabled": True, "ppm": 3000, "cds": False, "amplitude_e": {"median": 20, "sigma_log": 0.3},
           "tau_capture_s": {"min_s": 0.01, "max_s": 0.03}, "tau_emission_s": {"min_s": 0.01, "max_s": 0.03}}
    cfg = load_config(extra={"sensor": {"width": 192, "height": 128}, "source_follower": {"rts": rts}})
    manifest = fitting.write_measurement(cfg, tmp_path / "m", long_frames=300)
    assert yaml.safe_load(manifest.read_text())["stacks"][0]["frame_period_s"] == 0.005
    doc = fitting.run(manifest, load_config(), tmp_path / "fit", False)
    truth = Sensor(cfg).fixed_pattern.traps.pixels.size * 1e6 / (192 * 128)
    p = doc["parameters"]
    lo, hi = p["source_follower.rts.ppm"]["ci95"]
    assert lo <= truth <= hi, (truth, lo, hi)
    assert "0.005 s apart (the manifest's)" in p["source_follower.rts.ppm"]["method"]
    for name in ("amplitude_e", "tau_low_s", "tau_high_s"):
        assert p[f"source_follower.rts.median_{name}"]["ci95"] is not None
    fitted = yaml.safe_load((tmp_path / "fit" / "config.yaml").read_text())["source_follower"]["rts"]
    assert fitted["enabled"] and fitted["cds"] is False
    # the pixel offsets without the trap pixels: a tail there (the sensor has no offsets) is not the traps again,
    # which gave one of about their ppm (3133 ppm here) before they were left out
    assert p.get("pixel_offset.tail.ppm_above", {"value": 0})["value"] < p["source_follower.rts.ppm"]["ci95"][0]
    doc = fitting.run(manifest, load_config(), tmp_path / "fit2", False, with_round_trip=True)
    rows = {r["parameter"]: r for r in doc["round_trip"]}
    assert all(rows[f"source_follower.rts.{n}"]["agree"] for n in
               ("ppm", "median_amplitude_e", "median_tau_low_s", "median_tau_high_s")), doc["round_trip"]


@pytest.mark.slow
def test_a_measurement_without_random_telegraph_pixels_fits_none_and_a_short_stack_says_why(tmp_path):
    import yaml

    from cmosnoise import load_config
    from cmosnoise.app import fitting

    cfg = load_config(extra={"sensor": {"width": 96, "height": 64}})
    told = []  # measure's progress (frames made of frames to make) and fit's phases: what a terminal shows
    manifest = fitting.write_measurement(cfg, tmp_path / "m", long_frames=60, progress=lambda d, t: told.append((d, t)))
    frames = sum(e["files"] and len(np.load(tmp_path / "m" / e["files"][0], mmap_mode="r"))
                 for e in yaml.safe_load(manifest.read_text())["stacks"])
    assert told[-1] == (frames, frames) and [d for d, _ in told] == list(range(1, frames + 1))
    phases = []
    doc = fitting.run(manifest, cfg, tmp_path / "fit", False, with_round_trip=False, phase=phases.append)
    assert phases[0] == "reading the stacks" and phases[-1] == "writing fit_report.html"
    assert {f"fitting: {p}" for p in ("photon transfer", "black level", "random telegraph pixels", "dark current",
                                      "readout noise", "crosstalk", "PRNU and column gain")} <= set(phases)
    assert doc["parameters"]["source_follower.rts.ppm"]["value"] == 0
    assert not yaml.safe_load((tmp_path / "fit" / "config.yaml").read_text())["source_follower"]["rts"]["enabled"]
    short = fitting.write_measurement(cfg, tmp_path / "s", long_frames=20)
    doc = fitting.run(short, cfg, tmp_path / "fit_short", False, with_round_trip=False)
    assert "source_follower.rts.ppm" not in doc["parameters"]
    assert "at least 50 frames" in doc["not_fitted"]["source_follower.rts"]


#: traps seen through CDS: dwell times near the 10 us CDS interval, so a frame shows -A, 0 or +A, white in time
CDS_CONFIG = {"sensor": {"width": 128, "height": 96, "frame_rate_hz": 30}, "exposure": {"integration_time_s": 0.01},
              "source_follower": {"rts": {"enabled": True, "ppm": 5000, "cds": True, "cds_interval_s": 1e-5,
                                          "amplitude_e": {"median": 20, "sigma_log": 0.3},
                                          "tau_capture_s": {"min_s": 2e-6, "max_s": 2e-5},
                                          "tau_emission_s": {"min_s": 2e-6, "max_s": 2e-5}}}}


@pytest.mark.slow
def test_three_level_pixels_of_traps_through_cds_are_found_with_their_amplitudes_and_switching():
    """No pixel without a trap is found (the default config's flicker pixels are noisy but normal: the mixture
    must beat one normal at Z); a trap pixel is missed only where it is at a side level in few frames (its q F / 2
    below 5 frames, or by chance); each amplitude within Z se of the truth (the side levels' means over q F
    frames: se ~ sigma sqrt(2 / (q F)), plus half a code) and each pixel's switching fraction q = 2 pi0 pi1 (1 -
    e^-s tau) within Z binomial standard errors of its trap's, sqrt(q (1 - q) / F) (the side levels are about 8
    sigma from the centre here, so a frame is put at the wrong level with probability about P(|N| > 4) = 6e-5: the
    mixture's weight is the frame count at the side levels, a binomial)."""
    sensor = Sensor(CDS_CONFIG, seed=5)
    frames = np.stack(list(sensor.expose("flat:0").frames(300)))
    k = sensor.transfer.gain_dn_per_e
    r = fit_telegraph.fit(frames, k, 1 / 30)
    three = r["three_level"]
    traps = sensor.fixed_pattern.traps
    assert not r["pixels"]  # nothing is held over frames
    found, truth = set(three["pixels"]), set(traps.pixels.tolist())
    assert found <= truth and len(found) >= 0.8 * len(truth), (len(found), len(truth))
    size = dict(zip(traps.index.tolist(), traps.size))
    sigma_e = r["noise_dn"] / k
    for p, a, q in zip(three["pixels"], three["amplitude_e"], three["switching"]):
        assert abs(a - size[p]) <= Z * sigma_e * math.sqrt(2 / (q * 300)) + 0.5 / k, p
    _, var = random_telegraph.trap_moments(traps, 1e-5)
    q_true = dict(zip(traps.index.tolist(), var / traps.size**2))  # one trap a pixel: P(X(tau) != X(0))
    for p, q in zip(three["pixels"], three["switching"]):
        assert abs(q - q_true[p]) <= Z * math.sqrt(q_true[p] * (1 - q_true[p]) / 300), (p, q, q_true[p])
    sec = fit_telegraph.section(r)
    assert sec["cds"] is True and sec["cds_interval_s"] == 1e-5
    # equal dwell times t that give the median q: (1 - e^(-2 tau / t)) / 2 = q, inside the fitted law's range
    t = -2e-5 / math.log1p(-2 * three["median_switching"])
    assert sec["tau_capture_s"]["min_s"] < t < sec["tau_capture_s"]["max_s"]
