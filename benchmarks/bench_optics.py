"""What light in lux and a lens cost on a 12 MP exposure, against one frame of the kernel, in the same run.

The issue's target (#60): the optics and spectral work of an exposure (the spectral integral, the RGB mix, the
PSF, relative illumination, the chief-ray angle's QE and leaning crosstalk) costs at most one frame's worth of
the kernel; the frames after it cost what they cost without it. Each is the fastest of ``--repeats``:

- **frame**: ``shot.frame(k)`` of the default sensor at the size, the exposure made first (the reference);
- **exposure, no lens**: ``sensor.expose("photo")`` of the same sensor, caches off (the scene resampled, PRNU,
  crosstalk, dark current): what an exposure costs today;
- **exposure, with light and lens**: the same with light in lux (a spectral QE), a diffraction PSF, cos^4
  shading, a chief-ray angle with a QE loss and a leaning crosstalk kernel; the light's integral is made once
  per light (cached), so it is timed apart (**light integral**, first call);
- **frame with light and lens**: a frame of that exposure;
- **a frame of the same charge without the lens**: a sensor with the same light and no lens part, exposing the
  lens's own signal (the same mean charge): what a frame of that charge costs today. The frame with the lens
  must cost this; it differs from the reference's frame only as its charge does (the shot-noise sampler's cost
  depends on the mean).

"optics' worth" is (exposure with lens - exposure without) over a frame. Two such figures:

- **light and PSF** (``optics_spectral_frames_worth``): light in lux with a measured spectral QE and the
  diffraction PSF of those spectra, the issue's "optics and spectral work" (its "Optics" is the PSF; lens
  shading and the chief-ray angle are a bullet of their own);
- **the whole lens** (``optics_frames_worth``): that and cos^4 shading, the chief-ray angle's QE loss and its
  leaning crosstalk.

colour-science's import (about a second, once a process; the light's integral needs it) is timed apart from the
optical image's set-up (the light's integral, the PSF on the fine grid and its separable terms, made once per
light and lens).

**The optical image's fine grid** (#73): with light in lux (the spectral QE), the diffraction PSF at f/2.8 and at
f/8 at ``optics.oversample`` auto and 1 to 4, each exposure against the same light without a PSF, in frames'
worth (the issue's bound: 3 at auto). And the memory an exposure takes at ``--memory-megapixels`` (50) with the
PSF at f/2.8 at auto (its k = 3): the peak of what NumPy allocates (tracemalloc) while the scene's signal is made,
and the whole exposure's, against the same without the PSF.

    python benchmarks/bench_optics.py [--megapixels 12] [--repeats 5] [--memory-megapixels 50] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

LENS = ["light.enabled=true", "light.illuminance_lux=100", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.55",
        "optics.psf=diffraction", "optics.f_number=2.8", "optics.relative_illumination=cos4",
        "optics.chief_ray_angle=[[0, 0], [3, 25]]", "optics.microlens_compensation=0.5",
        "optics.angle_relative_qe=[[0, 1], [20, 0.7]]",
        "crosstalk.kernel_at_angle_pct=[[0.6, 4, 1.9], [3, 76, 8], [0.6, 4, 1.9]]"]


#: the parts of LENS, each timed alone
PARTS = {"light in lux (spectral QE)": LENS[:4], "diffraction PSF": LENS[4:6],
         "cos^4 shading": LENS[6:7], "chief-ray angle: QE loss": LENS[7:10],
         "chief-ray angle: leaning crosstalk": LENS[7:9] + LENS[10:]}


def fastest(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--megapixels", type=float, default=12.0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--memory-megapixels", type=float, default=50.0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from cmosnoise import Sensor, colour_lib, load_config
    from cmosnoise.model.focal_plane import focal_plane

    width = int(round(math.sqrt(args.megapixels * 1e6 * 4 / 3) / 2) * 2)
    height = int(round(width * 3 / 4 / 2) * 2)
    size = [f"sensor.width={width}", f"sensor.height={height}"]
    Sensor(load_config(overrides=["sensor.width=64", "sensor.height=48"])).expose().frame(0)  # compile first
    plain = Sensor(load_config(overrides=size), seed=1)
    lens_config = load_config(overrides=size + LENS)
    t0 = time.perf_counter()
    colour_lib.colour()  # its import, once a process
    imported = time.perf_counter() - t0
    t0 = time.perf_counter()
    focal_plane(lens_config)
    integral = time.perf_counter() - t0
    lens = Sensor(lens_config, seed=1)
    shot, lens_shot = plain.expose("photo"), lens.expose("photo")
    # the same light and no lens part, exposing the lens's own signal: a frame of the same charge
    same = Sensor(load_config(overrides=size + LENS[:4]), seed=1).expose(lens.scene_signal("photo"))
    shot.frame(0), lens_shot.frame(0), same.frame(0)
    res = {
        "megapixels": width * height / 1e6, "size": [height, width], "repeats": args.repeats,
        "frame_s": fastest(lambda: shot.frame(1), args.repeats),
        "exposure_s": fastest(lambda: plain.expose("photo"), args.repeats),
        "exposure_lens_s": fastest(lambda: lens.expose("photo"), args.repeats),
        "frame_lens_s": fastest(lambda: lens_shot.frame(1), args.repeats),
        "frame_same_charge_s": fastest(lambda: same.frame(1), args.repeats),
        "focal_plane_setup_s": integral,
        "colour_import_s": imported,
    }
    res["optics_frames_worth"] = (res["exposure_lens_s"] - res["exposure_s"]) / res["frame_s"]
    spectral = Sensor(load_config(overrides=size + LENS[:6]), seed=1)
    spectral.expose("photo")
    res["exposure_spectral_s"] = fastest(lambda: spectral.expose("photo"), args.repeats)
    res["optics_spectral_frames_worth"] = (res["exposure_spectral_s"] - res["exposure_s"]) / res["frame_s"]
    # where it goes: each part alone on top of the plain exposure, in frames' worth
    res["parts_frames_worth"] = {}
    for name, sets in PARTS.items():
        part = Sensor(load_config(overrides=size + sets), seed=1)
        part.expose("photo")
        res["parts_frames_worth"][name] = (fastest(lambda part=part: part.expose("photo"), args.repeats)
                                           - res["exposure_s"]) / res["frame_s"]
    print(f"{res['megapixels']:.1f} MP: frame {res['frame_s'] * 1e3:.0f} ms; exposure {res['exposure_s'] * 1e3:.0f} ms, "
          f"with light in lux and the PSF {res['exposure_spectral_s'] * 1e3:.0f} ms "
          f"({res['optics_spectral_frames_worth']:.2f} frames' worth), with the whole lens "
          f"{res['exposure_lens_s'] * 1e3:.0f} ms ({res['optics_frames_worth']:.2f}); a frame with them "
          f"{res['frame_lens_s'] * 1e3:.0f} ms (of the same charge without the lens "
          f"{res['frame_same_charge_s'] * 1e3:.0f} ms); the optical image's set-up "
          f"{res['focal_plane_setup_s'] * 1e3:.0f} ms once (colour-science's import before it "
          f"{res['colour_import_s'] * 1e3:.0f} ms)")
    print("  each part alone, frames' worth: " + ", ".join(f"{k} {v:.2f}" for k, v in res["parts_frames_worth"].items()))
    # the fine grid: the diffraction PSF at f/2.8 and f/8, k auto and 1 to 4, against the same light alone
    lit = Sensor(load_config(overrides=size + LENS[:4]), seed=1)
    lit.expose("photo")
    lit_s = fastest(lambda: lit.expose("photo"), args.repeats)
    res["exposure_light_s"] = lit_s
    res["oversample"] = {}
    for f_number in (2.8, 8.0):
        rows = {}
        for k in ("auto", 1, 2, 3, 4):
            s = Sensor(load_config(overrides=size + LENS[:4] + ["optics.psf=diffraction", f"optics.f_number={f_number}",
                                                               f"optics.oversample={k}"]), seed=1)
            s.expose("photo")
            rows[str(k)] = {"k": s.spec.focal_plane.k,
                            "frames_worth": (fastest(lambda s=s: s.expose("photo"), args.repeats) - lit_s)
                            / res["frame_s"]}
        res["oversample"][f"f/{f_number:g}"] = rows
        print(f"  f/{f_number:g}, frames' worth: " + ", ".join(
            f"{k} (k = {v['k']}) {v['frames_worth']:.2f}" for k, v in rows.items()))
    res["memory"] = memory(args.memory_megapixels)
    m = res["memory"]
    print(f"  {m['megapixels']:.0f} MP, f/2.8 (k = {m['k']}): the signal's peak {m['signal_mb']:.0f} MB "
          f"({m['signal_plain_mb']:.0f} MB without the PSF), the exposure's {m['exposure_mb']:.0f} MB "
          f"({m['exposure_plain_mb']:.0f} MB)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)
    return 0


def memory(megapixels: float) -> dict:
    """The peak of NumPy's allocations (tracemalloc) while a sensor of ``megapixels`` makes the photo's signal and its
    whole exposure, with light in lux and the diffraction PSF at f/2.8 (auto) and without the PSF, MB."""
    import tracemalloc

    from cmosnoise import Sensor, load_config

    width = int(round(math.sqrt(megapixels * 1e6 * 3 / 2) / 2) * 2)
    height = int(round(width * 2 / 3 / 2) * 2)
    size = [f"sensor.width={width}", f"sensor.height={height}"]
    out = {"megapixels": width * height / 1e6, "size": [height, width]}
    for name, extra in (("", ["optics.psf=diffraction", "optics.f_number=2.8"]), ("_plain", [])):
        sensor = Sensor(load_config(overrides=size + LENS[:4] + extra), seed=1)
        out.setdefault("k", sensor.spec.focal_plane.k)
        for what, fn in (("signal", lambda s=sensor: s.scene_signal("photo")),
                         ("exposure", lambda s=sensor: s.expose("photo"))):
            tracemalloc.start()
            result = fn()
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            del result
            out[f"{what}{name}_mb"] = peak / 1e6
    return out


if __name__ == "__main__":
    sys.exit(main())
