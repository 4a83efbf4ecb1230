"""The configuration schema: one pydantic section per stage of docs/model.md.

A configuration is YAML (or a dict) with one section per stage, each with an
``enabled`` switch, plus the run settings (``seed``, ``scene``, ``run``).
Every key has a type, a unit in its description and a physical range; an
unknown key is an error. The schema holds no physics: what the values imply
(reachable ppm, valid distributions) is checked by :mod:`cmosnoise.model.physics`.
"""

from __future__ import annotations

import functools
import json
import math
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

#: the longest exposure a configuration takes, s (an hour)
MAX_EXPOSURE_S = 3600.0


def frozen(value):
    """A configuration value as a hashable, comparable nested tuple: sections as their (key, value) pairs in
    field order, lists as tuples, mappings by sorted key. Equal values give equal keys (a cache's key without a
    JSON string)."""
    if isinstance(value, BaseModel):
        return tuple((name, frozen(getattr(value, name))) for name in type(value).model_fields)
    if isinstance(value, dict):
        return tuple(sorted((str(k), frozen(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(frozen(v) for v in value)
    return value


class Section(BaseModel):
    """Base of every section: unknown keys are errors, values are re-validated on assignment, inf and NaN refused."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)

    def key(self) -> tuple:
        """This section's values as a hashable nested tuple (:func:`frozen`): what a cache keys on."""
        return frozen(self)

    @field_validator("*", mode="before")
    @classmethod
    def _no_booleans_for_numbers(cls, value, info):
        """``seed: true`` is a mistake, not 1: a boolean is refused where a number is expected."""
        if not isinstance(value, bool):  # first: every field of every section passes here (42 a Sensor)
            return value
        field = cls.model_fields.get(info.field_name)
        numeric = (int, float, int | None, float | None)
        if field is not None and field.annotation in numeric:
            raise ValueError(f"expected a number, got {str(value).lower()}")
        return value


# --------------------------------------------------------------------------- run
class SceneSection(Section):
    """What the sensor looks at (stage 1, the perfect image).

    ``source`` is a built-in (``photo``, ``flat:LEVEL``, ``ramp``,
    ``colorchecker``, ``zoneplate``, ``siemens``, ``edge``, ``greys``), a path to an image, or a raw photograph
    (a camera raw, or a ``.npy`` mosaic with ``raw_cfa``).
    """

    source: str = Field("photo", description="photo, flat:LEVEL (0..1), ramp, colorchecker, zoneplate, siemens, or an image path")
    scale: float | None = Field(
        None, ge=1e-9, le=1e12, description="linear files (16-bit, float, .npy): value that maps to 1.0; null: the file's own maximum"
    )
    fit: Literal["crop", "stretch"] = Field(
        "crop", description="aspect mismatch: crop the scene's centre to the sensor's aspect, or stretch it"
    )
    window: tuple[int, int] | None = Field(
        None, description="(row, col): take the sensor's size of the source at this corner, at the source's own "
                          "resolution (no resampling); null: the whole source fitted to the sensor")
    source_size: tuple[int, int] | None = Field(
        None, description="(rows, cols) a built-in scene (the photo included) is drawn at before the window is "
                          "taken; null: the sensor's")
    raw_cfa: Literal["RGGB", "BGGR", "GRBG", "GBRG"] | None = Field(
        None, description="a 2-D .npy scene is a raw photograph's mosaic with this pattern at (0, 0) (a camera raw "
                          "file carries its own); null: a .npy is linear RGB or grey")
    raw_black_dn: float = Field(0.0, ge=0, le=1e6, description="a .npy mosaic's black level, DN")
    raw_white_dn: float | None = Field(None, gt=0, le=1e9, description="a .npy mosaic's white level, DN; null: "
                                                                          "its largest code")

    @field_validator("window", "source_size")
    @classmethod
    def _non_negative(cls, v, info):
        if v is not None and (min(v) < 0 or max(v) > 10**6 or (info.field_name == "source_size" and min(v) < 1)):
            raise ValueError(f"{info.field_name} = {list(v)}: give two whole numbers, "
                             f"{'1' if info.field_name == 'source_size' else '0'} to 1000000")
        return v


#: the last frame number: the frame is one 32-bit word of the random numbers' counter (docs/model.md section 1)
LAST_FRAME = 2**32 - 1


class RunSection(Section):
    frames: int = Field(1, ge=1, le=1_000_000, description="number of frames to produce")
    first_frame: int = Field(0, ge=0, le=LAST_FRAME,
                             description="index of the first frame (frame k's temporal noise depends only on seed and k)")
    dng: bool = Field(False, description="also write every raw frame as a DNG (dng/frame_NNNNNN.dng)")
    report: bool = Field(False, description="also write report.html, a self-contained run report")

    @model_validator(mode="after")
    def _frames_fit_the_counter(self):
        if self.first_frame + self.frames - 1 > LAST_FRAME:
            raise ValueError(f"frames {self.first_frame} to {self.first_frame + self.frames - 1}: frame numbers go up to "
                             f"{LAST_FRAME} (the random numbers' frame counter is a 32-bit word)")
        return self


class DefectsSection(Section):
    method: Literal["off", "median", "map"] = Field(
        "off", description="off; median: replace pixels outside their same-colour neighbours' range; map: defect map from the master dark"
    )
    threshold_sigma: float = Field(6.0, gt=0, le=1000, description="detection threshold, in robust standard deviations")
    corrector: str | None = Field(
        None, description="module:function: your own corrector (raw DN in, raw DN out, black included; f(raw) or "
                          "f(raw, meta) with meta's cfa, black_level_dn, white_level_dn), run after method, as "
                          "evaluate --method takes it"
    )

    @field_validator("corrector")
    @classmethod
    def _corrector(cls, v):
        if v is not None and (not v.partition(":")[0].strip() or not v.partition(":")[2].strip()):
            raise ValueError(f"{v!r}: expected module:function, e.g. mypkg.fix:correct")
        return v


class WhiteBalanceSection(Section):
    mode: Literal["sensor", "gains", "grey_world", "none"] = Field(
        "sensor", description="sensor: undo the channel responsivities; gains: the given gains; grey_world: make the mean grey"
    )
    gains: tuple[float, float, float] | None = Field(None, description="R, G, B gains for mode 'gains'")

    @model_validator(mode="after")
    def _gains(self):
        if self.mode == "gains" and self.gains is None:
            raise ValueError("white_balance.mode 'gains' needs gains: [r, g, b]")
        if self.gains is not None and any(g <= 0 or not math.isfinite(g) for g in self.gains):
            raise ValueError(f"white_balance.gains must be finite and > 0, got {list(self.gains)}")
        return self


class ProcessingSection(Section):
    """From raw to picture (docs/model.md section 5): each step switchable."""

    enabled: bool = Field(False, description="write processed.png (and processed.mp4 for several frames)")
    dark_frames: int = Field(0, ge=0, le=100000, description="dark calibration: master dark from this many dark frames (0: off)")
    defects: DefectsSection = Field(default_factory=DefectsSection)
    crosstalk_compensation: bool = Field(True, description="undo crosstalk's colour mixing with the inverse 3 x 3 matrix")
    white_balance: WhiteBalanceSection = Field(default_factory=WhiteBalanceSection)
    demosaic: Literal["bilinear", "malvar2004", "menon2007"] = Field("bilinear", description="demosaicing method")
    white_dn: float | None = Field(None, gt=0, le=1e6, description="raw code shown as white; null: the scene's white (simulation) or the white level (files)")
    video_fps: float | None = Field(None, gt=0, le=240, description="frame rate of processed.mp4, frames/s; "
                                       "null: the sensor's own (1 / its frame period), within 1 to 240")
    video_stretch: bool = Field(True, description="processed.mp4 brightened for display where the scene is dark "
                                "(frame 0's 99.5th percentile below mid-grey lifted to 235, at most 16 times; the "
                                "same gain for every frame, said in summary.json and the video's metadata)")


# ------------------------------------------------------------------------ sensor
class SensorSection(Section):
    width: int = Field(640, ge=2, le=30000, description="columns, pixels")
    height: int = Field(480, ge=2, le=30000, description="rows, pixels")
    cfa: Literal["RGGB", "BGGR", "GRBG", "GBRG", "none"] = Field("RGGB", description="Bayer pattern of the top-left 2 x 2 pixels, or none (monochrome)")
    channel_responsivity: tuple[float, float, float] = Field(
        (1.0, 1.0, 1.0), description="relative R, G, B responsivity of the colour filters"
    )
    full_well_e: float = Field(10000.0, ge=1, le=1e7, description="full-well capacity, e-")
    temperature_c: float = Field(25.0, ge=-60, le=150, description="operating temperature, degrees C")
    pixel_pitch_um: float = Field(2.2, gt=0, le=100, description="pixel pitch, um")
    iso: float | None = Field(None, gt=0, le=1e7, description="gain setting as ISO: selects the row of gain_table "
                                                                 "with this iso")
    gain_db: float | None = Field(None, ge=-60, le=120, description="gain setting in dB: selects the row of "
                                                                       "gain_table with this gain_db")
    binning: Literal["1x1", "2x2", "1x2", "2x1"] = Field(
        "1x1", description="the camera's binning mode (rows x columns of native pixels read as one): selects the "
                           "gain_table rows of this binning, with their own K, noise, bias, dark signal and pitch; "
                           "sensor.width and height are the frame's, in binned pixels")
    frame_rate_hz: float | None = Field(None, gt=0, le=1e6, description="frames per second: frame k starts k / "
                                           "frame_rate_hz seconds after frame 0 (random telegraph noise reads it); null: "
                                           "frames back to back, 1 / exposure.integration_time_s")
    quantum_efficiency: float | tuple[float, float, float] | None = Field(
        None, description="quantum efficiency (0, 1], one number or R, G, B: photo-electrons per photon. Light given "
                          "in photons (exposure.peak_rate_photons_per_s) needs it; with light in e-/s it says how many "
                          "photons that was (characterize's eta). null: light in e-/s, no photons")

    @field_validator("quantum_efficiency")
    @classmethod
    def _qe(cls, v):
        values = [v] if isinstance(v, (int, float)) else list(v or [])
        if any(not 0 < x <= 1 for x in values):
            raise ValueError("each must be in (0, 1] (electrons per photon)")
        return v

    def qe_mean(self) -> float | None:
        """The quantum efficiency, one number (the channels' mean), or None."""
        q = self.quantum_efficiency
        if q is None:
            return None
        return float(q) if isinstance(q, (int, float)) else float(sum(q) / 3)

    @field_validator("cfa", mode="before")
    @classmethod
    def _cfa_any_case(cls, v):
        return ("none" if v.lower() == "none" else v.upper()) if isinstance(v, str) else v

    @field_validator("channel_responsivity")
    @classmethod
    def _non_negative(cls, v):
        if any(x < 0 or x > 100 or not math.isfinite(x) for x in v):
            raise ValueError("each relative responsivity must be a number from 0 to 100")
        return v


class ExposureSection(Section):
    integration_time_s: float = Field(0.03, gt=0, le=MAX_EXPOSURE_S, description="integration (exposure) time, s")
    peak_rate_e_per_s: float = Field(
        100000.0, ge=0, le=1e10, description="photo-electron rate of a scene value of 1.0, e-/s per pixel"
    )
    peak_rate_photons_per_s: float | None = Field(
        None, ge=0, le=1e12, description="light as photons: photons per second per pixel at a scene value of 1.0 "
                                         "(times sensor.quantum_efficiency: e-/s); null: peak_rate_e_per_s")


# ------------------------------------------------------------------------- light
#: a table given inline: rows of (wavelength nm, value) or (wavelength nm, R, G, B), (mm, degrees), ...
SpectrumRows = list[list[float]]


def _check_rows(v, widths: tuple[int, ...], what: str):
    """Inline table rows: at least two, all of one of ``widths``; a file's name or None passes (read later)."""
    if isinstance(v, list):
        found = {len(r) for r in v}
        if len(v) < 2 or len(found) != 1 or found.pop() not in widths:
            raise ValueError(f"give at least two rows, each {what}")
    return v


class LightSection(Section):
    """Light in physical units (docs/model.md section 2b): an illuminant of a stated illuminance on a reflective
    scene, through the lens of ``optics``, onto pixels of a spectral quantum efficiency. Off: the light is
    ``exposure.peak_rate_e_per_s`` (or ``peak_rate_photons_per_s``), as before."""

    enabled: bool = Field(False, description="light in lux through a lens (this section and optics); off: "
                                             "exposure.peak_rate_e_per_s")
    illuminance_lux: float | None = Field(
        None, ge=0, le=1e6, description="illuminance on the scene, lux; scene values are reflectances (1: a white "
                                        "diffuser, 0.18: the reference grey)")
    luminance_cd_m2: float | None = Field(
        None, ge=0, le=1e9, description="luminance of a scene value of 1, cd/m2 (instead of illuminance_lux; a "
                                        "Lambertian white under E lux has E / pi)")
    illuminant: str = Field("D65", description="CIE D50, D55, D65, D75, A, FL1..FL12, LED-B1..LED-V2 (colour-science's "
                                               "names), blackbody:KELVIN, or a CSV file (wavelength nm, relative power)")
    spectral_qe: str | SpectrumRows | None = Field(
        None, description="the pixels' quantum efficiency against wavelength (colour filter, photodiode, microlens): "
                          "a CSV file or inline rows of (nm, QE) or (nm, QE_R, QE_G, QE_B), or a camera set that "
                          "colour-science ships ('Nikon 5100 (NPL)', 'Sigma SDMerill (NPL)': relative, give qe_peak); "
                          "null: sensor.quantum_efficiency at every wavelength from 380 to 780 nm (a flat QE), or "
                          "without it a measured colour camera's: the Nikon D5100's spectra (NPL) at a peak of 0.65")
    qe_peak: float | None = Field(None, gt=0, le=1, description="scale the spectral QE so its highest value is "
                                                                  "this (a relative table made absolute); null: as given")
    ir_cut_nm: float | None = Field(None, ge=300, le=1200, description="an ideal IR-cut filter: no light beyond "
                                                                           "this wavelength, nm; null: none")
    fill_factor: float = Field(1.0, gt=0, le=1, description="the share of the pixel's area that collects light, "
                                                            "where the QE does not include it (a measured QE does)")

    @field_validator("illuminant")
    @classmethod
    def _illuminant_text(cls, v):
        if not v.strip():
            raise ValueError("name an illuminant (D65, A, blackbody:3200, ...) or a CSV file")
        return v.strip()

    @field_validator("spectral_qe")
    @classmethod
    def _rows(cls, v):
        return _check_rows(v, (2, 4), "(nm, QE) or (nm, QE_R, QE_G, QE_B)")

    @model_validator(mode="after")
    def _light_once(self):
        if self.illuminance_lux is not None and self.luminance_cd_m2 is not None:
            raise ValueError("give the light once: light.illuminance_lux or light.luminance_cd_m2")
        if self.enabled and self.illuminance_lux is None and self.luminance_cd_m2 is None:
            raise ValueError("light.enabled needs light.illuminance_lux (lux on the scene) or light.luminance_cd_m2")
        return self


class OpticsSection(Section):
    """The lens between the scene and the pixels (docs/model.md section 2b): the camera equation's numbers, the
    relative illumination across the field and the point spread function. With ``relative_illumination`` and
    ``psf`` at ``none`` the picture is the scene's, pixel for pixel (the lens numbers act only with light on)."""

    f_number: float = Field(2.8, ge=0.5, le=1000, description="the lens's f-number N")
    transmittance: float = Field(0.9, gt=0, le=1, description="the lens's transmittance T (ISO 12232's default 0.9)")
    magnification: float = Field(0.0, ge=0, le=100, description="the image's magnification |m| (0: a distant scene)")
    focal_length_mm: float = Field(4.0, gt=0, le=10000, description="focal length, mm: the field angle of each "
                                                                    "pixel (tan = image height / focal length)")
    camera_equation: Literal["iso12232", "non_paraxial"] = Field(
        "iso12232", description="iso12232: E = pi L T / (4 N^2 (1 + m)^2), an aplanatic lens; non_paraxial: "
                                "pi L T / (1 + 4 N^2 (1 + m)^2), ISETCam's")
    relative_illumination: str = Field(
        "none", description="none; cos4: cos^4 of the field angle; or a CSV file of (image height mm, relative "
                            "illumination) from the optical centre outwards")
    psf: str = Field("none", description="none; diffraction: the polychromatic Airy pattern of each channel at "
                                         "f_number; gaussian: psf_sigma_px; or a .npy/.fits file of one 2-D PSF at "
                                         "the pixel pitch (or psf_sampling_um)")
    chief_ray_angle: str | SpectrumRows | None = Field(
        None, description="the chief ray's angle of incidence against image height: a CSV file or inline rows of "
                          "(image height mm, degrees) from the optical centre outwards; null: 0 everywhere "
                          "(an image-space telecentric lens)")
    microlens_compensation: float = Field(0.0, ge=0, le=1, description="the share of the chief-ray angle the "
                                                                       "microlenses' shift takes back (0: none, 1: all)")
    angle_relative_qe: str | SpectrumRows | None = Field(
        None, description="the pixels' QE against the angle of incidence left after the microlenses, relative to "
                          "normal incidence: rows of (degrees, QE) or (degrees, QE_R, QE_G, QE_B), or a CSV; null: "
                          "no loss with angle")
    psf_sigma_px: float = Field(0.5, gt=0, le=100, description="sigma of the gaussian PSF, pixels")
    psf_sampling_um: float | None = Field(None, gt=0, le=100, description="a PSF file's sample spacing, um (the "
                                                                              "fine grid's pitch, pitch / oversample, "
                                                                              "must be a whole number of them); null: "
                                                                              "the pixel pitch")
    oversample: int | Literal["auto"] = Field(
        "auto", description="the optical image's fine cells per pixel along each axis, 1 to 4: the PSF, the "
                            "optical low-pass filter and the pixel's aperture act on that grid, and detail finer "
                            "than a pixel aliases as a camera shows it; auto: the smallest at which the PSF is "
                            "sampled at Nyquist (its folded transfer at most 0.01), 1 without a PSF")
    olpf: float | None = Field(None, gt=0, le=100, description="an optical low-pass filter: a birefringent "
                                                                 "four-spot filter, its spots this many um apart "
                                                                 "along the rows and the columns (MTF |cos(pi d f)|); "
                                                                 "null: none")

    @field_validator("oversample", mode="before")
    @classmethod
    def _oversample(cls, v):
        if isinstance(v, str) and v.strip().lower() == "auto":
            return "auto"
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            raise ValueError(f"give auto or a whole number from 1 to 4, not {v!r}")
        try:
            n = float(v)
        except ValueError:
            raise ValueError(f"give auto or a whole number from 1 to 4, not {v!r}") from None
        if not (math.isfinite(n) and n == int(n) and 1 <= n <= 4):
            raise ValueError(f"{v!r} is not allowed: give auto or a whole number of fine cells per pixel from 1 to 4")
        return int(n)

    @field_validator("relative_illumination", "psf")
    @classmethod
    def _named(cls, v):
        return v.strip()

    @field_validator("chief_ray_angle", "angle_relative_qe")
    @classmethod
    def _table_rows(cls, v, info):
        if info.field_name == "chief_ray_angle":
            return _check_rows(v, (2,), "(mm, degrees)")
        return _check_rows(v, (2, 4), "(degrees, QE) or (degrees, R, G, B)")


# ------------------------------------------------------------------------ stages
class PrnuSection(Section):
    enabled: bool = True
    sigma_pct: float = Field(1.0, ge=0, le=100, description="PRNU, % of the signal: the std of the gain map, before crosstalk")
    measured_pct: float | None = Field(
        None, ge=0, le=100,
        description="PRNU as a data sheet or an EMVA 1288 measurement gives it (after crosstalk), %; "
                    "when set, sigma_pct is solved from it (crosstalk averages neighbouring gains: about 0.79 with the default kernel)",
    )


Kernel = list[list[float]]


def _check_kernel(k: Kernel, name: str) -> Kernel:
    if len(k) != 3 or any(len(row) != 3 for row in k):
        raise ValueError(f"{name} must be 3 x 3")
    flat = [float(x) for row in k for x in row]
    if any(x < 0 or not math.isfinite(x) for x in flat):
        raise ValueError(f"{name} entries must be finite and >= 0 (percent)")
    total = sum(flat)
    if flat[4] <= 0:
        raise ValueError(f"{name}'s centre is {flat[4]:g} %: a pixel must keep some of its own charge (> 0 %), "
                         "else the colour mixing cannot be undone")
    if total > 100.0 + 1e-9:
        raise ValueError(f"{name} sums to {total:g} %; it must sum to at most 100 % (charge is not created)")
    return [[float(x) for x in row] for row in k]


class CrosstalkSection(Section):
    """Diffusion crosstalk (stage 3): percent of a pixel's photo-charge landing in each neighbour.

    ``kernel_pct`` is one 3 x 3 kernel, or ``{R: k, G: k, B: k}`` for a kernel per
    CFA colour (the colour of the pixel where the charge was generated).
    """

    enabled: bool = True
    kernel_pct: Kernel | dict[Literal["R", "G", "B"], Kernel] = Field(
        default_factory=lambda: [[0.9, 4.5, 0.9], [4.5, 78.4, 4.5], [0.9, 4.5, 0.9]],
        description="3 x 3 kernel, % of a pixel's photo-charge landing in itself and each neighbour (sum <= 100), "
                    "or one kernel per colour {R: ..., G: ..., B: ...}",
    )

    kernel_at_angle_pct: Kernel | None = Field(
        None, description="3 x 3 kernel, %, for light arriving at reference_angle_deg from the left (a pixel right of "
                          "the optical centre): the charge leans outward; between 0 and that angle the kernel is "
                          "interpolated (optics.chief_ray_angle sets each pixel's angle). Same sum as kernel_pct. "
                          "null: one kernel at every angle")
    reference_angle_deg: float = Field(20.0, gt=0, le=60, description="the angle of incidence kernel_at_angle_pct is "
                                                                      "given at, degrees")

    @field_validator("kernel_at_angle_pct")
    @classmethod
    def _angle_kernel(cls, v):
        return None if v is None else _check_kernel(v, "kernel_at_angle_pct")

    @model_validator(mode="after")
    def _lean_keeps_the_charge(self):
        k1 = self.kernel_at_angle_pct
        if k1 is None:
            return self
        if isinstance(self.kernel_pct, dict):
            raise ValueError("crosstalk.kernel_at_angle_pct leans one kernel: give kernel_pct as one 3 x 3 kernel")
        a, b = sum(map(sum, self.kernel_pct)), sum(map(sum, k1))
        if abs(a - b) > 1e-9 * max(a, 1):
            raise ValueError(f"crosstalk.kernel_at_angle_pct sums to {b:g} %, kernel_pct to {a:g} %: leaning moves "
                             "charge, it neither makes nor loses it; give the same sum")
        return self

    @field_validator("kernel_pct")
    @classmethod
    def _kernel(cls, v):
        if isinstance(v, dict):
            missing = {"R", "G", "B"} - set(v)
            if missing:
                raise ValueError(f"a per-colour kernel needs R, G and B; missing {sorted(missing)}")
            return {c: _check_kernel(k, f"kernel for {c}") for c, k in v.items()}
        return _check_kernel(v, "kernel")


class ShotNoiseSection(Section):
    enabled: bool = Field(True, description="photon shot noise (Poisson); off: the photo-charge enters as its mean")
    gaussian_above_e: float | None = Field(
        None, ge=100,
        description="speed option: rounded normal approximation where the mean exceeds this many e- (paper: 1000); "
                    "null: exact Poisson. At least 100 e-: below that the approximation is biased (at 2 e-, var/mean 0.93, "
                    "mean +0.04 e-); at 100 e- its skewness error is 0.1",
    )


# ------------------------------------------------------- random telegraph noise
class DwellTimes(Section):
    """A mean dwell time's law across traps or pixels: log-uniform from ``min_s`` to ``max_s`` (equal: one value)."""

    min_s: float = Field(gt=0, le=1e6, description="shortest mean dwell time, s")
    max_s: float = Field(gt=0, le=1e6, description="longest mean dwell time, s")

    @model_validator(mode="after")
    def _ordered(self):
        if self.max_s < self.min_s:
            raise ValueError(f"max_s = {self.max_s:g} is below min_s = {self.min_s:g}; give min_s <= max_s")
        return self


class SpreadLaw(Section):
    """A positive quantity's law across traps or pixels: lognormal (``median`` and ``sigma_log``, the standard
    deviation of its natural log) or exponential (``mean``)."""

    distribution: Literal["lognormal", "exponential"] = Field("lognormal", description="family across traps or pixels")
    median: float | None = Field(None, gt=0, le=1e9, description="lognormal: the median")
    sigma_log: float | None = Field(None, ge=0, le=5, description="lognormal: standard deviation of the natural log")
    mean: float | None = Field(None, gt=0, le=1e9, description="exponential: the mean")

    @model_validator(mode="after")
    def _complete(self):
        if self.distribution == "lognormal":
            if self.median is None or self.sigma_log is None or self.mean is not None:
                raise ValueError("a lognormal law takes median and sigma_log (and no mean)")
        elif self.mean is None or self.median is not None or self.sigma_log is not None:
            raise ValueError("an exponential law takes mean (and no median or sigma_log)")
        return self


class SourceFollowerRtsSection(Section):
    """Random telegraph noise of the source follower in time (stage 6b, docs/model.md): traps that switch between
    two states, seen through correlated double sampling."""

    enabled: bool = False
    ppm: float = Field(1000.0, ge=0, lt=1e6, description="parts per million of pixels with one or more traps")
    traps_per_pixel: Literal["one", "poisson"] = Field(
        "one", description="one: each affected pixel has one trap; poisson: a pixel's trap count is Poisson, its mean "
                           "such that ppm of pixels have at least one (at most 4 a pixel)")
    amplitude_e: SpreadLaw = Field(default_factory=lambda: SpreadLaw(median=4.0, sigma_log=0.6),
                                   description="a trap's amplitude across traps, e- at the source follower's input")
    tau_capture_s: DwellTimes = Field(default_factory=lambda: DwellTimes(min_s=1e-6, max_s=1.0),
                                      description="mean time a trap stays empty, log-uniform across traps, s")
    tau_emission_s: DwellTimes = Field(default_factory=lambda: DwellTimes(min_s=1e-6, max_s=1.0),
                                       description="mean time a trap stays filled, log-uniform across traps, s")
    cds: bool = Field(True, description="correlated double sampling: a frame shows the trap's change between the reset "
                                        "and the signal sample; off: its level, held over frames")
    cds_interval_s: float = Field(1e-5, gt=0, le=10, description="time from the reset sample to the signal sample, s")


class DarkCurrentRtsSection(Section):
    """Dark-current random telegraph noise (stage 4b, docs/model.md): white pixels whose dark current blinks
    between two rates."""

    enabled: bool = False
    ppm: float = Field(100.0, ge=0, lt=1e6, description="parts per million of pixels that blink")
    step_e_per_s: SpreadLaw = Field(default_factory=lambda: SpreadLaw(median=300.0, sigma_log=0.7),
                                    description="the extra dark current of the high state across pixels, e-/s, at "
                                                "reference_temperature_c")
    reference_temperature_c: float = Field(25.0, ge=-60, le=150, description="where step_e_per_s holds; it doubles "
                                                                             "every dark_current.tail_doubling_c")
    tau_low_s: DwellTimes = Field(default_factory=lambda: DwellTimes(min_s=1.0, max_s=100.0),
                                  description="mean time at the low rate, log-uniform across pixels, s")
    tau_high_s: DwellTimes = Field(default_factory=lambda: DwellTimes(min_s=1.0, max_s=100.0),
                                   description="mean time at the high rate, log-uniform across pixels, s")


# --------------------------------------------------------------- dark current
RATE_UNITS = ("e_per_s", "aA", "nA_per_cm2")


def _one_of(obj, base: str, units=RATE_UNITS, required: bool = True):
    given = [u for u in units if getattr(obj, f"{base}_{u}", None) is not None]
    names = " or ".join(f"{base}_{u}" for u in units)
    if len(given) > 1:
        raise ValueError(f"give {base} once, as {names}; got {', '.join(base + '_' + u for u in given)}")
    if required and not given:
        raise ValueError(f"missing {base}: give {names}")


class DarkTail(Section):
    """White-pixel tail: ``ppm_above`` ppm of pixels above a threshold, tail values up to a maximum."""

    ppm_above: float = Field(ge=0, le=1e6, description="parts per million of pixels above the threshold")
    threshold_e_per_s: float | None = Field(None, ge=0, le=1e9, description="white-pixel threshold, e-/s per pixel")
    threshold_aA: float | None = Field(None, ge=0, le=1e8, description="white-pixel threshold, aA per pixel")
    threshold_nA_per_cm2: float | None = Field(None, ge=0, le=1e9, description="white-pixel threshold, nA/cm^2")
    max_e_per_s: float | None = Field(None, gt=0, le=1e9, description="largest extra dark current of a tail pixel")
    max_aA: float | None = Field(None, gt=0, le=1e8, description="largest extra dark current of a tail pixel, aA")
    max_nA_per_cm2: float | None = Field(None, gt=0, le=1e9, description="largest extra dark current of a tail pixel, nA/cm^2")

    @model_validator(mode="after")
    def _units(self):
        _one_of(self, "threshold")
        _one_of(self, "max")
        return self


class DarkPoint(Section):
    """A characterization point: the DCNU body (family, mean, std) and tail at one temperature."""

    temperature_c: float = Field(ge=-60, le=150, description="temperature of this characterization, degrees C")
    distribution: Literal["logistic", "inverse_gaussian", "lognormal", "normal", "gamma"] = Field(description="family of the DCNU body at this temperature")
    mean_e_per_s: float | None = Field(None, ge=0, le=1e8, description="body mean, e-/s per pixel (give one of the three units)")
    mean_aA: float | None = Field(None, ge=0, le=1e7, description="body mean, aA per pixel (1 aA = 6.2415 e-/s)")
    mean_nA_per_cm2: float | None = Field(None, ge=0, le=1e8, description="body mean, nA/cm^2 (needs sensor.pixel_pitch_um)")
    std_e_per_s: float | None = Field(None, gt=0, le=1e8, description="body standard deviation, e-/s per pixel")
    std_aA: float | None = Field(None, gt=0, le=1e7, description="body standard deviation, aA per pixel")
    std_nA_per_cm2: float | None = Field(None, gt=0, le=1e8, description="body standard deviation, nA/cm^2")
    tail: DarkTail | None = Field(None, description="white-pixel tail (ppm above a threshold); null: no tail")

    @model_validator(mode="after")
    def _units(self):
        _one_of(self, "mean")
        _one_of(self, "std")
        return self


def _default_dark_points():
    # Our defaults for a present-day ~2 um 4T pixel, with the paper's families;
    # the body roughly doubles every 7-8 C. 250 aA = 1560 e-/s.
    return [
        {"temperature_c": 25, "distribution": "logistic", "mean_e_per_s": 8.0, "std_e_per_s": 2.5,
         "tail": {"ppm_above": 50, "threshold_e_per_s": 100, "max_e_per_s": 2000}},
        {"temperature_c": 45, "distribution": "inverse_gaussian", "mean_e_per_s": 50.0, "std_e_per_s": 18.0,
         "tail": {"ppm_above": 100, "threshold_aA": 80, "max_e_per_s": 7000}},
        {"temperature_c": 65, "distribution": "lognormal", "mean_e_per_s": 320.0, "std_e_per_s": 130.0,
         "tail": {"ppm_above": 200, "threshold_aA": 250, "max_e_per_s": 25000}},
    ]


class DarkGlowSection(Section):
    """Amplifier glow (stage 4c): a dark-current rate rising from a corner or an edge."""

    enabled: bool = False
    rate_e_per_s: float = Field(0.0, ge=0, le=1e7, description="the glow's rate at its source, e-/s per pixel")
    source: Literal["top_left", "top_right", "bottom_left", "bottom_right", "top", "bottom", "left", "right"] = Field(
        "top_right", description="where the amplifiers sit: a corner (the glow falls with the distance from its "
                                 "point) or an edge (with the distance from its line)")
    length_px: float = Field(100.0, gt=0, le=1e6, description="the distance over which the glow falls by a factor "
                                                               "e, pixels")


class DarkCurrentSection(Section):
    """Dark current (stage 4, docs/model.md sections 3 and 4)."""

    enabled: bool = True
    shot_noise: bool = Field(True, description="dark shot noise (Poisson); off: dark charge enters as its mean")
    doubling_c: float = Field(7.0, gt=0, le=100, description="the body doubles every doubling_c degrees C")
    tail_doubling_c: float = Field(10.0, gt=0, le=100, description="the white-pixel tail doubles every tail_doubling_c C")
    points: list[DarkPoint] = Field(default_factory=lambda: [DarkPoint(**p) for p in _default_dark_points()], min_length=1,
                                    description="characterization points (one or more temperatures)")
    rts: DarkCurrentRtsSection = Field(default_factory=DarkCurrentRtsSection)
    glow: DarkGlowSection = Field(default_factory=DarkGlowSection)
    white_threshold_e_per_s: float | None = Field(
        None, ge=0, le=1e9, description="count white pixels above this rate, e-/s per pixel, at every temperature "
        "(null: the nearest characterization point's tail threshold)")
    white_threshold_aA: float | None = Field(None, ge=0, le=1e8, description="the white-pixel threshold, aA per pixel")
    white_threshold_nA_per_cm2: float | None = Field(None, ge=0, le=1e9, description="the white-pixel threshold, "
                                                        "nA/cm^2 (needs sensor.pixel_pitch_um)")

    @model_validator(mode="after")
    def _white_units(self):
        _one_of(self, "white_threshold", required=False)
        return self

    @field_validator("points")
    @classmethod
    def _distinct(cls, v):
        temps = [p.temperature_c for p in v]
        if len(set(temps)) != len(temps):
            raise ValueError(f"characterization temperatures must differ, got {temps}")
        return sorted(v, key=lambda p: p.temperature_c)


# ------------------------------------------------------------ readout noise
class FlickerTail(Section):
    """Very noisy pixels: ``ppm_above`` ppm of pixels with a flicker sigma above ``threshold_e``."""

    ppm_above: float = Field(ge=0, le=1e6, description="parts per million of pixels whose flicker sigma exceeds threshold_e")
    threshold_e: float = Field(gt=0, le=1e4, description="flicker sigma threshold, e- rms")
    max_e: float = Field(gt=0, le=1e4, description="largest extra sigma of a tail pixel, e- rms")


class FlickerSection(Section):
    """Flicker/RTS: per-pixel fixed sigma ~ Gumbel body (clipped at 0) + uniform tail."""

    enabled: bool = True
    gumbel_loc_e: float = Field(0.8, ge=-1000, le=1000, description="location of the gumbel_r body, e- rms")
    gumbel_scale_e: float = Field(0.25, gt=0, le=1000, description="scale of the gumbel_r body, e- rms")
    tail: FlickerTail | None = Field(default_factory=lambda: FlickerTail(ppm_above=100, threshold_e=4.0, max_e=12.0),
                                        description="RTS tail of very noisy pixels; null: no tail")
    spectrum: Literal["white", "one_over_f"] = Field(
        "white", description="the flicker in time: white (a new normal each frame, the paper's) or one_over_f (each "
                             "pixel a 1/f process: through CDS, source_follower.rts.cds, a frame shows its change "
                             "over the CDS interval, whose variance grows with the interval; without CDS its level, "
                             "correlated from frame to frame)")
    corner_hz: tuple[float, float] | None = Field(
        None, description="one_over_f: the lowest and highest corner of its Lorentzians, Hz; null: a thousandth of "
                          "the frame rate to a thousand times it")
    reference_cds_interval_s: float = Field(
        1e-5, gt=0, le=10, description="one_over_f through CDS: the CDS interval at which the sigmas above are a "
                                       "frame's (at another interval the flicker scales by the CDS transfer's "
                                       "integral of the 1/f spectrum)")

    @model_validator(mode="after")
    def _corners(self):
        _check_corners("source_follower.flicker", self.corner_hz)
        return self


class SourceFollowerSection(Section):
    """Source-follower noise (stage 6), input-referred."""

    enabled: bool = True
    thermal_sigma_e: float = Field(2.0, ge=0, le=10000, description="thermal noise, e- rms per pixel per frame")
    read_noise_e: float | None = Field(
        None, gt=0, le=10000, description="the dark temporal read noise, e- rms, as a data sheet gives it (EMVA "
                                          "1288's sigma_d at no exposure, over K): thermal, flicker, row and column "
                                          "temporal noise, the ADC's read noise, black-level error and "
                                          "quantization, as the population expects them; thermal_sigma_e is solved "
                                          "from it (random telegraph traps not counted); null: thermal_sigma_e as "
                                          "given")
    flicker: FlickerSection = Field(default_factory=FlickerSection)
    rts: SourceFollowerRtsSection = Field(default_factory=SourceFollowerRtsSection)


def _check_corners(section: str, corners) -> None:
    """A ``corner_hz`` range: two finite frequencies, ``0 < low < high`` (the frame rate's bound is the sensor's)."""
    if corners is None:
        return
    low, high = corners
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low < high):
        raise ValueError(f"{section}.corner_hz = [{low}, {high}]: need two frequencies in Hz with 0 < low < high "
                         "(null: from a thousandth of the frame rate to what the readout resolves)")


class RowNoiseSection(Section):
    enabled: bool = True
    sigma_e: float = Field(0.4, ge=0, le=10000, description="temporal row noise, e- rms per row per frame")
    fixed_sigma_e: float = Field(0.0, ge=0, le=10000, description="fixed row offsets, e- rms (the paper neglects them)")
    sigma_dn: float = Field(0.0, ge=0, le=10000, description="temporal row noise after the gain, DN rms per row per frame "
                                                             "(as ELD calibrates it; adds to sigma_e in variance)")
    spectrum: Literal["white", "one_over_f"] = Field(
        "white", description="the temporal row noise in time: white (a new value per row per frame) or one_over_f "
                             "(a 1/f process sampled at each row's readout time, rows of frame k after those of "
                             "frame k - 1: banding that drifts and correlates from frame to frame); the rms stays "
                             "sigma_e")
    corner_hz: tuple[float, float] | None = Field(
        None, description="one_over_f: the lowest and highest corner of its Lorentzians, Hz (the 1/f range); "
                          "null: a thousandth of the frame rate to the row rate")

    @model_validator(mode="after")
    def _corners(self):
        _check_corners("row_noise", self.corner_hz)
        return self


class ColumnTemporalSection(Section):
    enabled: bool = True
    gumbel_loc_e: float = Field(0.4, ge=-1000, le=1000, description="location of the per-column sigma's gumbel_r, e- rms")
    gumbel_scale_e: float = Field(0.1, gt=0, le=1000, description="scale of the per-column sigma's gumbel_r, e- rms")
    spectrum: Literal["white", "one_over_f"] = Field(
        "white", description="each column's temporal noise in time: white (a new value per frame) or one_over_f (a "
                             "1/f process per column amplifier sampled at each frame's time); its rms stays the "
                             "column's sigma")
    corner_hz: tuple[float, float] | None = Field(
        None, description="one_over_f: the lowest and highest corner of its Lorentzians, Hz; null: a thousandth of "
                          "the frame rate to half the frame rate")

    @model_validator(mode="after")
    def _corners(self):
        _check_corners("column_noise.temporal", self.corner_hz)
        return self


class ColumnAlternatingSection(Section):
    """Two-phase column amplifiers (even and odd columns read by two banks): each bank's offset."""

    enabled: bool = False
    fixed_sigma_e: float = Field(0.0, ge=0, le=10000, description="each bank's fixed offset, e- rms: one "
                                                                  "Normal(0, sigma) for the even columns and one for "
                                                                  "the odd, drawn once (their difference's rms is "
                                                                  "sqrt(2) sigma)")
    temporal_sigma_e: float = Field(0.0, ge=0, le=10000, description="each bank's offset per frame, e- rms: one "
                                                                     "Normal(0, sigma) for the even columns and one "
                                                                     "for the odd, every frame")


class ColumnNoiseSection(Section):
    enabled: bool = True
    temporal: ColumnTemporalSection = Field(default_factory=ColumnTemporalSection)
    alternating: ColumnAlternatingSection = Field(default_factory=ColumnAlternatingSection)
    vfpn_sigma_e: float = Field(0.8, ge=0, le=10000, description="vertical fixed pattern noise: column offsets, e- rms")
    gain_sigma_pct: float = Field(0.0, ge=0, le=50, description="column gain mismatch, % rms")


class AdcSection(Section):
    enabled: bool = Field(True, description="off: ideal readout, 1 DN per e-, no black level, 16-bit range")
    bits: int = Field(12, ge=8, le=16, description="ADC resolution, bits")
    output_bits: int | None = Field(None, ge=8, le=16, description="the output's range, bits: the ADC's codes "
                                       "times 2^(output_bits - bits), as a camera writes a 12- or 14-bit ADC in a "
                                       "16-bit range; K, the black level and DN noise are in output DN; null: bits")
    black_level_dn: float = Field(64.0, ge=0, le=65535, description="offset added before quantization, DN")
    full_scale_e: float | None = Field(None, ge=1, le=1e9, description="charge mapped to the top code, e-; null: the full well")
    gain_dn_per_e: float | None = Field(None, gt=0, le=1000, description="system gain K, DN per e- (instead of "
                                                                            "full_scale_e: the top code is then at (top - black) / K)")

    @model_validator(mode="after")
    def _one_scale(self):
        if self.full_scale_e is not None and self.gain_dn_per_e is not None:
            raise ValueError("give the ADC's scale once: adc.full_scale_e or adc.gain_dn_per_e")
        if self.output_bits is not None and self.output_bits < self.bits:
            raise ValueError(f"adc.output_bits = {self.output_bits} is below adc.bits = {self.bits}: the output "
                             "holds the ADC's codes, so it needs at least as many bits (null: the same)")
        return self

    @property
    def top_code(self) -> int:
        """The top output code, DN: ``2^(output_bits - bits) (2^bits - 1)``."""
        out = self.bits if self.output_bits is None else self.output_bits
        return 2 ** (out - self.bits) * (2**self.bits - 1)


# ------------------------------------------------ what measured sensors show
class OffsetTail(Section):
    """Pixels with a large offset: ``ppm_above`` ppm of pixels above ``threshold_e``."""

    ppm_above: float = Field(ge=0, le=1e6, description="parts per million of pixels whose offset exceeds threshold_e")
    threshold_e: float = Field(gt=0, le=1e6, description="offset threshold, e-")
    max_e: float = Field(gt=0, le=1e6, description="largest extra offset of a tail pixel, e-")


class PixelOffsetSection(Section):
    """Pixel offset non-uniformity (DSNU at zero exposure, dark shading), docs/model.md stage 5c.

    A fixed offset per pixel, e-: a Normal(0, sigma_e) body plus a uniform
    tail of pixels with large offsets; independent of exposure time and temperature.
    """

    enabled: bool = False
    sigma_e: float = Field(0.0, ge=0, le=1e5, description="standard deviation of the offsets' normal body, e-")
    tail: OffsetTail | None = Field(None, description="pixels with large offsets (ppm above a threshold); null: none")


class NonlinearitySection(Section):
    """Photo-response nonlinearity (stage 5b): the charge-to-voltage transfer before the readout noise, or the
    collection of the mean photo-charge before the shot noise (``acts_on``).

    Give ``linearity_error_pct`` (EMVA 1288's LE min and max over 5 to 95 %
    of saturation), ``coefficients`` (the cubic it is solved to) or
    ``curve_e`` (points of the transfer, e- in to e- out, strictly
    increasing, from (0, 0)). Off: the exact identity.
    """

    enabled: bool = False
    linearity_error_pct: tuple[float, float] | None = Field(
        None, description="EMVA 1288 linearity error [min, max], % (min <= 0 <= max), over 5-95 % of saturation")
    curve_e: list[tuple[float, float]] | None = Field(
        None, description="the transfer as points [[charge_e, output_e], ...], strictly increasing, from [0, 0]")
    coefficients: tuple[float, float, float] | None = Field(
        None, description="the transfer as the cubic x (1 + a s + b s^2 + c s^3), s = x / full well: [a, b, c]")
    acts_on: Literal["charge", "mean"] = Field(
        "charge", description="charge: the sense node's conversion of each frame's collected charge (after the shot "
                              "noise: the photon transfer bends too); mean: the collection of the mean photo-charge "
                              "(before the shot noise: the variance follows the mean, as a QE falling near full well)")

    @model_validator(mode="after")
    def _one_form(self):
        given = [k for k in ("linearity_error_pct", "curve_e", "coefficients") if getattr(self, k) is not None]
        if len(given) > 1 or (self.enabled and not given):
            raise ValueError("give one of linearity_error_pct, curve_e or coefficients"
                             + (f" (got {', '.join(given)})" if given else ""))
        if self.linearity_error_pct is not None:
            lo, hi = self.linearity_error_pct
            if not (-20 <= lo <= 0 <= hi <= 20) or lo == hi:
                raise ValueError(f"linearity_error_pct = {[lo, hi]}: need -20 <= min <= 0 <= max <= 20 "
                                 "(a linear fit leaves deviations of both signs), not both 0")
        if self.curve_e is not None:
            pts = [(float(a), float(b)) for a, b in self.curve_e]
            if len(pts) < 2 or pts[0] != (0.0, 0.0):
                raise ValueError(f"curve_e must start at [0, 0] and have 2 points or more, got {pts[:3]}")
            for (a0, b0), (a1, b1) in zip(pts, pts[1:]):
                if not (a1 > a0 and b1 > b0):
                    raise ValueError(f"curve_e must be strictly increasing in both columns (invertible): "
                                     f"[{a0:g}, {b0:g}] is followed by [{a1:g}, {b1:g}]")
        return self


class BlackLevelSection(Section):
    """The black level's offsets beside adc.black_level_dn: per CFA cell position and per frame (DN)."""

    channel_offsets_dn: tuple[float, float, float, float] = Field(
        (0.0, 0.0, 0.0, 0.0), description="offset of each position of the 2 x 2 CFA cell, in sensor.cfa's order "
                                          "(RGGB: R, Gr, Gb, B), DN")
    frame_sigma_dn: float = Field(0.0, ge=0, le=1000, description="black-level error of each frame, Normal(0, sigma), DN")

    @field_validator("channel_offsets_dn")
    @classmethod
    def _bounded(cls, v):
        if any(abs(x) > 1000 for x in v):
            raise ValueError("each must be within +-1000 DN")
        return v


class ReadNoiseSection(Section):
    """Read noise after the analogue gain, in DN (stage 9a), as ELD calibrates it.

    ``normal``: Normal(0, scale_dn). ``tukey_lambda``: Tukey-lambda with
    shape ``shape`` and scale ``scale_dn`` (heavy tails for shape < 0.14,
    light ones above; 0 is the logistic law), drawn by its quantile function.
    """

    enabled: bool = False
    distribution: Literal["normal", "tukey_lambda"] = Field("normal", description="normal or tukey_lambda")
    scale_dn: float = Field(1.0, gt=0, le=10000, description="scale: the normal's sigma, or the Tukey-lambda scale, DN")
    shape: float = Field(0.14, description="Tukey-lambda shape lambda, -0.5 < lambda <= 2")

    @field_validator("shape")
    @classmethod
    def _shape(cls, v):
        if not -0.5 < v <= 2.0:
            raise ValueError("a Tukey-lambda shape must be in (-0.5, 2] "
                             "(at -0.5 and below its variance is infinite)")
        return v


class LineDefects(Section):
    """Bad columns (or rows): each line is bad at its rate, with one of three kinds (docs/model.md stage 15)."""

    offset_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of the lines with a fixed offset")
    offset_e: tuple[float, float] = Field((20.0, 100.0), description="offset's size, uniform between the two, e- "
                                          "(its sign random)")
    gain_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of the lines with a gain error")
    gain: tuple[float, float] = Field((0.7, 0.9), description="the line's gain on its pixels' charge, uniform between "
                                      "the two (below 1: a dim line)")
    stuck_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of the lines stuck at a code")
    stuck_levels: list[float] = Field([0.0, 1.0], min_length=1, description="codes a stuck line reads, as fractions "
                                      "of the ADC's top code (one picked at random)")

    @model_validator(mode="after")
    def _check(self):
        _check_defect_ranges(self, ("offset_e", 0.0), ("gain", 0.0))
        _check_levels(self.stuck_levels, "stuck_levels")
        if self.offset_ppm + self.gain_ppm + self.stuck_ppm >= 1e6:
            raise ValueError(f"offset_ppm + gain_ppm + stuck_ppm = {self.offset_ppm + self.gain_ppm + self.stuck_ppm:g}"
                             " must be below 1e6")
        return self


class ClusterDefects(Section):
    """Clusters of hot pixels: 2 or more adjacent pixels with a large extra dark current (stage 15)."""

    ppm: float = Field(0.0, ge=0, lt=1e6, description="clusters per million pixels")
    size_weights: list[float] = Field([0.5, 0.25, 0.15, 0.1], min_length=1, max_length=30,
                                      description="relative weights of the sizes 2, 3, 4, ...: a cluster's pixel count")
    rate_e_per_s: float = Field(5000.0, gt=0, le=1e9, description="extra dark current of each pixel of a cluster, e-/s")

    @field_validator("size_weights")
    @classmethod
    def _weights(cls, v):
        if any(w < 0 for w in v) or sum(v) <= 0:
            raise ValueError(f"size_weights = {v}: weights must be >= 0 and not all 0")
        return v


class SensorDefectsSection(Section):
    """Manufacturing defects (stage 15), a fixed pattern at rates in ppm; off: every frame as without the stage.

    Dead pixels collect no charge; stuck pixels read a fixed code; low- and
    high-gain pixels scale their charge; clusters are 2 or more adjacent hot
    pixels; bad columns and rows carry an offset, a gain error or a stuck code.
    Drawn per pixel (per line) from the stage's counter-based key, so any tile
    is the same tile of the whole sensor.
    """

    enabled: bool = False
    dead_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of dead pixels (no charge)")
    stuck_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of pixels stuck at a code")
    stuck_levels: list[float] = Field([0.0, 1.0], min_length=1, description="codes a stuck pixel reads, as fractions "
                                      "of the ADC's top code (one picked at random per pixel)")
    low_gain_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of low-gain pixels")
    low_gain: tuple[float, float] = Field((0.2, 0.8), description="a low-gain pixel's factor on its charge, uniform "
                                          "between the two")
    high_gain_ppm: float = Field(0.0, ge=0, lt=1e6, description="parts per million of high-gain pixels")
    high_gain: tuple[float, float] = Field((1.25, 2.0), description="a high-gain pixel's factor on its charge, "
                                           "uniform between the two")
    clusters: ClusterDefects = Field(default_factory=ClusterDefects)
    columns: LineDefects = Field(default_factory=LineDefects)
    rows: LineDefects = Field(default_factory=LineDefects)

    @model_validator(mode="after")
    def _check(self):
        _check_defect_ranges(self, ("low_gain", 0.0), ("high_gain", 0.0))
        _check_levels(self.stuck_levels, "stuck_levels")
        total = self.dead_ppm + self.stuck_ppm + self.low_gain_ppm + self.high_gain_ppm
        if total >= 1e6:
            raise ValueError(f"dead_ppm + stuck_ppm + low_gain_ppm + high_gain_ppm = {total:g} must be below 1e6")
        return self


def _check_defect_ranges(section, *names) -> None:
    for name, lowest in names:
        lo, hi = getattr(section, name)
        if not lowest <= lo <= hi:
            raise ValueError(f"{name} = [{lo:g}, {hi:g}]: give [low, high] with {lowest:g} <= low <= high")


def _check_levels(levels, name) -> None:
    bad = [v for v in levels if not 0.0 <= v <= 1.0]
    if bad:
        raise ValueError(f"{name} = {levels}: each level is a fraction of the top code, 0 to 1")


class GainRow(Section):
    """One gain setting of a camera (docs/model.md stage 9b): its system gain K and what else changes with it.

    ``set`` holds the configuration keys this setting changes, dotted
    (``read_noise.scale_dn``, ``row_noise.sigma_dn``, ``sensor.full_well_e``,
    ``nonlinearity.linearity_error_pct``, ...): a camera with two conversion
    gains switches K, read noise, saturation and linearity there. Noise given
    in e- (the source follower's) stays in e-, so in DN it follows K; noise
    given in DN after the gain stays in DN unless the row sets it.
    """

    iso: float | None = Field(None, gt=0, le=1e7, description="the setting as ISO")
    gain_db: float | None = Field(None, ge=-60, le=120, description="the setting in dB")
    mode: str | None = Field(None, max_length=40, description="a name for the row's mode, e.g. LCG or HCG")
    binning: Literal["1x1", "2x2", "1x2", "2x1"] | None = Field(
        None, description="the binning mode this row is for (sensor.binning picks it); null: every binning")
    k_dn_per_e: float = Field(gt=0, le=1000, description="system gain K at this setting, DN per e-")
    set: dict[str, float | bool | str | list | None] = Field(
        default_factory=dict, description="configuration keys this setting changes, dotted, e.g. read_noise.scale_dn")

    @model_validator(mode="after")
    def _one_index(self):
        if (self.iso is None) == (self.gain_db is None):
            raise ValueError("a row is indexed by iso or by gain_db (one of the two)")
        bad = [k for k in self.set if k.split(".")[0] in ("gain_table", "seed", "run", "scene")
               or k in ("sensor.iso", "sensor.gain_db", "sensor.binning")]
        if bad:
            raise ValueError(f"{bad} cannot be set per gain (set sensor, stage and adc keys)")
        return self


# ------------------------------------------------------------------------- root
class Config(Section):
    """A complete, resolved cmosnoise configuration.

    Parameters
    ----------
    description : str
        Free text: what this configuration is for.
    seed : int
        The sensor instance: the same seed gives the same fixed pattern and noise.
    scene, run, processing : sections
        What is simulated (the scene, frames, outputs) and how the frames become pictures.
    sensor, exposure : sections
        The array (size, CFA, pixel, temperature, gain setting) and the exposure.
    light, optics : sections
        Light in lux through a lens (off by default: the exposure's peak rate is the light).
    prnu, crosstalk, dark_current, shot_noise, source_follower, row_noise, column_noise, adc : sections
        The paper's stages.
    pixel_offset, nonlinearity, black_level, read_noise, defects : sections
        What measured sensors show beyond the paper.
    gain_table : list of GainRow
        The camera's gain settings (ISO or dB).

    Notes
    -----
    Every key, with its unit and meaning: ``cmosnoise config --explain``; the model behind them: docs/model.md.

    Examples
    --------
    >>> from cmosnoise import Config
    >>> config = Config()                     # every default; cmosnoise.load_config adds presets, files, --set
    >>> config.sensor.width, config.sensor.height, config.sensor.cfa
    (640, 480, 'RGGB')
    """

    description: str = Field("", description="free text: what this configuration is for")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="sensor instance: the same seed gives the same fixed pattern and noise")
    scene: SceneSection = Field(default_factory=SceneSection)
    run: RunSection = Field(default_factory=RunSection)
    sensor: SensorSection = Field(default_factory=SensorSection)
    exposure: ExposureSection = Field(default_factory=ExposureSection)
    light: LightSection = Field(default_factory=LightSection)
    optics: OpticsSection = Field(default_factory=OpticsSection)
    prnu: PrnuSection = Field(default_factory=PrnuSection)
    crosstalk: CrosstalkSection = Field(default_factory=CrosstalkSection)
    dark_current: DarkCurrentSection = Field(default_factory=DarkCurrentSection)
    shot_noise: ShotNoiseSection = Field(default_factory=ShotNoiseSection)
    source_follower: SourceFollowerSection = Field(default_factory=SourceFollowerSection)
    row_noise: RowNoiseSection = Field(default_factory=RowNoiseSection)
    column_noise: ColumnNoiseSection = Field(default_factory=ColumnNoiseSection)
    adc: AdcSection = Field(default_factory=AdcSection)
    pixel_offset: PixelOffsetSection = Field(default_factory=PixelOffsetSection)
    nonlinearity: NonlinearitySection = Field(default_factory=NonlinearitySection)
    black_level: BlackLevelSection = Field(default_factory=BlackLevelSection)
    read_noise: ReadNoiseSection = Field(default_factory=ReadNoiseSection)
    defects: SensorDefectsSection = Field(default_factory=SensorDefectsSection)
    gain_table: list[GainRow] = Field(default_factory=list, description="the camera's gain settings (ISO or dB): "
                                      "sensor.iso or sensor.gain_db picks one")
    processing: ProcessingSection = Field(default_factory=ProcessingSection)

    @model_validator(mode="after")
    def _cross_checks(self):
        self._check_across_sections()
        return self

    def _check_across_sections(self) -> None:
        """What no section can check alone (the black level below the top code, a gain in the gain table, the
        light given once, ...): raises ValueError, changes nothing. Run on every validation and assignment
        (:meth:`_cross_checks`), and by :func:`~cmosnoise.config.merge_updates` once after it puts validated
        sections in."""
        top = self.adc.top_code
        if self.adc.black_level_dn >= top:
            raise ValueError(
                f"adc.black_level_dn = {self.adc.black_level_dn:g} leaves no range: it must be below the top code "
                f"{top} (2^bits - 1{' times the output step' if top >= 2**self.adc.bits else ''})"
            )
        if self.sensor.iso is not None and self.sensor.gain_db is not None:
            raise ValueError("give the gain once: sensor.iso or sensor.gain_db")
        index = "iso" if self.sensor.iso is not None else "gain_db" if self.sensor.gain_db is not None else None
        if index is not None:
            value = getattr(self.sensor, index)
            binning = self.sensor.binning
            have = [getattr(r, index) for r in self.gain_table if getattr(r, index) is not None]
            if not have:
                raise ValueError(f"sensor.{index} = {value:g} needs a gain_table with {index} rows (this configuration "
                                 "has none)")
            if value not in have:
                raise ValueError(f"sensor.{index} = {value:g} is not in the gain table; it has "
                                 f"{', '.join(f'{h:g}' for h in sorted(set(have)))}")
            if not any(getattr(r, index) == value and r.binning in (None, binning) for r in self.gain_table):
                # every row at this value has a binning of its own here (a row without one would have matched)
                modes = sorted({r.binning for r in self.gain_table
                                if getattr(r, index) == value and r.binning is not None})
                raise ValueError(f"sensor.binning = {binning!r}: the gain table has no row for it at sensor.{index} = "
                                 f"{value:g}; it has binning {', '.join(modes)} there")
        elif self.sensor.binning != "1x1" and any(r.binning is not None for r in self.gain_table):
            raise ValueError(f"sensor.binning = {self.sensor.binning!r} picks gain_table rows by binning: give the "
                             "gain setting too (sensor.iso or sensor.gain_db)")
        ex = self.exposure
        if ex.peak_rate_photons_per_s is not None:
            if self.sensor.quantum_efficiency is None:
                raise ValueError("exposure.peak_rate_photons_per_s needs sensor.quantum_efficiency (electrons per photon)")
            if "peak_rate_e_per_s" in ex.model_fields_set:
                raise ValueError("give the light once: exposure.peak_rate_e_per_s or exposure.peak_rate_photons_per_s")
        if self.light.enabled and ex.peak_rate_photons_per_s is not None:
            raise ValueError("give the light once: light (lux) or exposure.peak_rate_photons_per_s")
        if isinstance(self.crosstalk.kernel_pct, dict) and self.sensor.cfa == "none" and self.crosstalk.enabled:
            raise ValueError("crosstalk.kernel_pct: a per-colour kernel needs a colour sensor (sensor.cfa is 'none')")

    # convenience -----------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the sensor."""
        return (self.sensor.height, self.sensor.width)

    def to_dict(self) -> dict:
        """Plain data; unset optional keys (null) are left out, as they read back as defaults.

        Returns
        -------
        dict
            The sections as JSON-compatible data.
        """
        return self.model_dump(mode="json", exclude_none=True)

    def to_yaml(self) -> str:
        """Every key, those that are null included (they read back as null).

        Returns
        -------
        str
            The configuration as YAML, sections in their order.
        """
        # a top-level block mapping is its sections' texts one after another: each section is dumped on its own
        # and kept by its value (a data set writes one configuration per sample, most of its sections the same)
        return "".join(_section_yaml(json.dumps({k: v}, sort_keys=False))
                       for k, v in self.model_dump(mode="json").items())


class _Top(dict):
    """A configuration's top-level mapping: written in block style, as it is in the whole text (whose sections
    are mappings); alone, a section of one scalar (``seed: 0``) would be written in flow style."""


_BaseDumper: Any = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's emitter where PyYAML has it


class _Dumper(_BaseDumper):
    """PyYAML's safe dumper that writes :class:`_Top` as a block mapping."""


_Dumper.add_representer(_Top, lambda dumper, data: dumper.represent_mapping("tag:yaml.org,2002:map", data,
                                                                          flow_style=False))


@functools.lru_cache(maxsize=512)
def _section_yaml(section_json: str) -> str:
    """One top-level section (``{name: value}`` as JSON, the cache's key) as YAML, as it reads in the whole
    configuration's text (libyaml's emitter: the same text, some 15 times faster than PyYAML's own)."""
    return yaml.dump(_Top(json.loads(section_json)), Dumper=_Dumper, sort_keys=False, default_flow_style=None,
                     width=100)


