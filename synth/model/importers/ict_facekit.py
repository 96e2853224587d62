"""Import the ICT-FaceKit morphable head (MIT licence) into a synth head model.

    import_ict_facekit(Path("ICT-FaceKit"))   # the checkout, or its FaceXModel/ folder

Reads ``FaceXModel/generic_neutral_mesh.obj`` (topology, UVs), every ``identityNNN.obj``
(PCA identity modes, absolute shapes), every other ``*.obj`` there (expression shapes,
ARKit names plus ``cheekRaiser_*``/``PupilDilate_*``, absolute shapes) and
``vertex_indices.json`` (68 landmark vertices). Source units are centimetres, Y up, face
toward +Z; synth uses metres, Z up, face toward -Y: (x, y, z) -> 0.01 (x, -z, y), a proper
rotation, so +X stays the subject's left (checked against the eyeballs).

Identity component k is (identityk - neutral), stored as a unit direction with
``identity_scale[k]`` its norm, so code 1 reproduces the file's shape. ICT's identity
meshes are PCA modes; we assume codes ~ N(0, 1) (as ICT's own ``randomize_identity``
samples them) and store that prior. Expressions are
(shape - neutral) with scale 1: code 1 = the sculpted shape. Joints, skin weights and
regions are derived in :mod:`synth.model.importers.ict_rig`; docs/importers.md explains
every rule.
"""

from __future__ import annotations

import os
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from synth.errors import ModelFormatError
from synth.io import read_json
from synth.model import meshutil as mu
from synth.model.format import HeadModelData
from synth.model.importers import ict_rig as ir
from synth.model.importers import regions as rg
from synth.model.importers.assemble import imported_model
from synth.model.importers.derived import derived_regions
from synth.model.importers.obj import read_obj, read_obj_vertices

IMPORTER_VERSION = 1
NEUTRAL = "generic_neutral_mesh.obj"
_IDENTITY_RE = re.compile(r"^identity(\d+)\.obj$")
_FIX = "point at a checkout of https://github.com/ICT-VGL/ICT-FaceKit (or its FaceXModel folder)"

_MIT_FALLBACK = """MIT License

Copyright (c) 2020 USC Institute for Creative Technologies

Permission is hereby granted, free of charge, to any person obtaining a copy
of this software and associated documentation files (the "Software"), to deal
in the Software without restriction, including without limitation the rights
to use, copy, modify, merge, publish, distribute, sublicense, and/or sell
copies of the Software, and to permit persons to whom the Software is
furnished to do so, subject to the following conditions:

The above copyright notice and this permission notice shall be included in all
copies or substantial portions of the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
SOFTWARE.
"""


def to_synth(p_cm: np.ndarray) -> np.ndarray:
    """ICT (cm, Y up, face +Z) -> synth (m, Z up, face -Y)."""
    p = np.asarray(p_cm, np.float64)
    return 0.01 * np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def _locate(directory: Path) -> tuple[Path, Path]:
    d = Path(directory)
    if not d.is_dir():
        raise ModelFormatError("ICT-FaceKit folder not found", str(d), _FIX)
    if (d / "FaceXModel" / NEUTRAL).is_file():
        return d, d / "FaceXModel"
    if (d / NEUTRAL).is_file():
        return d.parent, d
    raise ModelFormatError(f"missing FaceXModel/{NEUTRAL}", str(d), _FIX)


def _license(root: Path, model_dir: Path) -> tuple[str, str]:
    for p in (root / "LICENSE", root / "LICENSE.txt", root / "LICENSE.md", model_dir / "LICENSE"):
        if p.is_file():
            text = p.read_text(encoding="utf-8", errors="replace").strip()
            if text:
                return text, p.name
    return _MIT_FALLBACK.strip(), "built-in copy (no LICENSE file found beside FaceXModel)"


def _shape(path: Path, n: int) -> np.ndarray:
    v = read_obj_vertices(path)
    if v.shape[0] != n:
        raise ModelFormatError(f"vertex count {v.shape[0]} differs from the neutral mesh ({n})", str(path),
                               "all ICT-FaceKit shapes must share the neutral topology")
    return to_synth(v)


def _shape_files(model_dir: Path, order: list[str]) -> tuple[list[Path], list[Path]]:
    ident: list[tuple[int, Path]] = []
    expr: dict[str, Path] = {}
    for p in model_dir.iterdir():
        if p.suffix.lower() != ".obj" or p.name == NEUTRAL or not p.is_file():
            continue
        m = _IDENTITY_RE.match(p.name)
        if m:
            ident.append((int(m.group(1)), p))
        else:
            expr[p.stem] = p
    ranked = [expr[n] for n in order if n in expr] + [expr[n] for n in sorted(expr) if n not in set(order)]
    return [p for _, p in sorted(ident)], ranked


def import_ict_facekit(directory: str | Path) -> HeadModelData:
    """Read an ICT-FaceKit checkout (or its FaceXModel folder) into a :class:`HeadModelData`.

    Raises :class:`ModelFormatError` (one line naming the file) on a missing folder,
    missing neutral mesh or landmark file, or a shape whose vertex count differs."""
    root, model_dir = _locate(Path(directory))
    neutral_path = model_dir / NEUTRAL
    mesh = read_obj(neutral_path)
    n = mesh.vertices.shape[0]
    if n != ir.NUM_VERTICES:
        raise ModelFormatError(f"expected the ICT-FaceKit topology ({ir.NUM_VERTICES} vertices), found {n}",
                               str(neutral_path), _FIX)
    v = to_synth(mesh.vertices)

    idx_path = model_dir / "vertex_indices.json"
    try:
        indices = read_json(idx_path, max_bytes=64 << 20)
        lm_ids = np.asarray(indices["idx_to_landmark_verts"], np.int64)
        order = [str(s) for s in indices.get("expressions", [])]
    except FileNotFoundError:
        raise ModelFormatError("missing vertex_indices.json (landmarks)", str(idx_path), _FIX) from None
    except (KeyError, TypeError, ValueError) as e:
        raise ModelFormatError(f"unreadable vertex_indices.json ({type(e).__name__}: {e})", str(idx_path),
                               "restore the original file") from None
    if lm_ids.shape != (68,) or lm_ids.min() < 0 or lm_ids.max() >= n:
        raise ModelFormatError("idx_to_landmark_verts must hold 68 vertex indices", str(idx_path),
                               "restore the original file")

    id_files, ex_files = _shape_files(model_dir, order)
    if not id_files:
        raise ModelFormatError("no identityNNN.obj files", str(model_dir), _FIX)
    with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:  # numpy's parser releases the GIL
        shapes = list(pool.map(lambda p: _shape(p, n), id_files + ex_files))
    id_off = np.stack(shapes[:len(id_files)]) - v
    id_scale = np.linalg.norm(id_off.reshape(len(id_files), -1), axis=1)
    if np.any(id_scale <= 0):
        bad = id_files[int(np.argmin(id_scale))]
        raise ModelFormatError("identity shape equals the neutral mesh", str(bad), "restore the original file")
    ex_off = np.stack(shapes[len(id_files):]) - v if ex_files else np.zeros((0, n, 3))
    del shapes
    ex_names = [p.stem for p in ex_files]
    jaw_open = v + ex_off[ex_names.index("jawOpen")] if "jawOpen" in ex_names else None

    # ---- joints
    lm = v[lm_ids]
    skin = ir.rng(ir.SKIN)
    edges = mu.polygon_edges(mesh.poly_offsets, mesh.poly_indices)
    ears = ir.find_ears(v, mesh.triangles, edges, mesh.tri_uv, lm)
    an = rg.anatomy(v, lm, ears)
    swap = bool(mu.fit_sphere(v[ir.rng(ir.SCLERA["l"])])[0][0] < 0)  # "left" must be +X
    keep = {s: ir.rng(ir.SCLERA[s])[mu.fit_sphere_robust(v[ir.rng(ir.SCLERA[s])])[2]] for s in ("l", "r")}
    jaw_c, jaw_angle, motion = ir.jaw_pivot(v, jaw_open, an)
    slab, front, back = ir.neck_base(v, skin, float(an.menton[2]))
    ear_sides = [e for e in (ears[v[ears, 0] > 0], ears[v[ears, 0] < 0]) if len(e)]
    if not ear_sides:
        raise ModelFormatError("could not find the ears of the neutral mesh", str(neutral_path), _FIX)
    rule = ir.JointRule(
        sclera_keep=keep, jaw_rest=jaw_c, jaw_anchors=ir.jaw_anchors(v, jaw_c, ears), ear_sides=ear_sides,
        ear_top=np.array([e[np.argmax(v[e, 2])] for e in ear_sides]),
        ear_bottom=np.array([e[np.argmin(v[e, 2])] for e in ear_sides]),
        neck_slab=slab, neck_front=front, neck_back=back, swap_eyes=swap)
    joints = rule.joints(v, v)
    id_dirs = id_off / id_scale[:, None, None]
    joint_basis = np.stack([(rule.joints(v + d, v) - joints) / s for d, s in zip(id_off, id_scale)])
    weights = ir.skin_weights(v, jaw_open, motion, joints, an, swap)

    # ---- regions and landmarks
    regions = rg.skin_regions(v, skin, ears, an)
    side = {"l": "r" if swap else "l", "r": "l" if swap else "r"}  # README side -> subject side
    for s in ("l", "r"):
        regions[f"eye_{side[s]}"] = ir.rng(ir.EYEBALL[s]).astype(np.int32)
    regions["eyes"] = ir.rng(ir.EYEBALL["l"], ir.EYEBALL["r"]).astype(np.int32)
    # the outer shell is the eye's surface (cornea included); the inner eyeball is hidden
    shells = ir.rng(ir.SCLERA["l"], ir.SCLERA["r"])
    regions["iris"] = np.concatenate([ir.cornea(v, ir.rng(ir.SCLERA[s])) for s in ("l", "r")]).astype(np.int32)
    regions["sclera"] = np.setdiff1d(shells, regions["iris"]).astype(np.int32)
    regions["eye_interior"] = ir.rng(ir.IRIS["l"], ir.IRIS["r"]).astype(np.int32)
    regions["teeth"] = ir.rng(ir.TEETH).astype(np.int32)
    regions["mouth_interior"] = ir.rng(ir.MOUTH_SOCKET, ir.GUMS_TONGUE).astype(np.int32)
    regions["eye_sockets"] = ir.rng(ir.EYE_SOCKET["l"], ir.EYE_SOCKET["r"]).astype(np.int32)
    regions["eye_fluids"] = ir.rng(*ir.EYE_FLUIDS["l"], *ir.EYE_FLUIDS["r"]).astype(np.int32)
    lashes = ir.rng(ir.LASHES["l"], ir.LASHES["r"])
    regions["eyelashes"] = lashes.astype(np.int32)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(v[lashes]).query(v[ir.rng(ir.FACE)])
    regions["eyelash_lines"] = np.nonzero(d < 2e-4)[0].astype(np.int32)  # skin where lash strips are rooted
    regions = derived_regions(v, regions, lm, float(joints[ir.JOINT_NAMES.index("neck"), 2]))

    landmarks = {"ibug68": mu.vertex_landmarks(mesh.triangles, lm_ids),
                 "dense": rg.dense_landmarks(v, mesh.triangles, regions["face"], int(lm_ids[30]), 600)}
    license_text, license_file = _license(root, model_dir)
    return imported_model(
        "ict-facekit", (v, mesh.triangles), (id_dirs, id_scale), (ex_off, np.ones(len(ex_names)), ex_names),
        (ir.JOINT_NAMES, ir.JOINT_PARENTS, joints, joint_basis), weights, regions, landmarks, license_text,
        provenance={
            "source": "ICT-FaceKit (USC Institute for Creative Technologies), MIT licence",
            "source_dir": root.name, "license_file": license_file,
            "importer": "synth.model.importers.ict_facekit", "importer_version": IMPORTER_VERSION,
            "vertices": n, "polygons": int(len(mesh.poly_offsets) - 1), "identities": len(id_files),
            "expressions": len(ex_names), "identity_files": [p.name for p in id_files],
            "source_units": "cm", "source_axes": "Y up, face +Z",
        },
        poly_offsets=mesh.poly_offsets, poly_indices=mesh.poly_indices,
        uvs=mesh.uvs, tri_uv=mesh.tri_uv, poly_uv=mesh.poly_uv,
        extra={
            "identity_prior": "N(0, I) assumed for ICT's PCA identity modes",
            "jaw_open_angle_rad": round(float(jaw_angle), 6),
            "eyes_swapped_from_readme": swap,
            "uv_layout": "UDIM-style: u beyond 1 selects the material tile",
        },
    )
