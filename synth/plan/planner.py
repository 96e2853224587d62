"""Build a plan: every random choice of a dataset as plain data, one spec per shard.

Identity i's data depends only on (run seed, i) and the inputs (config, model, asset
catalogue); frame (i, e, v) only on (run seed, i, e, v) (the views of one expression are
drawn together, since each is rejected against the earlier ones). So a plan of identities
[a, b) equals the matching slice of any larger plan, whatever the shard size.
"""

from __future__ import annotations

import gc
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from synth import seeds
from synth.assets.catalogue import Catalogue, load_catalogue
from synth.assets.classes import NAMES, check_model
from synth.assets.params import assets_from_json
from synth.config import Config
from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world
from synth.dataset.layout import frame_keys, shard_name
from synth.errors import SynthError
from synth.io.process import default_jobs
from synth.model.format import HeadModelData
from synth.plan import assets as assets_mod
from synth.plan import cameras, expressions, identities, parallel, skin


def check_counts(cfg: Config, first_identity: int, n_identities: int) -> None:
    d = cfg.dataset
    if n_identities < 1:
        raise SynthError(f"--identities must be at least 1, got {n_identities}", "--identities", "plan one or more")
    if first_identity < 0 or first_identity + n_identities > 1_000_000:
        raise SynthError("identity indices must lie in [0, 1000000) (frame keys have 6 digits)",
                         "--identities, --start", "plan fewer identities")
    if d.expressions_per_identity > 100 or d.views_per_expression > 100:
        raise SynthError("expressions_per_identity and views_per_expression must be at most 100 (frame keys have "
                         "2 digits)", "dataset", "lower them")
    if first_identity % d.identities_per_shard:
        raise SynthError(f"--start {first_identity} is not a multiple of dataset.identities_per_shard "
                         f"({d.identities_per_shard})", "--start", "start at a shard boundary")


@dataclass
class PlanArrays:
    """Everything sampled, as arrays over identities (N), expression pairs (P = N * E) and views (V)."""

    identity: np.ndarray  # (N,) identity indices
    codes: np.ndarray  # (N, Ki)
    targets: np.ndarray  # (N, 3)
    assets: list[dict[str, Any]]
    lighting: list[dict[str, Any]]  # (N,) environment 0 of each identity
    environments: list[list[dict[str, Any]]]  # (P,) environments 1.. of each expression ([] with one environment)
    expr: expressions.Expressions  # over P
    expr_model: expressions.ExpressionModel
    views: cameras.Views  # (P, V)
    roll_deg: np.ndarray  # (P, V)
    K: np.ndarray  # (P, V, 3, 3)
    c2w: np.ndarray  # (P, V, 4, 4)
    w2c: np.ndarray  # (P, V, 4, 4)
    frame_seeds: np.ndarray  # (P, V)
    width: int
    height: int


def sample_plan(cfg: Config, model: HeadModelData, catalogue: Catalogue, seed: int,
                first_identity: int, n_identities: int, extremes: np.ndarray | None = None) -> PlanArrays:
    """Sample identities [first_identity, first_identity + n_identities) (vectorised);
    ``extremes``: the model's :func:`identities.extreme_vertices` (default: searched here)."""
    cfg = cfg.resolved()
    d, cam = cfg.dataset, cfg.camera
    E, V = d.expressions_per_identity, d.views_per_expression
    cameras.check_feasible(cam, V)
    ids = np.arange(first_identity, first_identity + n_identities, dtype=np.int64)
    codes = identities.planned_codes(seed, ids, model, cfg.identity)
    assets = assets_mod.sample_assets_batch(seed, ids, catalogue, cfg.assets.disabled_classes)
    skin.apply_skin_tones(seed, ids, assets, cfg.skin)
    if cam.target == "head" or cam.distance == "fit":  # one hull search for both
        head_c, head_r = identities.head_spheres(model, codes, cam.head_margin_m, extremes)
        head_r = head_r + assets_mod.hair_reach_m(assets)
    if cam.target == "head":
        targets = head_c + np.asarray(cam.target_offset_m, np.float64)
    else:
        targets = identities.look_at_targets(model, codes, cam.target, cam.target_offset_m)
    ii = np.repeat(ids, E)
    ee = np.tile(np.arange(E, dtype=np.int64), n_identities)
    em = expressions.resolve(model.expression_names, cfg.expression)
    expr = expressions.sample_expressions(seed, ii, ee, em, cfg.expression)
    if ii.size > 64:  # fail fast: a hopeless request shows on a few expressions (same result as below)
        cameras.sample_views(seed, ii[:16], ee[:16], V, cam)
    views = cameras.sample_views(seed, ii, ee, V, cam)
    if cam.distance == "fit":
        views.radius_m = cameras.fit_distances(np.repeat(head_r, E)[:, None], views.radius_u, cam,
                                               cfg.fov_deg, cfg.render.resolution)
    vv = np.arange(V, dtype=np.int64)[None, :]
    extra = seeds.uniforms(seed, seeds.Stream.CAMERA_EXTRA, ii[:, None], ee[:, None], vv, n=3)
    roll = cam.roll_deg[0] + extra[..., 0] * (cam.roll_deg[1] - cam.roll_deg[0])
    jit = cam.principal_point_jitter_px * (2.0 * extra[..., 1:3] - 1.0)
    W, H = cfg.render.resolution
    K = intrinsics(W, H, cfg.fov_deg, jit)
    tgt = np.repeat(targets, E, axis=0)[:, None, :]
    c2w = orbit_camera_to_world(views.azimuth_deg, views.elevation_deg, views.radius_m, tgt, roll)
    w2c = invert_rigid(c2w)
    fseeds = seeds.frame_seeds(seed, ii[:, None], ee[:, None], vv)
    lighting = [assets_mod.sample_lighting(seed, int(i), cfg.lighting) for i in ids]
    envs = [[assets_mod.sample_environment(seed, int(i), int(e), k, cfg.lighting)
             for k in range(1, d.environments_per_expression)] for i, e in zip(ii.tolist(), ee.tolist())]
    return PlanArrays(ids, codes, targets, assets, lighting, envs, expr, em, views, roll, K, c2w, w2c, fseeds, W, H)


DECIMALS = 8  # every float of a plan is rounded to 8 decimal places (byte-stable output)


def _r(a) -> list:
    """Round and convert to nested lists; +0.0 turns -0.0 into 0.0."""
    return _rn(a).tolist()


def _rn(a) -> np.ndarray:
    """Rounded float64 array (C-contiguous, serialised natively by orjson)."""
    r = np.round(np.asarray(a, np.float64), DECIMALS)
    r += 0.0  # in place: no second array of the plan's size
    return np.ascontiguousarray(r)


def _texts(a: np.ndarray) -> list[bytes]:
    """orjson's text of each ``a[j]`` (a: (M,) or (M, r, c), C-contiguous), cut from one orjson
    call over the whole array: each scalar's digits, or each matrix's rows without its outer
    two brackets (``1,0,32],[0,1,32],[0,0,1`` for a 3x3). Numbers hold no brackets or commas,
    so the cuts are exact; the text is what orjson writes for the value inside a document."""
    import orjson

    t = orjson.dumps(a, option=orjson.OPT_SERIALIZE_NUMPY)
    out = t.split(b",") if a.ndim == 1 else t.split(b"]],[[")  # (M,) or (M, r, c)
    cut = 1 if a.ndim == 1 else 3  # the brackets around the whole array (not copying the text once more)
    out[0] = out[0][cut:]
    out[-1] = out[-1][:-cut]  # (in turn: with M = 1 both are the one piece)
    return out


class ShardSpecs:
    """Turns PlanArrays into shard specs. The bulk rounding happens once, here; :meth:`specs`
    then assembles shards [a, b) (cheap per shard, and fork-friendly).

    A shard's frames (585,000 for 1,500 identities at the paper's counts) are written as JSON
    text, not built as dicts: each expression's ``frames`` is an ``orjson.Fragment`` holding
    exactly the bytes orjson gives the list of frame objects (keys in the documented order,
    numbers as orjson writes the rounded float64 values), assembled from :func:`_texts` with
    slice assignments. ``tests/plan/test_plan_text.py`` checks the text against orjson's own
    serialisation of the frame dicts."""

    def __init__(self, cfg: Config, arr: PlanArrays, seed: int):
        cfg = cfg.resolved()
        d, cam = cfg.dataset, cfg.camera
        self.E, self.V, self.S = d.expressions_per_identity, d.views_per_expression, d.identities_per_shard
        self.N = d.environments_per_expression
        self.arr, self.seed = arr, seed
        ex = arr.expr
        P, V = arr.K.shape[:2]
        # matrices as (P * V, r, c), scalars as (P * V,): rounded float64, cut into text per shard
        self.K, self.w2c, self.c2w = (_rn(m).reshape(P * V, *m.shape[2:]) for m in (arr.K, arr.w2c, arr.c2w))
        self.az, self.el, self.rad = (_rn(x).reshape(P * V) for x in (arr.views.azimuth_deg, arr.views.elevation_deg,
                                                                      arr.views.radius_m))
        self.fseeds = np.ascontiguousarray(arr.frame_seeds, np.int64).reshape(P * V)
        self.codes_e = _rn(ex.codes)
        self.rots = {k: _r(v) for k, v in ex.joint_rotations().items()}
        self.pose = {k: _r(getattr(ex, k)) for k in ("jaw_open_deg", "jaw_lateral_deg", "gaze_yaw_deg",
                                                      "gaze_pitch_deg", "vergence_deg")}
        self.kinds = [expressions.KINDS[k] for k in ex.kind.tolist()]
        self.presets = [arr.expr_model.preset_names[p] if p >= 0 else None for p in ex.preset.tolist()]
        self.cand, self.rest = arr.views.candidates.tolist(), arr.views.restarts.tolist()
        self.id_codes, self.targets = _rn(arr.codes), _r(arr.targets)
        self.near, self.far = cam.near_m, cam.far_m
        self.n_shards = -(-arr.identity.size // self.S)

    def _frames_text(self, n0: int, n1: int) -> list[bytes]:
        """The ``frames`` JSON list of every expression of identities [n0, n1) (one bytes each).

        Each frame's text is 19 pieces: the variable ones (key, view, seed, the three matrices,
        azimuth, elevation, radius) cut from bulk orjson output (:func:`_texts`), the constant
        ones (the keys' names; identity, expression and environment; the image size, near, far
        and the target) made once; the pieces are laid out with slice assignments and joined
        per expression."""
        import orjson

        E, V, N, arr = self.E, self.V, self.N, self.arr
        r = slice(n0 * E * V, n1 * E * V)  # these identities' views (the same in every environment)
        var = [_texts(self.K[r]), _texts(self.w2c[r]), _texts(self.c2w[r]), _texts(self.az[r]), _texts(self.el[r]),
               _texts(self.rad[r]), _texts(self.fseeds[r])]
        if N > 1:  # every view in each environment, environment-major
            var = [[t for q in range(0, len(x), V) for _ in range(N) for t in x[q:q + V]] for x in var]
        Kt, Wt, Ct, azt, elt, radt, seedt = var
        F = len(Kt)  # frames
        fixed = (b'","identity_index":%d,"expression_index":%d,"environment_index":%d,"view_index":' if N > 1
                 else b'","identity_index":%d,"expression_index":%d,"view_index":')
        tail = (b']],"width":%d,"height":%d,"near":' % (arr.width, arr.height) + orjson.dumps(self.near)
                + b',"far":' + orjson.dumps(self.far) + b',"azimuth_deg":')
        views = [b"%d" % v for v in range(V)]
        keys: list[str] = []
        ie: list[bytes] = []
        tgt: list[bytes] = []
        for n in range(n0, n1):
            i = int(arr.identity[n])
            tgt += [b',"target":' + orjson.dumps(self.targets[n]) + b"}}"] * (E * N * V)
            for e in range(E):
                for k in range(N):
                    keys += frame_keys(i, e, V, k if N > 1 else None)
                    ie += [fixed % ((i, e, k) if N > 1 else (i, e))] * V
        parts: list = [b""] * (19 * F)
        parts[0::19] = [b',{"frame_id":"'] * F
        parts[1::19] = [k.encode() for k in keys]
        parts[2::19] = ie
        parts[3::19] = views * (F // V)
        parts[4::19] = [b',"seed":'] * F
        parts[5::19] = seedt
        parts[6::19] = [b',"camera":{"K":[['] * F
        parts[7::19] = Kt
        parts[8::19] = [b']],"world_to_camera":[['] * F
        parts[9::19] = Wt
        parts[10::19] = [b']],"camera_to_world":[['] * F
        parts[11::19] = Ct
        parts[12::19] = [tail] * F
        parts[13::19] = azt
        parts[14::19] = [b',"elevation_deg":'] * F
        parts[15::19] = elt
        parts[16::19] = [b',"radius_m":'] * F
        parts[17::19] = radt
        parts[18::19] = tgt
        step = 19 * N * V  # pieces per expression: its list opens without a comma and closes
        for q in range(0, 19 * F, step):
            parts[q] = b'[{"frame_id":"'
            parts[q + step - 1] += b"]"
        return [b"".join(parts[q:q + step]) for q in range(0, 19 * F, step)]

    def specs(self, a: int = 0, b: int | None = None):
        """Yield (shard_id, spec) for shards [a, b) of this plan (counted from its first shard);
        each expression's ``frames`` is an ``orjson.Fragment`` (see the class)."""
        import orjson

        E, S, arr = self.E, self.S, self.arr
        N = arr.identity.size
        b = self.n_shards if b is None else b
        for s0 in range(a * S, min(N, b * S), S):
            s1 = min(N, s0 + S)
            frames = iter(self._frames_text(s0, s1))
            idents = []
            for n in range(s0, s1):
                exprs = []
                for e in range(E):
                    p = n * E + e
                    rec = {
                        "expression_index": e, "kind": self.kinds[p], "preset": self.presets[p],
                        "expression_code": self.codes_e[p],
                        "joint_rotations": {k: r[p] for k, r in self.rots.items()},
                        "pose": {k: q[p] for k, q in self.pose.items()},
                        "camera_sampling": {"candidates": self.cand[p], "restarts": self.rest[p]}}
                    if self.N > 1:
                        rec["environments"] = [arr.lighting[n], *arr.environments[p]]
                    rec["frames"] = orjson.Fragment(next(frames))
                    exprs.append(rec)
                picks = assets_from_json(arr.assets[n], f"identity {int(arr.identity[n])} assets")
                skin = picks.get("skin")
                idents.append({"identity_index": int(arr.identity[n]), "identity_code": self.id_codes[n],
                               "target": self.targets[n],
                               "assets": {c: None if e is None else e.to_json() for c, e in picks.items()},
                               "skin": None if skin is None else skin.params.to_json(),
                               "lighting": arr.lighting[n], "expressions": exprs})
            sid = shard_name(int(arr.identity[s0]) // S)
            yield sid, {"format": "synth-plan-shard", "format_version": 1, "shard_id": sid, "run_seed": self.seed,
                        "identities": idents}

    @property
    def frames_per_identity(self) -> int:
        return self.E * self.N * self.V


def replan_frame(cfg: Config, model: HeadModelData, catalogue: Catalogue, seed: int, identity: int,
                 expression: int, view: int, environment: int = 0) -> dict[str, Any]:
    """Re-plan one frame alone (as plain JSON data): the same object as in any plan with this
    seed, config, model and catalogue that contains the frame."""
    import orjson

    arr = sample_plan(cfg, model, catalogue, seed, identity, 1)
    (_, spec), = ShardSpecs(cfg, arr, seed).specs()
    V = cfg.resolved().dataset.views_per_expression
    frames = spec["identities"][0]["expressions"][expression]["frames"]
    return orjson.loads(orjson.dumps(frames))[environment * V + view]


def model_record(model_path) -> tuple[HeadModelData, dict[str, Any]]:
    """Read the model (``None`` = the embedded default) and describe it for the plan header."""
    from synth.io import sha256_file
    from synth.model.format import read_model

    if model_path is None:
        from synth.model.default import default_model_path

        p, rec = default_model_path(), None
    else:
        p = Path(model_path).resolve()
        rec = str(p)
    data = read_model(p)
    return data, {"name": data.name, "sha256": sha256_file(p), "path": rec, "identity_dims": data.identity_dims,
                  "expression_dims": data.expression_dims, "expression_names": list(data.expression_names),
                  "joint_names": list(data.joint_names)}


def header_config(cfg: Config) -> dict[str, dict[str, Any]]:
    """The resolved config as the plan header records it (``io.LATER_KEYS`` at their old value left out)."""
    from synth.config import to_dict
    from synth.plan.io import LATER_KEYS

    out = to_dict(cfg, drop_none=False)
    for (sec, key), old in LATER_KEYS.items():
        if out[sec].get(key) == old:
            del out[sec][key]
    return out


def run_plan(cfg: Config, n_identities: int, out, seed: int | None = None, first_identity: int = 0,
             model_path=None, jobs: int | None = None) -> tuple[dict, dict]:
    """Sample and write a plan directory; returns (header, summary). With ``out=None`` nothing
    is written: the header says which plan (``plan_hash``) these inputs give.

    Identities are planned in chunks of whole shards, in up to ``jobs`` forked processes
    (default: up to 4 cores); each chunk samples and writes its own shards. Every number
    depends only on (seed, indices), so ``jobs`` and the chunking never change the output."""
    import dataclasses

    import synth
    from synth.plan import io, stats

    if seed is not None:
        try:
            seed = seeds.check_seed(seed)
        except ValueError as e:
            raise SynthError(str(e), "--seed", "use a seed from 0 to 18446744073709551615") from None
        cfg = dataclasses.replace(cfg, dataset=dataclasses.replace(cfg.dataset, seed=seed))
    cfg = cfg.resolved()
    seed = cfg.dataset.seed
    check_counts(cfg, first_identity, n_identities)
    cameras.check_feasible(cfg.camera, cfg.dataset.views_per_expression)
    if out is not None:
        io.check_out_dir(Path(out))  # fail fast, before the sampling
    model, model_rec = model_record(model_path)
    check_model(model, [c for c in NAMES if c not in cfg.assets.disabled_classes],
                str(model_path) if model_path is not None else "the embedded default model")
    cat = load_catalogue(cfg.assets.manifest_dir or None)
    d = cfg.dataset
    S = d.identities_per_shard
    n_shards = -(-n_identities // S)
    jobs = default_jobs() if jobs is None else max(1, int(jobs))
    extremes = None  # searched once here (cached per model), not in every forked chunk
    if cfg.camera.target == "head" or cfg.camera.distance == "fit":
        extremes = identities.extreme_vertices(model, model_rec["sha256"])

    def produce(tmp: Path | None) -> tuple[list[dict], dict]:
        def chunk(r: tuple[int, int]):
            lo, hi = first_identity + r[0] * S, min(first_identity + r[1] * S, first_identity + n_identities)
            arr = sample_plan(cfg, model, cat, seed, lo, hi - lo, extremes)
            specs = ShardSpecs(cfg, arr, seed)
            listing = io.write_shards(tmp, specs.specs(), specs.frames_per_identity)
            return listing, stats.partial(arr)

        parts = parallel.chunks(n_shards, 1 if jobs == 1 else 2 * jobs)
        enabled = gc.isenabled()
        gc.disable()  # millions of short-lived objects and no reference cycles: collections only cost time
        try:
            res = parallel.fork_map(chunk, parts, jobs)
        finally:
            if enabled:
                gc.enable()
        return [x for listing, _ in res for x in listing], stats.merge(cfg, [p for _, p in res])

    header = {
        "format": io.PLAN_FORMAT, "format_version": io.PLAN_FORMAT_VERSION, "synth_version": synth.__version__,
        "run_seed": seed, "first_identity": first_identity, "num_identities": n_identities,
        "identities_per_shard": S, "expressions_per_identity": d.expressions_per_identity,
        "views_per_expression": d.views_per_expression,
        "num_frames": n_identities * d.expressions_per_identity * d.environments_per_expression
        * d.views_per_expression,
        "model": model_rec, "catalogue": {"sha256": cat.digest}, "config": header_config(cfg),
    }
    return io.write_plan(out, header, produce)
