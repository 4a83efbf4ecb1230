"""The chain of docs/model.md section 2, composed from the stage modules.

>>> from cmosnoise import Sensor, load_config
>>> sensor = Sensor(load_config(preset="paper-fig3-prnu"), seed=7)   # fixed pattern drawn here
>>> shot = sensor.expose("flat:0.5")                                 # mean charge of a scene
>>> raw = shot.frame(0)                                              # uint16 DN, (rows, cols)
>>> detail = shot.frame(0, detail=True)                              # plus electrons and each stage's part

A :class:`Sensor` is a configuration plus a seed: everything fixed-pattern is
drawn when it is built and never changes. An :class:`Exposure` holds what is
fixed for one scene, exposure and temperature (the mean charge per pixel);
its frame ``k`` draws the temporal noise from streams keyed by ``(seed, k)``,
so any frame can be made alone, in any order, on any machine.

This module contains no physics: each stage is a function in its own module.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config, ExposureSection, build_section, load_config
from ..config.schema import LAST_FRAME
from ..engine import fixed_maps, reduce
from ..engine.frame import cuda_kernel, kernel
from ..engine.frame.plan import KEY_ROWS, FramePlan
from ..errors import CmosnoiseError
from . import footprint, reference
from . import optics as optics_mod
from . import scene as scene_mod
from .fixed_pattern import FixedPattern, PatternCache, cached, dependencies, draw
from .raw_info import RawInfo
from .seeds import SEQ_DARK_CALIBRATION, SEQ_SCENE, fixed_key, stream_key
from .spec import SensorSpec, resolve
from .stages import (
    adc,
    column_noise,
    crosstalk,
    dark_current,
    defects,
    prnu,
    random_telegraph,
    row_noise,
    source_follower,
)


@dataclass
class FrameDetail:
    """One frame with its parts.

    ``contributions`` maps each stage to what it added, in e-, shape (rows,
    cols); those before the ADC sum to ``electrons``. What the ADC adds is
    referred back to e- too: ``black_level`` (the CFA cell's offsets and the
    frame's black-level error, where set), ``read_noise`` (after the gain,
    where on) and ``quantization`` (rounding and clipping); ``raw`` is the ADC
    output in DN.

    Parameters
    ----------
    index : int
        The frame's index.
    raw : (rows, cols) uint16 array, DN
        The frame (float32 e- with the ADC off).
    electrons : (rows, cols) array, e-
        The charge at the ADC's input.
    contributions : dict of str to (rows, cols) array, e-
        What each stage added.

    Examples
    --------
    >>> from cmosnoise import Sensor
    >>> shot = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).expose("flat:0.5")
    >>> d = shot.frame(0, detail=True)
    >>> sorted(d.contributions)[:4]
    ['column_noise', 'crosstalk', 'dark_current', 'perfect']
    """

    index: int
    raw: np.ndarray
    electrons: np.ndarray
    contributions: dict[str, np.ndarray]


#: where frames are made: the CPU kernel, or an NVIDIA GPU (engine/frame/cuda_kernel)
DEVICES = ("cpu", "cuda")


def check_device(device: str, name: str = "device") -> None:
    """A one-line :class:`CmosnoiseError` for a device that is not one of :data:`DEVICES`, or a GPU this machine
    lacks; ``name`` is how the caller's user gave it (``--device``)."""
    if device not in DEVICES:
        given = f"{name} {device!r}" if name.startswith("--") else f"{name} = {device!r}"  # as an option, or a value
        raise CmosnoiseError(f"{given}: expected one of {', '.join(DEVICES)}")
    if device == "cuda":
        cuda_kernel.check()

class Sensor:
    """A simulated sensor: a configuration, a seed, and the fixed pattern drawn from them.

    Parameters
    ----------
    config : SensorSpec, Config, dict, str or Path, optional
        The sensor: a resolved spec, a configuration, a (partial) configuration as data merged over the
        defaults, or a YAML file's path (defaults if omitted).
    seed : int, optional
        Overrides the configuration's seed (every other value it set is kept, nulls included).
    fixed_pattern : FixedPattern, optional
        Maps already drawn for this configuration and seed (a sensor made again from its parts); drawn if
        omitted.
    cache : PatternCache, optional
        Fixed-pattern maps and exposure products kept between sensors (:mod:`.fixed_pattern`): a map
        whose inputs a cached sensor of the same seed and size shared is taken from it, bit for bit.
    device : {"cpu", "cuda"}
        Where frames are made: the CPU kernel (the default), or an NVIDIA GPU through numba's CUDA target
        (``pip install cmosnoise[cuda]``), with the same bits. A one-line error where no GPU is present.
        :meth:`Exposure.frames_on_device` keeps the frames on the GPU.
    window : (row0, row1, col0, col1), optional
        Make only this rectangle of the sensor (a tile of a sensor too large to hold whole; default the whole
        sensor): every fixed map, the scene and the mean charge cover the window alone, and its frames (any
        region inside it) are bit for bit those regions of the whole sensor's frames, except within a pixel of
        an inner edge of the window, where crosstalk would need the neighbours outside
        (:mod:`cmosnoise.model.tiles` adds that margin). ``row0`` and ``col0`` must be even, so that the CFA's
        phase is the sensor's. ``shape`` stays the whole sensor's; :attr:`map_shape` is the window's.
    populations : FixedPattern, optional
        Another window's fixed pattern of this configuration and seed, whose sparse populations (random
        telegraph traps, blinking pixels, defects: drawn for the whole sensor) are taken, not drawn again.

    Examples
    --------
    >>> from cmosnoise import Sensor
    >>> sensor = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7)
    >>> sensor.shape, sensor.cfa
    ((48, 64), 'RGGB')
    >>> raw = sensor.expose("flat:0.5").frame(0)       # frame 0 of a flat grey scene, DN
    >>> raw.shape, raw.dtype
    ((48, 64), dtype('uint16'))
    """

    def __init__(self, config: SensorSpec | Config | dict | str | Path | None = None, seed: int | None = None, *,
                 fixed_pattern: FixedPattern | None = None, cache: PatternCache | None = None,
                 device: str = "cpu", window: tuple[int, int, int, int] | None = None,
                 populations: FixedPattern | None = None):
        check_device(device)
        #: where frames are made: "cpu" or "cuda"
        self.device = device
        spec = as_spec(config)
        if seed is not None:
            seed = _whole(seed, "seed")
            if seed != spec.seed:
                spec = spec.updated({"seed": seed})
        #: the rectangle of the sensor this instance makes, (row0, row1, col0, col1); None: the whole sensor
        self.window = None if window is None else _window(window, spec)
        if self.window is not None and device != "cpu":
            raise CmosnoiseError(f"device = {device!r} with a window: a tile's frames are made by the CPU kernel "
                                 "(the GPU makes crops of a whole sensor's exposure: Exposure.frames_on_device)")
        if fixed_pattern is None:
            footprint.check_fits(spec.config, run=False, pixels=_pixels(self.window, spec.shape))
        #: the resolved specification this sensor reads (its ``config``: the configuration, PRNU solved)
        self.spec = spec
        self.config = spec.config
        self.cache = cache
        self.timings: dict[str, float] = defaultdict(float)
        t0 = time.perf_counter()
        self._fixed = (fixed_pattern if fixed_pattern is not None
                       else draw(spec, cache, region=self.window, populations=populations,
                                 engine="cuda" if device == "cuda" else "auto"))
        self._sf_sigma: np.ndarray | None = None
        self._flat: np.ndarray | None = None
        self._statistics: dict[str, float] = {}
        self.timings["fixed_pattern"] += time.perf_counter() - t0

    def with_exposure(self, integration_time_s: float | None = None, peak_rate_e_per_s: float | None = None) -> Sensor:
        """The same sensor instance at another exposure: the fixed pattern is shared, not redrawn.

        Valid because nothing fixed-pattern depends on the exposure (docs/model.md section 1). A
        ``peak_rate_e_per_s`` is the light from here: light in lux (``light.enabled``) is switched off with it
        (an EMVA 1288 series sets its own irradiation, the same in every channel).

        Parameters
        ----------
        integration_time_s : float, optional
            The exposure time, s (default: this sensor's).
        peak_rate_e_per_s : float, optional
            The scene's white as a photo-charge rate, e-/s (default: this sensor's light).

        Returns
        -------
        Sensor
            A sensor of the same instance (seed, maps) at that exposure.
        """
        updates: dict[str, float | None] = {}
        if integration_time_s is not None:
            updates["integration_time_s"] = float(integration_time_s)
        if peak_rate_e_per_s is not None:  # light in e-/s from here (a photon rate would take precedence)
            updates["peak_rate_e_per_s"] = float(peak_rate_e_per_s)
            updates["peak_rate_photons_per_s"] = None
        exposure = build_section(ExposureSection, {**self.config.exposure.model_dump(), **updates}, "exposure")
        changed = {"exposure": exposure}
        if peak_rate_e_per_s is not None and self.config.light.enabled:  # a rate in e-/s replaces light in lux
            changed["light"] = self.config.light.model_copy(update={"enabled": False})
        spec = self.spec.with_config(self.config.model_copy(update=changed))
        other = Sensor(spec, fixed_pattern=self._fixed, cache=self.cache, device=self.device, window=self.window)
        other.timings = self.timings
        other._statistics = self._statistics  # of the fixed maps: the same at any exposure
        return other

    def map_statistic(self, name: str, compute: Callable[[], float]) -> float:
        """A statistic of this sensor's fixed maps (a map's mean, variance, mean square), computed by ``compute()``
        once and kept: the noise budget, the summary and the explorer ask for the same ones many times, and each
        is a pass over every pixel.

        Parameters
        ----------
        name : str
            Which statistic (the key it is kept under).
        compute : callable
            Computes it, with no arguments, the first time it is asked for.

        Returns
        -------
        float
            What ``compute()`` returns, bit for bit.
        """
        if name not in self._statistics:
            self._statistics[name] = float(compute())
        return self._statistics[name]

    # ------------------------------------------------------------ fixed pattern, read-only
    @property
    def fixed_pattern(self) -> FixedPattern:
        """Every fixed-pattern map of this sensor instance (None where a stage is off)."""
        return self._fixed

    @property
    def dark_rate(self) -> np.ndarray | None:
        """Dark-current map at the sensor's temperature, e-/s per pixel, (rows, cols) float32."""
        return self._fixed.dark_rate

    @property
    def dark_state(self) -> dark_current.DarkState | None:
        """The DCNU parameters (body, tail, threshold) at the sensor's temperature."""
        return self._fixed.dark_state

    @property
    def source_follower_sigma(self) -> np.ndarray:
        """Each pixel's fixed source-follower sigma, thermal and flicker together (e-), (rows, cols) float32."""
        if self._sf_sigma is None:
            thermal = self.config.source_follower.thermal_sigma_e
            # a 1/f flicker a frame shows as its level (no CDS) is drawn by its bridges, not in this normal
            flicker = None if self.spec.flicker_in_frames else self._fixed.flicker_sigma
            self._sf_sigma = cached(
                self.cache, "sf_sigma", (self.seed, self.shape, self.window, dependencies(self.spec)["flicker_sigma"],
                                         thermal, self.spec.flicker_in_frames),
                lambda: source_follower.total_sigma(thermal, flicker, self.map_shape))
        return self._sf_sigma

    @property
    def flat_response(self) -> np.ndarray:
        """Each pixel's photo-charge under a flat field, relative to the array's mean: PRNU after crosstalk, (rows, cols) float64.

        Crosstalk averages neighbouring gains, so the PRNU a user measures is
        this map's standard deviation, not ``prnu.sigma_pct`` (about 0.79
        times it with the default kernel). All ones when both stages are off.
        """
        if self._flat is None:
            g = self.photo_response(np.broadcast_to(1.0, self.map_shape))[1]  # ones, without making them
            self._flat = g / g.mean()
        return self._flat

    def flat_statistics(self) -> dict[str, float]:
        """:func:`~cmosnoise.engine.reduce.statistics` of :attr:`flat_response` (mean, variance, mean square,
        extremes), made a band of rows at a time without the whole map: what the noise budget needs of it.

        Each band's response is made from its rows and two more on each side (crosstalk reads one; two keep the
        CFA's phase), so its rows are the whole map's bit for bit; the bands' statistics are joined
        (:func:`~cmosnoise.engine.reduce.combine`) and scaled by the mean, as the map is.

        Returns
        -------
        dict of str to float
            ``mean`` (1 up to rounding), ``var``, ``mean_square``, ``min`` and ``max`` of the flat response.
        """
        rows, cols = self.map_shape
        parts = []
        step = 2 * max(8, -(-reduce.BAND_VALUES // (2 * cols)))  # even, and enough values for a parallel pass
        for r0 in range(0, rows, step):
            r1 = min(rows, r0 + step)
            a0, a1 = max(r0 - 2, 0), min(r1 + 2, rows)
            g = self.photo_response(np.broadcast_to(1.0, (a1 - a0, cols)), rows=(a0, a1))[1][r0 - a0:r1 - a0]
            parts.append((g.size, reduce.statistics(g)))
        st = reduce.combine(parts)
        m = st["mean"]
        return {"mean": 1.0, "var": st["var"] / m**2, "mean_square": st["mean_square"] / m**2,
                "min": st["min"] / m, "max": st["max"] / m}

    def photo_response(self, perfect_e: np.ndarray, rows: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Mean photo-charge of ``perfect_e`` through PRNU (stage 2) and crosstalk (stage 3), e- float64.

        The one place both stages meet a mean image (exposures and :attr:`flat_response` call it).

        Parameters
        ----------
        perfect_e : ndarray, (rows, cols)
            The photo-charge before PRNU, e-.
        rows : (int, int), optional
            ``(row0, row1)``: ``perfect_e`` holds only those rows of the map (``row0`` even), and crosstalk
            treats their first and last as edges.

        Returns
        -------
        (ndarray, ndarray)
            After PRNU and after crosstalk, each (rows, cols) float64 e-.
        """
        c = self.config
        gain = self._fixed.prnu_gain
        if gain is not None and rows is not None:
            gain = gain[rows[0]:rows[1]]
        after_prnu = perfect_e if gain is None else prnu.apply(perfect_e, gain)
        mean = after_prnu
        if c.crosstalk.enabled:
            kernel = crosstalk.kernel_fractions(c.crosstalk.kernel_pct)
            mean = crosstalk.apply(mean, kernel, c.sensor.cfa)
            if c.crosstalk.kernel_at_angle_pct is not None:  # the kernel leans outward with the chief-ray angle
                r0, r1, c0, c1 = self.region
                if rows is not None:
                    r0, r1 = r0 + rows[0], r0 + rows[1]
                leans = crosstalk.lean_kernels(kernel, crosstalk.kernel_fractions(c.crosstalk.kernel_at_angle_pct))
                moved = optics_mod.leaning_charge(after_prnu, c, self.shape, (r0, r1, c0, c1), leans)
                if moved is not None:
                    mean = np.add(mean, moved, out=moved)  # into the lean's own float64 array: no new one
        return after_prnu, mean

    @property
    def dark_cooling_fraction(self) -> float:
        """Fraction of this sensor's pixels whose dark current drops between two warmer characterization points (0 when they are ordered)."""
        c = self.config
        if not c.dark_current.enabled:
            return 0.0
        rows, cols = self.shape
        key = fixed_key(c.seed, "dark_current")

        def bands():  # the map's own variates, a row band at a time
            for r0, r1 in fixed_maps.bands((0, rows, 0, cols)):
                yield fixed_maps.variates((r0, r1, 0, cols), cols, key)

        return dark_current.cooling_fraction(list(self.spec.dark_points), bands)

    @property
    def flicker_model(self):
        """The distribution the per-pixel flicker sigma was drawn from (e- rms)."""
        return self.spec.flicker

    @property
    def seed(self) -> int:
        return self.config.seed

    @property
    def shape(self) -> tuple[int, int]:
        return self.config.shape

    @property
    def map_shape(self) -> tuple[int, int]:
        """The shape of this instance's maps and mean images: the window's, or the sensor's."""
        if self.window is None:
            return self.shape
        r0, r1, c0, c1 = self.window
        return r1 - r0, c1 - c0

    @property
    def region(self) -> tuple[int, int, int, int]:
        """The rectangle this instance makes, (row0, row1, col0, col1): the window, or the whole sensor."""
        return self.window if self.window is not None else (0, self.shape[0], 0, self.shape[1])

    @property
    def cfa(self) -> str:
        return self.config.sensor.cfa

    @property
    def transfer(self) -> adc.Transfer:
        """The ADC transfer (the ideal one, 1 DN per e-, with the ADC off)."""
        return self.spec.transfer

    @property
    def saturation_e(self) -> float:
        """Charge at saturation: the full well, or the ADC's full scale if that comes first (e-)."""
        return self.spec.saturation_e

    @property
    def white_dn(self) -> float:
        """The raw code of scene white: a scene value of 1, or the top code if that is lower."""
        return self.spec.white_dn

    def raw_info(self) -> RawInfo:
        """What the processing chain needs to know about this sensor's raw frames.

        Returns
        -------
        RawInfo
            The CFA, black and white level, K and the channels' responsivities.
        """
        c = self.config
        t = self.transfer
        return RawInfo(
            cfa=self.cfa, black_level_dn=t.black_level_dn, bits=t.output_bits, white_dn=self.white_dn,
            crosstalk_kernel_pct=c.crosstalk.kernel_pct if c.crosstalk.enabled else None,
            responsivity=self.spec.channel_responsivity,
        )

    def stages_on(self) -> dict[str, bool]:
        """Which stages of docs/model.md run in this configuration.

        Returns
        -------
        dict of str to bool
            Each stage's name and whether it runs.
        """
        c = self.config
        return {
            "prnu": c.prnu.enabled,
            "crosstalk": c.crosstalk.enabled,
            "dark_current": c.dark_current.enabled,
            "dark_shot_noise": c.dark_current.enabled and c.dark_current.shot_noise,
            "shot_noise": c.shot_noise.enabled,
            "source_follower": c.source_follower.enabled,
            "flicker": c.source_follower.enabled and c.source_follower.flicker.enabled,
            "row_noise": c.row_noise.enabled,
            "column_noise": c.column_noise.enabled,
            "adc": c.adc.enabled,
            "nonlinearity": self.spec.active_nonlinearity is not None,
            "pixel_offset": self.fixed_pattern.pixel_offset is not None,
            "black_level_offsets": self.spec.black_level_varies,
            "read_noise": c.read_noise.enabled,
            "source_follower_rts": self.fixed_pattern.traps is not None,
            "dark_current_rts": self.fixed_pattern.blinkers is not None,
            "defects": self.fixed_pattern.defects is not None,
        }

    # ------------------------------------------------------------ scene
    def scene_signal(self, scene: str | np.ndarray | None = None) -> np.ndarray:
        """The scene through the CFA, relative signal in [0, 1], (rows, cols).

        Parameters
        ----------
        scene : str or ndarray, optional
            A built-in name or path (see :mod:`cmosnoise.scene`), a linear RGB array (rows, cols, 3) or a
            CFA-sampled array (rows, cols) at the sensor's size (the window's, for a window); default: the
            configuration's scene. The scene section's window and source size place any scene but a flat (the
            same everywhere, drawn at the sensor's size).

        Returns
        -------
        ndarray, (rows, cols)
            The relative signal at each pixel, float64 in [0, 1].
        """
        c = self.config
        fp = self.spec.focal_plane
        if scene is None:
            scene = c.scene.source
        if isinstance(scene, str):
            # a flat is the same everywhere: no window of it can leave it (a windowed sensor's dark frames)
            flat = scene_mod.builtin_name(scene) == "flat" and c.scene.window is not None
            section = c.scene.model_copy(update={"window": None, "source_size": None}) if flat else c.scene
            return fp.pixel_signal(fp.prepare(scene, section), self.cfa, self.window)
        try:
            given = np.asarray(scene)
            if given.dtype.kind not in "uifb":  # complex, object, text: not light levels (a cast would drop parts)
                raise TypeError
            rgb = given.astype(np.float64)
        except (TypeError, ValueError):
            kind = f"an array of {given.dtype}" if "given" in locals() else type(scene).__name__
            raise CmosnoiseError(f"scene: expected a name, a path or an array of real numbers, got {kind}") from None
        shape = self.map_shape
        if rgb.ndim not in (2, 3) or rgb.shape[:2] != shape or (rgb.ndim == 3 and rgb.shape[2] not in (1, 3)):
            whose = "sensor's" if self.window is None else "window's"
            raise CmosnoiseError(f"scene array has shape {rgb.shape}; expected the {whose} {shape} (CFA signal), "
                                 f"{shape + (1,)} (grey) or {shape + (3,)} (linear RGB)")
        bad = ~np.isfinite(rgb)
        if bad.any() or (rgb < 0).any():
            what = f"{int(bad.sum())} NaN or infinite" if bad.any() else f"{int((rgb < 0).sum())} negative"
            raise CmosnoiseError(f"scene array has {what} values; a scene is finite light levels >= 0")
        if rgb.ndim == 2:  # a CFA signal relative to the peak rate, in the focal plane's unit
            return rgb if fp.unit_e_per_s == fp.peak_rate_e_per_s else rgb * (fp.peak_rate_e_per_s / fp.unit_e_per_s)
        if rgb.shape[2] == 1:
            rgb = np.repeat(rgb, 3, axis=2)
        rgb = scene_mod.mixed(rgb, self.spec.light)
        if fp.trivial and not optics_mod.active(c):
            return fp.through_cfa(rgb, self.cfa)
        if self.window is not None:
            raise CmosnoiseError("scene array: with a lens (optics.psf, optics.relative_illumination, optics.olpf) or "
                                 "an optical image finer than the pixels, give a sensor of the whole array the scene "
                                 "(the lens acts across the whole picture), or a CFA signal (rows, cols) already "
                                 "through it")
        return fp.pixel_signal(fp.picture(rgb), self.cfa)

    def expose(self, scene: str | np.ndarray | None = None, sequence: int = SEQ_SCENE) -> Exposure:
        """Mean charge of ``scene`` at the configured exposure and temperature.

        With a cache, a named scene's signal and the exposure's mean images come from it when their inputs are
        unchanged.

        Parameters
        ----------
        scene : str or ndarray, optional
            As :meth:`scene_signal` takes it (default: the configuration's scene).
        sequence : int
            Numbers independent frame series of the same sensor (0: the run; 1: the dark frames of a dark
            calibration).

        Returns
        -------
        Exposure
            The exposure, whose :meth:`Exposure.frame` makes its frames.
        """
        if scene is None:
            scene = self.config.scene.source
        if self.cache is None or not isinstance(scene, str):
            return Exposure(self, self.scene_signal(scene), sequence)
        c = self.config
        signal_parts: tuple = (scene, self.shape, self.window, self.cfa, list(self.spec.channel_responsivity),
                               c.scene.scale, c.scene.fit, c.scene.window, c.scene.source_size)
        if c.scene.raw_cfa is not None:
            signal_parts += (c.scene.raw_cfa, c.scene.raw_black_dn, c.scene.raw_white_dn)
        fp = self.spec.focal_plane
        if c.light.enabled or not fp.trivial or optics_mod.active(c):  # the optical image (absent: the same keys)
            signal_parts += (fp.key,)
        signal = self.cache.get("signal", signal_parts, lambda: self.scene_signal(scene))
        return Exposure(self, signal, sequence, signal_parts)

    def dark_frames(self, n: int) -> Iterator[np.ndarray]:
        """``n`` dark frames (no light) for dark calibration, from their own noise sequence.

        Parameters
        ----------
        n : int
            How many frames.

        Returns
        -------
        iterator of ndarray
            Each frame (rows, cols) uint16 DN.
        """
        n = _whole(n, "n", minimum=1)
        return self.expose("flat:0", sequence=SEQ_DARK_CALIBRATION).frames(n)

    def capture(self, scene=None, frames: int = 1, first_frame: int = 0) -> np.ndarray:
        """Raw frames ``first_frame`` to ``first_frame + frames - 1`` of ``scene``.

        Parameters
        ----------
        scene : str or ndarray, optional
            As :meth:`expose` takes it.
        frames : int
            How many frames.
        first_frame : int
            The first frame's number.

        Returns
        -------
        ndarray, (frames, rows, cols)
            uint16 DN.
        """
        frames = _whole(frames, "frames", minimum=1)
        first_frame = _whole(first_frame, "first_frame")
        shot = self.expose(scene)
        return np.stack(list(shot.frames(frames, first_frame)))


class Exposure:
    """What is fixed for one scene on one sensor: the mean charge per pixel (e-).

    Parameters
    ----------
    sensor : Sensor
    signal : ndarray, (rows, cols)
        The scene through the CFA, relative signal.
    sequence : int
        Which frame series (see :meth:`Sensor.expose`).
    signal_parts : tuple, optional
        What ``signal`` was made from, when the sensor has a cache: the
        photo mean (signal, exposure, PRNU, crosstalk) and the dark mean
        (dark map, integration time) are then kept in it as two products,
        so a change of one (a temperature, say) reuses the other.

    Examples
    --------
    >>> from cmosnoise import Sensor
    >>> shot = Sensor({"sensor": {"width": 64, "height": 48}}, seed=7).expose("flat:0.5")
    >>> frames = list(shot.frames(3))          # frames 0, 1, 2, one at a time
    >>> len(frames), frames[0].shape, shot.photo_mean_e.shape
    (3, (48, 64), (48, 64))
    """

    def __init__(self, sensor: Sensor, signal: np.ndarray, sequence: int = SEQ_SCENE, signal_parts: tuple | None = None):
        self.sensor = sensor
        self.sequence = sequence
        c = sensor.config
        timings = sensor.timings
        t0 = time.perf_counter()
        cache = sensor.cache if signal_parts is not None else None
        deps = dependencies(sensor.spec)
        ex = c.exposure

        on_mean = sensor.spec.nonlinearity_on("mean")

        def photo():
            with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below, in one line
                perfect = scene_mod.photo_electrons(signal, sensor.spec.signal_unit_e_per_s, ex.integration_time_s)
            scene_mod.check_charge(perfect, c.sensor.full_well_e)
            after_prnu, mean = sensor.photo_response(perfect)
            if on_mean is not None:  # stage 5b on the mean photo-charge: the collection saturates, the shot noise follows
                mean = on_mean.apply(mean)
            return perfect, after_prnu, mean.astype(np.float32)

        photo_parts: tuple = (signal_parts, sensor.seed, sensor.shape, sensor.window, sensor.spec.signal_unit_e_per_s, ex.integration_time_s,
                       deps["prnu_gain"], c.crosstalk, c.nonlinearity if on_mean is not None else None)
        if c.crosstalk.kernel_at_angle_pct is not None:  # the lean reads the chief-ray angle
            photo_parts += (c.optics, c.sensor.pixel_pitch_um)
        #: stage 1: mean photo-electrons of the perfect image; after PRNU (stage 2); after crosstalk (stage 3):
        #: the mean photo-charge that shot noise acts on
        self.perfect_e, self.after_prnu_e, self.photo_mean_e = cached(cache, "photo_mean", photo_parts, photo)
        #: stage 4: mean dark electrons (None with dark current off)
        self.dark_mean_e: np.ndarray | None = None
        rate = sensor.fixed_pattern.dark_rate
        if rate is not None:
            self.dark_mean_e = cached(
                cache, "dark_mean", (sensor.seed, sensor.shape, sensor.window, deps["dark_rate"], ex.integration_time_s),
                lambda: dark_current.mean_charge(rate, ex.integration_time_s))
        #: the mean photo- and dark charge a pixel collects, with the defects of stage 15 (the same arrays as
        #: photo_mean_e and dark_mean_e without them)
        self.collected_photo_e, self.collected_dark_e = self.photo_mean_e, self.dark_mean_e
        d = sensor.fixed_pattern.defects
        if d is not None and d.has_charge_effect:
            self.collected_photo_e, self.collected_dark_e = defects.collected(
                self.photo_mean_e, self.dark_mean_e, d, sensor.region, ex.integration_time_s)
        # what shot noise acts on, and what enters as its mean
        noisy: list[np.ndarray] = []
        exact: list[np.ndarray] = []
        (noisy if c.shot_noise.enabled else exact).append(self.collected_photo_e)
        if self.collected_dark_e is not None:
            (noisy if c.dark_current.shot_noise else exact).append(self.collected_dark_e)
        self._noisy_e: np.ndarray | None = noisy[0] + noisy[1] if len(noisy) == 2 else (noisy[0] if noisy else None)
        self._exact_e: np.ndarray | None = exact[0] + exact[1] if len(exact) == 2 else (exact[0] if exact else None)
        self._plan: FramePlan | None = None
        self._device_plan: cuda_kernel.DevicePlan | None = None
        timings["expose"] += time.perf_counter() - t0

    @property
    def mean_charge_e(self) -> np.ndarray:
        """Expected collected charge before the full-well clip: photo + dark (e-), with the defects."""
        if self.collected_dark_e is None:
            return self.collected_photo_e
        return self.collected_photo_e + self.collected_dark_e

    def expected_sum(self, part: tuple[slice, slice] | None = None) -> float:
        """The sum of :attr:`mean_charge_e` over ``part`` of the maps (all of them by default), e-, float64: the
        photo- and the dark charge summed apart, so the map of their sum is not made.

        Parameters
        ----------
        part : (slice, slice), optional
            Rows and columns of this exposure's maps.

        Returns
        -------
        float
            Within float32 rounding of ``mean_charge_e[part].sum(dtype=np.float64)`` (each pixel's two charges
            are added in float64 here, in float32 there; :func:`~cmosnoise.engine.reduce.total`'s sums, in
            parallel).
        """
        part = part or (slice(None), slice(None))
        total = reduce.total(self.collected_photo_e[part])
        if self.collected_dark_e is not None:
            total += reduce.total(self.collected_dark_e[part])
        return total

    @property
    def frame_period_s(self) -> float:
        """Seconds between the starts of two frames (``sensor.frame_rate_hz``, or the exposure time)."""
        c = self.sensor.config
        return random_telegraph.frame_period_s(c.sensor.frame_rate_hz, c.exposure.integration_time_s)

    # ------------------------------------------------------------ frames
    def plan(self) -> FramePlan:
        """What every frame of this exposure shares, for the engine (built once, then reused).

        Returns
        -------
        FramePlan
            The frame kernels' input (:mod:`cmosnoise.engine.frame.plan`).
        """
        if self._plan is None:
            s = self.sensor
            c = s.config
            fp = s.fixed_pattern
            keys = np.array([stream_key(c.seed, st) for st in KEY_ROWS], dtype=np.uint64)
            cols = s.map_shape[1]

            rows_on, row_sigma, row_offset, columns_on, col_offset = self.readout_lines()

            def col(a, fill):
                return np.full(cols, fill) if a is None else a.ravel().astype(np.float64)

            row_flicker, col_flicker, col_sigma = self._flicker(row_sigma, col(fp.column_sigma, 0.0))
            pixel_flicker = None
            if s.spec.flicker_in_frames and fp.flicker_sigma is not None:
                pixel_flicker = source_follower.Flicker(fp.flicker_sigma, s.spec.pixel_flicker, self.frame_period_s,
                                                        stream_key(c.seed, "source_follower_flicker"),
                                                        (s.region[0], s.region[2]), int(s.shape[1]))
            t = s.transfer
            o0, o1, o2, o3 = (float(v) for v in c.black_level.channel_offsets_dn)
            cell_offsets = (o0, o1, o2, o3)
            self._plan = FramePlan(
                shape=s.shape, keys=keys, sequence=self.sequence, full_well_e=float(c.sensor.full_well_e),
                noisy_e=self._noisy_e, exact_e=self._exact_e,
                normal_above_e=c.shot_noise.gaussian_above_e if c.shot_noise.gaussian_above_e is not None else np.inf,
                sf_sigma_e=s.source_follower_sigma if c.source_follower.enabled else None,
                row_sigma_e=(0.0 if row_flicker is not None else row_sigma) if rows_on else None,
                row_offset_e=row_offset, row_flicker=row_flicker, col_flicker=col_flicker,
                col_sigma_e=col_sigma if columns_on else None,
                col_offset_e=col_offset if columns_on else None,
                col_gain=col(fp.column_gain, 1.0) if columns_on else None,
                adc=(t.gain_dn_per_e, t.black_level_dn, 2**t.bits - 1, t.step) if c.adc.enabled else None,
                nonlinearity=s.spec.nonlinearity_on("charge"),
                offset_e=(fp.pixel_offset if fp.pixel_offset is not None or pixel_flicker is None
                          else np.zeros(s.map_shape, np.float32)),
                pixel_flicker=pixel_flicker,
                cell_offsets_dn=cell_offsets,
                frame_black_sigma_dn=float(c.black_level.frame_sigma_dn),
                read_noise=((c.read_noise.distribution, float(c.read_noise.scale_dn), float(c.read_noise.shape))
                            if c.read_noise.enabled else None),
                traps=fp.traps,
                trap_key=stream_key(c.seed, "source_follower_rts"),
                cds_interval_s=c.source_follower.rts.cds_interval_s if c.source_follower.rts.cds else None,
                blinkers=fp.blinkers, blink_key=stream_key(c.seed, "dark_current_rts"),
                frame_period_s=self.frame_period_s, exposure_s=float(c.exposure.integration_time_s),
                blink_noisy=bool(c.dark_current.shot_noise), window=s.window,
            )
        return self._plan

    def _flicker(self, row_sigma: float, col_sigma: np.ndarray):
        """(row noise's 1/f offsets or None, the columns' offsets that change from frame to frame or None, the
        column sigma the kernels draw white noise with: zero where the columns' noise is 1/f) of
        ``row_noise.spectrum``, ``column_noise.temporal.spectrum`` and ``column_noise.alternating``. The 1/f processes are addressed by the sensor's rows and columns, so
        a window's are the frame's."""
        s = self.sensor
        c = s.config
        r0, r1, c0, c1 = s.region
        period = self.frame_period_s
        row_flicker: row_noise.Flicker | None = None
        col_flicker: column_noise.Flicker | column_noise.Alternating | column_noise.Summed | None = None
        if s.spec.row_flicker is not None and row_sigma > 0:
            row_flicker = row_noise.Flicker(float(row_sigma), s.spec.row_flicker, int(s.shape[0]),
                                            period / s.shape[0], stream_key(c.seed, "row_noise_flicker"), r0, r1 - r0)
        parts: list[column_noise.Flicker | column_noise.Alternating] = []
        if s.spec.column_flicker is not None:
            parts.append(column_noise.Flicker(col_sigma, s.spec.column_flicker, period,
                                              stream_key(c.seed, "column_noise_flicker"), c0, c1 - c0))
            col_sigma = np.zeros_like(col_sigma)
        alt = c.column_noise.alternating
        if c.column_noise.enabled and alt.enabled and alt.temporal_sigma_e > 0:
            parts.append(column_noise.Alternating(float(alt.temporal_sigma_e),
                                                  stream_key(c.seed, "column_noise_alternating"), c0, c1 - c0))
        if parts:
            col_flicker = parts[0] if len(parts) == 1 else column_noise.Summed(tuple(parts))
        return row_flicker, col_flicker, col_sigma

    def readout_lines(self) -> tuple[bool, float, np.ndarray, bool, np.ndarray]:
        """The fixed row and column offsets with the offset lines of stage 15 in them; a stage off runs with
        sigma 0 when an offset line needs it. The lines are the window's (its rows and columns) on a window.

        Returns
        -------
        (bool, float, ndarray, bool, ndarray)
            Rows on, row sigma e-, row offsets (rows,) float64, columns on, column offsets (cols,) float64.
        """
        s = self.sensor
        c = s.config
        fp = s.fixed_pattern
        rows, cols = s.map_shape
        row_offset = np.zeros(rows) if fp.row_offset is None else fp.row_offset.ravel().astype(np.float64)
        col_offset = np.zeros(cols) if fp.vfpn is None else fp.vfpn.ravel().astype(np.float64)
        rows_on, columns_on = c.row_noise.enabled, c.column_noise.enabled
        if fp.defects is not None:
            r0, r1, c0, c1 = s.region
            lines_r, lines_c = defects.line_offsets(fp.defects)
            on_r, on_c = fp.defects.has_offsets
            row_offset, col_offset = row_offset + lines_r[r0:r1], col_offset + lines_c[c0:c1]
            rows_on, columns_on = rows_on or on_r, columns_on or on_c
        return rows_on, (s.spec.row_sigma_e if c.row_noise.enabled else 0.0), row_offset, columns_on, col_offset

    def _electrons(self, k: int, region: tuple[int, int, int, int], keep: dict | None) -> np.ndarray:
        """Charge at the ADC input in frame ``k`` (e-, float64) of ``region``, stage by stage: :mod:`.reference`
        (the NumPy specification the kernels are held to). Fills ``keep`` with each stage's part."""
        parts: dict | None = {} if keep is not None else None
        n = reference.electrons(self.plan(), k, region, parts)
        if keep is not None and parts is not None:
            self._contributions(n, region, parts, keep)
        return n

    def _contributions(self, n: np.ndarray, region: tuple[int, int, int, int], parts: dict, keep: dict) -> None:
        """Each stage's part of frame ``n`` (what :func:`.reference.electrons` reported in ``parts``), in e-, into
        ``keep``: the means' parts (perfect image, PRNU, crosstalk, dark current), then the temporal stages'."""
        s = self.sensor
        fp = s.fixed_pattern
        r0, r1, c0, c1 = region
        w0, _, v0, _ = s.region  # the region in this instance's arrays (a window's own)
        win = (slice(r0 - w0, r1 - w0), slice(c0 - v0, c1 - v0))
        keep["perfect"] = self.perfect_e[win]
        keep["prnu"] = self.after_prnu_e[win] - self.perfect_e[win]
        keep["crosstalk"] = self.photo_mean_e[win] - self.after_prnu_e[win]
        if self.dark_mean_e is not None:
            keep["dark_current"] = self.dark_mean_e[win]

        def sparse(at, values):  # a map of the region, zero but at ``at``
            out = np.zeros(n.shape, np.float32)
            out[at] = values
            return out

        mean = self.mean_charge_e[win]
        if "blinking" in parts:
            keep["dark_current_rts"] = sparse(*parts["blinking"])
            mean = mean + keep["dark_current_rts"]
        collected, converted = parts["collected"], parts["converted"]
        keep["shot_noise"] = (collected - mean).astype(np.float32)
        if converted is not collected:
            keep["nonlinearity"] = (converted - collected).astype(np.float32)
        if fp.pixel_offset is not None:
            keep["pixel_offset"] = fp.pixel_offset[win]
        if "source_follower" in parts:
            keep["source_follower"] = parts["source_follower"].astype(np.float32)
        if "pixel_flicker" in parts:  # a 1/f flicker level, added with the offsets: the source follower's
            keep["source_follower"] = keep.get("source_follower", np.zeros(n.shape, np.float32)) + parts["pixel_flicker"]
        if "traps" in parts:
            keep["source_follower_rts"] = sparse(*parts["traps"])
        if parts["rows_on"]:
            keep["row_noise"] = np.broadcast_to(parts["row_noise"], n.shape).astype(np.float32)
        if parts["columns_on"]:
            keep["column_noise"] = (n - parts["before_columns"]).astype(np.float32)
        if fp.defects is not None:  # stage 15: the change of the mean charge and the offset lines
            part = np.zeros(n.shape, np.float32)
            if self.collected_photo_e is not self.photo_mean_e:
                part = (self.mean_charge_e[win] - self._mean_without_defects()[win]).astype(np.float32)
            # the offset lines ran with the row and column stages: their part moves from those stages' to this
            lines_r, lines_c = (a[lo:hi] for a, (lo, hi) in zip(defects.line_offsets(fp.defects),
                                                                ((r0, r1), (c0, c1))))
            on_r, on_c = fp.defects.has_offsets
            if on_r:
                keep["row_noise"] = keep["row_noise"] - lines_r[:, None].astype(np.float32)
            if on_c:
                keep["column_noise"] = keep["column_noise"] - lines_c[None, :].astype(np.float32)
            keep["defects"] = part + (lines_r[:, None] + lines_c[None, :]).astype(np.float32)

    def _mean_without_defects(self) -> np.ndarray:
        return self.photo_mean_e if self.dark_mean_e is None else self.photo_mean_e + self.dark_mean_e

    def _region(self, region) -> tuple[int, int, int, int]:
        """``region`` validated (default: the sensor's whole window); on a window, it must lie inside it."""
        s = self.sensor
        if region is None or s.window is None:
            return region_of(region if region is not None else s.window, s.shape)
        r0, r1, c0, c1 = region_of(region, s.shape)
        w0, w1, v0, v1 = s.window
        if not (w0 <= r0 and r1 <= w1 and v0 <= c0 and c1 <= v1):
            raise CmosnoiseError(f"region = {(r0, r1, c0, c1)}: must lie inside the sensor's window {s.window}")
        return r0, r1, c0, c1

    def _render(self, k: int, keep: dict | None = None, region=None, electrons: bool = True):
        """(raw, charge at the ADC input in e- or None) of frame ``k``.

        ``raw`` is uint16 DN, or float32 e- with the ADC off (the ideal
        readout, unclipped). The fused kernel renders it where numba is
        installed and no stage detail is asked for; otherwise the stages run
        one by one on the NumPy samplers (same bits).
        """
        k = _frame_index(k)
        region = self._region(region)
        timings = self.sensor.timings
        t0 = time.perf_counter()
        if keep is None and self.sensor.device == "cuda":
            raw, e = self.frames_on_device([k], region, electrons=electrons)
            raw, e = raw.copy_to_host()[0], (e.copy_to_host()[0] if e is not None else None)
            timings["frame_kernel"] += time.perf_counter() - t0
            return raw, e
        if keep is None and kernel.ready():
            raw, e = kernel.render(self.plan(), k, region, electrons, timings)
            timings["frame_kernel"] += time.perf_counter() - t0
            return self._stick(raw, region, None), e
        e = self._electrons(k, region, keep)
        t = self.sensor.transfer
        if self.sensor.config.adc.enabled:
            black, read = reference.after_gain(self.plan(), k, region)
            raw = adc.convert(e, t, black, read)
            if keep is not None:  # in e-, beside the quantization
                if self.sensor.spec.black_level_varies:
                    keep["black_level"] = ((black - t.black_level_dn) / t.gain_dn_per_e).astype(np.float32)
                if read is not None:
                    keep["read_noise"] = (read / t.gain_dn_per_e).astype(np.float32)
        else:
            raw = e.astype(np.float32)
        timings["frame_numpy"] += time.perf_counter() - t0
        return self._stick(raw, region, keep), e.astype(np.float32)

    def stuck_pixels(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The stuck pixels and lines of stage 15 as the GPU kernel takes them, each pixel once.

        Returns
        -------
        (ndarray, ndarray) or None
            Flat pixel index (n,) int64 and value (n,) float64 (a code in DN, or e- with the ADC off); None where
            there are none.
        """
        s = self.sensor
        d = s.fixed_pattern.defects
        if d is None or not d.has_stuck:
            return None
        adc_on = s.config.adc.enabled
        return defects.stuck_pixels(d, s.transfer.max_code if adc_on else s.config.sensor.full_well_e,
                                    rounded=adc_on)

    def device_plan(self) -> cuda_kernel.DevicePlan:
        """This exposure's :meth:`plan` on the GPU, with its stuck pixels (uploaded once, then reused).

        Returns
        -------
        DevicePlan
            The plan's arrays on the device.
        """
        if self._device_plan is None:
            self._device_plan = cuda_kernel.DevicePlan(self.plan(), self.stuck_pixels())
        return self._device_plan

    def frames_on_device(self, frames, region=None, corners=None, electrons: bool = False):
        """A batch of frames made on the GPU, left there: (raw, electrons or None), device arrays (B, h, w).

        Parameters
        ----------
        frames : int or sequence of int
            Frame numbers, one per item of the batch.
        region : (row0, row1, col0, col1), optional
            The rectangle of every item (default the whole frame); with ``corners``, only its size counts.
        corners : array_like (B, 2), optional
            Each item's top-left pixel (a batch of crops of this exposure at different places).
        electrons : bool
            Also the charge at the ADC input, float32 e-.

        Returns
        -------
        (device array, device array or None)
            The raw frames (B, h, w) and, with ``electrons``, the charge. Every item equals
            ``frame(k, region=...)`` bit for bit. The arrays expose ``__cuda_array_interface__``:
            ``torch.as_tensor(raw, device="cuda")`` or ``cupy.asarray(raw)`` takes them without a copy;
            ``raw.copy_to_host()`` brings them back.
        """
        frames = [_frame_index(k) for k in np.atleast_1d(np.asarray(frames, dtype=object)).tolist()]
        r0, r1, c0, c1 = self._region(region)
        if corners is None:
            corners = np.tile([r0, c0], (len(frames), 1))
        return self.device_plan().render(frames, corners, (r1 - r0, c1 - c0), electrons)

    def _stick(self, raw: np.ndarray, region, keep: dict | None) -> np.ndarray:
        """``raw`` with its stuck pixels and lines (stage 15); ``keep`` gets what they changed, in e-."""
        d = self.sensor.fixed_pattern.defects
        if d is None or not d.has_stuck:
            return raw
        s = self.sensor
        adc_on = s.config.adc.enabled
        before = raw.copy() if keep is not None else None
        raw = defects.stick(raw, d, region, s.transfer.max_code if adc_on else s.config.sensor.full_well_e)
        if keep is not None:
            t = s.transfer
            assert before is not None
            change = t.to_electrons(raw) - t.to_electrons(before) if adc_on else raw - before
            keep["stuck"] = change.astype(np.float32)
        return raw

    def frame(self, k: int, detail: bool = False, region=None):
        """Frame ``k`` of this exposure.

        Parameters
        ----------
        k : int
            The frame's number (any frame alone is the same bits as in a run from 0).
        detail : bool
            Return a :class:`FrameDetail`: ``contributions`` holds each stage's part in e- (they sum to
            ``electrons``), plus ``quantization``: what the ADC's rounding and clipping added, in e-.
        region : (row0, row1, col0, col1), optional
            Render only that rectangle, bit-identical to the same crop of the whole frame.

        Returns
        -------
        ndarray or FrameDetail
            The raw frame (rows, cols) uint16 DN (float32 e- with the ADC off), or its detail.
        """
        keep: dict | None = {} if detail else None
        raw, electrons = self._render(k, keep, region, electrons=detail)
        if keep is None:
            return raw
        if self.sensor.config.adc.enabled:
            after = sum(keep.get(part, 0.0) for part in ("black_level", "read_noise", "stuck"))
            keep["quantization"] = (self.sensor.transfer.to_electrons(raw) - electrons - after).astype(np.float32)
        return FrameDetail(_frame_index(k), raw, electrons, keep)

    def frames(self, n: int, first: int = 0) -> Iterator[np.ndarray]:
        """Raw frames ``first`` to ``first + n - 1``, one at a time.

        Parameters
        ----------
        n : int
            How many frames.
        first : int
            The first frame's number.

        Returns
        -------
        iterator of ndarray
            Each (rows, cols) uint16 DN.
        """
        n, first = _whole(n, "n"), _frame_index(first)
        return (self.frame(k) for k in range(first, first + n))

    def frames_with_electrons(self, n: int, first: int = 0, region=None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Frames ``first`` onwards with their charge at the ADC input, one at a time.

        Parameters
        ----------
        n : int
            How many frames.
        first : int
            The first frame's number.
        region : (row0, row1, col0, col1), optional
            Only that rectangle of each.

        Returns
        -------
        iterator of (ndarray, ndarray)
            Each frame's raw (rows, cols) uint16 DN and charge, e-.
        """
        n, first = _whole(n, "n"), _frame_index(first)
        return (self._render(k, region=region) for k in range(first, first + n))


def frames_together(exposures, frames=0, electrons: bool = False):
    """One frame of each of several exposures of the same shape, made on the GPU in one launch and left there.

    The exposures are those of different sensors (each its own configuration, seed, maps and scene: the samples
    of a data set, each a crop-sized sensor); their plans are uploaded together
    (:class:`.cuda_kernel.DevicePlan` of several plans) and item ``b`` of the batch is frame ``frames[b]`` of
    ``exposures[b]``, bit for bit ``exposures[b].frame(frames[b])``.

    Parameters
    ----------
    exposures : sequence of Exposure, (B,)
        Of one shape, all with the ADC on or all with it off.
    frames : int or sequence of int, (B,)
        Each exposure's frame number (one number: the same for all).
    electrons : bool
        Also the charge at the ADC input, float32 e-.

    Returns
    -------
    raw : device array (B, rows, cols)
        uint16 DN, or float32 e- with the ADC off.
    electrons : device array (B, rows, cols) float32, or None

    Examples
    --------
    Two sensors of different seeds and presets (on a GPU; numba's CUDA simulator stands in for one in the tests):

    >>> import numpy as np
    >>> from cmosnoise import Sensor, frames_together, load_config
    >>> size = {"sensor": {"width": 32, "height": 24}}
    >>> shots = [Sensor(load_config(preset=p, extra=size), seed=s).expose("photo")
    ...          for p, s in ((None, 1), ("sony-imx900", 2))]
    >>> raw, _ = frames_together(shots, frames=[0, 7])
    >>> raw.shape
    (2, 24, 32)
    >>> bool(np.array_equal(raw.copy_to_host()[1], shots[1].frame(7)))
    True
    """
    exposures = list(exposures)
    if not exposures:
        raise ValueError("exposures: expected at least one")
    frames = np.atleast_1d(np.asarray(frames, dtype=object)).tolist()
    if len(frames) == 1:
        frames = frames * len(exposures)
    if len(frames) != len(exposures):
        raise ValueError(f"frames: {len(frames)} frame numbers for {len(exposures)} exposures")
    frames = [_frame_index(k) for k in frames]
    plan = cuda_kernel.DevicePlan([e.plan() for e in exposures], [e.stuck_pixels() for e in exposures])
    return plan.render(frames, electrons=electrons)


def as_spec(config) -> SensorSpec:
    """The resolved sensor a user means: None (defaults), a spec, a Config, a dict (merged over the defaults)
    or a YAML file's path (what :class:`Sensor` and :class:`~cmosnoise.model.tiles.Tiling` take).

    Parameters
    ----------
    config : SensorSpec, Config, dict, str, Path or None
        The sensor as a user gives it.

    Returns
    -------
    SensorSpec

    Examples
    --------
    >>> from cmosnoise.model.sensor import as_spec
    >>> as_spec({"sensor": {"width": 64, "height": 48}}).shape
    (48, 64)
    """
    if isinstance(config, SensorSpec):
        return config
    if config is None:
        return resolve(load_config())
    if isinstance(config, Config):
        return resolve(config)
    if isinstance(config, dict):
        return resolve(load_config(extra=config))
    if isinstance(config, (str, Path)):
        return resolve(load_config(Path(config)))
    raise CmosnoiseError(f"config: expected a Config, a dict or a YAML file's path, got {type(config).__name__}")


def _window(window, spec: SensorSpec) -> tuple[int, int, int, int]:
    """A sensor's window, validated: a rectangle of it with even first row and column (the CFA's phase)."""
    r0, r1, c0, c1 = region_of(window, spec.shape)
    if r0 % 2 or c0 % 2:
        raise CmosnoiseError(f"window = {(r0, r1, c0, c1)}: row0 and col0 must be even (a window keeps the CFA's "
                             "2 x 2 phase)")
    return r0, r1, c0, c1


def _pixels(window, shape: tuple[int, int]) -> int:
    """Pixels of ``window`` (or of the whole ``shape``)."""
    if window is None:
        return shape[0] * shape[1]
    return (window[1] - window[0]) * (window[3] - window[2])


def _whole(value, name: str, minimum: int = 0) -> int:
    """A whole number >= ``minimum`` (1.0 is accepted, 1.5 and True are not)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer, float, np.floating)) \
            or (isinstance(value, (float, np.floating)) and not float(value).is_integer()):
        raise CmosnoiseError(f"{name} = {value!r}: expected a whole number >= {minimum}")
    value = int(value)
    if value < minimum:
        raise CmosnoiseError(f"{name} = {value}: expected a whole number >= {minimum}")
    return value


def _frame_index(k) -> int:
    """A frame number: a whole number >= 0 (1.7 is refused, not truncated)."""
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
        if isinstance(k, (float, np.floating)) and float(k).is_integer():
            k = int(k)
        else:
            raise CmosnoiseError(f"frame = {k!r}: a frame number must be a whole number >= 0")
    if k < 0 or k > LAST_FRAME:
        raise CmosnoiseError(f"frame = {k}: a frame number must be 0 to {LAST_FRAME} (a 32-bit counter word)")
    return int(k)


def region_of(region, shape: tuple[int, int], *, clip: bool = False) -> tuple[int, int, int, int]:
    """A region ``(row0, row1, col0, col1)`` of an array of ``shape``, validated.

    ``None`` is the whole array. Bounds are half-open, as slices. With
    ``clip`` a region reaching outside is cut to the array (at least one
    pixel), as a viewer panning past an edge wants; without it, it is refused.

    Raises
    ------
    CmosnoiseError
        Not four whole numbers, or (without ``clip``) outside the array.
    """
    rows, cols = shape
    if region is None:
        return (0, rows, 0, cols)
    try:
        r0, r1, c0, c1 = (int(v) for v in region)
    except (TypeError, ValueError, OverflowError):
        raise CmosnoiseError(f"region = {region!r}: give (row0, row1, col0, col1), whole numbers") from None
    if clip:
        r0, c0 = max(0, min(r0, rows - 1)), max(0, min(c0, cols - 1))
        r1, c1 = max(r0 + 1, min(r1, rows)), max(c0 + 1, min(c1, cols))
    if not (0 <= r0 < r1 <= rows and 0 <= c0 < c1 <= cols):
        raise CmosnoiseError(
            f"region = {(r0, r1, c0, c1)}: must satisfy 0 <= row0 < row1 <= {rows} and 0 <= col0 < col1 <= {cols}"
        )
    return r0, r1, c0, c1
