"""``synth export usd``: one committed shard as a USD stage (docs/export.md). Needs ``usd-core``.

::

    /World                               Xform, the default prim; stage: metres, Z up
      /World/id000042                    one identity of the shard
        head                             Mesh: the head model evaluated with each frame's codes,
                                         points time-sampled (time code = expression index);
                                         GeomSubsets "synthSegmentation" (one per class) and a
                                         uniform int primvar synth:segmentationId
        landmarks_ibug68                 Points: the 68 landmarks per expression
        assets/<name>                    Mesh per built shell asset (garment, headwear, glasses),
                                         topology as default values, points time-sampled,
                                         constant synth:segmentationId
        cameras                          Scope
        cameras/v07                      Camera per view index: at time code e, the camera of
                                         frame (identity, e, view 7)

Every random choice is replayed from the frames and the plan, never drawn: the head from the
frame JSON's ``model`` codes (:class:`synth.model.head.HeadModel`), the assets from the plan's
choice and the rig's seed (:mod:`synth.export.usd_assets`). Cameras come from
:func:`synth.conventions.usd_camera_params` and ``opencv_to_opengl_c2w``. The stage is written
under a temporary name and renamed when complete.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

from synth.conventions import opencv_to_opengl_c2w, usd_camera_params
from synth.dataset.layout import SHARDS_DIR, parse_frame_key
from synth.appearance.srgb import srgb_to_linear
from synth.dataset.segmentation import NAMES, PALETTE, polygon_classes
from synth.errors import SynthError
from synth.export.select import select_frames
from synth.export.usd_assets import HeadPose, asset_meshes
from synth.io import sha256_file

try:  # the `export` extra; export_usd says how to install it
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt
except ImportError:  # pragma: no cover - depends on the environment
    Usd = None

SUFFIXES = (".usd", ".usda", ".usdc")
SUBSET_FAMILY = "synthSegmentation"
SEG_PRIMVAR = "synth:segmentationId"


def _resolve_model(root: Path, model_path, frames: list[dict]):
    """(HeadModelData, run seed or None): the model the frames were rendered with, and the
    plan's run seed (for the asset rigs) when the dataset's plan is there."""
    from synth.model.format import read_model

    shas = {f["model"]["sha256"] for f in frames}
    if len(shas) != 1:
        raise SynthError("the frames were rendered with different head models", str(root), "export one shard")
    want = shas.pop()
    plan = None
    plan_dir = root / "plan"
    if (plan_dir / "plan.json").is_file():
        from synth.plan.io import load_plan

        plan = load_plan(plan_dir)
    if model_path is not None:
        path = Path(model_path)
    elif plan is not None:
        path = plan.model_path()
    else:
        from synth.model.default import default_model_path

        path = default_model_path()
    if not path.is_file():
        raise SynthError("head model file not found", str(path), "pass the model the dataset was rendered with: --model")
    if sha256_file(path) != want:
        raise SynthError(f"the head model's sha256 differs from the frames' ({want[:12]})", str(path),
                         "pass the model the dataset was rendered with: --model PATH")
    return read_model(path), (plan.seed if plan is not None else None)


def _set_mesh(mesh, counts, indices, time=None) -> None:
    t = () if time is None else (time,)
    mesh.GetFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(np.asarray(counts, np.int32)), *t)
    mesh.GetFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(np.asarray(indices, np.int32)), *t)


def _set_points(geom, points, time) -> None:
    pts = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, np.float32))
    geom.GetPointsAttr().Set(pts, time)
    geom.GetExtentAttr().Set(UsdGeom.PointBased.ComputeExtent(pts), time)


def _new_mesh(stage, path: str, seg_ids):
    mesh = UsdGeom.Mesh.Define(stage, path)
    for make in (mesh.CreatePointsAttr, mesh.CreateExtentAttr, mesh.CreateFaceVertexCountsAttr,
                 mesh.CreateFaceVertexIndicesAttr):
        make()
    mesh.CreateSubdivisionSchemeAttr().Set(UsdGeom.Tokens.none)  # polygons as modelled, not a limit surface
    pv = UsdGeom.PrimvarsAPI(mesh)
    seg = np.atleast_1d(np.asarray(seg_ids, np.int32))
    interp = UsdGeom.Tokens.uniform if seg.size > 1 else UsdGeom.Tokens.constant
    pv.CreatePrimvar(SEG_PRIMVAR, Sdf.ValueTypeNames.IntArray, interp).Set(Vt.IntArray.FromNumpy(seg))
    colours = np.array([srgb_to_linear(np.asarray(PALETTE.get(int(i), (255, 255, 255))) / 255.0) for i in seg],
                       np.float32)
    mesh.CreateDisplayColorPrimvar(interp).Set(Vt.Vec3fArray.FromNumpy(colours))
    return mesh


def _head(stage, path: str, data):
    off, idx, cls, _ = polygon_classes(data)
    mesh = _new_mesh(stage, path, cls)
    _set_mesh(mesh, np.diff(off), idx)
    for cid in sorted(set(cls.tolist())):
        faces = Vt.IntArray.FromNumpy(np.flatnonzero(cls == cid).astype(np.int32))
        sub = UsdGeom.Subset.CreateGeomSubset(mesh, NAMES[cid], UsdGeom.Tokens.face, faces, SUBSET_FAMILY,
                                              UsdGeom.Tokens.partition)
        sub.GetPrim().SetCustomDataByKey("synth:segmentationId", cid)
    return mesh


def _camera(stage, path: str):
    cam = UsdGeom.Camera.Define(stage, path)
    cam.CreateProjectionAttr().Set(UsdGeom.Tokens.perspective)
    return cam, cam.AddTransformOp()


def _set_camera(cam, op, meta: dict, time) -> None:
    c = meta["camera"]
    p = usd_camera_params(c["K"], c["width"], c["height"])
    cam.GetFocalLengthAttr().Set(p["focalLength"], time)
    cam.GetHorizontalApertureAttr().Set(p["horizontalAperture"], time)
    cam.GetVerticalApertureAttr().Set(p["verticalAperture"], time)
    cam.GetHorizontalApertureOffsetAttr().Set(p["horizontalApertureOffset"], time)
    cam.GetVerticalApertureOffsetAttr().Set(p["verticalApertureOffset"], time)
    cam.GetClippingRangeAttr().Set(Gf.Vec2f(c["near"], c["far"]), time)
    c2w = opencv_to_opengl_c2w(c["camera_to_world"])
    op.Set(Gf.Matrix4d(c2w.T.tolist()), time)  # Gf multiplies row vectors: the transpose


def _poses(hm, frames_by_expr: dict[int, dict]) -> tuple[HeadPose, dict[int, HeadPose]]:
    """The neutral head and the head at each expression, evaluated as the worker does."""
    any_meta = next(iter(frames_by_expr.values()))
    beta = np.asarray(any_meta["model"]["identity"], np.float64)
    ev = hm.evaluate(beta, np.zeros(hm.Ke), np.zeros((hm.J, 3)))
    rest = HeadPose(ev.vertices[0].astype(np.float64), {k: v[0].astype(np.float64) for k, v in ev.landmarks.items()})
    poses = {}
    for e, meta in sorted(frames_by_expr.items()):
        rot = np.zeros((hm.J, 3))
        for name, r in (meta["model"].get("joint_rotations") or {}).items():
            rot[hm.joint_index[name]] = r
        ev = hm.evaluate(beta, np.asarray(meta["model"]["expression"], np.float64), rot)
        poses[e] = HeadPose(ev.vertices[0].astype(np.float64),
                            {k: v[0].astype(np.float64) for k, v in ev.landmarks.items()})
    return rest, poses


def _first_committed(root: Path) -> str:
    refs = select_frames(root)
    return refs[0].shard


def export_usd(source, out, *, shard: str | None = None, model=None, assets: bool = True) -> dict:
    """Write shard ``shard`` (default: the first committed) of dataset ``source`` as a USD
    stage at ``out`` (.usdc binary, .usda text or .usd). Returns a summary."""
    if Usd is None:
        from synth.extras import require

        require("export", ("pxr",), "synth export usd")
    from synth.model.head import HeadModel

    root, out = Path(source), Path(out)
    if out.suffix not in SUFFIXES:
        raise SynthError(f"a USD file name ends in {', '.join(SUFFIXES)}", str(out), "name it scene.usdc")
    if not (root / SHARDS_DIR).is_dir():
        raise SynthError("not a dataset directory (no shards/)", str(root), "pass the --out directory of synth render")
    if not out.parent.is_dir():
        raise SynthError("the output's folder does not exist", str(out.parent), "create it first")
    shard = shard or _first_committed(root)
    refs = select_frames(root, shards=[shard], environment=0)  # the cameras: views under environment 0
    metas = [r.meta() for r in refs]
    data, run_seed = _resolve_model(root, model, metas)
    hm = HeadModel(data)
    by_identity: dict[int, dict[int, dict[int, dict]]] = defaultdict(lambda: defaultdict(dict))
    for r, m in zip(refs, metas):
        i, e, v = parse_frame_key(r.key)
        by_identity[i][e][v] = m
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    summary = {"out": str(out), "shard": shard, "identities": [], "frames": len(refs)}
    try:
        stage = Usd.Stage.CreateNew(str(tmpdir / out.name))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.LinearUnits.meters)
        exprs = sorted({e for ident in by_identity.values() for e in ident})
        stage.SetStartTimeCode(exprs[0])
        stage.SetEndTimeCode(exprs[-1])
        stage.SetTimeCodesPerSecond(1.0)
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        stage.GetRootLayer().customLayerData = {
            "synth:shard": shard, "synth:model": data.name, "synth:timeCode": "expression index",
            "synth:segmentationClasses": {name: int(cid) for cid, name in NAMES.items()}}
        for ident, exprs_of in sorted(by_identity.items()):
            summary["identities"].append(_identity(stage, hm, data, ident, exprs_of, run_seed, assets))
        stage.GetRootLayer().Save()
        os.replace(tmpdir / out.name, out)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return summary


def _identity(stage, hm, data, ident: int, exprs_of: dict, run_seed, assets: bool) -> dict:
    base = f"/World/id{ident:06d}"
    UsdGeom.Xform.Define(stage, base)
    first = {e: next(iter(views.values())) for e, views in exprs_of.items()}
    rest, poses = _poses(hm, first)
    head = _head(stage, f"{base}/head", data)
    lms = UsdGeom.Points.Define(stage, f"{base}/landmarks_ibug68")
    lms.CreatePointsAttr()
    lms.CreateExtentAttr()
    lms.CreateWidthsAttr().Set(Vt.FloatArray([0.002]))
    lms.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    for e, pose in poses.items():
        t = Usd.TimeCode(e)
        _set_points(head, pose.vertices, t)
        _set_points(lms, pose.landmarks["ibug68"], t)
    cams = {}
    UsdGeom.Scope.Define(stage, f"{base}/cameras")  # typed, so importers (Blender) keep it as the cameras' parent
    for e, views in sorted(exprs_of.items()):
        for v, meta in sorted(views.items()):
            if v not in cams:
                cams[v] = _camera(stage, f"{base}/cameras/v{v:02d}")
            _set_camera(*cams[v], meta, Usd.TimeCode(e))
    record = {"identity": ident, "expressions": sorted(exprs_of), "views": sorted(cams), "assets": [], "skipped": {}}
    if assets:
        order = sorted(poses)
        meshes, skipped = asset_meshes(data, rest, [poses[e] for e in order], first[order[0]]["assets"], run_seed,
                                       ident)
        UsdGeom.Scope.Define(stage, f"{base}/assets")
        for m in meshes:
            mesh = _new_mesh(stage, f"{base}/assets/{m.name}", m.segmentation_id)
            _set_mesh(mesh, np.full(len(m.faces[0]), 3), m.faces[0].reshape(-1))  # topology: a default value
            varies = any(not np.array_equal(f, m.faces[0]) for f in m.faces[1:])
            for e, pts, faces in zip(order, m.points, m.faces):
                if varies:  # (glasses whose parts differ between expressions) and time samples where it changes
                    _set_mesh(mesh, np.full(len(faces), 3), faces.reshape(-1), Usd.TimeCode(e))
                _set_points(mesh, pts, Usd.TimeCode(e))
            record["assets"].append(m.name)
        record["skipped"] = skipped
        stage.GetPrimAtPath(base).SetCustomDataByKey("synth:assetsNotExported", dict(skipped))
    return record
