"""The registry of asset classes (``synth/assets/classes.py``): the orders the data depends on,
the segmentation ids, the schemas generated from nothing else, and that no other module lists
the classes. No Blender."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from synth import seeds
from synth.assets import classes
from synth.assets.classes import BUILD_ORDER, CLASSES, NAMES, RECORD_ORDER, rig_rng
from synth.dataset.segmentation import CLASSES as SEGMENTATION_IDS

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "synth" / "schemas"


def test_orders_are_the_ones_existing_data_depends_on():
    """Plans and frames written before the registry existed used these orders: the seed slots
    (ASSETS and ASSET_GEOMETRY counters, and the sampling order), the build order and the key
    order of the frame JSON. Changing one changes existing datasets, so it is pinned here."""
    assert NAMES == ("skin", "iris", "hair", "eyebrows", "eyelashes", "beard", "makeup", "garment", "glasses",
                     "headwear")
    assert [CLASSES[n].slot for n in NAMES] == list(range(10))
    assert BUILD_ORDER == ("skin", "iris", "makeup", "eyelashes", "eyebrows", "beard", "hair", "garment", "headwear",
                           "glasses")
    assert RECORD_ORDER == ("hair", "beard", "eyebrows", "eyelashes", "garment", "glasses", "headwear", "makeup",
                            "iris", "skin")


def test_segmentation_ids_are_the_segmentation_tables():
    for c in CLASSES.values():
        assert SEGMENTATION_IDS[c.segmentation] == c.segmentation_id, c.name
    # the ids of the asset classes that own a segmentation class, fixed forever
    assert {c.name: c.segmentation_id for c in CLASSES.values()} == {
        "skin": 1, "iris": 2, "makeup": 1, "hair": 5, "beard": 6, "eyebrows": 7, "eyelashes": 8, "garment": 9,
        "glasses": 10, "headwear": 11}
    # shader layers are exactly the classes that render into their host's id (skin, eyes)
    assert {c.name for c in CLASSES.values() if c.shader_layer} == {"skin", "iris", "makeup"}


def test_rig_rng_is_the_geometry_stream_at_the_class_slot():
    for c in CLASSES.values():
        a = rig_rng(7, 3, c.name).random(4)
        b = seeds.generator(7, seeds.Stream.ASSET_GEOMETRY, 3, expression=c.slot).random(4)
        assert np.array_equal(a, b)
    assert not np.array_equal(rig_rng(7, 3, "hair").random(4), rig_rng(7, 3, "beard").random(4))


def test_generators_packs_and_rig_modules():
    assert classes.PROCEDURAL_GENERATORS["glasses_frame"] == "glasses"
    assert set(classes.PROCEDURAL_GENERATORS.values()) == set(NAMES)
    assert set(classes.PACK_ANCHORS) == {c.name for c in CLASSES.values() if not c.shader_layer}
    for c in CLASSES.values():
        assert (ROOT / "blender_scripts" / "assets" / f"{c.rig}.py").is_file(), c.rig
        assert (ROOT / "assets_manifest" / f"{c.name}.toml").is_file(), c.name


@pytest.mark.parametrize("field,value", [("slot", 3), ("build", 0), ("record", 9), ("pack_anchor", "chin")])
def test_a_broken_table_is_refused(field, value):
    import dataclasses

    table = list(CLASSES.values())
    assert table[2].name == "hair"
    table[2] = dataclasses.replace(table[2], **{field: value})
    with pytest.raises(ValueError):
        classes._check(tuple(table))
    classes._check(tuple(CLASSES.values()))  # the real one passes


def test_schemas_list_the_registered_classes():
    frame = json.loads((SCHEMAS / "frame.schema.json").read_text())
    assets = frame["properties"]["assets"]
    assert assets["required"] == list(RECORD_ORDER)
    assert list(assets["properties"]) == list(RECORD_ORDER)
    plan = json.loads((SCHEMAS / "plan.schema.json").read_text())
    assert plan["$defs"]["identity"]["properties"]["assets"]["required"] == list(NAMES)
    asset = json.loads((SCHEMAS / "asset.schema.json").read_text())
    assert asset["$defs"]["class_name"]["enum"] == list(NAMES)


def test_no_other_module_lists_the_classes():
    """A line naming three or more asset classes as strings is a second list of them."""
    names = "|".join(NAMES)
    rx = re.compile(rf"[\"']({names})[\"']")
    bad = []
    for pkg in ("synth", "blender_scripts", "renderer_jobs", "prior"):
        for p in sorted((ROOT / pkg).rglob("*.py")):
            if p == ROOT / "synth" / "assets" / "classes.py":
                continue
            for i, line in enumerate(p.read_text(encoding="utf-8").split("\n"), 1):
                if len(set(rx.findall(line))) >= 3:
                    bad.append(f"{p.relative_to(ROOT)}:{i}")
    assert not bad, bad


def test_the_check_catches_a_list():
    line = 'ORDER = ("hair", "beard", "skin")'
    assert len(set(re.findall(rf"[\"']({'|'.join(NAMES)})[\"']", line))) == 3


def test_every_class_declares_what_it_reads_and_a_model_without_it_is_refused():
    """``needs``: regions present and non-empty on the default model and the importers' output
    (tests/blender/test_assets_contract.py builds every class on those). A model lacking one
    is refused in one line naming the model, the class, the missing region and the fix."""
    from synth.errors import SynthError
    from tests.support.toy_model import make_toy_model

    model = make_toy_model()
    assert all(CLASSES[c].needs for c in NAMES)
    assert {c: classes.unavailable(model, c) for c in NAMES} == dict.fromkeys(NAMES)
    classes.check_model(model, NAMES, "toy.npz")
    del model.regions["shoulders"]
    model.regions["eyelid_r_lower"] = np.zeros(0, np.int32)  # empty counts as missing
    assert classes.unavailable(model, "garment") == "the model has no shoulders region"
    assert classes.unavailable(model, "eyelashes") == "the model has no eyelid_r_lower region"
    classes.check_model(model, [c for c in NAMES if c not in ("garment", "eyelashes")], "toy.npz")
    with pytest.raises(SynthError) as e:
        classes.check_model(model, NAMES, "toy.npz")
    msg = str(e.value)
    assert "\n" not in msg and "'toy-ellipsoid'" in msg and "(toy.npz)" in msg
    assert "asset class eyelashes (also: garment): the model has no eyelid_r_lower region" in msg
    assert """--set 'assets.disabled_classes=["eyelashes","garment"]'""" in msg
    del model.landmarks["ibug68"]
    assert classes.unavailable(model, "hair") == "the model has no ibug68 landmarks"
