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
alpha only.

The merged table ``<prepare dir>/table.merged`` (:data:`MERGED_FILE`; a record's name always ends
in ``.npz``, so no shard can take it) holds every record of the last pass in one file: each
field of all records concatenated into one array, and per record its shard, signature, frame
count and offsets. :func:`prepare` rewrites it whenever the records it returns are not exactly
the ones it holds (and only then), and trusts it for every shard whose signature it holds, so a
rank of a run opens one file, not a record per shard, and builds its table from a few large
arrays: its memory after the table does not grow with scattered small allocations (reading
1,500 record files one by one fragments ~10 MB of heap).
:func:`build_table` merges the records (vectorised over the concatenated fields) into the
run's :class:`Table`.
"""

from __future__ import annotations

import io
import json
import os
import struct
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
MERGED_FORMAT = "synth-prior-prepare-merged/1"
MERGED_FILE = "table.merged"
REDUCE_AT = 2_000_000
#: a record's per-identity fields (one row per identity of the shard) and per-pair fields (one
#: row per (identity, expression) of the shard); ``joints`` is per pair, by ``joint_names``
IDENT_FIELDS = ("identities", "frames", "fg_points", "front_score", "front_K", "front_c2w", "box", "centre", "radius")
PAIR_FIELDS = ("pairs", "views", "beta", "expr")


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
    """Every array of a record (a :class:`Record` is read from its file, a :class:`MergedRecord` from its table)."""
    return rec.load() if isinstance(rec, (Record, MergedRecord)) else rec


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


class Merged:
    """The records of one prepare pass in one file (:data:`MERGED_FILE`): ``fields`` holds each
    record field of all records concatenated (``joints`` over the union ``joint_names``, NaN where
    a record lacks a joint), ``ident_off`` / ``pair_off`` the (n + 1) row offsets of each record,
    and per record its shard id, signature, frame count and kind (index into ``kinds``: its head
    model, image size and code sizes)."""

    def __init__(self, fields: dict[str, np.ndarray], shards: list[str], signatures: list[str],
                 frames: np.ndarray, kind: np.ndarray, kinds: list[dict]):
        self.fields, self.shards, self.signatures = fields, shards, signatures
        self.frames, self.kind, self.kinds = frames, kind, kinds
        self.position = {s: i for i, s in enumerate(shards)}

    def __len__(self) -> int:
        return len(self.shards)

    def meta(self, i: int) -> dict:
        return {"format": FORMAT, "shard": self.shards[i], "signature": self.signatures[i],
                "frames": int(self.frames[i]), **self.kinds[int(self.kind[i])]}

    def record(self, i: int) -> dict[str, np.ndarray]:
        """Record ``i``'s arrays, as :func:`summarise_shard` made them (its joints over the union names)."""
        f = self.fields
        a, b = int(f["ident_off"][i]), int(f["ident_off"][i + 1])
        c, d = int(f["pair_off"][i]), int(f["pair_off"][i + 1])
        out = {"meta": np.array(json.dumps(self.meta(i)))}
        out.update({k: f[k][a:b] for k in IDENT_FIELDS})
        out.update({k: f[k][c:d] for k in PAIR_FIELDS})
        out["joint_names"], out["joints"] = f["joint_names"], f["joints"][c:d]
        return out

    def save(self, path: Path) -> None:
        """Written atomically (not fsynced: it is a cache, recomputed from the records when lost)."""
        index = {"format": MERGED_FORMAT, "shards": self.shards, "signatures": self.signatures, "kinds": self.kinds}
        buf = io.BytesIO()
        np.savez(buf, index=np.array(json.dumps(index)), rec_frames=self.frames, rec_kind=self.kind, **self.fields)
        atomic_write_bytes(path, buf.getvalue(), durable=False)

    @classmethod
    def load(cls, path: Path) -> "Merged | None":
        """The merged table at ``path``, memory-mapped (read-only), or None when it is missing,
        cut short or foreign (it is then rebuilt from the records). Mapped, not read: dropping
        it unmaps the file and frees no heap memory (freeing large heap blocks raises glibc's
        mmap threshold, after which a run's later arrays stay in the heap and add to its peak)."""
        try:
            z = _map_npz(path)
            index = json.loads(str(z["index"]))
            if index.get("format") != MERGED_FORMAT:
                return None
            fields = {k: z[k] for k in (*IDENT_FIELDS, *PAIR_FIELDS, "joint_names", "joints", "ident_off", "pair_off")}
            frames, kind = z["rec_frames"], z["rec_kind"]
            n = len(index["shards"])
            if len(index["signatures"]) != n or frames.shape != (n,) or kind.shape != (n,) \
                    or fields["ident_off"].shape != (n + 1,) or fields["pair_off"].shape != (n + 1,):
                return None
            return cls(fields, list(index["shards"]), list(index["signatures"]), frames, kind, list(index["kinds"]))
        except (OSError, ValueError, KeyError, TypeError, EOFError, struct.error):
            return None


def _map_npz(path: Path) -> dict[str, np.ndarray]:
    """The arrays of an uncompressed ``.npz`` (what :func:`numpy.savez` writes) as read-only
    views of one memory map of the file. Raises OSError or ValueError for anything else."""
    import mmap
    import zipfile

    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size == 0:
            raise ValueError("empty file")
        mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
    except zipfile.BadZipFile as e:
        raise ValueError(str(e)) from None
    for info in infos:
        if info.compress_type != zipfile.ZIP_STORED or not info.filename.endswith(".npy"):
            raise ValueError(f"member {info.filename} is not a stored .npy")
        h = info.header_offset
        if mm[h:h + 4] != b"PK\x03\x04":
            raise ValueError("bad local header")
        name_len, extra_len = struct.unpack("<HH", mm[h + 26:h + 30])
        start = h + 30 + name_len + extra_len
        if start + info.file_size > size:
            raise ValueError("member runs past the end of the file")
        head = io.BytesIO(mm[start:start + min(info.file_size, 65536)])
        version = np.lib.format.read_magic(head)
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read(head)
        if dtype.hasobject:
            raise ValueError("object arrays are not read")
        offset = start + head.tell()
        if offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize > start + info.file_size:
            raise ValueError(f"member {info.filename} is cut short")
        out[info.filename[:-4]] = np.ndarray(shape, dtype, buffer=mm, offset=offset, order="F" if fortran else "C")
    return out


class MergedRecord(Mapping):
    """Record ``i`` of a :class:`Merged` table (a view: nothing is copied until asked)."""

    __slots__ = ("merged", "i")

    def __init__(self, merged: Merged, i: int):
        self.merged, self.i = merged, i

    def load(self) -> dict:
        return self.merged.record(self.i)

    def __getitem__(self, k: str):
        if k == "meta":
            return np.array(json.dumps(self.merged.meta(self.i)))
        if k == "identities":
            f = self.merged.fields
            return f["identities"][int(f["ident_off"][self.i]):int(f["ident_off"][self.i + 1])]
        return self.load()[k]

    def __iter__(self):
        return iter(self.load())

    def __len__(self) -> int:
        return len(self.load())


def _meta_kind(meta: dict) -> dict:
    return {"size": list(meta["size"]), "head_model": meta["head_model"], "code_sizes": list(meta["code_sizes"])}


def merge_records(records: list) -> Merged:
    """One :class:`Merged` of ``records`` (in order). Runs of consecutive records of one merged
    table are taken as row ranges of its arrays; other records are read from their files one at a
    time. A single merged table taken whole is returned as it is."""
    if records and isinstance(records[0], MergedRecord) and _is_whole(records, records[0].merged):
        return records[0].merged
    parts: list[tuple[dict, list[dict], list[str]]] = []  # (fields, per-record metas, joint names)
    run: list[MergedRecord] = []

    def flush():
        if not run:
            return
        m, idx = run[0].merged, np.array([r.i for r in run])
        f = m.fields
        irows = np.concatenate([np.arange(f["ident_off"][i], f["ident_off"][i + 1]) for i in idx])
        prows = np.concatenate([np.arange(f["pair_off"][i], f["pair_off"][i + 1]) for i in idx])
        out = {k: f[k][irows] for k in IDENT_FIELDS}
        out.update({k: f[k][prows] for k in PAIR_FIELDS})
        out["joints"] = f["joints"][prows]
        out["ident_n"] = np.diff(f["ident_off"])[idx]
        out["pair_n"] = np.diff(f["pair_off"])[idx]
        parts.append((out, [m.meta(i) for i in idx.tolist()], [str(j) for j in f["joint_names"]]))
        run.clear()

    for r in records:
        if isinstance(r, MergedRecord) and (not run or run[-1].merged is r.merged):
            run.append(r)
            continue
        flush()
        if isinstance(r, MergedRecord):
            run.append(r)
            continue
        rec = loaded(r)
        out = {k: np.asarray(rec[k]) for k in (*IDENT_FIELDS, *PAIR_FIELDS)}
        out["pairs"] = out["pairs"].reshape(-1, 2)
        out["joints"] = np.asarray(rec["joints"], np.float32).reshape(len(out["pairs"]), -1, 3)
        out["ident_n"] = np.array([len(out["identities"])])
        out["pair_n"] = np.array([len(out["pairs"])])
        parts.append((out, [record_meta(rec)], [str(j) for j in rec["joint_names"]]))
    flush()
    names = sorted({j for _, _, jn in parts for j in jn})
    fields: dict[str, np.ndarray] = {}
    if parts:
        for k in (*IDENT_FIELDS, *PAIR_FIELDS):
            fields[k] = np.concatenate([p[0][k] for p in parts])
        joints = np.full((len(fields["pairs"]), len(names), 3), np.nan, np.float32)
        o = 0
        for out, _, jn in parts:
            n = len(out["pairs"])
            for b, j in enumerate(jn):
                joints[o:o + n, names.index(j)] = out["joints"][:, b]
            o += n
        fields["joints"] = joints
    else:
        fields.update({k: np.zeros((0,)) for k in (*IDENT_FIELDS, *PAIR_FIELDS)})
        fields["joints"] = np.zeros((0, 0, 3), np.float32)
    fields["joint_names"] = np.array(names, dtype="U32")
    metas = [m for _, ms, _ in parts for m in ms]
    for k, name in (("ident_off", "ident_n"), ("pair_off", "pair_n")):
        counts = np.concatenate([p[0][name] for p in parts]) if parts else np.zeros(0, np.int64)
        fields[k] = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    kinds: list[dict] = []
    kind = np.zeros(len(metas), np.int64)
    for a, m in enumerate(metas):
        k = _meta_kind(m)
        if k not in kinds:
            kinds.append(k)
        kind[a] = kinds.index(k)
    return Merged(fields, [m["shard"] for m in metas], [m["signature"] for m in metas],
                  np.array([m["frames"] for m in metas], np.int64), kind, kinds)


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
            warn: Callable[[str], None] | None = None, progress=None, workers: int = 1,
            write_merged: bool = True) -> PrepareResult:
    """Records of every committed shard of ``source`` (or of ``refs``), computing and writing
    only those missing or stale (in ``workers`` processes); a damaged shard is skipped with one
    line to ``warn``. A shard whose signature the merged table holds is taken from it (its
    record file is not opened). ``write_merged``: rewrite the merged table when the records
    returned are not exactly its own (one writer per prepare directory at a time: rank 0)."""
    out_dir = Path(out_dir)
    refs = source.committed() if refs is None else refs
    merged = Merged.load(out_dir / MERGED_FILE)
    got: dict[int, object] = {}
    todo = []
    for i, ref in enumerate(refs):
        path = out_dir / f"{ref.shard}.npz"
        try:
            sig = shard_signature(ref)
            j = merged.position.get(ref.shard) if merged is not None else None
            if j is not None and merged.signatures[j] == sig:
                got[i] = MergedRecord(merged, j)
                continue
            rec = _read_record(path) if path.is_file() else None
            fresh = rec is not None and record_meta(rec).get("signature") == sig
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
    if write_merged and res.records and not _is_whole(res.records, merged):
        res.records = _write_merged(res.records, out_dir)
    return res


#: at least this many records to read from their files: the merged table is built in a child
#: process, so that reading them one by one leaves no fragmented heap in this one
MERGE_IN_CHILD_AT = 64


def _is_whole(records: list, merged: "Merged | None") -> bool:
    return merged is not None and len(records) == len(merged) and all(
        isinstance(r, MergedRecord) and r.merged is merged and r.i == i for i, r in enumerate(records))


def _merge_to(records: list, path: Path) -> None:
    merge_records(records).save(path)


def _write_merged(records: list, out_dir: Path) -> list:
    """Write the merged table of ``records`` and return them as its records."""
    path = out_dir / MERGED_FILE
    out_dir.mkdir(parents=True, exist_ok=True)
    m = None
    if sum(not isinstance(r, MergedRecord) for r in records) >= MERGE_IN_CHILD_AT:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        try:
            with ProcessPoolExecutor(1, mp_context=mp.get_context("fork")) as pool:
                pool.submit(_merge_to, records, path).result()
            m = Merged.load(path)
        except (OSError, RuntimeError):  # no process to spare (BrokenProcessPool is a RuntimeError)
            m = None
    if m is None or len(m) != len(records):
        m = merge_records(records)
        m.save(path)
    return [MergedRecord(m, i) for i in range(len(m))]


def _progress(it, progress, total):
    for n, x in enumerate(it):
        if progress is not None:
            progress(n + 1, total)
        yield x



def trim_heap() -> None:
    """Hand the heap's free pages back to the system (glibc's ``malloc_trim``; nothing where
    there is none). Call it once the prepare result is dropped, after :func:`build_table`: the
    table is built from a few large temporaries, and glibc keeps freed ones in the heap once its
    mmap threshold has grown past their size, where they would add to every later peak."""
    try:
        import ctypes

        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError, TypeError):
        pass

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
    index of the plan (latent ids then do not change as shards arrive). Vectorised over the
    records' concatenated fields (:func:`merge_records`): a few large arrays, whatever the
    number of shards."""
    if not result.records:
        raise SynthError("dataset has no committed frames", where,
                         "render it first (synth render ... --out DIR) or pass the --out directory of a render")
    mg = merge_records(result.records)
    f, refs = mg.fields, result.refs
    k0 = mg.kinds[int(mg.kind[0])]
    other = np.nonzero(mg.kind != mg.kind[0])[0]
    if other.size:  # the first record unlike the first one: what differs, in this order
        k = mg.kinds[int(mg.kind[other[0]])]
        _check_same(k["head_model"], k0["head_model"], "head models", where, "train on a dataset of one head model")
        _check_same(tuple(k["size"]), tuple(k0["size"]), "resolutions", where,
                    "train on a dataset rendered at one resolution")
        _check_same(tuple(k["code_sizes"]), tuple(k0["code_sizes"]), "code sizes", where,
                    "use one head model for the whole dataset")
    head, size, sizes = k0["head_model"], tuple(k0["size"]), tuple(k0["code_sizes"])
    ident_rec = np.repeat(np.arange(len(mg)), np.diff(f["ident_off"]))  # record of each identity row
    pair_rec = np.repeat(np.arange(len(mg)), np.diff(f["pair_off"]))
    ids = np.asarray(f["identities"], np.int64)
    uniq = np.union1d(np.asarray(planned or [], np.int64), ids)
    M = len(uniq)
    lat = np.searchsorted(uniq, ids)
    frames = np.zeros(M, np.int64)
    np.add.at(frames, lat, np.asarray(f["frames"], np.int64))
    shards_of: dict[int, list[ShardRef]] = {}
    for m, r in zip(lat.tolist(), ident_rec.tolist()):
        shards_of.setdefault(m, []).append(refs[r])
    # the front camera: the row of lowest score, the first in shard order on a tie
    front_K, front_c2w = np.tile(np.eye(3), (M, 1, 1)), np.tile(np.eye(4), (M, 1, 1))
    order = np.lexsort((np.arange(len(lat)), f["front_score"], lat))
    first = order[np.r_[True, lat[order][1:] != lat[order][:-1]]] if len(order) else order
    front_K[lat[first]], front_c2w[lat[first]] = f["front_K"][first], f["front_c2w"][first]
    # bounds: one shard's exact sphere, or the merged box's centre and a radius holding every shard's sphere
    sel = np.nonzero(np.asarray(f["fg_points"]) > 0)[0]
    ls = lat[sel]
    parts = np.bincount(ls, minlength=M)
    lo, hi = np.full((M, 3), np.inf), np.full((M, 3), -np.inf)
    np.minimum.at(lo, ls, f["box"][sel, 0])
    np.maximum.at(hi, ls, f["box"][sel, 1])
    centre, radius = np.zeros((M, 3)), np.zeros(M)
    one = sel[parts[ls] == 1]
    centre[lat[one]], radius[lat[one]] = f["centre"][one], f["radius"][one]
    many = np.nonzero(parts > 1)[0]
    centre[many] = 0.5 * (lo[many] + hi[many])
    reach = np.sqrt(((centre[ls] - f["centre"][sel]) ** 2).sum(1)) + f["radius"][sel]
    far = np.full(M, -np.inf)
    np.maximum.at(far, ls, reach)
    radius[many] = far[many]
    empty = np.nonzero((frames > 0) & (parts == 0))[0]
    if empty.size:
        raise SynthError(f"identity {uniq[empty[0]]} has no foreground depth pixel in any frame", where,
                         "check the renders (synth preview): the head must be visible")
    has = frames > 0
    radius[has] = grow(radius[has], margin)
    # conditioning codes: each (identity, expression)'s first shard's, with the run's joints
    jn = [str(j) for j in f["joint_names"]]
    pairs = np.asarray(f["pairs"], np.int64).reshape(-1, 2)
    ok = np.stack([np.isfinite(f["joints"][:, jn.index(j)]).all(1) if j in jn else np.zeros(len(pairs), bool)
                   for j in joints], 1) if joints else np.ones((len(pairs), 0), bool)
    if not ok.all():
        bad = int(np.argmin(ok.all(1)))
        rows = pair_rec == pair_rec[bad]
        have = [j for b, j in enumerate(jn) if np.isfinite(f["joints"][rows, b]).all()]
        missing = [j for a, j in enumerate(joints) if not ok[rows, a].all()]
        raise SynthError(f"frames of identity {pairs[bad, 0]} have no rotation for joint(s) {', '.join(missing)} "
                         f"(they have: {', '.join(have) or 'none'})", refs[int(pair_rec[bad])].shard,
                         "set data.joints to joints the dataset records")
    # (latent id, expression) as one int64, ordered as the pair: unique rows without 2-D temporaries
    e0, span = int(pairs[:, 1].min()), int(pairs[:, 1].max() - pairs[:, 1].min()) + 1
    flat = np.searchsorted(uniq, pairs[:, 0]) * span + (pairs[:, 1] - e0)
    uk, first, inv = np.unique(flat, return_index=True, return_inverse=True)
    keys = np.stack([uk // span, uk % span + e0], 1)
    views = np.bincount(inv.reshape(-1), np.asarray(f["views"], np.int64), len(keys)).astype(np.int64)
    # the codes: the identity code once per latent id when all of an identity's rows agree (as in
    # every dataset synth renders), else full rows; filled in row blocks, so that no temporary
    # exceeds ~200 kB
    beta, blocks = f["beta"], [f["expr"], *(f["joints"][:, jn.index(j)] for j in joints)]
    psi = np.empty((len(keys), sum(b.shape[1] for b in blocks)), np.float32)
    ident = np.zeros((M, beta.shape[1]), np.float32)
    lead = np.r_[True, keys[1:, 0] != keys[:-1, 0]][:len(keys)]  # each latent id's first row
    ident[keys[lead, 0]] = beta[first[lead]]
    same = True
    for a in range(0, len(keys), 1024):
        rows, o = first[a:a + 1024], 0
        same = same and bool((beta[rows] == ident[keys[a:a + 1024, 0]]).all())
        for b in blocks:
            psi[a:a + 1024, o:o + b.shape[1]] = b[rows]
            o += b.shape[1]
    if same:
        code_parts = dict(identity_codes=ident, psi_codes=psi)
    else:
        codes = np.empty((len(keys), beta.shape[1] + psi.shape[1]), np.float32)
        for a in range(0, len(keys), 1024):
            codes[a:a + 1024, :beta.shape[1]] = beta[first[a:a + 1024]]
        codes[:, beta.shape[1]:] = psi
        code_parts = dict(codes=codes)
    del mg, f, blocks, beta, psi
    if holdout_views and (views <= holdout_views).any():
        (m, e), v = keys[np.argmax(views <= holdout_views)], views[np.argmax(views <= holdout_views)]
        raise SynthError(f"identity {uniq[m]} expression {e} has {v} views, not more than "
                         f"data.holdout_views = {holdout_views}", where,
                         "lower data.holdout_views or render more views")
    layout = CodeLayout(int(sizes[0]), int(sizes[1]), tuple(joints))
    info = IdentityInfo(identity_index=uniq, centre=centre, radius=radius, front_K=front_K, front_c2w=front_c2w,
                        front_size=np.where(frames[:, None] > 0, [size[0], size[1]], 0).astype(np.int64),
                        code_keys=keys.astype(np.int64).reshape(-1, 2), **code_parts)
    return Table(layout, info, shards_of, frames, (int(size[1]), int(size[0])), head or {})


__all__ = ["FORMAT", "MERGED_FILE", "Merged", "MergedRecord", "PrepareResult", "Record", "Table", "build_table",
           "loaded", "merge_records", "prepare", "summarise_shard", "trim_heap"]
