"""THE registry of asset classes: the one place that lists them.

Each class is one :class:`AssetClass` in :data:`CLASSES`. Everything that needs to know the
classes reads this table: the configuration (``assets.disabled_classes``), the catalogue
loader and ``synth assets validate`` (one manifest file per class, generator ownership,
which classes packs may provide), the plan (sampling order and seeds), the render worker
(build order, the frame JSON's ``assets`` object), the rigs (``blender_scripts.assets``:
module, segmentation id) and the schema tests (``tests/assets/test_registry.py`` checks
``synth/schemas/*.json`` against this table). Adding a class is one entry here, a
``<name>.toml`` in the catalogue and a rig module in ``blender_scripts/assets/``.

Three orders, each fixed by an integer per class (never by the table's layout):

``slot`` (:data:`NAMES`, the *plan order*)
    The class's counter in the seed scheme, fixed forever: the planner draws the class's
    uniforms with ``seeds.uniforms(run_seed, Stream.ASSETS, identity, expression=slot)``
    (``synth/plan/assets.py``) and a rig its geometry randomness from
    ``seeds.generator(run_seed, Stream.ASSET_GEOMETRY, identity, expression=slot)``
    (:func:`rig_rng`). Classes are also sampled in this order, so a compatibility rule lets
    an earlier class remove candidates of a later one. Changing a slot changes every seed
    of that class; a new class takes the next free slot.
``build`` (:data:`BUILD_ORDER`)
    The order the worker builds rigs in: shader layers first (they edit the head's
    materials), then strands, shells, and glasses last.
``record`` (:data:`RECORD_ORDER`)
    The key order of the frame JSON's ``assets`` object (hair ... skin); changing it
    changes the bytes of every frame JSON.

``needs`` is what a class's rig reads from the head model: regions that must be present and
non-empty (``synth model info`` lists them per model; :func:`unavailable` and
:func:`check_model` compare a model against them, and ``synth plan`` / ``synth render`` refuse a
model that lacks what an enabled class needs, before any worker starts). Every class also needs
the ``ibug68`` landmark set (:data:`LANDMARKS_NEEDED`). The importers derive these regions from
any topology (``synth/model/importers/derived.py``, docs/importers.md).

Segmentation ids are data and fixed forever (``synth/dataset/segmentation.py`` owns the table;
a test checks the ids here against it). Shader-layer classes (skin, iris, makeup) create no
objects: they edit the head's own materials, so their pixels carry the host's id
(skin 1, eyes 2) and they cannot come from an external pack (``pack_anchor`` is None).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth import seeds

#: Points an external pack's origin may be placed at (docs/assets.md).
ANCHORS = ("head", "nose_bridge", "neck")


@dataclass(frozen=True)
class AssetClass:
    name: str  # stable: manifest file stem, plan and frame JSON key, CLI value
    slot: int  # seed counter and sampling position (see the module docstring); fixed forever
    build: int  # position in the worker's build order
    record: int  # position in the frame JSON's "assets" object
    segmentation: str  # segmentation class its pixels carry (synth.dataset.segmentation.CLASSES)
    segmentation_id: int  # that class's id (fixed forever)
    rig: str  # rig module: blender_scripts.assets.<rig>
    generators: tuple[str, ...]  # procedural generator names its rig builds ("procedural:<name>")
    pack_anchor: str | None  # default anchor of an external pack; None: packs cannot provide it
    needs: tuple[str, ...] = ()  # model regions its rig reads (present and non-empty)

    @property
    def shader_layer(self) -> bool:
        """True for classes that edit the head's materials instead of adding objects."""
        return self.pack_anchor is None


_TABLE = (
    AssetClass("skin", 0, 0, 9, "skin", 1, "skin_detail", ("skin_shader",), None,
               ("skin", "face")),
    AssetClass("iris", 1, 1, 8, "eyes", 2, "iris", ("iris_shader",), None,
               ("eye_l", "eye_r", "iris_l", "iris_r")),
    AssetClass("hair", 2, 6, 0, "hair", 5, "hair", ("hair_strands",), "head",
               ("scalp",)),
    AssetClass("eyebrows", 3, 4, 2, "eyebrows", 7, "eyebrows", ("eyebrow_strands",), "head",
               ("face", "brow")),
    AssetClass("eyelashes", 4, 3, 3, "eyelashes", 8, "eyelashes", ("eyelash_cards",), "head",
               ("eye_l", "eye_r", "eyelid_l_upper", "eyelid_l_lower", "eyelid_r_upper", "eyelid_r_lower")),
    AssetClass("beard", 5, 5, 1, "beard", 6, "beard", ("beard_strands",), "head",
               ("beard",)),
    AssetClass("makeup", 6, 2, 7, "skin", 1, "makeup", ("makeup_layer",), None,
               ("skin", "face", "lips")),
    AssetClass("garment", 7, 7, 4, "clothing", 9, "garment", ("garment_shell",), "neck",
               ("skin", "neck", "shoulders")),
    AssetClass("glasses", 8, 9, 5, "glasses", 10, "glasses", ("glasses_frame",), "nose_bridge",
               ("eyes", "ears")),
    AssetClass("headwear", 9, 8, 6, "headwear", 11, "headwear", ("headwear_shell",), "head",
               ("skin", "scalp")),
)


#: landmark sets every class reads
LANDMARKS_NEEDED = ("ibug68",)


def _check(table: tuple[AssetClass, ...]) -> None:
    n = len(table)
    for field in ("slot", "build", "record"):
        if sorted(getattr(c, field) for c in table) != list(range(n)):
            raise ValueError(f"asset class {field}s must be 0..{n - 1}, each once")
    names = [c.name for c in table]
    gens = [g for c in table for g in c.generators]
    if len(set(names)) != n or len(set(gens)) != len(gens):
        raise ValueError("asset class names and generator names must be unique")
    if any(c.pack_anchor not in (None, *ANCHORS) for c in table):
        raise ValueError(f"a pack anchor is one of {ANCHORS}")


_check(_TABLE)

#: name -> AssetClass
CLASSES: dict[str, AssetClass] = {c.name: c for c in sorted(_TABLE, key=lambda c: c.slot)}
#: class names in plan (slot) order: skin, iris, hair, eyebrows, eyelashes, beard, makeup,
#: garment, glasses, headwear
NAMES: tuple[str, ...] = tuple(CLASSES)
#: the worker's build order: skin, iris, makeup, eyelashes, eyebrows, beard, hair, garment,
#: headwear, glasses
BUILD_ORDER: tuple[str, ...] = tuple(c.name for c in sorted(_TABLE, key=lambda c: c.build))
#: the frame JSON's "assets" key order: hair, beard, eyebrows, eyelashes, garment, glasses,
#: headwear, makeup, iris, skin
RECORD_ORDER: tuple[str, ...] = tuple(c.name for c in sorted(_TABLE, key=lambda c: c.record))
#: procedural generator name -> the class whose rig builds it
PROCEDURAL_GENERATORS: dict[str, str] = {g: c.name for c in CLASSES.values() for g in c.generators}
#: classes an external pack may provide -> their default anchor
PACK_ANCHORS: dict[str, str] = {c.name: c.pack_anchor for c in CLASSES.values() if c.pack_anchor}


def rig_rng(run_seed: int, identity: int, cls: str) -> np.random.Generator:
    """The one generator a rig of class ``cls`` draws its geometry randomness from (strand
    roots, jitter, wrinkles), derived from (run seed, identity index, the class's slot)."""
    return seeds.generator(run_seed, seeds.Stream.ASSET_GEOMETRY, identity, expression=CLASSES[cls].slot)


def unavailable(model, cls: str) -> str | None:
    """Why ``model`` (a HeadModelData) cannot carry class ``cls``, or None if it can: the first
    missing (absent or empty) region or landmark set of the class's ``needs``."""
    for name in LANDMARKS_NEEDED:
        if name not in model.landmarks:
            return f"the model has no {name} landmarks"
    for r in CLASSES[cls].needs:
        if len(model.regions.get(r, ())) == 0:
            return f"the model has no {r} region"
    return None


def check_model(model, classes, where: str) -> None:
    """Refuse (one-line SynthError) a model that cannot carry one of the enabled ``classes``."""
    from synth.errors import SynthError

    bad = [(c, why) for c in classes if (why := unavailable(model, c))]
    if bad:
        cls, why = bad[0]
        others = f" (also: {', '.join(c for c, _ in bad[1:])})" if len(bad) > 1 else ""
        names = ",".join(f'"{c}"' for c, _ in bad)
        raise SynthError(f"head model {model.name!r} cannot carry asset class {cls}{others}: {why}", where,
                         f"leave them out with --set 'assets.disabled_classes=[{names}]', or re-import the model "
                         "with this synth ('synth model import' derives the regions the classes need)")
