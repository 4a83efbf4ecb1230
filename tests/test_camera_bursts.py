"""A camera from its own DNG bursts (docs/sensor/camera-from-bursts.md): DNG files that say their ISO and exposure
time, a folder of them fitted without a manifest into a camera with a gain table, and that camera in ``dataset``."""

import json

import numpy as np
import pytest
import yaml
from conftest import cli

from cmosnoise import load_config
from cmosnoise.io.dng import read_settings, write_dng

#: the sony-a7s2 preset's gain table (docs/sensor/published-figures.md section 1): ISO -> K, DN/e-
A7S2_K = {100: 0.09563, 800: 0.76504, 3200: 3.06016}


def _codes(shape=(48, 64), seed=0) -> np.ndarray:
    return np.random.default_rng(seed).integers(500, 4000, shape).astype(np.uint16)


def test_a_dng_says_its_iso_and_exposure_time():
    """What write_dng puts in IFD0 (TIFF/EP's ISOSpeedRatings and ExposureTime) read_settings gives back; an ISO
    past a SHORT's 65535 whole through EXIF 2.3's ISOSpeed; a file that says neither gives None; LibRaw reads the
    same exposure time."""
    import tempfile
    from pathlib import Path

    import rawpy

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp)
        write_dng(p / "a.dng", _codes(), "RGGB", 64, 4095, iso=1600, exposure_s=0.005)
        write_dng(p / "b.dng", _codes(), "GRBG", 64, 4095, iso=204800, exposure_s=1 / 3)
        write_dng(p / "c.dng", _codes(), "none", 64, 4095)
        assert read_settings(p / "a.dng") == (1600.0, 0.005)
        iso, t = read_settings(p / "b.dng")
        assert iso == 204800.0 and t == pytest.approx(1 / 3, rel=1e-6)
        assert read_settings(p / "c.dng") == (None, None)
        with rawpy.imread(str(p / "a.dng")) as r:
            assert r.other.shutter_speed == pytest.approx(0.005, rel=1e-6)
            assert np.array_equal(r.raw_image_visible, _codes())


def _burst(folder, kind, iso, t, n, shape=(48, 64), seed=0, **kw):
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        write_dng(folder / f"{kind}_{i:03d}.dng", _codes(shape, seed + i), "RGGB", 64, 4095, exposure_s=t,
                  **({"iso": iso} if iso is not None else {}), **kw)


def test_a_folder_of_bursts_is_read_into_stacks_by_tag_and_path(tmp_path):
    """Each folder's files at one (kind, ISO, exposure time) are a stack; the kind from the innermost name that
    says one; the ISOs are the settings of the gain table; CFA, black and white from the files."""
    from cmosnoise.io import stacks

    _burst(tmp_path / "dark" / "iso100", "d", 100, 0.005, 3)
    _burst(tmp_path / "dark" / "iso100", "long", 100, 0.5, 2, seed=10)  # the same folder, another exposure time
    _burst(tmp_path / "dark" / "iso400", "d", 400, 0.005, 2, seed=20)
    _burst(tmp_path / "lab" / "iso100" / "flat_03", "x", 100, 0.005, 2, seed=30)  # its folder says flat
    ds = stacks.load(tmp_path)
    assert ds.kind == "bursts" and ds.cfa == "RGGB" and ds.black_level_dn == 64 and ds.shape == (48, 64)
    got = sorted((s.kind, s.iso, s.exposure_s, s.n) for s in ds.stacks)
    assert got == [("dark", 100, 0.005, 3), ("dark", 100, 0.5, 2), ("dark", 400, 0.005, 2), ("flat", 100, 0.005, 2)]
    assert ds.settings() == ("iso", [100.0, 400.0])
    first = next(s for s in ds.stacks if s.kind == "dark" and s.n == 3)
    assert np.array_equal(first.mean, np.mean([_codes(seed=i) for i in range(3)], axis=0))


@pytest.mark.parametrize("case", ["no_iso", "no_kind", "mixed_sizes", "sizes_across", "empty"])
def test_a_bad_folder_of_bursts_gets_one_line_naming_the_file(case, tmp_path):
    """A DNG without its ISO, one whose path says no kind, a burst of two sizes, bursts of two sizes, a folder with
    no DNG: exit 2, one line naming the file or folder and what is allowed, no output folder."""
    lab = tmp_path / "lab"
    if case == "no_iso":
        _burst(lab / "dark", "d", None, 0.005, 2)
        said = ("has no ISO tag", "d_000.dng")
    elif case == "no_kind":
        _burst(lab / "iso100", "frame", 100, 0.005, 2)
        said = ("neither its name nor its folders", "dark, flat, spot")
    elif case == "mixed_sizes":
        _burst(lab / "dark", "d", 100, 0.005, 2)
        write_dng(lab / "dark" / "d_009.dng", _codes((40, 64)), "RGGB", 64, 4095, iso=100, exposure_s=0.005)
        said = ("frame 2 is 64 x 40", "one size")
    elif case == "sizes_across":
        _burst(lab / "dark", "d", 100, 0.005, 2)
        _burst(lab / "flat", "f", 100, 0.005, 2, shape=(40, 64))
        said = ("different frame sizes", "one camera's frames have one size")
    else:
        lab.mkdir()
        said = ("DNG bursts", "found none")
    r = cli("fit", "--frames-from", lab, "--out", tmp_path / "fit")
    assert r.returncode == 2, r.stdout + r.stderr
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert all(s in lines[0] for s in said), lines[0]
    assert not (tmp_path / "fit").exists()


@pytest.mark.parametrize("args,said", [
    (["-p", "paper-fig9-vga", "--isos", "100,200"], "no gain table"),
    (["-p", "sony-a7s2", "--isos", "100,abc"], "expected ISO settings"),
    (["-p", "sony-a7s2", "--isos", "100,100"], "distinct"),
    (["-p", "sony-a7s2", "--isos", "100", "--format", "dng", "--temperatures", "25,45"], "holds no temperature"),
    (["-p", "paper-fig9-vga", "--format", "dng"], "--format dng writes each burst's ISO"),
    (["-p", "sony-a7s2", "--format", "raw"], "--format 'raw'"),
])
def test_measure_refuses_settings_it_cannot_write_in_one_line(args, said, tmp_path):
    r = cli("measure", *args, "--set", "sensor.width=32", "--set", "sensor.height=24", "--out", tmp_path / "m")
    assert r.returncode == 2 and said in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "m").exists()


def _camera_file(path):
    """A small camera of two gain settings, as a fitted config.yaml holds one."""
    cfg = load_config(preset="sony-a7s2", overrides=["sensor.width=64", "sensor.height=48"]).to_dict()
    cfg["gain_table"] = [r for r in cfg["gain_table"] if r["iso"] in (100, 3200)]
    cfg["sensor"]["iso"] = 100
    path.write_text(yaml.safe_dump(cfg))
    return path


def test_dataset_takes_a_camera_file_and_carries_its_text(tmp_path):
    """``--camera FILE`` (and ``FILE@iso=3200``): each sample a row of the file's gain table, K in the settings;
    the recipe in dataset.json holds the file's text, so the file may go and the set is made again the same."""
    import h5py

    cam = _camera_file(tmp_path / "camera.yaml")
    r = cli("-q", "dataset", "-n", "6", "--crop", "32", "--camera", cam, "--camera", f"{cam}@iso=3200", "--out",
            tmp_path / "d")
    assert r.returncode == 0, r.stderr
    with h5py.File(tmp_path / "d" / "shard-00000.h5") as f:
        isos = f["settings"]["iso"][:]
        ks = f["settings"]["k_dn_per_e"][:]
        raw = f["raw"][:]
    assert set(isos) <= {100.0, 3200.0} and 3200.0 in isos
    assert all(k == pytest.approx(A7S2_K[100] if i == 100 else A7S2_K[3200]) for i, k in zip(isos, ks, strict=True))
    recipe = json.loads((tmp_path / "d" / "dataset.json").read_text())["recipe"]
    assert recipe["camera_files"][0] == [str(cam), cam.read_text()]
    cam.unlink()  # the recipe carries the camera: a resumed or remade set needs no file
    from cmosnoise.app import dataset as ds

    again = ds.make_sample(ds.Recipe.from_json(json.dumps(recipe)), 0)[0]["raw"]
    assert np.array_equal(again, raw[0])


@pytest.mark.parametrize("text,said", [("- a list\n", "must hold a mapping"),
                                       ("sensor: {width: -5}\n", "sensor.width")])
def test_a_bad_camera_file_gets_one_line(text, said, tmp_path):
    cam = tmp_path / "cam.yaml"
    cam.write_text(text)
    r = cli("dataset", "-n", "2", "--crop", "32", "--camera", cam, "--out", tmp_path / "d")
    assert r.returncode == 2 and said in r.stderr and str(cam) in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "d").exists()
    r = cli("dataset", "-n", "2", "--crop", "32", "--camera", tmp_path / "missing.yaml", "--out", tmp_path / "d")
    assert r.returncode == 2 and "missing.yaml" in r.stderr, r.stderr


@pytest.mark.slow
def test_a_camera_fitted_from_its_dng_bursts_at_three_isos_is_the_camera(tmp_path):
    """The round trip of docs/sensor/camera-from-bursts.md (``readme_numbers.compute_camera_bursts``, its table
    measured again here and held to the stored one): the sony-a7s2 measured at ISO 100, 800 and 3200 as DNG
    bursts (``measure --format dng``: a camera's files, ISO and exposure time in their tags, no manifest), fitted
    from the folder. K per ISO within 3 % of the preset's table, and its 95 % interval holds it; the read noise
    in e- (the temporal dark noise without dark shot and quantization, ``fit.read_floor_e``) within 3 % of the
    true camera's; the fitted camera characterized at each ISO (EMVA 1288) gives K and the temporal dark noise
    within 3 % of the true camera's (its table, ``characterize.model_values``). ``dataset`` then takes it.

    The 3 % holds with room: on 128 x 96 pixels K's 95 % interval is about +-1 % (12 flat levels of two frames
    and a 16-frame flat), and the dark noise's per-pixel variance over 47 degrees of freedom and 12288 pixels
    has a relative standard error of sqrt(2 / (47 12288)) / 2 = 0.1 %."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    spec = importlib.util.spec_from_file_location("readme_numbers", root / "docs" / "readme_numbers.py")
    numbers = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(numbers)
    d = json.loads(json.dumps(numbers.compute_camera_bursts()))
    from test_readme_numbers import _close  # the stored numbers' own comparison: each value to 9 digits

    assert _close(d, numbers.load("camera_bursts")), "docs/numbers/camera_bursts.json is stale: compute camera_bursts"
    assert [r["iso"] for r in d["rows"]] == list(A7S2_K) and d["files"] > 0
    for r in d["rows"]:
        assert r["k_true"] == A7S2_K[r["iso"]]
        assert r["k_fit"] == pytest.approx(r["k_true"], rel=0.03) and r["k_ci95"][0] <= r["k_true"] <= r["k_ci95"][1]
        assert r["floor_fit_e"] == pytest.approx(r["floor_true_e"], rel=0.03), r
        assert r["emva_k"] == pytest.approx(r["k_true"], rel=0.03), r
        assert r["emva_dark_noise_e"] == pytest.approx(r["model_dark_noise_e"], rel=0.03), r
    assert [r["mode"] for r in d["rows"]] == ["LCG", "LCG", "HCG"]  # the conversion-gain step found between
    size = ["--set", "sensor.width=128", "--set", "sensor.height=96"]
    r = cli("-q", "measure", "-p", "sony-a7s2", "--isos", "100,3200", "--format", "dng", *size, "--long-frames",
            "16", "--levels", "8", "--out", tmp_path / "lab")
    assert r.returncode == 0, r.stderr
    assert [p.name for p in (tmp_path / "lab").rglob("*.yaml")] == ["truth.yaml"]  # no manifest beside the bursts
    r = cli("-q", "fit", "--frames-from", tmp_path / "lab" / "bursts", "--no-round-trip", "--out", tmp_path / "fit")
    assert r.returncode == 0, r.stderr
    assert [row.iso for row in load_config(tmp_path / "fit" / "config.yaml").gain_table] == [100, 3200]
    r = cli("-q", "dataset", "-n", "4", "--crop", "32", "--camera", tmp_path / "fit" / "config.yaml", "--out",
            tmp_path / "d")
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_a_folder_of_dng_bursts_fits_as_the_same_frames_in_a_manifest(tmp_path):
    """The same measurement written as DNG bursts and as .npy stacks with a manifest (``measure --format``): the
    two fits give every parameter the same value, to the rounding of sums taken in another stack order (1e-12;
    the folder's stacks are the manifest's, read from the tags)."""
    args = ["-p", "sony-a7s2", "--isos", "800", "--set", "sensor.width=64", "--set", "sensor.height=48",
            "--long-frames", "16", "--levels", "8"]
    for form in ("dng", "npy"):
        r = cli("-q", "measure", *args, "--format", form, "--out", tmp_path / form)
        assert r.returncode == 0, r.stderr
    fits = {}
    for form, where in (("dng", tmp_path / "dng" / "bursts"), ("npy", tmp_path / "npy" / "manifest.yaml")):
        r = cli("-q", "fit", "--frames-from", where, "--no-round-trip", "--out", tmp_path / f"fit-{form}")
        assert r.returncode == 0, r.stderr
        fits[form] = json.loads((tmp_path / f"fit-{form}" / "fit.json").read_text())
    assert fits["dng"]["input"] == "bursts" and fits["npy"]["input"] == "manifest"
    values = {form: {k: p["value"] for k, p in f["settings"]["800"]["parameters"].items()} for form, f in fits.items()}
    assert values["dng"].keys() == values["npy"].keys() and len(values["dng"]) > 20
    for k, v in values["dng"].items():
        w = values["npy"][k]
        if isinstance(v, float):
            assert v == pytest.approx(w, rel=1e-12, abs=1e-15), k
        elif isinstance(v, list) and np.asarray(v).dtype.kind == "f":
            assert np.allclose(v, w, rtol=1e-12, atol=1e-12), k
        else:
            assert v == w, k


def test_simulated_dng_frames_say_their_iso_and_exposure_time(tmp_path):
    """``simulate`` with ``run.dng``: each frame's file holds the sensor's ISO and exposure time, as a camera's."""
    r = cli("-q", "simulate", "-p", "sony-a7s2", "--set", "sensor.iso=1600", "--set", "sensor.width=32", "--set",
            "sensor.height=24", "--set", "exposure.integration_time_s=0.004", "--frames", "1", "--set", "run.dng=true",
            "--out", tmp_path / "s")
    assert r.returncode == 0, r.stderr
    assert read_settings(tmp_path / "s" / "dng" / "frame_000000.dng") == (1600.0, 0.004)
