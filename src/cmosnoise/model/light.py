"""Light in physical units: from an illuminant in lux, through a lens, to photo-electrons per pixel and channel.

docs/model.md section 2b is the specification. The chain, per wavelength lambda (nm), on a working grid of
:data:`STEP_NM` where the illuminant and the quantum efficiency are both given:

1. the illuminant's relative spectral power ``S(lambda)`` is scaled to the spectral irradiance ``E(lambda)``
   (W m^-2 nm^-1) whose illuminance is the configured ``E_v`` lux: ``683 lm/W * integral E V d lambda = E_v``,
   V the CIE 1931 2 degree observer's y-bar (colour-science's table, 1 nm);
2. a Lambertian reflector of reflectance 1 has the spectral radiance ``E(lambda) / pi``; light given as a
   luminance ``L_v`` (cd/m2) is the same with ``E_v = pi L_v``;
3. the lens puts the focal-plane irradiance ``k L`` on the optical axis (:func:`camera_factor`): ISO 12232's
   ``k = pi T / (4 N^2 (1 + m)^2)`` or the non-paraxial ``pi T / (1 + 4 N^2 (1 + m)^2)`` that ISETCam uses;
4. photons: ``k L(lambda) lambda / (h c)`` per second and square metre and nm, times the pixel's area (pitch
   squared; the share its aperture collects, the fill factor, is the optical image's: :mod:`.focal_plane`);
5. electrons: times the channel's quantum efficiency ``QE_c(lambda)``, integrated over lambda (trapezoid rule).

The result, for a scene value of 1, is one rate per colour channel (:attr:`ChannelLight.rates_e_per_s`). A scene
value is a reflectance; an RGB picture is turned into spectra by Mallett and Yuksel's (2019) up-sampling, which is
linear in RGB, so the whole spectral integral of a picture is one 3 x 3 matrix (:attr:`ChannelLight.mix`) made once
per exposure: the frame kernel never sees a wavelength. :class:`~cmosnoise.model.focal_plane.FocalPlane` reads the
configuration (the light, the lens's numbers, the pixel) and calls :func:`integrate` with them.

Examples
--------
>>> from cmosnoise.model import light
>>> k = light.camera_factor(2.8, 1.0)                        # f/2.8, every photon through
>>> li = light.integrate("D65", 100.0, None, None, 0.5, None, k, 2.2**2)
>>> round(float(li.rates_e_per_s[1] * 0.03 * 0.18))          # an 18 % grey card at 100 lux, 30 ms, 2.2 um
579
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import inputs
from ..errors import CmosnoiseError

#: the working grid's step, nm: colour-science's illuminants, charts and camera sets are tabulated at 5 nm
STEP_NM = 5.0
#: the luminous efficacy of radiation at 555 nm, lm/W (the definition of the candela)
KM_LM_PER_W = 683.0
#: Planck's constant (J s) and the speed of light (m/s), exact in the SI
PLANCK_J_S = 6.62607015e-34
LIGHT_M_PER_S = 299792458.0
#: the wavelengths a flat quantum efficiency (``light.spectral_qe`` null) covers, nm
FLAT_QE_NM = (380.0, 780.0)
#: the default sensor's spectral QE, where neither light.spectral_qe nor sensor.quantum_efficiency is given: a colour
#: camera's measured relative spectral sensitivities (the Nikon D5100's, NPL's measurement: Darrodi et al., "Reference
#: data set for camera spectral sensitivity estimation", JOSA A 32, 2015; colour-science's "Nikon 5100 (NPL)",
#: its colour filters, IR cut and silicon together) scaled so that their peak is DEFAULT_QE_PEAK: the green
#: channel's QE Basler gives for a current colour CMOS camera (the acA4112-30uc: its monochrome twin's 70 % at
#: 545 nm times the IR-cut filter's 93 %; docs.baslerweb.com, "About EMVA1288 Reports for Color Sensors")
DEFAULT_SPECTRAL_QE, DEFAULT_QE_PEAK = "Nikon 5100 (NPL)", 0.65
#: the ColorChecker's reflectance spectra: colour-science's name for them (Ohta's measurement, 380-780 nm)
COLORCHECKER_SPECTRA = "ColorChecker N Ohta"
#: the largest CSV table read (rows of a spectrum)
MAX_TABLE_BYTES = 4_000_000

__all__ = ["ChannelLight", "integrate", "read_table", "camera_factor", "illuminant_spectrum", "qe_spectrum",
           "photopic_efficiency", "reflectance_channels", "spectral_channels", "read_cube",
           "colorchecker_reflectances"]


def _colour():
    """colour-science, imported when light is used (about a second the first time; :mod:`cmosnoise.colour_lib`)."""
    from .. import colour_lib

    return colour_lib.colour()


def read_table(path: str, what: str) -> np.ndarray:
    """A table of numbers from a CSV (commas, semicolons or whitespace; ``#`` comments; a header line allowed),
    through the input gate: the spectra here, and the lens's tables of :mod:`.optics`.

    Parameters
    ----------
    path : str
        The file.
    what : str
        The key it was given for, named in errors.

    Returns
    -------
    (rows, columns) float64 array
        At least two rows, all of the same length.
    """
    text = inputs.read_text(path, what, MAX_TABLE_BYTES)
    rows = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = [p for p in line.replace(",", " ").replace(";", " ").split() if p]
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            if not rows:  # a header line
                continue
            raise CmosnoiseError(f"{what} {path}: {line!r} is not a row of numbers") from None
    if len(rows) < 2 or len({len(r) for r in rows}) != 1:
        raise CmosnoiseError(f"{what} {path}: give at least two rows of the same number of columns")
    return np.asarray(rows, dtype=np.float64)


def _check_wavelengths(wl: np.ndarray, key: str) -> None:
    if not np.isfinite(wl).all() or (np.diff(wl) <= 0).any():
        raise CmosnoiseError(f"{key}: the wavelengths must be finite and increasing (got {wl[:4].tolist()}...)")
    if wl[0] < 200 or wl[-1] > 2500:
        raise CmosnoiseError(f"{key}: wavelengths {wl[0]:g} to {wl[-1]:g} nm; give nm from 200 to 2500")


def illuminant_spectrum(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The relative spectral power of an illuminant.

    Parameters
    ----------
    name : str
        A CIE illuminant colour-science ships (``D65``, ``A``, ``FL2``, ``LED-B1``, ...; any case),
        ``blackbody:KELVIN``, or a CSV file of (wavelength nm, relative power).

    Returns
    -------
    wavelengths : (n,) float64, nm, increasing
    power : (n,) float64, relative (any scale: :func:`integrate` sets the illuminance)
    """
    key = "light.illuminant"
    low = name.lower()
    if low.startswith("blackbody"):
        text = name.partition(":")[2]
        try:
            kelvin = float(text)
        except ValueError:
            kelvin = float("nan")
        if not 500 <= kelvin <= 50000:
            raise CmosnoiseError(f"{key} = {name!r}: give blackbody:KELVIN with KELVIN from 500 to 50000")
        colour = _colour()
        sd = colour.sd_blackbody(kelvin, colour.SpectralShape(300, 1100, STEP_NM))
        return np.asarray(sd.wavelengths, float), np.asarray(sd.values, float)
    colour = _colour()
    names = {k.lower(): k for k in colour.SDS_ILLUMINANTS}
    if low in names:
        sd = colour.SDS_ILLUMINANTS[names[low]]
        return np.asarray(sd.wavelengths, float), np.asarray(sd.values, float)
    if Path(name).suffix.lower() in (".csv", ".txt", ".tsv") or Path(name).exists():
        t = read_table(name, key)
        if t.shape[1] != 2:
            raise CmosnoiseError(f"{key} {name}: give two columns, wavelength (nm) and relative power")
        _check_wavelengths(t[:, 0], key)
        if not np.isfinite(t[:, 1]).all() or (t[:, 1] < 0).any() or t[:, 1].max() <= 0:
            raise CmosnoiseError(f"{key} {name}: the power must be finite, >= 0 and somewhere > 0")
        top = float(t[:, 1].max())
        if top < np.finfo(np.float64).tiny:
            raise CmosnoiseError(f"{key} {name}: the largest power is {top:g}, below the smallest normal number "
                                 f"({np.finfo(np.float64).tiny:g}); give a spectrum in any unit whose largest value "
                                 "is a normal number")
        return t[:, 0], t[:, 1] / top  # relative: its scale is free, kept away from overflow in the integrals
    shown = ", ".join(sorted(k for k in colour.SDS_ILLUMINANTS if not k.startswith(("FL3.", "ISO", "HP", "ID"))))
    raise CmosnoiseError(f"{key} = {name!r} is not known; give one of {shown}, blackbody:KELVIN or a CSV file")


def qe_spectrum(spectral_qe, qe_peak: float | None, quantum_efficiency) -> tuple[np.ndarray, np.ndarray]:
    """The pixels' quantum efficiency against wavelength, one column per colour channel.

    Parameters
    ----------
    spectral_qe : str, list of rows, or None
        A CSV file or inline rows of (nm, QE) or (nm, QE_R, QE_G, QE_B); a camera set colour-science ships
        (relative: give ``qe_peak``); None: ``quantum_efficiency`` at every wavelength of :data:`FLAT_QE_NM`, or,
        without that either, :data:`DEFAULT_SPECTRAL_QE` at :data:`DEFAULT_QE_PEAK` (or ``qe_peak``).
    qe_peak : float or None
        Scale the table so its highest value is this.
    quantum_efficiency : float, (3,) or None
        ``sensor.quantum_efficiency``, for a flat QE.

    Returns
    -------
    wavelengths : (n,) float64, nm, increasing
    qe : (n, 3) float64, electrons per photon, R, G, B (a monochrome table repeated)
    """
    key = "light.spectral_qe"
    if spectral_qe is None and quantum_efficiency is None:  # the default sensor's measured spectra
        return qe_spectrum(DEFAULT_SPECTRAL_QE, DEFAULT_QE_PEAK if qe_peak is None else qe_peak, None)
    if spectral_qe is None:
        q = np.broadcast_to(np.asarray(quantum_efficiency, float), (3,))
        wl = np.arange(FLAT_QE_NM[0], FLAT_QE_NM[1] + STEP_NM / 2, STEP_NM)
        table = np.repeat(q[None, :], wl.size, axis=0)
    else:
        if isinstance(spectral_qe, str):
            colour = _colour()
            names = {k.lower(): k for k in colour.MSDS_CAMERA_SENSITIVITIES}
            if spectral_qe.lower() in names:
                if qe_peak is None:
                    raise CmosnoiseError(f"{key} = {spectral_qe!r} is relative (its highest value is 1): give "
                                         "light.qe_peak, the QE at its peak (0 to 1)")
                msds = colour.MSDS_CAMERA_SENSITIVITIES[names[spectral_qe.lower()]]
                t = np.column_stack([msds.wavelengths, msds.values])
            else:
                t = read_table(spectral_qe, key)
        else:
            t = np.asarray(spectral_qe, dtype=np.float64)
        if t.ndim != 2 or t.shape[1] not in (2, 4):
            raise CmosnoiseError(f"{key}: give columns (nm, QE) or (nm, QE_R, QE_G, QE_B); got {t.shape[1]} columns")
        wl = t[:, 0]
        _check_wavelengths(wl, key)
        table = t[:, 1:]
        if table.shape[1] == 1:
            table = np.repeat(table, 3, axis=1)
    if qe_peak is not None:
        top = float(np.nanmax(table)) if table.size else 0.0
        if not top >= np.finfo(np.float64).tiny or not math.isfinite(top):
            raise CmosnoiseError(f"{key}: the table's largest value is {top:g}; it cannot be scaled to "
                                 "light.qe_peak (give finite values whose largest is a normal number above 0)")
        table = table * (qe_peak / top)
    if not np.isfinite(table).all() or (table < 0).any() or table.max() > 1 or table.max() <= 0:
        raise CmosnoiseError(f"{key}: each QE must be in [0, 1] and somewhere > 0 (electrons per photon); this "
                             f"table spans {np.nanmin(table):g} to {np.nanmax(table):g}")
    return np.asarray(wl, float), np.ascontiguousarray(table)


@functools.lru_cache(maxsize=1)
def photopic_efficiency() -> tuple[np.ndarray, np.ndarray]:
    """V(lambda): the CIE 1931 2 degree observer's y-bar, 360 to 830 nm at 1 nm (colour-science's table)."""
    cmfs = _colour().MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.asarray(cmfs.wavelengths, float), np.asarray(cmfs.values[:, 1], float)


def _integral(y: np.ndarray, wl: np.ndarray) -> np.ndarray:
    """The trapezoid rule over the last axis of ``y`` on wavelengths ``wl`` (nm)."""
    from scipy.integrate import trapezoid

    return trapezoid(y, wl, axis=-1)


def camera_factor(f_number: float, transmittance: float, magnification: float = 0.0,
                  equation: str = "iso12232") -> float:
    """The camera equation's factor k: on the optical axis, focal-plane illuminance = k x scene luminance.

    Parameters
    ----------
    f_number : float
        N.
    transmittance : float
        T, 0 to 1.
    magnification : float
        |m| (0: a distant scene).
    equation : {"iso12232", "non_paraxial"}
        ISO 12232's ``pi T / (4 N^2 (1 + m)^2)`` (an aplanatic lens, whose N is ``1 / (2 sin u')``), or
        ``pi T / (1 + 4 N^2 (1 + m)^2)`` (N as ``f / D`` of a thin lens; ISETCam's ``oiCalculateIrradiance``).

    Returns
    -------
    float
        k, lux per cd/m2 (the same factor for W m^-2 per W m^-2 sr^-1).
    """
    n2 = 4.0 * f_number**2 * (1.0 + magnification) ** 2
    return float(np.pi * transmittance / (n2 if equation == "iso12232" else 1.0 + n2))


@dataclass(frozen=True, eq=False)
class ChannelLight:
    """The configured light at the pixels, per colour channel, integrated once.

    Parameters
    ----------
    wavelengths : (n,) float64, nm
        The working grid.
    photon_flux : (n,) float64
        Photons per second and nm on the optical axis from a white (reflectance 1) scene, on a pixel's area (its
        whole square: the aperture's share is the optical image's).
    qe : (n, 3) float64
        The channels' quantum efficiency on the grid (the IR cut applied).
    rates_e_per_s : (3,) float64
        Photo-electrons per second of each channel from a white scene on a pixel's area: the integral of
        ``photon_flux * qe``.
    mix : (3, 3) float64
        Linear-sRGB reflectances to the channels' relative signal (1 for a white): row c, column k is channel c's
        response to the Mallett-Yuksel basis spectrum of primary k, over its response to white. Each row sums to 1,
        so a grey of reflectance r gives r in every channel.
    focal_plane_lux : float
        The focal-plane illuminance on the axis from a white scene, lux.
    """

    wavelengths: np.ndarray
    photon_flux: np.ndarray
    qe: np.ndarray
    rates_e_per_s: np.ndarray
    mix: np.ndarray
    focal_plane_lux: float

    def reflectance_channels(self, reflectance: np.ndarray, wavelengths: np.ndarray) -> np.ndarray:
        """The channels' relative signal of reflectance spectra: :func:`reflectance_channels` with this light."""
        return reflectance_channels(self, reflectance, wavelengths)


def _on_grid(wl: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """``values`` (n, ...) tabulated at ``wl``, linearly interpolated at ``grid`` (inside ``wl``'s range)."""
    values = np.asarray(values, float)
    if values.ndim == 1:
        return np.interp(grid, wl, values)
    return np.column_stack([np.interp(grid, wl, values[:, j]) for j in range(values.shape[1])])


def integrate(illuminant: str, illuminance_lux: float, spectral_qe, qe_peak: float | None, flat_qe,
              ir_cut_nm: float | None, camera_k: float, area_um2: float) -> ChannelLight:
    """The light at the pixels, integrated over wavelength per colour channel (see the module docstring).

    :class:`cmosnoise.model.focal_plane.FocalPlane` reads the configuration's light, lens and pixel once and calls
    this with the numbers; the result is kept for the same numbers.

    Parameters
    ----------
    illuminant : str
        ``light.illuminant`` (:func:`illuminant_spectrum`).
    illuminance_lux : float
        The illuminance on the scene, lux (a luminance L as ``pi L``).
    spectral_qe, qe_peak
        ``light.spectral_qe`` (rows as nested tuples) and ``light.qe_peak`` (:func:`qe_spectrum`).
    flat_qe : float, (3,) tuple or None
        ``sensor.quantum_efficiency``, for a flat QE.
    ir_cut_nm : float or None
        An ideal IR-cut filter's edge, nm.
    camera_k : float
        The camera equation's factor (:func:`camera_factor`).
    area_um2 : float
        The area the rates are for, um^2: the pixel's (its aperture's share is the optical image's to apply).

    Returns
    -------
    ChannelLight

    Raises
    ------
    CmosnoiseError
        An unknown illuminant, a QE table outside [0, 1] or with non-increasing wavelengths, spectra that do not
        overlap.
    """
    rows = spectral_qe
    if isinstance(rows, list):
        rows = tuple(tuple(r) for r in rows)
    flat = tuple(flat_qe) if isinstance(flat_qe, (list, tuple)) else flat_qe
    return _integrate(illuminant, float(illuminance_lux), rows, qe_peak, flat, ir_cut_nm, float(camera_k),
                      float(area_um2))


#: the least rate a channel may collect, e-/s (one electron in 30 000 years): below it the light's integrals are
#: rounding, and a scene's signal relative to it overflows
MIN_RATE_E_PER_S = 1e-12


@functools.lru_cache(maxsize=16)
def _integrate(illuminant, e_lux, spectral_qe, qe_peak, flat_qe, ir_cut_nm, k, area_um2) -> ChannelLight:
    if not e_lux > 0:
        raise CmosnoiseError(f"light.illuminance_lux = {e_lux:g}: the light needs an illuminance above 0 (a dark "
                             "picture: a scene of flat:0, or the dark frames, at any illuminance)")
    s_wl, s_pow = illuminant_spectrum(illuminant)
    table = [list(r) for r in spectral_qe] if isinstance(spectral_qe, tuple) else spectral_qe
    q_wl, q_tab = qe_spectrum(table, qe_peak, flat_qe)
    lo, hi = max(s_wl[0], q_wl[0]), min(s_wl[-1], q_wl[-1])
    if ir_cut_nm is not None:
        hi = min(hi, ir_cut_nm)
    if hi - lo < STEP_NM:
        raise CmosnoiseError(f"light: the illuminant ({s_wl[0]:g}-{s_wl[-1]:g} nm) and the quantum efficiency "
                             f"({q_wl[0]:g}-{q_wl[-1]:g} nm) do not overlap"
                             + (f" below the IR cut at {ir_cut_nm:g} nm" if ir_cut_nm else ""))
    grid = np.arange(np.ceil(lo / STEP_NM) * STEP_NM, hi + 1e-9, STEP_NM)
    # 1. the illuminant scaled to its illuminance: 683 * integral(E V) = E_v, over the illuminant's own range
    v_wl, v = photopic_efficiency()
    lum_wl = v_wl[(v_wl >= s_wl[0]) & (v_wl <= s_wl[-1])]
    per_unit = KM_LM_PER_W * _integral(np.interp(lum_wl, s_wl, s_pow) * np.interp(lum_wl, v_wl, v), lum_wl)
    if per_unit <= 0:
        raise CmosnoiseError(f"light.illuminant = {illuminant!r} has no visible light (no power from 360 to "
                             "830 nm): it has no illuminance to scale")
    irradiance = np.interp(grid, s_wl, s_pow) * (e_lux / per_unit)  # W m^-2 nm^-1 on the scene
    # 2.-4. a white Lambertian reflector's radiance, the lens, photons on one pixel
    photon_flux = k * irradiance / np.pi * (grid * 1e-9) / (PLANCK_J_S * LIGHT_M_PER_S) * (area_um2 * 1e-12)
    # 5. electrons per channel
    qe = _on_grid(q_wl, q_tab, grid)
    rates = _integral(photon_flux[None, :] * qe.T, grid)
    if not (rates > 0).all():
        raise CmosnoiseError("light: a colour channel collects no light (its QE is 0 where the illuminant shines)")
    # the RGB up-sampling's basis (normalised to sum to exactly 1, from 0.99999), held at its ends outside 380-780
    colour = _colour()
    basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    b = _on_grid(np.asarray(basis.wavelengths, float), np.asarray(basis.values, float), grid)
    b = b / b.sum(axis=1, keepdims=True)
    response = _integral((photon_flux[None, None, :] * qe.T[:, None, :]) * b.T[None, :, :], grid)  # (3, 3)
    mix = response / response.sum(axis=1, keepdims=True)
    if not (np.isfinite(rates).all() and np.isfinite(mix).all()) or float(rates.min()) < MIN_RATE_E_PER_S:
        raise CmosnoiseError(f"light: the channels collect {', '.join(f'{r:.3g}' for r in rates)} e-/s at "
                             f"light.illuminance_lux = {e_lux:g} of light.illuminant = {illuminant!r} through the "
                             f"QE; each must be a finite rate of at least {MIN_RATE_E_PER_S:g} e-/s (more light, "
                             "or spectra of normal numbers)")
    lux = k * e_lux / np.pi
    for a in (grid, photon_flux, qe, rates, mix):
        a.setflags(write=False)
    return ChannelLight(grid, photon_flux, qe, rates, mix, float(lux))


def reflectance_channels(light: ChannelLight, reflectance: np.ndarray, wavelengths: np.ndarray) -> np.ndarray:
    """Each channel's relative signal (1: a white) of reflectance spectra under the light.

    Parameters
    ----------
    light : ChannelLight
    reflectance : (patches, n) array
        Reflectance spectra, 0 to 1, at ``wavelengths`` (held at their ends beyond them).
    wavelengths : (n,) array, nm

    Returns
    -------
    (patches, 3) float64
        The integral of reflectance x photon flux x QE of each channel over that of a white.
    """
    r = np.atleast_2d(np.asarray(reflectance, float))
    on = np.stack([np.interp(light.wavelengths, wavelengths, row) for row in r])
    weight = light.photon_flux[None, :] * light.qe.T  # (3, n)
    return _integral(on[:, None, :] * weight[None, :, :], light.wavelengths) / light.rates_e_per_s[None, :]


#: the largest multispectral cube read, bytes decoded
MAX_CUBE_BYTES = 2_000_000_000


def read_cube(path: str) -> tuple[np.ndarray, np.ndarray]:
    """A multispectral scene: an ``.npz`` holding ``reflectance`` (rows, cols, n), each pixel's reflectance
    spectrum, 0 to 1 (a radiance relative to a white's), and ``wavelengths_nm`` (n,), increasing, through the
    input gate (its members' decoded size from the zip directory before anything is inflated).

    Parameters
    ----------
    path : str
        The file.

    Returns
    -------
    wavelengths : (n,) float64, nm
    reflectance : (rows, cols, n) float64
    """
    key = "scene"
    members = inputs.npz_members(path, f"{key} cube", MAX_CUBE_BYTES)
    need = {"reflectance.npy", "wavelengths_nm.npy"}
    if not need <= set(members):
        raise CmosnoiseError(f"{key} {path!r}: a multispectral cube is an .npz of 'reflectance' (rows, cols, n) and "
                             f"'wavelengths_nm' (n,); it holds {sorted(m.removesuffix('.npy') for m in members)}")
    try:
        with np.load(inputs.check_regular(path, f"{key} cube"), allow_pickle=False) as z:
            wl = np.asarray(z["wavelengths_nm"], np.float64)
            cube = np.asarray(z["reflectance"])
    except (ValueError, OSError, EOFError) as exc:
        raise CmosnoiseError(f"{key} {path!r} is not a readable .npz file: {exc}") from None
    if cube.ndim != 3 or wl.ndim != 1 or cube.shape[2] != wl.size or wl.size < 2 or cube.dtype.kind not in "uif":
        raise CmosnoiseError(f"{key} {path!r}: 'reflectance' must be (rows, cols, n) real numbers and "
                             f"'wavelengths_nm' (n,); got {cube.shape} {cube.dtype} and {wl.shape}")
    _check_wavelengths(wl, f"{key} {path} wavelengths_nm")
    cube = cube.astype(np.float64)
    if not np.isfinite(cube).all() or (cube < 0).any():
        raise CmosnoiseError(f"{key} {path!r}: every reflectance must be finite and >= 0")
    return wl, cube


def spectral_channels(light: ChannelLight, wavelengths: np.ndarray) -> np.ndarray:
    """The matrix that takes spectra sampled at ``wavelengths`` (held at their ends beyond them, linearly
    interpolated between) to each channel's signal relative to a white's under the light: (3, n). Its rows sum to
    1: a flat reflectance r gives r in every channel.

    Parameters
    ----------
    light : ChannelLight
    wavelengths : (n,) array, nm

    Returns
    -------
    (3, n) float64 array
        :func:`reflectance_channels` of each unit spectrum: a cube's pixels times it are their channels.
    """
    wl = np.asarray(wavelengths, float)
    return reflectance_channels(light, np.eye(wl.size), wl).T


def colorchecker_reflectances() -> tuple[np.ndarray, np.ndarray]:
    """The ColorChecker's 24 reflectance spectra, row by row from "dark skin" to "black" (:data:`COLORCHECKER_SPECTRA`).

    Returns
    -------
    wavelengths : (n,) float64, nm
    reflectance : (24, n) float64
    """
    sds = _colour().SDS_COLOURCHECKERS[COLORCHECKER_SPECTRA]
    first = next(iter(sds.values()))
    return np.asarray(first.wavelengths, float), np.stack([np.asarray(sd.values, float) for sd in sds.values()])
