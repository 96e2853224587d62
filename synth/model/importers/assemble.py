"""The model file an importer writes, assembled in one place: synth's dtypes (float32 arrays,
int32 indices, int32 regions in sorted order), the iBUG-68 landmark names and a standard
normal identity prior (the sources' identity coefficients are unit-variance PCA modes)."""

from __future__ import annotations

import numpy as np

from synth.model.format import HeadModelData
from synth.model.importers.regions import IBUG68_NAMES


def imported_model(name: str, mesh, identity, expression, joints, skin_weights, regions: dict, landmarks: dict,
                   license: str, provenance: dict, extra: dict, **optional) -> HeadModelData:
    """``mesh`` = (template, triangles); ``identity`` = (basis, scale); ``expression`` =
    (basis, scale, names); ``joints`` = (names, parents, rest, identity basis). ``optional``:
    the polygon and UV members of :class:`HeadModelData`."""
    f32 = np.float32
    k = len(identity[0])
    return HeadModelData(
        name=name, template=np.array(mesh[0], f32), triangles=np.array(mesh[1], np.int32),
        identity_basis=np.array(identity[0], f32), identity_scale=np.array(identity[1], f32),
        expression_basis=np.array(expression[0], f32), expression_scale=np.array(expression[1], f32),
        expression_names=list(expression[2]), joint_names=list(joints[0]),
        joint_parents=np.array(joints[1], np.int32), joint_rest=np.array(joints[2], f32),
        joint_identity_basis=np.array(joints[3], f32), skin_weights=np.array(skin_weights, f32),
        regions={r: np.asarray(v, np.int32) for r, v in sorted(regions.items())}, landmarks=landmarks,
        landmark_names={"ibug68": list(IBUG68_NAMES)},
        prior_weights=np.ones(1), prior_means=np.zeros((1, k)), prior_covs=np.eye(k)[None].copy(),
        license=license, provenance=provenance, extra=extra, **optional)
