"""``synth export usd``, read back with pxr: landmarks on the exported head mesh, projected
through the exported camera by USD's own camera maths (GfCamera -> GfFrustum; the oracle in
tests/support/export_oracles.py), land on the frame's landmarks_2d; stage metadata,
segmentation subsets and refusals."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

pxr = pytest.importorskip("pxr", reason="usd-core is not installed (the `export` extra; scripts/setup.sh installs it)")
from pxr import Usd, UsdGeom  # noqa: E402

from synth.errors import SynthError  # noqa: E402
from synth.export.usd import SEG_PRIMVAR, SUBSET_FAMILY, export_usd  # noqa: E402
from tests.support.datasets import model_dataset  # noqa: E402
from tests.support.export_oracles import check_stage  # noqa: E402


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = tmp_path_factory.mktemp("usd")
    ds, model = model_dataset(root / "ds", identities=1, expressions=3, views=4)
    out = root / "scene.usdc"
    summary = export_usd(ds, out, model=model)
    return ds, model, out, summary


def _frames(ds) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(ds.glob("shards/*/*.json")) if p.name != "manifest.json"}


def test_landmarks_project_through_the_usd_cameras(exported):
    from synth.model.format import read_model

    ds, model, out, summary = exported
    stage = Usd.Stage.Open(str(out))
    frames = _frames(ds)
    assert len(frames) == 12
    assert check_stage(stage, frames, read_model(model)) < 0.5e-2  # well under 0.5 px (float32 points)


def test_stage_metadata_and_time_samples(exported):
    ds, _, out, summary = exported
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/World"
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 2)
    head = UsdGeom.Mesh(stage.GetPrimAtPath("/World/id000000/head"))
    assert head.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/id000000/cameras/v03"))
    assert cam.GetFocalLengthAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    # the jaw opens with the expression index in model_dataset: the head changes between samples
    P0, P2 = (np.asarray(head.GetPointsAttr().Get(t)) for t in (0, 2))
    assert np.abs(P2 - P0).max() > 1e-3
    # clipping range and the 36 mm filmback in tenths of a metre
    fj = _frames(ds)["id000000_ex01_v03"]
    assert tuple(cam.GetClippingRangeAttr().Get(1)) == pytest.approx((fj["camera"]["near"], fj["camera"]["far"]))
    assert cam.GetHorizontalApertureAttr().Get(1) == pytest.approx(0.36)
    assert summary["identities"][0]["skipped"]["hair"].startswith("made in Blender")


def test_segmentation_subsets_partition_the_head(exported):
    from synth.dataset.segmentation import CLASSES, polygon_classes
    from synth.model.format import read_model

    _, model, out, _ = exported
    stage = Usd.Stage.Open(str(out))
    head = UsdGeom.Mesh(stage.GetPrimAtPath("/World/id000000/head"))
    n_faces = len(head.GetFaceVertexCountsAttr().Get())
    ids = np.asarray(UsdGeom.PrimvarsAPI(head).GetPrimvar(SEG_PRIMVAR).Get())
    _, _, cls, _ = polygon_classes(read_model(model))
    assert ids.tolist() == cls.tolist() and len(ids) == n_faces
    subsets = UsdGeom.Subset.GetGeomSubsets(head, UsdGeom.Tokens.face, SUBSET_FAMILY)
    valid, why = UsdGeom.Subset.ValidateFamily(head, UsdGeom.Tokens.face, SUBSET_FAMILY)
    assert valid, why
    for sub in subsets:
        name = sub.GetPrim().GetName()
        faces = np.asarray(sub.GetIndicesAttr().Get())
        assert (ids[faces] == CLASSES[name]).all()
        assert sub.GetPrim().GetCustomDataByKey("synth:segmentationId") == CLASSES[name]
    assert sum(len(s.GetIndicesAttr().Get()) for s in subsets) == n_faces


def test_refusals_leave_nothing(exported, tmp_path):
    from tests.support.toy_model import make_toy_model
    from synth.model.format import write_model

    ds, model, _, _ = exported
    other = write_model(make_toy_model(identity_dims=6), tmp_path / "other.npz")
    with pytest.raises(SynthError, match="sha256 differs"):
        export_usd(ds, tmp_path / "a.usdc", model=other)
    with pytest.raises(SynthError, match="ends in"):
        export_usd(ds, tmp_path / "a.obj", model=model)
    with pytest.raises(SynthError, match="not committed"):
        export_usd(ds, tmp_path / "a.usdc", model=model, shard="shard_000009")
    assert list(tmp_path.iterdir()) == [other]


def test_cli_json(exported, tmp_path):
    ds, model, _, _ = exported
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", "export", "usd", str(ds), "-o", str(tmp_path / "s.usda"),
                        "--model", str(model), "--json"], capture_output=True, text=True, check=True)
    s = json.loads(p.stdout)
    assert s["shard"] == "shard_000000" and s["frames"] == 12 and (tmp_path / "s.usda").is_file()


def test_every_prim_is_typed_and_cameras_sit_in_a_scope(exported):
    """A typeless ``def`` is dropped by importers (Blender's, with its children's parent)."""
    _, _, out, _ = exported
    stage = Usd.Stage.Open(str(out))
    untyped = [str(p.GetPath()) for p in stage.Traverse() if not p.GetTypeName()]
    assert untyped == []
    cams = stage.GetPrimAtPath("/World/id000000/cameras")
    assert cams.IsA(UsdGeom.Scope) and all(c.IsA(UsdGeom.Camera) for c in cams.GetChildren())


def test_topology_is_a_default_value_and_points_are_time_samples(exported, tmp_path, monkeypatch):
    """Face counts and indices are default values (read at any time, also by tools that ignore
    time samples); points vary per expression. An asset whose topology changes between
    expressions (glasses parts) gets time samples of it on top of the default."""
    import synth.export.usd as usd
    from synth.export.usd_assets import AssetMesh

    ds, model, out, _ = exported
    stage = Usd.Stage.Open(str(out))
    head = UsdGeom.Mesh(stage.GetPrimAtPath("/World/id000000/head"))
    for attr in (head.GetFaceVertexCountsAttr(), head.GetFaceVertexIndicesAttr()):
        assert attr.GetTimeSamples() == [] and len(attr.Get()) > 0
    assert head.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]

    tri = np.array([[0, 1, 2], [0, 2, 3]])
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    fixed = AssetMesh("garment", "fixed", 5, [quad + e for e in range(3)], [tri] * 3)
    varying = AssetMesh("glasses", "varying", 7, [quad, quad, quad[:3]], [tri, tri, tri[:1]])
    monkeypatch.setattr(usd, "asset_meshes", lambda *a: ([fixed, varying], {}))
    export_usd(ds, tmp_path / "a.usda", model=model)
    stage = Usd.Stage.Open(str(tmp_path / "a.usda"))
    m = UsdGeom.Mesh(stage.GetPrimAtPath("/World/id000000/assets/fixed"))
    assert m.GetFaceVertexCountsAttr().GetTimeSamples() == m.GetFaceVertexIndicesAttr().GetTimeSamples() == []
    assert list(m.GetFaceVertexIndicesAttr().Get()) == tri.reshape(-1).tolist()
    assert m.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    assert np.asarray(m.GetPointsAttr().Get(2))[1].tolist() == [3.0, 2.0, 2.0]
    v = UsdGeom.Mesh(stage.GetPrimAtPath("/World/id000000/assets/varying"))
    idx = v.GetFaceVertexIndicesAttr()
    assert list(idx.Get(Usd.TimeCode.Default())) == tri.reshape(-1).tolist()
    assert idx.GetTimeSamples() == [0.0, 1.0, 2.0] and list(idx.Get(2)) == [0, 1, 2]
