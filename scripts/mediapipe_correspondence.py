"""Derive (and evaluate) the mapping of mediapipe's face-mesh points to head-model surface points.

The steps (mediapipe==0.10.21 is the fit extra, in the project's venv):

    # 1. renders of the model (any synth dataset, faces roughly frontal), then PNGs + truth
    .venv/bin/synth render -n 6 -e 1 -v 5 -p preview -o R --set render.resolution=[384,384] ...
    .venv/bin/python scripts/mediapipe_correspondence.py export R WORK
    # 2. detection (any environment with mediapipe==0.10.21, numpy and pillow)
    .venv/bin/python scripts/mediapipe_correspondence.py detect WORK
    # 3. the correspondence from identities < --train (prior/fit/data/mediapipe-<model key>.json)
    .venv/bin/python scripts/mediapipe_correspondence.py derive WORK --train 4
    # 4. fit the held-out identities with it and compare with the renders' cameras
    .venv/bin/python scripts/mediapipe_correspondence.py evaluate WORK --train 4
    # a new topology whose face triangles are the old ones (e.g. the bust appended): move the file
    .venv/bin/python scripts/mediapipe_correspondence.py remap OLD_MODEL.npz [--model NEW_MODEL.npz]

Derivation: for every training frame and detected point, the camera ray through the point
is cast onto the posed model mesh of that frame (the frame JSON's codes; hair and clothes
ignored): the front-most triangle containing the point in the image, with perspective-correct
barycentric weights. Each hit (triangle, weights) is a candidate surface point; it is posed in
every training frame and projected with that frame's camera, and the candidate with the
smallest RMS distance to the detections, in units of each frame's face width (distance of
points 234 and 454), is kept. That RMS ("sigma_face") becomes the point's sigma when fitting
(times the detected face width). Points hit in fewer than half of the frames are left out.

``detect`` also runs mediapipe on each image mirrored left-right. A point found there and
mapped back (x -> W - x) is a second detection of its mirror partner (the partners come from
the data, :func:`mirror_pairs`), so every point is derived from detections on both sides of
the face. With them, a point and its partner are chosen together: the candidates of both (the
partner's mirrored onto this side, ``synth.model.meshutil.mesh_mirror``) are scored by the sum
of the point's mean squared residual and the partner's for the candidate's mirror image, so the
two land on mirror-image surface points of the (symmetric) model; points that are their own
partner are moved onto the model's midline first (``mesh_midline``). ``--independent`` chooses
every point on its own (left-right asymmetric by up to 8.8 mm on the face contour).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

N_POINTS = 478  # face mesh with refined irises


def detect(work: Path) -> None:
    import mediapipe as mp
    from PIL import Image

    out, mirrored = {}, {}
    with mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1, refine_landmarks=True) as fm:
        for p in sorted((work / "png").glob("*.png")):
            img = np.asarray(Image.open(p).convert("RGB"))
            H, W = img.shape[:2]
            for dst, im in ((out, img), (mirrored, img[:, ::-1])):
                r = fm.process(np.ascontiguousarray(im))
                dst[p.stem] = None if not r.multi_face_landmarks else \
                    [[q.x * W, q.y * H] for q in r.multi_face_landmarks[0].landmark]
    (work / "mediapipe.json").write_text(json.dumps({"mediapipe": mp.__version__, "points": out,
                                                     "points_mirrored": mirrored}))
    print(f"{sum(v is not None for v in out.values())}/{len(out)} images with a face "
          f"({sum(v is not None for v in mirrored.values())} mirrored)")


# ---------------------------------------------------------------------------- project env


def _setup_path() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def export(dataset: Path, work: Path) -> None:
    _setup_path()
    from PIL import Image

    from synth.appearance.srgb import srgb8
    from synth.dataset.reader import iter_frames

    (work / "png").mkdir(parents=True, exist_ok=True)
    truth = {}
    for fr in iter_frames(dataset):
        rgb = fr.rgb_premultiplied + (1.0 - fr.alpha[..., None]) * 0.5  # over mid grey, linear
        Image.fromarray(srgb8(rgb)).save(work / "png" / f"{fr.key}.png")
        truth[fr.key] = {"identity_index": fr.identity_index, "K": fr.K.tolist(),
                         "world_to_camera": fr.world_to_camera.tolist(), "width": fr.width, "height": fr.height,
                         "identity": fr.meta["model"]["identity"], "expression": fr.meta["model"]["expression"],
                         "joint_rotations": fr.meta["model"]["joint_rotations"]}
    (work / "truth.json").write_text(json.dumps(truth))
    print(f"exported {len(truth)} frames")


def _load(work: Path):
    truth = json.loads((work / "truth.json").read_text())
    det = json.loads((work / "mediapipe.json").read_text())
    return truth, det


def _posed(hm, t: dict) -> np.ndarray:
    rot = np.zeros((hm.J, 3))
    for n, r in t["joint_rotations"].items():
        rot[hm.joint_index[n]] = r
    return hm.vertices(np.asarray(t["identity"]), np.asarray(t["expression"]), rot)[0].astype(np.float64)


def cast(points: np.ndarray, V: np.ndarray, tris: np.ndarray, K: np.ndarray, w2c: np.ndarray):
    """Front-most triangle under each image point: (tri (P,), bary (P, 3)), tri = -1 for none.
    2D barycentrics of the projected triangle, made perspective-correct (weights / depth)."""
    from synth.conventions import project

    uv, z = project(K, w2c, V)
    a, b, c = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    za, zb, zc = z[tris[:, 0]], z[tris[:, 1]], z[tris[:, 2]]
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    ok_t = (np.abs(den) > 1e-12) & (za > 0) & (zb > 0) & (zc > 0)
    den = np.where(ok_t, den, 1.0)
    out_t, out_b = np.full(len(points), -1), np.zeros((len(points), 3))
    for i, p in enumerate(points):
        l1 = ((b[:, 1] - c[:, 1]) * (p[0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (p[1] - c[:, 1])) / den
        l2 = ((c[:, 1] - a[:, 1]) * (p[0] - c[:, 0]) + (a[:, 0] - c[:, 0]) * (p[1] - c[:, 1])) / den
        l3 = 1.0 - l1 - l2
        inside = ok_t & (l1 >= 0) & (l2 >= 0) & (l3 >= 0)
        if not inside.any():
            continue
        idx = np.nonzero(inside)[0]
        w = np.stack([l1[idx] / za[idx], l2[idx] / zb[idx], l3[idx] / zc[idx]], 1)
        depth = 1.0 / w.sum(1)  # perspective-correct depth of the hit
        k = int(np.argmin(depth))
        out_t[i], out_b[i] = idx[k], w[k] / w[k].sum()
    return out_t, out_b


def mirror_pairs(det: np.ndarray, unmirrored: np.ndarray) -> np.ndarray:
    """mediapipe's left-right partner of each point, from the data: ``pair[i] = j`` when point j
    found on the mirrored image and mapped back (``unmirrored``, (F, P, 2)) lands where point i is
    found on the image (``det``); the assignment minimising the mean squared distance in face
    widths, after moving each frame's mapped-back points onto the centroid of its points."""
    from scipy.optimize import linear_sum_assignment

    face = np.linalg.norm(det[:, 454] - det[:, 234], axis=-1)[:, None, None]
    # the two runs err by a shift of the whole face; the point set is its own mirror image, so
    # both have the same centroid: align them on it first
    unmirrored = unmirrored - unmirrored.mean(axis=1, keepdims=True) + det.mean(axis=1, keepdims=True)
    cost = np.mean(np.sum((det[:, :, None] - unmirrored[:, None]) ** 2, axis=-1) / face ** 2, axis=0)
    rows, cols = linear_sum_assignment(cost)
    pair = np.empty(len(rows), np.int64)
    pair[rows] = cols
    return pair


def derive(work: Path, train: int, out_dir: Path | None, independent: bool = False) -> Path:
    _setup_path()
    from prior.fit.landmark_sources import CORRESPONDENCE_DIR, model_key
    from synth.conventions import project
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from synth.model.meshutil import barycentric_points, mesh_midline, mesh_mirror

    model = load_default_model()
    hm = HeadModel(model, np.float64)
    tris = np.asarray(model.triangles, np.int64)
    tmpl = np.asarray(model.template, np.float64)
    truth, det = _load(work)
    keys = [k for k, t in truth.items() if t["identity_index"] < train and det["points"].get(k)]
    F = len(keys)
    posed = [_posed(hm, truth[k]) for k in keys]
    cams = [(np.asarray(truth[k]["K"]), np.asarray(truth[k]["world_to_camera"])) for k in keys]
    from prior.fit.landmark_sources import MP_PIXEL_OFFSET

    # mediapipe's pixel centres are at integers, synth's at +0.5
    det_px = np.asarray([det["points"][k] for k in keys]) + MP_PIXEL_OFFSET  # (F, 478, 2)
    obs, frame_of, pair = det_px, np.arange(F), None
    mir = det.get("points_mirrored") or {}
    mkeys = [f for f, k in enumerate(keys) if mir.get(k)]
    if mkeys:  # the mirrored images: each point's detection there is one of its mirror partner here
        W = np.asarray([truth[keys[f]]["width"] for f in mkeys], np.float64)
        un = np.asarray([mir[keys[f]] for f in mkeys]) + MP_PIXEL_OFFSET
        un[..., 0] = W[:, None] - un[..., 0]
        pair = mirror_pairs(det_px[mkeys], un)
        obs = np.concatenate([det_px, un[:, pair]])
        frame_of = np.concatenate([frame_of, mkeys])
    N = len(obs)
    face_px = np.linalg.norm(obs[:, 454] - obs[:, 234], axis=-1)  # (N,) face width in pixels
    hits_t = np.full((N, N_POINTS), -1)
    hits_b = np.zeros((N, N_POINTS, 3))
    for n in range(N):
        hits_t[n], hits_b[n] = cast(obs[n], posed[frame_of[n]], tris, *cams[frame_of[n]])

    def residuals(cand_t, cand_b, j):
        """(C, N): each candidate's 2D distance to every detection of point j, in face widths."""
        res = np.empty((len(cand_t), N))
        for f in range(F):
            X = np.einsum("ck,ckd->cd", cand_b, posed[f][tris[cand_t]])
            uv, _ = project(*cams[f], X)
            for n in np.nonzero(frame_of == f)[0]:
                res[:, n] = np.linalg.norm(uv - obs[n, j], axis=-1) / face_px[n]
        return res

    def hits(j):
        ok = np.nonzero(hits_t[:, j] >= 0)[0]
        return hits_t[ok, j], hits_b[ok, j]  # one candidate surface point per detection that hit

    def entry(j, t, b, res):
        return {"mediapipe": j, "triangle": int(t), "bary": [round(float(x), 6) for x in b],
                "sigma_face": round(float(np.sqrt(np.mean(res ** 2))), 6), "frames": int((hits_t[:, j] >= 0).sum())}

    enough = [(hits_t[:, j] >= 0).sum() >= max(2, 0.5 * N) for j in range(N_POINTS)]
    chosen = {}
    if pair is not None and not np.array_equal(pair[pair], np.arange(N_POINTS)):
        raise SystemExit("the mirror pairs found from the detections are not symmetric; "
                         "detect on more frames, or derive with --independent")
    if pair is None or independent:  # each point on its own
        for j in range(N_POINTS):
            if enough[j]:
                ct, cb = hits(j)
                res = residuals(ct, cb, j)
                c = int(np.argmin(np.mean(res ** 2, axis=1)))
                chosen[j] = entry(j, ct[c], cb[c], res[c])
    else:  # left-right pairs chosen together: a point and its partner's are mirror images on the model
        mirror = mesh_mirror(tmpl, tris)  # x -> -x of surface points
        midline = mesh_midline(tmpl, tris)
        for j in range(N_POINTS):
            p = int(pair[j])
            if p < j or not (enough[j] and enough[p]):
                continue
            (tj, bj), (tp, bp) = hits(j), hits(p)
            mtp, mbp = mirror(tp, bp)
            ct, cb = np.concatenate([tj, mtp]), np.concatenate([bj, mbp])  # j's candidates and p's mirrored
            if p == j:  # a point on the midline: its candidates moved onto the model's midline
                ct, cb = midline(ct, cb)
            mt, mb = mirror(ct, cb)  # their mirror images
            rj = residuals(ct, cb, j)
            rp = rj if p == j else residuals(mt, mb, p)
            c = int(np.argmin(np.mean(rj ** 2, axis=1) + np.mean(rp ** 2, axis=1)))
            chosen[j] = entry(j, ct[c], cb[c], rj[c])
            if p != j:
                chosen[p] = entry(p, mt[c], mb[c], rp[c])
    points = [chosen[j] for j in sorted(chosen)]
    doc = {"format": "synth-mediapipe-correspondence", "format_version": 2, "model": model.name,
           "model_key": model_key(model), "mediapipe": det["mediapipe"],
           "derivation": {"frames": len(keys), "mirrored_frames": len(mkeys), "identities": train,
                          "mirror_symmetric": pair is not None and not independent,
                          "script": "scripts/mediapipe_correspondence.py"},
           "points": points,
           # where the points lie on the rest shape they were derived on (checked when the file is read)
           "template_points": np.round(barycentric_points(
               np.asarray(model.template, np.float64), model.triangles, np.array([p["triangle"] for p in points]),
               np.array([p["bary"] for p in points], np.float64)), 7).tolist()}
    if pair is not None:  # mediapipe's left-right partners (found from the data, mirror_pairs)
        doc["mirror"] = pair.tolist()
    path = (out_dir or CORRESPONDENCE_DIR) / f"mediapipe-{model_key(model)}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=0) + "\n")
    sp = 100.0 * np.array([p["sigma_face"] for p in points])
    if pair is not None:
        print(f"mirror pairs: {int((pair == np.arange(N_POINTS)).sum())} points on the midline, "
              f"{int((pair[pair] == np.arange(N_POINTS)).sum())}/{N_POINTS} pairs symmetric")
    print(f"{len(points)}/{N_POINTS} points mapped from {F} frames (+{len(mkeys)} mirrored); RMS residual median {np.median(sp):.2f} %, "
          f"90th percentile {np.percentile(sp, 90):.2f} % of the face width -> {path}")
    return path


def evaluate(work: Path, train: int) -> None:
    """Fit each held-out identity's views with the mediapipe landmarks (K known, and unknown)."""
    _setup_path()
    from prior.fit.camera import relative_pose_errors
    from prior.fit.landmark_sources import load_correspondence, mediapipe_points_observations
    from prior.fit.landmarks_fit import fit_landmarks
    from synth.model.default import load_default_model

    model = load_default_model()
    corr = load_correspondence(model)
    truth, det = _load(work)
    ids = sorted({t["identity_index"] for t in truth.values() if t["identity_index"] >= train})
    print("| identity | views | K | rotation ° max | position cm max | RMSE px max | converged |")
    print("|---|---|---|---|---|---|---|")
    for i in ids:
        keys = [k for k, t in truth.items() if t["identity_index"] == i and det["points"].get(k)]
        t0 = truth[keys[0]]
        pts = np.asarray([det["points"][k] for k in keys])
        for known in (True, False):
            obs = mediapipe_points_observations(pts, t0["width"], t0["height"], corr)
            if known:
                obs.K = np.stack([np.asarray(truth[k]["K"]) for k in keys])
            fit = fit_landmarks(model, obs)
            rot, pos = relative_pose_errors(fit.world_to_camera, np.stack([truth[k]["world_to_camera"] for k in keys]))
            print(f"| {i} | {len(keys)} | {'known' if known else 'fitted'} | {rot.max():.2f} | {100 * pos.max():.1f} | "
                  f"{fit.rmse_px.max():.2f} | {fit.converged} |")


def remap(old_path: Path, new_path: Path | None) -> None:
    """The correspondence of the model ``old_path`` moved onto the model ``new_path`` (default: the
    shipped one) whose triangles include every triangle it names (the same three vertices, renumbered
    triangles): each point keeps its weights on the same vertices; its surface point on the new
    template must be within CORRESPONDENCE_TOLERANCE_M of the old file's. Written beside the old file
    under the new model key (the old one is removed)."""
    from prior.fit.landmark_sources import CORRESPONDENCE_DIR, CORRESPONDENCE_TOLERANCE_M, model_key
    from synth.model.default import packaged_model_path
    from synth.model.format import read_model
    from synth.model.meshutil import barycentric_points

    old, new = read_model(old_path), read_model(new_path or packaged_model_path())
    src = CORRESPONDENCE_DIR / f"mediapipe-{model_key(old)}.json"
    d = json.loads(src.read_text())
    T_old, T_new = np.asarray(old.triangles, np.int64), np.asarray(new.triangles, np.int64)
    where = {tuple(t): i for i, t in enumerate(T_new.tolist())}
    tris = np.array([where[tuple(T_old[p["triangle"]].tolist())] for p in d["points"]], np.int64)
    bary = np.array([p["bary"] for p in d["points"]], np.float64)
    pts = barycentric_points(np.asarray(new.template, np.float64), new.triangles, tris, bary)
    off = np.linalg.norm(pts - np.asarray(d["template_points"]), axis=1)
    if off.max() > CORRESPONDENCE_TOLERANCE_M:
        raise SystemExit(f"the surface points moved by up to {1000 * off.max():.4f} mm: derive the correspondence anew")
    for p, t in zip(d["points"], tris.tolist()):
        p["triangle"] = t
    key = model_key(new)
    d["model_key"] = key
    d["derivation"]["remapped"] = {"from_model_key": model_key(old), "points": len(tris), "max_move_m": float(off.max())}
    out = CORRESPONDENCE_DIR / f"mediapipe-{key}.json"
    out.write_text(json.dumps(d, indent=0) + "\n")
    if out != src:
        src.unlink()
    print(f"{src.name} -> {out.name}: {len(tris)} points, moved at most {1000 * off.max():.5f} mm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("export")
    e.add_argument("dataset", type=Path)
    e.add_argument("work", type=Path)
    e.set_defaults(run=lambda a: export(a.dataset, a.work))
    d = sub.add_parser("detect")
    d.add_argument("work", type=Path)
    d.set_defaults(run=lambda a: detect(a.work))
    for name in ("derive", "evaluate"):
        s = sub.add_parser(name)
        s.add_argument("work", type=Path)
        s.add_argument("--train", type=int, default=4, help="identities below this index derive the mapping")
        if name == "derive":
            s.add_argument("--out", type=Path, default=None, help="directory (default: prior/fit/data)")
            s.add_argument("--independent", action="store_true",
                           help="choose each point on its own, not together with its mirror partner")
            s.set_defaults(run=lambda a: derive(a.work, a.train, a.out, a.independent))
        else:
            s.set_defaults(run=lambda a: evaluate(a.work, a.train))
    r = sub.add_parser("remap")
    r.add_argument("old_model", type=Path)
    r.add_argument("--model", type=Path, default=None, help="the new model (default: the shipped one)")
    r.set_defaults(run=lambda a: remap(a.old_model, a.model))
    a = ap.parse_args()
    a.run(a)


if __name__ == "__main__":
    main()
