"""Skin reflectance beyond the albedo (pure numpy): subsurface radii, the two specular lobes,
and which surface details a render can show.

**Subsurface radius per channel.** Jensen et al. 2001 ("A practical model for subsurface light
transport", Table 1, skin 1) measured the reduced scattering and absorption coefficients of
skin in red, green and blue: ``sigma_s' = (0.74, 0.88, 1.01)`` and ``sigma_a = (0.032, 0.17,
0.48)`` per mm. The diffuse falloff distance is ``1 / sigma_tr`` with ``sigma_tr = sqrt(3
sigma_a (sigma_a + sigma_s'))``: (3.67, 1.37, 0.68) mm, red light scattering furthest. Cycles'
random-walk subsurface takes these as its per-channel radius; the plan's
``subsurface_radius_scale`` (0.8-1.2) scales all three.

**Two specular lobes** (skin's specular reflection is better fitted by two microfacet lobes
than by one: d'Eon & Luebke 2007, GPU Gems 3 ch. 14; Weyrich et al. 2006 measured roughness
0.3-0.5 varying over the face): the Principled base specular is the broad lobe (the sampled
``roughness``, 0.35-0.6: the stratum corneum's micro-relief) and the clear coat the sharp one
(``SHARP_LOBE_RATIO`` x that roughness, IOR 1.45 of sebum), a thin oily film whose weight
grows with ``oiliness`` (``COAT_WEIGHT`` + ``COAT_OIL`` x oiliness; more in the T-zone, where
the skin-detail rig raises it).

**Model only what the scene shows.** A bump layer whose pattern repeats every ``period`` metres
is resolved when one pixel covers at most half a period on the face (Nyquist) and not at all
when a pixel covers a whole period or more. :func:`detail_weight` is 1 at
``period >= 2 x pixel``, 0 at ``period <= pixel``, linear in between; the layer's bump
strength is multiplied by it, and at 0 its nodes are not built at all. What a skipped (or
faded) layer would have done below the pixel, spreading the reflected light, is kept by
widening the broad lobe: ``roughness' = sqrt(roughness^2 + (1 - w) slope_variance)``
(Toksvig 2005: the variance of unresolved normals adds to the microfacet slope variance).
The same rule fades the rig's albedo layers (freckles, age spots, the stubble shadow): a
spot pattern whose spots span at most one pixel is replaced by its mean, the area fraction it
darkens (:data:`VORONOI_F1_BELOW`, :data:`NOISE_FAC_MEAN`), a flat tint over the layer's mask.
Left to the sampler, sub-pixel spots are only per-pixel sampling noise at ``preview``'s 16
samples, and their nodes cost shading time for nothing. (The camouflage-like patches seen over
the beard area of stubble identities were not this: they came from the stubble shadow's
strength and the beard region's hard edge, blender_scripts/assets/skin_detail.py.) The pixel
footprint is that of the identity's finest view, ``distance / f_x``
(:func:`pixel_footprint_m`), so all views of one identity share one material (views are camera
moves of one scene).
"""

from __future__ import annotations

import numpy as np

#: Jensen et al. 2001, skin 1, per mm (R, G, B)
SIGMA_S_REDUCED = (0.74, 0.88, 1.01)
SIGMA_A = (0.032, 0.17, 0.48)

#: Wrinkle depth (0..1) where a plan gives none: the middle of the catalogue's range
#: (assets_manifest/skin.toml), which planned skins draw from.
DEFAULT_WRINKLE_DEPTH = 0.5

#: sharp lobe roughness / broad lobe roughness; sharp lobe IOR (sebum); its weight
SHARP_LOBE_RATIO = 0.45
SHARP_LOBE_IOR = 1.45
COAT_WEIGHT, COAT_OIL = 0.12, 0.35

#: detail layers: (period in metres at scale 1, slope variance folded into roughness when unresolved)
PORES = (0.0007, 0.02)  # pore spacing ~0.5-1 mm on the cheeks and nose
FINE_LINES = (0.0022, 0.015)  # the micro-relief's grooves (the skin's furrow network)
WRINKLES = (0.011, 0.0)  # forehead bands, crow's feet, nasolabial folds

#: albedo layers of the skin-detail rig (blender_scripts/assets/skin_detail.py): Voronoi cell
#: size in metres and the spot radius in cells (spots are cells whose random colour is below a
#: threshold, within that radius of the cell's feature point), and the stubble noise's period
FRECKLES = (1.0 / 450.0, 0.35)
AGE_SPOTS = (1.0 / 60.0, 0.25)
STUBBLE_PERIOD_M = 1.0 / 2500.0
#: mottling: uneven melanin and blood in the skin at millimetre scales, an fBm noise (Blender's
#: Noise texture, 4 octaves from MOTTLE_PERIOD_M down) that multiplies the albedo by
#: 1 - MOTTLE_AMPLITUDE * (fac - 0.5) * MOTTLE_TINT per channel (mean 1: the calibrated skin colour
#: stays; the darker patches are browner and redder, as melanin and haemoglobin absorb green and
#: blue more). Set against real photos with benchmarks/skin_spectrum.py (docs/realism.md)
MOTTLE_PERIOD_M = 0.008
MOTTLE_DETAIL = 3.0
MOTTLE_ROUGHNESS = 0.7
MOTTLE_AMPLITUDE = 0.9
MOTTLE_TINT = (0.8, 1.0, 1.1)
#: area fraction of a 3D slice of Blender's 4D Voronoi (randomness 1) whose distance to the
#: nearest feature point is below r cells (numpy Monte Carlo over 400,000 points, 3^4
#: neighbour cells; checked against Cycles in tests/blender/test_skin_layers.py)
VORONOI_F1_BELOW = {0.25: 0.0194, 0.35: 0.0723}
#: mean of Blender's Noise texture ``Fac`` (normalised fBm around 0.5)
NOISE_FAC_MEAN = 0.5

#: footprint assumed without cameras (unit tests): a 0.2 m face over 60 % of the image
FACE_WIDTH_M, FACE_FILL = 0.2, 0.6


def diffuse_mean_free_path_mm(sigma_a=SIGMA_A, sigma_s_reduced=SIGMA_S_REDUCED) -> np.ndarray:
    """(3,) ``1 / sigma_tr`` in mm, ``sigma_tr = sqrt(3 sigma_a (sigma_a + sigma_s'))``."""
    a = np.asarray(sigma_a, np.float64)
    s = np.asarray(sigma_s_reduced, np.float64)
    return 1.0 / np.sqrt(3.0 * a * (a + s))


def subsurface(scale: float = 1.0) -> tuple[tuple[float, float, float], float]:
    """(per-channel radius relative to red, scale in metres) for Cycles' subsurface inputs."""
    mfp = diffuse_mean_free_path_mm()
    rel = mfp / mfp[0]
    return (float(rel[0]), float(rel[1]), float(rel[2])), float(mfp[0] * 1e-3 * scale)


def sharp_lobe(roughness: float, oiliness: float = 0.0) -> dict[str, float]:
    """Principled coat inputs of the sharp specular lobe."""
    return {"Coat Weight": float(np.clip(COAT_WEIGHT + COAT_OIL * oiliness, 0.0, 1.0)),
            "Coat Roughness": float(SHARP_LOBE_RATIO * roughness), "Coat IOR": SHARP_LOBE_IOR}


def detail_weight(pixel_m: float, period_m: float) -> float:
    """1 when the period spans >= 2 pixels, 0 when <= 1 pixel, linear in between."""
    if pixel_m <= 0:
        return 1.0
    return float(np.clip(period_m / pixel_m - 1.0, 0.0, 1.0))


def spot_weight(pixel_m: float | None, layer: tuple[float, float]) -> float:
    """:func:`detail_weight` of a Voronoi spot layer (``(cell_m, radius)``): its spots'
    diameter against the pixel (None: full detail)."""
    cell, radius = layer
    return 1.0 if pixel_m is None else detail_weight(pixel_m, 2.0 * radius * cell)


def spot_coverage(threshold: float, radius: float) -> float:
    """Mean of a spot layer's factor: the fraction of cells drawn (``threshold`` of the cell's
    uniform random colour, clipped to [0, 1]) times the fraction of a cell within ``radius``."""
    return float(np.clip(threshold, 0.0, 1.0)) * VORONOI_F1_BELOW[radius]


def subpixel_roughness(roughness: float, unresolved: list[tuple[float, float]]) -> float:
    """Broad-lobe roughness widened by the unresolved part of detail layers: ``unresolved`` is
    [(weight, slope variance)] per layer; ``sqrt(r^2 + sum (1 - w) var)``."""
    var = sum((1.0 - w) * v for w, v in unresolved)
    return float(min(1.0, np.sqrt(roughness ** 2 + var)))


def pixel_footprint_m(cameras, default_resolution: int | None = None) -> float:
    """Metres one pixel covers on the face in the finest of ``cameras`` (the plan's cameras,
    :class:`synth.plan.records.Camera`: ``K``, ``world_to_camera``, ``target``):
    ``|camera centre - target| / f_x``. Without cameras, a face of ``FACE_WIDTH_M`` filling
    ``FACE_FILL`` of ``default_resolution`` pixels."""
    best = np.inf
    for c in cameras or ():
        K = np.asarray(c.K, np.float64)
        w2c = np.asarray(c.world_to_camera, np.float64)
        centre = -w2c[:3, :3].T @ w2c[:3, 3]
        best = min(best, float(np.linalg.norm(centre - np.asarray(c.target, np.float64)) / K[0, 0]))
    if np.isfinite(best):
        return best
    if not default_resolution:
        raise ValueError("pixel_footprint_m needs cameras or a resolution")
    return FACE_WIDTH_M / (FACE_FILL * float(default_resolution))
