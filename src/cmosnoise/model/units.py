"""Unit conversions for dark current.

Rates are carried internally in electrons per second per pixel (e-/s).
Data sheets also quote dark current as a current per pixel in attoampere
(1 aA = 1e-18 C/s = 6.241509 e-/s) or as a current density in nA/cm^2, which
needs the pixel pitch.

Examples
--------
>>> from cmosnoise import units
>>> round(units.aa_to_e_per_s(250), 1)   # 250 aA of dark current per pixel, in e-/s
1560.4
"""

ELEMENTARY_CHARGE_C = 1.602176634e-19
#: electrons per second in one attoampere (1e-18 A / q)
E_PER_S_PER_AA = 1e-18 / ELEMENTARY_CHARGE_C


def aa_to_e_per_s(current_aa: float) -> float:
    """Convert a per-pixel current in aA to a rate in e-/s.

    Parameters
    ----------
    current_aa : float or array
        Dark current per pixel, aA (1e-18 A).

    Returns
    -------
    float or array, e-/s
    """
    return current_aa * E_PER_S_PER_AA


def e_per_s_to_aa(rate_e_per_s: float) -> float:
    """Convert a per-pixel rate in e-/s to a current in aA.

    Parameters
    ----------
    rate_e_per_s : float or array
        Dark current per pixel, e-/s.

    Returns
    -------
    float or array, aA
    """
    return rate_e_per_s / E_PER_S_PER_AA


def na_per_cm2_to_e_per_s(density_na_per_cm2: float, pixel_pitch_um: float) -> float:
    """Convert a dark-current density in nA/cm^2 to e-/s for a square pixel.

    The pixel area is ``pixel_pitch_um**2`` (um^2, 1 um^2 = 1e-8 cm^2).

    Parameters
    ----------
    density_na_per_cm2 : float or array
        Dark-current density, nA/cm^2.
    pixel_pitch_um : float
        The pixel's pitch, um.

    Returns
    -------
    float or array, e-/s per pixel
    """
    area_cm2 = (pixel_pitch_um * 1e-4) ** 2
    current_a = density_na_per_cm2 * 1e-9 * area_cm2
    return current_a / ELEMENTARY_CHARGE_C
