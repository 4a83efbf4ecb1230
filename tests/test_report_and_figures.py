"""The run report, the paper's figures gallery, and readable plots."""

import base64
import io
import json
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest
from conftest import Z

from cmosnoise import load_config, plots
from cmosnoise.app.run import simulate


class _Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.tables, self.links, self.scripts = [], [], [], 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a.get("src", ""))
        if tag == "table":
            self.tables.append(a.get("class", ""))
        if tag in ("a", "link", "script", "iframe") and (a.get("href") or a.get("src")):
            self.links.append(a.get("href") or a.get("src"))
        if tag == "script":
            self.scripts += 1


@pytest.fixture(scope="module")
def report_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("r") / "run"
    cfg = load_config(preset="paper-fig9-vga", overrides=["run.frames=2", "run.report=true"])
    summary = simulate(cfg, out)
    return out, summary


def test_report_is_self_contained_with_images_and_tables(report_run):
    out, summary = report_run
    text = (out / "report.html").read_text()
    c = _Collector()
    c.feed(text)
    assert len(c.imgs) >= 8  # perfect, raw, pre, processed, budget chart, 2 histograms, couplet zoom
    import imageio.v3 as iio

    for src in c.imgs:
        assert src.startswith("data:image/png;base64,")
        img = iio.imread(io.BytesIO(base64.b64decode(src.split(",", 1)[1])), extension=".png")
        assert img.size > 0
    assert {"keyfigures", "budget", "params"} <= set(c.tables)
    assert not c.links and c.scripts == 0  # nothing to fetch, nothing to run
    assert "http://" not in text and "https://" not in text
    for needle in ["Noise budget", "Distributions", "White pixels and couplets", "Parameters", "dark_current",
                   f"{summary['dark_current']['map']['couplets']} /"]:
        assert needle in text


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium here: apt-get install chromium to run this check")
def test_report_opens_in_headless_chromium_without_network(report_run, tmp_path):
    out, _ = report_run
    # a copy with a probe appended: the title reports whether every image decoded
    probe = ("<script>document.title = Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)"
             " ? 'IMAGES-OK ' + document.images.length + ' TABLES ' + document.querySelectorAll('table').length"
             " : 'IMAGES-BROKEN';</script>")
    page = tmp_path / "probe.html"
    page.write_text((out / "report.html").read_text().replace("</body>", probe + "</body>"))
    r = subprocess.run([
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--host-resolver-rules=MAP * ~NOTFOUND", f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=10000", "--dump-dom", page.as_uri(),
    ], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    import re

    m = re.search(r"<title>IMAGES-OK (\d+) TABLES (\d+)</title>", r.stdout)
    assert m, r.stdout[:500]
    assert int(m.group(1)) >= 8 and int(m.group(2)) >= 10


def test_summary_has_the_reports_key_figures(report_run):
    _, s = report_run
    kf = s["key_figures"]
    for lvl, v in kf["snr_temporal_db_at_signal_e"].items():
        assert v >= kf["snr_total_db_at_signal_e"][lvl]  # fixed pattern only adds noise


@pytest.fixture(scope="module")
def gallery():
    from cmosnoise.app.figures import FIGURES

    return {f.__name__: f(seed=0) for f in FIGURES}


@pytest.mark.slow
def test_figures_gallery_holds_every_figure(tmp_path, gallery, monkeypatch):
    from cmosnoise.app import figures

    made = list(gallery.values())
    monkeypatch.setattr(figures, "FIGURES", [lambda seed, f=f: f for f in gallery.values()])  # reuse, do not redraw
    items = figures.write_gallery(tmp_path, seed=0)
    names = [n for n, _ in items]
    assert names == [f.name for f in made]
    for fig in ["fig3", "fig5", "fig6", "fig7", "fig9", "fig10", "fig11"]:
        assert any(n.startswith(fig + "_") for n in names)
    c = _Collector()
    c.feed((tmp_path / "index.html").read_text())
    assert sorted(c.imgs) == sorted(names)
    import imageio.v3 as iio

    for n, caption in items:
        assert iio.imread(tmp_path / n).shape[0] > 200
        assert "seed" in caption.lower() and len(caption) > 80  # a caption that states the parameters


@pytest.mark.slow
def test_each_figure_shows_what_the_paper_shows(gallery):
    # Fig. 3: 10 % PRNU on 196 pixels; the sample std's relative SE is 1/sqrt(2 (n - 1))
    f3 = gallery["fig3_prnu"].facts
    assert f3["mean_e"] == pytest.approx(1000, abs=Z * 100 / np.sqrt(f3["pixels"]))
    assert f3["prnu_pct"] == pytest.approx(10, abs=Z * 10 / np.sqrt(2 * (f3["pixels"] - 1)))
    # Fig. 5: the paper's family per temperature, and dark current rising with it
    f5 = gallery["fig5_dark_temperatures"].facts
    assert f5["families"] == {25: "logistic", 45: "inverse_gaussian", 65: "lognormal"}
    assert f5["map_mean_e_per_s"][25] < f5["map_mean_e_per_s"][45] < f5["map_mean_e_per_s"][65]
    # Fig. 6: the white-pixel count above 250 aA is binomial around the configured ppm
    f6 = gallery["fig6_body_and_tail"].facts
    n, p = f6["pixels"], f6["ppm_configured"] * 1e-6
    assert abs(f6["above_threshold"] - n * p) <= Z * np.sqrt(n * p * (1 - p))
    # Fig. 7: per-pixel sample variances are unbiased for each pixel's own variance
    f7 = gallery["fig7_temporal_noise"].facts
    assert abs(f7["mean_measured_var_e2"] - f7["mean_true_var_e2"]) <= Z * f7["se_mean_var_e2"]
    # Fig. 9: more couplets at 5 MP than at VGA, and dark cal + median leaves some at 5 MP
    f9 = gallery["fig9_couplets"].facts
    assert f9["paper-fig9-5m"]["couplets_map"] > f9["paper-fig9-vga"]["couplets_map"]
    assert f9["paper-fig9-5m"]["couplets_after_processing"] > 0
    # Fig. 10: column means hold the 6 e- VFPN plus the shot noise they average (peak/rows at most);
    # the std of cols values has a relative SE of 1/sqrt(2 (cols - 1))
    f10 = gallery["fig10_vfpn"].facts
    for peak, measured in f10["column_mean_std_e"].items():
        lo, hi = f10["vfpn_sigma_e"], np.sqrt(f10["vfpn_sigma_e"] ** 2 + peak / f10["rows"])
        se = hi / np.sqrt(2 * (f10["cols"] - 1))
        assert lo - Z * se <= measured <= hi + Z * se, peak
    # Fig. 11: every stage of the paper's chain on (the measured-sensor stages it lacks stay off)
    paper = ("prnu", "crosstalk", "dark_current", "dark_shot_noise", "shot_noise", "source_follower", "flicker",
             "row_noise", "column_noise", "adc")
    stages = gallery["fig11_full"].facts["stages"]
    assert all(stages[s] for s in paper) and not any(v for s, v in stages.items() if s not in paper)


def test_plots_have_labels_units_titles_and_legends():
    from cmosnoise import Sensor
    from cmosnoise.analysis.noise_budget import budget

    sensor = Sensor(load_config(overrides=["sensor.width=200", "sensor.height=150"]))
    fig, axes = plots.figure(1, 3)
    plots.dark_current_histogram(axes[0], sensor.fixed_pattern.dark_rate, sensor.fixed_pattern.dark_state)
    plots.temporal_noise_histogram(axes[1], sensor.fixed_pattern.flicker_sigma, sensor.flicker_model, 4.0)
    plots.noise_budget_bars(axes[2], budget(sensor, 0), budget(sensor, 500))
    for ax in axes:
        assert ax.get_title() and ax.get_xlabel()
        assert "[" in ax.get_xlabel()  # a unit
        assert ax.get_legend() is not None
    assert all(ax.get_ylabel() for ax in axes[:2])
    plots.to_png_bytes(fig)


@pytest.mark.slow
def test_report_of_a_wide_sensor_is_reduced_with_1_to_1_crops_and_counts_couplets_honestly(tmp_path):
    """A 5 MP report was 40.8 MB; the zoom said '0 couplet(s) circled' when the map had 2."""
    from conftest import cli

    out = tmp_path / "wide"
    r = cli("simulate", "--preset", "paper-fig9-vga", "--set", "sensor.width=1920", "--set", "sensor.height=400",
            "--set", "processing.dark_frames=0", "--report", "--out", out)
    assert r.returncode == 0, r.stderr
    text = (out / "report.html").read_text()
    summary = json.loads((out / "summary.json").read_text())
    n_couplets = summary["dark_current"]["map"]["couplets"]
    assert n_couplets > 0
    assert ", 1:2" in text and "centre at 1:1" in text
    assert f"of the map&#x27;s {n_couplets} couplet(s)" in text
    assert len(text) < 4e6, len(text)  # the full-size pictures alone would be about 9 MB of base64


def test_large_pngs_are_written_in_bands_and_read_back_by_other_decoders():
    """io.output.png_bands: a standard PNG (grey, RGB, RGBA; filter Up; one zlib stream of independently deflated
    bands) that Pillow and imageio decode to the same pixels, at odd sizes and with more bands than rows' worth of
    work; png_bytes sends pictures of BANDED_PNG_PIXELS or more to it."""
    import io

    import imageio.v3 as iio
    from PIL import Image

    from cmosnoise.io import output

    rng = np.random.default_rng(0)
    for shape in [(1, 1, 3), (7, 5), (13, 11, 4), (301, 457, 3)]:
        picture = rng.integers(0, 256, shape, dtype=np.uint8)
        for workers in (1, 3):
            data = output.png_bands(picture, workers=workers)
            Image.open(io.BytesIO(data)).verify()  # chunk CRCs and structure
            assert np.array_equal(np.asarray(Image.open(io.BytesIO(data))), picture), (shape, workers)
            assert np.array_equal(iio.imread(io.BytesIO(data), extension=".png"), picture), (shape, workers)
    big = np.zeros((2000, 2000, 3), np.uint8)
    big[::7] = 200
    data = output.png_bytes(big, compress_level=1)
    assert data.startswith(b"\x89PNG") and np.array_equal(np.asarray(Image.open(io.BytesIO(data))), big)


def test_the_budget_table_is_in_the_bar_charts_order_and_the_snr_says_what_it_holds(report_run):
    """#63: the table listed the sources alphabetically beside a chart sorted by size; now both are largest first."""
    from cmosnoise.analysis import noise_budget

    out, summary = report_run
    text = (out / "report.html").read_text()
    table = text[text.index("<h2>Noise budget</h2>"):]
    table = table[:table.index("</table>")]
    nb = summary["noise_budget"]
    order = noise_budget.by_size(nb["dark"], nb["scene_mean"])
    positions = [table.index(">" + noise_budget.SOURCE_NAMES.get(n, n) + "<") for n in order]
    assert positions == sorted(positions) and len(order) >= 3
    values = [nb["scene_mean"]["temporal_rms_e"].get(n, 0.0) for n in order]
    assert values == sorted(values, reverse=True)
    assert "hot ones included" in text
