"""Image quality of a configured sensor and its processing, through the test charts, at a list of illuminances.

At each illuminance three charts are exposed under the configuration's light (lux on a reflective scene, its
illuminant and lens; :mod:`cmosnoise.model.light`), each on a sensor of its own size (a chart needs a few
hundred pixels, not the whole frame), and ``frames`` frames are drawn:

- a flat 18 % grey (``flat:0.18``): the raw green SNR (e-, against the noise model's prediction,
  :mod:`.snr_light`), the output luminance's SNR, the visual luminance noise and the row and column banding's
  visibility (:mod:`.visual_noise`);
- the slanted edge (``edge``): the e-SFR of the output luminance averaged over the frames (:mod:`.sfr`);
- the ColorChecker (``colorchecker``): CIEDE2000 per patch after a least-squares colour matrix, on the raw
  mosaic's patch means (:mod:`.colour_error`; colour sensors only).

The output luminance is the processing's linear RGB (``config.processing``: black level and the mean dark signal,
as a camera's optically black pixels clamp it, demosaicing, crosstalk compensation, white balance; no dark
calibration) turned into Y with sRGB's primaries
(``0.2126 R + 0.7152 G + 0.0722 B``), scaled so that the grey's mean is 0.18 of white: what an auto-exposure
brings a grey to, so that the visual noise is judged at the output's level and not darkened away at low light.
The viewing conditions (the whole picture, ``sensor.height`` rows, ``picture_height_cm`` high, seen from
``viewing_distance_cm``) are in every result.

The metrics are one table, :data:`METRICS`: each a name, a label and unit, which way is better, the chart it
reads and a function of a :class:`Captures`. A new metric is one function and one row; ``cmosnoise quality``,
its report and ``--compare`` iterate the table.

Examples
--------
>>> from cmosnoise import load_config
>>> from cmosnoise.analysis import quality
>>> c = load_config(overrides=["light.enabled=true", "sensor.width=640", "sensor.height=480"])
>>> r = quality.measure(c, [10.0, 100.0], frames=2, sizes={"flat": (64, 64), "edge": (64, 64),
...                                                         "colorchecker": (96, 144)})
>>> [round(v, 1) for v in r["metrics"]["snr_green"]]
[6.6, 22.3]
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..config.loading import merge_updates
from ..errors import CmosnoiseError
from ..estimators import snr
from ..model import charts
from ..model.sensor import Sensor
from . import colour_error, sfr, snr_light, visual_noise

#: the charts' default sizes (rows, cols): enough pixels for each metric's estimate, few enough for speed
SIZES = {"flat": (1024, 1024), "edge": (192, 192), "colorchecker": (240, 360)}
#: the share of the flat field's side the banding reads (its middle): the more lines and the longer, the smaller the
#: noise's spread in the lines' estimate (it falls as the side to the power -3/4)
BANDING_SHARE = 0.875
#: the largest standard error of the SFR at the frequency an MTF figure reads (:attr:`.sfr.SfrResult.se`): above it
#: an MTF of 0.5 cannot be told from 0.3 or 0.7 at 2 standard errors, and the figure is not given
SFR_SE_LIMIT = 0.1
#: the grey the flat field, the SNR and the visual noise are measured on (ISO 15739 and SNR10's reference grey)
GREY = 0.18
#: sRGB's (Rec. 709) luminance weights of linear R, G, B (IEC 61966-2-1)
LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class Captures:
    """One illuminance's charts: frames and what the metrics need to read them.

    Parameters
    ----------
    lux : float
        The illuminance, lux.
    raw : dict
        Chart name -> (frames, rows, cols) raw frames (DN).
    processors : dict
        Chart name -> its :class:`~cmosnoise.isp.process.Processor` (the configuration's processing).
    luminance : dict
        Chart name -> (frames, rows, cols) output luminance, float64 (linear; the grey scaled to 0.18).
    sensors : dict
        Chart name -> its :class:`Sensor`.
    shots : dict
        Chart name -> its exposure.
    rows : int
        The whole picture's height, pixels (the viewing conditions' scale).
    picture_height_cm, viewing_distance_cm : float
        A print's viewing conditions.
    rgb : dict
        Chart name -> (frames, rows, cols, 3) output linear sRGB, scaled as ``luminance`` (the flat grey's, for the
        colour visual noise).
    display : Viewing
        A display's viewing conditions at 100 %.
    colour_reference : str
        ``spectral`` or ``xrite`` (:data:`.colour_error.REFERENCES`).
    pitch_um : float
        The pixel pitch, for line pairs per mm.
    mean_luminance : dict
        Chart name -> the frames' mean output luminance over the whole chart (the flat grey's, for the banding).

    Notes
    -----
    ``luminance["flat"]`` and ``rgb["flat"]`` hold the grey patch alone (:meth:`patch` gives where it lies in the
    chart): each frame is processed over it and a margin.
    """

    lux: float
    raw: dict
    processors: dict
    luminance: dict
    sensors: dict
    shots: dict
    rows: int
    picture_height_cm: float
    viewing_distance_cm: float
    rgb: dict = field(default_factory=dict)
    display: visual_noise.Viewing = field(default_factory=visual_noise.display_viewing)
    colour_reference: str = "spectral"
    pitch_um: float = 2.2
    mean_luminance: dict = field(default_factory=dict)
    cache: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)  #: why a metric is not measured here, one line each

    def clipped(self, chart: str, boxes) -> bool:
        """Whether a part of ``chart`` (boxes (row0, row1, col0, col1)) reaches saturation in the frames' mean:
        within 2 % of the saturation code, where the charge (or the ADC) clips and the metric would read the clip."""
        s = self.sensors[chart]
        t = s.transfer
        top = t.black_level_dn + 0.98 * s.saturation_e * t.gain_dn_per_e
        mean = self.mean_raw(chart)
        return any(float(mean[r0:r1, c0:c1].max()) >= top for r0, r1, c0, c1 in boxes)

    def mean_raw(self, chart: str) -> np.ndarray:
        """The frames' mean of ``chart`` (rows, cols) float64, DN, made once."""
        key = f"mean:{chart}"
        if key not in self.cache:
            self.cache[key] = self.raw[chart].astype(np.float64).mean(axis=0)
        return self.cache[key]

    def black_dn(self, chart: str) -> float:
        """The raw frame's black, DN: the black level and the mean dark signal, as a camera's optically black
        pixels (dark current and all) take it out (:func:`capture` clamps the processed pictures so too)."""
        return float(self.sensors[chart].transfer.black_level_dn) + _dark_clamp_dn(self.sensors[chart],
                                                                                   self.shots[chart])

    def patch(self, chart: str = "flat") -> tuple[slice, slice]:
        r0, r1, c0, c1 = charts.truth(_SOURCES[chart], self.raw[chart].shape[1:])["patches"][0]
        return slice(r0, r1), slice(c0, c1)

    def banding_patch(self) -> tuple[slice, slice]:
        """The flat field's middle :data:`BANDING_SHARE` of each side, where banding is read."""
        rows, cols = self.raw["flat"].shape[1:]
        dr, dc = int(rows * (1 - BANDING_SHARE) / 2), int(cols * (1 - BANDING_SHARE) / 2)
        return slice(dr, rows - dr), slice(dc, cols - dc)

    @property
    def print_view(self) -> visual_noise.Viewing:
        """The print's viewing conditions: the whole picture, :attr:`rows` pixels high."""
        return visual_noise.print_viewing(self.rows, self.picture_height_cm, self.viewing_distance_cm)


@dataclass(frozen=True)
class Metric:
    """One row of :data:`METRICS`.

    Parameters
    ----------
    name : str
        Its key in results.
    label, unit : str
        How tables and plots name it.
    better : {"higher", "lower"}
        Which way is better.
    chart : str
        The chart it reads: ``flat``, ``edge`` or ``colorchecker``.
    compute : callable
        ``compute(captures) -> float or None`` (None: these data cannot give it, e.g. colour on a monochrome
        sensor).
    source : str
        Where its definition was read.
    """

    name: str
    label: str
    unit: str
    better: str
    chart: str
    compute: Callable[[Captures], float | None]
    source: str


_SOURCES = {"flat": f"flat:{GREY!r}", "edge": "edge", "colorchecker": "colorchecker"}


def _grey_clipped(c: Captures) -> bool:
    """Whether the grey patch reaches saturation (said once in the notes): its noise would read the clip."""
    if "grey_clipped" not in c.cache:
        r, col = c.patch()
        c.cache["grey_clipped"] = c.clipped("flat", [(r.start, r.stop, col.start, col.stop)])
        if c.cache["grey_clipped"]:
            c.notes.append(f"noise at {c.lux:g} lux: the grey patch reaches saturation; its SNR, visual noise and "
                           "banding are not measured")
    return c.cache["grey_clipped"]


def _on_grey(compute: Callable[[Captures], float]) -> Callable[[Captures], float | None]:
    """``compute`` of the grey patch's noise, None where the patch clips (:func:`_grey_clipped`)."""
    def guarded(c: Captures) -> float | None:
        return None if _grey_clipped(c) else compute(c)
    return guarded


def _green_snr(c: Captures) -> float:
    return snr_light.measured_snr(c.sensors["flat"], c.shots["flat"], c.raw["flat"])


def _green_snr_predicted(c: Captures) -> float:
    return snr(*snr_light.predicted_snr(c.sensors["flat"], c.shots["flat"]))


def _luminance_snr(c: Captures) -> float:
    y = c.luminance["flat"]
    return snr(float(y.mean()), math.sqrt(float(y.var(axis=0, ddof=1).mean())))


def _luminance_snr_picture(c: Captures) -> float:
    y = c.luminance["flat"]
    return snr(float(y.mean()), math.sqrt(float(y.reshape(y.shape[0], -1).var(axis=1, ddof=1).mean())))


def _visual(c: Captures) -> float:
    if "visual" not in c.cache:
        y = c.luminance["flat"]
        per = [visual_noise.visual_luminance_noise(np.clip(f, 0, None), viewing=c.print_view)["sigma_l"] for f in y]
        c.cache["visual"] = float(np.mean(per))
    return c.cache["visual"]


def _visual_colour(variant: str, key: str = "value") -> Callable[[Captures], float | None]:
    """A colour visual noise (:func:`.visual_noise.visual_noise`) of the grey patch, each frame's, their mean; None
    on a monochrome sensor (no colour) and where the figure is infinite (S-CIELAB's vSNR of a noise-free patch, said
    in the notes)."""
    def compute(c: Captures) -> float | None:
        if c.sensors["flat"].cfa == "none":
            return None
        name = f"visual:{variant}"
        if name not in c.cache:
            rgb = c.rgb["flat"]
            c.cache[name] = [visual_noise.visual_noise(np.clip(f, 0, None), variant, c.print_view) for f in rgb]
        values = [r[key] for r in c.cache[name]]
        if not all(math.isfinite(v) for v in values):
            c.notes.append(f"{variant} {key} at {c.lux:g} lux: infinite (the patch has no noise)")
            return None
        return float(np.mean(values))
    return compute


def _banding(axis: str, display: bool = False) -> Callable[[Captures], float]:
    def compute(c: Captures) -> float:
        # the frames' mean: banding is the fixed pattern a still picture shows (the temporal part averages out
        # over the frames as a viewer's eye does over a video; one frame's adds the row noise of that frame)
        y = c.mean_luminance["flat"][c.banding_patch()]
        return visual_noise.banding(y, axis,
                                    viewing=c.display if display else c.print_view)["visibility"]
    return compute


def _edge_measured(c: Captures, key: str, what: str, measure: Callable[[tuple], sfr.SfrResult],
                   shape: tuple[int, int]) -> sfr.SfrResult | None:
    """An e-SFR of the edge chart, made once; None with a note where the edge clips or is too faint to read."""
    if key not in c.cache:
        region = charts.truth("edge", shape)["region"]
        c.cache[key] = None
        if c.clipped("edge", [region]):
            c.notes.append(f"{what} at {c.lux:g} lux: the edge's bright side reaches saturation; not measured")
        else:
            try:
                c.cache[key] = measure(region)
            except CmosnoiseError as e:  # an edge the noise or the light leaves without the contrast to read
                c.notes.append(f"{what} at {c.lux:g} lux: not measured ({e})")
    return c.cache[key]


def _esfr(c: Captures) -> sfr.SfrResult | None:
    y = c.luminance["edge"].mean(axis=0)
    return _edge_measured(c, "sfr", "MTF", lambda region: sfr.esfr(y, region), y.shape)


def _raw_sfr(c: Captures) -> sfr.SfrResult | None:
    """The e-SFR of the raw mosaic's green pixels (a monochrome sensor's every pixel), before demosaicing, its
    black (the black level and the mean dark signal) taken out."""
    raw = c.mean_raw("edge")
    return _edge_measured(c, "raw_sfr", "raw MTF", lambda region: sfr.raw_channel(
        raw - c.black_dn("edge"), c.sensors["edge"].cfa, region), raw.shape)


def _sfr_value(name: str, raw: bool = False, unit: str = "cy/px") -> Callable[[Captures], float | None]:
    """An e-SFR figure of the picture's luminance (or the raw green pixels'), in cycles per pixel, line pairs per
    mm (over the pixel pitch) or line widths per picture height (two a cycle, over the whole picture's rows)."""
    def compute(c: Captures) -> float | None:
        r = _raw_sfr(c) if raw else _esfr(c)
        if r is None:
            return None
        v = getattr(r, name)
        at = 0.5 if name == "mtf_nyquist" else v
        se = r.se_at(at)
        what = f"{'raw ' if raw else ''}{'MTF at Nyquist' if name == 'mtf_nyquist' else 'MTF50'} at {c.lux:g} lux"
        note = None
        if not math.isfinite(at):
            note = f"{what}: the SFR does not fall to 0.5 (the noise's floor); not measured"
        elif not se <= SFR_SE_LIMIT:
            note = (f"{what}: the edge is too noisy to read (the SFR's standard error at {at:.2f} cycles/pixel is "
                    f"{se:.2f}, over {SFR_SE_LIMIT:g}: more light or frames); not measured")
        if note is not None:
            if note not in c.notes:
                c.notes.append(note)
            return None
        if unit == "lp/mm":
            return v / (c.pitch_um * 1e-3)
        if unit == "LW/PH":
            return 2.0 * v * c.rows
        return v
    return compute


def _colour(c: Captures) -> dict | None:
    s = c.sensors["colorchecker"]
    if s.cfa == "none":
        return None
    if "colour" not in c.cache:
        raw = c.mean_raw("colorchecker")
        patches = charts.truth("colorchecker", raw.shape)["patches"]
        if c.clipped("colorchecker", patches):
            c.notes.append(f"colour error at {c.lux:g} lux: a ColorChecker patch reaches saturation; not measured")
            c.cache["colour"] = None
        else:
            cam = colour_error.mosaic_patch_means(raw, s.cfa, patches, s.transfer.black_level_dn)
            ref = colour_error.reference(c.colour_reference, s.config.light.illuminant)
            c.cache["colour"] = colour_error.colour_error(cam, ref)
    return c.cache["colour"]


def _defects_left(c: Captures) -> float:
    """The defect pixels (white pixels, couplets, clusters, dead, stuck, gain) visible in the grey's first frame
    that the processing's correction (``processing.defects``) leaves, per megapixel (scoring.defects_left)."""
    from . import ground_truth, scoring

    s, shot, proc = c.sensors["flat"], c.shots["flat"], c.processors["flat"]
    frame = c.raw["flat"][0]
    out = proc.cfa_image(frame).astype(np.float64) + s.transfer.black_level_dn
    left = scoring.defects_left(frame.astype(np.float64), out, ground_truth.expected_raw(shot),
                                ground_truth.mask(s), s.cfa)
    return sum(v["left"] for v in left.values()) / (frame.size / 1e6)


def _colour_value(key: str) -> Callable[[Captures], float | None]:
    def compute(c: Captures) -> float | None:
        r = _colour(c)
        return None if r is None else r[key]
    return compute


#: the metrics, in the order tables show them
METRICS: list[Metric] = [
    Metric("snr_green", "SNR, raw green", "", "higher", "flat", _on_grey(_green_snr),
           "mean photo-charge over the temporal noise of the green pixels (snr_light)"),
    Metric("snr_green_predicted", "SNR, raw green (model)", "", "higher", "flat", _green_snr_predicted,
           "noise_budget's temporal and after-gain variances at the patch's charge"),
    Metric("snr_luminance", "SNR, output luminance", "", "higher", "flat", _on_grey(_luminance_snr),
           "mean Y over its temporal noise after the processing and sRGB's luminance weights"),
    Metric("snr_luminance_picture", "SNR, output luminance, one picture", "", "higher", "flat",
           _on_grey(_luminance_snr_picture), "mean Y over Y's standard deviation across the patch in one frame (temporal "
           "and fixed-pattern noise, as one picture shows them), frames averaged; ISO 12232's noise-based speed "
           "reads it"),
    Metric("visual_noise_l", "visual luminance noise", "L*", "lower", "flat", _on_grey(_visual),
           "CSF-weighted sigma of L* (ISO 15739 Annex B's luminance channel, CPIQ CSF; visual_noise), print viewing"),
    Metric("visual_noise_iso15739", "visual noise, ISO 15739:2013", "", "lower", "flat",
           _on_grey(_visual_colour("iso15739_2013")),
           "sigma(L*) + 0.852 sigma(u*) + 0.323 sigma(v*) of the CSF-filtered opponent channels, as ISO 15739:2013's "
           "public re-implementations write it (visual_noise.visual_noise), print viewing"),
    Metric("visual_noise_scielab", "visual noise, S-CIELAB", "dE", "lower", "flat",
           _on_grey(_visual_colour("scielab")),
           "sqrt(var L* + var a* + var b*) of S-CIELAB (ISETCam's matrix and filters; visual_noise), print viewing"),
    Metric("vsnr_scielab", "vSNR, S-CIELAB", "", "higher", "flat", _on_grey(_visual_colour("scielab", "vsnr")),
           "ISETCam's vSNR: 1 / sqrt(var L* + var a* + var b*) of S-CIELAB, print viewing"),
    Metric("visual_noise_cpiq", "visual noise, CPIQ (Keelan)", "L*^2", "lower", "flat",
           _on_grey(_visual_colour("cpiq")),
           "100 var(L*) + 5 var(a*) + 12 cov(L*, a*) of the CSF-filtered CIELAB (Keelan et al. 2011), no JND "
           "mapping, print viewing"),
    Metric("banding_columns", "column banding, print", "JND", "lower", "flat", _on_grey(_banding("columns")),
           "the column lines' CSF-weighted sigma of L* (two halves' cross-estimate: the noise's share out) over the "
           "just-detectable 3 % noise (visual_noise.banding), print viewing"),
    Metric("banding_rows", "row banding, print", "JND", "lower", "flat", _on_grey(_banding("rows")),
           "the row lines' CSF-weighted sigma of L* over the just-detectable 3 % noise, print viewing"),
    Metric("banding_columns_display", "column banding, display", "JND", "lower", "flat",
           _on_grey(_banding("columns", display=True)),
           "as banding_columns, at 100 % on a display (visual_noise.display_viewing)"),
    Metric("banding_rows_display", "row banding, display", "JND", "lower", "flat",
           _on_grey(_banding("rows", display=True)), "as banding_rows, at 100 % on a display"),
    Metric("mtf50", "MTF50, picture", "cy/px", "higher", "edge", _sfr_value("mtf50"),
           "ISO 12233 e-SFR of the output luminance, after demosaicing (sfr)"),
    Metric("mtf50_lp_mm", "MTF50, picture", "lp/mm", "higher", "edge", _sfr_value("mtf50", unit="lp/mm"),
           "mtf50 over the pixel pitch"),
    Metric("mtf50_lw_ph", "MTF50, picture", "LW/PH", "higher", "edge", _sfr_value("mtf50", unit="LW/PH"),
           "mtf50 in line widths per picture height (2 a cycle, the whole picture's rows)"),
    Metric("mtf_nyquist", "MTF at Nyquist, picture", "", "higher", "edge", _sfr_value("mtf_nyquist"),
           "ISO 12233 e-SFR of the output luminance at 0.5 cy/px (sfr)"),
    Metric("mtf50_raw", "MTF50, raw", "cy/px", "higher", "edge", _sfr_value("mtf50", raw=True),
           "ISO 12233 e-SFR of the raw mosaic's green pixels before demosaicing (every pixel of a monochrome "
           "sensor; sfr.raw_channel)"),
    Metric("mtf50_raw_lp_mm", "MTF50, raw", "lp/mm", "higher", "edge", _sfr_value("mtf50", True, "lp/mm"),
           "mtf50_raw over the pixel pitch"),
    Metric("mtf50_raw_lw_ph", "MTF50, raw", "LW/PH", "higher", "edge", _sfr_value("mtf50", True, "LW/PH"),
           "mtf50_raw in line widths per picture height"),
    Metric("mtf_nyquist_raw", "MTF at Nyquist, raw", "", "higher", "edge", _sfr_value("mtf_nyquist", raw=True),
           "the raw green pixels' e-SFR at 0.5 cy/px of the sensor"),
    Metric("defects_left_per_mp", "defects left after correction", "per MP", "lower", "flat", _defects_left,
           "defect pixels of the truth's mask visible in a frame (6 robust sigma) that processing.defects leaves, "
           "every kind of scoring.KINDS (scoring.defects_left)"),
    Metric("colour_de2000_mean", "colour error, mean", "dE00", "lower", "colorchecker", _colour_value("mean_de2000"),
           "CIEDE2000 after a least-squares 3 x 3 matrix on the raw patch means, 24 patches, against the chart's own "
           "colours (its spectra under the light, CIE 1931 2 degree, Bradford to D65; colour_error)"),
    Metric("colour_de2000_max", "colour error, worst patch", "dE00", "lower", "colorchecker", _colour_value("max_de2000"),
           "the largest patch's CIEDE2000 (colour_error)"),
]
BY_NAME = {m.name: m for m in METRICS}


def with_light(config):
    """``config`` with its light on (the light section's own defaults, the illuminance replaced at each step, where
    it was off), and whether it was off.

    Returns
    -------
    (Config, bool)
    """
    if config.light.enabled:
        return config, False
    return merge_updates(config, {"light": {"enabled": True, "illuminance_lux": 100.0}}), True


def check_light(config) -> None:
    """Raise :class:`~cmosnoise.errors.CmosnoiseError` where ``config`` cannot be lit in lux for the charts (a
    light without a quantum efficiency or spectrum, an unreadable spectrum), before any chart is exposed.

    Parameters
    ----------
    config : Config
    """
    from ..model.focal_plane import focal_plane

    focal_plane(with_light(config)[0])


def capture(config, lux: float, frames: int, sizes: dict | None = None, seed: int = 0,
            picture_height_cm: float = visual_noise.PICTURE_HEIGHT_CM,
            viewing_distance_cm: float = visual_noise.VIEWING_DISTANCE_CM,
            charts_: tuple[str, ...] = ("flat", "edge", "colorchecker"), display: visual_noise.Viewing | None = None,
            colour_reference: str = "spectral") -> Captures:
    """The charts at one illuminance: ``frames`` frames of each, and their output luminance.

    Parameters
    ----------
    config : Config
        With ``light.enabled``.
    lux : float
        Illuminance on the scene, lux.
    frames : int
        Frames of each chart, at least 2.
    sizes : dict, optional
        Chart name -> (rows, cols); default :data:`SIZES`.
    seed : int
        The sensor instance.
    picture_height_cm, viewing_distance_cm : float
        A print's viewing conditions.
    charts_ : tuple of str
        The charts to expose (the flat grey sets the output's scale; without it the scale is the processing's).
    display : Viewing, optional
        A display's viewing conditions (default: :func:`.visual_noise.display_viewing`'s).
    colour_reference : {"spectral", "xrite"}
        What the colour error compares with (:func:`.colour_error.reference`).

    Returns
    -------
    Captures
    """
    from ..isp.process import Processor

    sizes = {**SIZES, **(sizes or {})}
    raw, lum, sensors, shots, procs, rgbs, means = {}, {}, {}, {}, {}, {}, {}
    grey_scale = None
    for chart in [c for c in ("flat", "edge", "colorchecker") if c in charts_]:
        rows, cols = sizes[chart]
        c = merge_updates(config, {"light": {"illuminance_lux": float(lux)},
                                   "sensor": {"height": int(rows), "width": int(cols)}})
        s = Sensor(c, seed=seed)
        shot = s.expose(_SOURCES[chart])
        stack = np.stack(list(shot.frames(int(frames))))
        dark = None
        if c.processing.dark_frames > 0 or c.processing.defects.method == "map":
            # a master dark of the same sensor from its own frames, as the processing's dark calibration or its
            # defect map asks (at least 8 frames for a map)
            n = max(int(c.processing.dark_frames), 8)
            dark = np.mean(np.stack(list(s.dark_frames(n))).astype(np.float64), axis=0).astype(np.float32)
        proc = Processor(c.processing, s.raw_info(), dark)
        clamp = _dark_clamp_dn(s, shot)
        # the grey: each frame processed over its patch alone (and a margin: the processing is local), the frames'
        # mean over the whole field for the banding (the processing is linear: the mean's picture is the pictures'
        # mean)
        crop = _patch_window((rows, cols), s.cfa) if chart == "flat" else None
        y, colour_frames, total = [], [], None
        for f in stack:
            cfa_img = proc.cfa_image(f) - np.float32(clamp)
            if crop is not None:
                total = cfa_img.astype(np.float64) if total is None else total + cfa_img
                (a0, a1, b0, b1), inner = crop
                cfa_img = cfa_img[a0:a1, b0:b1]
            rgb = proc.linear_rgb(cfa_img).astype(np.float64)
            if crop is not None:
                rgb = rgb[inner]
            y.append(rgb if rgb.ndim == 2 else rgb @ LUMA)
            if chart == "flat" and rgb.ndim == 3:
                colour_frames.append(rgb)
        y = np.stack(y)
        if grey_scale is None and chart == "flat":  # the grey's mean to 0.18: an auto-exposure's level, for each chart
            mean = float(y.mean())
            grey_scale = GREY / mean if mean > 0 else 1.0
        if crop is not None:
            rgb_mean = proc.linear_rgb((total / len(stack)).astype(np.float32)).astype(np.float64)
            means[chart] = (rgb_mean if rgb_mean.ndim == 2 else rgb_mean @ LUMA) * (grey_scale or 1.0)
        raw[chart], lum[chart], sensors[chart], shots[chart] = stack, y * (grey_scale or 1.0), s, shot
        if colour_frames:
            rgbs[chart] = np.stack(colour_frames) * (grey_scale or 1.0)
        procs[chart] = proc
    return Captures(float(lux), raw, procs, lum, sensors, shots, int(config.sensor.height), picture_height_cm,
                    viewing_distance_cm, rgbs, display or visual_noise.display_viewing(), colour_reference,
                    float(config.sensor.pixel_pitch_um), means)


def _dark_clamp_dn(sensor: Sensor, shot) -> float:
    """The optical-black clamp, DN: the mean dark signal goes with the black level, as a camera's optically black
    pixels (dark current and all) take it out; the dark signal's pattern and noise stay."""
    return 0.0 if shot.dark_mean_e is None else float(np.mean(shot.dark_mean_e)) * sensor.transfer.gain_dn_per_e


#: the margin a patch is processed with, pixels: more than the demosaicing's and the defect correction's reach
PATCH_MARGIN = 8


def _patch_window(shape: tuple[int, int], pattern: str) -> tuple[tuple[int, int, int, int], tuple[slice, slice]]:
    """The flat chart's grey patch with :data:`PATCH_MARGIN` around it (its corner even, so the CFA's phase is the
    frame's): the window processed, and the patch within it."""
    r0, r1, c0, c1 = charts.truth(_SOURCES["flat"], shape)["patches"][0]
    a0, b0 = max(r0 - PATCH_MARGIN, 0) // 2 * 2, max(c0 - PATCH_MARGIN, 0) // 2 * 2
    a1, b1 = min(r1 + PATCH_MARGIN, shape[0]), min(c1 + PATCH_MARGIN, shape[1])
    return (a0, a1, b0, b1), (slice(r0 - a0, r1 - a0), slice(c0 - b0, c1 - b0))


#: the illuminances one measurement takes: how many, and from what to what, lux (below 1e-3 lux no pixel of any
#: camera collects a photon in a frame; 1e6 is the light section's own bound)
MAX_LUX_POINTS, LUX_RANGE = 64, (1e-3, 1e6)


def check_lux(lux) -> list[float]:
    """Illuminances as :func:`measure` takes them: 1 to :data:`MAX_LUX_POINTS`, increasing, within
    :data:`LUX_RANGE`, or a one-line error.

    Parameters
    ----------
    lux : sequence of numbers

    Returns
    -------
    list of float
    """
    try:
        values = [float(v) for v in lux]
    except (TypeError, ValueError, OverflowError):
        raise CmosnoiseError(f"lux = {str(lux)[:80]}: give a list of illuminances (numbers), lux") from None
    if not 1 <= len(values) <= MAX_LUX_POINTS:
        raise CmosnoiseError(f"lux: {len(values)} illuminances; give 1 to {MAX_LUX_POINTS}")
    if any(not LUX_RANGE[0] <= v <= LUX_RANGE[1] for v in values) or any(b <= a for a, b in zip(values, values[1:])):
        shown = ", ".join(f"{v:g}" for v in values[:8]) + (", ..." if len(values) > 8 else "")
        raise CmosnoiseError(f"lux = {shown}: give increasing illuminances from {LUX_RANGE[0]:g} to "
                             f"{LUX_RANGE[1]:g} lux")
    return values


def measure(config, lux, frames: int = 8, sizes: dict | None = None, seed: int = 0, metrics=None,
            picture_height_cm: float = visual_noise.PICTURE_HEIGHT_CM,
            viewing_distance_cm: float = visual_noise.VIEWING_DISTANCE_CM,
            display_pixel_pitch_mm: float = visual_noise.DISPLAY_PIXEL_PITCH_MM,
            display_distance_cm: float = visual_noise.DISPLAY_DISTANCE_CM,
            colour_reference: str = "spectral") -> dict:
    """Every metric at each illuminance, SNR10 and SNR1, and the curves the plots draw.

    Parameters
    ----------
    config : Config
        The sensor and its processing; its light is switched on where it is off (``light_switched_on`` says so).
    lux : sequence of float
        Illuminances, lux, increasing.
    frames : int
        Frames of each chart at each illuminance, at least 2.
    sizes : dict, optional
        Chart name -> (rows, cols).
    seed : int
        The sensor instance.
    metrics : sequence of str, optional
        Names in :data:`METRICS` (default: all).
    picture_height_cm, viewing_distance_cm : float
        A print's viewing conditions (positive).
    display_pixel_pitch_mm, display_distance_cm : float
        A display's at 100 % (positive): the banding's second reading.
    colour_reference : {"spectral", "xrite"}
        What the colour error compares with (:func:`.colour_error.reference`).

    Returns
    -------
    dict
        ``lux``; ``metrics``: name -> list of values (None where the data cannot give one); ``snr10_lux``,
        ``snr1_lux`` (measured, interpolated; None outside the curve) and their ``_predicted``;
        ``dynamic_range`` (ISO 15739's form, :func:`.snr_light.dynamic_range`); ``noise_speed`` (ISO 12232's
        noise-based speeds of the one-picture luminance SNR, :func:`.snr_light.noise_based_speed`); the conditions
        (``f_number``, ``integration_time_s``, ``illuminant``, ``frames``, ``seed``, viewing); ``sfr`` (the curve at
        the brightest illuminance whose edge does not clip) and ``colour`` (the per-patch errors likewise), where
        measured; ``notes`` (why a metric is missing, what it assumes); ``light_switched_on``.
    """
    lux = check_lux(lux)
    if int(frames) < 2:
        raise CmosnoiseError(f"frames = {frames}: the temporal noise needs at least 2")
    visual_noise.print_viewing(int(config.sensor.height), picture_height_cm, viewing_distance_cm)  # one line if bad
    display = visual_noise.display_viewing(display_pixel_pitch_mm, display_distance_cm)
    if colour_reference not in colour_error.REFERENCES:
        raise CmosnoiseError(f"colour reference = {colour_reference!r} is not known; give one of "
                             f"{', '.join(colour_error.REFERENCES)}")
    names = [m.name for m in METRICS] if metrics is None else list(metrics)
    unknown = [n for n in names if n not in BY_NAME]
    if unknown:
        raise CmosnoiseError(f"metrics {unknown}: not known; choose from {', '.join(BY_NAME)}")
    for chart, size in (sizes or {}).items():
        if chart not in SIZES or len(size) != 2 or min(size) < 32:
            raise CmosnoiseError(f"sizes[{chart!r}] = {size}: give a chart of {', '.join(SIZES)} at least 32 x 32")
    config, switched = with_light(config)
    flat = {**SIZES, **(sizes or {})}["flat"]
    r0, r1, c0, c1 = charts.truth(_SOURCES["flat"], flat)["patches"][0]  # the patch the visual noise reads
    out = {"lux": lux, "metrics": {n: [] for n in names}, "frames": int(frames), "seed": int(seed),
           "f_number": config.optics.f_number, "integration_time_s": config.exposure.integration_time_s,
           "illuminant": config.light.illuminant, "light_switched_on": switched,
           "picture_height_cm": picture_height_cm, "viewing_distance_cm": viewing_distance_cm,
           "picture_rows": int(config.sensor.height),
           "viewing": {"print": visual_noise.print_viewing(int(config.sensor.height), picture_height_cm,
                                                           viewing_distance_cm).as_dict(),
                       "display": display.as_dict()},
           "colour_reference": {"reference": colour_reference, "illuminant": config.light.illuminant,
                                **({"observer": colour_error.OBSERVER, "adaptation": f"{colour_error.ADAPTATION} to "
                                    "D65", "chart": "ColorChecker N Ohta (reflectance spectra)"}
                                   if colour_reference == "spectral" else
                                   {"chart": "X-Rite's published sRGB values (post-2014), D65"}),
                                "fit": "3 x 3 matrix by least squares from the raw patch means to linear sRGB",
                                "difference": "CIEDE2000 in CIELAB, D65"},
           "visual_threshold_l": visual_noise.threshold_sigma_l(int(config.sensor.height),
                                                                (r1 - r0, c1 - c0),
                                                                picture_height_cm, viewing_distance_cm)}
    out["notes"] = qe_notes(config)
    edge_cap = colour_cap = None
    seen = {n: [] for n in names}  # the values as measured (an SNR without noise infinite), for the crossings
    for v in lux:
        cap = capture(config, v, frames, sizes, seed, picture_height_cm, viewing_distance_cm, display=display,
                      colour_reference=colour_reference)
        for n in names:
            val = BY_NAME[n].compute(cap)
            seen[n].append(0.0 if val is None else float(val))
            out["metrics"][n].append(None if val is None or not math.isfinite(val) else float(val))
        out["notes"] += cap.notes
        if cap.cache.get("sfr") is not None:
            edge_cap = cap  # the brightest illuminance the edge does not clip at
        if cap.cache.get("colour") is not None:
            colour_cap = cap
    if "snr_green" in out["metrics"]:
        for target in (10.0, 1.0):
            key = f"snr{target:g}_lux"
            out[key] = snr_light.crossing_lux(lux, seen["snr_green"], target)
            out[key + "_side"] = snr_light.crossing_side(lux, seen["snr_green"], target)
            out[key + "_predicted"] = snr_light.predicted_crossing_lux(config, target, flat, GREY, seed)
        out["dynamic_range"] = snr_light.dynamic_range(config, flat, GREY, seed, out["snr1_lux_predicted"])
    if "snr_luminance_picture" in out["metrics"]:
        out["noise_speed"] = snr_light.noise_based_speed(config, lux, seen["snr_luminance_picture"], GREY)
    if edge_cap is not None:
        r = edge_cap.cache["sfr"]
        keep = r.frequency <= 1.0
        out["sfr"] = {"lux": edge_cap.lux, "frequency": r.frequency[keep].tolist(), "sfr": r.sfr[keep].tolist(),
                      "se": None if r.se is None else r.se[keep].tolist(),
                      "angle_deg": r.angle_deg}
    if colour_cap is not None:
        col = colour_cap.cache["colour"]
        out["colour"] = {"lux": colour_cap.lux, "de2000": col["de2000"].tolist(),
                         "names": charts.truth("colorchecker", SIZES["colorchecker"])["names"],
                         "corrected": col["corrected"].tolist()}
    return out


def qe_notes(config) -> list[str]:
    """What a configuration's quantum efficiency does to colour and signal, one line each: a flat QE (the same at
    every wavelength for each channel, ``sensor.quantum_efficiency`` without ``light.spectral_qe``) and a one-column
    table (the same spectrum for R, G and B).

    Parameters
    ----------
    config : Config

    Returns
    -------
    list of str
    """
    from ..model import light
    from ..model.focal_plane import focal_plane

    li = config.light
    out = []
    if li.spectral_qe is None and config.sensor.quantum_efficiency is not None:
        lit, _ = with_light(config)
        camera = merge_updates(lit, {"sensor": {"quantum_efficiency": None}, "light": {"qe_peak": None}})
        flat_g = float(focal_plane(lit).white_e_per_s[1])
        peak = float(np.max(config.sensor.quantum_efficiency))
        spectra_g = float(focal_plane(camera).white_e_per_s[1]) * peak / light.DEFAULT_QE_PEAK
        out.append(f"a flat QE (sensor.quantum_efficiency at every wavelength from 380 to 780 nm, no "
                   f"light.spectral_qe): every channel sees the whole spectrum, so colours come out grey and the "
                   f"colour error measures only that; and a green pixel collects {flat_g / spectra_g:.1f} times the "
                   f"electrons of a measured camera's spectra at the same peak ({light.DEFAULT_SPECTRAL_QE}): give "
                   "light.spectral_qe for a camera's colour and signal")
    elif li.spectral_qe is not None and _one_column(li.spectral_qe):
        out.append("one QE spectrum for every colour channel (light.spectral_qe gives no R, G, B columns): the "
                   "channels see the same light, so the colour error measures only that")
    return out


def _one_column(spectral_qe) -> bool:
    """Whether inline spectral QE rows give one column (the same spectrum for R, G and B)."""
    return not isinstance(spectral_qe, str) and all(len(row) == 2 for row in spectral_qe)


#: keys a threshold search cannot vary, and why: the measurement sets them itself
NOT_SEARCHED = {"seed": "the sensor instances are the search's own (--instances)",
                "light.illuminance_lux": "the illuminance is --lux", "light.luminance_cd_m2": "the illuminance is --lux",
                "light.enabled": "the light is on in every measurement",
                "sensor.width": "each chart has its own size", "sensor.height": "each chart has its own size"}


def threshold(config, key: str, low: float, high: float, metric: str, limit: float, lux: float,
              instances: int = 5, frames: int = 4, sizes: dict | None = None, steps: int = 12) -> dict:
    """The value of one parameter at which a metric crosses a limit, per sensor instance, by bisection.

    Each instance (seed 0 to ``instances - 1``) keeps its random numbers while the parameter moves (common random
    numbers: the same seed, every other parameter the same), so its metric is a smooth function of the
    parameter and the bisection converges on that instance's own crossing; the spread of the crossings over the
    instances is the answer's uncertainty ("the largest column FPN at which banding stays below 1 JND at 10 lux:
    4.1 e-, 3.8 to 4.4 over 5 sensors").

    Parameters
    ----------
    config : Config
        The sensor (its light switched on as :func:`measure` does).
    key : str
        The parameter, dotted (e.g. ``column_noise.vfpn_sigma_e``).
    low, high : float
        The interval searched; the metric must lie on either side of ``limit`` at its ends.
    metric : str
        A name in :data:`METRICS`.
    limit : float
        The value the metric crosses.
    lux : float
        The illuminance.
    instances : int
        Sensor instances, at least 2.
    frames : int
        Frames of each chart.
    sizes : dict, optional
        Chart sizes (:func:`capture`).
    steps : int
        Bisection steps: the crossing within ``(high - low) / 2**steps``.

    Returns
    -------
    dict
        ``crossings`` (one per instance; None where the metric stays on one side over the interval), ``mean``,
        ``se`` (the standard error of the mean), ``min``, ``max``, ``below_at`` (``"low"`` or ``"high"``: the end
        where the metric is below the limit), ``points`` (each instance's evaluated (value, metric) pairs), and
        the inputs.
    """
    if metric not in BY_NAME:
        raise CmosnoiseError(f"metric {metric!r}: not known; choose from {', '.join(BY_NAME)}")
    if not math.isfinite(limit):
        raise CmosnoiseError(f"the limit {limit:g} of {metric}: give a finite number")
    if key in NOT_SEARCHED or key.split(".", 1)[0] == "scene":
        raise CmosnoiseError(f"--find {key}: {NOT_SEARCHED.get(key, 'the charts are the scene')}; give a setting of "
                             "the sensor, its lens or its processing")
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise CmosnoiseError(f"the interval {low:g} to {high:g} of {key}: give low < high")
    if instances < 2:
        raise CmosnoiseError(f"instances = {instances}: a threshold's spread needs at least 2 sensor instances")
    if not lux > 0:
        raise CmosnoiseError(f"lux = {lux:g}: give an illuminance above 0")
    from ..config.loading import apply_values, config_values, default_data, validate_data

    config, _ = with_light(config)
    data, defaults = config_values(config), default_data()

    def value(x: float, seed: int) -> float:
        # the dotted key as --set and --vary take it (a number in it indexes a list)
        c = apply_values(data, {key: x}, defaults, where="--find")
        try:
            c = validate_data(c)
        except CmosnoiseError as exc:
            raise CmosnoiseError(f"{key} = {x:g}: {exc}") from None
        v = BY_NAME[metric].compute(capture(c, lux, frames, sizes, seed, charts_=(BY_NAME[metric].chart,)))
        if v is None or not math.isfinite(v):
            raise CmosnoiseError(f"{metric} cannot be measured at {key} = {x:g} and {lux:g} lux")
        return float(v)

    crossings, points, below = [], [], set()
    for s in range(int(instances)):
        a, b = float(low), float(high)
        fa, fb = value(a, s), value(b, s)
        pts = [(a, fa), (b, fb)]
        if (fa - limit) * (fb - limit) > 0:
            crossings.append(None)
            points.append(pts)
            continue
        below.add("low" if fa < limit else "high")
        for _ in range(int(steps)):
            m = 0.5 * (a + b)
            fm = value(m, s)
            pts.append((m, fm))
            if (fm - limit) * (fa - limit) > 0:
                a, fa = m, fm
            else:
                b, fb = m, fm
        crossings.append(a + (b - a) * (limit - fa) / (fb - fa) if fb != fa else 0.5 * (a + b))
        points.append(sorted(pts))
    found = [x for x in crossings if x is not None]
    out = {"key": key, "low": low, "high": high, "metric": metric, "limit": limit, "lux": lux,
           "instances": int(instances), "frames": int(frames), "crossings": crossings, "points": points,
           "below_at": below.pop() if len(below) == 1 else None}
    if len(found) >= 2:
        out.update(mean=float(np.mean(found)), se=float(np.std(found, ddof=1) / math.sqrt(len(found))),
                   min=float(min(found)), max=float(max(found)))
    else:
        out.update(mean=found[0] if found else None, se=None, min=min(found, default=None),
                   max=max(found, default=None))
    return out

