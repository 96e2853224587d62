"""The procedural studio environment (``lighting.environment = 'studio'``; pure numpy, no bpy).

A constant environment (``'uniform'``) lights every surface the same whatever its normal: no
shading tells the jaw from the neck or the nose from the cheeks, and faces read flat. The
paper renders in one environment "chosen to minimize shadows on the face"; the studio
environment is that kind of map, made here so nothing has to be downloaded:

- a **key** light: a soft lobe (von Mises-Fisher, angular spread ``key_size_deg``) in front of
  the face, to one side and above it;
- a **fill**: a wider, weaker lobe from the other side;
- **ambient**: the rest of the power, spread over the whole sphere, the upper hemisphere
  brighter than the lower (sky and floor).

Each term is normalised to its share of the map's power, and the map so that surfaces facing
the front half-space (the face, before ``rotation_deg``) receive on average the irradiance pi
of the uniform environment of radiance 1: the face is exposed on average as under
``'uniform'`` (the skin calibration's renders), its key side more, its fill side, the chin's
underside and the back of the head less. (Normalising a single frontal normal instead left
the rendered faces 23 % darker than under ``'uniform'``: the face's normals average 0.77 of
the frontal irradiance.)

Directions use the camera convention (synth.conventions.spherical_offset): azimuth 0 is in
front of the face (-Y), positive toward the subject's left (+X), elevation positive up (+Z).
The image is an equirectangular map in Blender's convention (row 0 at the top, +Z; column
``u`` looks along ``atan2(y, x) = pi (1 - 2 u)``), as its Environment Texture node reads it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.conventions import spherical_offset

#: Width of the generated map (height = width / 2): 1.4 degrees per pixel, well under the
#: narrowest lobe allowed (``key_size_deg`` >= 5).
MAP_WIDTH = 256
#: The floor (lower hemisphere) gets this fraction of the sky's ambient radiance.
FLOOR = 0.5


@dataclass(frozen=True)
class Studio:
    """One studio environment; angles in degrees (camera convention, see the module doc)."""
    key_deg: tuple[float, float] = (-35.0, 30.0)
    key_size_deg: float = 25.0
    key_share: float = 0.45
    fill_deg: tuple[float, float] = (60.0, 5.0)
    fill_size_deg: float = 45.0
    fill_share: float = 0.2
    rotation_deg: float = 0.0  # about the vertical axis, added to both lobes' azimuths

    def __post_init__(self):
        if not (0.0 <= self.key_share and 0.0 <= self.fill_share and self.key_share + self.fill_share <= 1.0):
            raise ValueError(f"studio shares must be >= 0 with key + fill <= 1 (got {self.key_share}, {self.fill_share})")
        if not (self.key_size_deg > 0.0 and self.fill_size_deg > 0.0):
            raise ValueError("studio lobe sizes must be > 0 degrees")

    @classmethod
    def from_record(cls, env: dict) -> Studio:
        """The environment of a plan's lighting record (synth.plan.assets.sample_lighting)."""
        return cls(key_deg=tuple(env["key_deg"]), key_size_deg=float(env["key_size_deg"]),
                   key_share=float(env["key_share"]), fill_deg=tuple(env["fill_deg"]),
                   fill_size_deg=float(env["fill_size_deg"]), fill_share=float(env["fill_share"]),
                   rotation_deg=float(env.get("rotation_deg", 0.0)))


def map_directions(width: int = MAP_WIDTH) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) unit directions of the pixel centres of a ``width`` x ``width / 2``
    equirectangular map (Blender's convention) and (H, W) their solid-angle weights (sum 4 pi)."""
    H = width // 2
    el = np.pi * (0.5 - (np.arange(H) + 0.5) / H)  # row 0 at the top
    az = np.pi * (1.0 - 2.0 * (np.arange(width) + 0.5) / width)  # atan2(y, x)
    ce = np.cos(el)[:, None]
    d = np.stack(np.broadcast_arrays(ce * np.cos(az)[None], ce * np.sin(az)[None], np.sin(el)[:, None]), axis=-1)
    w = np.broadcast_to(ce * (np.pi / H) * (2.0 * np.pi / width), (H, width))
    return d, w


def _unit_mean(f: np.ndarray, w: np.ndarray) -> np.ndarray:
    return f * (w.sum() / float((f * w).sum()))


def _lobe(d: np.ndarray, w: np.ndarray, az: float, el: float, size_deg: float) -> np.ndarray:
    """A von Mises-Fisher lobe about the direction (az, el) with angular spread ``size_deg``
    (kappa = 1 / size^2), normalised to unit mean over the sphere."""
    mu = spherical_offset(az, el)
    kappa = 1.0 / np.radians(size_deg) ** 2
    return _unit_mean(np.exp(kappa * (d @ mu - 1.0)), w)


FRONT = (0.0, -1.0, 0.0)  # the normal of a surface facing the front (azimuth 0, elevation 0)


def front_normals(n: int = 2048) -> np.ndarray:
    """(n, 3) unit normals spread evenly over the front half-space (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    y = -i / n  # uniform in y over [-1, 0]: uniform over the half-sphere's area
    r = np.sqrt(1.0 - y * y)
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=-1)


def _radiance(s: Studio, rotation_deg: float, width: int) -> np.ndarray:
    d, w = map_directions(width)
    ambient = _unit_mean(FLOOR + (1.0 - FLOOR) * 0.5 * (1.0 + np.tanh(4.0 * d[..., 2])), w)  # sky above, floor below
    key = _lobe(d, w, s.key_deg[0] + rotation_deg, s.key_deg[1], s.key_size_deg)
    fill = _lobe(d, w, s.fill_deg[0] + rotation_deg, s.fill_deg[1], s.fill_size_deg)
    return s.key_share * key + s.fill_share * fill + (1.0 - s.key_share - s.fill_share) * ambient


def studio_map(s: Studio, width: int = MAP_WIDTH) -> np.ndarray:
    """(width / 2, width, 3) float32 linear radiance of the studio environment ``s`` (grey:
    ``lighting.color`` and ``strength`` multiply it in the renderer), scaled so that surfaces
    facing the front half-space get the irradiance pi on average before the rotation (see the
    module doc)."""
    front = float(irradiance(_radiance(s, 0.0, width)[..., None], front_normals()).mean())
    L = _radiance(s, s.rotation_deg, width) * (np.pi / front)
    return np.repeat(L[..., None], 3, axis=-1).astype(np.float32)


def irradiance(L: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Irradiance (..., ) on surfaces with unit ``normals`` (..., 3) from the map ``L``
    (H, W, 3; the mean of its channels): the cosine-weighted integral over the hemisphere."""
    d, w = map_directions(L.shape[1])
    rad = L.mean(axis=-1) * w
    c = np.clip(np.asarray(normals, np.float64) @ d.reshape(-1, 3).T, 0.0, None)
    return c @ rad.reshape(-1)
