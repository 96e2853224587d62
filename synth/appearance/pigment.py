"""Hair pigmentation: named hair colours as melanin concentrations (pure numpy, no bpy).

Hair colour is modelled as in physically based hair shading (d'Eon et al. 2011, Chiang et al.
2016): the fibre's absorption coefficient is a sum of eumelanin (brown-black) and
pheomelanin (red-yellow) contributions,

    sigma_a = c_eu * EUMELANIN_SIGMA + c_pheo * PHEOMELANIN_SIGMA      (per unit fibre width)

with the per-unit-concentration coefficients Cycles uses. Blender's Principled Hair BSDF in
its "Melanin" parametrisation takes two numbers instead of the concentrations:

    Melanin         m = 1 - exp(-(c_eu + c_pheo))        (in [0, 1), perceptually linear)
    Melanin Redness r = c_pheo / (c_eu + c_pheo)

which Cycles maps back with ``c = -log(1 - m)``, ``c_eu = c (1 - r)``, ``c_pheo = c r``
(intern/cycles/kernel/svm/closure.h). :func:`to_blender` / :func:`from_blender` are exact
inverses of that mapping.

Grey and white hair are mixtures of pigmented and unpigmented fibres: ``white_fraction`` is
the share of (almost) unpigmented strands a renderer mixes in (the rigs pick them per strand
from the Hair Info "Random" output).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: Absorption per unit concentration (linear Rec.709 RGB), as in Cycles'
#: bsdf_principled_hair_sigma_from_concentration.
EUMELANIN_SIGMA = np.array([0.506, 0.841, 1.653])
PHEOMELANIN_SIGMA = np.array([0.343, 0.733, 1.924])

#: Concentrations of unpigmented (white) fibres: a trace of pheomelanin gives the slight
#: yellow of real white hair.
WHITE_FIBRE = (0.015, 0.02)


@dataclass(frozen=True)
class HairPigment:
    """One hair colour: melanin concentrations and the unpigmented-fibre share."""

    eumelanin: float
    pheomelanin: float
    white_fraction: float = 0.0

    @property
    def melanin(self) -> float:
        """Blender's "Melanin" input."""
        return to_blender(self.eumelanin, self.pheomelanin)[0]

    @property
    def redness(self) -> float:
        """Blender's "Melanin Redness" input."""
        return to_blender(self.eumelanin, self.pheomelanin)[1]

    def absorption(self) -> np.ndarray:
        return absorption(self.eumelanin, self.pheomelanin)

    def as_dict(self) -> dict:
        m, r = to_blender(self.eumelanin, self.pheomelanin)
        return {"eumelanin": float(self.eumelanin), "pheomelanin": float(self.pheomelanin),
                "melanin": float(m), "melanin_redness": float(r), "white_fraction": float(self.white_fraction),
                "approx_rgb": [float(x) for x in approx_reflectance(self.eumelanin, self.pheomelanin)]}


#: The manifest's colour names (assets_manifest/hair.toml) -> concentrations. Values follow
#: the ranges used in the hair-rendering literature (black ~8, brown ~1.3, blonde ~0.3
#: eumelanin; red hair is pheomelanin-dominated).
COLOURS: dict[str, HairPigment] = {
    "black": HairPigment(8.0, 0.3),
    "dark_brown": HairPigment(3.0, 0.35),
    "brown": HairPigment(1.3, 0.3),
    "light_brown": HairPigment(0.7, 0.25),
    "blonde": HairPigment(0.22, 0.14),
    "red": HairPigment(0.25, 1.7),
    "grey": HairPigment(1.5, 0.2, white_fraction=0.55),
    "white": HairPigment(0.6, 0.12, white_fraction=0.93),
}

#: A darker neighbour per colour (eyelashes are usually darker than scalp hair).
DARKER = {"white": "grey", "grey": "dark_brown", "blonde": "light_brown", "light_brown": "brown",
          "brown": "dark_brown", "red": "red", "dark_brown": "black", "black": "black"}


def absorption(eumelanin, pheomelanin) -> np.ndarray:
    """(..., 3) absorption coefficient sigma_a (per unit fibre width) of the concentrations."""
    eu = np.asarray(eumelanin, np.float64)[..., None]
    ph = np.asarray(pheomelanin, np.float64)[..., None]
    return eu * EUMELANIN_SIGMA + ph * PHEOMELANIN_SIGMA


def to_blender(eumelanin, pheomelanin) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Concentrations -> (Melanin, Melanin Redness) of Blender's Principled Hair BSDF."""
    eu = np.asarray(eumelanin, np.float64)
    ph = np.asarray(pheomelanin, np.float64)
    if np.any(eu < 0) or np.any(ph < 0):
        raise ValueError("melanin concentrations must be >= 0")
    total = eu + ph
    m = -np.expm1(-total)
    r = np.where(total > 0, ph / np.where(total > 0, total, 1.0), 0.0)
    if m.ndim == 0:
        return float(m), float(r)
    return m, r


def from_blender(melanin, redness) -> tuple[np.ndarray | float, np.ndarray | float]:
    """(Melanin, Melanin Redness) -> concentrations, exactly as Cycles maps them."""
    m = np.asarray(melanin, np.float64)
    r = np.asarray(redness, np.float64)
    c = -np.log(np.maximum(1.0 - m, 1e-4))
    eu, ph = c * (1.0 - r), c * r
    if eu.ndim == 0:
        return float(eu), float(ph)
    return eu, ph


def _roughness_scale(radial_roughness: float) -> float:
    b = float(radial_roughness)
    return 5.969 - 0.215 * b + 2.532 * b ** 2 - 10.73 * b ** 3 + 5.574 * b ** 4 + 0.245 * b ** 5


def approx_reflectance(eumelanin, pheomelanin, radial_roughness: float = 0.3) -> np.ndarray:
    """(..., 3) approximate multiple-scattering albedo (linear RGB) of a hair volume with these
    concentrations: the inverse of Chiang et al.'s colour -> absorption mapping that Cycles uses
    for its "Direct coloring" parametrisation. For previews, tests and sanity checks."""
    s = absorption(eumelanin, pheomelanin)
    return np.exp(-np.sqrt(s) * _roughness_scale(radial_roughness))


def pigment(name: str) -> HairPigment:
    try:
        return COLOURS[name]
    except KeyError:
        raise ValueError(f"unknown hair colour {name!r}; known: {sorted(COLOURS)}") from None


def sample(name: str, rng: np.random.Generator, spread: float = 0.12) -> HairPigment:
    """The named colour with a small per-identity variation: concentrations jittered by a
    log-normal factor (sd ``spread``), the white share by +-0.08 (grey/white only)."""
    p = pigment(name)
    f = np.exp(rng.normal(0.0, spread, 2))
    wf = p.white_fraction
    if wf > 0:
        wf = float(np.clip(wf + rng.uniform(-0.08, 0.08), 0.0, 1.0))
    return replace(p, eumelanin=float(p.eumelanin * f[0]), pheomelanin=float(p.pheomelanin * f[1]), white_fraction=wf)


def shaft_darkness(p: HairPigment) -> float:
    """How dark a sparse cover of these hairs (stubble, its shadow under the skin) reads over
    skin, 0..1: ``1 - exp(-(eumelanin + 0.3 pheomelanin))`` of the pigmented share. Black and
    dark brown about 0.95-1, brown 0.75, light brown 0.54, red 0.53, blonde 0.23, grey 0.36,
    white 0.03: fair stubble barely shows, dark stubble shows as a grey shadow."""
    return float((1.0 - p.white_fraction) * (1.0 - np.exp(-(p.eumelanin + 0.3 * p.pheomelanin))))


def darker(name: str) -> str:
    return DARKER.get(name, name)
