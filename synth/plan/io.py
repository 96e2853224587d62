"""Plan directories: writer, reader and schema (docs/plan-format.md).

::

    DIR/plan.json                 header: format, seed, resolved config, model and catalogue
                                  hashes, shard list with sha256 per shard file, plan_hash
    DIR/summary.json              deterministic statistics (no timings)
    DIR/shards/shard_000000.json  one spec per shard: everything a worker needs

The writer builds everything in a sibling temporary directory and renames it into place,
so a failed or interrupted run leaves nothing half-written. Shard files are compact JSON
(orjson); the header and summary are indented with sorted keys. ``plan_hash`` is the
sha256 of the header's canonical JSON without ``plan_hash`` itself; the header lists the
sha256 of every shard file, so the hash covers the whole plan.
"""

from __future__ import annotations

import json
import os
import shutil
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterable

import orjson

from synth.dataset.layout import frame_key
from synth.errors import SynthError
from synth.io import (DirectoryTaken, FileRefused, atomic_dir, created_dirs, file_digest, fsync_file, read_bounded,
                      loads_json, read_json, sha256_bytes, sha256_file)

PLAN_FORMAT = "synth-plan"
PLAN_FORMAT_VERSION = 1
HEADER_FILE = "plan.json"
SUMMARY_FILE = "summary.json"
SHARDS_DIR = "shards"
SCHEMA_PATH = Path(__file__).resolve().parents[1] / "schemas" / "plan.schema.json"
#: plan.json lists every shard (~300 bytes each): a larger file is refused, never read.
MAX_HEADER_BYTES = 256 << 20

#: Config keys added after plans were first hashed, with the value every older plan had: at that
#: value the plan's header leaves the key out, so plans made without it keep their bytes and
#: ``plan_hash`` (readers take the value from here when the key is absent: :func:`planned`;
#: the writer: ``planner.header_config``).
LATER_KEYS = {("dataset", "environments_per_expression"): 1,
              # the head-shape rule (synth.plan.head_shapes): plans made before it kept every draw ("none");
              # its ranges at their first defaults are left out too, so a plan with "none" keeps its bytes
              ("identity", "head_shape"): "none", ("identity", "head_breadth_mm"): [131.0, 180.0],
              ("identity", "head_length_mm"): [168.0, 225.0], ("identity", "face_height_mm"): [91.0, 156.0],
              ("identity", "face_width_mm"): [116.0, 174.0], ("identity", "cephalic_index"): [70.0, 90.0],
              ("identity", "facial_index"): [65.0, 100.0], ("identity", "head_shape_attempts"): 32,
              # the light-path and denoiser settings a preset may set (unset: Cycles' own, as plans before them
              # rendered; synth.plan.records.RenderSettings holds those values)
              **{("render", k): None for k in ("diffuse_bounces", "glossy_bounces", "transmission_bounces",
                                               "transparent_bounces", "hair_shape", "light_tree", "caustics",
                                               "denoise_prefilter", "denoise_quality", "path_guiding")}}


def planned(config: dict, section: str, key: str):
    """A plan header's config value, :data:`LATER_KEYS`' value when the header leaves it out."""
    sec = config[section]
    return sec[key] if key in sec else LATER_KEYS[(section, key)]


@lru_cache(maxsize=1)
def plan_schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


def _validator(definition: str):
    import jsonschema

    schema = {**plan_schema(), "$ref": f"#/$defs/{definition}"}
    return jsonschema.Draft202012Validator(schema)


def validate(obj: Any, definition: str, where: str) -> None:
    """Check ``obj`` against ``$defs/<definition>`` of plan.schema.json (header, shard, frame, ...)."""
    err = next(iter(sorted(_validator(definition).iter_errors(obj), key=lambda e: list(e.absolute_path))), None)
    if err is not None:
        loc = "/".join(str(p) for p in err.absolute_path) or "top level"
        raise SynthError(f"plan {definition} invalid at {loc}: {err.message[:200]}", where,
                         "re-run 'synth plan' (see docs/plan-format.md)")


def dumps_compact(obj: Any) -> bytes:
    return orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY)


def dumps_pretty(obj: Any) -> bytes:
    return orjson.dumps(obj, option=orjson.OPT_INDENT_2 | orjson.OPT_SORT_KEYS) + b"\n"


def header_hash(header: dict) -> str:
    body = {k: v for k, v in header.items() if k != "plan_hash"}
    return sha256_bytes(orjson.dumps(body, option=orjson.OPT_SORT_KEYS))


# --------------------------------------------------------------------------- writer


def check_out_dir(out: Path) -> str | None:
    """Refuse an unusable --out early. Returns the plan_hash already there, if any."""
    if out.exists() and not out.is_dir():
        raise SynthError("output path exists and is not a directory", str(out), "choose a directory for --out")
    if not out.exists() or not any(out.iterdir()):
        return None
    hp = out / HEADER_FILE
    if not hp.is_file():
        raise SynthError("output directory is not empty and holds no plan", str(out), "use an empty or new --out")
    try:
        return str(read_json(hp, max_bytes=MAX_HEADER_BYTES)["plan_hash"])
    except (ValueError, KeyError, TypeError):
        raise SynthError("output directory holds an unreadable plan.json", str(out), "use a new --out") from None


def write_shards(tmp: Path | None, shards: Iterable[tuple[str, dict]],
                 frames_per_identity: int | None = None) -> list[dict]:
    """Write shard specs into ``tmp/shards/`` (``tmp=None``: only hash them); returns their
    header listing entries. ``frames_per_identity``: the frame count per identity, for specs
    whose frames are JSON text (``orjson.Fragment``, planner.ShardSpecs); else counted."""
    listing = []
    for shard_id, spec in shards:
        data = dumps_compact(spec)
        name = f"{SHARDS_DIR}/{shard_id}.json"
        if tmp is not None:
            (tmp / name).write_bytes(data)
        idents = spec["identities"]
        n_frames = len(idents) * frames_per_identity if frames_per_identity is not None \
            else sum(len(e["frames"]) for i in idents for e in i["expressions"])
        listing.append({"shard_id": shard_id, "file": name,
                        "identities": [idents[0]["identity_index"], idents[-1]["identity_index"] + 1],
                        "frames": n_frames, "bytes": len(data), "sha256": sha256_bytes(data)})
    return listing


def finish_header(header: dict, listing: list[dict], summary: dict) -> tuple[dict, dict]:
    """The header with its shard listing and ``plan_hash``, and the summary with the hash."""
    header = {**header, "shards": listing}
    header["plan_hash"] = header_hash(header)
    return header, {**summary, "plan_hash": header["plan_hash"]}


def write_plan(out: str | os.PathLike | None, header: dict,
               produce: Callable[[Path | None], tuple[list[dict], dict]]) -> tuple[dict, dict]:
    """Write a plan directory atomically. ``produce(tmp)`` writes the shard files into
    ``tmp/shards/`` (see :func:`write_shards`) and returns (listing, summary); ``header``
    lacks ``shards`` and ``plan_hash``, which are filled in here. Returns (header, summary).

    ``out=None`` writes nothing: ``produce(None)`` only hashes, and the header tells the plan
    hash these inputs give (to compare with an existing plan on read-only media, say). If
    ``out`` already holds the identical plan, or another process puts it there while this one
    plans (two ``synth render`` started at once), that plan is kept and this one discarded; a
    different plan there is refused (SynthError). A refused or failed plan leaves nothing,
    not even the parent directories it created."""
    if out is None:
        return finish_header(header, *produce(None))
    out = Path(out)
    existing = check_out_dir(out)
    with created_dirs(out.parent):
        try:
            with atomic_dir(out) as tmp:  # replaces an empty ``out`` (checked above)
                (tmp / SHARDS_DIR).mkdir()
                header, summary = finish_header(header, *produce(tmp))
                (tmp / SUMMARY_FILE).write_bytes(dumps_pretty(summary))
                (tmp / HEADER_FILE).write_bytes(dumps_pretty(header))
                fsync_file(tmp / HEADER_FILE)
                if existing is not None:
                    _same_plan(out, existing, header["plan_hash"])
                    shutil.rmtree(tmp)  # the identical plan is already there: keep it
        except DirectoryTaken:  # another process placed its plan first: adopt it if identical
            _same_plan(out, check_out_dir(out), header["plan_hash"])
    return header, summary


def _same_plan(out: Path, existing: str | None, plan_hash: str) -> None:
    if existing != plan_hash:
        raise SynthError(f"output directory holds a different plan (hash {str(existing)[:16]}, this plan "
                         f"{plan_hash[:16]})", str(out), "use a new --out or delete the old plan")


def check_hdri_files(lighting: dict) -> None:
    """Refuse a lighting config whose environment maps are missing (before any worker starts)."""
    if lighting.get("environment") != "hdri":
        return
    for f in lighting.get("hdri_files") or ():
        if not Path(f).is_file():
            raise SynthError("HDR environment file not found", str(f),
                             "restore the file or remove it from lighting.hdri_files")


# --------------------------------------------------------------------------- reader


class Plan:
    """A plan directory opened for reading (what workers and the render command use)."""

    def __init__(self, root: str | os.PathLike, validate_header: bool = True):
        self.root = Path(root)
        hp = self.root / HEADER_FILE
        if not hp.is_file():
            raise SynthError("no plan.json in the plan directory", str(self.root), "run 'synth plan --out DIR' first")
        try:
            self.header: dict = read_json(hp, max_bytes=MAX_HEADER_BYTES)
        except ValueError as e:
            raise SynthError(f"plan.json cannot be read ({e})", str(hp), "re-run 'synth plan'") from None
        if not isinstance(self.header, dict) or self.header.get("format") != PLAN_FORMAT:
            raise SynthError("not a synth plan (format field)", str(hp), "point at a directory written by 'synth plan'")
        if self.header.get("format_version") != PLAN_FORMAT_VERSION:
            raise SynthError(f"plan format version {self.header.get('format_version')} is not supported "
                             f"(this synth reads {PLAN_FORMAT_VERSION})", str(hp), "re-run 'synth plan'")
        if validate_header:
            validate(self.header, "header", str(hp))
        if header_hash(self.header) != self.header["plan_hash"]:
            raise SynthError("plan.json was modified after planning (plan_hash mismatch)", str(hp),
                             "re-run 'synth plan'")
        self._shards = {s["shard_id"]: s for s in self.header["shards"]}

    @property
    def plan_hash(self) -> str:
        return self.header["plan_hash"]

    @property
    def seed(self) -> int:
        return int(self.header["run_seed"])

    @property
    def config(self) -> dict:
        return self.header["config"]

    def shard_ids(self) -> list[str]:
        return list(self._shards)

    def shard(self, shard_id: str, validate_spec: bool = False) -> dict:
        """One shard spec, checked against the sha256 recorded in the header."""
        if shard_id not in self._shards:
            raise SynthError(f"unknown shard '{shard_id}'", str(self.root), f"the plan has {len(self._shards)} shards")
        entry = self._shards[shard_id]
        p = self.root / entry["file"]
        try:
            data = read_bounded(p, entry["bytes"])
        except OSError as e:
            raise SynthError(f"cannot read shard spec ({e.strerror})", str(p), "re-run 'synth plan'") from None
        except FileRefused:
            data = b""  # larger than planned: the sha256 below cannot match
        if sha256_bytes(data) != entry["sha256"]:
            raise SynthError("shard spec does not match its sha256 in plan.json", str(p), "re-run 'synth plan'")
        try:
            spec = loads_json(data)
        except ValueError as e:
            raise SynthError(f"shard spec cannot be read ({e})", str(p), "re-run 'synth plan'") from None
        if validate_spec:
            validate(spec, "shard", str(p))
        return spec

    def shard_spec(self, shard_id: str):
        """One shard spec as typed records (:class:`synth.plan.records.ShardSpec`), checked."""
        from synth.plan.records import ShardSpec

        return ShardSpec.from_json(self.shard(shard_id), str(self.root / self._shards[shard_id]["file"]))

    def verify(self) -> None:
        """Check the whole plan before any worker starts: every shard spec has the sha256
        plan.json lists, the model file is the one planned with, the HDR maps exist."""
        for sid, entry in self._shards.items():
            p = self.root / entry["file"]
            try:
                digest, _ = file_digest(p, max_bytes=entry["bytes"])
            except FileNotFoundError:
                raise SynthError(f"shard spec of {sid} is missing", str(p), "restore the plan or re-run 'synth plan'") \
                    from None
            except (OSError, FileRefused):
                digest = None
            if digest != entry["sha256"]:
                raise SynthError(f"shard spec of {sid} was changed after planning (its sha256 differs from plan.json)",
                                 str(p), "restore the plan or re-run 'synth plan'")
        self.checked_model_path()
        check_hdri_files(self.lighting())

    def frame_keys(self, shard_id: str) -> list[str]:
        """Frame keys of a shard, from the header alone (no shard file read)."""
        a, b = self._shards[shard_id]["identities"]
        E = self.config["dataset"]["expressions_per_identity"]
        V = self.config["dataset"]["views_per_expression"]
        N = self.environments
        if N == 1:
            return [frame_key(i, e, v) for i in range(a, b) for e in range(E) for v in range(V)]
        return [frame_key(i, e, v, k) for i in range(a, b) for e in range(E) for k in range(N) for v in range(V)]

    @property
    def environments(self) -> int:
        """Environments per expression (plans made before the option: 1)."""
        return int(planned(self.config, "dataset", "environments_per_expression"))

    def expected(self) -> dict[str, list[str]]:
        """shard id -> frame keys (what a dataset directory expects)."""
        return {s: self.frame_keys(s) for s in self._shards}

    @property
    def shard_format(self) -> str:
        """How committed shards are stored: ``"dir"`` or ``"tar"`` (plans made before the option: dir)."""
        return str(self.config["dataset"].get("shard_format", "dir"))

    def render_settings(self) -> dict:
        return dict(self.config["render"])

    def lighting(self) -> dict:
        return dict(self.config["lighting"])

    def model_sha256(self) -> str:
        return self.header["model"]["sha256"]

    def model_path(self) -> Path:
        """Where the plan's model is: the recorded file, or (for the embedded default) the model
        file shipped in the installed package."""
        p = self.header["model"]["path"]
        if p is None:
            from synth.model.default import default_model_path

            return default_model_path()
        return Path(p)

    def checked_model_path(self) -> Path:
        """The model file the plan was made with, refused in one line if it is missing or its
        sha256 is not the plan's. For the embedded default, a model with the plan's sha256 in this
        node's cache (a plan made before the model shipped as package data) is used as well."""
        import socket

        want = self.model_sha256()
        path = self.model_path()
        default = self.header["model"]["path"] is None
        if not path.is_file():
            raise SynthError("the plan's model file is missing", str(path),
                             "put it at that path on every node (shared storage) or re-run 'synth plan'")
        have = sha256_file(path)
        if have == want:
            return path
        if default:
            cached = _cached_model(want)
            if cached is not None:
                return cached
            fix = ("install the synth-faces version the plan was made with on this node, or re-run 'synth plan' "
                   "here; a farm of mixed versions plans with --model FILE on shared storage (docs/farm.md)")
        else:
            fix = "restore the plan's model file, or re-run 'synth plan' with this model"
        raise SynthError(f"the model differs from the plan's on node {socket.gethostname()}: plan sha256 "
                         f"{want[:16]}..., this node's {have[:16]}...", str(path), fix)

    def model_data(self):
        """The head model the plan was made with (refused if the file changed since)."""
        from synth.model.format import read_model

        return read_model(self.checked_model_path())


def _cached_model(sha256: str) -> Path | None:
    """A default model built into this node's cache whose sha256 is ``sha256``, if any."""
    from synth.io import cache_dir

    for p in sorted((cache_dir() / "models").glob("makehuman-head-*.npz")):
        if sha256_file(p) == sha256:
            return p
    return None


def load_plan(root: str | os.PathLike) -> Plan:
    return Plan(root)
