"""The prepare pass: one read of the committed frames, before training, for what needs them all.

Per committed shard, one record ``<prepare dir>/<shard>.npz`` (default ``DATASET/.prior/prepare``;
written atomically, keyed by the sha256 of the shard's manifest) holds, per identity in it:
frame count, views per expression, the conditioning code parts of each (identity, expression)
(its first frame's identity and expression codes and joint rotations), the front camera (the
frame nearest azimuth 0 / elevation 0), and the box and tight sphere of its foreground depth
points (:mod:`prior.data.bounds`). Plus the shard's head model (name, sha256), image size and
code sizes.

Bounds: an identity whose frames are all in one shard (``synth render`` writes one shard per
identity) gets exactly the sphere of all its points. One spread over several shards gets the
centre of the merged box (exact) and the smallest radius the per-shard spheres guarantee
(``max |c - c_s| + r_s``: conservative, it holds every point).

:func:`prepare` writes the records of shards that have none (or whose manifest changed), and
nothing else: a rerun with nothing new writes nothing. Memory: one identity's points of one
shard at a time, reduced to their convex-hull vertices (which keep the box and the farthest
point from any centre: exact) beyond :data:`REDUCE_AT` points; records are a few kB per
identity and stay on disk (a :class:`Record` holds a shard's meta and identities; the rest is
read when merged). Per frame the pass reads the frame JSON (orjson) and the EXR's depth and
alpha only. :func:`build_table` merges records, one at a time, into the run's :class:`Table`.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import orjson

from prior.data.bounds import depth_points, grow, tight_sphere
from prior.data.codes import CodeLayout
from prior.data.identities import IdentityInfo
from prior.data.sources import ShardDamaged, ShardRef, Source, read_shard
from synth.dataset.exr import DEPTH_CHANNEL, decode_channels
from synth.errors import SynthError
from synth.io import atomic_write_bytes, sha256_bytes

FORMAT = "synth-prior-prepare/1"
REDUCE_AT = 2_000_000


def _hull(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of ``points`` (float32, (n, 3)); every point when the set
    is too small or flat for a hull (Qhull refuses it)."""
    if len(points) < 64:
        return points
    from scipy.spatial import ConvexHull, QhullError

    try:
        return np.ascontiguousarray(points[ConvexHull(points.astype(np.float64)).vertices])
    except (QhullError, ValueError):
        return np.unique(points, axis=0)


def _front_score(meta: dict) -> float:
    cam = meta.get("camera", {})
    try:
        return abs(float(cam["azimuth_deg"])) + abs(float(cam["elevation_deg"]))
    except (KeyError, TypeError, ValueError):
        return float("inf")


def shard_signature(ref: ShardRef) -> str:
    """What identifies the shard's content: its manifest's sha256 (a tar without manifest: size and mtime)."""
    if ref.manifest is not None:
        return ref.signed or sha256_bytes(ref.manifest.read_bytes())
    st = os.stat(ref.path)
    return f"tar:{st.st_size}:{st.st_mtime_ns}"


def summarise_shard(ref: ShardRef, signature: str) -> dict[str, np.ndarray]:
    """The record of one shard (see the module docstring). Raises ShardDamaged."""
    per: dict[int, dict] = {}
    pairs: dict[tuple[int, int], dict] = {}
    head = size = sizes = None
    n = 0
    for key, jb, eb in read_shard(ref):
        try:  # the frame JSON and the EXR's depth and alpha: all a record needs (not the colours)
            meta = orjson.loads(jb)  # strict (no NaN), 1024 levels at most; 4x json.loads here
            if not isinstance(meta, dict) or meta.get("frame_id") != key:
                raise ValueError(f"its JSON is not the JSON of frame {key}")
            model, cam = meta["model"], meta["camera"]
            ident, expr = int(meta["identity_index"]), int(meta["expression_index"])
            beta = np.asarray(model["identity"], np.float32).reshape(-1)
            ex = np.asarray(model["expression"], np.float32).reshape(-1)
            hm = {k: model.get(k) for k in ("name", "sha256")}
            K, c2w = np.asarray(cam["K"], np.float64), np.asarray(cam["camera_to_world"], np.float64)
            width, height, (alpha, depth) = decode_channels(eb, ("A", DEPTH_CHANNEL), f"{ref.path}:{key}")
            pts = depth_points(depth, alpha, K, c2w).astype(np.float32)
        except (SynthError, KeyError, TypeError, ValueError, RecursionError) as e:
            raise ShardDamaged(f"frame {key} cannot be read ({str(getattr(e, 'what', e))[:120]})") from None
        if head is None:
            head, size, sizes = hm, (width, height), (beta.size, ex.size)
        if hm != head or (width, height) != size or (beta.size, ex.size) != sizes:
            raise ShardDamaged(f"frame {key} has another head model, code size or resolution than the shard's first")
        p = per.get(ident)
        if p is None:
            p = per[ident] = {"frames": 0, "pts": [], "npts": 0, "fg": 0, "front": (np.inf, None, None)}
        p["frames"] += 1
        p["pts"].append(pts)
        p["npts"] += len(pts)
        p["fg"] += len(pts)
        if p["npts"] > REDUCE_AT:
            p["pts"] = [_hull(np.concatenate(p["pts"]))]
            p["npts"] = len(p["pts"][0])
        score = _front_score(meta)
        if p["front"][1] is None or score < p["front"][0]:
            p["front"] = (score, K, c2w)
        q = pairs.get((ident, expr))
        if q is None:
            rots = model.get("joint_rotations") or {}
            q = pairs[ident, expr] = {"views": 0, "beta": beta, "expr": ex,
                                      "joints": {j: np.asarray(r, np.float32).reshape(-1)[:3]
                                                 for j, r in rots.items() if np.asarray(r).size == 3}}
        q["views"] += 1
        n += 1
    if n == 0:
        raise ShardDamaged("it has no frames")
    ids = sorted(per)
    boxes, spheres = [], []
    for i in ids:
        pts = np.concatenate(per[i]["pts"]) if per[i]["npts"] else np.zeros((1, 3), np.float32)
        boxes.append(np.stack([pts.min(0), pts.max(0)]))
        spheres.append(tight_sphere(pts))
    keys = sorted(pairs)
    jn = sorted({j for q in pairs.values() for j in q["joints"]})
    joints = np.full((len(keys), len(jn), 3), np.nan, np.float32)
    for a, k in enumerate(keys):
        for b, j in enumerate(jn):
            if j in pairs[k]["joints"]:
                joints[a, b] = pairs[k]["joints"][j]
    meta_out = {"format": FORMAT, "shard": ref.shard, "signature": signature, "frames": n, "size": list(size),
                "head_model": head, "code_sizes": list(sizes)}
    return {"meta": np.array(json.dumps(meta_out)), "identities": np.array(ids, np.int64),
            "frames": np.array([per[i]["frames"] for i in ids], np.int64),
            "fg_points": np.array([per[i]["fg"] for i in ids], np.int64),
            "front_score": np.array([per[i]["front"][0] for i in ids]),
            "front_K": np.stack([per[i]["front"][1] if per[i]["front"][1] is not None else np.eye(3) for i in ids]),
            "front_c2w": np.stack([per[i]["front"][2] if per[i]["front"][2] is not None else np.eye(4) for i in ids]),
            "box": np.stack(boxes).astype(np.float64),
            "centre": np.stack([c for c, _ in spheres]), "radius": np.array([r for _, r in spheres]),
            "pairs": np.array(keys, np.int64).reshape(-1, 2), "views": np.array([pairs[k]["views"] for k in keys]),
            "beta": np.stack([pairs[k]["beta"] for k in keys]).astype(np.float32),
            "expr": np.stack([pairs[k]["expr"] for k in keys]).astype(np.float32),
            "joint_names": np.array(jn, dtype="U32"), "joints": joints}


def record_meta(rec) -> dict:
    return json.loads(str(rec["meta"]))


class Record(Mapping):
    """A shard's record on disk: its ``meta`` and ``identities`` held, the rest read when asked
    (:meth:`load`), so that a run holds a few hundred bytes per shard, not the record."""

    def __init__(self, path: Path, meta, identities: np.ndarray):
        self.path, self._meta, self._ids = Path(path), meta, identities

    def load(self) -> dict:
        with np.load(self.path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}

    def __getitem__(self, k: str):
        if k == "meta":
            return self._meta
        if k == "identities":
            return self._ids
        return self.load()[k]

    def __iter__(self):
        return iter(self.load())

    def __len__(self) -> int:
        return len(self.load())


def loaded(rec) -> dict:
    """Every array of a record (a :class:`Record` is read from its file)."""
    return rec.load() if isinstance(rec, Record) else rec


def _read_record(path: Path) -> Record | None:
    """A record's meta and identities, or None when it cannot be read (cut short, foreign): it
    is then computed again."""
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            rec = Record(path, z["meta"], z["identities"])
        return rec if record_meta(rec).get("format") == FORMAT else None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None


@dataclass
class PrepareResult:
    records: list  # in shard order: Record (on disk) or dict (its arrays)
    refs: list[ShardRef]  # the shards of the records
    written: int = 0
    reused: int = 0
    skipped: list[str] = field(default_factory=list)  # damaged shards, one line each
    skipped_shards: list[str] = field(default_factory=list)  # their ids


def _compute(ref: ShardRef, out_dir: Path) -> tuple[Record | None, str | None]:
    """Summarise one shard and write its record (atomically): (record, None) or (None, warning)."""
    try:
        rec = summarise_shard(ref, shard_signature(ref))
        buf = io.BytesIO()
        np.savez(buf, **rec)
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{ref.shard}.npz"
        atomic_write_bytes(path, buf.getvalue(), durable=False)
        return Record(path, rec["meta"], rec["identities"]), None
    except (ShardDamaged, OSError) as e:
        return None, f"skipping damaged shard {ref.shard} ({ref.path}): {e}"


def prepare(source: Source, out_dir: Path, *, refs: list[ShardRef] | None = None,
            warn: Callable[[str], None] | None = None, progress=None, workers: int = 1) -> PrepareResult:
    """Records of every committed shard of ``source`` (or of ``refs``), computing and writing
    only those missing or stale (in ``workers`` processes); a damaged shard is skipped with one
    line to ``warn``."""
    out_dir = Path(out_dir)
    refs = source.committed() if refs is None else refs
    got: dict[int, dict] = {}
    todo = []
    for i, ref in enumerate(refs):
        path = out_dir / f"{ref.shard}.npz"
        try:
            rec = _read_record(path) if path.is_file() else None
            fresh = rec is not None and record_meta(rec).get("signature") == shard_signature(ref)
        except OSError:
            fresh = False
        if fresh:
            got[i] = rec
        else:
            todo.append(i)
    res = PrepareResult([], [], reused=len(got))
    if len(todo) > 1 and workers > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as pool:
            done = pool.map(_compute, [refs[i] for i in todo], [out_dir] * len(todo), chunksize=4)
            results = list(_progress(done, progress, len(todo)))
    else:
        results = list(_progress((_compute(refs[i], out_dir) for i in todo), progress, len(todo)))
    for i, (rec, line) in zip(todo, results):
        if rec is None:
            res.skipped.append(line)
            res.skipped_shards.append(refs[i].shard)
            if warn is not None:
                warn(line)
        else:
            got[i] = rec
            res.written += 1
    for i in sorted(got):
        res.records.append(got[i])
        res.refs.append(refs[i])
    return res


def _progress(it, progress, total):
    for n, x in enumerate(it):
        if progress is not None:
            progress(n + 1, total)
        yield x


@dataclass
class Table:
    """What training needs to know before reading pixels: the run's identities (latent id =
    position in the sorted ``identities``), their bounds, codes and front cameras
    (:class:`IdentityInfo`), where each one's frames are, the code layout, head model and size."""

    layout: CodeLayout
    info: IdentityInfo
    shards_of: dict[int, list[ShardRef]]  # latent id -> shards holding its frames
    frames: np.ndarray  # (M,) frames per latent id (0: not committed yet)
    size: tuple[int, int]  # (height, width)
    head_model: dict

    @property
    def available(self) -> np.ndarray:
        """Latent ids with committed frames and bounds."""
        return np.nonzero(self.frames > 0)[0]


def _check_same(value, first, what: str, where: str, fix: str):
    if value != first:
        raise SynthError(f"the dataset mixes {what}: {value} and {first}", where, fix)


def build_table(result: PrepareResult, *, joints: tuple[str, ...], margin: float, holdout_views: int = 0,
                planned: list[int] | None = None, where: str = "dataset") -> Table:
    """Merge shard records (shard order) into a :class:`Table`; ``planned``: every identity
    index of the plan (latent ids then do not change as shards arrive)."""
    if not result.records:
        raise SynthError("dataset has no committed frames", where,
                         "render it first (synth render ... --out DIR) or pass the --out directory of a render")
    meta0 = record_meta(result.records[0])
    head, size, sizes = meta0["head_model"], tuple(meta0["size"]), tuple(meta0["code_sizes"])
    for m in map(record_meta, result.records[1:]):
        _check_same(m["head_model"], head, "head models", where, "train on a dataset of one head model")
        _check_same(tuple(m["size"]), size, "resolutions", where, "train on a dataset rendered at one resolution")
        _check_same(tuple(m["code_sizes"]), sizes, "code sizes", where, "use one head model for the whole dataset")
    seen = np.unique(np.concatenate([np.asarray(r["identities"], np.int64) for r in result.records]))
    uniq = np.union1d(np.asarray(planned or [], np.int64), seen)
    M = len(uniq)
    frames = np.zeros(M, np.int64)
    fg = np.zeros(M, np.int64)
    spheres: dict[int, list[tuple]] = {}  # latent id -> (box, centre, radius) per shard
    front_score = np.full(M, np.nan)  # nan: no front camera yet
    front_K, front_c2w = np.tile(np.eye(3), (M, 1, 1)), np.tile(np.eye(4), (M, 1, 1))
    shards_of: dict[int, list[ShardRef]] = {}
    pair_keys, pair_codes, pair_views = [], [], []  # per record: (latent id, expression), codes, views
    for r, ref in zip(result.records, result.refs):
        rec = loaded(r)
        lat = np.searchsorted(uniq, rec["identities"])
        for a, m in enumerate(lat.tolist()):
            frames[m] += rec["frames"][a]
            fg[m] += rec["fg_points"][a]
            if rec["fg_points"][a]:
                spheres.setdefault(m, []).append((rec["box"][a], rec["centre"][a], float(rec["radius"][a])))
            shards_of.setdefault(m, []).append(ref)
            if np.isnan(front_score[m]) or rec["front_score"][a] < front_score[m]:
                front_score[m], front_K[m], front_c2w[m] = rec["front_score"][a], rec["front_K"][a], rec["front_c2w"][a]
        jn = [str(j) for j in rec["joint_names"]]
        pairs = rec["pairs"].reshape(-1, 2)
        ok = [np.isfinite(rec["joints"][:, jn.index(j)]).all(1) if j in jn else np.zeros(len(pairs), bool)
              for j in joints]
        missing = [j for j, o in zip(joints, ok) if not o.all()]
        if missing:
            raise SynthError(f"frames of identity {pairs[~np.logical_and.reduce(ok)][0, 0]} have no rotation for "
                             f"joint(s) {', '.join(missing)} (they have: {', '.join(jn) or 'none'})", ref.shard,
                             "set data.joints to joints the dataset records")
        cols = [rec["joints"][:, jn.index(j)] for j in joints]
        pair_keys.append(np.stack([np.searchsorted(uniq, pairs[:, 0]), pairs[:, 1]], 1))
        pair_codes.append(np.concatenate([rec["beta"], rec["expr"], *cols], 1).astype(np.float32))
        pair_views.append(np.asarray(rec["views"], np.int64))
    keys, first, inv = np.unique(np.concatenate(pair_keys), axis=0, return_index=True, return_inverse=True)
    codes = np.concatenate(pair_codes)[first]  # each (identity, expression)'s first shard's codes
    views = np.bincount(inv.reshape(-1), np.concatenate(pair_views), len(keys)).astype(np.int64)
    del pair_codes
    centre, radius = np.zeros((M, 3)), np.zeros(M)
    for m in np.nonzero(frames)[0].tolist():
        parts = spheres.get(m)
        if not parts:
            raise SynthError(f"identity {uniq[m]} has no foreground depth pixel in any frame", where,
                             "check the renders (synth preview): the head must be visible")
        if len(parts) == 1:
            c, r = parts[0][1], parts[0][2]
        else:  # the merged box's centre; a radius that holds every shard's sphere
            box = np.stack([p[0] for p in parts])
            c = 0.5 * (box[:, 0].min(0) + box[:, 1].max(0))
            r = max(float(np.linalg.norm(c - p[1])) + p[2] for p in parts)
        centre[m], radius[m] = c, grow(r, margin)
    if holdout_views and (views <= holdout_views).any():
        (m, e), v = keys[np.argmax(views <= holdout_views)], views[np.argmax(views <= holdout_views)]
        raise SynthError(f"identity {uniq[m]} expression {e} has {v} views, not more than "
                         f"data.holdout_views = {holdout_views}", where,
                         "lower data.holdout_views or render more views")
    layout = CodeLayout(int(sizes[0]), int(sizes[1]), tuple(joints))
    info = IdentityInfo(identity_index=uniq, centre=centre, radius=radius, front_K=front_K, front_c2w=front_c2w,
                        front_size=np.where(frames[:, None] > 0, [size[0], size[1]], 0).astype(np.int64),
                        code_keys=keys.astype(np.int64).reshape(-1, 2), codes=codes.reshape(len(keys), layout.size))
    return Table(layout, info, shards_of, frames, (int(size[1]), int(size[0])), head or {})


__all__ = ["FORMAT", "PrepareResult", "Record", "Table", "build_table", "loaded", "prepare", "summarise_shard"]
