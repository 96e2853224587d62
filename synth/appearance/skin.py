"""Skin albedo from a two-layer melanin / haemoglobin absorption model, via colour-science.

Spectral model (380-780 nm, 5 nm steps), documented approximations:

* epidermis: Beer-Lambert double pass, ``T = exp(-f_mel * mu_mel * d_epi)``, with the
  eumelanin absorption ``mu_mel = 6.6e11 * lambda^-3.33`` 1/cm (Jacques 1998) and
  ``d_epi = 0.006`` cm;
* dermis: diffuse reflectance ``R = exp(-4 sqrt(mu_a / (3 (mu_a + mu_s'))))`` with
  ``mu_a = f_hb * mu_blood + (1 - f_hb) * mu_base``, a baseline tissue absorption
  ``0.244 + 85.3 exp(-(lambda - 154)/66.2)`` 1/cm, whole-blood absorption approximated by
  Gaussian bands at 415, 542 and 577 nm, and ``mu_s' = 46 (lambda/500)^-1.42`` 1/cm.

The reflectance spectrum is integrated under D65 with the CIE 1931 observer and converted
to linear sRGB (Rec.709 primaries), the renderer's working space. The result is an albedo in
[0, 1]; parameters are recorded in the frame JSON.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

WAVELENGTHS = np.arange(380.0, 781.0, 5.0)


def _mu_melanin(lam):
    return 6.6e11 * lam ** -3.33


def _mu_blood(lam):
    return (3000.0 * np.exp(-(((lam - 415.0) / 18.0) ** 2)) + 270.0 * np.exp(-(((lam - 542.0) / 13.0) ** 2))
            + 280.0 * np.exp(-(((lam - 577.0) / 11.0) ** 2)) + 120.0 * np.exp(-(((lam - 560.0) / 40.0) ** 2))
            + 4.0)


def _mu_base(lam):
    return 0.244 + 85.3 * np.exp(-(lam - 154.0) / 66.2)


def reflectance(melanin: float, haemoglobin: float, lam: np.ndarray = WAVELENGTHS) -> np.ndarray:
    """Diffuse reflectance spectrum for melanin and blood volume fractions in [0, 1]."""
    if not (0.0 <= melanin <= 1.0 and 0.0 <= haemoglobin <= 1.0):
        raise ValueError(f"melanin and haemoglobin fractions must be in [0, 1], got {melanin}, {haemoglobin}")
    t_epi = np.exp(-melanin * _mu_melanin(lam) * 0.006)
    mu_a = haemoglobin * _mu_blood(lam) + (1.0 - haemoglobin) * _mu_base(lam)
    mu_s = 46.0 * (lam / 500.0) ** -1.42
    r_derm = np.exp(-4.0 * np.sqrt(mu_a / (3.0 * (mu_a + mu_s))))
    return np.clip(t_epi * t_epi * r_derm, 0.0, 1.0)


@lru_cache(maxsize=4096)
def _albedo_cached(melanin: float, haemoglobin: float) -> tuple[float, float, float]:
    import colour

    sd = colour.SpectralDistribution(dict(zip(WAVELENGTHS.tolist(), reflectance(melanin, haemoglobin).tolist())))
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = colour.sd_to_XYZ(sd, cmfs=cmfs, illuminant=colour.SDS_ILLUMINANTS["D65"]) / 100.0
    rgb = colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False)
    rgb = np.clip(rgb, 0.0, 1.0)
    return float(rgb[0]), float(rgb[1]), float(rgb[2])


def skin_albedo(melanin: float, haemoglobin: float) -> tuple[float, float, float]:
    """Linear sRGB albedo for the given melanin / haemoglobin fractions (rounded inputs cache)."""
    return _albedo_cached(round(float(melanin), 4), round(float(haemoglobin), 4))


#: Linear sRGB (Rec.709 primaries, D65) -> CIE XYZ, IEC 61966-2-1.
_SRGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                         [0.2126729, 0.7151522, 0.0721750],
                         [0.0193339, 0.1191920, 0.9503041]])
_D65_XYZ = _SRGB_TO_XYZ.sum(axis=1)  # the white (1, 1, 1)


def individual_typology_angle(linear_srgb) -> np.ndarray:
    """The Individual Typology Angle (degrees) of linear sRGB colours (..., 3):
    ``ITA = arctan((L* - 50) / b*)`` in CIELAB under D65 (the dermatology scale: > 55 very
    light, 41-55 light, 28-41 intermediate, 10-28 tan, -30-10 brown, < -30 dark)."""
    xyz = np.asarray(linear_srgb, np.float64) @ _SRGB_TO_XYZ.T / _D65_XYZ
    eps, kappa = 216.0 / 24389.0, 24389.0 / 27.0
    f = np.where(xyz > eps, np.cbrt(xyz), (kappa * xyz + 16.0) / 116.0)
    L = 116.0 * f[..., 1] - 16.0
    b = 200.0 * (f[..., 1] - f[..., 2])
    return np.degrees(np.arctan2(L - 50.0, b))
