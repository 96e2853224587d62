"""Regions the asset rigs read that an importer derives from the ones it already has
(docs/importers.md, "Derived regions"); shared by every importer, so an imported model carries
what the asset classes need (``needs`` in ``synth.assets.classes``) whatever its topology.

Axes are synth's (metres, Z up, face toward -Y, +X the subject's left): ``_l`` is +X.

* ``shoulders``: the ``neck`` vertices below the root joint (where the neck flares into the
  shoulders); they leave ``neck``. When the mesh ends above the root joint, the lowest third
  of the neck's height instead. ``face``, ``scalp``, ``ears``, ``neck`` and ``shoulders`` then
  partition ``skin``.
* ``skin``: that union (what garments and headwear are fitted to).
* ``ear_l``/``ear_r``, ``brow_l``/``brow_r``, ``iris_l``/``iris_r``, ``sclera_l``/``sclera_r``:
  the region split by the sign of x (iris and sclera: by eyeball, ``eye_l``/``eye_r``).
* ``eyelid_{l,r}_{upper,lower}``: the ``eyelash_lines`` vertices of that side, above / below the
  straight line between the eye's two corners (iBUG 42-45 left, 36-39 right) in the x-z plane.
"""

from __future__ import annotations

import numpy as np

#: iBUG-68 (inner, outer) corner of each eye
EYE_CORNERS = {"l": (42, 45), "r": (39, 36)}


def _ids(mask_or_ids) -> np.ndarray:
    return np.sort(np.asarray(mask_or_ids, np.int64)).astype(np.int32)


def shoulders_split(v: np.ndarray, neck: np.ndarray, root_z: float) -> tuple[np.ndarray, np.ndarray]:
    """(neck, shoulders) of a neck region: below ``root_z``, or the lowest third of the neck."""
    neck = np.asarray(neck, np.int64)
    if len(neck) == 0:
        return _ids(neck), np.zeros(0, np.int32)
    z = v[neck, 2]
    low = z < root_z
    if not low.any() or low.all():
        low = z < z.min() + (z.max() - z.min()) / 3.0
    return _ids(neck[~low]), _ids(neck[low])


def lid_lines(v: np.ndarray, lines: np.ndarray, lm: np.ndarray) -> dict[str, np.ndarray]:
    """``eyelid_{side}_{upper,lower}`` from the lid-margin vertices ``lines`` (module doc)."""
    lines = np.asarray(lines, np.int64)
    out = {}
    for side, (a, b) in EYE_CORNERS.items():
        ids = lines[(v[lines, 0] > 0) == (side == "l")]
        p, q = lm[a], lm[b]
        dx = q[0] - p[0]
        t = (v[ids, 0] - p[0]) / (dx if abs(dx) > 1e-9 else 1e-9)
        above = v[ids, 2] > p[2] + t * (q[2] - p[2])
        out[f"eyelid_{side}_upper"] = _ids(ids[above])
        out[f"eyelid_{side}_lower"] = _ids(ids[~above])
    return out


def derived_regions(vertices: np.ndarray, regions: dict, lm: np.ndarray, root_z: float) -> dict[str, np.ndarray]:
    """The regions of the module doc, from an importer's ``regions`` (face, scalp, ears, neck,
    brow, eye_l, eye_r, iris, sclera, eyelash_lines), the iBUG-68 landmark positions ``lm`` and
    the root joint's height. Returns a new dict: ``regions`` with ``neck`` replaced and the
    derived ones added (names already present are kept as they are)."""
    v = np.asarray(vertices, np.float64)
    lm = np.asarray(lm, np.float64)
    out = dict(regions)

    def get(name: str) -> np.ndarray:
        return np.asarray(regions.get(name, ()), np.int64)

    if "shoulders" not in regions:
        out["neck"], out["shoulders"] = shoulders_split(v, get("neck"), root_z)
    if "skin" not in regions:
        out["skin"] = _ids(np.unique(np.concatenate([np.asarray(out.get(r, ()), np.int64)
                                                     for r in ("face", "scalp", "ears", "neck", "shoulders")])))
    for name in ("ear", "brow"):
        src = get(f"{name}s" if name == "ear" else name)
        for side in ("l", "r"):
            if f"{name}_{side}" not in regions:
                out[f"{name}_{side}"] = _ids(src[(v[src, 0] > 0) == (side == "l")])
    for name in ("iris", "sclera"):
        src = get(name)
        for side in ("l", "r"):
            if f"{name}_{side}" not in regions:
                out[f"{name}_{side}"] = _ids(np.intersect1d(src, get(f"eye_{side}")))
    for k, ids in lid_lines(v, get("eyelash_lines"), lm).items():
        out.setdefault(k, ids)
    return out
