"""Skin albedo from a layered melanin / haemoglobin absorption model, calibrated to measured
human skin colour (docs/realism.md), and the Individual Typology Angle (ITA).

Spectral model (380-780 nm, 5 nm steps), documented approximations:

* epidermis: Beer-Lambert double pass, ``T = exp(-(f_mel * mu_mel' + mu_car) * d_epi)`` with
  ``d_epi = 0.006`` cm; the eumelanin absorption ``mu_mel = 6.6e11 * lambda^-3.33`` 1/cm
  (Jacques 1998) is flattened by the packaging (sieve) factor of absorbers packed in slabs of
  thickness ``PACKAGING_CM``: ``mu_mel' = mu_mel (1 - exp(-mu_mel l)) / (mu_mel l)``;
  ``mu_car`` is a carotenoid / baseline band (peak ``CAROTENOID_PER_CM`` at 480 nm, 45 nm wide);
* dermis: diffuse reflectance ``R = exp(-4 sqrt(mu_a / (3 (mu_a + mu_s'))))`` with
  ``mu_a = f_hb * mu_blood + (1 - f_hb) * mu_base``, a baseline tissue absorption
  ``0.244 + 85.3 exp(-(lambda - 154)/66.2)`` 1/cm, whole-blood absorption approximated by
  Gaussian bands at 415, 542 and 577 nm, and ``mu_s' = 46 (lambda/500)^-1.42`` 1/cm;
* the upper epidermis (stratum corneum, above the melanin of the basal layer) back-scatters a
  spectrally flat ``TOP_BACKSCATTER`` of the light; layers are added with the
  Kubelka-Munk interreflection ``R = r + (1 - r)^2 X / (1 - r X)``, ``X = T^2 R_dermis``.

``PACKAGING_CM``, ``CAROTENOID_PER_CM`` and ``TOP_BACKSCATTER`` are calibration constants,
fitted so that the model's colours across ITA -55..70 deg fall inside the published
measurements of human skin (docs/realism.md: L* 30-82, a* 8-18, b* 7-25; b* peaks for tan
and brown skin and falls towards very light and dark skin); they are effective values, not
measured tissue properties.

The reflectance spectrum is integrated under D65 with the CIE 1931 observer (colour-science's
``sd_to_XYZ``, which is linear in the spectrum: its weights per wavelength are precomputed in
:mod:`synth.appearance.cie_srgb`, so nothing imports colour-science at run time) and converted
to linear sRGB (Rec.709 primaries), the renderer's working space.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from synth.appearance.cie_srgb import LINEAR_SRGB_TO_XYZ, SPECTRUM_TO_LINEAR_SRGB, WAVELENGTHS
#: The skin parameters where a plan gives none (a frame of an identity without a skin pick, a
#: hand-written plan); planned skins draw both from the catalogue (assets_manifest/skin.toml).
DEFAULT_MELANIN = 0.05
DEFAULT_HAEMOGLOBIN = 0.015

EPIDERMIS_CM = 0.006
PACKAGING_CM = 0.0015
CAROTENOID_PER_CM = 45.0
TOP_BACKSCATTER = 0.03


def _mu_melanin(lam):
    mu = 6.6e11 * lam ** -3.33
    tau = mu * PACKAGING_CM
    return mu * -np.expm1(-tau) / tau


def _mu_carotenoid(lam):
    return CAROTENOID_PER_CM * np.exp(-(((lam - 480.0) / 45.0) ** 2))


def _mu_blood(lam):
    return (3000.0 * np.exp(-(((lam - 415.0) / 18.0) ** 2)) + 270.0 * np.exp(-(((lam - 542.0) / 13.0) ** 2))
            + 280.0 * np.exp(-(((lam - 577.0) / 11.0) ** 2)) + 120.0 * np.exp(-(((lam - 560.0) / 40.0) ** 2))
            + 4.0)


def _mu_base(lam):
    return 0.244 + 85.3 * np.exp(-(lam - 154.0) / 66.2)


def _dermis(haemoglobin, lam):
    hb = np.asarray(haemoglobin, np.float64)[..., None]
    mu_a = hb * _mu_blood(lam) + (1.0 - hb) * _mu_base(lam)
    mu_s = 46.0 * (lam / 500.0) ** -1.42
    return np.exp(-2.0 * _mu_carotenoid(lam) * EPIDERMIS_CM) * np.exp(-4.0 * np.sqrt(mu_a / (3.0 * (mu_a + mu_s))))


def _with_epidermis(melanin, dermis, lam):
    """Reflectance from the dermis (times the melanin-free epidermal passes) and the melanin."""
    m = np.asarray(melanin, np.float64)[..., None]
    x = np.exp(-2.0 * EPIDERMIS_CM * m * _mu_melanin(lam)) * dermis
    r = TOP_BACKSCATTER
    return np.clip(r + (1.0 - r) ** 2 * x / (1.0 - r * x), 0.0, 1.0)


def _check(melanin, haemoglobin) -> None:
    m, hb = np.asarray(melanin, np.float64), np.asarray(haemoglobin, np.float64)
    if np.any(~((m >= 0) & (m <= 1))) or np.any(~((hb >= 0) & (hb <= 1))):
        raise ValueError(f"melanin and haemoglobin fractions must be in [0, 1], got {melanin}, {haemoglobin}")


def reflectance(melanin, haemoglobin, lam: np.ndarray = WAVELENGTHS) -> np.ndarray:
    """Diffuse reflectance spectra (..., len(lam)) for melanin and blood volume fractions in [0, 1]
    (scalars or arrays of one shape)."""
    _check(melanin, haemoglobin)
    return _with_epidermis(melanin, _dermis(haemoglobin, lam), lam)


def _spectrum_to_rgb() -> np.ndarray:
    """(3, len(WAVELENGTHS)) linear map spectrum -> linear sRGB: colour-science's D65 / CIE 1931
    integration (linear in the spectrum) of each unit impulse, then XYZ -> sRGB, precomputed
    (:mod:`synth.appearance.cie_srgb`)."""
    return SPECTRUM_TO_LINEAR_SRGB


def albedos(melanin, haemoglobin) -> np.ndarray:
    """(..., 3) linear sRGB albedos for arrays of melanin / haemoglobin fractions (vectorised)."""
    rgb = reflectance(melanin, haemoglobin) @ _spectrum_to_rgb().T
    return np.clip(rgb, 0.0, 1.0)


@lru_cache(maxsize=4096)
def _albedo_cached(melanin: float, haemoglobin: float) -> tuple[float, float, float]:
    rgb = albedos(melanin, haemoglobin)
    return float(rgb[0]), float(rgb[1]), float(rgb[2])


def skin_albedo(melanin: float, haemoglobin: float) -> tuple[float, float, float]:
    """Linear sRGB albedo for the given melanin / haemoglobin fractions (rounded inputs cache);
    what the render worker gives the skin shader."""
    return _albedo_cached(round(float(melanin), 7), round(float(haemoglobin), 7))


#: Linear sRGB (Rec.709 primaries, D65) -> CIE XYZ: the inverse of the conversion the spectra
#: take to linear sRGB (:mod:`synth.appearance.cie_srgb`, colour-science's sRGB matrices).
_SRGB_TO_XYZ = LINEAR_SRGB_TO_XYZ
_D65_XYZ = _SRGB_TO_XYZ.sum(axis=1)  # the white (1, 1, 1)


def cielab(linear_srgb) -> np.ndarray:
    """(..., 3) CIELAB (D65 white) of linear sRGB colours (..., 3)."""
    xyz = np.asarray(linear_srgb, np.float64) @ _SRGB_TO_XYZ.T / _D65_XYZ
    eps, kappa = 216.0 / 24389.0, 24389.0 / 27.0
    f = np.where(xyz > eps, np.cbrt(xyz), (kappa * xyz + 16.0) / 116.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])],
                    axis=-1)


def linear_srgb_from_cielab(lab) -> np.ndarray:
    """(..., 3) linear sRGB of CIELAB (D65 white) colours (..., 3): the inverse of :func:`cielab`."""
    lab = np.asarray(lab, np.float64)
    fy = (lab[..., 0] + 16.0) / 116.0
    f = np.stack([fy + lab[..., 1] / 500.0, fy, fy - lab[..., 2] / 200.0], axis=-1)
    eps, kappa = 216.0 / 24389.0, 24389.0 / 27.0
    xyz = np.where(f ** 3 > eps, f ** 3, (116.0 * f - 16.0) / kappa) * _D65_XYZ
    return xyz @ np.linalg.inv(_SRGB_TO_XYZ).T


def individual_typology_angle(linear_srgb) -> np.ndarray:
    """The Individual Typology Angle (degrees) of linear sRGB colours (..., 3):
    ``ITA = arctan((L* - 50) / b*)`` in CIELAB under D65 (the dermatology scale of Chardon et
    al. 1991: > 55 very light, 41-55 light, 28-41 intermediate, 10-28 tan, -30-10 brown,
    < -30 dark)."""
    lab = cielab(linear_srgb)
    return np.degrees(np.arctan2(lab[..., 0] - 50.0, lab[..., 2]))


def melanin_for_ita(ita_deg, haemoglobin, iterations: int = 32) -> np.ndarray:
    """Melanin fractions in [0, 1] whose albedo has the given ITA (degrees) at the given
    haemoglobin fractions (arrays of one shape; vectorised bisection, to 2**-32: ITA falls
    monotonically with melanin). Targets outside the model's reach give the end of [0, 1]
    nearest to them."""
    ita = np.asarray(ita_deg, np.float64)
    hb = np.broadcast_to(np.asarray(haemoglobin, np.float64), ita.shape)
    _check(0.0, hb)
    dermis, to_rgb = _dermis(hb, WAVELENGTHS), _spectrum_to_rgb().T
    lo, hi = np.zeros(ita.shape), np.ones(ita.shape)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        rgb = np.clip(_with_epidermis(mid, dermis, WAVELENGTHS) @ to_rgb, 0.0, 1.0)
        above = individual_typology_angle(rgb) > ita  # still too light: more melanin
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return 0.5 * (lo + hi)

#: The six ITA categories (Chardon et al. 1991; Del Bino et al. 2006), lightest first, with
#: their lower bounds in degrees (the lightest has no upper bound, the darkest no lower one).
ITA_CATEGORIES: tuple[tuple[str, float], ...] = (
    ("very_light", 55.0), ("light", 41.0), ("intermediate", 28.0), ("tan", 10.0), ("brown", -30.0),
    ("dark", -np.inf))


def ita_category(ita_deg) -> np.ndarray:
    """Index into :data:`ITA_CATEGORIES` (0 = very light .. 5 = dark) of ITA values (degrees)."""
    bounds = np.array([b for _, b in ITA_CATEGORIES[:-1]])  # 55, 41, 28, 10, -30
    return np.sum(np.asarray(ita_deg, np.float64)[..., None] <= bounds, axis=-1)
