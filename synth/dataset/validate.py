"""``synth validate DIR``: check every committed shard of a dataset and report each defect.

Checks (docs/shard-format.md, "Validation"; docs/reliability.md):

- dataset: ``dataset.json`` parses; every planned shard is committed (``--partial``: missing
  shards are warnings); ``shards/`` holds nothing but shard directories (a stray file, tar or
  symlink is a defect, and is never opened); no unplanned shard directories; ``index.json``
  exists, parses, lists exactly the shard directories, signs each manifest's current sha256
  and its digest matches its entries (an index-less dataset fails until ``--repair-index``);
  staging leftovers are warnings;
- shard: ``manifest.json`` parses, lists exactly the planned frames and their two files; no
  missing or extra files; every file is a regular file (``lstat``: symbolic links, devices and
  FIFOs are refused, never followed); sizes and sha256 match (hashing skipped with ``quick``);
- frame: the JSON parses (depth- and size-bounded: every read is bounded by the size the
  manifest declares) and validates (schema + consistency, :mod:`synth.dataset.frame_json`) and
  names its key; the EXR opens with every channel, the JSON's size and the right pixel types;
  no NaN/Inf in RGBA, normals or depth; depth >= 0; alpha in [0, 1]; segmentation IDs known.
"""

from __future__ import annotations

import json
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from synth.dataset.exr import decode_frame_exr, pixel_defects
from synth.dataset.frame_json import validate_frame_json
from synth.dataset.index import (REPAIR_HINT, IndexDamaged, ManifestError, dataset_digest, parse_manifest,
                                 read_index, read_manifest_bytes, read_records, repair_index, shard_entries)
from synth.dataset.layout import (FRAME_KEY_RE, KIND_TEXT, LOGS_DIR, MANIFEST_FILE, MAX_FRAME_JSON_BYTES, SHARD_ID_RE,
                                  SHARDS_DIR, STAGING_DIR,
                                  entry_kind, frame_files, utc_now)
from synth.dataset.shards import load_dataset
from synth.errors import SynthError
from synth.io import file_digest, is_temp_name, loads_json, read_bounded, sha256_bytes

#: Where ``synth validate --repair-index`` appends what each repair changed (JSON lines).
REPAIR_LOG = "index-repairs.jsonl"


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
    digest: str | None = None  # index.json's digest over every committed manifest

    @property
    def ok(self) -> bool:
        return not self.defects

    def to_json(self) -> dict:
        d = asdict(self)
        d["ok"] = self.ok
        return d


def _read(path: Path, declared: int, cap: int | None = None) -> bytes:
    """A shard file's bytes, never more than the manifest declares (nor ``cap``), never
    through a symbolic link (the caller checked it is a regular file with lstat)."""
    return read_bounded(path, min(declared, cap) if cap is not None else declared, follow_symlinks=False)


def _check_frame(shard_dir: Path, shard: str, key: str, listed: dict, readable: set[str]) -> list[Defect]:
    """Content checks of one frame; only files in ``readable`` (regular, the declared size) are read."""
    out: list[Defect] = []
    exr, js = frame_files(key)
    fj = None
    if js in readable:
        try:
            fj = loads_json(_read(shard_dir / js, listed[js]["bytes"], MAX_FRAME_JSON_BYTES))
        except (ValueError, OSError) as e:
            why = e.strerror if isinstance(e, OSError) else e
            out.append(Defect(shard, key, "json", f"{js} does not parse: {why}"))
    if fj is not None:
        errs = validate_frame_json(fj)
        for e in errs[:5]:
            out.append(Defect(shard, key, "json", f"{js}: {e}"))
        if len(errs) > 5:
            out.append(Defect(shard, key, "json", f"{js}: ... and {len(errs) - 5} more schema error(s)"))
        if isinstance(fj, dict) and fj.get("frame_id") != key:
            out.append(Defect(shard, key, "json", f"{js}: frame_id is {str(fj.get('frame_id'))[:80]!r}"))
    if exr not in readable:
        return out
    try:
        px = decode_frame_exr(_read(shard_dir / exr, listed[exr]["bytes"]), str(shard_dir / exr), verify=True)
    except SynthError as e:
        out.append(Defect(shard, key, "exr", e.what))
        return out
    except (ValueError, OSError) as e:
        out.append(Defect(shard, key, "exr", f"{exr} cannot be read: {e.strerror if isinstance(e, OSError) else e}"))
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
        out.append(Defect(shard, key, "exr", f"header names frame {str(hk)[:80]!r}"))
    for msg in pixel_defects(px):
        out.append(Defect(shard, key, "pixels", msg))
    return out


def _stem(name: str) -> str | None:
    return name.rsplit(".", 1)[0] if not name.startswith(".") else None


def validate_shard(root: str, shard: str, expected_keys: list[str] | None, quick: bool,
                   signature: dict | None) -> tuple[list[Defect], list[Defect], int]:
    """Check one committed shard (a real directory under ``shards/``) against the signature
    its commit wrote; returns (defects, warnings, frames checked)."""
    d = Path(root) / SHARDS_DIR / shard
    defects: list[Defect] = []
    warnings: list[Defect] = []
    try:
        mbytes = read_manifest_bytes(d)
        m = parse_manifest(mbytes, shard)
    except FileNotFoundError:
        return [Defect(shard, None, "manifest", "no manifest.json: not a committed shard (leftover or damaged)")], [], 0
    except (OSError, ManifestError) as e:
        return [Defect(shard, None, "manifest", str(e))], [], 0
    if signature is None:
        defects.append(Defect(shard, None, "index", "no commit record: synth did not commit this shard (or its "
                                                    f"signature was lost); {REPAIR_HINT}"))
    elif signature.get("manifest_sha256") != sha256_bytes(mbytes):
        defects.append(Defect(shard, None, "manifest", "manifest.json changed after commit (its sha256 differs from "
                                                       "the commit record)"))
    frames = m["frames"]
    if expected_keys is not None:
        exp = set(expected_keys)
        for k in sorted(exp - set(frames)):
            defects.append(Defect(shard, k, "missing-frame", "planned frame not in the manifest"))
        for k in sorted(set(frames) - exp):
            defects.append(Defect(shard, k[:80], "extra-frame", "frame not in the plan"))
    listed = dict(m["files"])
    want_files = {n for k in frames for n in frame_files(k)}
    for n in sorted(want_files - set(listed)):
        defects.append(Defect(shard, _stem(n), "manifest", f"{n} not listed in the manifest"))
    try:
        on_disk = {n: entry_kind(d / n) for n in os.listdir(d) if n != MANIFEST_FILE}
    except OSError as e:
        return defects + [Defect(shard, None, "io", f"cannot list the shard: {e.strerror}")], warnings, 0
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
    for key in frames:
        if FRAME_KEY_RE.match(key):  # only files named in the manifest, found regular and of its size, are read
            defects.extend(_check_frame(d, shard, key, listed, readable))
            checked += 1
    return defects, warnings, checked


def _staging_warnings(root: Path) -> tuple[list[Defect], list[Defect]]:
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
            if files:
                nj = sum(f.endswith(".json") for f in files)
                out.append(Defect(n, None, "staging", f"uncommitted work: {nj} frame JSON(s), {len(files)} file(s) "
                                                      "in .staging (resume the render to finish it)"))
        elif k == "file" and (n.endswith((".lock", ".lease")) or is_temp_name(n)):
            continue
        elif k == "file":
            out.append(Defect(None, None, "staging", f"stray file .staging/{n}"))
        else:
            defects.append(Defect(None, None, "unexpected-entry", f".staging/{n} is a {KIND_TEXT[k]}"))
    return defects, out


def _signature_checks(root: Path, rep: Report, plan_hash: str, dirs: list[str]) -> dict[str, dict]:
    """Report what is wrong with ``index.json`` and the commit records; returns every shard's
    signature (its commit record, else its index entry) to check the manifests against."""
    try:
        idx = read_index(root)
    except IndexDamaged as e:
        rep.defects.append(Defect(None, None, "index", f"index.json is damaged ({e}); {REPAIR_HINT}"))
        idx = None
    else:
        if idx is None and dirs:
            rep.defects.append(Defect(None, None, "index", "index.json is missing (a render that resumes rewrites it "
                                                           f"from the commit records; or {REPAIR_HINT})"))
        elif idx is not None and idx["plan_hash"] != plan_hash:
            rep.defects.append(Defect(None, None, "index", f"index.json belongs to another plan; {REPAIR_HINT}"))
            idx = None
    entries = (idx or {}).get("shards", {})
    if idx is not None:
        rep.digest = idx.get("digest")
        if rep.digest is None:
            rep.warnings.append(Defect(None, None, "index", "index.json has no digest (written by an older synth); "
                                                            "--repair-index adds one"))
        elif rep.digest != dataset_digest(entries):
            rep.defects.append(Defect(None, None, "index", "index.json's digest does not match its entries (edited?)"))
    records, problems = read_records(root, plan_hash)
    for msg in problems:
        rep.defects.append(Defect(None, None, "index", msg))
    for s in sorted(set(records) & set(dirs)):
        if idx is not None and entries.get(s) != records[s]:
            rep.warnings.append(Defect(s, None, "index", "index.json is behind the shard's commit record (the next "
                                                         "render rewrites it)"))
    for s in sorted(set(entries) - set(dirs)):
        if entry_kind(root / STAGING_DIR / s / MANIFEST_FILE) == "file":
            rep.warnings.append(Defect(s, None, "index", "commit in progress or interrupted (the next render "
                                                         "finishes it)"))
        elif entry_kind(root / SHARDS_DIR / s) is None:
            rep.defects.append(Defect(s, None, "index", "index.json lists a shard that is not on disk"))
    return {**entries, **records}


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
    kind = entry_kind(root / SHARDS_DIR)
    entries = shard_entries(root) if kind == "dir" else {}
    if kind not in (None, "dir"):
        rep.defects.append(Defect(None, None, "unexpected-entry",
                                  f"{SHARDS_DIR} is a {KIND_TEXT[kind]}, not a directory (not followed)"))
    dirs = []
    for n, k in entries.items():
        if k != "dir":
            rep.defects.append(Defect(None, None, "unexpected-entry",
                                      f"{SHARDS_DIR}/{n[:120]!r} is a {KIND_TEXT[k]}: only shard directories belong "
                                      "there (not opened)"))
        elif not SHARD_ID_RE.match(n) or n not in ds.expected:
            rep.defects.append(Defect(n[:120], None, "unexpected-shard", "shard directory not in the plan"))
            if SHARD_ID_RE.match(n):
                dirs.append(n)
        else:
            dirs.append(n)
    sigs = _signature_checks(root, rep, ds.plan_hash, dirs)
    for s in ds.expected:
        if s not in dirs:
            (rep.warnings if partial else rep.defects).append(
                Defect(s, None, "missing-shard", f"planned shard not committed ({len(ds.expected[s])} frames)"))
    args = [(str(root), s, ds.expected.get(s), quick, sigs.get(s)) for s in dirs]
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
    defs, warns = _staging_warnings(root)
    rep.defects.extend(defs)
    rep.warnings.extend(warns)
    return rep


def repair(root) -> list[dict]:
    """``synth validate --repair-index``: rebuild ``index.json`` from the manifests (signing what
    they now say), append the changes to ``DIR/logs/index-repairs.jsonl`` and return them."""
    ds = load_dataset(root)
    _, changes = repair_index(ds.root, ds.plan_hash)
    if changes:
        log = ds.root / LOGS_DIR
        log.mkdir(exist_ok=True)
        with open(log / REPAIR_LOG, "a", encoding="utf-8") as f:
            f.write(json.dumps({"time": utc_now(), "pid": os.getpid(), "changes": changes}) + "\n")
    return changes


def describe_change(c: dict) -> str:
    """One line for a change made by :func:`repair`."""
    what = c["shard"] or "index.json"
    detail = c.get("reason") or ""
    if "old" in c or "new" in c:
        detail = f"manifest sha256 {c.get('old', '-')[:16]} -> {c.get('new', '-')[:16]}"
    return f"{what}: {c['change']}" + (f" ({detail})" if detail else "")
