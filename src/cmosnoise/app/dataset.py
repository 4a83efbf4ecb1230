"""Training and test data: noisy raw frames with their ground truth, over a distribution of cameras and scenes.

A data set is a :class:`Recipe` (how many samples, the crop, the cameras,
the scenes, the light, exposure and temperature ranges, the seed) and the
samples it implies. Sample ``i`` depends on nothing but (recipe, ``i``): its
settings come from a generator keyed by (seed, i) (:func:`settings`), its
sensor instance is seeded from it, and its frame and truth are those of
:class:`~cmosnoise.Sensor` with that configuration. So any shard can be made
alone, on any process or Dask worker, and an interrupted set is completed by
making the shards that are missing (``--resume``).

Each sample records its full configuration (``config``, YAML): ``cmosnoise
simulate --config`` with it gives the same raw frame, bit for bit.

Output formats (:data:`FORMATS`):

- ``hdf5`` (h5py; the default): one file per shard, each array chunked per
  sample and compressed (gzip with the byte shuffle). HDF5 rather than zarr:
  one file per shard (no tree of small files for a file system or a copy to
  walk), read by every language and by MATLAB and IDL, and h5py's API has been
  stable for a decade (zarr's changed with its version 3). Times are not
  written into the file: the same shard is the same bytes.
- ``npz``: one NumPy zip per shard, for small sets (entries dated 1980, so
  the bytes too are the same).
- ``fits`` (astropy): one FITS file per shard, an image extension per array
  and a table of the settings, for astronomy users.

Arrays per shard (n samples of H x W): ``raw`` uint16 (the noisy frame),
``expected_raw`` and ``perfect_dn`` float32 (DN), ``mask`` uint16 (the
defect bits of :data:`cmosnoise.analysis.ground_truth.MASK_BITS`), and the
settings of each sample as columns (:data:`COLUMNS`).

Examples
--------
>>> from cmosnoise import dataset
>>> recipe = dataset.Recipe(samples=4, crop=(64, 64), seed=0)
>>> sample, truth = dataset.make_sample(recipe, 0)
>>> sorted(sample)[:4], sorted(truth)[:3]
(['expected_raw', 'mask', 'perfect_dn', 'raw'], ['binning', 'black_level_dn', 'camera'])
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .. import inputs
from .._version import __version__
from ..analysis import ground_truth
from ..config import load_config, virtual_cameras
from ..config.loading import config_data, deep_merge, merge_updates, parse_override, preset_data, preset_names
from ..engine.samplers import SCHEME_VERSION
from ..errors import CmosnoiseError, check_terminated, keeping, note_kept
from ..io.output import atomic_file, resumable_mode
from ..model import physics, raw_scene
from ..model import scene as scene_mod
from ..model.cfa import BAYER_PATTERNS
from ..model.sensor import Sensor, check_device, frames_together

FORMATS = {"hdf5": ".h5", "npz": ".npz", "fits": ".fits"}
#: image files a --images folder may hold
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".npy", ".bmp", ".webp", ".dng")
#: built-in scenes a set draws from when no --images are given (drawn at :func:`builtin_shape`)
BUILTIN_SCENES = ("photo", "colorchecker", "zoneplate", "siemens", "ramp")
#: the side a built-in scene is drawn at for crops up to this size (larger crops: the crop's size)
BUILTIN_SIZE = 1024


#: the most pixels a built-in scene is drawn at (linear RGB, 24 bytes a pixel: 288 MB a scene)
MAX_BUILTIN_PIXELS = 4000 * 3000


def builtin_shape(crop: tuple[int, int]) -> tuple[int, int]:
    """(rows, cols) a built-in scene is drawn at for crops of ``crop``: :data:`BUILTIN_SIZE` square, or the crop's
    own side where it is larger (a 5 MP crop of a built-in is its whole scene, drawn at 2592 x 1944; crops up to
    1024 keep the scenes, and the bits, of sets made before); a crop whose scene would pass
    :data:`MAX_BUILTIN_PIXELS` is a one-line error.

    Parameters
    ----------
    crop : (int, int)
        The crop's rows and columns.

    Returns
    -------
    (int, int)
        The scene's rows and columns.
    """
    shape = max(BUILTIN_SIZE, int(crop[0])), max(BUILTIN_SIZE, int(crop[1]))
    if shape[0] * shape[1] > MAX_BUILTIN_PIXELS:
        raise CmosnoiseError(f"--crop {crop[0]}x{crop[1]}: the built-in scenes are drawn at most "
                             f"{MAX_BUILTIN_PIXELS / 1e6:g} MP (e.g. 3000 x 4000), and this crop's would be "
                             f"{shape[0]} x {shape[1]}; give a smaller crop, or --images of larger images")
    return shape
#: the arrays of a sample
ARRAYS = ("raw", "expected_raw", "perfect_dn", "mask")
#: each sample's settings, as columns: name -> numpy dtype ("str": text)
COLUMNS = {
    "sample": "int64", "camera": "str", "mode": "str", "binning": "str", "iso": "float64", "gain_db": "float64",
    "k_dn_per_e": "float64", "black_level_dn": "float64", "white_level_dn": "float64", "cfa": "str",
    "light_e": "float64", "level": "float64", "ratio": "float64", "clipped_share": "float64",
    "integration_time_s": "float64", "temperature_c": "float64", "seed": "int64",
    "source": "str", "window_row": "int64", "window_col": "int64", "config": "str",
}
_MANIFEST = "dataset.json"
#: the most samples a data set (or a stream) holds
MAX_SAMPLES = 10**9
#: the most samples one shard holds
MAX_SHARD_SIZE = 100000


@dataclass(frozen=True)
class Recipe:
    """What a data set is made of. Ranges are (low, high); a range of None keeps each camera's own value.

    ``cameras`` holds preset names (``sony-imx900``: a random row of its gain
    table per sample; ``sony-imx900@gain_db=3`` or ``sony-a7s2@iso=1600``: that
    setting), camera configuration files (``lab-fit/config.yaml``, as ``fit``
    writes it; their texts are in ``camera_files``, so the recipe alone
    makes its samples wherever it runs) and virtual camera families (``led``, ``eld``, ``eld:nikon-d850``,
    :mod:`cmosnoise.config.virtual_cameras`), each picked with equal
    probability. ``sources`` are image paths or built-in scene names.
    ``level`` is where the scene's white lands, a share of the camera's own saturation (the full well, or the
    ADC's white level above black if that comes first), log-uniform: each camera and gain gets a clean signal
    that does not clip; ``light_e`` (instead) is the charge at the scene's white in e-, whatever the camera.
    ``ratio`` is each sample's exposure ratio, ``reference_level / level``: how much a reference exposure whose
    white lands at ``reference_level`` outshines it (SID's and ELD's short against long exposures; the literature's
    metrics amplify the short exposure by it);
    ``integration_time_s`` log-uniform; ``temperature_c`` uniform.
    ``overrides`` are ``--set`` texts applied to every sample last.

    Parameters
    ----------
    samples : int
        How many samples.
    crop : (rows, cols)
        Each sample's size, pixels.
    seed : int
        The data set's seed: sample i depends on (seed, i) alone.
    cameras : tuple of str
        Presets and virtual camera families, as above.
    sources : tuple of str
        Image paths or built-in scene names.
    light_e : (float, float) or None
        The charge at the scene's white, e-, log-uniform (None: by ``level``).
    level : (float, float)
        The scene's white as a share of the camera's saturation, log-uniform (without ``light_e``).
    reference_level : float
        The reference exposure's level the ratio is against.
    allow_clipping : bool
        Whether a level above 1 (a white that saturates) is taken.
    integration_time_s : (float, float) or None
        Log-uniform, s (None: each camera's).
    temperature_c : (float, float) or None
        Uniform, C (None: each camera's).
    overrides : tuple of str
        ``--set`` texts.
    camera_files : tuple of (str, str)
        Each camera configuration file of ``cameras``: (its name there, its YAML text) (:func:`camera_files`).
    white_threshold_e_per_s : float or None
        The mask's white-pixel threshold, e-/s (None: the model's).
    shard_size : int
        Samples per shard file.
    format : str
        The shards' format: hdf5, npz or fits.
    """

    samples: int
    crop: tuple[int, int]
    seed: int = 0
    cameras: tuple[str, ...] = ("led",)
    sources: tuple[str, ...] = BUILTIN_SCENES
    light_e: tuple[float, float] | None = None
    level: tuple[float, float] = (0.003, 0.9)
    reference_level: float = 0.9
    allow_clipping: bool = False
    integration_time_s: tuple[float, float] | None = None
    temperature_c: tuple[float, float] | None = None
    overrides: tuple[str, ...] = ()
    camera_files: tuple[tuple[str, str], ...] = ()
    white_threshold_e_per_s: float | None = None
    shard_size: int = 64
    format: str = "hdf5"

    def shards(self) -> int:
        return math.ceil(self.samples / self.shard_size)

    def shard_range(self, shard: int) -> range:
        return range(shard * self.shard_size, min(self.samples, (shard + 1) * self.shard_size))

    def shard_name(self, shard: int) -> str:
        return f"shard-{shard:05d}{FORMATS[self.format]}"

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> Recipe:
        data = json.loads(text)
        for k in ("crop", "cameras", "sources", "light_e", "level", "integration_time_s", "temperature_c",
                  "overrides"):
            if data.get(k) is not None:
                data[k] = tuple(data[k])
        data["camera_files"] = tuple(tuple(f) for f in data.get("camera_files", ()))
        return cls(**data)


def check(recipe: Recipe, sources: Sources | None = None) -> Recipe:
    """``recipe`` if every part is usable; raises CmosnoiseError naming the first that is not (before any work).

    Parameters
    ----------
    recipe : Recipe
    sources : Sources, optional
        Where the sources' images are read (or given).

    Returns
    -------
    Recipe
    """
    r = recipe
    sources = sources or Sources()
    if not 1 <= r.samples <= MAX_SAMPLES:
        raise CmosnoiseError(f"--samples {r.samples}: give 1 to {MAX_SAMPLES}")
    if len(r.crop) != 2 or min(r.crop) < 2 or max(r.crop) > 30000 or any(c % 2 for c in r.crop):
        raise CmosnoiseError(f"--crop {r.crop}: give an even size from 2 to 30000 (the CFA's 2 x 2 cell kept whole)")
    if r.format not in FORMATS:
        raise CmosnoiseError(f"--format {r.format!r}: choose one of {', '.join(FORMATS)} (zarr is not offered: "
                             "HDF5 holds the same chunked, compressed arrays in one file per shard)")
    if not 1 <= r.shard_size <= MAX_SHARD_SIZE:
        raise CmosnoiseError(f"--shard-size {r.shard_size}: give 1 to {MAX_SHARD_SIZE} samples per shard")
    for name, rng, lo in (("--light", r.light_e, 1e-3), ("--exposure", r.integration_time_s, 1e-7)):
        if rng is not None and not lo <= rng[0] <= rng[1] <= 1e8:
            raise CmosnoiseError(f"{name} {rng[0]:g}:{rng[1]:g}: give LOW:HIGH with {lo:g} <= LOW <= HIGH")
    top = 100.0 if r.allow_clipping else 1.0
    if len(r.level) != 2 or not 1e-6 <= r.level[0] <= r.level[1] <= top:
        raise CmosnoiseError(f"--level {r.level[0]:g}:{r.level[1]:g}: give LOW:HIGH, shares of the camera's "
                             f"saturation, 1e-06 <= LOW <= HIGH <= {top:g}"
                             + ("" if r.allow_clipping else " (a white above 1 saturates: --allow-clipping)"))
    if not 0 < r.reference_level <= top:
        raise CmosnoiseError(f"--reference-level {r.reference_level:g}: give a share of the saturation in (0, "
                             f"{top:g}]")
    if r.temperature_c is not None and not -60 <= r.temperature_c[0] <= r.temperature_c[1] <= 150:
        raise CmosnoiseError(f"--temperature {r.temperature_c[0]:g}:{r.temperature_c[1]:g}: give LOW:HIGH in C, "
                             "-60 <= LOW <= HIGH <= 150")
    if not r.cameras:
        raise CmosnoiseError("--camera: give at least one preset or virtual camera family")
    presets = preset_names()
    for cam in r.cameras:
        name, _, gain = cam.partition("@")
        if name in virtual_cameras.FAMILIES:
            if gain:
                raise CmosnoiseError(f"--camera {cam!r}: a virtual camera family takes no @setting")
            continue
        if name in dict(r.camera_files):
            try:
                sources.preset(name, r.camera_files)
            except CmosnoiseError as exc:
                raise CmosnoiseError(f"--camera {name!r}: {exc}") from None
        elif name not in presets:
            raise CmosnoiseError(f"--camera {cam!r}: not a preset ({', '.join(presets)}), a camera configuration "
                                 f"file (.yaml, as fit writes it) or a virtual camera family "
                                 f"({', '.join(virtual_cameras.FAMILIES)})")
        if gain:
            _gain_update(cam)
    if not r.sources:
        raise CmosnoiseError("--images: the folder holds no images (" + ", ".join(IMAGE_SUFFIXES) + ")")
    settings(r, 0, sources)  # the first sample's configuration: a bad --set or a crop larger than a source says so now
    return r


def notes(recipe: Recipe, sources: Sources | None = None) -> list[str]:
    """What a recipe asks that some of its cameras cannot show, one line each: a ``--temperature`` range on a
    camera without a dark-current model (ELD's and LED's virtual cameras, calibrated on exposures too short to
    see it) changes nothing of its samples.

    Parameters
    ----------
    recipe : Recipe
    sources : Sources, optional

    Returns
    -------
    list of str
    """
    if recipe.temperature_c is None:
        return []
    sources = sources or Sources()
    blind = []
    for cam in recipe.cameras:
        name = cam.partition("@")[0]
        on = False if name in virtual_cameras.FAMILIES else sources.preset(name, recipe.camera_files).dark_current.enabled
        if not on:
            blind.append(cam)
    if not blind:
        return []
    return [f"--temperature {recipe.temperature_c[0]:g}:{recipe.temperature_c[1]:g}: {', '.join(blind)} "
            f"{'has' if len(blind) == 1 else 'have'} no dark-current model, so the temperature changes nothing of "
            "their samples"]


def camera_files(cameras) -> tuple[tuple[str, str], ...]:
    """The camera configuration files among ``cameras`` (``--camera`` values: a name not a preset or a virtual
    family, ending in .yaml or .yml, with or without an ``@setting``), each (its name, its text), read once here
    (at most the configuration files' size) so a recipe carries its cameras.

    Parameters
    ----------
    cameras : sequence of str

    Returns
    -------
    tuple of (str, str)
    """
    from ..config.loading import MAX_CONFIG_BYTES

    out: dict[str, str] = {}
    presets = preset_names()
    for cam in cameras:
        name = cam.partition("@")[0]
        if name in virtual_cameras.FAMILIES or name in presets or name in out:
            continue
        if name.lower().endswith((".yaml", ".yml")):
            out[name] = inputs.read_text(Path(name), "camera file", MAX_CONFIG_BYTES)
    return tuple(out.items())


def _gain_update(cam: str) -> dict:
    _, _, gain = cam.partition("@")
    key, _, value = gain.partition("=")
    if key not in ("iso", "gain_db"):
        raise CmosnoiseError(f"--camera {cam!r}: give the setting as @iso=VALUE or @gain_db=VALUE")
    try:
        return {key: float(value)}
    except ValueError:
        raise CmosnoiseError(f"--camera {cam!r}: {value!r} is not a number") from None


def image_sources(folder: str | Path) -> tuple[str, ...]:
    """The image files of ``folder`` (sorted by name), as the sources of a recipe.

    Parameters
    ----------
    folder : str or Path

    Returns
    -------
    tuple of str
        The files' paths.
    """
    p = Path(folder)
    if not p.is_dir():
        raise CmosnoiseError(f"--images {str(folder)!r} is not a folder of images")
    return tuple(str(f) for f in sorted(p.iterdir()) if f.suffix.lower() in IMAGE_SUFFIXES and f.is_file())


def _scene_shape(recipe: Recipe, source: str) -> tuple[int, int]:
    """The shape a source is drawn at: a built-in's for the recipe's crop (:func:`builtin_shape`); a file has its
    own (the shape is not used)."""
    return builtin_shape(recipe.crop) if scene_mod.is_builtin(source) else (BUILTIN_SIZE, BUILTIN_SIZE)


@dataclass
class Sources:
    """Each source's whole image at its own resolution, read once per process (a worker's own).

    ``images`` may be given arrays under names of their own (``array:0``, ...): linear RGB (rows, cols, 3) or a
    clean raw mosaic (rows, cols) in [0, 1] of the white, its CFA phase at (0, 0) the sensor's.

    Parameters
    ----------
    images : dict
        Source name -> its whole image (read on first use).
    presets : dict
        The presets' configurations, loaded once.
    preset_texts : dict
        The presets' files as data, read once.
    patterns : dict
        A raw photograph's CFA pattern, read once (:meth:`check_pattern`).
    saturations : dict
        A camera's saturation at a gain, worked out once (:meth:`saturation_e`).
    templates : dict
        A camera's configuration with the recipe's overrides, validated once (:meth:`template`).
    """

    images: dict = field(default_factory=dict)
    presets: dict = field(default_factory=dict)
    preset_texts: dict = field(default_factory=dict)
    patterns: dict = field(default_factory=dict)
    saturations: dict = field(default_factory=dict)
    templates: dict = field(default_factory=dict)

    def saturation_e(self, key: tuple, config) -> float:
        """:func:`_saturation_e` of ``config``, worked out once per ``key``: a camera, its gain row and the recipe's
        overrides (what sets K, the black and white levels and the full well; not a sample's seed, crop, light,
        exposure or temperature)."""
        if key not in self.saturations:
            self.saturations[key] = _saturation_e(config)
        return self.saturations[key]

    def template(self, name: str | None, files: tuple = (), overrides: tuple = ()):
        """A camera's configuration with the recipe's ``overrides``, validated once (:func:`sample_config` merges
        each sample into it); None where it does not validate without a sample's keys."""
        key = (name, files, tuple(overrides))
        if key not in self.templates:
            try:
                self.templates[key] = load_config(extra=self.preset_data(name, files), overrides=list(overrides))
            except CmosnoiseError:
                self.templates[key] = None
        return self.templates[key]

    def preset(self, name: str | None, files: tuple = ()):
        """A preset's (or a camera file's: ``files``, :attr:`Recipe.camera_files`) configuration, loaded once."""
        if name not in self.presets:
            self.presets[name] = load_config(extra=self.preset_data(name, files))
        return self.presets[name]

    def preset_data(self, name: str | None, files: tuple = ()) -> dict:
        """A preset file's data (``{}`` for None): what ``load_config(preset=name)`` merges first; a camera
        file's (``files``: (name, YAML text) pairs) read from its text."""
        if name not in self.preset_texts:
            given = dict(files).get(name) if name else None
            if given is not None:
                self.preset_texts[name] = config_data(given, f"camera file {name!r}")
            else:
                self.preset_texts[name] = preset_data(name) if name else {}
        return self.preset_texts[name]

    def image(self, source: str, shape: tuple[int, int] = (BUILTIN_SIZE, BUILTIN_SIZE)) -> np.ndarray:
        """A source's whole image: a file's at its own resolution, a built-in drawn at ``shape`` (rows, cols;
        :func:`builtin_shape`), each read or drawn once."""
        key = source
        if scene_mod.is_builtin(source) and tuple(shape) != (BUILTIN_SIZE, BUILTIN_SIZE):
            key = f"{source}@{shape[0]}x{shape[1]}"
        if key not in self.images:
            self.images[key] = scene_mod.source_image(source, tuple(int(v) for v in shape))
        return self.images[key]

    def check_pattern(self, source: str, pattern: str) -> None:
        """A raw photograph's mosaic keeps its colours: a camera of another CFA pattern is a one-line error (the
        crops' corners are even, so every crop has the photograph's pattern)."""
        if self.image(source).ndim != 2 or scene_mod.is_builtin(source) or not raw_scene.is_raw(source):
            return
        if source not in self.patterns:
            self.patterns[source] = raw_scene.read(source).pattern
        if self.patterns[source] != pattern:
            raise CmosnoiseError(f"--images: the raw photograph {source!r} has the colour filters "
                                 f"{self.patterns[source]}, a camera of this data set {pattern}: a mosaic keeps its "
                                 "colours; give cameras of its pattern")


@dataclass(frozen=True)
class SampleSettings:
    """What sample ``index`` is: its configuration (the sensor, seed, scene window, exposure) and its columns.

    Parameters
    ----------
    index : int
        The sample's number.
    config : Config
        Its sensor's configuration.
    columns : dict
        Its settings as columns (:data:`COLUMNS`).
    """

    index: int
    config: object
    columns: dict


def _rng(recipe: Recipe, index: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(recipe.seed, spawn_key=(0x7DA7A5E7, index)))


def settings(recipe: Recipe, index: int, sources: Sources | None = None) -> SampleSettings:
    """Sample ``index``'s settings, from a generator keyed by (recipe seed, index) alone.

    Parameters
    ----------
    recipe : Recipe
    index : int
        The sample's number.
    sources : Sources, optional

    Returns
    -------
    SampleSettings
    """
    sources = sources or Sources()
    rng = _rng(recipe, index)
    cam = recipe.cameras[int(rng.integers(len(recipe.cameras)))]
    name, _, gain = cam.partition("@")
    updates: dict = {}
    virtual = name in virtual_cameras.FAMILIES
    preset = None if virtual else name
    # its exposure and temperature are the sample's defaults (a gain row or a virtual camera changes neither)
    base = sources.preset(preset, recipe.camera_files)
    if virtual:
        camera, updates = virtual_cameras.sample(name, rng)
    else:
        camera = name
        if gain:
            updates["sensor"] = _gain_update(cam)
        elif base.gain_table:
            row = base.gain_table[int(rng.integers(len(base.gain_table)))]
            key = "iso" if row.iso is not None else "gain_db"
            updates["sensor"] = {key: getattr(row, key)}
    source = recipe.sources[int(rng.integers(len(recipe.sources)))]
    h, w = recipe.crop
    size = _scene_shape(recipe, source)
    img = sources.image(source, size)
    if img.shape[0] < h or img.shape[1] < w:
        raise CmosnoiseError(f"--crop {h}x{w}: the source {source!r} is {img.shape[0]} x {img.shape[1]}; give a "
                             "smaller crop or larger images")
    row = 2 * int(rng.integers((img.shape[0] - h) // 2 + 1))  # even corners: the CFA phase of the source kept
    col = 2 * int(rng.integers((img.shape[1] - w) // 2 + 1))
    span = recipe.light_e if recipe.light_e is not None else recipe.level
    drawn = math.exp(rng.uniform(math.log(span[0]), math.log(span[1])))
    t = base.exposure.integration_time_s
    if recipe.integration_time_s is not None:
        t = math.exp(rng.uniform(*(math.log(v) for v in recipe.integration_time_s)))
    temp = base.sensor.temperature_c
    if recipe.temperature_c is not None:
        temp = float(rng.uniform(*recipe.temperature_c))
    seed = int(rng.integers(0, 2**62))
    sample = {
        "seed": seed,
        "sensor": {"width": w, "height": h, "temperature_c": temp},
        "scene": {"source": source, "window": [row, col],
                  **({"source_size": list(size)} if scene_mod.is_builtin(source) else {})},
        "exposure": {"integration_time_s": t, **({"peak_rate_e_per_s": drawn / t} if recipe.light_e else {})},
        "run": {"frames": 1, "first_frame": 0},
    }
    merged = deep_merge(updates, sample)
    try:
        config = sample_config(recipe, sources, preset, merged)
    except CmosnoiseError as exc:
        raise CmosnoiseError(f"sample {index} ({camera}): {exc}") from None
    if config.light.enabled:  # a data set's light is its own axis (--light, e- at the white): not lux as well
        raise CmosnoiseError(f"sample {index} ({camera}): light.enabled is on, but a data set sets each sample's "
                             "light itself (--light, electrons at the scene's white); leave light in lux off")
    # a camera's saturation at a gain, once per process: a virtual camera's drawn parameters are its key too
    saturation = sources.saturation_e((preset, json.dumps(updates, sort_keys=True, default=str), recipe.overrides,
                                       recipe.camera_files), config)
    if recipe.light_e is not None:
        light, level = drawn, drawn / saturation
    else:  # the white where asked on this camera at this gain: its charge from the camera's own saturation
        light, level = drawn * saturation, drawn
        config = config.model_copy(update={"exposure": config.exposure.model_copy(
            update={"peak_rate_e_per_s": light / t})})
    sensor = config.sensor
    gain_row = physics.gain_row(config)
    columns = {"sample": index, "camera": camera, "mode": (gain_row.mode or "") if gain_row else "",
               "binning": sensor.binning,
               "iso": sensor.iso if sensor.iso is not None else math.nan,
               "gain_db": sensor.gain_db if sensor.gain_db is not None else math.nan,
               "cfa": sensor.cfa, "light_e": light, "level": level, "ratio": recipe.reference_level / level,
               "integration_time_s": t, "temperature_c": temp, "seed": seed,
               "source": source, "window_row": row, "window_col": col}
    return SampleSettings(index, config, columns)


def sample_config(recipe: Recipe, sources: Sources, preset: str | None, merged: dict):
    """A sample's configuration: the camera's data (``preset``: a preset or camera file; None: the defaults) with
    the sample's ``merged`` over it and the recipe's overrides last, validated.

    What ``load_config(extra=preset's data + merged, overrides=...)`` gives,
    made cheaply: the camera's configuration with the overrides is validated
    once per process (:meth:`Sources.template`) and the sample's keys are
    merged into it by :func:`~cmosnoise.config.merge_updates`, which
    validates only the sections they name. An override wins over the
    sample's keys; where one sets a key the sample sets too (or the camera
    alone does not validate) the whole validation is done, as it is to say
    an error (``tests/test_dataset.py`` holds the two equal).

    Parameters
    ----------
    recipe : Recipe
    sources : Sources
    preset : str or None
    merged : dict
        The sample's keys (a virtual camera's drawn parameters, a gain, its crop, seed, exposure), as data.

    Returns
    -------
    Config
    """
    template = sources.template(preset, recipe.camera_files, recipe.overrides)
    if template is not None and not _overridden(recipe.overrides, merged):
        try:
            return merge_updates(template, merged)
        except CmosnoiseError:
            pass  # the whole validation below says it as a configuration file would
    # the preset's data merged under the sample's, as load_config(preset=...) does, without reading the file
    return load_config(extra=deep_merge(sources.preset_data(preset, recipe.camera_files), merged),
                       overrides=list(recipe.overrides))


def _overridden(overrides: tuple, merged: dict) -> bool:
    """Whether an override sets a key of ``merged`` (one path the start of the other): it then wins over it."""
    def leaves(d: dict, at: tuple) -> Iterator[tuple]:
        for k, v in d.items():
            yield from leaves(v, (*at, k)) if isinstance(v, dict) and v else [(*at, k)]

    paths = list(leaves(merged, ()))
    for text in overrides:
        key = tuple(parse_override(text)[0])
        if any(p[:len(key)] == key or key[:len(p)] == p for p in paths):
            return True
    return False


def _saturation_e(config) -> float:
    """The charge a camera saturates at, e-: its full well, or the ADC's white level above black if that comes
    first (:attr:`cmosnoise.model.spec.SensorSpec.saturation_e`, from the transfer alone)."""
    from ..model.spec import transfer

    config = physics.apply_gain(config)  # the gain table's row (ISO, conversion gain) sets K and the full well
    t = transfer(config)
    return float(min(config.sensor.full_well_e, (t.max_code - t.black_level_dn) / t.gain_dn_per_e))


#: samples whose frames the GPU makes in one launch (:func:`make_samples`): their maps are stacked on the host and
#: the device, some 16 bytes a pixel each
GPU_BATCH = 64


def make_sample(recipe: Recipe, index: int, sources: Sources | None = None, frame: int = 0,
                device: str = "cpu", on_device: bool = False) -> tuple[dict, dict]:
    """(arrays, columns) of sample ``index``: the noisy raw and its truths (:data:`ARRAYS`), and its settings.

    ``frame``: which frame of the sample's sensor is the noisy raw (0 in a data set; another frame is fresh
    temporal noise on the same sensor, scene and truth). ``device``: where the frame is made (the same bits);
    ``on_device`` (with ``device="cuda"``): the raw is left on the GPU, a device array (the truths are made on the
    host either way).

    Parameters
    ----------
    recipe : Recipe
    index : int
        The sample's number.
    sources : Sources, optional
        Where the sources' images are read (or given).
    frame : int
        Which frame of the sample's sensor is the noisy raw.
    device : str
        "cpu" or "cuda".
    on_device : bool
        Leave the raw on the GPU.

    Returns
    -------
    (dict, dict)
        The arrays by name (:data:`ARRAYS`: ``raw`` and ``expected_raw`` in DN, ``perfect_dn``, ``mask``), each
        (rows, cols), and the settings by column name (:data:`COLUMNS`).
    """
    return make_samples(recipe, [index], sources, frame, device, on_device)[0]


def make_samples(recipe: Recipe, indices, sources: Sources | None = None, frame: int = 0, device: str = "cpu",
                 on_device: bool = False) -> list[tuple[dict, dict]]:
    """Samples ``indices``, as :func:`make_sample` makes each, the same bits; on the GPU their frames in one launch.

    With ``device="cuda"`` each sample's sensor and exposure are set up as
    one alone would be, and then the noisy raws of all of them (each its own
    sensor: camera, gain, seed, scene) are made together
    (:func:`cmosnoise.frames_together`): one upload of their maps and one
    launch for every :data:`GPU_BATCH` samples, not one per sample.

    Parameters
    ----------
    recipe, sources, frame, device
        As :func:`make_sample`.
    indices : sequence of int
        The samples' numbers.
    on_device : bool
        Leave the raws on the GPU: each sample's ``raw`` is then an item of its batch's device array (B, rows,
        cols).

    Returns
    -------
    list of (dict, dict)
        Each sample's arrays and settings, in the order of ``indices``.
    """
    sources = sources or Sources()
    indices = [int(i) for i in indices]
    gpu = device == "cuda"
    step = GPU_BATCH if gpu else 1  # the host holds a batch's exposures (on the GPU, their maps stacked) at a time
    out = []
    for first in range(0, len(indices), step):
        made = [_exposure(recipe, i, sources, device) for i in indices[first:first + step]]
        if gpu:
            raws, _ = frames_together([shot for shot, _ in made], frame)
            raws = raws if on_device else raws.copy_to_host()
        else:
            raws = [shot.frame(frame) for shot, _ in made]
        out += [_finish(recipe, shot, st, raws[b]) for b, (shot, st) in enumerate(made)]
    return out


def _exposure(recipe: Recipe, index: int, sources: Sources, device: str) -> tuple:
    """Sample ``index``'s exposure (its sensor set up, the crop's scene exposed) and its settings."""
    st = settings(recipe, index, sources)
    c = st.config
    sensor = Sensor(c, device=device)
    sources.check_pattern(c.scene.source, sensor.cfa)
    # the crop's pixels through the CFA, read from the source where they lie (no copy of the window), a built-in at
    # the size its settings recorded
    shot = sensor.expose(scene_mod.window_cfa(sources.image(c.scene.source, tuple(c.scene.source_size or (BUILTIN_SIZE, BUILTIN_SIZE))), tuple(c.scene.window), sensor.shape,
                                              sensor.cfa, sensor.spec.channel_responsivity))
    return shot, st


def _finish(recipe: Recipe, shot, st: SampleSettings, raw) -> tuple[dict, dict]:
    """A sample's arrays (its noisy ``raw`` and its truths) and columns."""
    truth = ground_truth.truth(shot, recipe.white_threshold_e_per_s)
    t = shot.sensor.transfer
    clipped = float(np.mean(np.asarray(raw) >= t.max_code)) if hasattr(raw, "shape") else math.nan
    columns = {**st.columns, "k_dn_per_e": t.gain_dn_per_e, "black_level_dn": t.black_level_dn,
               "white_level_dn": float(t.max_code), "clipped_share": clipped, "config": st.config.to_yaml()}
    arrays = {"raw": raw, "expected_raw": truth.expected_raw, "perfect_dn": truth.perfect_dn, "mask": truth.mask}
    return arrays, columns


# ------------------------------------------------------------------ shards
def shard_bytes(recipe_json: str, shard: int, device: str = "cpu", sources: Sources | None = None) -> bytes:
    """Shard ``shard`` of the recipe, as the bytes of its file (made in memory: a Dask task returns them).

    Parameters
    ----------
    recipe_json : str
        The recipe as JSON (what a Dask task gets).
    shard : int
        The shard's number.
    device : str
        "cpu" or "cuda".
    sources : Sources, optional
        The source images already read (one process's shards share them, and one Dask worker's).

    Returns
    -------
    bytes
        The shard file's contents.
    """
    recipe = Recipe.from_json(recipe_json)
    made = make_samples(recipe, recipe.shard_range(shard), sources or Sources(), device=device)
    arrays = {k: np.stack([a[k] for a, _ in made]) for k in ARRAYS}
    columns = {k: [c[k] for _, c in made] for k in COLUMNS}
    return {"hdf5": _hdf5, "npz": _npz, "fits": _fits}[recipe.format](arrays, columns, recipe)


def _column_array(name: str, values: list) -> np.ndarray:
    kind = COLUMNS[name]
    return np.array([str(v) for v in values]) if kind == "str" else np.array(values, dtype=kind)


def _attrs(recipe: Recipe) -> dict:
    return {"cmosnoise": __version__, "scheme_version": SCHEME_VERSION, "recipe": recipe.to_json(),
            "mask_bits": json.dumps(ground_truth.MASK_BITS)}


def _hdf5(arrays: dict, columns: dict, recipe: Recipe) -> bytes:
    import h5py

    bio = io.BytesIO()
    # text as fixed-length UTF-8, never variable-length: HDF5 keeps those in a global heap whose unused space it
    # does not clear, so the same shard would not always be the same bytes
    # and no chunk cache, each array flushed as it is written: the file's layout (where each chunk lands) is then
    # the order of the writes, not the caches' eviction order (which varied from process to process)
    with h5py.File(bio, "w", track_order=True, rdcc_nbytes=0) as f:
        for k, v in _attrs(recipe).items():
            f.attrs[k] = np.bytes_(str(v).encode())
        for k in ARRAYS:
            a = arrays[k]
            f.create_dataset(k, data=a, chunks=(1, *a.shape[1:]), compression="gzip", compression_opts=4,
                             shuffle=True, track_times=False)
            f.flush()
        g = f.create_group("settings", track_order=True)
        for k in COLUMNS:
            a = _column_array(k, columns[k])
            if a.dtype.kind == "U":
                raw = [v.encode() for v in a]
                g.create_dataset(k, data=np.array(raw, dtype=f"S{max(1, max(map(len, raw)))}"), track_times=False)
            else:
                g.create_dataset(k, data=a, track_times=False)
    return bio.getvalue()


def _npz(arrays: dict, columns: dict, recipe: Recipe) -> bytes:
    bio = io.BytesIO()
    entries = {**arrays, **{f"settings.{k}": _column_array(k, v) for k, v in columns.items()},
               **{f"attrs.{k}": np.array(str(v)) for k, v in _attrs(recipe).items()}}
    with zipfile.ZipFile(bio, "w", zipfile.ZIP_DEFLATED) as z:
        for name, a in entries.items():
            info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with z.open(info, "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asarray(a), allow_pickle=False)
    return bio.getvalue()


def _fits(arrays: dict, columns: dict, recipe: Recipe) -> bytes:
    from astropy.io import fits

    primary = fits.PrimaryHDU()
    for k, v in _attrs(recipe).items():
        if k != "recipe":  # a FITS card holds 68 characters: the recipe is in the table's header as COMMENT lines
            primary.header[k[:8].upper()] = str(v)
    hdus = [primary] + [fits.ImageHDU(arrays[k], name=k.upper()) for k in ARRAYS]
    cols = []
    for k in COLUMNS:
        a = _column_array(k, columns[k])
        fmt = f"{max(1, max(len(s.encode()) for s in a))}A" if a.dtype.kind == "U" else {"int64": "K", "float64": "D"}[COLUMNS[k]]
        cols.append(fits.Column(name=k, format=fmt, array=a))
    table = fits.BinTableHDU.from_columns(cols, name="SETTINGS")
    for i in range(0, len(recipe.to_json()), 64):
        table.header.add_comment(recipe.to_json()[i:i + 64])
    hdus.append(table)
    bio = io.BytesIO()
    fits.HDUList(hdus).writeto(bio)
    return bio.getvalue()


def read_shard(path: str | Path) -> tuple[dict, dict]:
    """(arrays, columns) of a shard file of any format, checked before and after it is decoded.

    The file must be a regular file (a FIFO never blocks the reader); its decoded size, read from its headers
    (HDF5 datasets' shapes, an npz's zip directory, FITS headers), is bounded by :data:`MAX_SHARD_BYTES` and the
    machine's available memory before a byte is decoded; its arrays must be numeric, of one shape
    (samples, rows, cols), with a column of each setting per sample, finite black and white levels and a known
    CFA. Anything else is one :class:`CmosnoiseError` naming the shard and what is wrong.

    Parameters
    ----------
    path : str or Path
        An HDF5, npz or FITS shard.

    Returns
    -------
    (dict, dict)
        The arrays (each (samples, rows, cols)) and the columns (each (samples,)).
    """
    p = Path(path)
    what = "shard"
    if p.suffix not in (".h5", ".npz", ".fits"):
        raise CmosnoiseError(f"{str(path)!r} is not a shard (.h5, .npz or .fits)")
    inputs.check_regular(p, what)
    try:
        if p.suffix == ".h5":
            arrays, columns = _read_h5(p)
        elif p.suffix == ".npz":
            members = inputs.npz_members(p, what, MAX_SHARD_BYTES)
            for k in (*ARRAYS, *(f"settings.{c}" for c in COLUMNS)):
                if f"{k}.npy" not in members:
                    raise CmosnoiseError(f"shard {str(p)!r} has no {k!r} array ({_HOLDS})")
            with np.load(p, allow_pickle=False) as z:
                arrays, columns = {k: z[k] for k in ARRAYS}, {k: z[f"settings.{k}"] for k in COLUMNS}
        else:
            from astropy.io import fits

            inputs.fits_data_bytes(p, what, MAX_SHARD_BYTES)
            with fits.open(p, memmap=False) as h:
                names = {hdu.name for hdu in h}
                for k in (*(a.upper() for a in ARRAYS), "SETTINGS"):
                    if k not in names:
                        raise CmosnoiseError(f"shard {str(p)!r} has no {k} extension ({_HOLDS})")
                arrays = {k: np.asarray(h[k.upper()].data) for k in ARRAYS}
                t = h["SETTINGS"].data
                missing = [k for k in COLUMNS if t is None or k not in t.names]
                if missing:
                    raise CmosnoiseError(f"shard {str(p)!r} has no {missing[0]!r} setting ({_HOLDS})")
                columns = {k: np.asarray(t[k]) for k in COLUMNS}
    except CmosnoiseError:
        raise
    except Exception as exc:  # a damaged file of any format: the reader's own words, one line
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise CmosnoiseError(f"shard {str(p)!r} cannot be read: {first}") from None
    return _checked_shard(p, arrays, columns)


#: the most bytes one shard decodes to (arrays and settings): 64 samples of 1024 x 1024 take 0.74 GB
MAX_SHARD_BYTES = 2_000_000_000
_HOLDS = "a shard holds raw, expected_raw, perfect_dn and mask, and a setting of each sample: make it with cmosnoise dataset"


def _read_h5(p: Path) -> tuple[dict, dict]:
    import h5py

    with h5py.File(p, "r") as f:
        total = 0
        for k in (*ARRAYS, *(f"settings/{c}" for c in COLUMNS)):
            d = f.get(k)
            if not isinstance(d, h5py.Dataset):
                raise CmosnoiseError(f"shard {str(p)!r} has no {k!r} array ({_HOLDS})")
            if d.is_virtual or d.external:  # its data in other files, read without a word where they are missing
                raise CmosnoiseError(f"shard {str(p)!r}: {k!r} is stored outside the file ("
                                     f"{'a virtual dataset' if d.is_virtual else 'external storage'}); a shard "
                                     "holds its own data (make one with cmosnoise dataset)")
            if d.dtype.kind in "OV" or (d.dtype.kind not in "SU" and d.dtype.kind not in "uifb"):
                raise CmosnoiseError(f"shard {str(p)!r}: {k!r} holds {d.dtype} values; expected numbers or text")
            total += int(np.prod(d.shape, dtype=np.int64)) * max(d.dtype.itemsize, 1)
        inputs.check_decoded(total, p, "shard", MAX_SHARD_BYTES)  # from the datasets' shapes: nothing inflated yet
        arrays = {k: f[k][()] for k in ARRAYS}
        columns = {k: _decoded(f["settings"][k][()]) for k in COLUMNS}
    return arrays, columns


def read_sample(path: str | Path, at: int) -> tuple[dict, dict]:
    """Sample ``at`` of a shard alone: in an HDF5 shard, its own chunk of each array (one sample a chunk) and its
    row of the settings, checked as :func:`read_shard` checks the whole; in another format, the shard read whole.

    Parameters
    ----------
    path : str or Path
        The shard.
    at : int
        The sample's place in the shard.

    Returns
    -------
    (dict, dict)
        Its arrays (rows, cols) and its settings, by name.
    """
    p = Path(path)
    if p.suffix.lower() != ".h5":
        arrays, columns = read_shard(p)
        return {k: v[at] for k, v in arrays.items()}, {k: v[at] for k, v in columns.items()}
    inputs.check_regular(p, "shard")
    try:
        import h5py

        with h5py.File(p, "r") as f:
            n = _h5_header(p, f)
            if not 0 <= at < n:
                raise CmosnoiseError(f"shard {str(p)!r} holds {n} samples; sample {at} is not one of them")
            arrays = {k: f[k][at:at + 1] for k in ARRAYS}
            columns = {k: _decoded(f["settings"][k][at:at + 1]) for k in COLUMNS}
    except CmosnoiseError:
        raise
    except Exception as exc:  # a damaged file: the reader's own words, one line
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise CmosnoiseError(f"shard {str(p)!r} cannot be read: {first}") from None
    arrays, columns = _checked_shard(p, arrays, columns)
    return {k: v[0] for k, v in arrays.items()}, {k: v[0] for k, v in columns.items()}


def _h5_header(p: Path, f) -> int:
    """An HDF5 shard's datasets checked from their headers (present, numbers or text, stored in the file, one
    shape, a setting per sample): its number of samples."""
    import h5py

    n = None
    for k in (*ARRAYS, *(f"settings/{c}" for c in COLUMNS)):
        d = f.get(k)
        if not isinstance(d, h5py.Dataset):
            raise CmosnoiseError(f"shard {str(p)!r} has no {k!r} array ({_HOLDS})")
        if d.is_virtual or d.external:
            raise CmosnoiseError(f"shard {str(p)!r}: {k!r} is stored outside the file ("
                                 f"{'a virtual dataset' if d.is_virtual else 'external storage'}); a shard holds its "
                                 "own data (make one with cmosnoise dataset)")
        if d.dtype.kind in "OV" or (d.dtype.kind not in "SU" and d.dtype.kind not in "uifb"):
            raise CmosnoiseError(f"shard {str(p)!r}: {k!r} holds {d.dtype} values; expected numbers or text")
        if not d.shape or (n is not None and d.shape[0] != n):
            raise CmosnoiseError(f"shard {str(p)!r}: {k!r} has shape {d.shape}; a shard's arrays and settings hold "
                                 f"one entry per sample ({n})")
        n = d.shape[0]
    return int(n)


def _checked_shard(p: Path, arrays: dict, columns: dict) -> tuple[dict, dict]:
    """The shard's arrays and columns if they are a shard's: one shape, numbers, a setting per sample."""
    name = f"shard {str(p)!r}"
    shape = None
    for k in ARRAYS:
        a = np.asarray(arrays[k])
        if a.dtype.kind not in "uifb":
            raise CmosnoiseError(f"{name}: {k!r} holds {a.dtype} values; expected numbers")
        if a.ndim != 3 or min(a.shape) < 1:
            raise CmosnoiseError(f"{name}: {k!r} has shape {a.shape}; expected (samples, rows, cols)")
        if shape is not None and a.shape != shape:
            raise CmosnoiseError(f"{name}: {k!r} has shape {a.shape}, {ARRAYS[0]!r} {shape}; the arrays of a shard "
                                 "share one shape")
        shape = a.shape
    for k in COLUMNS:
        c = np.asarray(columns[k])
        if c.ndim != 1 or len(c) != shape[0]:
            raise CmosnoiseError(f"{name}: the setting {k!r} has {c.size} values for {shape[0]} samples")
        if COLUMNS[k] != "str" and c.dtype.kind not in "uif":
            raise CmosnoiseError(f"{name}: the setting {k!r} holds {c.dtype} values; expected numbers")
    black = np.asarray(columns["black_level_dn"], np.float64)
    white = np.asarray(columns["white_level_dn"], np.float64)
    if not (np.all(np.isfinite(black)) and np.all(np.isfinite(white)) and np.all(white > black)):
        raise CmosnoiseError(f"{name}: black_level_dn and white_level_dn must be finite, white above black "
                             f"(black {black.tolist()[:3]}, white {white.tolist()[:3]})")
    for cfa in set(str(v) for v in columns["cfa"]):
        if cfa not in (*BAYER_PATTERNS, "none"):
            raise CmosnoiseError(f"{name}: cfa {cfa!r}; expected one of {', '.join(BAYER_PATTERNS)} or none")
    return arrays, columns


def _decoded(a: np.ndarray) -> np.ndarray:
    return np.array([v.decode() for v in a]) if a.dtype.kind == "S" else a


# ------------------------------------------------------------------ the folder
def _write(folder: Path, name: str, data: bytes) -> None:
    with atomic_file(folder / name) as tmp:
        tmp.write_bytes(data)


def _manifest(recipe: Recipe) -> str:
    return json.dumps({"cmosnoise": __version__, "scheme_version": SCHEME_VERSION, "recipe": json.loads(recipe.to_json()),
                       "shards": [recipe.shard_name(s) for s in range(recipe.shards())],
                       "arrays": list(ARRAYS), "columns": list(COLUMNS), "mask_bits": ground_truth.MASK_BITS},
                      indent=1, sort_keys=True) + "\n"


def missing(recipe: Recipe, folder: Path) -> list[int]:
    """The shards of ``recipe`` that ``folder`` does not hold yet.

    Parameters
    ----------
    recipe : Recipe
    folder : Path

    Returns
    -------
    list of int
        The missing shards' numbers.
    """
    return [s for s in range(recipe.shards()) if not (folder / recipe.shard_name(s)).is_file()]


def _mode(out: Path, recipe: Recipe, resume: bool, overwrite: bool) -> str:
    return resumable_mode(out, _MANIFEST, _manifest(recipe), resume, overwrite, "data set")


def _shards_here(recipe: Recipe, todo: list[int], device: str = "cpu") -> Iterator[tuple[int, bytes]]:
    recipe_json = recipe.to_json()
    sources = Sources()  # each source image read once for all the shards
    for s in todo:
        yield s, shard_bytes(recipe_json, s, device, sources)


def _shard_task(recipe_json: str, shard: int, device: str) -> bytes:
    """A Dask task: :func:`shard_bytes` with the worker's source images, read by its first shard task of this
    recipe and kept on the worker for its next ones (:func:`~cmosnoise.app.cluster.worker_attribute`)."""
    from .cluster import worker_attribute

    held = worker_attribute("dataset_sources", dict)
    if held.get("recipe") != recipe_json:
        held.update(recipe=recipe_json, sources=Sources())
    return shard_bytes(recipe_json, shard, device, held["sources"])


def _shards_on(client, recipe: Recipe, todo: list[int], device: str = "cpu") -> Iterator[tuple[int, bytes]]:
    from distributed import as_completed

    from .cluster import task_result

    recipe_json = recipe.to_json()
    futures = {client.submit(_shard_task, recipe_json, s, device, pure=False, retries=2): s for s in todo}
    for future in as_completed(futures):
        data = task_result(future, "a dataset task")
        future.release()
        yield futures[future], data


def build(recipe: Recipe, out: str | Path, resume: bool = False, overwrite: bool = False,
          scheduler: str | None = None, workers: int | None = None,
          progress: Callable[[int, int], None] | None = None, say: Callable[[str], None] = lambda m: None,
          device: str = "cpu") -> Path:
    """Make the data set ``recipe`` in ``out``: ``dataset.json`` and its shards (each written whole, under a
    temporary name first). ``resume`` makes only the missing shards of the same recipe. ``workers`` or
    ``scheduler``: the shards are made on Dask (a LocalCluster of processes, or that scheduler); the bytes
    are the same. ``device``: where the frames are made (``"cuda"``: the GPU; the same bytes).

    Parameters
    ----------
    recipe : Recipe
    out : str or Path
        The data set's folder.
    resume, overwrite : bool
        Complete the data set in ``out``, or replace it.
    scheduler : str, optional
        An existing Dask scheduler's address.
    workers : int, optional
        A LocalCluster of this many processes.
    progress : callable, optional
        Called with (samples done, samples).
    say : callable
        Told what is started.
    device : str
        "cpu" or "cuda".

    Returns
    -------
    Path
        The folder.
    """
    from ..io.output import OutputFolder
    from .cluster import connect, disconnect

    check(recipe)
    check_device(device, "--device")
    out = Path(out)
    folder = OutputFolder(out, overwrite=True)  # its checks on the name and place; creates nothing
    mode = _mode(out, recipe, resume, overwrite)
    try:
        with contextlib.ExitStack() as stack:
            if mode == "replace":
                work = stack.enter_context(folder)
            else:
                stack.enter_context(folder.lock)
                mode = _mode(out, recipe, resume, overwrite)
                work = out
                work.mkdir(parents=True, exist_ok=True)
                for stale in work.glob(".shard-*.tmp"):  # a shard an interrupted run had not finished
                    stale.unlink()
            if mode != "resume":
                _write(work, _MANIFEST, _manifest(recipe).encode())
            todo = missing(recipe, work) if mode == "resume" else list(range(recipe.shards()))
            total = recipe.samples
            done = total - sum(len(recipe.shard_range(s)) for s in todo)
            if progress:
                progress(done, total)
            if mode == "resume":
                say(f"--resume: {recipe.shards() - len(todo)} of {recipe.shards()} shard(s) already made; "
                    f"making {len(todo)}")
            if todo and (workers is not None or scheduler is not None):
                client, cluster = connect(scheduler, workers, say)
                stack.callback(disconnect, client, cluster)
                made = _shards_on(client, recipe, todo, device)
            else:
                made = _shards_here(recipe, todo, device)
            counted = [done]

            def kept() -> str:
                if mode == "replace":
                    return f"nothing was written: {out} keeps the data set it held"
                shards = recipe.shards() - len(missing(recipe, work))
                rest = "the data set is whole" if shards == recipe.shards() else "--resume completes it"
                return f"{shards} of {recipe.shards()} shards ({counted[0]} of {total} samples) kept in {out}; {rest}"

            try:
                with keeping(kept):  # the shards made so far stay where they are resumable
                    for s, data in made:
                        _write(work, recipe.shard_name(s), data)
                        counted[0] += len(recipe.shard_range(s))
                        if progress:
                            progress(counted[0], total)
                        # a signal whose exception a library swallowed (LLVM's callbacks into numba) stops the
                        # job here, with what it kept said, not after the last shard as "nothing was written"
                        check_terminated()
            except BaseException as exc:
                note_kept(exc, kept())
                raise
    except OSError as exc:
        raise CmosnoiseError(f"--out {str(out)!r} cannot be written: {exc.strerror or exc}") from None
    return out


def read(folder: str | Path) -> Iterator[tuple[dict, dict]]:
    """Every shard of a data set folder in order: (arrays, columns).

    Parameters
    ----------
    folder : str or Path
        A data set folder (``dataset.json`` and its shards).

    Yields
    ------
    (dict, dict)
        Each shard's arrays (each (samples, rows, cols)) and columns (each (samples,)).
    """
    folder = Path(folder)
    manifest = read_manifest(folder)
    for name in manifest["shards"]:
        yield read_shard(folder / name)


#: the most bytes of a dataset.json (a million shards' names take some 25 MB)
MAX_MANIFEST_BYTES = 50_000_000


def read_manifest(folder: str | Path) -> dict:
    """A data set folder's ``dataset.json``, checked: a JSON object with a recipe (its samples a whole number)
    and a list of shard files of that folder; one line for anything else.

    Parameters
    ----------
    folder : str or Path
        A data set folder.

    Returns
    -------
    dict
        The manifest (``recipe``, ``shards``, ...).
    """
    folder = Path(folder)
    path = folder / _MANIFEST
    if not path.exists():
        raise CmosnoiseError(f"--data {str(folder)!r} is not a data set (no dataset.json): make one with "
                             "cmosnoise dataset")
    m = inputs.read_json(path, "dataset.json", MAX_MANIFEST_BYTES)
    recipe, shards = m.get("recipe"), m.get("shards")
    if not isinstance(recipe, dict) or not isinstance(shards, list):
        raise CmosnoiseError(f"{str(path)!r} has no recipe or no list of shards: not a data set's manifest "
                             "(make one with cmosnoise dataset)")
    samples = recipe.get("samples")
    if isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= MAX_SAMPLES:
        raise CmosnoiseError(f"{str(path)!r}: recipe.samples is {samples!r}; expected a whole number from 1 to "
                             f"{MAX_SAMPLES}")
    size = recipe.get("shard_size", 64)
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_SHARD_SIZE:
        raise CmosnoiseError(f"{str(path)!r}: recipe.shard_size is {size!r}; expected a whole number from 1 to "
                             f"{MAX_SHARD_SIZE}")
    want = -(-samples // size)  # the shards its samples fill, counted before any list of that length is made
    if len(shards) != want:
        raise CmosnoiseError(f"{str(path)!r}: it names {len(shards)} shards, and its recipe's {samples} samples of "
                             f"{size} a shard fill {want}: not a data set's manifest (make one with cmosnoise "
                             "dataset)")
    for name in shards:
        if not isinstance(name, str) or Path(name).name != name or not name.startswith("shard-"):
            raise CmosnoiseError(f"{str(path)!r}: shard {name!r} is not a shard file's name in the folder")
    try:
        Recipe.from_json(json.dumps(recipe))
    except (TypeError, ValueError) as exc:
        raise CmosnoiseError(f"{str(path)!r}: its recipe is not a data set's ({' '.join(str(exc).split())[:200]})") \
            from None
    return m


def load_sample_config(text: str):
    """A sample's configuration from its ``config`` column (YAML; ``cmosnoise simulate --config`` reads it too).

    Parameters
    ----------
    text : str
        A sample's ``config`` column.

    Returns
    -------
    Config
    """
    from ..config.loading import load_yaml_text

    return load_config(extra=load_yaml_text(str(text)))
