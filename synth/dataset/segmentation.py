"""Segmentation class IDs (the EXR ``segmentation`` layer). Fixed forever: IDs are data, so
datasets stay comparable across versions.
"""

from __future__ import annotations

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
