"""``synth validate DIR``: check every committed shard of a dataset and report each defect.

Checks (docs/shard-format.md, "Validation"; docs/reliability.md):

- dataset: ``dataset.json`` parses; every planned shard is committed (``--partial``: missing
  shards are warnings); ``shards/`` holds nothing but shard directories and tar shards (a
  ``<id>.tar`` with its ``<id>.tar.json``): a stray file, tar or symlink is a defect and is
  never opened, a tar without its manifest (a killed commit) and leftover temporary files are
  warnings; no unplanned shards, none in both forms; ``index.json`` exists, parses, lists
  exactly the shards, signs each manifest's current sha256 and its digest matches its entries
  (an index-less dataset fails until ``--repair-index``; :mod:`synth.dataset.validate_index`);
  staging leftovers are warnings;
- shard: the manifest (``manifest.json``, or ``<id>.tar.json`` of a tar shard) is a regular
  file of bounded size, parses, is the one its commit signed, lists exactly the planned frames
  and their two files; a directory shard has no missing or extra files and every file is a
  regular file (``lstat``: symbolic links, devices and FIFOs are refused, never followed);
  sizes and sha256 match (hashing skipped with ``quick``); a tar shard's tar and members are
  checked by :mod:`synth.dataset.tar_validate`;
- frame: the JSON parses (depth- and size-bounded: every read is bounded by the size the
  manifest declares) and validates (schema + consistency, :mod:`synth.dataset.frame_json`) and
  names its key; the EXR opens with every channel, the JSON's size and the right pixel types;
  no NaN/Inf in RGBA, normals or depth; depth >= 0; alpha in [0, 1]; segmentation IDs known.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from synth.dataset.defects import Defect, Report
from synth.dataset.exr import pixel_defects, verify_frame_exr
from synth.dataset.frame_json import validate_frame_json
from synth.dataset.index import REPAIR_HINT, ManifestError, parse_manifest, read_manifest_bytes
from synth.dataset.layout import (FRAME_KEY_RE, KIND_TEXT, MANIFEST_FILE, MAX_FRAME_JSON_BYTES, SHARD_ID_RE,
                                  SHARDS_DIR, STAGING_DIR, entry_kind, frame_files)
from synth.dataset.shards import load_dataset
from synth.dataset.tar_validate import check_tar_shard
from synth.dataset.tarshard import TAR_MANIFEST_SUFFIX, TAR_SUFFIX, shard_entries, tar_manifest_path
from synth.dataset.validate_index import check_signatures
from synth.errors import SynthError
from synth.io import file_digest, is_temp_name, loads_json, read_bounded, sha256_bytes


def _read(path: Path, declared: int, cap: int | None = None) -> bytes:
    """A shard file's bytes, never more than the manifest declares (nor ``cap``), never
    through a symbolic link (the caller checked it is a regular file with lstat)."""
    return read_bounded(path, min(declared, cap) if cap is not None else declared, follow_symlinks=False)


def check_frame_data(shard: str, key: str, json_bytes: bytes | None, exr_bytes: bytes | None,
                     where: str) -> list[Defect]:
    """The content defects of one frame from the bytes of its JSON and its EXR (``where``
    names the EXR); ``None`` for a file that cannot be read (reported elsewhere)."""
    out: list[Defect] = []
    js = frame_files(key)[1]
    fj = None
    if json_bytes is not None:
        try:
            fj = loads_json(json_bytes)
        except ValueError as e:
            out.append(Defect(shard, key, "json", f"{js} does not parse: {e}"))
    if fj is not None:
        errs = validate_frame_json(fj)
        for e in errs[:5]:
            out.append(Defect(shard, key, "json", f"{js}: {e}"))
        if len(errs) > 5:
            out.append(Defect(shard, key, "json", f"{js}: ... and {len(errs) - 5} more schema error(s)"))
        if isinstance(fj, dict) and fj.get("frame_id") != key:
            out.append(Defect(shard, key, "json", f"{js}: frame_id is {str(fj.get('frame_id'))[:80]!r}"))
    if exr_bytes is None:
        return out
    try:
        px = verify_frame_exr(exr_bytes, where)
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
    hk = px["frame_key"]
    if hk is not None and hk != key:
        out.append(Defect(shard, key, "exr", f"header names frame {str(hk)[:80]!r}"))
    for msg in pixel_defects(px):
        out.append(Defect(shard, key, "pixels", msg))
    return out


def _check_frame(shard_dir: Path, shard: str, key: str, listed: dict, readable: set[str]) -> list[Defect]:
    """Content checks of one frame of a directory shard; only files in ``readable`` (regular,
    the declared size) are read."""
    out: list[Defect] = []
    data: dict[str, bytes | None] = {}
    for name, cap, kind in zip(frame_files(key), (None, MAX_FRAME_JSON_BYTES), ("exr", "json")):
        data[kind] = None
        if name in readable:
            try:
                data[kind] = _read(shard_dir / name, listed[name]["bytes"], cap)
            except (ValueError, OSError) as e:
                out.append(Defect(shard, key, kind, f"{name} cannot be read: "
                                                    f"{e.strerror if isinstance(e, OSError) else e}"))
    where = str(shard_dir / frame_files(key)[0])
    return out + check_frame_data(shard, key, data["json"], data["exr"], where)


def _stem(name: str) -> str | None:
    return name.rsplit(".", 1)[0] if not name.startswith(".") else None


def check_manifest(mp: Path, shard: str, expected_keys: list[str] | None,
                   signature: dict | None) -> tuple[dict | None, list[Defect]]:
    """Read a shard's manifest (bounded, never through a link) and check it against the
    signature its commit wrote and against the plan: (the manifest, or None when unusable;
    defects)."""
    defects: list[Defect] = []
    try:
        mbytes = read_manifest_bytes(mp)
        m = parse_manifest(mbytes, shard, mp.name)
    except FileNotFoundError:
        return None, [Defect(shard, None, "manifest", f"no {mp.name}: not a committed shard (leftover or damaged)")]
    except (OSError, ManifestError) as e:
        return None, [Defect(shard, None, "manifest", str(e))]
    if signature is None:
        defects.append(Defect(shard, None, "index", "no commit record: synth did not commit this shard (or its "
                                                    f"signature was lost); {REPAIR_HINT}"))
    elif signature.get("manifest_sha256") != sha256_bytes(mbytes):
        defects.append(Defect(shard, None, "manifest", f"{mp.name} changed after commit (its sha256 differs from "
                                                       "the commit record)"))
    frames = m["frames"]
    if expected_keys is not None:
        exp = set(expected_keys)
        for k in sorted(exp - set(frames)):
            defects.append(Defect(shard, k, "missing-frame", "planned frame not in the manifest"))
        for k in sorted(set(frames) - exp):
            defects.append(Defect(shard, k[:80], "extra-frame", "frame not in the plan"))
    want_files = {n for k in frames for n in frame_files(k)}
    for n in sorted(want_files - set(m["files"])):
        defects.append(Defect(shard, _stem(n), "manifest", f"{n} not listed in the manifest"))
    return m, defects


def validate_shard(root: str, shard: str, expected_keys: list[str] | None, quick: bool,
                   signature: dict | None) -> tuple[list[Defect], list[Defect], int]:
    """Check one committed shard (a real directory under ``shards/``, else a tar shard) against
    the signature its commit wrote; returns (defects, warnings, frames checked)."""
    d = Path(root) / SHARDS_DIR / shard
    if entry_kind(d) != "dir":  # a tar shard (synth.dataset.tar_validate)
        m, defects = check_manifest(tar_manifest_path(root, shard), shard, expected_keys, signature)
        if m is None:
            return defects, [], 0
        found, checked = check_tar_shard(
            root, shard, m, quick, lambda k, j, e: defects.extend(check_frame_data(shard, k, j, e, f"{shard}/{k}.exr")))
        return defects + [Defect(shard, k, kind, msg) for k, kind, msg in found], [], checked
    m, defects = check_manifest(d / MANIFEST_FILE, shard, expected_keys, signature)
    if m is None:
        return defects, [], 0
    listed = dict(m["files"])
    try:
        on_disk = {n: entry_kind(d / n) for n in os.listdir(d) if n != MANIFEST_FILE}
    except OSError as e:
        return defects + [Defect(shard, None, "io", f"cannot list the shard: {e.strerror}")], [], 0
    for n in sorted(set(listed) - set(on_disk)):
        defects.append(Defect(shard, _stem(n), "missing-file", f"{n} is listed but missing"))
    for n in sorted(set(on_disk) - set(listed)):
        defects.append(Defect(shard, _stem(n), "extra-file", f"{n} is not in the manifest"))
    readable = set()
    for n in sorted(set(listed) & set(on_disk)):
        ent, key = listed[n], _stem(n)
        if on_disk[n] != "file":
            defects.append(Defect(shard, key, "not-a-file",
                                  f"{n} is a {KIND_TEXT[on_disk[n]]}, not a regular file (not read)"))
            continue
        size = os.lstat(d / n).st_size
        if size != ent["bytes"]:
            defects.append(Defect(shard, key, "checksum", f"{n} is {size} bytes, manifest says {ent['bytes']}"))
            continue
        if not quick:
            try:
                digest, _ = file_digest(d / n, max_bytes=ent["bytes"], follow_symlinks=False)
            except (OSError, ValueError) as e:
                defects.append(Defect(shard, key, "io", f"{n} cannot be read: {e}"))
                continue
            if digest != ent["sha256"]:
                defects.append(Defect(shard, key, "checksum", f"{n} sha256 differs from the manifest"))
                continue
        readable.add(n)
    checked = 0
    for key in m["frames"]:
        if FRAME_KEY_RE.match(key):  # only files named in the manifest, found regular and of its size, are read
            defects.extend(_check_frame(d, shard, key, listed, readable))
            checked += 1
    return defects, [], checked


def _shards_listing(root: Path, rep: Report, expected: dict) -> list[str]:
    """Report what ``shards/`` holds besides the planned shards (never opening it); returns
    the shards present in either form, to validate (a shard in both forms: its directory)."""
    kind = entry_kind(root / SHARDS_DIR)
    if kind not in (None, "dir"):
        rep.defects.append(Defect(None, None, "unexpected-entry",
                                  f"{SHARDS_DIR} is a {KIND_TEXT[kind]}, not a directory (not followed)"))
    if kind != "dir":
        return []
    ents = shard_entries(root)
    stray = dict(ents.others)
    stray.update({f"{s}{TAR_SUFFIX}": "file" for s in ents.orphans if s not in expected})  # no commit makes those
    for n, k in sorted(stray.items()):
        rep.defects.append(Defect(None, None, "unexpected-entry",
                                  f"{SHARDS_DIR}/{n[:120]!r} is a {KIND_TEXT[k]}: only shard directories and tar "
                                  f"shards (<id>{TAR_SUFFIX} with <id>{TAR_MANIFEST_SUFFIX}) belong there "
                                  "(not opened)"))
    for s in ents.orphans:
        if s in expected:
            rep.warnings.append(Defect(s, None, "staging", f"{SHARDS_DIR}/{s}{TAR_SUFFIX} has no manifest: a commit "
                                                           "was interrupted (not committed; the next render replaces "
                                                           "it)"))
    for n in ents.temps:
        rep.warnings.append(Defect(None, None, "staging", f"leftover temporary file {SHARDS_DIR}/{n[:120]} (safe to "
                                                          "delete)"))
    present = []
    for n in ents.dirs:
        if not SHARD_ID_RE.match(n) or n not in expected:
            rep.defects.append(Defect(n[:120], None, "unexpected-shard", "shard directory not in the plan"))
        if SHARD_ID_RE.match(n):
            present.append(n)
    for s in ents.tars:
        if s not in expected:
            rep.defects.append(Defect(s, None, "unexpected-shard", "tar shard not in the plan"))
        if s in present:
            rep.defects.append(Defect(s, None, "unexpected-shard", f"committed twice: {SHARDS_DIR}/{s}/ and "
                                                                   f"{SHARDS_DIR}/{s}{TAR_MANIFEST_SUFFIX} (the "
                                                                   "directory is read; remove one)"))
        else:
            present.append(s)
    return sorted(present)


def _staging_warnings(root: Path, committed: set[str]) -> tuple[list[Defect], list[Defect]]:
    """(defects, warnings) about ``.staging``: leftovers are warnings, links are defects."""
    st = root / STAGING_DIR
    kind = entry_kind(st)
    if kind is None:
        return [], []
    if kind != "dir":
        return [Defect(None, None, "unexpected-entry", f"{STAGING_DIR} is a {KIND_TEXT[kind]}, not a directory")], []
    defects, out = [], []
    for n in sorted(os.listdir(st)):
        k = entry_kind(st / n)
        if k == "dir":
            files = os.listdir(st / n)
            if n in committed:  # a tar commit killed after its commit point, before removing the staging
                out.append(Defect(n, None, "staging", f"{STAGING_DIR}/{n} is a leftover of the committed shard "
                                                      "(safe to delete)"))
            elif files:
                nj = sum(f.endswith(".json") for f in files)
                out.append(Defect(n, None, "staging", f"uncommitted work: {nj} frame JSON(s), {len(files)} file(s) "
                                                      f"in {STAGING_DIR} (resume the render to finish it)"))
        elif k == "file" and (n.endswith((".lock", ".lease")) or is_temp_name(n)):
            continue
        elif k == "file":
            out.append(Defect(None, None, "staging", f"stray file {STAGING_DIR}/{n}"))
        else:
            defects.append(Defect(None, None, "unexpected-entry", f"{STAGING_DIR}/{n} is a {KIND_TEXT[k]}"))
    return defects, out


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
    present = _shards_listing(root, rep, ds.expected)
    sigs = check_signatures(root, rep, ds.plan_hash, present)
    for s in ds.expected:
        if s not in present:
            (rep.warnings if partial else rep.defects).append(
                Defect(s, None, "missing-shard", f"planned shard not committed ({len(ds.expected[s])} frames)"))
    args = [(str(root), s, ds.expected.get(s), quick, sigs.get(s)) for s in present]
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
    defs, warns = _staging_warnings(root, set(present))
    rep.defects.extend(defs)
    rep.warnings.extend(warns)
    return rep
