"""The lips' own colour: the vermilion is skin with a thin, barely keratinised epidermis over a
dense superficial capillary bed, so it reads redder and (on all but the darkest skin) darker than
the skin around it.

What is known, from colour measurements of natural lips and the perioral skin next to them
(Baras et al., L'Oreal, 914 women aged 18-65: 238 African American, 238 white American, 225 white
French and 213 Japanese; presented at the L'Oreal Institute for Ethnic Hair and Skin Research
symposium, Miami): the lips' hue is strongly redder than the skin's, whose hue is more yellow;
their chroma does not differ significantly; the vermilion is always darker than the perioral
skin except in the African American group.

The model: the same melanin / haemoglobin reflectance model as the skin
(:mod:`synth.appearance.skin`), with :data:`LIP_BLOOD_ADDED` more blood volume fraction than the
identity's skin and :data:`LIP_MELANIN_FACTOR` times its melanin. Those two numbers are chosen,
not fitted: they are round values with which the model reproduces all three observations over
the catalogue's ranges (ITA -55..70 degrees, skin blood fraction 0.005-0.05; docs/realism.md,
"Lips"): hue 3-41 degrees redder, chroma within 4 CIELAB units, L* up to 12 lower on light
skin and none lower on the darkest. (Scaling the skin's blood fraction instead, by 5, turned the
lips of skin already rich in blood mauve: hue 4 degrees.) The lips' vertices (the model's
``lips`` region: the lip-contact loop out to the vermilion border) carry the ``vermilion`` point
attribute (:func:`vermilion_attribute`); the skin material mixes this colour in over it
(``blender_scripts.materials.skin_material``), with a slightly smoother surface (moister than skin).
"""

from __future__ import annotations

import numpy as np

from synth.appearance.skin import skin_albedo

#: blood volume fraction of the vermilion above the identity's skin's
LIP_BLOOD_ADDED = 0.04
#: melanin fraction of the vermilion's epidermis over the identity's skin's
LIP_MELANIN_FACTOR = 0.8
#: the lips' broad-lobe roughness below the skin's (a wetter surface; lipstick gloss is makeup's)
LIP_ROUGHNESS_DROP = 0.1
#: the ``vermilion`` attribute is 1 inside the lips, this on the vermilion border's own loop and 0
#: beyond; the material's colour edge is where the interpolated attribute crosses it, sharpened to
#: :data:`EDGE_WIDTH` of the attribute's range (the loop is a few millimetres from the next one out)
BORDER_VALUE = 0.5
EDGE_WIDTH = 0.3


def lip_albedo(melanin: float, haemoglobin: float) -> tuple[float, float, float]:
    """Linear sRGB albedo of the vermilion of skin with these melanin / haemoglobin fractions."""
    return skin_albedo(float(melanin) * LIP_MELANIN_FACTOR, min(1.0, float(haemoglobin) + LIP_BLOOD_ADDED))


def vermilion_attribute(n_vertices: int, regions: dict, triangles) -> np.ndarray | None:
    """(V,) the head's ``vermilion`` point attribute: 1 on the ``lips`` region and on the mouth
    interior's vertices next to it, :data:`BORDER_VALUE` on the lips' outer loop (lips vertices
    that share a triangle edge with skin outside the lips and the mouth interior), 0 elsewhere;
    None when the model names no lips."""
    from synth.model.meshutil import adjacency, triangle_edges

    lips = regions.get("lips")
    if lips is None or len(lips) == 0:
        return None
    inside = np.zeros(n_vertices, bool)
    inside[np.asarray(lips, np.int64)] = True
    mouth = np.zeros(n_vertices, bool)
    for name in ("mouth_interior", "teeth"):
        if name in regions:
            mouth[np.asarray(regions[name], np.int64)] = True
    A = adjacency(triangle_edges(triangles), n_vertices)
    a = inside.astype(np.float64)
    a[inside & (A @ (~inside & ~mouth) > 0)] = BORDER_VALUE  # next to skin beyond the lips
    # the skin-class faces between the lips' inner loop and the mouth interior are the inner lip
    # (its wet mucosa): their mouth-interior corners get the lips' value too (faces of the mouth
    # interior's own class do not use the skin material, so nothing else reads it there)
    a[mouth & (A @ inside > 0)] = 1.0
    return a
