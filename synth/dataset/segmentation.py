"""Segmentation class IDs (the EXR ``segmentation`` layer). Fixed forever: IDs are data, so
datasets stay comparable across versions.

The head mesh's polygons get their class from the model's regions (:func:`polygon_classes`);
asset objects carry their class's id (``synth.assets.classes``). The render worker and the
USD export both use this table.
"""

from __future__ import annotations

import numpy as np

CLASSES: dict[str, int] = {
    "background": 0,
    "skin": 1,
    "eyes": 2,
    "mouth_interior": 3,
    "teeth": 4,
    "hair": 5,
    "beard": 6,
    "eyebrows": 7,
    "eyelashes": 8,
    "clothing": 9,
    "glasses": 10,
    "headwear": 11,
}
NAMES: dict[int, str] = {v: k for k, v in CLASSES.items()}

#: Distinct display colours (sRGB 0-255) for previews, one per class ID.
PALETTE: dict[int, tuple[int, int, int]] = {
    0: (0, 0, 0), 1: (230, 180, 150), 2: (60, 120, 255), 3: (150, 30, 40), 4: (255, 255, 240),
    5: (120, 70, 20), 6: (90, 50, 10), 7: (200, 140, 40), 8: (255, 0, 200), 9: (40, 170, 80),
    10: (0, 230, 230), 11: (250, 230, 0),
}

#: Region -> segmentation class, in priority order (first match wins for a polygon).
REGION_CLASSES = (("teeth", "teeth"), ("eyes", "eyes"), ("mouth_interior", "mouth_interior"))
#: Regions whose polygons are not rendered (vertices are kept so indices stay the model's): the
#: default model's lash placement strips, and an imported model's own lash cards and eye shading
#: helpers (ICT-FaceKit's ``eyelashes``, ``eye_fluids``: lacrimal fluid, eye blend and occlusion
#: meshes made for a game engine's blending, which drawn opaque cover the eyeballs; and
#: ``eye_interior``, the inner eyeball behind its transparent outer shell).
HIDDEN_REGIONS = ("lash_helper_l_upper", "lash_helper_l_lower", "lash_helper_r_upper", "lash_helper_r_lower",
                  "eyelashes", "eye_fluids", "eye_interior")


def polygon_classes(data) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(offsets, indices, class id per polygon, kept-polygon mask). A polygon takes a region's
    class when all its corners are in that region; everything else is skin. Polygons entirely in
    HIDDEN_REGIONS are left out."""
    if data.poly_offsets is not None:
        off, idx = data.poly_offsets.astype(np.int64), data.poly_indices.astype(np.int64)
    else:
        off = np.arange(0, data.triangles.size + 1, 3, dtype=np.int64)
        idx = data.triangles.reshape(-1).astype(np.int64)
    cls = np.full(len(off) - 1, CLASSES["skin"], np.int32)
    counts = np.diff(off)
    assigned = np.zeros(len(cls), bool)
    for region, name in REGION_CLASSES:
        if region not in data.regions:
            continue
        member = np.zeros(data.num_vertices, bool)
        member[data.regions[region]] = True
        all_in = np.add.reduceat(member[idx].astype(np.int64), off[:-1]) == counts
        sel = all_in & ~assigned
        cls[sel] = CLASSES[name]
        assigned |= sel
    # helper geometry (MakeHuman's eyelash placement strips) is not part of the surface: dropped
    helper = np.zeros(data.num_vertices, bool)
    for region in HIDDEN_REGIONS:
        if region in data.regions:
            helper[data.regions[region]] = True
    if helper.any():
        hidden = np.add.reduceat(helper[idx].astype(np.int64), off[:-1]) == counts
        if hidden.any():
            keep = ~hidden
            starts, counts_k = off[:-1][keep], counts[keep]
            idx = np.concatenate([idx[a:a + n] for a, n in zip(starts.tolist(), counts_k.tolist())])
            off = np.concatenate([[0], np.cumsum(counts_k)]).astype(np.int64)
            cls = cls[keep]
            return off, idx, cls, keep
    return off, idx, cls, np.ones(len(cls), bool)
