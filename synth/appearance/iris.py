"""Iris colour from a small physical model (pure numpy): melanin absorption over a scattering stroma.

Physical reasoning (documented approximations):

* The iris has no blue or green pigment. Its colour comes from (a) eumelanin (and a little
  pheomelanin) in the anterior border layer and stroma, which absorbs strongly at short
  wavelengths (``mu ~ lambda^-3.33``, as in skin, Jacques 1998), and (b) scattering of light
  by the stroma's collagen fibrils and cells, small compared with the wavelength, so close
  to Rayleigh/Tyndall (``~ lambda^-4``): short wavelengths are scattered back, long ones
  pass through and are absorbed by the posterior iris pigment epithelium, which is heavily
  pigmented in everyone (a nearly black backing).
* Little melanin: the back-scattered light is blue (blue eyes); a weaker-scattering stroma
  gives a greyer, darker blue-grey (grey eyes). Some melanin (with its pheomelanin share,
  which absorbs blue more gently and looks yellow-brown) filters the blue scattering into
  green / hazel. Much melanin: absorption dominates and the diffuse reflectance of the
  pigmented layer is brown, darker as melanin grows.

Model, per wavelength (380-780 nm, 10 nm):

``R = T^2 * (S + (1 - S)^2 * R_back) + (1 - T^2) * R_mel`` with the anterior-layer double-pass
transmission ``T^2 = exp(-2 (c_eu m_eu (lambda/500)^-3.33 + c_ph m_ph (lambda/500)^-2))``,
stromal scattering reflectance ``S = s (1 - exp(-k (lambda/500)^-4))``, a dark backing
``R_back = 0.02`` and the melanin layer's own diffuse reflectance ``R_mel`` (a brown
spectrum rising toward red). Melanin ``m`` in [0, 1] is split into eu- and pheomelanin
(pheomelanin share peaking at intermediate ``m``: hazel/green). The spectrum is integrated
with an analytic fit of the CIE 1931 colour-matching functions (Wyman, Sloan & Shirley
2013) under an equal-energy illuminant, converted to linear sRGB and white-balanced so that
a perfect reflector maps to (1, 1, 1) (the renderer's uniform white environment).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from synth.assets.params import IrisParams

WAVELENGTHS = np.arange(380.0, 781.0, 10.0)

_XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                         [-0.9692660, 1.8760108, 0.0415560],
                         [0.0556434, -0.2040259, 1.0572252]])


def _g(x, mu, s1, s2):
    return np.exp(-0.5 * ((x - mu) / np.where(x < mu, s1, s2)) ** 2)


def cie_cmf(lam):
    """CIE 1931 2-degree colour-matching functions, multi-lobe Gaussian fit (Wyman et al. 2013)."""
    x = 1.056 * _g(lam, 599.8, 37.9, 31.0) + 0.362 * _g(lam, 442.0, 16.0, 26.7) - 0.065 * _g(lam, 501.1, 20.4, 26.2)
    y = 0.821 * _g(lam, 568.8, 46.9, 40.5) + 0.286 * _g(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _g(lam, 437.0, 11.8, 36.0) + 0.681 * _g(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], -1)


def spectrum_to_linear_srgb(refl, lam=WAVELENGTHS):
    cmf = cie_cmf(lam)
    xyz = (refl[..., :, None] * cmf).sum(-2)
    white = cmf.sum(0)
    rgb = xyz @ _XYZ_TO_SRGB.T
    rgb_w = white @ _XYZ_TO_SRGB.T
    return rgb / rgb_w


def iris_reflectance(melanin: float, stroma_scatter: float = 0.7, lam=WAVELENGTHS):
    """Diffuse reflectance spectrum of the iris (see module docstring)."""
    m = float(np.clip(melanin, 0.0, 1.0))
    s = float(np.clip(stroma_scatter, 0.0, 1.0))
    x = lam / 500.0
    pheo = 0.35 * m * np.exp(-((m - 0.45) / 0.22) ** 2)  # yellow-brown share, peaks around hazel/green
    eu = m ** 1.6
    tau = 1.6 * eu * x ** -3.33 + 1.1 * pheo * x ** -2.0
    T2 = np.exp(-2.0 * tau)
    S = (0.15 + 0.45 * s) * (1.0 - np.exp(-0.9 * x ** -4.0))
    r_back = 0.02
    r_mel = 0.02 + 0.16 * np.clip((lam - 450.0) / 330.0, 0, 1) ** 1.5  # brown pigment layer
    return np.clip(T2 * (S + (1.0 - S) ** 2 * r_back) + (1.0 - T2) * r_mel, 0.0, 1.0)


def iris_colour(melanin: float, stroma_scatter: float = 0.7) -> tuple[float, float, float]:
    """Linear-sRGB iris albedo for melanin in [0, 1] (blue/grey low, brown high)."""
    rgb = spectrum_to_linear_srgb(iris_reflectance(melanin, stroma_scatter))
    rgb = np.clip(rgb, 0.0, 1.0)
    return float(rgb[0]), float(rgb[1]), float(rgb[2])


def iris_palette(params: IrisParams | Mapping) -> dict[str, tuple[float, float, float]]:
    """Colours the iris shader mixes: base, light fibres, dark crypts, inner (collarette)
    zone, limbal ring. All from the same model at shifted melanin / scattering (``params``:
    an iris pick's, :class:`synth.assets.params.IrisParams`, where the defaults live)."""
    p = IrisParams.of("iris", params)
    m, s, het = float(p.melanin), float(p.stroma_scatter), p.heterochromia
    base = iris_colour(m, s)
    light = iris_colour(max(0.0, m - 0.12), min(1.0, s + 0.15))
    dark = tuple(0.45 * c for c in iris_colour(min(1.0, m + 0.2), s))
    inner = iris_colour(min(1.0, m + 0.25 + 0.35 * het), s) if het > 0 else iris_colour(min(1.0, m + 0.08), s)
    limbal = tuple(0.25 * c for c in iris_colour(min(1.0, m + 0.3), s))
    return {"base": base, "light": light, "dark": dark, "inner": inner, "limbal": limbal}


def pupil_ratio(pupil_dilation: float) -> float:
    """Pupil radius / iris radius: 2-8 mm pupil in an ~11.7 mm iris -> 0.17 .. 0.68."""
    return float(0.17 + 0.51 * np.clip(pupil_dilation, 0.0, 1.0))
