"""Tooth enamel colour, from spectrophotometric measurements of natural teeth.

The head's teeth were a flat (0.85, 0.82, 0.72) linear sRGB: CIELAB L* 92.5, b* 6.8, whiter
and lighter than teeth are; open mouths showed a bright white band. Intraoral measurements of
maxillary central incisors (Vita Easyshade) give L* 80.6 at ages 11-15 and L* 84.0, a* 0.17,
b* 24.1 over ages 7-15 (Oh et al., J Korean Acad Pediatr Dent 2022;49(4):414-427); adult teeth
are reported darker still. The teeth take the 11-15 group's lightness and the reported a*; b* is
14, chosen by eye below the measured 24 (docs/realism.md, "Teeth"): at 24 the teeth rendered
olive in the mouth's shade, the instrument measures the enamel under its own light.
"""

from __future__ import annotations

from synth.appearance.skin import linear_srgb_from_cielab

#: CIELAB (D65) the teeth's base colour is set to
TOOTH_CIELAB = (80.6, 0.17, 14.0)
#: linear sRGB of :data:`TOOTH_CIELAB` (about 0.65, 0.57, 0.42)
TOOTH_ALBEDO = tuple(round(float(c), 4) for c in linear_srgb_from_cielab(TOOTH_CIELAB))
