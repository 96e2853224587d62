"""One render worker: a fresh Python + bpy process that renders whole shards and exits.

    python -m blender_scripts.worker --dataset DIR --plan PLAN_DIR --shards shard_000000,shard_000001

Per identity one scene is built (head mesh, materials, lights, camera); each expression is a
vertex update and each view a camera move, so nothing is rebuilt per view. Frames already
written by an interrupted run are skipped. Progress goes to stdout as JSON lines:
``{"event": "frame", ...}``, ``{"event": "commit", ...}``, ``{"event": "rss", ...}``.
The worker draws no random numbers: every choice comes from the plan.
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


#: Classes listed under "assets" in every frame JSON (null where absent).
ASSET_CLASSES = ("hair", "beard", "eyebrows", "eyelashes", "garment", "glasses", "headwear", "makeup", "iris", "skin")


def emit(**ev) -> None:
    sys.stdout.write(json.dumps(ev) + "\n")
    sys.stdout.flush()


def rss_mb() -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def software_versions() -> dict:
    import bpy

    import synth

    return {"synth": synth.__version__, "blender": bpy.app.version_string, "python": platform.python_version()}


def render_shard(ds, plan, shard_id: str, hm, model_info: dict, tmp: Path) -> int:
    """Render the missing frames of one shard and commit it. Returns frames rendered."""
    from blender_scripts import camera as bcam
    from blender_scripts import head as bhead
    from blender_scripts import materials as bmat
    from blender_scripts import scene as bscene
    from blender_scripts.render_frame import render_view
    from synth.frames import frame_key
    from synth.labels import visibility
    from synth.conventions import project
    from synth.exr import CHANNELS
    from synth.skin import skin_albedo

    spec = plan.shard(shard_id)
    render_cfg = plan.render_settings()
    env_cfg = plan.lighting()
    versions = software_versions()
    rendered = 0
    seeds = {}
    with ds.staging(shard_id) as st:
        done = st.frames_done()
        for ident in spec["identities"]:
            i = ident["identity_index"]
            keys = [f["frame_id"] for e in ident["expressions"] for f in e["frames"]]
            for e in ident["expressions"]:
                for f in e["frames"]:
                    seeds[f["frame_id"]] = f["seed"]
            if all(k in done for k in keys):
                continue
            bscene.reset()
            f0 = ident["expressions"][0]["frames"][0]["camera"]
            width, height = int(f0["width"]), int(f0["height"])
            effective = bscene.configure_render(render_cfg, width, height)
            if env_cfg.get("environment", "uniform") == "uniform":
                bscene.uniform_environment(float(env_cfg.get("strength", 1.0)))
            else:
                bscene.hdr_environment(env_cfg["environment"], float(env_cfg.get("strength", 1.0)),
                                       float(ident.get("environment_rotation_deg", 0.0)))
            skin = dict(ident.get("skin") or {})
            albedo = skin_albedo(float(skin.get("melanin", 0.05)), float(skin.get("haemoglobin", 0.015)))
            skin_record = {**skin, "albedo_linear_srgb": [round(a, 6) for a in albedo]}
            mats = bmat.head_materials(skin, albedo)
            beta = np.asarray(ident["identity_code"], np.float64)
            head_ob = None
            cam_ob = bcam.make_camera()
            for e in ident["expressions"]:
                ekeys = [f["frame_id"] for f in e["frames"]]
                if all(k in done for k in ekeys):
                    continue
                psi = np.asarray(e["expression_code"], np.float64)
                rot = np.zeros((hm.J, 3))
                for name, r in (e.get("joint_rotations") or {}).items():
                    rot[hm.joint_index[name]] = r
                ev = hm.evaluate(beta, psi, rot)
                verts = ev.vertices[0]
                if head_ob is None:
                    head_ob = bhead.build_head_object(hm.data, verts, mats)
                else:
                    bhead.set_vertices(head_ob, verts)
                lm3d = ev.landmarks["ibug68"][0].astype(np.float64)
                head_pose = ev.joint_transforms[0, hm.joint_index["head"]].astype(np.float64)
                for f in e["frames"]:
                    key = f["frame_id"]
                    if key in done:
                        continue
                    c = f["camera"]
                    K = np.asarray(c["K"], np.float64)
                    w2c = np.asarray(c["world_to_camera"], np.float64)
                    bcam.set_camera(cam_ob, K, w2c, width, height, c["near"], c["far"])
                    out = render_view(tmp, int(f["seed"]))
                    uv, z = project(K, w2c, lm3d)
                    vis = visibility(uv, z, out["depth"], out["rgba"][..., 3])
                    fj = dict(f)
                    fj["image"] = {"width": width, "height": height, "file": f"{key}.exr",
                                   "layers": list(CHANNELS)}
                    fj["model"] = {**model_info, "identity": beta.tolist(), "expression": psi.tolist(),
                                   "expression_preset": e.get("preset"),
                                   "joint_rotations": {n: rot[j].tolist() for n, j in hm.joint_index.items()},
                                   "head_pose": head_pose.tolist()}
                    fj["landmarks_3d"] = lm3d.tolist()
                    fj["landmarks_2d"] = uv.tolist()
                    fj["landmarks_visible"] = vis.tolist()
                    fj["assets"] = {c: None for c in ASSET_CLASSES} | dict(ident.get("assets") or {})
                    fj["skin"] = skin_record
                    fj["render"] = {"preset": render_cfg.get("preset"), "resolution": [width, height],
                                    "seed": int(f["seed"]), **effective}
                    fj["software"] = versions
                    st.write_frame(key, out["rgba"], out["depth"], out["normals"], out["segmentation"], fj)
                    rendered += 1
                    emit(event="frame", shard=shard_id, key=key, render_seconds=out["render_seconds"])
            emit(event="rss", rss_mb=rss_mb())
        st.commit(manifest_extra={"seeds": seeds, "versions": versions})
    emit(event="commit", shard=shard_id)
    return rendered


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="synth render worker (one bpy process)")
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--plan", required=True)
    ap.add_argument("--shards", required=True)
    args = ap.parse_args(argv)

    # SIGTERM (Ctrl-C in the parent) -> stop between frames; staged frames are kept.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))

    from synth.errors import SynthError
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan
    from synth.shards import load_dataset

    try:
        plan = load_plan(Path(args.plan))
        ds = load_dataset(Path(args.dataset))
        data = plan.model_data()
        hm = HeadModel(data)
        model_info = {"name": data.name, "sha256": plan.model_sha256()}
        with tempfile.TemporaryDirectory(prefix="synth-worker-") as tmp:
            for shard_id in args.shards.split(","):
                t0 = time.perf_counter()
                n = render_shard(ds, plan, shard_id, hm, model_info, Path(tmp))
                print(f"worker: {shard_id}: {n} frames in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    except SynthError as e:
        emit(event="error", message=str(e))
        print(f"synth worker: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
