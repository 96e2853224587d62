"""The built meshes of an identity's shell assets, per expression, for the USD export.

The render worker builds every asset in Blender from numpy geometry (:mod:`synth.assets.fit`)
fitted to the identity's neutral head, and re-fits it at each expression. The meshes of the
classes whose geometry *is* that numpy (garments and headwear: fitted shells; glasses: the
frame and lenses posed by contact) are rebuilt here the same way, from the plan's choice, the
rig's seed (:func:`synth.assets.classes.rig_rng`) and the head model, and checked against what
the render recorded (vertex and face counts). Not rebuilt, and said so in the result:

- strand classes (hair, beard, eyebrows, eyelashes): Blender's Geometry Nodes style their
  curves at render time (clump, frizz), so the numpy strands are not what was rendered;
- shader layers (skin, iris, makeup): no geometry of their own (they colour the head);
- assets from external ``.blend`` packs: their meshes live in Blender files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from synth.assets.classes import CLASSES, RECORD_ORDER, rig_rng
from synth.assets.params import AssetPick
from synth.dataset.segmentation import CLASSES as SEGMENTATION


@dataclass
class AssetMesh:
    """One mesh of a built asset: triangles per expression (topology may change per expression)."""

    cls: str
    name: str
    segmentation_id: int
    points: list[np.ndarray] = field(default_factory=list)  # per expression, (n, 3) metres
    faces: list[np.ndarray] = field(default_factory=list)  # per expression, (m, 3) int


@dataclass
class HeadPose:
    """The head at one expression: what a rig reads."""

    vertices: np.ndarray
    landmarks: dict[str, np.ndarray]


def _entry(cls: str, record: dict) -> AssetPick:
    """The plan's pick of a frame JSON's asset record (without what the rig built)."""
    return AssetPick.from_json(cls, {k: v for k, v in record.items() if k != "build"}, f"frame JSON assets.{cls}")


def _shell(module: str, cls: str, data, rest: HeadPose, poses: list[HeadPose], record: dict, run_seed: int,
           identity: int):
    """A fitted shell (``synth.assets.fit.<module>``: ``<module>_shell`` and ``CLEARANCE``), as
    ``blender_scripts/assets/garment.py`` builds it."""
    import importlib

    from synth.assets.fit.body import Body, fit_shell

    fit = importlib.import_module(f"synth.assets.fit.{module}")
    make, CLEARANCE = getattr(fit, f"{module}_shell"), fit.CLEARANCE
    body = Body(rest.vertices, data.triangles, data.regions, rest.landmarks["ibug68"])
    fitted = fit_shell(body, make(body, _entry(cls, record), rig_rng(run_seed, identity, cls)), CLEARANCE)
    built = record.get("build") or {}
    for k in ("vertices", "faces"):
        if k in built and built[k] != fitted.info.get(k):
            return None, f"rebuilt {k} {fitted.info.get(k)} differ from the render's {built[k]}"
    mesh = AssetMesh(cls, fitted.name, CLASSES[cls].segmentation_id)
    meshes = [mesh]
    if "torso_vertices" in built:  # the body below the bust (and the forearms), the garment rig's second object
        from synth.assets.fit import torso
        from synth.assets.fit.arms import FOREARM_INSET

        if "torso_arms" in built:  # renders before the bust (2026-12): tube arms, not rebuilt any more
            return None, "the render's garment has the tube arms of an earlier version (torso_arms), not rebuilt"
        with_fore = bool(built.get("torso_forearms"))
        bare = fitted.info.get("sleeves", "long") != "long"
        offset = 0.0 if bare else max(float(fitted.info.get("cloth_reach_m", 0.0)) - FOREARM_INSET, 0.0)
        (Vp, Fp), (Va, Fa) = torso.garment_torso_parts(
            fitted, (rest.vertices, data.triangles, data.regions) if with_fore else None, offset)
        if built.get("torso_forearms_skin"):  # bare forearms in the head's skin (short sleeves, none)
            parts = [(f"{fitted.name}_torso", CLASSES[cls].segmentation_id, Vp, Fp),
                     (f"{fitted.name}_forearms", SEGMENTATION["skin"], Va, Fa)]
        else:
            parts = [(f"{fitted.name}_torso", CLASSES[cls].segmentation_id, np.vstack([Vp, Va]),
                      np.vstack([Fp, np.asarray(Fa, np.int64) + len(Vp)]))]
        n = sum(len(part[2]) for part in parts)
        if n != built["torso_vertices"]:
            return None, f"rebuilt torso vertices {n} differ from the render's {built['torso_vertices']}"
        band = torso.hem_band(fitted)
        for name, seg, _, _ in parts:
            meshes.append(AssetMesh(cls, name, seg))
    for p in poses:
        P = fitted.follow(p.vertices, data.triangles)
        mesh.points.append(P)
        mesh.faces.append(np.asarray(fitted.F, np.int64))
        if len(meshes) > 1:
            for m, (_, _, Vx, Fx) in zip(meshes[1:], parts):
                m.points.append(torso.follow(Vx, fitted.P[band], P[band]))
                m.faces.append(np.asarray(Fx, np.int64))
    return meshes, None


def _close(a, b, atol: float = 1e-5) -> bool:
    """Recorded numbers (rounded, through JSON) against rebuilt ones."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], atol) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y, atol) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return abs(float(a) - float(b)) <= atol
    return a == b


def _glasses(cls: str, data, rest: HeadPose, poses: list[HeadPose], record: dict, run_seed: int, identity: int):
    from synth.assets.fit.glasses.front import build_front
    from synth.assets.fit.glasses.solve import FRAME_PARTS, fit_glasses
    from synth.assets.fit.glasses.spec import frame_spec

    entry = _entry(cls, record)
    spec = frame_spec(entry.id, entry.params, rig_rng(run_seed, identity, "glasses"))
    front = build_front(spec)
    recorded = (record.get("build") or {}).get("pose")
    rebuilt = fit_glasses(rest.vertices, data.triangles, data.regions, rest.landmarks, spec, front=front).info["pose"]
    if recorded is not None and not _close(recorded, rebuilt):
        return None, "the rebuilt pose on the neutral head differs from the render's record"
    sid = CLASSES["glasses"].segmentation_id
    frame, lenses = AssetMesh("glasses", "glasses_frame", sid), AssetMesh("glasses", "glasses_lenses", sid)
    for p in poses:
        fit = fit_glasses(p.vertices, data.triangles, data.regions, p.landmarks, spec, front=front)
        for mesh, keys in ((frame, FRAME_PARTS), (lenses, ("lens",))):
            parts = [fit.parts[k] for k in keys if k in fit.parts and len(fit.parts[k][0])]
            offsets = np.cumsum([0] + [len(V) for V, _ in parts])
            mesh.points.append(np.concatenate([np.asarray(V, np.float64) for V, _ in parts]))
            mesh.faces.append(np.concatenate([np.asarray(F, np.int64) + o for (_, F), o in zip(parts, offsets)]))
    return [frame, lenses], None


#: procedural generator -> how its geometry is rebuilt (synth.assets.classes lists the generators)
REBUILD = {
    "garment_shell": lambda *a: _shell("garment", *a),
    "headwear_shell": lambda *a: _shell("headwear", *a),
    "glasses_frame": _glasses,
}


def asset_meshes(data, rest: HeadPose, poses: list[HeadPose], assets: dict, run_seed: int | None,
                 identity: int) -> tuple[list[AssetMesh], dict[str, str]]:
    """(meshes, skipped class -> why) for the frame JSON's ``assets`` record of one identity;
    ``poses`` are the head at each exported expression, ``rest`` the neutral head."""
    meshes: list[AssetMesh] = []
    skipped: dict[str, str] = {}
    for cls in RECORD_ORDER:
        rec = assets.get(cls)
        if not rec:
            continue
        gen = str(rec.get("generator", ""))
        if not gen.startswith("procedural:"):
            skipped[cls] = "from an external pack (its mesh lives in a .blend file)"
        elif CLASSES[cls].shader_layer:
            skipped[cls] = "a shader layer on the head (no geometry of its own)"
        elif gen.removeprefix("procedural:") not in REBUILD:
            skipped[cls] = "made in Blender (strands: styled by Geometry Nodes at render time); not rebuilt"
        elif run_seed is None:
            skipped[cls] = "the plan (DIR/plan) is missing, so the rig's seed is unknown"
        else:
            out, why = REBUILD[gen.removeprefix("procedural:")](cls, data, rest, poses, rec, run_seed, identity)
            if out is None:
                skipped[cls] = why
            else:
                meshes.extend(out)
    return meshes, skipped
