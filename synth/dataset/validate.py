"""``synth validate DIR``: check every committed shard of a dataset and report each defect.

Checks (docs/shard-format.md, "Validation"):

- dataset: ``dataset.json`` parses; every planned shard is committed (``--partial``: missing
  shards are warnings); no unplanned or manifest-less shard directories; the index agrees with
  the manifests; staging leftovers are warnings;
- shard: ``manifest.json`` parses, lists exactly the planned frames and their two files; no
  missing or extra files; sizes and sha256 match (hashing skipped with ``quick``);
- frame: the JSON parses and validates (schema + consistency, :mod:`synth.dataset.frame_json`) and names
  its key; the EXR opens with every channel, the JSON's size and the right pixel types; no
  NaN/Inf in RGBA, normals or depth; depth >= 0; alpha in [0, 1]; segmentation IDs known.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from synth.dataset.exr import pixel_defects, read_frame_exr
from synth.dataset.frame_json import validate_frame_json
from synth.dataset.index import ManifestError, parse_manifest, read_index
from synth.dataset.layout import MANIFEST_FILE, SHARDS_DIR, STAGING_DIR, frame_files
from synth.dataset.shards import load_dataset
from synth.dataset.tar_validate import check_tar_shard
from synth.dataset.tarshard import shard_entries, tar_manifest_path
from synth.errors import SynthError
from synth.io import is_temp_name, loads_json, sha256_bytes, sha256_file


class DefectsFound(SynthError):
    """Validation found defects: the CLI exits with code 1 (not 2: the input was usable)."""

    exit_code = 1


@dataclass(frozen=True)
class Defect:
    shard: str | None
    key: str | None
    kind: str
    message: str

    def line(self) -> str:
        where = "/".join(p for p in (self.shard, self.key) if p) or "dataset"
        return f"{where}: {self.kind}: {self.message}"


@dataclass
class Report:
    root: str
    defects: list[Defect] = field(default_factory=list)
    warnings: list[Defect] = field(default_factory=list)
    shards_expected: int = 0
    frames_expected: int = 0
    shards_checked: int = 0
    frames_checked: int = 0
    hashed: bool = True

    @property
    def ok(self) -> bool:
        return not self.defects

    def to_json(self) -> dict:
        d = asdict(self)
        d["ok"] = self.ok
        return d


def _check_frame(shard_dir: Path, shard: str, key: str) -> list[Defect]:
    exr, js = frame_files(key)
    try:
        jb = (shard_dir / js).read_bytes()
    except FileNotFoundError:
        jb = None  # reported as a missing file
    except OSError as e:
        return [Defect(shard, key, "json", f"{js} cannot be read: {e}")]
    return check_frame_data(shard, key, jb, shard_dir / exr if (shard_dir / exr).exists() else None)


def check_frame_data(shard: str, key: str, json_bytes: bytes | None, exr) -> list[Defect]:
    """The defects of one frame from its JSON's bytes and its EXR (a path or bytes); ``None``
    for a file that is missing (reported elsewhere)."""
    out: list[Defect] = []
    exr_name, js = frame_files(key)
    fj = None
    try:
        fj = loads_json(json_bytes) if json_bytes is not None else None
    except (ValueError, UnicodeDecodeError) as e:
        out.append(Defect(shard, key, "json", f"{js} does not parse: {e}"))
    if fj is not None:
        errs = validate_frame_json(fj)
        for e in errs[:5]:
            out.append(Defect(shard, key, "json", f"{js}: {e}"))
        if len(errs) > 5:
            out.append(Defect(shard, key, "json", f"{js}: ... and {len(errs) - 5} more schema error(s)"))
        if isinstance(fj, dict) and fj.get("frame_id") != key:
            out.append(Defect(shard, key, "json", f"{js}: frame_id is {fj.get('frame_id')!r}"))
    if exr is None:
        return out
    try:
        px = read_frame_exr(exr, verify=True, where=f"{shard}/{exr_name}" if isinstance(exr, bytes) else None)
    except SynthError as e:
        out.append(Defect(shard, key, "exr", e.what))
        return out
    if isinstance(fj, dict) and isinstance(fj.get("image"), dict):
        want = (fj["image"].get("width"), fj["image"].get("height"))
        if (px["width"], px["height"]) != want:
            out.append(Defect(shard, key, "exr", f"size {px['width']}x{px['height']} differs from the JSON's "
                                                 f"{want[0]}x{want[1]}"))
    if px["rgba"].dtype != np.float16:
        out.append(Defect(shard, key, "exr", f"RGBA stored as {px['rgba'].dtype}, expected HALF"))
    hk = px["header"].get("synthFrameKey")
    if hk is not None and hk != key:
        out.append(Defect(shard, key, "exr", f"header names frame {hk!r}"))
    for msg in pixel_defects(px):
        out.append(Defect(shard, key, "pixels", msg))
    return out


def validate_shard(root: str, shard: str, expected_keys: list[str] | None, quick: bool,
                   index_entry: dict | None, has_index: bool = True) -> tuple[list[Defect], list[Defect], int]:
    """Check one committed shard (a directory, or a tar: :mod:`synth.dataset.tar_validate`);
    returns (defects, warnings, frames checked)."""
    d = Path(root) / SHARDS_DIR / shard
    if not d.is_dir() and os.path.lexists(tar_manifest_path(root, shard)):  # a tar shard
        m, defects, warnings = check_manifest(tar_manifest_path(root, shard), shard, expected_keys, index_entry,
                                              has_index)
        if m is None:
            return defects, warnings, 0
        found, checked = check_tar_shard(root, shard, m, quick,
                                         lambda k, j, e: defects.extend(check_frame_data(shard, k, j, e)))
        return defects + [Defect(shard, k, kind, msg) for k, kind, msg in found], warnings, checked
    m, defects, warnings = check_manifest(d / MANIFEST_FILE, shard, expected_keys, index_entry, has_index)
    if m is None:
        return defects, warnings, 0
    frames, listed = m["frames"], dict(m["files"])
    try:
        on_disk = set(os.listdir(d)) - {MANIFEST_FILE}
    except OSError as e:
        return defects + [Defect(shard, None, "io", f"cannot list the shard: {e}")], warnings, 0
    for n in sorted(set(listed) - on_disk):
        defects.append(Defect(shard, n.rsplit(".", 1)[0], "missing-file", f"{n} is listed but missing"))
    for n in sorted(on_disk - set(listed)):
        defects.append(Defect(shard, n.rsplit(".", 1)[0] if not n.startswith(".") else None, "extra-file",
                              f"{n} is not in the manifest"))
    for n in sorted(set(listed) & on_disk):
        ent = listed[n]
        key = n.rsplit(".", 1)[0]
        size = (d / n).stat().st_size
        if size != ent["bytes"]:
            defects.append(Defect(shard, key, "checksum", f"{n} is {size} bytes, manifest says {ent['bytes']}"))
        elif not quick and sha256_file(d / n) != ent["sha256"]:
            defects.append(Defect(shard, key, "checksum", f"{n} sha256 differs from the manifest"))
    checked = 0
    for key in frames:
        defects.extend(_check_frame(d, shard, key))
        checked += 1
    return defects, warnings, checked


def check_manifest(mp: Path, shard: str, expected_keys: list[str] | None, index_entry: dict | None,
                   has_index: bool) -> tuple[dict | None, list[Defect], list[Defect]]:
    """Read and check a shard's manifest against the index and the plan: (the manifest, or
    None when unusable; defects; warnings)."""
    defects: list[Defect] = []
    warnings: list[Defect] = []
    try:
        mbytes = mp.read_bytes()
        m = parse_manifest(mbytes, shard)
    except FileNotFoundError:
        return None, [Defect(shard, None, "manifest", f"no {mp.name}: not a committed shard (leftover or damaged)")], []
    except (OSError, ManifestError) as e:
        return None, [Defect(shard, None, "manifest", str(e))], []
    if index_entry is None and has_index:
        warnings.append(Defect(shard, None, "index", "not in index.json (stale index; the next render repairs it)"))
    elif index_entry is not None and index_entry.get("manifest_sha256") != sha256_bytes(mbytes):
        defects.append(Defect(shard, None, "manifest", f"{mp.name} changed after commit (sha256 differs from "
                                                       "index.json)"))
    frames = m["frames"]
    if expected_keys is not None:
        exp = set(expected_keys)
        for k in sorted(exp - set(frames)):
            defects.append(Defect(shard, k, "missing-frame", "planned frame not in the manifest"))
        for k in sorted(set(frames) - exp):
            defects.append(Defect(shard, k, "extra-frame", "frame not in the plan"))
    listed = m["files"]
    want_files = {n for k in frames for n in frame_files(k)}
    for n in sorted(want_files - set(listed)):
        defects.append(Defect(shard, n.rsplit(".", 1)[0], "manifest", f"{n} not listed in the manifest"))
    return m, defects, warnings


def _staging_warnings(root: Path, committed: set[str] = frozenset()) -> list[Defect]:
    out = []
    st = root / STAGING_DIR
    if not st.is_dir():
        return out
    for n in sorted(os.listdir(st)):
        p = st / n
        if p.is_dir():
            files = [f for f in os.listdir(p)]
            if n in committed:  # a tar commit killed after its commit point, before removing the staging
                out.append(Defect(n, None, "staging", f".staging/{n} is a leftover of the committed shard "
                                                      "(safe to delete)"))
            elif files:
                nj = sum(f.endswith(".json") for f in files)
                out.append(Defect(n, None, "staging", f"uncommitted work: {nj} frame JSON(s), {len(files)} file(s) "
                                                      "in .staging (resume the render to finish it)"))
        elif n.endswith((".lock", ".lease")) or is_temp_name(n):
            continue
        else:
            out.append(Defect(None, None, "staging", f"stray file .staging/{n}"))
    return out


def validate_dataset(root, *, quick: bool = False, partial: bool = False, jobs: int = 1,
                     progress=None) -> Report:
    """Validate a dataset directory. Raises :class:`SynthError` only when it is not a dataset.

    ``progress(shard_id)`` is called after each shard (for a progress bar).
    """
    ds = load_dataset(root)
    root = ds.root
    rep = Report(root=str(root), hashed=not quick)
    rep.shards_expected = len(ds.expected)
    rep.frames_expected = sum(len(v) for v in ds.expected.values())
    ents = shard_entries(root)  # directories and tar shards (synth.dataset.tarshard)
    on_disk = sorted(set(ents.dirs) | set(ents.tars))
    for s in sorted(set(ents.dirs) & set(ents.tars)):
        rep.defects.append(Defect(s, None, "unexpected-shard", f"committed twice: shards/{s}/ and shards/{s}.tar.json "
                                                               "(the directory is read; remove one)"))
    for s in ents.orphans:
        rep.warnings.append(Defect(s, None, "staging", f"shards/{s}.tar has no manifest: a commit was interrupted "
                                                       "(not committed; the next render replaces it)"))
    for n in ents.temps:
        rep.warnings.append(Defect(None, None, "staging", f"leftover temporary file shards/{n} (safe to delete)"))
    idx = read_index(root)
    if idx is None and on_disk:
        rep.warnings.append(Defect(None, None, "index", "index.json missing or unreadable (rebuildable from the "
                                                        "manifests; the next render rewrites it)"))
    elif idx is not None and idx.get("plan_hash") != ds.plan_hash:
        rep.defects.append(Defect(None, None, "index", "index.json belongs to another plan"))
        idx = None
    entries = (idx or {}).get("shards", {})
    for s in sorted(set(entries) - set(on_disk)):
        rep.defects.append(Defect(s, None, "index", "index.json lists a shard that is not on disk"))
    for s in ds.expected:
        if s not in on_disk:
            (rep.warnings if partial else rep.defects).append(
                Defect(s, None, "missing-shard", f"planned shard not committed ({len(ds.expected[s])} frames)"))
    for s in on_disk:
        if s not in ds.expected:
            rep.defects.append(Defect(s, None, "unexpected-shard", "shard not in the plan"))
    # without an index (warned above) there is nothing to compare manifests with
    args = [(str(root), s, ds.expected.get(s), quick, entries.get(s), idx is not None) for s in on_disk]
    results = []
    if jobs > 1 and len(args) > 1:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            futs = [ex.submit(validate_shard, *a) for a in args]
            for a, f in zip(args, futs):
                results.append(f.result())
                if progress:
                    progress(a[1])
    else:
        for a in args:
            results.append(validate_shard(*a))
            if progress:
                progress(a[1])
    for defs, warns, n in results:
        rep.defects.extend(defs)
        rep.warnings.extend(warns)
        rep.frames_checked += n
        rep.shards_checked += 1
    rep.warnings.extend(_staging_warnings(root, set(on_disk)))
    return rep
