"""The numbers the docs quote: measured by code in this repository, stored, and rendered into the pages.

Each section has a ``compute`` (runs cmosnoise, returns plain data) and a
``render`` (data -> the Markdown between ``<!-- numbers:NAME -->`` and
``<!-- /numbers:NAME -->`` in whichever page holds the block: README.md or a
page under docs/). Data live in ``docs/numbers/NAME.json``.

    python docs/readme_numbers.py compute [NAME ...]   # measure again, write the JSON
    python docs/readme_numbers.py render               # rewrite the pages' blocks from the JSON
    python docs/readme_numbers.py check                # exit 1 if a page and its JSON disagree
    python docs/readme_numbers.py images               # the pages' pictures, into docs/img
    python docs/readme_numbers.py images light         # the light page's pictures alone
    python docs/readme_numbers.py images explore_quality  # the explorer's image-quality box alone
    python docs/readme_numbers.py images noise_in_time    # the measured-sensors page's noise in time

``speed`` and ``kernel_parts`` (and ``speed_avx2``, ``kernel_parts_avx2``), ``explore``, ``sweep_speed``, ``fit_speed`` and
``fit_coverage`` are measured by the scripts in ``benchmarks/`` (``BENCHMARKS``; machine-dependent or minutes
long, never recomputed by tests); ``sweep_fig9`` is deterministic but takes minutes, so the tests check its
stored data instead. The tests check that every README block is the rendering of its JSON, and recompute the
deterministic sections (``tests/test_readme_numbers.py``), so the README cannot drift.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "docs" / "numbers"
README = ROOT / "README.md"


# ---------------------------------------------------------------- sections
def compute_fig9_map() -> dict:
    """White pixels and couplets of the dark-current map, paper-fig9-vga and -5m, seed 0."""
    from cmosnoise import Sensor, load_config, white_pixels

    out = {}
    for preset in ("paper-fig9-vga", "paper-fig9-5m"):
        sensor = Sensor(load_config(preset=preset), seed=0)
        state = sensor.dark_state
        r = white_pixels.report(sensor.dark_rate, state.threshold, sensor.cfa)
        n = sensor.dark_rate.size
        p = r["white_pixels"] / n
        out[preset] = {
            "pixels": n, "white_pixels": r["white_pixels"], "ppm": r["ppm"], "couplets": r["couplets"],
            "expected": r["couplets_expected_random"], "ppm_se": 1e6 * (p * (1 - p) / n) ** 0.5,
            "threshold_aA": round(state.threshold / 6.241509, 1),
            "map_mean": float(sensor.dark_rate.mean()), "map_max": float(sensor.dark_rate.max()),
            "body_mean": float(state.mean),
        }
    return out


def render_fig9_map(d: dict) -> str:
    thr = {v["threshold_aA"] for v in d.values()}
    head = f"ppm above {thr.pop():g} aA" if len(thr) == 1 else "ppm above threshold"
    lines = [f"| preset | pixels | white pixels (map) | {head} | couplets | expected at random |",
             "|---|---|---|---|---|---|"]
    for preset, v in d.items():
        lines.append(f"| `{preset}` | {_int(v['pixels'])} | {_int(v['white_pixels'])} | {_int(round(v['ppm']))} "
                     f"| {v['couplets']} | {v['expected']:.1f} |")
    se = [f"{round(v['ppm_se'])} ppm at {'VGA' if 'vga' in k else '5 MP'}" for k, v in d.items()]
    lines += ["", f"(seed 0; the binomial standard error of the ppm is {' and '.join(se)}.)"]
    v = d["paper-fig9-5m"]
    lines += ["", f"The presets' 500 e-/s is the body's mean, as the paper prints it; the tail of white pixels "
              f"raises the map's mean to {v['map_mean']:.0f} e-/s (+{100 * (v['map_mean'] / v['body_mean'] - 1):.0f} %), "
              f"and its brightest pixel reaches {_int(round(v['map_max']))} e-/s (body plus up to 80 000 of tail)."]
    return "\n".join(lines)


def compute_dark_budget() -> dict:
    """The default sensor in the dark: predicted total temporal noise and what 4 frames measure (seed 0)."""
    import tempfile

    from cmosnoise.app import cli

    with tempfile.TemporaryDirectory() as tmp:
        code = cli.run(["simulate", "--scene", "flat:0", "--frames", "4", "--seed", "0", "--no-progress",
                        "--out", f"{tmp}/o"])
        assert code == 0
        s = json.loads(Path(f"{tmp}/o/summary.json").read_text())
    return {"predicted_dn": s["temporal_noise"]["predicted_rms_dn"], "measured_dn": s["temporal_noise"]["rms_dn"],
            "pairs": 3}


def render_dark_budget(d: dict) -> str:
    return (f"For the default sensor in the dark (`cmosnoise simulate --scene flat:0 --frames 4`) the budget\n"
            f"predicts {d['predicted_dn']:.3f} DN and three frame pairs measure {d['measured_dn']:.3f} DN.")


def render_speed(d: dict) -> str:
    lines = [f"On the development machine ({d['machine']}; CPU {d['cpu']}, {d['vectors']} vectors; `{d['command']}`). "
             "Each ratio is to the reference "
             "timed alternately with that row (its ms/frame beside it), so a slow spell of the machine falls on "
             "both sides:", "",
             "| | frames/s | ms/frame | reference ms/frame | x reference |", "|---|---|---|---|---|"]
    for row in d["rows"]:
        lines.append(f"| {row['label']} | {row['fps']:.1f} | {row['ms']:.1f} | {row['ref_ms']:.1f} | {row['ratio']:.2f} |")
    first = (f" (the first sensor of a process {d['first_sensor_ms']:.0f} ms: it also loads the compiled loops)"
             if "first_sensor_ms" in d else "")
    lines += ["", f"Once per sensor, drawing the fixed pattern takes {d['fixed_ms']:.0f} ms{first}; once per scene, "
              f"exposing the photograph {d['expose_ms']:.0f} ms."
              + (f" The command's start-up and wrap-up (imports, compile-cache load, fixed pattern, scene, "
                 f"summary, preview) take {d['cli_start_up_s']:.1f} s once per run." if "cli_start_up_s" in d else ""),
              "",
              "Processing one 1920 x 1080 frame into an 8-bit picture:", "",
              "| processing | ms/frame |", "|---|---|"]
    for row in d["processing"]:
        lines.append(f"| {row['label']} | {row['ms']:.0f} |")
    ratio = {row["label"]: row["ratio"] for row in d["rows"]}
    one, two = ratio.get("frame kernel, 1 thread(s)"), ratio.get("frame kernel, 2 thread(s)")
    cli = next((r for r in d["rows"] if r["label"].startswith("cmosnoise simulate")), None)
    further = next((r for r in d["rows"] if r["label"].startswith("each further frame")), None)
    if "cli_start_up_s" in d and cli and further:
        n = int(re.search(r"--frames (\d+)", cli["label"]).group(1))
        frames = n * further["ms"] / 1000
        lines += ["", f"Beside {n} frames ({frames:.1f} s at the further frames' rate) the start-up weighs "
                  f"{d['cli_start_up_s'] / frames:.2f} times as much as the frames themselves."]
    if one is not None and two is not None and cli and further:
        lines += ["", f"Against the engine issue's targets: the kernel at {one:.2f} of the reference on one thread "
                  f"(target 0.4) and {two:.2f} on two (target 0.25); `simulate`, TIFF writing and run statistics "
                  f"included, at {further['ratio']:.2f} per further frame and {cli['ratio']:.2f} per frame of the "
                  f"whole 50-frame command, start-up included (target 0.5)."]
    return "\n".join(lines)


def render_kernel_parts(d: dict) -> str:
    lines = [f"Where a frame of the kernel goes on that CPU ({d['cpu']}, {d['vectors']} vectors, numba {d['numba']}; "
             f"`{d['command']}`), one thread, the photo at 1920 x 1080:", "",
             "| the kernel with | ms/frame |", "|---|---|"]
    lines += [f"| {row['label']} | {row['ms']:.1f} |" for row in d["parts"]]
    lines += ["", "The generator scheme's building blocks, the kernel's own compiled helpers, each alone over "
              "1920 x 1080 values on one thread:", "", "| block | ms/frame |", "|---|---|"]
    lines += [f"| {row['label']} | {row['ms']:.1f} |" for row in d["blocks"]]
    floor, ref, whole = d["floor_ms"], d["ref_ms"], d["whole_ms"]
    budget = 0.4 * ref
    left = (f"would leave {budget - floor:.0f} ms for them" if budget >= floor else
            f"is {floor - budget:.0f} ms below it already")
    lines += ["", f"Shot noise's first pass, the source follower's Philox block and normal, and the kernel with "
              f"nothing but the ADC ({d['adc_ms']:.1f} ms) add up to {floor:.0f} ms: what the scheme of docs/model.md "
              f"section 1 costs here before any PTRS retry or inversion, {floor / ref:.2f} of the reference's "
              f"{ref:.0f} ms timed in the same run. The PTRS retries and the inversion take the other "
              f"{whole - floor:.0f} ms of the whole kernel's {whole:.0f} ms; the one-thread target of 0.4 "
              f"({budget:.0f} ms) {left}."]
    return "\n".join(lines)


README_CHARACTERIZE_ROWS = ["system_gain_K_dn_per_e", "temporal_dark_noise_e", "saturation_capacity_e",
                            "dark_current_mean_e_per_s", "dsnu_e", "dsnu_column_e", "prnu_pct"]


def compute_characterize() -> dict:
    """`cmosnoise characterize` on the default sensor, seed 0: measured and model values."""
    import tempfile

    from cmosnoise.app import cli

    with tempfile.TemporaryDirectory() as tmp:
        assert cli.run(["-q", "characterize", "--seed", "0", "--out", f"{tmp}/c"]) == 0
        d = json.loads(Path(f"{tmp}/c/characterization.json").read_text())
    return {"measured": {k: d["measured"][k] for k in README_CHARACTERIZE_ROWS},
            "model": {k: d["model"][k] for k in README_CHARACTERIZE_ROWS}}


def render_characterize(d: dict) -> str:
    from cmosnoise.analysis.emva_evaluation import TABLE_ROWS, table

    labels = {key: label for key, label, _, _ in TABLE_ROWS}
    keep = {labels[k] for k in README_CHARACTERIZE_ROWS}
    out = ["| quantity | unit | measured | model | deviation % |", "|---|---|---|---|---|"]
    for label, unit, mv, xv, dev in table(d["measured"], d["model"]):
        if label in keep:
            out.append(f"| {label.strip().replace(' mu_e.sat', '')} | {unit} | {mv} | {xv} | {dev} |")
    return "\n".join(out)


#: presets where pixels clip: characterize's deviations from the model (the 5 MP one is the VGA one, larger)
README_PRESETS = ["paper-fig9-vga", "paper-fig11-full", "paper-fig10-vfpn", "paper-fig3-prnu"]
README_PRESET_ROWS = ["temporal_dark_noise_e", "dark_current_mean_e_per_s", "dsnu_e", "prnu_pct"]


def compute_characterize_presets() -> dict:
    """`characterize` (40 steps, 16-frame stacks, seed 0) on presets with white pixels that saturate, and without shot noise."""
    from cmosnoise import Sensor, load_config
    from cmosnoise import characterize as ch
    from cmosnoise.analysis import emva_evaluation as ev

    out = {}
    for name in README_PRESETS:
        sensor = Sensor(load_config(preset=name), seed=0)
        m = ch.measure(sensor)
        res, model = ev.evaluate(m), ch.model_values(sensor, m.stack_texp_s)
        out[name] = {"measured": {k: res[k] for k in README_PRESET_ROWS}, "model": {k: model[k] for k in README_PRESET_ROWS},
                     "excluded": res["prnu_excluded_pixels"], "dark_fit_points": res["dark_fit_points"],
                     "unavailable": sorted(k for k in res["unavailable"] if k in README_PRESET_ROWS),
                     "unresolved": {k: v for k, v in res["unresolved"].items() if k in README_PRESET_ROWS}}
    return out


def render_characterize_presets(d: dict) -> str:
    from cmosnoise.analysis.emva_evaluation import TABLE_ROWS, table

    labels = {key: label.strip() for key, label, _, _ in TABLE_ROWS}
    head = "| preset | " + " | ".join(labels[k] for k in README_PRESET_ROWS) + " | PRNU: defects left out | dark fit: exposure times |"
    out = [head, "|---" * (len(README_PRESET_ROWS) + 3) + "|"]
    for name, e in d.items():
        measured = {**e["measured"], "unresolved": e.get("unresolved", {})}
        rows = {label.strip(): (mv, xv, dev) for label, _, mv, xv, dev in table(measured, e["model"])}
        cells = []
        for k in README_PRESET_ROWS:
            mv, xv, dev = rows[labels[k]]
            cells.append(f"n/a (no K) / {xv}" if k in e["unavailable"] else f"{mv} / {xv} ({dev or '-'} %)")
        fit = "n/a" if "dark_current_mean_e_per_s" in e["unavailable"] else f"{e['dark_fit_points']} of 40"
        out.append(f"| `{name}` | " + " | ".join(cells) + f" | {_int(e['excluded'])} | {fit} |")
    return "\n".join(out)


def compute_cooled_dark() -> dict:
    """`characterize` on the IMX571 preset at -9.6 C (256 x 192 pixels, seed 0, 40 steps, 16-frame stacks): the
    dark current with the automatic dark series and without it (--dark-exposures none)."""
    import tempfile

    from cmosnoise.app import cli

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("auto", "none"):
            assert cli.run(["-q", "characterize", "--preset", "sony-imx571", "--set", "sensor.width=256", "--set",
                            "sensor.height=192", "--seed", "0", "--dark-exposures", name, "--out", f"{tmp}/{name}"]) == 0
            d = json.loads(Path(f"{tmp}/{name}/characterization.json").read_text())
            res = d["measured"]
            out[name] = {"measured": res["dark_current_mean_e_per_s"], "se": res["dark_current_mean_se_e_per_s"],
                         "bound": res["unresolved"].get("dark_current_mean_e_per_s"),
                         "model": d["model"]["dark_current_mean_e_per_s"],
                         "longest_s": res["dark_series_longest_s"] or float(max(d["series"]["texp_s"])),
                         "points": res["dark_series_points"] or len(d["series"]["texp_s"])}
    return out


def render_cooled_dark(d: dict) -> str:
    out = ["| series | dark pairs | longest exposure | dark current (from mean), e-/s | model, e-/s |", "|---|---|---|---|---|"]
    for name, label in (("none", "photon-transfer darks only (`--dark-exposures none`)"),
                        ("auto", "with the automatic dark series (`auto`)")):
        e = d[name]
        value = (f"< {e['bound']:.2g} (below what this series resolves)" if e["bound"] is not None else
                 f"{e['measured']:.3g} +- {e['se']:.1g} ({100 * (e['measured'] / e['model'] - 1):+.1f} %)")
        out.append(f"| {label} | {e['points']} | {e['longest_s']:.4g} s | {value} | {e['model']:.3g} |")
    return "\n".join(out)


def compute_fig9_processing() -> dict:
    """paper-fig9-5m, seed 0, frame 0 after dark calibration (8 frames): pixels more than 150 e- off the scene,
    and how many of them are in couplets, with no defect correction, the median corrector and the defect map."""
    import json
    import tempfile

    from cmosnoise.app.cli import run

    out = {}
    with tempfile.TemporaryDirectory() as tmp:  # the command that prints it: simulate's "processing left ..." line
        for method in ("off", "median", "map"):
            args = ["-q", "simulate", "--preset", "paper-fig9-5m", "--seed", "0", "--dark-frames", "8", "--set",
                    f"processing.defects.method=\"{method}\"", "--out", f"{tmp}/{method}"]  # quoted: YAML reads off as false
            assert run(args) == 0, args
            left = json.loads(Path(tmp, method, "summary.json").read_text())["processing"]["left"]
            out[method] = {"bad": left["pixels"], "couplets": left["couplets"]}
    return {"command": "cmosnoise simulate --preset paper-fig9-5m --seed 0 --dark-frames 8 "
                       "--set processing.defects.method=median --out run1", **out}


def render_fig9_processing(d: dict) -> str:
    o, m, p = d["off"], d["median"], d["map"]
    return (f"On `paper-fig9-5m` (seed 0), after dark calibration {o['bad']} pixels still stand more than 150 e- off\n"
            f"the scene (saturated white pixels that calibration cannot restore, and dark shot noise),\n"
            f"forming {o['couplets']} couplets; the median corrector leaves {m['bad']}, with {m['couplets']} couplets among them;\n"
            f"the defect map leaves {p['bad'] if p['bad'] else 'none'}"
            + (f" ({p['couplets']} couplets)." if p["bad"] else ".")
            + f"\n`{d['command']}` prints the median's count (its line \"processing left ...\"; `summary.json`\n"
            "holds it under `processing.left`), and `cmosnoise sweep` counts the same, per die, as\n"
            "`residual_defects` and `couplets_after_correction`.")


def compute_colour() -> dict:
    """ColorChecker through crosstalk, processed with and without compensation: CIEDE2000 against the truth."""
    import colour
    import numpy as np

    from cmosnoise import Processor, Sensor, load_config, scene
    from cmosnoise.config import ProcessingSection

    shape = (240, 360)
    off = {k: {"enabled": False} for k in ("prnu", "shot_noise", "dark_current", "source_follower", "row_noise",
                                           "column_noise")}
    sensor = Sensor(load_config(extra={**off, "sensor": {"width": shape[1], "height": shape[0], "cfa": "RGGB"}}))
    raw = sensor.expose("colorchecker").frame(0)

    def patches(img):
        return np.array([img[r, c].reshape(-1, 3).mean(axis=0) for r, c in scene.colorchecker_patches(shape)])

    def lab(x):
        return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.asarray(x) / 255.0))

    truth = patches(scene.linear_to_srgb(scene.colorchecker(shape)) * 255)
    res = {}
    for name, comp in (("on", True), ("off", False)):
        img = Processor(ProcessingSection(crosstalk_compensation=comp), sensor.raw_info()).render(raw).astype(float)
        de = colour.delta_E(lab(patches(img)), lab(truth), method="CIE 2000")
        res[name] = {"mean": float(de.mean()), "max": float(de.max())}
    return res


def render_colour(d: dict) -> str:
    return (f"With crosstalk on, compensation brings the ColorChecker back to a mean CIEDE2000 of {d['on']['mean']:.2f}\n"
            f"(max {d['on']['max']:.2f}); without it the mean error is {d['off']['mean']:.2f} (max {d['off']['max']:.2f}): "
            "visibly desaturated.")


#: the light page's camera: D65 on a reflective scene, f/2.8, 1/30 s, the Nikon D5100's spectral sensitivities at a
#: peak QE of 0.55, the default 2.2 um pixel
LIGHT_SETS = ["light.enabled=true", "light.spectral_qe=Nikon 5100 (NPL)", "light.qe_peak=0.55", "optics.f_number=2.8",
              "exposure.integration_time_s=0.033333", "light.illuminance_lux=100"]
LIGHT_LUX = [1, 10, 100, 1000]


def compute_light() -> dict:
    """The light page's camera at 1 to 1000 lux: the 18 % grey's green electrons from the light's integral, the
    exposure's mean green charge (after crosstalk, with dark current) and what 16 frames measure (48 x 64 green
    pixels), with its temporal SNR."""
    import numpy as np

    from cmosnoise import Sensor, load_config

    rows = []
    for lux in LIGHT_LUX:
        c = load_config(overrides=[*LIGHT_SETS, f"light.illuminance_lux={lux}", "sensor.width=128", "sensor.height=96"])
        t_s = c.exposure.integration_time_s
        sensor = Sensor(c, seed=0)
        shot = sensor.expose("flat:0.18")
        frames = np.stack(list(shot.frames(16))).astype(np.float64)
        t = sensor.transfer
        green = (frames[:, 0::2, 1::2] - t.black_level_dn) / t.gain_dn_per_e
        mean = float(green.mean())
        snr = mean / float(np.sqrt(green.var(axis=0, ddof=1).mean()))
        charge = shot.photo_mean_e + (shot.dark_mean_e if shot.dark_mean_e is not None else 0)
        fp = sensor.spec.focal_plane
        rows.append({"lux": lux, "focal_plane_lux_s": fp.focal_plane_lux * 0.18 * t_s,
                     "green_e_light": float(fp.white_e_per_s[1] * 0.18 * t_s),
                     "green_e_mean": float(charge[0::2, 1::2].mean()), "green_e_measured": mean,
                     "snr_measured": snr})
    return {"rows": rows}


def render_light(d: dict) -> str:
    out = ["| scene illuminance | focal-plane exposure of the 18 % grey | its green electrons from the light | the "
           "exposure's mean green charge | measured (16 frames) | temporal SNR, measured |", "|---|---|---|---|---|---|"]
    for r in d["rows"]:
        out.append(f"| {r['lux']:g} lux | {r['focal_plane_lux_s']:.3g} lux-s | {r['green_e_light']:.1f} e- | "
                   f"{r['green_e_mean']:.1f} e- | {r['green_e_measured']:.1f} e- | {r['snr_measured']:.1f} "
                   f"({20 * math.log10(r['snr_measured']):.0f} dB) |")
    return "\n".join(out)


def light_pictures(out: Path) -> None:
    """The light page's pictures: the photo at 1, 10, 100 and 1000 lux (each shown up to its own white, as a camera's
    auto gain would), and a lens's shading and chief-ray angle across the sensor."""
    import numpy as np

    from cmosnoise import Processor, Sensor, load_config
    from cmosnoise.app import plots
    from cmosnoise.config import ProcessingSection
    from cmosnoise.model import optics

    fig, axes = plots.figure(1, 4, figsize=(13, 2.9))
    for ax, lux in zip(axes, LIGHT_LUX):
        c = load_config(overrides=[*LIGHT_SETS, f"light.illuminance_lux={lux}"])
        sensor = Sensor(c, seed=0)
        raw = sensor.expose("photo").frame(0)
        ax.imshow(Processor(ProcessingSection(), sensor.raw_info()).render(raw))
        white = sensor.spec.peak_rate_e_per_s * c.exposure.integration_time_s
        ax.set_title(f"{lux:g} lux (white: {white:,.0f} e-)".replace(",", " "), fontsize=9)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    (out / "light_lux.png").write_bytes(plots.to_png_bytes(fig, dpi=80))

    c = load_config(overrides=[*LENS_SETS])
    shape = c.shape
    ri = optics.relative_illumination(c, shape)
    angle = optics.incidence(c, shape)[0]
    qe = optics.angle_qe(c, "none", shape)
    sensor = Sensor(load_config(overrides=[*LENS_SETS, "light.illuminance_lux=300"]), seed=0)
    raw = sensor.expose("flat:0.5").frame(0).astype(np.float64) - sensor.transfer.black_level_dn
    green = raw[0::2, 1::2]
    h, w = green.shape[0] // 2, green.shape[1] // 2
    fig, axes = plots.figure(1, 4, figsize=(13, 2.9))
    for ax, (img, title, unit) in zip(axes, [(ri, "relative illumination (cos^4)", ""),
                                             (angle, "angle at the photodiode", " deg"),
                                             (qe, "QE at that angle", ""),
                                             (green / green[h - 16:h + 16, w - 16:w + 16].mean(),
                                              "a flat grey's green pixels / centre's", "")]):
        im = ax.imshow(img, cmap="viridis")
        ax.set_title(title + (f" ({unit.strip()})" if unit else ""), fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.04)
    (out / "lens_shading.png").write_bytes(plots.to_png_bytes(fig, dpi=80))


#: the lens of the shading picture: a 2 mm lens on the default 640 x 480 sensor, its chief ray 25 degrees at 1 mm
#: from the centre, the microlenses taking 60 % of it back, a QE that falls to 70 % at 20 degrees
LENS_SETS = [*LIGHT_SETS, "optics.relative_illumination=cos4", "optics.focal_length_mm=2",
             "optics.chief_ray_angle=[[0, 0], [1, 25]]", "optics.microlens_compensation=0.6",
             "optics.angle_relative_qe=[[0, 1], [5, 0.97], [10, 0.9], [20, 0.7]]"]


#: the optical image's MTF table (docs/model.md 2b): the issue's lenses, (pitch um, f-number), each at two fill factors
MTF_LENSES = [(2.2, 2.8), (2.2, 4.0), (2.2, 8.0), (1.0, 2.8), (1.0, 4.0)]


def compute_focal_plane_mtf() -> dict:
    """A slanted edge through the diffraction PSF on a monochrome sensor of flat QE under D65 (every noise off),
    measured by the e-SFR, against ``OTF(f) |sinc(a f)|`` written from the formulas (tests/test_focal_plane.py's
    truth): MTF50 and the MTF at Nyquist, measured and true, at each lens and fill factor."""
    import numpy as np

    sys.path.insert(0, str(ROOT / "tests"))
    import test_focal_plane as t

    rows = []
    for pitch, n in MTF_LENSES:
        for ff in (1.0, 0.5):
            sets = t.MONO_LIGHT + ["optics.psf=diffraction", f"optics.f_number={n}", f"sensor.pixel_pitch_um={pitch}",
                                   f"light.fill_factor={ff}"]
            r = t._edge_sfr(sets)
            want = t._airy_mtf(r.frequency, pitch, n, ff)
            from cmosnoise import load_config
            from cmosnoise.model.focal_plane import focal_plane

            rows.append({"pitch_um": pitch, "f_number": n, "fill_factor": ff,
                         "k": focal_plane(load_config(overrides=t.QUIET + sets)).k,
                         "mtf50": r.mtf50, "mtf50_true": t.sfr.mtf50(r.frequency, want),
                         "nyquist": r.mtf_nyquist, "nyquist_true": float(np.interp(0.5, r.frequency, want))})
    return {"rows": rows}


def render_focal_plane_mtf(d: dict) -> str:
    out = ["| pixel, f-number, fill factor | k | MTF50 (cy/px): measured, true, error | MTF at Nyquist: measured, "
           "true, error |", "|---|---|---|---|"]
    for r in d["rows"]:
        out.append(f"| {r['pitch_um']:g} um, f/{r['f_number']:g}, {r['fill_factor']:g} | {r['k']} | "
                   f"{r['mtf50']:.4f}, {r['mtf50_true']:.4f}, {100 * (r['mtf50'] / r['mtf50_true'] - 1):+.1f} % | "
                   f"{r['nyquist']:.4f}, {r['nyquist_true']:.4f}, {r['nyquist'] - r['nyquist_true']:+.4f} |")
    return "\n".join(out)


def aliasing_picture(path: Path) -> None:
    """The light page's zone plate to 1 cycle per pixel through an f/2 lens on 2.2 um pixels: a monochrome sensor
    and a Bayer one (demosaiced, Malvar), each without and with a four-spot filter of one pixel's separation."""
    import numpy as np

    from cmosnoise import Sensor, load_config
    from cmosnoise.app import plots
    from cmosnoise.isp import reconstruction
    from cmosnoise.model.encoding import linear_to_srgb

    quiet = ["shot_noise.enabled=false", "source_follower.enabled=false", "row_noise.enabled=false",
             "column_noise.enabled=false", "dark_current.enabled=false", "prnu.enabled=false",
             "crosstalk.enabled=false", "adc.enabled=false", "sensor.width=360", "sensor.height=360",
             "optics.psf=diffraction", "optics.f_number=2"]
    fig, axes = plots.figure(1, 4, figsize=(15.6, 4.3))  # each panel at its own pixels (a resampled one would alias)
    for ax, (cfa, olpf, title) in zip(axes, [("none", None, "monochrome"), ("none", 2.2, "monochrome, OLPF 1 px"),
                                            ("RGGB", None, "Bayer, demosaiced"),
                                            ("RGGB", 2.2, "Bayer, OLPF 1 px")]):
        sets = quiet + [f"sensor.cfa={cfa}"] + ([f"optics.olpf={olpf}"] if olpf else [])
        signal = Sensor(load_config(overrides=sets)).scene_signal("zoneplate:1").astype(np.float32)
        rgb = np.repeat(signal[..., None], 3, axis=2) if cfa == "none" else \
            reconstruction.demosaic(signal, cfa, "malvar2004")
        ax.imshow(linear_to_srgb(np.clip(rgb, 0, 1)), interpolation="nearest")
        ax.set_title(title, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.subplots_adjust(left=0.005, right=0.995, top=0.93, bottom=0.005, wspace=0.02)
    path.write_bytes(plots.to_png_bytes(fig, dpi=100))


def render_optics_speed(d: dict) -> str:
    mp = f"{d['megapixels']:.0f} MP"
    rows = [f"{mp} ({d['size'][1]} x {d['size'][0]}), fastest of {d['repeats']}: a frame of the kernel "
            f"{d['frame_s'] * 1e3:.0f} ms; an exposure of the photo {d['exposure_s'] * 1e3:.0f} ms, with light in "
            f"lux and the diffraction PSF at f/2.8 {d['exposure_spectral_s'] * 1e3:.0f} ms "
            f"({d['optics_spectral_frames_worth']:.1f} frames' worth), with every part below "
            f"{d['exposure_lens_s'] * 1e3:.0f} ms ({d['optics_frames_worth']:.1f} frames' worth); a frame "
            f"of that exposure {d['frame_lens_s'] * 1e3:.0f} ms, and a frame of the same charge without the lens "
            f"{d['frame_same_charge_s'] * 1e3:.0f} ms; the optical image's set-up (the light's spectral integral, the "
            f"PSF on the fine grid, its separable terms) {d['focal_plane_setup_s'] * 1e3:.0f} ms, once per light "
            f"and lens (colour-science's import before it, once a process: {d['colour_import_s'] * 1e3:.0f} ms).",
            "", "| part, alone | its cost on an exposure, frames' worth |", "|---|---|"]
    rows += [f"| {k} | {max(v, 0):.1f} |" for k, v in d["parts_frames_worth"].items()]
    rows += ["", "The diffraction PSF on the optical image's fine grid, against the same light without it, frames' "
             "worth:", "", "| lens | auto | k = 1 | k = 2 | k = 3 | k = 4 |", "|---|---|---|---|---|---|"]
    for lens, r in d["oversample"].items():
        rows.append(f"| {lens} | **{r['auto']['frames_worth']:.1f}** (k = {r['auto']['k']}) | "
                    + " | ".join(f"{r[str(k)]['frames_worth']:.1f}" for k in (1, 2, 3, 4)) + " |")
    m = d["memory"]
    rows += ["", f"At {m['megapixels']:.0f} MP ({m['size'][1]} x {m['size'][0]}), f/2.8 (k = {m['k']}): the peak "
             f"of NumPy's allocations while the photo's signal is made, {m['signal_mb']:.0f} MB "
             f"({m['signal_plain_mb']:.0f} MB without the PSF; the signal itself, float64, is "
             f"{m['megapixels'] * 8:.0f} MB); while the whole exposure is made, {m['exposure_mb']:.0f} MB "
             f"({m['exposure_plain_mb']:.0f} MB)."]
    return "\n".join(rows)


def compute_fig10_visibility() -> dict:
    """paper-fig10-vfpn, seeds 0 to 2: each band's column-banding visibility (CSF-weighted L* sigma of the column
    means over the just-detectable noise) at the default viewing conditions, with and without the VFPN."""
    import numpy as np

    from cmosnoise import Sensor, load_config
    from cmosnoise.analysis import visual_noise as vn

    out = {}
    for name, sets in (("vfpn", []), ("no_vfpn", ["column_noise.enabled=false"])):
        bands = [[], [], [], []]
        for seed in range(3):
            sensor = Sensor(load_config(preset="paper-fig10-vfpn", overrides=sets), seed=seed)
            t = sensor.transfer
            y = np.clip((sensor.expose().frame(0).astype(float) - t.black_level_dn) / t.gain_dn_per_e / 5000.0, 0,
                        None)
            for b in range(4):
                bands[b].append(vn.banding(y[b * 120 + 4:(b + 1) * 120 - 4], rows=480)["visibility"])
        out[name] = [float(np.mean(v)) for v in bands]
    out["levels_e"] = [78.125, 312.5, 1250.0, 5000.0]
    return out


def render_fig10_visibility(d: dict) -> str:
    rows = ["| band (mean charge) | visibility with sigma_VFPN = 6 e- | without it (shot noise alone) |",
            "|---|---|---|"]
    for level, a, b in zip(d["levels_e"], d["vfpn"], d["no_vfpn"]):
        rows.append(f"| {level:g} e- | {a:.2f}{' (visible)' if a >= 1 else ''} | {b:.2f} |")
    return "\n".join(rows)


def render_explore(d: dict) -> str:
    lines = [f"Measured with `{d['command']}` ({d['machine']}); the median and the worst of the moves, and the",
             "server's own share:", "",
             "| parameter moved | slider to pixels, median | worst | on the server | target |", "|---|---|---|---|---|"]
    for r in d["rows"]:
        target = "150 ms" if r["label"].startswith("temporal") else "400 ms"
        lines.append(f"| {r['label']} | {r['median_ms']:.0f} ms | {r['max_ms']:.0f} ms | {r['server_median_ms']:.0f} ms | {target} |")
    return "\n".join(lines)


SWEEP_FIG9 = {"preset": "paper-fig9-vga", "instances": 12,
              "vary": ["sensor.temperature_c=25,45,65", "sensor.width,sensor.height=640x480,2592x1944"],
              "spec": ["couplets_after_correction<=0"]}


def compute_sweep_fig9() -> dict:
    """`cmosnoise sweep` of the Fig. 9 sensor at VGA and 5 MP over temperature: couplets against random placement,
    and the yield of "no couplet left after dark calibration and the median corrector". Writes the plots to docs/img."""
    import shutil
    import tempfile

    from cmosnoise import load_config
    from cmosnoise.app import sweep as sw

    d = SWEEP_FIG9
    with tempfile.TemporaryDirectory() as tmp:
        df = sw.run(load_config(preset=d["preset"]), d["vary"], d["instances"], Path(tmp) / "s", specs=d["spec"], workers=2)
        for name, target in (("couplets.png", "sweep_couplets.png"), ("yield.png", "sweep_yield.png")):
            shutil.copy(Path(tmp) / "s" / name, ROOT / "docs" / "img" / target)
    points = []
    for (w, t), g in df.groupby(["sensor.width", "sensor.temperature_c"], sort=True):
        k, n = int(g["pass"].sum()), len(g)
        lo, hi = sw.wilson(k, n)
        points.append({"width": int(w), "temperature_c": float(t), "instances": n,
                       "couplets_mean": float(g["couplets"].mean()), "couplets_std": float(g["couplets"].std(ddof=1)),
                       "expected_mean": float(g["couplets_expected_random"].mean()),
                       "after_correction_mean": float(g["couplets_after_correction"].mean()),
                       "yield": k / n, "yield_lo": lo, "yield_hi": hi})
    return {"command": "python docs/readme_numbers.py compute sweep_fig9", **d, "points": points}


def render_sweep_fig9(d: dict) -> str:
    lines = ["| sensor | temperature | couplets (mean +- se) | expected at random | left after correction | "
             "yield, 95 % interval |", "|---|---|---|---|---|---|"]
    for p in d["points"]:
        size = "VGA" if p["width"] == 640 else "5 MP"
        se = p["couplets_std"] / p["instances"] ** 0.5
        lines.append(f"| {size} | {p['temperature_c']:g} C | {p['couplets_mean']:.1f} +- {se:.1f} | {p['expected_mean']:.1f} | "
                     f"{p['after_correction_mean']:.2f} | {p['yield']:.2f} ({p['yield_lo']:.2f} to {p['yield_hi']:.2f}) |")
    return "\n".join(lines)


#: a yield on visibility: the column FPN at which banding stays below 1 JND at 10 lux, over sensor instances
QUALITY_YIELD = {"set": [], "vary": ["column_noise.vfpn_sigma_e=0.3,0.5,0.7,0.9"],
                 "instances": 10, "frames": 8, "quality_lux": 10.0, "spec": ["banding_columns<=1"]}


def compute_quality_yield(values: list[float] | None = None) -> dict:
    """`cmosnoise sweep --quality-lux 10 --spec banding_columns<=1` over the column FPN: each point's yield and its
    banding's spread over the instances (the default sensor). ``values``: only these column FPNs (a point's
    instances have the same seeds in any sweep, so its row is the whole study's: the suite's check recomputes one)."""
    import tempfile

    from cmosnoise import load_config
    from cmosnoise.app import sweep as sw

    d = QUALITY_YIELD
    vary = d["vary"] if values is None else [f"column_noise.vfpn_sigma_e={','.join(map(str, values))}"]
    with tempfile.TemporaryDirectory() as tmp:
        sw.run(load_config(overrides=d["set"]), vary, d["instances"], Path(tmp) / "s", frames=d["frames"],
               specs=d["spec"],
               workers=2, quality_lux=d["quality_lux"], metrics=["banding_columns"])
        import pandas as pd

        summary = pd.read_csv(Path(tmp) / "s" / "summary.csv").to_dict(orient="records")
    names = {"vfpn_sigma_e": "column_noise.vfpn_sigma_e", "yield": "yield", "yield_lo": "yield_lo",
             "yield_hi": "yield_hi", "banding_mean": "banding_columns_mean", "banding_p5": "banding_columns_p5",
             "banding_p95": "banding_columns_p95"}
    points = [{k: float(r[v]) for k, v in names.items()} for r in summary]
    return {"command": "python docs/readme_numbers.py compute quality_yield", **d, "points": points}


def render_quality_yield(d: dict) -> str:
    lines = ["| column FPN (e-) | column banding at 10 lux, JND: mean (5th to 95th percentile) | "
             "yield of banding <= 1 JND, 95 % interval |", "|---|---|---|"]
    for p in d["points"]:
        lines.append(f"| {p['vfpn_sigma_e']:g} | {p['banding_mean']:.2f} ({p['banding_p5']:.2f} to "
                     f"{p['banding_p95']:.2f}) | {p['yield']:.1f} ({p['yield_lo']:.2f} to {p['yield_hi']:.2f}) |")
    return "\n".join(lines)


def render_sweep_speed(d: dict) -> str:
    lines = [f"Measured with `{d['command']}` ({d['machine']}):", "",
             "| how | instances / s | against the plain loop |", "|---|---|---|"]
    for r in d["rows"]:
        lines.append(f"| {r['label']} | {r['per_s']:.2f} | {r['per_s'] / d['rows'][0]['per_s']:.2f} |")
    return "\n".join(lines)


def render_fit_speed(d: dict) -> str:
    lines = [f"Measured with `{d['command']}` ({d['machine']}; {d['data_set']}, {d['files']} .npy files read from disk):", "",
             "| run | seconds |", "|---|---|"]
    for r in d["rows"]:
        lines.append(f"| {r['label']} | {r['seconds']:.1f} |")
    return "\n".join(lines)


def render_fit_coverage(d: dict) -> str:
    short = {"default": "default", "paper-fig11-full": "fig11-full", "paper-fig9-vga": "fig9-vga"}
    heads = [f"{short[c.split('@')[0]]} {c.split('@')[1]} C" for c in d["combos"]]
    lines = [f"Measured with `{d['command']}` ({d['seeds']} sensors of {d['size']['width']} x {d['size']['height']} "
             f"per column; how many of the {d['seeds']} 95 % intervals hold the configured value):", "",
             "| parameter | " + " | ".join(heads) + " |", "|---" * (len(heads) + 1) + "|"]
    for name, row in d["hits"].items():
        lines.append(f"| `{name}` | " + " | ".join(str(row[c]) for c in d["combos"]) + " |")
    for name, row in d["mean_z"].items():
        lines.append(f"| mean z, `{name.split('.')[-1]}` | " + " | ".join(f"{row[c]:+.2f}" for c in d["combos"]) + " |")
    return "\n".join(lines)


def render_fit_selection(d: dict) -> str:
    lines = [f"Measured with `{d['command']}`: {d['seeds']} data sets from emva1288's camera simulator per column, "
             f"each its own camera and noise; each test at p < {d['alpha']:g} / {len(d['tests'])}.", "",
             f"| stage | switched on, data without it | switched on, data with it ({d['offset_e']:g} e- offsets, "
             f"{100 * d['nonlinearity']:g} % compression at saturation) |", "|---|---|---|"]
    for name in d["tests"]:
        lines.append(f"| `{name}` | {d['counts']['absent'][name]} of {d['seeds']} | "
                     f"{d['counts']['present'][name]} of {d['seeds']} |")
    lines += ["", f"Of the {d['seeds']} data sets without any of the six stages, {d['any_absent']} had one switched "
                  "on. The data sets with stages have only the offsets and the nonlinearity."]
    return "\n".join(lines)


def _stage_cost_table(d: dict, script: str) -> list[str]:
    """A stage-cost benchmark's table (bench_measured_stages.py, bench_telegraph.py): its rows against the reference."""
    repeats = f" --repeats {d['repeats']}" if "repeats" in d else ""
    lines = [f"Measured with `python benchmarks/{script} --frames {d['frames']}{repeats}` ({d['cpu']}, {d['vectors']} vectors, "
             f"numba threads {d['threads']}; 1920 x 1080 photo frame, each ratio to the NumPy reference timed "
             "alternately with it):", "",
             "| frame kernel | ms/frame | reference ms/frame | x reference |", "|---|---|---|---|"]
    return lines + [f"| {r['label']} | {r['ms']:.1f} | {r['ref_ms']:.1f} | {r['ratio']:.3f} |" for r in d["rows"]]


def render_measured_stages(d: dict) -> str:
    return "\n".join(_stage_cost_table(d, "bench_measured_stages.py")
                     + ["", f"The stages together cost {100 * d['cost']:+.0f} % per frame."])


def render_telegraph_cost(d: dict) -> str:
    return "\n".join(_stage_cost_table(d, "bench_telegraph.py")
                     + ["", f"Random telegraph noise costs {100 * d['cost']:+.0f} % per frame; frame 1 000 000 made "
                            f"alone at 640 x 480 with it takes {d['frame_1e6_vga_ms']:.1f} ms."])


def render_telegraph_fit(d: dict) -> str:
    n = len(d["rows"])
    s = d["summary"]
    lines = [f"Measured with `python benchmarks/fit_telegraph_coverage.py` ({n} sensors of 256 x 256, "
             f"{d['frames']} dark frames each; how many of the {n} sensors meet each check):", "",
             "| | ppm | median amplitude | median tau_low | median tau_high |", "|---|---|---|---|---|",
             f"| within the configured ppm's binomial interval | {s['ppm_in_band']} | | | |",
             f"| median within 10 % of the law's | | {s['amplitude_e_within_10pct']} | {s['tau_low_s_within_10pct']} | "
             f"{s['tau_high_s_within_10pct']} |",
             f"| 95 % interval holds the truth | {s['ppm_covered']} | {s['amplitude_e_covered']} | "
             f"{s['tau_low_s_covered']} | {s['tau_high_s_covered']} |"]
    return "\n".join(lines)


DATASET_SAMPLE = ["-q", "dataset", "-n", "1", "--crop", "256", "--camera", "sony-imx900@gain_db=3", "--light",
                  "300:300", "--seed", "2", "--set", "defects.enabled=true", "--set", "defects.dead_ppm=300",
                  "--set", "defects.clusters.ppm=200", "--set", "defects.columns.offset_ppm=8000",
                  "--set", "dark_current.points.0.tail={ppm_above: 2000, threshold_e_per_s: 30, max_e_per_s: 20000}",
                  "--set", "exposure.integration_time_s=0.05"]


def _dataset_sample(tmp: str):
    from cmosnoise.app import cli
    from cmosnoise.app import dataset as ds

    assert cli.run([*DATASET_SAMPLE, "--out", f"{tmp}/d"]) == 0
    return next(ds.read(f"{tmp}/d"))


def compute_dataset_sample() -> dict:
    """One sample of `cmosnoise dataset` (the IMX900 in its high conversion gain, with defects): what it holds."""
    import tempfile

    import numpy as np

    from cmosnoise.analysis import ground_truth as gt
    from cmosnoise.analysis import scoring

    with tempfile.TemporaryDirectory() as tmp:
        arrays, columns = _dataset_sample(tmp)
    raw, expected, mask = arrays["raw"][0], arrays["expected_raw"][0], arrays["mask"][0]
    clean = scoring.defect_free(expected, mask, str(columns["cfa"][0]))
    black, white = float(columns["black_level_dn"][0]), float(columns["white_level_dn"][0])
    return {"command": "cmosnoise " + " ".join(DATASET_SAMPLE[1:]) + " --out d", "camera": str(columns["camera"][0]),
            "mode": str(columns["mode"][0]), "k_dn_per_e": float(columns["k_dn_per_e"][0]),
            "light_e": float(columns["light_e"][0]),
            "psnr_db": scoring.image_scores(raw, clean, black, white)["psnr_code_range_db"],
            "mask": {k: int(np.sum((mask & v) > 0)) for k, v in gt.MASK_BITS.items()}}


def render_dataset_sample(d: dict) -> str:
    kinds = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in d["mask"].items() if v)
    return (f"The sample above: `{d['command']}`, the {d['camera']} in its {d['mode']} mode (K {d['k_dn_per_e']:g} "
            f"DN/e-) at {d['light_e']:.0f} e- at the scene's white. The noisy frame is {d['psnr_db']:.1f} dB (over the "
            f"code range) from the "
            f"expected raw without its defects; the mask marks {kinds} pixels.")


#: the burst round trip of docs/sensor/camera-from-bursts.md: the camera, its size, the settings, the measurement
CAMERA_BURSTS = {"preset": "sony-a7s2", "size": ["sensor.width=128", "sensor.height=96"], "isos": [100, 800, 3200],
                 "measure": ["--long-frames", "48", "--levels", "12"]}


def compute_camera_bursts() -> dict:
    """The sony-a7s2 measured as DNG bursts at three ISOs (`measure --format dng`), fitted from the folder of
    bursts, the fitted camera characterized at each ISO; beside each figure the true camera's (its gain table's
    K, the read floor it implies, characterize's model of it). Fixed seeds: deterministic."""
    import tempfile

    from cmosnoise import Sensor, load_config
    from cmosnoise.analysis import characterize as ch
    from cmosnoise.analysis.fit import read_floor_e
    from cmosnoise.app import cli

    c = CAMERA_BURSTS
    sets = [a for kv in c["size"] for a in ("--set", kv)]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        assert cli.run(["-q", "measure", "-p", c["preset"], "--isos", ",".join(map(str, c["isos"])), "--format",
                        "dng", *sets, *c["measure"], "--out", f"{tmp}/lab"]) == 0
        files = len(list(Path(f"{tmp}/lab/bursts").rglob("*.dng")))
        assert cli.run(["-q", "fit", "--frames-from", f"{tmp}/lab/bursts", "--no-round-trip", "--out",
                        f"{tmp}/fit"]) == 0
        doc = json.loads(Path(f"{tmp}/fit/fit.json").read_text())
        for iso in c["isos"]:
            at = [f"sensor.iso={iso}"]
            truth = load_config(preset=c["preset"], overrides=[*c["size"], *at])
            assert cli.run(["-q", "characterize", "--config", f"{tmp}/fit/config.yaml", "--set", at[0], "--out",
                            f"{tmp}/c{iso}"]) == 0
            m = json.loads(Path(f"{tmp}/c{iso}/characterization.json").read_text())["measured"]
            k = doc["settings"][str(iso)]["parameters"]["system_gain_K_dn_per_e"]
            rows.append({"iso": iso, "k_fit": k["value"], "k_ci95": k["ci95"],
                         "k_true": next(r.k_dn_per_e for r in truth.gain_table if r.iso == iso),
                         "floor_fit_e": read_floor_e(load_config(f"{tmp}/fit/config.yaml", overrides=at)),
                         "floor_true_e": read_floor_e(truth),
                         "emva_k": m["system_gain_K_dn_per_e"], "emva_dark_noise_e": m["temporal_dark_noise_e"],
                         "model_dark_noise_e": ch.model_values(Sensor(truth))["temporal_dark_noise_e"],
                         "mode": doc["settings"][str(iso)]["mode"]})
    return {"command": f"cmosnoise measure -p {c['preset']} --isos {','.join(map(str, c['isos']))} --format dng "
                       + " ".join(f"--set {kv}" for kv in c["size"]) + " " + " ".join(c["measure"]) + " --out lab",
            "files": files, "rows": rows}


def render_camera_bursts(d: dict) -> str:
    lines = [f"`{d['command']}` ({d['files']} DNG files), then `cmosnoise fit --frames-from lab/bursts "
             "--no-round-trip --out lab-fit` and `cmosnoise characterize --config lab-fit/config.yaml --set "
             "sensor.iso=ISO` at each ISO (`python docs/readme_numbers.py compute camera_bursts`):", "",
             "| ISO | mode | K fitted (95 % CI), DN/e- | K of the camera | read noise fitted, e- | of the camera "
             "| EMVA K of the fitted camera | EMVA dark noise of the fitted camera, e- | of the camera, e- |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        lo, hi = r["k_ci95"]
        lines.append(f"| {r['iso']} | {r['mode'] or ''} | {r['k_fit']:.4f} ({lo:.4f} to {hi:.4f}) | {r['k_true']:.4f} "
                     f"| {r['floor_fit_e']:.3f} | {r['floor_true_e']:.3f} | {r['emva_k']:.4f} "
                     f"| {r['emva_dark_noise_e']:.3f} | {r['model_dark_noise_e']:.3f} |")
    return "\n".join(lines)


def render_dataset_speed(d: dict) -> str:
    paired = "against_numpy_range" in d["rows"][0]
    lines = [f"Measured with `{d['command']}` ({d['machine']}), samples with their truth per CPU-second (each "
             "process's CPU time, summed over the workers), all in one run"
             + (f", the best of {d.get('repeats', 3)} repeats; the ratios are the median (and range) of each repeat's "
                "own, to the references timed in that repeat:" if paired else ":"), "",
             "| crop | | workers | samples per CPU-second | against NumPy on the same crops | against getframes |",
             "|---|---|---|---|---|---|"]

    def ratio(r, key):
        if r[key] is None:
            return ""
        span = r.get(key + "_range")
        if not span or f"{span[0]:.2f}" == f"{span[1]:.2f}":
            return f"{r[key]:.2f}"
        return f"{r[key]:.2f} ({span[0]:.2f} to {span[1]:.2f})"

    for r in d["rows"]:
        lines.append(f"| {r['crop']} x {r['crop']} | {r['label']} | {r['workers']} | {r['per_cpu_s']:.1f} | "
                     f"{ratio(r, 'against_numpy')} | {ratio(r, 'against_getframes')} |")
    if d.get("setup_ms"):
        parts = [f"{k.split(' ', 1)[1]} at {k.split(' ', 1)[0]} x {k.split(' ', 1)[0]} {v:.0f} ms"
                 for k, v in d["setup_ms"].items() if v is not None]
        parts += [f"{cam} none (no gain table)" for cam in dict.fromkeys(
            k.split(" ", 1)[1] for k, v in d["setup_ms"].items() if v is None)]
        lines += ["", "Each worker is a fresh process, warmed before the clock as a data set's first samples warm it "
                      "(compiled, sources read, one sample of each camera and gain the timed ones use). Setting up a "
                      "camera and gain (its nonlinearity solved, its template validated), once a process and gain "
                      "row, not in the rates: " + ", ".join(parts) + "."]
    if "memory" in d:
        m = d["memory"]
        lines += ["", f"Peak memory of `cmosnoise dataset` (64 x 64 crops): {m['peak_mb'][0]:.0f} MB for "
                      f"{m['samples'][0]} samples, {m['peak_mb'][1]:.0f} MB for {m['samples'][1]}."]
    if "truth_cost" in d:
        t = d["truth_cost"]
        lines += ["", f"A led sample's truth (expected raw, perfect image, mask) against its noisy frame, one thread, "
                      f"{t['samples']} samples of {d['crops'][0]} x {d['crops'][0]}: {t['median']:.2f} frames at the "
                      f"median, {t['mean']:.2f} on average, {t['max']:.2f} at most (K {t['max_k_dn_per_e']:.1f} DN/e-)."]
    return "\n".join(lines)


def render_gpu_speed(d: dict) -> str:
    driver = f"driver {d['driver']}, " if d.get("driver") else ""
    lines = [f"Measured with `{d['command']}` on one {d['device']} ({driver}numba-cuda {d['numba_cuda']}, numba {d['numba']}; "
             f"host: {d['host']['cpu']}, {d['host']['cores']} cores, {d['host']['vectors']}). Frames per second, the "
             "CPU kernel and the NumPy reference timed in the same run on that host:", "",
             "| frame | sensor | GPU kernel (frames left on the GPU) | GPU, copied to host memory | CPU kernel "
             "(all cores) | NumPy reference | GPU kernel / CPU kernel |", "|---|---|---|---|---|---|---|"]
    for r in d["speed"]:
        lines.append(f"| {r['size']} | {r['sensor']} | {_int(round(r['gpu_kernel_fps']))} | "
                     f"{_int(round(r['gpu_to_host_fps']))} | {r['cpu_kernel_fps']:.0f} | {r['numpy_reference_fps']:.1f} | "
                     f"{r['gpu_over_cpu']:.0f} |")
    lines += ["", "| training data | samples / s |", "|---|---|"]
    for r in d["training"]:
        lines.append(f"| {r['what']}, batches of {r['batch']} | {_int(round(r['samples_per_s']))} |")
    if d.get("dataset"):
        lines += ["", "| `cmosnoise dataset` samples (a sensor each) | GPU, samples / s | CPU, one process | CPU, "
                      "all cores | ms a GPU sample: set-up, upload, launch, copy back, truth |", "|---|---|---|---|---|"]
        for r in d["dataset"]:
            parts = r["ms_per_sample"]
            lines.append(f"| {r['what']} | {r['samples_per_s']:.0f} | {r['cpu_samples_per_s_one_process']:.0f} | "
                         f"{r['cpu_samples_per_s_all_cores']:.0f} ({r['cores']}) | "
                         + " / ".join(f"{parts[k]:.2f}" for k in ("set_up", "upload", "launch", "copy_back", "truth"))
                         + " |")
    ok = all(v is True for v in d["bits"].values())
    lines += ["", f"Bit for bit equal to the CPU kernel in the same run ({'every check' if ok else 'NOT every check'}): "
              + "; ".join(d["bits"]) + "."]
    if d.get("device_tests"):
        t = d["device_tests"]
        lines += ["", f"The GPU tests on the device (`{t['command']}`): {t['passed']} passed, {t['skipped']} skipped, "
                      f"{t['failed']} failed ({t['failed_test']}), {t.get('not_run', 0)} not run ("
                      + ", ".join(t.get("not_run_tests", [])) + f": {t.get('not_run_note', '')})."]
    if d.get("run_note"):
        lines += ["", f"The run: {d['run_note']}."]
    if d.get("training_note"):
        lines += ["", f"The training rows were {d['training_note']}."]
    if d.get("later_quick_run"):
        q = d["later_quick_run"]
        speeds = ", ".join(f"{_int(round(r['gpu_kernel_fps']))} ({r['size']}, {r['sensor']})" for r in q["speed"])
        crops = " and ".join(_int(round(r["samples_per_s"])) for r in q["training"])
        lines += ["", f"A later run, {q['what']}: GPU kernel {speeds} frames/s; training crops {crops} a second "
                      "(default, every stage): the training rate moves by a sixth between runs."]
    return "\n".join(lines)


def benchmark_command(name: str) -> str:
    """The command line that measures ``name`` (:data:`BENCHMARKS`), as a reader runs it from the project's root."""
    script, *rest = BENCHMARKS[name]
    return " ".join(["python", f"benchmarks/{script}",
                     *(f"docs/numbers/{a}" if a.endswith(".json") else a for a in rest)])


def render_compile_load(d: dict) -> str:
    first, second = d["runs"][0], d["runs"][1]
    ready = d["compiled_after_s"]
    return (f"Measured with `{benchmark_command('compile_load')}` ({d['cores']} cores, an empty cache; load: "
            f"{d['load']}): the `cmosnoise` run took {first['s']:.0f} s on the NumPy specification and started "
            f"{d['builds_started']} build; `python -m cmosnoise` {second['at_s']:.0f} s later "
            f"{'joined it' if d['second_run_joined'] else 'did not join it'} ({second['s']:.0f} s); the first run "
            f"on the compiled loops began {ready:.0f} s after the first run's start"
            + (" (within 300 s)." if d["within_300_s"] else "."))


def render_setup_speed(d: dict) -> str:
    timed = (f"the fastest of at least {d['repeats']} set-ups and of {d['min_time_s']:g} s of them: "
             + ", ".join(str(r["setups_timed"]) for r in d["rows"]) + " timed")
    lines = [f"Measured with `{benchmark_command('setup_speed')}` ({d['threads']} threads; {timed}):", "",
             "| sensor | pixels | set-up | per pixel | frames' worth | resident rise / maps kept |",
             "|---|---|---|---|---|---|"]
    for r in d["rows"]:
        lines.append(f"| {r['width']} x {r['height']} | {r['pixels'] / 1e6:.1f} MP | {r['setup_s']:.3f} s | "
                     f"{r['setup_ns_per_pixel']:.1f} ns | {r['frames_worth']:.2f} | "
                     f"{r['setup_rise_bytes'] / 2**20:.0f} / {r['maps_bytes'] / 2**20:.0f} MiB |")
    lines += ["", f"The cost a pixel varies by {100 * d['per_pixel_spread']:.0f} % over these sizes."]
    return "\n".join(lines)


def render_tile_speed(d: dict) -> str:
    k = d["kernel_1080p"]
    runs = d["rows"][0].get("runs", 1)
    lines = [f"Measured with `{benchmark_command('tile_speed')}` ({d['threads']} threads; a flat grey scene, "
             f"tiles of {d['rows'][0]['tile']}, written to disk"
             f"{f'; each row the fastest of {runs} runs' if runs > 1 else ''}). The frame kernel takes {k['ns_per_pixel']:.1f} ns a pixel on a 1920 x 1080 frame and "
             f"{k['tile_ns_per_pixel']:.1f} ns ({k['tile_ratio']:.2f} times) on a tile of the 400 MP sensor, in the "
             "same run:", "",
             "| sensor | frames | tiles | wall time | a pixel a frame (x the 1080p kernel's) | system time | "
             "peak memory | raw.tiff |",
             "|---|---|---|---|---|---|---|---|"]
    for r in d["rows"]:
        lines.append(f"| {r['width']} x {r['height']} ({r['pixels'] / 1e6:.0f} MP) | {r['frames']} | "
                     f"{r['tiles']} | {r['wall_s']:.1f} s | {r['ns_per_pixel']:.1f} ns ({r['run_ratio']:.1f}) | "
                     f"{r['sys_s']:.1f} s | {r['peak_bytes'] / 2**30:.2f} GiB | {r['raw_bytes'] / 2**30:.2f} GiB |")
    if "after_set_up" in d:
        f = d["after_set_up"]
        one, many = f["frames"]
        lines += ["", f"Each {d['rows'][-1]['pixels'] / 1e6:.0f} MP frame after the first (the {many}-frame run's wall time less the {one}-frame run's, "
                      f"over {many - one}): {f['frame_s']:.1f} s, {f['ns_per_pixel']:.1f} ns a pixel, "
                      f"{f['ratio']:.2f} times the 1080p kernel's. That is a frame made in tiles and written with "
                      "its tiles' set-up already paid, as the kernel's own time leaves out its sensor's set-up. The "
                      f"tiles' set-up (each tile's fixed pattern and mean charge) is {f['set_up_frames']:.1f} "
                      "frames' worth of thread time."]
    return "\n".join(lines)


def render_run_speed(d: dict) -> str:
    a = d["summary_alone"]
    lines = [f"Measured with `{benchmark_command('run_speed')}` ({d['threads']} threads; `cmosnoise simulate` of the default sensor at {d['width']} x {d['height']}, "
             f"the bundled photo, one frame, every output, {len(d['runs'])} runs):", "",
             "| run | wall time | peak memory | set-up | frame | summary after the frames | beside them |",
             "|---|---|---|---|---|---|---|"]
    for k, r in enumerate(d["runs"], 1):
        lines.append(f"| {k} | {r['wall_s']:.1f} s | {r['peak_bytes'] / 2**30:.2f} GiB | {r['set_up_s']:.2f} s | "
                     f"{r['frame_s']:.2f} s | {r['summary_s']:.2f} s | {r['summary_aside_s']:.2f} s |")
    lines += ["", f"The whole summary made alone after a frame, without the pictures beside it, takes "
                  f"{a['summary_s']:.2f} s against the frame kernel's {a['frame_s']:.2f} s: "
                  f"{a['frames_worth']:.2f} frames' worth (the fastest of {len(d['runs'])} each)."]
    return "\n".join(lines)


def compute_quality_hot(instances: int = 3) -> dict:
    """`cmosnoise quality`'s comparison of the default sensor at 25 C and at 65 C: 1, 10 and 100 lux,
    8 frames, the default charts, ``instances`` paired sensor instances (seeds 0, 1, ...; the table shows the
    first instance's values and the differences over all). With one instance there are no differences."""
    from cmosnoise import load_config
    from cmosnoise.analysis import quality
    from cmosnoise.app.quality import difference

    a_cfg = load_config()
    b_cfg = load_config(overrides=["sensor.temperature_c=65"])
    lux = [1.0, 10.0, 100.0]
    a = [quality.measure(a_cfg, lux, frames=8, seed=s) for s in range(instances)]
    b = [quality.measure(b_cfg, lux, frames=8, seed=s) for s in range(instances)]
    keys = ["snr_green", "visual_noise_l", "visual_noise_iso15739", "visual_noise_scielab", "banding_columns",
            "banding_rows", "mtf50"]
    out = {"lux": lux, "a": {k: a[0]["metrics"][k] for k in keys}, "b": {k: b[0]["metrics"][k] for k in keys},
           "snr10": [a[0]["snr10_lux"], b[0]["snr10_lux"]], "threshold_l": a[0]["visual_threshold_l"]}
    if instances > 1:
        d = difference(a, b)
        out["diff"] = {k: d[k] for k in keys}
    return out


def render_quality_hot(d: dict) -> str:
    from cmosnoise.analysis import quality

    lines = ["| metric | unit | " + " | ".join(f"{v:g} lux: 25 C / 65 C (65 - 25)" for v in d["lux"]) + " |",
             "|---|---|" + "---|" * len(d["lux"])]
    for k in d["a"]:
        m = quality.BY_NAME[k]
        cells = []
        for i in range(len(d["lux"])):
            diff, a, b = d["diff"][k][i], d["a"][k][i], d["b"][k][i]
            if a is None or b is None or diff is None or diff.get("mean") is None:
                cells.append(f"{'not measured' if a is None else format(a, '.3g')} / "
                             f"{'not measured' if b is None else format(b, '.3g')}")
                continue
            star = " **clear**" if diff["clear"] else ""
            cells.append(f"{a:.3g} / {b:.3g} ({diff['mean']:+.2g} ± {diff['se']:.1g}){star}")
        lines.append(f"| {m.label} | {m.unit} | " + " | ".join(cells) + " |")
    lines += ["", f"SNR10: {d['snr10'][0]:.3g} lux at 25 C, {d['snr10'][1]:.3g} lux at 65 C (f/2.8, 0.03 s, D65). "
                  f"The just-detectable visual noise at these viewing conditions is {d['threshold_l']:.3g} L*."]
    return "\n".join(lines)


def render_quality_speed(d: dict) -> str:
    lines = [f"| {d['megapixels']:.1f} MP ({d['width']} x {d['height']}), {d['cores']} cores, {d['vectors']} | s | "
             "frames' worth |", "|---|---|---|"]
    lines += [f"| {r['label']} | {r['s']:.3f} | {r['frames_worth']:.2f} |" for r in d["rows"]]
    return "\n".join(lines)


# ---------------------------------------------------------------- noise in time (#76)
NOISE_IN_TIME_QUIET = ["prnu.enabled=false", "crosstalk.enabled=false", "shot_noise.enabled=false",
                       "dark_current.enabled=false", "row_noise.enabled=false", "column_noise.enabled=false",
                       "read_noise.enabled=false", "pixel_offset.enabled=false", "nonlinearity.enabled=false",
                       "defects.enabled=false", "source_follower.thermal_sigma_e=3", "source_follower.flicker.enabled=false",
                       "adc.bits=16", "adc.gain_dn_per_e=4", "adc.black_level_dn=1000", "sensor.frame_rate_hz=30",
                       "exposure.integration_time_s=0.02", "sensor.width=64", "sensor.height=64"]


def _time_stack(sets: list[str], frames: int, seed: int = 5):
    import numpy as np

    from cmosnoise import Sensor, load_config

    sensor = Sensor(load_config(overrides=[*NOISE_IN_TIME_QUIET, *sets]), seed=seed)
    stack = np.stack(list(sensor.expose("flat:0.0").frames(frames))).astype(np.float64)
    return sensor, (stack - 1000.0) / sensor.transfer.gain_dn_per_e


ROW_1F = ["row_noise.enabled=true", "row_noise.sigma_e=2", "row_noise.spectrum=one_over_f"]
COL_1F = ["column_noise.enabled=true", "column_noise.vfpn_sigma_e=0", "column_noise.temporal.gumbel_loc_e=2",
          "column_noise.temporal.gumbel_scale_e=0.3", "column_noise.temporal.spectrum=one_over_f"]


def compute_noise_in_time() -> dict:
    """Row noise in readout order and column noise over frames, white and 1/f: the dark stack's spectra as
    `cmosnoise characterize` reads them, and the rows' frame-to-frame correlation against the law's."""
    import numpy as np

    from cmosnoise.analysis import noise_spectrum as ns
    from cmosnoise.model import one_over_f

    out: dict = {"frames": 256, "size": "64 x 64", "settings": NOISE_IN_TIME_QUIET}
    for name, sets in (("rows_white", ROW_1F[:2]), ("rows_one_over_f", ROW_1F), ("columns_white", COL_1F[:4]),
                       ("columns_one_over_f", COL_1F)):
        _, stack = _time_stack(sets, 256)
        e = ns.readout_order(stack) if name.startswith("rows") else ns.over_frames(stack, columns=True)
        out[name] = {"slope": round(e.slope, 4), "se": round(e.slope_se, 4), "verdict": e.verdict,
                     "band": [round(b, 5) for b in e.band], "unit": e.unit}
    sensor, stack = _time_stack([*ROW_1F, "row_noise.corner_hz=[3, 400]"], 513)
    rows = stack.mean(axis=2)
    products = (rows[:-1] * rows[1:]).mean(axis=1) / 4.0
    batches = products[:512].reshape(16, 32).mean(axis=1)
    out["row_lag1"] = {"corner_hz": [3, 400], "measured": round(float(batches.mean()), 4),
                       "se": round(float(batches.std(ddof=1) / np.sqrt(16)), 4),
                       "law": round(float(one_over_f.autocorrelation(sensor.spec.row_flicker, 1 / 30.0)), 4)}
    return out


def render_noise_in_time(d: dict) -> str:
    def row(label, e):
        return (f"| {label} | {e['slope']:.2f} +- {1.96 * e['se']:.2f} | {e['verdict'].replace('_', ' ')} | "
                f"{e['band'][0]:g} to {e['band'][1]:g} {e['unit']} |")

    lag = d["row_lag1"]
    return "\n".join([
        f"Measured on {d['frames']} dark frames of {d['size']} pixels at 30 frames/s (3 e- of white pixel noise "
        "under the pattern; `python docs/readme_numbers.py compute noise_in_time`), as `characterize` reads them:",
        "", "| series | slope (95 %) | verdict | band |", "|---|---|---|---|",
        row("row noise, white, in readout order", d["rows_white"]),
        row("row noise, one_over_f, in readout order", d["rows_one_over_f"]),
        row("column noise, white, over frames", d["columns_white"]),
        row("column noise, one_over_f, over frames", d["columns_one_over_f"]), "",
        f"With `row_noise.corner_hz: [{lag['corner_hz'][0]}, {lag['corner_hz'][1]}]` a row's offset correlates "
        f"with the same row's in the next frame by {lag['measured']:.3f} +- {lag['se']:.3f} (513 frames, batch "
        f"means); the law's `rho(1 / 30 s)` is {lag['law']:.3f}."])


def noise_in_time_picture(path: Path) -> None:
    """The measured-sensors page's picture: a dark stack's row offsets in readout order, white and 1/f, their
    spectra against the law's, and a long dark frame with amplifier glow and two column banks."""
    import numpy as np

    from cmosnoise import Sensor, load_config
    from cmosnoise.analysis import noise_spectrum as ns
    from cmosnoise.app import plots
    from cmosnoise.model import one_over_f

    fig, axes = plots.figure(1, 3, figsize=(14, 3.8))
    series, stacks = {}, {}
    for label, sets in (("white", ROW_1F[:2]), ("one_over_f", ROW_1F)):
        sensor, stack = _time_stack(sets, 256)
        series[label] = (sensor, stack.mean(axis=2).ravel())
        stacks[label] = (sensor, stack)
    for label, (_, x) in series.items():
        axes[0].plot(np.arange(4 * 64), x[:4 * 64], lw=0.9, label=f"row_noise.spectrum: {label}")
    for k in range(1, 4):
        axes[0].axvline(64 * k, color="grey", lw=0.5, ls=":")
    axes[0].set_xlabel("row in readout order (four frames of 64 rows)")
    axes[0].set_ylabel("row mean [e-]")
    axes[0].set_title("row noise in readout order (2 e- rms)", fontsize=10)
    axes[0].legend(fontsize=8)
    fs = 30.0 * 64
    for label, (_, stack) in stacks.items():
        e = ns.readout_order(stack)  # as characterize reads it: each row's and each frame's mean taken away
        keep = e.f >= e.band[0]
        axes[1].loglog(e.f[keep] * fs, e.psd[keep] / fs, lw=0.8,
                       label=f"{label}: Welch, slope {e.slope:.2f}")
    law = series["one_over_f"][0].spec.row_flicker
    f = np.logspace(np.log10(fs / 32), np.log10(fs / 2), 200)
    axes[1].loglog(f, 4.0 * one_over_f.psd(law, f), "k--", lw=1.2, label="the law: 4 e-^2 S(f)")
    axes[1].set_xlabel("frequency [Hz] (rows read at 1920 Hz)")
    axes[1].set_ylabel("power [e-^2 / Hz]")
    axes[1].set_title("their spectra (256 frames)", fontsize=10)
    axes[1].legend(fontsize=8)
    dark = Sensor(load_config(overrides=[*NOISE_IN_TIME_QUIET[:-2], "sensor.width=160", "sensor.height=96",
                                         "dark_current.enabled=true", "dark_current.glow.enabled=true",
                                         "dark_current.glow.rate_e_per_s=400", "dark_current.glow.length_px=25",
                                         "column_noise.enabled=true", "column_noise.vfpn_sigma_e=0",
                                         "column_noise.temporal.enabled=false", "column_noise.alternating.enabled=true",
                                         "column_noise.alternating.fixed_sigma_e=10", "exposure.integration_time_s=1"]),
                  seed=2)
    frame = (dark.expose("flat:0.0").frame(0).astype(np.float64) - 1000.0) / 4.0
    im = axes[2].imshow(frame, cmap="gray", vmin=np.percentile(frame, 1), vmax=np.percentile(frame, 75),
                        interpolation="nearest")
    fig.colorbar(im, ax=axes[2], fraction=0.03, label="e- (to the 75th percentile)")
    axes[2].set_title("1 s dark: glow (top right), two column banks", fontsize=10)
    axes[2].set_xticks([])
    axes[2].set_yticks([])
    path.write_bytes(plots.to_png_bytes(fig, dpi=90))


SECTIONS = {
    "noise_in_time": (compute_noise_in_time, render_noise_in_time),
    "quality_hot": (compute_quality_hot, render_quality_hot),
    "quality_speed": (None, render_quality_speed),
    "characterize": (compute_characterize, render_characterize),
    "characterize_presets": (compute_characterize_presets, render_characterize_presets),
    "cooled_dark": (compute_cooled_dark, render_cooled_dark),
    "fig9_processing": (compute_fig9_processing, render_fig9_processing),
    "colour": (compute_colour, render_colour),
    "light": (compute_light, render_light),
    "fig10_visibility": (compute_fig10_visibility, render_fig10_visibility),
    "fig9_map": (compute_fig9_map, render_fig9_map),
    "dark_budget": (compute_dark_budget, render_dark_budget),
    "speed": (None, render_speed),
    "speed_avx2": (None, render_speed),
    "kernel_parts": (None, render_kernel_parts),
    "kernel_parts_avx2": (None, render_kernel_parts),
    "explore": (None, render_explore),
    "sweep_fig9": (compute_sweep_fig9, render_sweep_fig9),
    "quality_yield": (compute_quality_yield, render_quality_yield),
    "sweep_speed": (None, render_sweep_speed),
    "fit_speed": (None, render_fit_speed),
    "fit_coverage": (None, render_fit_coverage),
    "fit_selection": (None, render_fit_selection),
    "measured_stages": (None, render_measured_stages),
    "telegraph_cost": (None, render_telegraph_cost),
    "telegraph_fit": (None, render_telegraph_fit),
    "dataset_sample": (compute_dataset_sample, render_dataset_sample),
    "dataset_speed": (None, render_dataset_speed),
    "gpu_speed": (None, render_gpu_speed),
    "setup_speed": (None, render_setup_speed),
    "tile_speed": (None, render_tile_speed),
    "run_speed": (None, render_run_speed),
    "optics_speed": (None, render_optics_speed),
    "focal_plane_mtf": (compute_focal_plane_mtf, render_focal_plane_mtf),
    "camera_bursts": (compute_camera_bursts, render_camera_bursts),
    "compile_load": (None, render_compile_load),
}

#: sections measured by a benchmark script (machine-dependent), and deterministic ones too slow for the tests
#: speed on a CPU with AVX-512 and on one with AVX2 only: run the one that fits the machine you measure on
BENCHMARKS = {"speed": ["bench_chain.py", "--json", "speed.json"],
              "compile_load": ["bench_compile_load.py", "--json", "compile_load.json"],
              "speed_avx2": ["bench_chain.py", "--json", "speed_avx2.json"],
              "kernel_parts": ["kernel_parts.py", "--json", "kernel_parts.json"],
              "kernel_parts_avx2": ["kernel_parts.py", "--json", "kernel_parts_avx2.json"],
              "explore": ["bench_explore.py", "--repeats", "10", "--json", "explore.json", "--screenshot", "../img/explore.png"],
              "sweep_speed": ["bench_sweep.py", "--json", "sweep_speed.json"],
              "fit_speed": ["bench_fit.py", "--json", "fit_speed.json", "--figures", "../img"],
              "fit_coverage": ["fit_coverage.py", "--json", "fit_coverage.json"],
              "fit_selection": ["fit_selection.py", "--json", "fit_selection.json"],
              "measured_stages": ["bench_measured_stages.py", "--repeats", "15", "--json", "measured_stages.json"],
              "telegraph_cost": ["bench_telegraph.py", "--json", "telegraph_cost.json"],
              "telegraph_fit": ["fit_telegraph_coverage.py", "--json", "telegraph_fit.json"],
              "dataset_speed": ["bench_dataset.py", "--memory", "10000", "--json", "dataset_speed.json"],
              # on a machine with an NVIDIA GPU and cmosnoise[cuda]
              "gpu_speed": ["bench_gpu.py", "--json", "gpu_speed.json"],
              "setup_speed": ["bench_setup.py", "--sizes", "1,12,50", "--repeats", "20", "--json", "setup_speed.json"],
              "tile_speed": ["bench_tiles.py", "--sizes", "50,400", "--many", "4", "--runs", "3", "--json",
                             "tile_speed.json"],
              "run_speed": ["bench_run.py", "--megapixels", "50", "--json", "run_speed.json"],
              "optics_speed": ["bench_optics.py", "--megapixels", "12", "--repeats", "5", "--json",
                               "optics_speed.json"],
              "quality_speed": ["bench_quality.py", "--megapixels", "12", "--json", "quality_speed.json"]}
#: sections the suite's stored-numbers test does not recompute whole: camera_bursts's own slow test recomputes it
#: (test_camera_bursts.py), quality_yield's recomputes one of its four points (test_readme_numbers.py: the whole
#: sweep took 4 min of 2 cores)
SLOW = {"sweep_fig9", "camera_bursts", "quality_yield"}


# ---------------------------------------------------------------- plumbing
def _int(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def load(name: str) -> dict:
    return json.loads((DATA / f"{name}.json").read_text())


def save(name: str, data: dict) -> None:
    DATA.mkdir(parents=True, exist_ok=True)
    (DATA / f"{name}.json").write_text(json.dumps(data, indent=2) + "\n")


def _pattern(name: str) -> re.Pattern:
    return re.compile(rf"(<!-- numbers:{name} -->)(.*?)(<!-- /numbers:{name} -->)", re.S)


def pages() -> list[Path]:
    """The Markdown pages that may hold blocks: README.md and the docs' sources (not the built site)."""
    skip = {"_build", "auto_examples"}
    return [README, *sorted(p for p in (ROOT / "docs").rglob("*.md") if not skip & set(p.relative_to(ROOT).parts))]


def page_blocks(paths: list[Path] | None = None) -> dict[str, str]:
    """Every page's generated blocks, by name."""
    out: dict[str, str] = {}
    for path in paths if paths is not None else pages():
        out.update(readme_blocks(path.read_text()))
    return out


def readme_blocks(text: str) -> dict[str, str]:
    """The README's generated blocks, by name."""
    return {name: m.group(2).strip("\n") for name in SECTIONS if (m := _pattern(name).search(text))}


def rendered(text: str) -> str:
    """README text with every block rendered from its JSON."""
    for name, (_, render) in SECTIONS.items():
        text = _pattern(name).sub(lambda m, n=name, r=render: m.group(1) + "\n" + r(load(n)) + "\n" + m.group(3), text)
    return text


#: README picture <- `cmosnoise figures` output (seed 0); the VFPN picture as JPEG (a photograph: 6 times smaller)
IMAGES = {"fig5_dark_temperatures.png": "fig5_dark_temperatures.png", "fig7_temporal_noise.png": "fig7_temporal_noise.png",
          "fig9_couplets.png": "fig9_couplets.png", "fig10_vfpn.jpg": "fig10_vfpn.png"}


def images() -> None:
    """Regenerate docs/img from `cmosnoise figures --seed 0` and `cmosnoise characterize --seed 0`."""
    import shutil
    import tempfile

    import imageio.v3 as iio

    from cmosnoise.app import cli

    out = ROOT / "docs" / "img"
    with tempfile.TemporaryDirectory() as tmp:
        assert cli.run(["-q", "figures", "--seed", "0", "--out", f"{tmp}/f"]) == 0
        assert cli.run(["-q", "characterize", "--seed", "0", "--out", f"{tmp}/c"]) == 0
        for name, src in IMAGES.items():
            if name.endswith(".jpg"):
                iio.imwrite(out / name, iio.imread(f"{tmp}/f/{src}")[..., :3], extension=".jpg", quality=75)
            else:
                shutil.copyfile(f"{tmp}/f/{src}", out / name)
        shutil.copyfile(f"{tmp}/c/photon_transfer.png", out / "photon_transfer.png")
        dataset_picture(*_dataset_sample(tmp), out / "dataset_sample.png")
    light_pictures(out)
    aliasing_picture(out / "zoneplate_aliasing.png")
    explore_quality_picture(out / "explore_quality.png")
    noise_in_time_picture(out / "noise_in_time.png")


def explore_quality_picture(path: Path) -> None:
    """The explorer's image-quality box (docs/sensor/explore.md), made by ``benchmarks/bench_explore.py``."""
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_explore.py"), "--quality-picture", str(path)],
                   check=True)


def dataset_picture(arrays: dict, columns: dict, path: Path) -> None:
    """The README's picture of a data set sample: noisy raw, expected raw, perfect image (each as its 2 x 2 cells'
    means, so the CFA's grid does not show), and the defect mask, a colour per kind."""
    import numpy as np
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from cmosnoise.analysis import ground_truth as gt
    from cmosnoise.app import plots

    def cells(a):
        a = a.astype(np.float64)
        return (a[0::2, 0::2] + a[0::2, 1::2] + a[1::2, 0::2] + a[1::2, 1::2]) / 4

    black = float(columns["black_level_dn"][0])
    top = float(np.percentile(cells(arrays["expected_raw"][0]), 99.5))
    fig, axes = plots.figure(1, 4, figsize=(13, 3.7))
    for ax, key, title in zip(axes, ("raw", "expected_raw", "perfect_dn"),
                              ("noisy raw (what the sensor gives)", "expected raw (the fixed pattern kept)",
                               "perfect image (an ideal pixel)")):
        ax.imshow(cells(arrays[key][0]), cmap="gray", vmin=black, vmax=top, interpolation="nearest")
        ax.set_title(title, fontsize=9)
    mask = arrays["mask"][0]
    kinds = [(k, v) for k, v in gt.MASK_BITS.items() if np.any(mask & v)]
    shown = np.zeros(mask.shape, int)
    for i, (_, bit) in enumerate(kinds, start=1):
        shown[(mask & bit) > 0] = i
    colours = ["black", "#ff4040", "#ffd000", "#40a0ff", "#40ff80", "#ff80ff", "#ffffff", "#ff9020", "#a0a0ff"]
    axes[3].imshow(shown, cmap=ListedColormap(colours[:len(kinds) + 1]), vmin=0, vmax=len(kinds),
                   interpolation="nearest")
    axes[3].set_title("defect mask (full resolution)", fontsize=9)
    axes[3].legend(handles=[Patch(color=colours[i + 1], label=k.replace("_", " ")) for i, (k, _) in enumerate(kinds)],
                   fontsize=7, loc="lower left", framealpha=0.8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    path.write_bytes(plots.to_png_bytes(fig, dpi=90))


def main(argv: list[str]) -> int:
    cmd, names = (argv[0] if argv else "check"), argv[1:]
    if cmd == "compute":
        for name in names or [n for n, (c, _) in SECTIONS.items() if c]:
            compute = SECTIONS[name][0]
            if compute is None:
                script, *rest = BENCHMARKS[name]
                rest = [str(DATA / a) if a.endswith((".json", ".png")) or a.startswith("../") else a for a in rest]
                subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *rest], check=True)
            else:
                save(name, compute())
            print(f"measured {name}")
        return 0
    if cmd == "images":
        if names == ["light"]:  # the light page's pictures alone
            light_pictures(ROOT / "docs" / "img")
            aliasing_picture(ROOT / "docs" / "img" / "zoneplate_aliasing.png")
        elif names == ["explore_quality"]:  # the explorer's image-quality box alone
            explore_quality_picture(ROOT / "docs" / "img" / "explore_quality.png")
        elif names == ["noise_in_time"]:  # the measured-sensors page's noise in time
            noise_in_time_picture(ROOT / "docs" / "img" / "noise_in_time.png")
        else:
            images()
        return 0
    if cmd == "render":
        for path in pages():
            text = path.read_text()
            if (new := rendered(text)) != text:
                path.write_text(new)
        return 0
    if cmd == "check":
        bad, found = [], {}
        for path in pages():
            text = path.read_text()
            have, fresh = readme_blocks(text), readme_blocks(rendered(text))
            found.update(have)
            bad += [f"{n} ({path.relative_to(ROOT)})" for n in have if have[n] != fresh[n]]
        missing = [n for n in SECTIONS if n not in found]
        if bad or missing:
            print(f"pages out of step: {bad}; blocks missing: {missing}", file=sys.stderr)
            return 1
        return 0
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
