"""One render worker: a fresh Python + bpy process that renders whole shards and exits.

    python -m blender_scripts.worker --dataset DIR --plan PLAN_DIR --shards shard_000000,shard_000001

Per identity one scene is built on the neutral head (head mesh, materials, lights, assets,
camera); each expression is a vertex update and each view a camera move, so nothing is rebuilt
per view, and a frame's bytes do not depend on which frames the process rendered before it.
Frames already written by an interrupted run are skipped. Progress goes to stdout as JSON-line
events (``renderer_jobs.events``: start, frame, rss, heartbeat, skip, commit, error); the exit
status says how it ended (0, 2 input error, 4 disk full, 128 + signal when told to stop).
Signals and the death of the parent stop it at once (``renderer_jobs.guard``).
The worker draws no random numbers: every choice comes from the plan.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

# One BLAS thread, whatever the machine: a matrix product's last bits depend on how many
# threads share it, and frames must be the same bytes on every host and backend (Ray sets
# OMP_NUM_THREADS=1 for its tasks, a 64-core node would use 64). Set before numpy loads BLAS.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import numpy as np  # noqa: E402

from renderer_jobs.events import EXIT_DISK_FULL, EXIT_INPUT, Commit, Error, Rss, Skip, Start, emit
from renderer_jobs.events import Frame as FrameDone
from synth.assets.classes import RECORD_ORDER
from synth.dataset.exr import camera_attributes
from synth.errors import SynthError
from synth.io.process import rss_mb
from synth.plan.records import (Expression, Frame, Identity, Lighting, RenderSettings, StudioLight,
                                UniformLight)


def software_versions() -> dict:
    import bpy

    import synth

    return {"synth": synth.__version__, "blender": bpy.app.version_string, "python": platform.python_version()}


def _dress(ident: Identity, ctx, rigs_out: dict) -> dict:
    """Build the identity's chosen assets (only those). Returns class -> frame-JSON record, every
    registered class in RECORD_ORDER (null where absent)."""
    from blender_scripts import assets as basset

    chosen = {c: ident.assets.get(c) for c in RECORD_ORDER}
    rigs = basset.dress(ctx, {c: e for c, e in chosen.items() if e is not None})
    rigs_out.update(rigs)
    return {c: None if e is None else {**e.to_json(), "build": rigs[c].record()} for c, e in chosen.items()}


def _set_environment(env: Lighting) -> Lighting:
    """Make the plan's lighting record ``env`` the scene's world; returns it."""
    from blender_scripts import scene as bscene

    if isinstance(env, UniformLight):
        bscene.uniform_environment(float(env.strength), tuple(env.color))
    elif isinstance(env, StudioLight):
        bscene.studio_environment(env, float(env.strength), tuple(env.color))
    else:
        if not env.file:
            raise SynthError("the plan's lighting names no HDR file", "lighting", "re-plan with lighting.hdri_files")
        if not Path(env.file).is_file():
            raise SynthError("HDR environment file not found", env.file,
                             "restore the file or remove it from lighting.hdri_files and re-plan")
        bscene.hdr_environment(env.file, float(env.strength), float(env.rotation_deg))
    return env


class IdentityScene:
    """One identity's scene, built once on the identity's neutral head (head, materials,
    lighting, assets, camera); each expression is a vertex update (+ rig updates) and each view
    a camera move.

    Resume gives the same bytes: what an expression's frames show depends only on the identity
    and that expression, never on the expressions rendered before it in this process. So the
    assets are fitted to the neutral head (not to whichever expression happens to come first),
    every ``set_expression`` is a pure function of the built rigs and the new expression, and
    Cycles' persistent data (BVH, shaders) is dropped at each expression change: it is kept
    only between the views of one expression, where nothing but the camera moves.
    """

    def __init__(self, ident: Identity, hm, render_cfg: RenderSettings, run_seed: int, model_info: dict,
                 versions: dict, shard_id: str = "", asset_resolution: int | None = None):
        from blender_scripts import camera as bcam
        from blender_scripts import head as bhead
        from blender_scripts import materials as bmat
        from blender_scripts import scene as bscene
        from blender_scripts.assets import HeadContext
        from synth.appearance.lips import lip_albedo
        from synth.appearance.skin import skin_albedo
        from synth.appearance.skin_optics import pixel_footprint_m
        from synth.dataset.frame_json import RenderRecord

        self.ident, self.hm, self.render_cfg = ident, hm, render_cfg
        self.run_seed, self.model_info, self.versions, self.shard_id = run_seed, model_info, versions, shard_id
        bscene.reset()
        c0 = ident.expressions[0].frames[0].camera
        self.width, self.height = int(c0.width), int(c0.height)
        self.effective = bscene.configure_render(render_cfg, self.width, self.height)
        self.env = _set_environment(ident.lighting)
        skin = ident.skin
        mel, hb = float(skin.melanin), float(skin.haemoglobin)
        albedo, lips = skin_albedo(mel, hb), lip_albedo(mel, hb)
        self.skin_record = {**skin.to_json(), "albedo_linear_srgb": [round(a, 6) for a in albedo],
                            "lip_albedo_linear_srgb": [round(a, 6) for a in lips]}
        pixel_m = pixel_footprint_m([f.camera for f in ident.frames()])
        self.materials = bmat.head_materials(skin, albedo, pixel_m, lips)
        self.beta = np.asarray(ident.identity_code, np.float64)
        rest = self._evaluate(np.zeros(hm.data.expression_dims), np.zeros((hm.J, 3)))
        self.rest = rest[0]
        self.head_ob = bhead.build_head_object(hm.data, self.rest, self.materials)
        bhead.set_rest_positions(self.head_ob, self.rest)
        self.effective["subdivision_levels"] = bhead.add_render_subdivision(self.head_ob, max(self.width, self.height))
        self.render_record = RenderRecord(shard_id, self.width, self.height, render_cfg.preset, self.effective,
                                          versions)
        # asset_resolution: benchmarks keep strand counts independent of the image size
        self.ctx = HeadContext(data=hm.data, head=self.head_ob, materials=self.materials, rest_vertices=self.rest,
                               vertices=self.rest, joint_transforms=rest[2], joint_index=dict(hm.joint_index),
                               landmarks=rest[1], resolution=asset_resolution or max(self.width, self.height),
                               identity_index=int(ident.identity_index), run_seed=run_seed, pixel_m=pixel_m)
        self.rigs: dict = {}
        self.assets_record = _dress(ident, self.ctx, self.rigs)
        self.cam_ob = bcam.make_camera()
        self.expr = None

    def _evaluate(self, psi: np.ndarray, rot: np.ndarray):
        """(vertices, landmarks by set, joint transforms) of this identity, float64."""
        ev = self.hm.evaluate(self.beta, psi, rot)
        return (ev.vertices[0].astype(np.float64), {k: v[0].astype(np.float64) for k, v in ev.landmarks.items()},
                ev.joint_transforms[0].astype(np.float64))

    def set_expression(self, e: Expression) -> None:
        from blender_scripts import head as bhead
        from blender_scripts import scene as bscene
        from blender_scripts.assets import update as update_rigs

        hm = self.hm
        psi = np.asarray(e.expression_code, np.float64)
        rot = np.zeros((hm.J, 3))
        for name, r in e.joint_rotations.items():
            rot[hm.joint_index[name]] = r
        verts, lms, joints = self._evaluate(psi, rot)
        bhead.set_vertices(self.head_ob, verts)
        self.ctx.vertices, self.ctx.joint_transforms, self.ctx.landmarks = verts, joints, lms
        update_rigs(self.rigs, self.ctx)
        bscene.drop_render_cache()
        self.expr = {"e": e, "psi": psi, "rot": rot, "lm3d": lms["ibug68"],
                     "head_pose": joints[hm.joint_index["head"]]}

    def use_environment(self, env: Lighting) -> None:
        """Light the scene with ``env`` (an expression's environment, plans of more than one
        per expression); the world it replaces is removed and Cycles' cache dropped, so a
        frame's pixels do not depend on the environment rendered before it."""
        from blender_scripts import scene as bscene

        if env == self.env:
            return
        old = bscene.current_world()
        self.env = _set_environment(env)
        bscene.remove_world(old)
        bscene.drop_render_cache()

    def render(self, f: Frame, tmp: Path, seed: int | None = None) -> tuple[dict, dict]:
        """Render one planned frame of the current expression: (passes, frame JSON)."""
        from blender_scripts import camera as bcam
        from blender_scripts.passes import render_view
        from synth.conventions import project
        from synth.dataset.frame_json import ModelEvaluation, SceneRecord, build_frame_record
        from synth.dataset.labels import visibility

        x = self.expr
        c = f.camera
        K = np.asarray(c.K, np.float64)
        w2c = np.asarray(c.world_to_camera, np.float64)
        bcam.set_camera(self.cam_ob, K, w2c, self.width, self.height, c.near, c.far)
        out = render_view(tmp, int(f.seed if seed is None else seed))
        uv, z = project(K, w2c, x["lm3d"])
        vis = visibility(uv, z, out["depth"], out["rgba"][..., 3])
        model = ModelEvaluation(self.model_info, self.beta, x["e"], x["psi"],
                                {n: x["rot"][j] for n, j in self.hm.joint_index.items()}, x["head_pose"], x["lm3d"],
                                uv, vis)
        scene = SceneRecord(self.assets_record, self.skin_record, self.env.to_json())
        fj = build_frame_record(f, model, scene, self.render_record)
        return out, fj

    def close(self) -> None:
        self.rigs.clear()
        self.ctx = self.head_ob = None


def render_shard(ds, plan, shard_id: str, hm, model_info: dict, tmp: Path, lease_ttl: float) -> int:
    """Render the missing frames of one shard and commit it. Returns frames rendered."""
    spec = plan.shard_spec(shard_id)
    render_cfg = RenderSettings.from_json(plan.render_settings())
    versions = software_versions()
    rendered = 0
    seeds = {f.frame_id: f.seed for f in spec.frames()}
    st = ds.try_staging(shard_id, lease_ttl)
    if st is None:  # committed meanwhile, or another process holds it
        emit(Skip(shard=shard_id))
        return 0
    with st:
        done = st.frames_done()
        for ident in spec.identities:
            if all(f.frame_id in done for f in ident.frames()):
                continue
            sc = IdentityScene(ident, hm, render_cfg, spec.run_seed, model_info, versions, shard_id)
            for e in ident.expressions:
                if all(f.frame_id in done for f in e.frames):
                    continue
                sc.set_expression(e)
                for f in e.frames:
                    if f.frame_id in done:
                        continue
                    if e.environments:  # plans of more than one environment per expression
                        sc.use_environment(e.environments[int(f.environment_index)])
                    out, fj = sc.render(f, tmp)
                    cam = fj["camera"]  # also in the EXR header, as OpenEXR's standard attributes
                    st.write_frame(f.frame_id, out["rgba"], out["depth"], out["normals"], out["segmentation"], fj,
                                   exr_header=camera_attributes(cam["K"], cam["world_to_camera"], sc.width, sc.height))
                    rendered += 1
                    emit(FrameDone(shard=shard_id, key=f.frame_id, render_seconds=out["render_seconds"]))
            sc.close()
            emit(Rss(rss_mb=rss_mb()))
        st.commit(manifest_extra={"seeds": seeds, "versions": versions})
    emit(Commit(shard=shard_id))
    return rendered


def main(argv: list[str] | None = None) -> int:
    from renderer_jobs import guard
    from synth.dataset.lease import DEFAULT_TTL_S, held_leases

    ap = argparse.ArgumentParser(description="synth render worker (one bpy process)")
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--plan", required=True)
    ap.add_argument("--shards", required=True)
    ap.add_argument("--lease-seconds", type=float, default=DEFAULT_TTL_S)
    args = ap.parse_args(argv)
    # SIGTERM/SIGINT/SIGHUP, or the death of the process that started us: release the shard
    # leases and exit at once, also mid-render (renderer_jobs/guard.py)
    guard.install()
    emit(Start(shards=tuple(args.shards.split(",")), pid=os.getpid(), host=platform.node()))
    guard.heartbeat(min(10.0, args.lease_seconds / 4),
                    lambda: tuple(lease.path.name.removesuffix(".lease") for lease in held_leases()))

    from synth.dataset.shards import open_dataset
    from synth.errors import disk_full, is_disk_full
    from synth.model.head import HeadModel
    from synth.plan.io import load_plan

    try:
        plan = load_plan(Path(args.plan))
        ds = open_dataset(Path(args.dataset), plan.plan_hash, plan.expected(), shard_format=plan.shard_format)
        data = plan.model_data()
        hm = HeadModel(data)
        model_info = {"name": data.name, "sha256": plan.model_sha256()}
        with tempfile.TemporaryDirectory(prefix="synth-worker-") as tmp:
            for shard_id in args.shards.split(","):
                t0 = time.perf_counter()
                n = render_shard(ds, plan, shard_id, hm, model_info, Path(tmp), args.lease_seconds)
                print(f"worker: {shard_id}: {n} frames in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    except SynthError as e:
        emit(Error(shard=args.shards, message=str(e)))
        print(f"synth worker: error: {e}", file=sys.stderr)
        return EXIT_INPUT
    except OSError as e:
        if not is_disk_full(e):
            raise
        err = disk_full(e.filename or args.dataset, e)
        emit(Error(shard=args.shards, message=str(err)))
        print(f"synth worker: error: {err}", file=sys.stderr)
        return EXIT_DISK_FULL
    return 0


if __name__ == "__main__":
    from renderer_jobs.guard import finish

    try:
        rc = main()
    except SystemExit as e:  # argparse
        rc = e.code if isinstance(e.code, int) else 2
    except BaseException:
        import traceback

        traceback.print_exc()
        rc = 1
    finish(rc)
