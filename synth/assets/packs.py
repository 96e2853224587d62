"""External asset packs (``generator = "blend:PATH.blend"``): the checks, in one place.

A pack file must exist, lie inside its class file's asset root once symlinks are resolved,
and have the declared sha256. The same functions run when the catalogue is loaded at plan
time (:func:`synth.assets.catalogue.load_catalogue`, first defect), in ``synth assets
validate`` (:mod:`synth.assets.validate`, every defect) and when the rig links the file
(``blender_scripts/assets/external.py``, :func:`verify_pack`). Which classes a pack may
provide and their default anchors come from the registry (:data:`synth.assets.classes.PACK_ANCHORS`).
See docs/assets.md.
"""

from __future__ import annotations

import os
from pathlib import Path

from synth.assets.classes import PACK_ANCHORS
from synth.errors import SynthError
from synth.io import sha256_file

#: Skull width (X extent of the scalp region in the head-joint frame, metres) a pack is
#: modelled for unless the entry says otherwise (the default head measures 0.149 m).
REFERENCE_SKULL_WIDTH_M = 0.15
#: Entry keys only an external pack may carry.
PACK_KEYS = ("object", "sha256", "anchor", "reference_width_m")


def is_external(generator: str) -> bool:
    """True for a pack generator (``blend:PATH.blend`` or a bare ``PATH.blend``)."""
    g = str(generator)
    return g.startswith("blend:") or g.endswith(".blend") or ".blend#" in g


def split_generator(generator: str) -> tuple[str, str | None]:
    """``blend:packs/a.blend#Cap`` -> (``packs/a.blend``, ``Cap``); without ``#``: (path, None)."""
    g = str(generator)
    if g.startswith("blend:"):
        g = g[len("blend:"):]
    path, sep, obj = g.partition("#")
    return path, (obj or None) if sep else None


def pack_object_name(entry: dict) -> str | None:
    """The object or collection to link: the entry's ``object``, else the generator's ``#NAME``."""
    return entry.get("object") or split_generator(entry.get("generator", ""))[1]


def asset_root_of(doc: dict, manifest_file: Path) -> Path:
    """The folder packs of one class file are confined to: its top-level ``asset_root``
    (relative to the manifest folder, or absolute), default the manifest folder itself."""
    base = Path(manifest_file).resolve().parent
    root = doc.get("asset_root")
    return (base / root) if root else base


def pack_path_problem(rel: str, root: str | Path) -> tuple[Path | None, tuple[str, str] | None]:
    """Resolve a pack path inside ``root``. Returns (resolved path, None) or (None, (what, fix)).

    Symlinks are resolved (the root's too) before the confinement test, so neither ``..``
    nor a link may lead outside the root; an absolute path is accepted only if it resolves
    inside the root."""
    if not rel:
        return None, ("external pack names no .blend file", "write generator = \"blend:PATH.blend\"")
    if not str(rel).endswith(".blend"):
        return None, (f"external pack '{rel}' is not a .blend file", "point the generator at a .blend file")
    if "\0" in str(rel):
        return None, (f"external pack path {rel!r} contains a NUL byte", "remove the NUL (\\0) from the path")
    root_p = Path(root)
    if not root_p.is_dir():
        return None, (f"asset root '{root_p}' is not a folder", "fix asset_root (relative to the manifest folder)")
    root_r = root_p.resolve()
    cand = root_r / rel  # an absolute rel replaces the root here; it is then checked like any other
    try:
        real = Path(os.path.realpath(cand))
    except (OSError, RuntimeError) as e:  # symlink loop
        return None, (f"external pack path '{rel}' cannot be resolved: {e}", "fix the path or the symlink")
    if not real.is_relative_to(root_r):
        if Path(os.path.normpath(cand)).is_relative_to(root_r):
            how = "a symlink"
        else:
            how = "an absolute path" if Path(rel).is_absolute() else "'..'"
        return None, (f"external pack '{rel}' escapes the asset root {root_r} via {how} (resolves to {real})",
                      "keep pack files inside asset_root; copy the file there instead of linking to it")
    if not real.exists():
        return None, (f"external pack file '{rel}' not found (looked for {real})",
                      "restore the file or fix the generator path")
    if not real.is_file():
        return None, (f"external pack '{rel}' is not a file ({real})", "point the generator at a .blend file")
    return real, None


def verify_pack(rel: str, root: str | Path, sha256: str | None, where: str) -> Path:
    """Resolve, confine and checksum one pack file; the resolved path or a SynthError.

    Used at plan time (load_catalogue) and by the rig before linking (defence in depth)."""
    real, problem = pack_path_problem(rel, root)
    if problem:
        raise SynthError(problem[0], where, problem[1])
    if not sha256:
        raise SynthError(f"external pack '{rel}' declares no sha256", where,
                         f"add sha256 = \"{sha256_file(real)}\" after checking the file")
    got = sha256_file(real)
    if got != sha256.lower():
        raise SynthError(f"external pack file {real} does not match its checksum (sha256 {got}, declared {sha256})",
                         where, "the file changed: restore the original or review it and update sha256")
    return real


def pack_record(cls: str, entry: dict, root: Path) -> dict:
    """What the plan stores for an external asset (``asset_choice["pack"]``) and the rig reads."""
    rel, _ = split_generator(entry["generator"])
    return {"class": cls, "file": rel, "asset_root": str(Path(root).resolve()), "object": pack_object_name(entry),
            "sha256": str(entry.get("sha256", "")).lower(),
            "anchor": entry.get("anchor", PACK_ANCHORS.get(cls, "head")),
            "reference_width_m": float(entry.get("reference_width_m", REFERENCE_SKULL_WIDTH_M))}


def pack_defects(cls: str, entry: dict, root: Path, where: str) -> list[tuple[str, str]]:
    """Every problem of one external entry as (what, fix) pairs (empty when it is usable)."""
    out: list[tuple[str, str]] = []
    if cls not in PACK_ANCHORS:
        out.append((f"class '{cls}' cannot come from an external pack (it is a shader layer on the head)",
                    f"use a procedural generator; packs may provide: {', '.join(PACK_ANCHORS)}"))
    if not pack_object_name(entry):
        out.append(("external pack names no object or collection",
                    "add object = \"NAME\" (the object or collection inside the .blend)"))
    if not str(entry.get("licence", "")).strip():
        out.append(("external pack has no licence", "add licence = \"...\" (the pack's licence)"))
    rel, _ = split_generator(entry.get("generator", ""))
    real, problem = pack_path_problem(rel, root)
    if problem:
        out.append(problem)
        return out
    declared = entry.get("sha256")
    if not declared:
        out.append((f"external pack '{rel}' declares no sha256",
                    f"add sha256 = \"{sha256_file(real)}\" after checking the file"))
    else:
        got = sha256_file(real)
        if got != str(declared).lower():
            out.append((f"external pack file {real} does not match its checksum (sha256 {got}, declared {declared})",
                        "the file changed: restore the original or review it and update sha256"))
    return out
