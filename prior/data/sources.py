"""Where the training frames come from: committed shards, listed again whenever asked.

A source is one of (``synth prior train SOURCE...``):

- a dataset directory (the ``--out`` of ``synth render``): its *committed* shards, directory
  or tar, i.e. a manifest under ``shards/`` that a commit signed (commit record or
  ``index.json`` entry, :mod:`synth.dataset.index`) with the manifest's sha256 the signature
  names. Staging areas are never read. The plan (``dataset.json``) names every identity that
  will ever be rendered (read by :func:`prior.data.plan.read_plan` without holding its frame
  keys), so latent ids are fixed before the farm has finished and shards
  committed later are picked up (:meth:`Source.committed` lists them again each time);
- shard paths: tar shards (``.../shard_000042.tar``, read with their manifest
  ``shard_000042.tar.json`` beside them when it is there) or shard directories, given as a list
  or as a WebDataset-style brace pattern (``DIR/shards/shard_{000000..000149}.tar``). The set
  is fixed.

:func:`read_shard` yields a shard's frames as bytes and checks each file against the sha256
its manifest records; a shard that fails is :class:`ShardDamaged` (the loader skips it with one
warning line).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, NamedTuple

from synth.dataset.index import ManifestError, parse_manifest, read_manifest_bytes, signatures
from synth.dataset.layout import (DATASET_FILE, FRAME_KEY_RE, MANIFEST_FILE, MAX_EXR_BYTES, MAX_FRAME_JSON_BYTES,
                                  SHARDS_DIR, parse_frame_key, parse_frame_key_env)
from synth.dataset.tarshard import TAR_SUFFIX, TarRefused, iter_members, present_shards
from synth.errors import SynthError
from synth.io import loads_json, read_bounded, sha256_bytes

#: where the prepare pass keeps its records, relative to a dataset directory
PREPARE_DIR = ".prior/prepare"


class ShardDamaged(Exception):
    """A committed shard that cannot be read as its manifest says (the message says why)."""


class ShardRef(NamedTuple):
    """One shard: its id, its path (a directory or a ``.tar``) and its manifest (or None)."""

    shard: str
    path: Path
    manifest: Path | None
    #: sha256 of the manifest's bytes that the commit signed (dataset directories), else None
    signed: str | None = None

    @property
    def is_tar(self) -> bool:
        return self.path.name.endswith(TAR_SUFFIX)


_BRACE = re.compile(r"\{([^{}]*)\}")


def expand_braces(pattern: str) -> list[str]:
    """``a{000..002}b`` -> a000b, a001b, a002b (zero padding kept); ``{x,y}`` -> x, y; nested in order."""
    m = _BRACE.search(pattern)
    if not m:
        return [pattern]
    body, head, tail = m.group(1), pattern[:m.start()], pattern[m.end():]
    r = re.fullmatch(r"(\d+)\.\.(\d+)", body)
    if r:
        lo, hi = int(r[1]), int(r[2])
        items = [f"{i:0{len(r[1])}d}" for i in range(lo, hi + 1)]
    else:
        items = body.split(",")
    return [x for it in items for x in expand_braces(head + it + tail)]


def _shard_id(path: Path) -> str:
    name = path.name[:-len(TAR_SUFFIX)] if path.name.endswith(TAR_SUFFIX) else path.name
    return name


@dataclass
class Source:
    """The shards a run trains on (see the module docstring)."""

    root: Path | None  # a dataset directory, or None for an explicit list of shards
    paths: tuple[Path, ...] = ()
    #: dataset identity index -> shard ids that hold its frames (from the plan), or None
    planned: dict[int, list[str]] | None = None
    plan_hash: str | None = None

    @property
    def planned_identities(self) -> list[int] | None:
        """Every identity index of the plan, sorted (None without a plan)."""
        return sorted(self.planned) if self.planned is not None else None

    def describe(self) -> str:
        if self.root is not None:
            return str(self.root)
        return str(self.paths[0]) + (f" (+{len(self.paths) - 1} more shards)" if len(self.paths) > 1 else "")

    def default_prepare_dir(self) -> Path:
        base = self.root
        if base is None:
            first = self.paths[0].parent
            base = first.parent if first.name == SHARDS_DIR else first
        return base / PREPARE_DIR

    def committed(self) -> list[ShardRef]:
        """The shards to read now, sorted by shard id (dataset directories: listed again each time)."""
        if self.root is None:
            out = []
            for p in self.paths:
                man = p.with_name(p.name + ".json") if p.name.endswith(TAR_SUFFIX) else p / MANIFEST_FILE
                out.append(ShardRef(_shard_id(p), p, man if man.is_file() else None))
            return sorted(out)
        sigs = signatures(self.root, self.plan_hash) if self.plan_hash else {}
        out = []
        for sid, mp in present_shards(self.root).items():
            if self.plan_hash and sid not in sigs:
                continue  # not committed by synth (nothing adopts it)
            path = mp.parent if mp.name == MANIFEST_FILE else mp.with_name(sid + TAR_SUFFIX)
            out.append(ShardRef(sid, path, mp, sigs.get(sid, {}).get("manifest_sha256")))
        return out


def open_source(args) -> Source:
    """A :class:`Source` from the command line's SOURCE arguments (one dataset directory, or
    shard paths and brace patterns)."""
    args = [str(a) for a in ([args] if isinstance(args, (str, os.PathLike)) else args)]
    if not args:
        raise SynthError("no dataset given", "DATASET", "pass the --out directory of synth render")
    if len(args) == 1 and "{" not in args[0]:
        p = Path(args[0])
        if not os.path.lexists(p):
            raise SynthError("not a dataset (no such path)", str(p), "pass the --out directory of synth render")
        if p.is_dir() and (p / SHARDS_DIR).is_dir():
            planned, plan_hash = None, None
            if (p / DATASET_FILE).is_file():
                from prior.data.plan import read_plan

                top, planned = read_plan(p)
                plan_hash = top["plan_hash"]
            return Source(p, planned=planned, plan_hash=plan_hash)
    paths = [Path(x) for a in args for x in expand_braces(a)]
    for p in paths:
        if not (p.is_file() and p.name.endswith(TAR_SUFFIX)) and not (p / MANIFEST_FILE).is_file():
            raise SynthError("not a tar shard or a committed shard directory", str(p),
                             "pass a dataset directory, shard paths (.tar or shard directories) or a brace pattern")
    if len({_shard_id(p) for p in paths}) != len(paths):
        raise SynthError("a shard id is given twice", " ".join(args)[:200], "list each shard once")
    return Source(None, tuple(paths))


def _check(data: bytes, entry, name: str, ref: ShardRef) -> bytes:
    if entry is not None and (len(data) != entry.get("bytes") or sha256_bytes(data) != entry.get("sha256")):
        raise ShardDamaged(f"{name} does not match its manifest's sha256")
    return data


#: The lighting environment the prior trains on. The field is conditioned on identity and
#: expression only, so the views of one expression must share their lighting: in a dataset of
#: several environments per expression (``dataset.environments_per_expression``) the frames of
#: the other environments are skipped (docs/prior.md, "Data").
PRIOR_ENVIRONMENT = 0


def _wanted(key: str, identity: int | None) -> bool:
    if identity is None and not FRAME_KEY_RE.match(key):
        return True  # (a tar read without its manifest: other members are sorted out later)
    i, _, k, _ = parse_frame_key_env(key)
    return k == PRIOR_ENVIRONMENT and (identity is None or i == identity)


def read_shard(ref: ShardRef, identity: int | None = None) -> Iterator[tuple[str, bytes, bytes]]:
    """(key, JSON bytes, EXR bytes) of the shard's frames in key order (only ``identity``'s
    when given; only environment :data:`PRIOR_ENVIRONMENT`'s), each file checked against the
    manifest's sha256. Raises :class:`ShardDamaged`."""
    def want(k: str) -> bool:
        return _wanted(k, identity)

    try:
        files = None
        if ref.manifest is not None:
            data = read_manifest_bytes(ref.manifest)
            if ref.signed is not None and sha256_bytes(data) != ref.signed:
                raise ShardDamaged("its manifest changed after its commit")
            m = parse_manifest(data, ref.shard, ref.manifest.name)
            files = m["files"]
            keys = sorted(str(k) for k in m["frames"] if FRAME_KEY_RE.match(str(k)))
        if ref.is_tar and files is not None:
            with open(ref.path, "rb") as f:
                for k in keys:
                    if not want(k):
                        continue
                    out = []
                    for ext in ("json", "exr"):
                        e = files.get(f"{k}.{ext}")
                        if not isinstance(e, dict) or not isinstance(e.get("offset"), int) \
                                or not 0 <= e["bytes"] <= (MAX_FRAME_JSON_BYTES if ext == "json" else MAX_EXR_BYTES):
                            raise ShardDamaged(f"manifest has no usable member offset and size for {k}.{ext}")
                        f.seek(e["offset"])
                        out.append(_check(f.read(e["bytes"]), e, f"{k}.{ext}", ref))
                    yield k, out[0], out[1]
        elif ref.is_tar:  # a tar without its manifest: its members as they come (no sha256 to check)
            pending: dict[str, dict[str, bytes]] = {}
            with open(ref.path, "rb") as f:
                for mem in iter_members(f, str(ref.path), select=lambda n, s: want(n.partition(".")[0])):
                    if mem.data is None:
                        continue
                    parts = pending.setdefault(mem.key, {})
                    parts[mem.name.partition(".")[2]] = mem.data
                    if len(parts) == 2:
                        del pending[mem.key]
                        yield mem.key, parts["json"], parts["exr"]
            if pending:
                raise ShardDamaged(f"{len(pending)} frame(s) lack their JSON or EXR")
        else:
            if files is None:
                raise ShardDamaged("it has no manifest")
            for k in keys:
                if want(k):
                    yield (k, _check(read_bounded(ref.path / f"{k}.json", MAX_FRAME_JSON_BYTES),
                                     files.get(f"{k}.json"), f"{k}.json", ref),
                           _check(read_bounded(ref.path / f"{k}.exr", MAX_EXR_BYTES), files.get(f"{k}.exr"),
                                  f"{k}.exr", ref))
    except (OSError, ValueError, ManifestError, TarRefused) as e:
        raise ShardDamaged(f"{type(e).__name__}: {str(e)[:120]}") from None


def frame_meta(json_bytes: bytes, key: str) -> dict:
    """The frame JSON as a dict (ShardDamaged when it does not parse or names another frame)."""
    try:
        meta = loads_json(json_bytes)
    except ValueError as e:
        raise ShardDamaged(f"{key}.json does not parse ({str(e)[:80]})") from None
    if not isinstance(meta, dict) or meta.get("frame_id", key) != key:
        raise ShardDamaged(f"{key}.json is not the JSON of frame {key}")
    return meta


__all__ = ["PREPARE_DIR", "PRIOR_ENVIRONMENT", "ShardDamaged", "ShardRef", "Source", "expand_braces", "frame_meta",
           "open_source", "read_shard"]
