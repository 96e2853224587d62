"""Which parts of a planned identity make a face recogniser see two identities as different people?

A factor analysis with the judge of benchmarks/identity_diversity.py (dlib's face-recognition
ResNet, same person under 0.6). For pairs (A, B) of planned identities it renders *what-if*
identities: A with ONE factor taken from B, everything else (camera, expression and gaze,
lighting, the rigs' index-seeded randomness, the frame's render seed) A's, and measures how far
the judge moves A::

    .venv/bin/synth plan -n 12 -o BASE --set dataset.identities_per_shard=1 \\
        --set dataset.expressions_per_identity=1 --set dataset.views_per_expression=2 \\
        --set 'camera.azimuth_deg=[-20,20]' --set 'camera.elevation_deg=[-10,15]' \\
        --set camera.min_separation_deg=10 --set expression.neutral_weight=1.0 \\
        --set expression.preset_weight=0.0 --set expression.random_weight=0.0
    .venv/bin/python -m benchmarks.identity_factors run BASE WORK [--real PHOTO ...] [--json OUT.json]

``run`` writes one what-if plan per variant under WORK/plans (``plan`` alone does only that),
renders each with ``synth render`` into WORK/renders (resumed: a rerun renders nothing twice),
writes the frames as PNGs over mid grey (WORK/png) and judges them once per variant
(WORK/judge); then prints the tables. The base plan needs one identity per shard (the what-if
plans hold only the identities a factor changes) and one neutral expression; view 0 of each
identity is the one every variant renders, view 1 gives the same-identity reference.

Pairs: identity k with identity k + 1 (mod K): each identity is A once and B once.
The factors (:data:`FACTORS`): ``shape`` (the identity code), ``skin_tone`` (melanin, ITA,
haemoglobin), ``skin_detail`` (the other skin parameters: roughness, oiliness, pores, freckles,
age spots, wrinkles, subsurface radius, detail variant), ``eyebrows``, ``iris``, ``hair``,
``beard``, ``makeup`` (makeup and eyelashes), ``outfit`` (garment, glasses, headwear); ``all``
takes every one of them from B. References: ``b_view`` is B itself (its own index, so its own
rig randomness) rendered with A's expression record (gaze, camera, render seed): d(A, b_view)
is the pair's distance at one view (D), the quantity the factors are to explain; ``reseed`` is A
with another render seed (the renderer's noise floor). At ``preview`` that floor is about a third
of the threshold (the judge moves about 0.2 between two renders of one face with two seeds), so
every variant is also rendered with the second seed (``V+reseed``) and the tables give, beside
the one-seed distance, a noise-corrected one (:func:`corrected_sq`: cross-seed squared distances
less within-condition ones). The lighting is not a factor: every
identity of the default config has the same studio (``lighting.studio_rotation_deg`` = [0, 0]);
a swap that would break a catalogue rule (a cap over a bun) is rendered and flagged.

A change to the planner or catalogue, measured on a set (``identity_diversity`` plan flags) as
before -> after with only the identities it touches rendered again::

    .venv/bin/python -m benchmarks.identity_factors subset BEFORE_PLAN AFTER_PLAN SUB        # + 1 unchanged
    .venv/bin/python -m benchmarks.identity_factors subset BEFORE_PLAN AFTER_PLAN CTL --reseed
    .venv/bin/synth render -o SUBSET --plan SUB ; .venv/bin/synth render -o CONTROL --plan CTL
    .venv/bin/python -m benchmarks.identity_diversity measure BEFORE_SET SUBSET CONTROL --keep J
    .venv/bin/python -m benchmarks.identity_factors compare J/BEFORE_SET.json J/SUBSET.json \
        --fill BEFORE_PLAN AFTER_PLAN                       # and J/CONTROL.json: render noise alone

The what-if plans are written through the plan library (:func:`synth.plan.io.write_plan`: fresh
shard sha256s and plan hash; every identity checked as a :class:`synth.plan.records.ShardSpec`
first), so ``synth render`` checks them as it checks any plan. Their header is the base plan's
with ``views_per_expression`` 1 and the identity count of the subset; WORK/plans/VARIANT/whatif.json
says what was swapped.
"""

from __future__ import annotations

import argparse
import copy
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.identity_diversity import THRESHOLD, pair_distances, run_judge, same_pairs

#: factor -> (what it is, asset classes it takes whole from B; skin factors take skin parameters)
FACTORS = {
    "shape": ("identity code (head and face shape)", ()),
    "skin_tone": ("skin tone: melanin, ITA, haemoglobin", ()),
    "skin_detail": ("skin detail: roughness, oiliness, pores, freckles, age spots, wrinkles, SSS radius, "
                    "detail variant", ()),
    "eyebrows": ("eyebrows (style, thickness, density, arch, colour)", ("eyebrows",)),
    "iris": ("iris (eye colour)", ("iris",)),
    "hair": ("scalp hair (style, length, colour)", ("hair",)),
    "beard": ("facial hair", ("beard",)),
    "makeup": ("makeup and eyelashes", ("makeup", "eyelashes")),
    "outfit": ("garment, glasses, headwear", ("garment", "glasses", "headwear")),
}
SKIN_TONE = ("haemoglobin", "ita_deg", "melanin")  #: skin parameters of the tone factor
#: variants rendered besides the factors: every factor from B; B at A's view; A re-seeded
REFERENCES = ("all", "b_view", "reseed")
#: the same what-if identities with another render seed (A's own second seed is ``reseed``): for
#: the noise-corrected distances of :func:`corrected_sq`
SECOND_SEED = tuple(f"{v}+reseed" for v in (*FACTORS, "all", "b_view"))
VARIANTS = (*FACTORS, *REFERENCES, *SECOND_SEED)
RESEED_STEP = 7919  #: ``reseed`` adds this to each frame seed (mod 2**31)


# --------------------------------------------------------------------------- what-if identities


def _set_skin(ident: dict, params: dict | None) -> None:
    skin = ident["assets"].get("skin")
    if skin is None or params is None:
        return
    skin["params"] = dict(sorted(params.items()))
    ident["skin"] = dict(skin["params"])


def with_factor(a: dict, b: dict, factor: str) -> dict:
    """Identity record ``a`` (a shard's identity JSON) with ``factor`` (a :data:`FACTORS` key, or
    ``all``) taken from ``b``; a new dict, ``a`` untouched. Index, target, lighting and
    expressions stay ``a``'s."""
    if factor == "all":
        out = a
        for f in FACTORS:
            out = with_factor(out, b, f)
        return out
    if factor not in FACTORS:
        raise KeyError(f"unknown factor {factor!r}")
    out = copy.deepcopy(a)
    if factor == "shape":
        out["identity_code"] = list(b["identity_code"])
    elif factor in ("skin_tone", "skin_detail"):
        sa, sb = a["assets"].get("skin"), b["assets"].get("skin")
        if sa is None or sb is None:  # no parameters to mix: the whole pick
            out["assets"]["skin"] = copy.deepcopy(sb)
            out["skin"] = None if sb is None else dict(sb["params"])
            return out
        pa, pb = sa["params"], sb["params"]
        keys = set(SKIN_TONE) if factor == "skin_tone" else (set(pa) | set(pb)) - set(SKIN_TONE)
        p = {k: v for k, v in pa.items() if k not in keys}
        p.update({k: pb[k] for k in keys if k in pb})
        _set_skin(out, p)
    else:
        for cls in FACTORS[factor][1]:
            out["assets"][cls] = copy.deepcopy(b["assets"].get(cls))
    return out


def at_view_of(b: dict, a: dict) -> dict:
    """Identity ``b`` (its index, code, assets) with ``a``'s expressions: A's gaze, cameras and
    render seeds; the frames re-keyed to ``b``'s index."""
    from synth.dataset.layout import frame_key

    out = copy.deepcopy(b)
    out["expressions"] = copy.deepcopy(a["expressions"])
    out["lighting"] = copy.deepcopy(a["lighting"])
    i = out["identity_index"]
    for e in out["expressions"]:
        for f in e["frames"]:
            f["identity_index"] = i
            f["frame_id"] = frame_key(i, f["expression_index"], f["view_index"], f.get("environment_index"))
    return out


def reseeded(a: dict) -> dict:
    """``a`` with every frame seed moved by :data:`RESEED_STEP` (mod 2**31): only the render noise changes."""
    out = copy.deepcopy(a)
    for e in out["expressions"]:
        for f in e["frames"]:
            f["seed"] = (int(f["seed"]) + RESEED_STEP) % (1 << 31)
    return out


def first_view(ident: dict) -> dict:
    """``ident`` with only view 0 of each expression."""
    out = copy.deepcopy(ident)
    for e in out["expressions"]:
        e["frames"] = [f for f in e["frames"] if f["view_index"] == 0]
    return out


def cycle_pairs(n: int) -> list[tuple[int, int]]:
    """(k, k + 1 mod n) for k < n: each of n items is A once and B once."""
    return [(k, (k + 1) % n) for k in range(n)]


def variant_identity(variant: str, a: dict, b: dict) -> dict | None:
    """The what-if identity of a pair for ``variant`` (view 0 only), or None where the variant
    would render A unchanged (both lack the class, or carry the same pick). ``V+reseed``: variant
    V's identity with :func:`reseeded` frames."""
    if variant.endswith("+reseed"):
        w = variant_identity(variant[:-len("+reseed")], a, b)
        return None if w is None else reseeded(w)
    if variant == "b_view":
        return first_view(at_view_of(b, a))
    if variant == "reseed":
        return first_view(reseeded(a))
    out = with_factor(a, b, variant)
    return None if out == a else first_view(out)


def rule_conflicts(assets: dict, catalogue) -> list[str]:
    """The catalogue's exclusion rules an identity's picks break (``if_tag -> tag``, each once)."""
    tags = {}
    for cls, pick in assets.items():
        if pick is None or cls not in catalogue.classes:
            continue
        for a in catalogue.classes[cls]["assets"]:
            if a["id"] == pick["id"]:
                tags[cls] = set(a.get("tags", ()))
    out = []
    for r in catalogue.rules:
        for c1, t1 in tags.items():
            if r["if_tag"] not in t1:
                continue
            for c2, t2 in tags.items():
                hit = sorted(set(r["excludes_tags"]) & t2)
                if c2 != c1 and hit:
                    out.append(f"{cls_tag(c1, r['if_tag'])} with {cls_tag(c2, hit[0])}")
    return sorted(set(out))


def cls_tag(cls: str, tag: str) -> str:
    return f"{cls}:{tag}"


# --------------------------------------------------------------------------- plans


def base_identities(plan_dir: Path) -> dict[int, dict]:
    """identity index -> identity JSON of a plan (read through :class:`synth.plan.io.Plan`: checked)."""
    from synth.plan.io import Plan

    plan = Plan(plan_dir)
    out = {}
    for sid in plan.shard_ids():
        for ident in plan.shard(sid)["identities"]:
            out[int(ident["identity_index"])] = ident
    return out


def check_base(plan_dir: Path) -> None:
    from synth.errors import SynthError
    from synth.plan.io import Plan

    h = Plan(plan_dir).header
    if h["identities_per_shard"] != 1 or h["expressions_per_identity"] != 1 or h["views_per_expression"] < 2:
        raise SynthError("the base plan needs dataset.identities_per_shard=1, expressions_per_identity=1 and "
                         "views_per_expression >= 2", str(plan_dir), "re-plan it with the flags in the docstring")


def write_whatif_plan(base_dir: Path, out: Path, identities: list[dict], note: dict, one_view: bool = True) -> str:
    """A plan of ``identities`` (one per shard; ``one_view``: one view each) with the base plan's
    header otherwise; written by :func:`synth.plan.io.write_plan` (an identical plan already at
    ``out`` is kept, a different one refused). Returns its plan hash."""
    from synth.dataset.layout import shard_name
    from synth.plan import io
    from synth.plan.records import ShardSpec

    base = io.Plan(base_dir)
    header = {k: v for k, v in base.header.items() if k not in ("shards", "plan_hash")}
    header = json.loads(json.dumps(header))
    idents = sorted(identities, key=lambda i: i["identity_index"])
    header["config"]["dataset"]["identities_per_shard"] = 1
    header.update(identities_per_shard=1, first_identity=idents[0]["identity_index"], num_identities=len(idents),
                  num_frames=sum(len(e["frames"]) for i in idents for e in i["expressions"]))
    if one_view:
        header["config"]["dataset"]["views_per_expression"] = 1
        header["views_per_expression"] = 1
    specs = []
    for ident in idents:
        sid = shard_name(int(ident["identity_index"]))
        spec = {"format": "synth-plan-shard", "format_version": 1, "shard_id": sid, "run_seed": base.seed,
                "identities": [ident]}
        ShardSpec.from_json(spec, f"what-if {out.name} {sid}")  # the worker's own checks, before writing
        specs.append((sid, spec))
    summary = {"what_if": note}
    header_out, _ = io.write_plan(out, header, lambda tmp: (io.write_shards(tmp, specs), summary))
    (out / "whatif.json").write_text(json.dumps({**note, "plan_hash": header_out["plan_hash"]}, indent=1))
    io.Plan(out).verify()
    return header_out["plan_hash"]


def changed_subset(before_dir: Path, after_dir: Path, out: Path, check: int = 1, reseed: bool = False) -> dict:
    """The identities whose records differ between two plans of one set (e.g. before and after a
    catalogue change), as a plan of their own (every frame; one identity per shard), plus the
    first ``check`` identities whose records are identical (their frames must come out as in the
    before render: the check that the unchanged frames may be taken from it). The plan header is
    the after plan's. ``reseed``: the control instead: the changed identities as the *before*
    plan has them, rendered with other seeds (:func:`reseeded`; no check identity): what render
    noise alone does to the comparison."""
    b, a = base_identities(before_dir), base_identities(after_dir)
    if sorted(a) != sorted(b):
        raise ValueError("the two plans hold different identities")
    changed = [i for i in sorted(a) if a[i] != b[i]]
    same = [] if reseed else [i for i in sorted(a) if a[i] == b[i]][:check]
    note = {"what": "identities whose records differ" + (", before's records re-seeded" if reseed else ""),
            "before_plan": str(before_dir), "after_plan": str(after_dir), "changed": changed, "unchanged_checked": same}
    rows = [reseeded(b[i]) for i in changed] if reseed else [a[i] for i in sorted(changed + same)]
    h = write_whatif_plan(before_dir if reseed else after_dir, out, rows, note, one_view=False)
    return {**note, "plan_hash": h}


def make_plans(base_dir: Path, work: Path, variants=VARIANTS) -> dict[str, dict]:
    """Every variant's what-if plan under WORK/plans; variant -> {pairs, identities, conflicts, hash}."""
    from synth.assets.catalogue import load_catalogue

    check_base(base_dir)
    ids = base_identities(base_dir)
    keys = sorted(ids)
    cat = load_catalogue()
    out = {}
    for v in variants:
        rows, pairs, conflicts = [], [], {}
        for ka, kb in cycle_pairs(len(keys)):
            a, b = ids[keys[ka]], ids[keys[kb]]
            w = variant_identity(v, a, b)
            if w is None:
                continue
            rows.append(w)
            pairs.append((a["identity_index"], b["identity_index"]))
            c = rule_conflicts(w["assets"], cat)
            if c and c != rule_conflicts(a["assets"], cat):
                conflicts[str(w["identity_index"])] = c
        note = {"variant": v, "base_plan": str(base_dir), "pairs": pairs, "rule_conflicts": conflicts,
                "what": FACTORS[v][0] if v in FACTORS else v}
        h = write_whatif_plan(base_dir, work / "plans" / v, rows, note) if rows else None
        out[v] = {"pairs": pairs, "conflicts": conflicts, "plan_hash": h}
    return out


# --------------------------------------------------------------------------- render and judge


def render(plan: Path, dataset: Path) -> None:
    """``synth render`` of a plan (resumes; a complete dataset renders nothing), one worker
    process for the whole plan (its shards hold one frame each: a worker per two would spend
    more time starting than rendering)."""
    synth = Path(sys.executable).with_name("synth")
    cmd = [str(synth), "render", "-o", str(dataset), "--plan", str(plan), "-q", "--shards-per-worker", "1000"]
    subprocess.run(cmd, check=True)


def judged(dataset: Path, png: Path, judge: Path, python: str) -> dict[str, dict]:
    """frame key -> {"identity", "view", "face" (the largest face, or None)}; the PNGs and the
    judge's JSON are kept (WORK/png, WORK/judge) and reused while they cover every frame."""
    from benchmarks.realism.common import _png
    from synth.dataset.reader import iter_frames

    meta = {}
    png.mkdir(parents=True, exist_ok=True)
    for fr in iter_frames(dataset):
        p = png / f"{fr.key}.png"
        if not p.is_file():
            _png(fr, p)
        meta[fr.key] = (int(fr.meta["identity_index"]), int(fr.meta["view_index"]))
    det = json.loads(judge.read_text())["images"] if judge.is_file() else {}
    if any(f"{k}.png" not in det for k in meta):
        judge.parent.mkdir(parents=True, exist_ok=True)
        det = run_judge(python, judge, [png])["images"]
    return {k: {"identity": i, "view": v, "face": (det[f"{k}.png"]["faces"] or [None])[0]}
            for k, (i, v) in meta.items()}


def embeddings(frames: dict[str, dict], view: int | None = 0) -> dict[int, np.ndarray]:
    """identity -> embedding of its frame at ``view`` (None: every view, (V, 128)); faces not found left out."""
    out: dict[int, list] = {}
    for k in sorted(frames):
        f = frames[k]
        if f["face"] is not None and (view is None or f["view"] == view):
            out.setdefault(f["identity"], []).append(np.asarray(f["face"]["embedding"]))
    return {i: (np.stack(e) if view is None else e[0]) for i, e in out.items()}


# --------------------------------------------------------------------------- analysis


def _d(x, y) -> float:
    return float(np.linalg.norm(np.asarray(x) - np.asarray(y)))


def _stats(v) -> dict:
    v = np.asarray(v, np.float64)
    if not len(v):
        return {"n": 0}
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return {"n": int(len(v)), "median": float(med), "q1": float(q1), "q3": float(q3), "min": float(v.min()),
            "max": float(v.max())}


def corrected_sq(a0, a1, f0, f1) -> float:
    """An estimate of the squared distance between two conditions A and F without the render noise,
    from each rendered with two seeds (0, 1): the mean squared distance across conditions at
    different seeds, less the mean squared distance within a condition across its seeds. With
    independent zero-mean noise per render this is unbiased (each cross term carries the noise of
    two renders, as each within term does); it can come out negative where the true distance is
    below the noise."""
    cross = 0.5 * (_d(a0, f1) ** 2 + _d(a1, f0) ** 2)
    within = 0.5 * (_d(a0, a1) ** 2 + _d(f0, f1) ** 2)
    return float(cross - within)


def _signed_sqrt(x: float) -> float:
    return float(np.sign(x) * np.sqrt(abs(x)))


def analyse(base: dict[int, np.ndarray], variants: dict[str, dict[int, np.ndarray]],
            pairs: list[tuple[int, int]], unchanged: dict[str, set] | None = None) -> dict:
    """The figures from embeddings. ``base``: identity -> (V, 128) (its views); ``variants``:
    variant -> {A's index (B's for ``b_view``) -> (128,) view-0 embedding}; ``pairs``: (A, B);
    ``unchanged``: factor -> the A's it had nothing to swap for (same picks: d_f counts 0).

    Per pair: D = d(A, B at A's view) (``b_view``), and per factor d(A, A with B's factor) (a
    factor that would not change A counts 0: same picks, nothing to swap; a face not found leaves
    the pair out of that factor). Per factor over the pairs: the distances' median and IQR, the
    median of d_f / D, how often d_f alone reaches the threshold, and in how many pairs it is the
    largest. Additivity: d(A, all) / D; sqrt(sum d_f^2) / d(A, all) (1 when the factors move A in
    orthogonal directions); the embedding sum e_A + sum_f (e_f - e_A) against e_all (relative
    residual |pred - e_all| / |e_all - e_A|).

    Noise-corrected (``corrected``, where the second seeds were rendered: ``reseed`` for A and
    ``V+reseed`` for variant V): per pair the signed square root of :func:`corrected_sq` for each
    factor, for ``all`` and for D; their medians and IQRs, the share of D (of the pairs with a
    positive D estimate) and sqrt(sum of the factors' positive squared estimates) / all."""
    v0 = {i: e[0] for i, e in base.items()}
    a1s = variants.get("reseed", {})

    def csq(v: str, a: int, key: int) -> float | None:
        """Noise-corrected squared distance of A to variant v (its embedding under ``key``)."""
        f0, f1 = variants.get(v, {}).get(key), variants.get(f"{v}+reseed", {}).get(key)
        if a not in a1s or f0 is None or f1 is None:
            return None
        return corrected_sq(v0[a], a1s[a], f0, f1)

    c_rows = {f: [] for f in FACTORS}
    c_ratio = {f: [] for f in FACTORS}
    c_D, c_all, c_quad = [], [], []
    rows = {f: [] for f in FACTORS}
    ratio = {f: [] for f in FACTORS}
    largest = {f: 0 for f in FACTORS}
    D, D_set, d_all, quad, resid, all_over_D, rig = [], [], [], [], [], [], []
    for a, b in pairs:
        if a not in v0 or b not in base:
            continue
        D_set.append(float(np.median([_d(x, y) for x in base[a] for y in base[b]])))
        Dab = _d(v0[a], variants["b_view"][b]) if b in variants.get("b_view", {}) else None
        if Dab is not None:
            D.append(Dab)
        cD = csq("b_view", a, b)
        if cD is not None:
            c_D.append(_signed_sqrt(cD))
        c_per = {}
        for f in FACTORS:
            if a in (unchanged or {}).get(f, ()):
                c_per[f] = 0.0
            elif (c := csq(f, a, a)) is not None:
                c_per[f] = c
            else:
                continue
            c_rows[f].append(_signed_sqrt(c_per[f]))
            if cD is not None and cD > 0:
                c_ratio[f].append(_signed_sqrt(c_per[f]) / np.sqrt(cD))
        if (ca := csq("all", a, a)) is not None:
            c_all.append(_signed_sqrt(ca))
            if len(c_per) == len(FACTORS) and ca > 0:
                c_quad.append(float(np.sqrt(sum(max(x, 0.0) for x in c_per.values()) / ca)))
        per = {}
        for f in FACTORS:
            got = variants.get(f, {})
            if a in got:
                per[f] = _d(v0[a], got[a])
            elif a in (unchanged or {}).get(f, ()):
                per[f] = 0.0
            else:
                continue
            rows[f].append(per[f])
            if Dab:
                ratio[f].append(per[f] / Dab)
        if per:
            largest[max(per, key=lambda f: (per[f], f))] += 1
        if a in variants.get("all", {}):
            ea = variants["all"][a]
            da = _d(v0[a], ea)
            d_all.append(da)
            if Dab:
                all_over_D.append(da / Dab)
                rig.append(_d(ea, variants["b_view"][b]))
            if len(per) == len(FACTORS):
                quad.append(float(np.sqrt(sum(x * x for x in per.values()))) / da)
                pred = v0[a] + sum((variants[f][a] - v0[a]) for f in FACTORS if a in variants.get(f, {}))
                resid.append(_d(pred, ea) / da)
    same_view = [_d(e[0], e[1]) for e in base.values() if len(e) > 1]
    noise = [_d(v0[a], e) for a, e in variants.get("reseed", {}).items() if a in v0]
    return {
        "factors": {f: {**_stats(rows[f]), "share_median": _stats(ratio[f]).get("median"),
                        "share_q1": _stats(ratio[f]).get("q1"), "share_q3": _stats(ratio[f]).get("q3"),
                        "alone_over_threshold": int(sum(x >= THRESHOLD for x in rows[f])),
                        "largest_in": largest[f]} for f in FACTORS},
        "pair_distance_same_view": _stats(D), "pair_distance_set_views": _stats(D_set),
        "all_swapped": _stats(d_all), "all_over_pair": _stats(all_over_D), "rig_and_noise": _stats(rig),
        "quadrature_over_all": _stats(quad), "embedding_sum_residual": _stats(resid),
        "same_identity_views": _stats(same_view), "render_noise": _stats(noise),
        "corrected": {"factors": {f: {**_stats(c_rows[f]), "share_median": _stats(c_ratio[f]).get("median"),
                                      "share_q1": _stats(c_ratio[f]).get("q1"),
                                      "share_q3": _stats(c_ratio[f]).get("q3")} for f in FACTORS},
                      "pair_distance_same_view": _stats(c_D), "all_swapped": _stats(c_all),
                      "quadrature_over_all": _stats(c_quad)}}


def real_vs_render(render_emb: np.ndarray, real_emb: np.ndarray) -> dict:
    """How far rendered faces sit from real ones. Distances render-render (different identities),
    real-real and render-real (medians, minima, fraction under the threshold), and the two
    clouds' centroids: their distance against each cloud's spread (median distance of its
    members to its own centroid)."""
    r, p = np.asarray(render_emb, np.float64), np.asarray(real_emb, np.float64)
    rr, pp = pair_distances(r), pair_distances(p)
    rp = np.linalg.norm(r[:, None] - p[None], axis=-1).ravel()
    cr, cp = r.mean(0), p.mean(0)

    def dist(x):
        return {"median": float(np.median(x)), "min": float(x.min()), "max": float(x.max()),
                "under": float((x < THRESHOLD).mean()), "n": int(len(x))}

    return {"render_render": dist(rr), "real_real": dist(pp), "render_real": dist(rp),
            "centroid_distance": _d(cr, cp), "render_spread": float(np.median(np.linalg.norm(r - cr, axis=1))),
            "real_spread": float(np.median(np.linalg.norm(p - cp, axis=1))),
            "real_to_render_centroid": float(np.median(np.linalg.norm(p - cr, axis=1))),
            "render_to_real_centroid": float(np.median(np.linalg.norm(r - cp, axis=1)))}


def real_faces(paths: list, python: str, work: Path, min_score: float = 0.2, face_px: int | None = None) -> np.ndarray:
    """Embeddings of every face with a detector score of at least ``min_score`` in the photos;
    ``face_px``: each such face cropped and scaled so that its detector box is that wide
    (:func:`benchmarks.identity_diversity.face_crops`; a face not found again is left out)."""
    from benchmarks.identity_diversity import face_crops

    (work / "judge").mkdir(parents=True, exist_ok=True)
    det = run_judge(python, work / "judge" / "real.json", paths)["images"]
    kept = [(k, f) for k, v in sorted(det.items()) for f in v["faces"] if f["score"] >= min_score]
    if face_px:
        folder = work / "png" / f"real_{face_px}px"
        folder.mkdir(parents=True, exist_ok=True)
        crops = face_crops(paths, det, kept, face_px, folder)
        small = run_judge(python, work / "judge" / f"real_{face_px}px.json", crops)["images"]
        kept = [(k, small[c.name]["faces"][0]) for (k, _), c in zip(kept, crops) if small[c.name]["faces"]]
    return np.asarray([f["embedding"] for _, f in kept]).reshape(-1, 128)


# --------------------------------------------------------------------------- report


def _r(x, fmt=".3f") -> str:
    return "-" if x is None else format(x, fmt)


def _iqr(s: dict, key: str = "") -> str:
    return f"{_r(s.get(key + 'q1'), '.3f' if not key else '.0%')}-{_r(s.get(key + 'q3'), '.3f' if not key else '.0%')}"


def print_report(res: dict, plans: dict) -> None:
    cor = res.get("corrected", {}).get("factors", {})
    print("\n| factor taken from B | pairs where it differs | d(A, A with it), one seed: median (IQR) | max | "
          "share of D | noise-corrected: median (IQR) | share of corrected D | alone >= 0.6 | largest in |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    key = (lambda f: -(cor[f].get("median") or 0)) if any(c.get("n") for c in cor.values()) \
        else (lambda f: -(res["factors"][f].get("median") or 0))
    for f in sorted(FACTORS, key=key):
        s, c = res["factors"][f], cor.get(f, {"n": 0})
        if not s["n"]:
            continue
        corr = f"{c['median']:.3f} ({_iqr(c)})" if c["n"] else "-"
        cshare = f"{_r(c['share_median'], '.0%')} ({_iqr(c, 'share_')})" if c["n"] else "-"
        print(f"| {f} ({FACTORS[f][0]}) | {len(plans[f]['pairs'])} / {s['n']} | {s['median']:.3f} "
              f"({_iqr(s)}) | {s['max']:.3f} | {_r(s['share_median'], '.0%')} ({_iqr(s, 'share_')}) | {corr} | "
              f"{cshare} | {s['alone_over_threshold']} | {s['largest_in']} |")
    cr = res.get("corrected", {})
    for k, label in (("pair_distance_same_view", "D"), ("all_swapped", "d(A, all)"),
                     ("quadrature_over_all", "sqrt(sum of the factors' d^2) / d(A, all)")):
        if cr.get(k, {}).get("n"):
            s = cr[k]
            print(f"\nnoise-corrected {label}: median {s['median']:.3f} (IQR {_iqr(s)}, n {s['n']})", end="")
    print()
    print("\n| reference | n | median | IQR | min-max |")
    print("|---|---:|---:|---:|---:|")
    names = {"pair_distance_same_view": "D = d(A, B at A's view)",
             "pair_distance_set_views": "d(A, B) at their own views (median of 4 view pairs)",
             "all_swapped": "d(A, A with every factor of B)", "all_over_pair": "d(A, all) / D",
             "rig_and_noise": "d(A with every factor of B, B at A's view): index-seeded rig draws + noise",
             "quadrature_over_all": "sqrt(sum d_f^2) / d(A, all)",
             "embedding_sum_residual": "|e_A + sum(e_f - e_A) - e_all| / d(A, all)",
             "same_identity_views": "same identity, view 0 vs view 1",
             "render_noise": "render noise: A re-rendered with another seed"}
    for k, label in names.items():
        s = res[k]
        if s["n"]:
            print(f"| {label} | {s['n']} | {s['median']:.3f} | {s['q1']:.3f}-{s['q3']:.3f} | "
                  f"{s['min']:.3f}-{s['max']:.3f} |")
    conf = {v: p["conflicts"] for v, p in plans.items() if p["conflicts"]}
    if conf:
        print(f"\nswaps that break a catalogue rule (rendered anyway): {conf}")


def print_real(rv: dict) -> None:
    print("\n| distances | n | median | min | max | under 0.6 |")
    print("|---|---:|---:|---:|---:|---:|")
    for k, label in (("render_render", "render - render (different identities)"),
                     ("real_real", "real - real"), ("render_real", "render - real")):
        s = rv[k]
        print(f"| {label} | {s['n']} | {s['median']:.3f} | {s['min']:.3f} | {s['max']:.3f} | {s['under']:.0%} |")
    print(f"\ncentroids: render-real {rv['centroid_distance']:.3f}; spread (median to own centroid): renders "
          f"{rv['render_spread']:.3f}, real {rv['real_spread']:.3f}; real faces to the renders' centroid "
          f"{rv['real_to_render_centroid']:.3f}, renders to the real centroid {rv['render_to_real_centroid']:.3f}")


# --------------------------------------------------------------------------- CLI


def measure(base_dir: Path, work: Path, plans: dict, python: str) -> tuple[dict, dict]:
    """Render (resuming) and judge the base plan and every variant; the analysis and the embeddings."""
    render(base_dir, work / "renders" / "base")
    base_frames = judged(work / "renders" / "base", work / "png" / "base", work / "judge" / "base.json", python)
    base = embeddings(base_frames, None)
    variants, unchanged = {}, {}
    pairs = plans["b_view"]["pairs"]  # every pair (b_view never leaves one out)
    for v, p in plans.items():
        if p["plan_hash"] is not None:
            render(work / "plans" / v, work / "renders" / v)
            fr = judged(work / "renders" / v, work / "png" / v, work / "judge" / f"{v}.json", python)
            variants[v] = embeddings(fr, 0)
        changed = {a for a, _ in p["pairs"]}
        unchanged[v] = {a for a, _ in pairs if a not in changed}
    return analyse(base, variants, pairs, unchanged), {"base": base, **variants}


def judged_set(path: Path) -> dict[str, tuple[int, int, np.ndarray]]:
    """A dataset's faces from the judge's JSON that ``identity_diversity measure --keep`` wrote:
    frame key -> (identity, expression, embedding of its largest face); frames without a face left out."""
    det = json.loads(Path(path).read_text())["images"]
    return {k[:-4]: (int(k[2:8]), int(k[11:13]), np.asarray(v["faces"][0]["embedding"]))
            for k, v in sorted(det.items()) if v["faces"]}


def filled(before: dict, after: dict, before_plan: Path, after_plan: Path) -> dict:
    """``after`` (the frames of some identities) completed with ``before``'s frames of the other
    identities, refused unless those identities' plan records are identical in the two plans,
    and unless every identity ``after`` holds whose record is identical has exactly ``before``'s
    embeddings (rendering is deterministic here, so a taken frame is the frame a full render
    would give)."""
    b, a = base_identities(before_plan), base_identities(after_plan)
    held = {v[0] for v in after.values()}
    for k, v in after.items():
        if a[v[0]] == b[v[0]] and (k not in before or not np.array_equal(before[k][2], v[2])):
            raise ValueError(f"{k}: identity {v[0]} is planned the same in both, yet its face differs")
    out = dict(after)
    for k, v in before.items():
        if v[0] not in held:
            if a[v[0]] != b[v[0]]:
                raise ValueError(f"identity {v[0]} changed between the plans but is not in the after render")
            out[k] = v
    return dict(sorted(out.items()))


def _median(x) -> float:
    return float(np.median(x)) if len(x) else float("nan")


def compare_sets(before: dict, after: dict) -> dict:
    """Two renders of one set that differ in some identities (``judged_set`` of each): the
    different-identity fraction under the threshold of each, paired over the frames both found;
    which identities changed (any frame whose embedding differs); per different-identity pair
    that involves a changed identity, the distance's change (median) and the pairs crossing the
    threshold either way. Render noise alone moves such figures too: compare against a control
    in which the same identities are only rendered again with other seeds (``subset --reseed``)."""
    keys = sorted(set(before) & set(after))
    ident = np.array([before[k][0] for k in keys])
    eb = np.stack([before[k][2] for k in keys])
    ea = np.stack([after[k][2] for k in keys])
    moved = np.any(eb != ea, axis=1)
    changed = sorted({int(i) for i in ident[moved]})
    diff = ~same_pairs(ident)
    db, da = pair_distances(eb), pair_distances(ea)
    i, j = np.triu_indices(len(keys), 1)
    touch = diff & (np.isin(ident[i], changed) | np.isin(ident[j], changed))
    fb, fa = float((db[diff] < THRESHOLD).mean()), float((da[diff] < THRESHOLD).mean())
    return {"frames": len(keys), "changed_identities": changed, "changed_frames": int(moved.sum()),
            "fraction_before": fb, "fraction_after": fa, "change": fa - fb,
            "median_different_before": float(np.median(db[diff])), "median_different_after": float(np.median(da[diff])),
            "pairs_touched": int(touch.sum()), "median_change_touched": _median(da[touch] - db[touch]),
            "median_before_touched": _median(db[touch]), "median_after_touched": _median(da[touch]),
            "crossed_up": int(((db < THRESHOLD) & (da >= THRESHOLD) & diff).sum()),
            "crossed_down": int(((db >= THRESHOLD) & (da < THRESHOLD) & diff).sum())}


def noisy(img: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """An 8-bit image with Gaussian noise of ``sigma`` (8-bit units) added, rounded and clipped."""
    return np.clip(np.asarray(img, np.float64) + rng.normal(0.0, sigma, np.shape(img)), 0, 255).round().astype(np.uint8)


def jitter(renders: list[Path], real: list, work: Path, python: str, sigmas=(1.0, 2.0, 4.0), face_px: int = 75,
           seed: int = 0) -> dict:
    """How far the judge moves a face when the image gets a little pixel noise: each render PNG and
    each real face (score >= 0.2, cropped and scaled to a ``face_px`` box) against itself with
    Gaussian noise of each ``sigma`` (8-bit units). kind -> sigma -> the distances."""
    from PIL import Image

    from benchmarks.identity_diversity import face_crops

    folder = work / "png" / "jitter"
    folder.mkdir(parents=True, exist_ok=True)
    (work / "judge").mkdir(parents=True, exist_ok=True)
    src = {}
    if real:
        det = run_judge(python, work / "judge" / "real.json", real)["images"]
        kept = [(k, f) for k, v in sorted(det.items()) for f in v["faces"] if f["score"] >= 0.2]
        for c in face_crops(real, det, kept, face_px, folder):
            src[f"real_{c.stem}"] = np.asarray(Image.open(c).convert("RGB"))
    for p in renders:
        src[f"render_{Path(p).stem}"] = np.asarray(Image.open(p).convert("RGB"))
    rng = np.random.default_rng(seed)
    names = []
    for k, a in src.items():
        Image.fromarray(a).save(folder / f"{k}__0.png")
        for s in sigmas:
            Image.fromarray(noisy(a, s, rng)).save(folder / f"{k}__{s:g}.png")
        names.append(k)
    det = run_judge(python, work / "judge" / "jitter.json", [folder])["images"]
    out: dict = {}
    for k in names:
        f0 = det[f"{k}__0.png"]["faces"]
        for s in sigmas:
            f1 = det[f"{k}__{s:g}.png"]["faces"]
            if f0 and f1:
                out.setdefault(k.split("_")[0], {}).setdefault(s, []).append(
                    _d(f0[0]["embedding"], f1[0]["embedding"]))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.identity_factors", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name in ("plan", "run"):
        p = sub.add_parser(name)
        p.add_argument("base", type=Path, help="base plan (see the module docstring)")
        p.add_argument("work", type=Path, help="work folder (plans, renders, PNGs, the judge's JSON)")
        p.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
        if name == "run":
            p.add_argument("--real", nargs="*", default=[], help="real photos (files or folders of PNGs)")
            p.add_argument("--real-face-px", type=int, nargs="*", default=[],
                           help="also with the real faces rescaled to this detector-box width (px)")
            p.add_argument("--judge-python", default=sys.executable)
            p.add_argument("--json", type=Path)
    c = sub.add_parser("compare", help="two renders of one set (the judge's JSON of identity_diversity "
                       "measure --keep): the fraction change, paired, against render noise alone")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--json", type=Path)
    c.add_argument("--fill", nargs=2, type=Path, metavar=("BEFORE_PLAN", "AFTER_PLAN"),
                   help="AFTER holds only some identities (``subset``): take the others' frames from BEFORE, "
                        "after checking that their plan records are identical and that every identity AFTER "
                        "holds with an identical record has the same embeddings in both")
    j = sub.add_parser("jitter", help="the judge's distance between a face and itself with a little pixel noise")
    j.add_argument("work", type=Path)
    j.add_argument("--renders", nargs="*", default=[], type=Path, help="render PNGs")
    j.add_argument("--real", nargs="*", default=[], help="real photos")
    j.add_argument("--sigma", nargs="*", type=float, default=[1.0, 2.0, 4.0])
    j.add_argument("--judge-python", default=sys.executable)
    s2 = sub.add_parser("subset", help="the identities whose records differ between two plans, as a plan")
    s2.add_argument("before_plan", type=Path)
    s2.add_argument("after_plan", type=Path)
    s2.add_argument("out", type=Path)
    s2.add_argument("--check", type=int, default=1, help="unchanged identities to render again as a check")
    s2.add_argument("--reseed", action="store_true",
                    help="the noise control: the changed identities as BEFORE_PLAN has them, with other render seeds")
    args = ap.parse_args(argv)
    if args.cmd == "jitter":
        res = jitter(args.renders, args.real, args.work, args.judge_python, args.sigma)
        print("| faces | noise (8-bit SD) | n | median distance | max |\n|---|---:|---:|---:|---:|")
        for kind, by in res.items():
            for sg, d in by.items():
                print(f"| {kind} | {sg:g} | {len(d)} | {np.median(d):.3f} | {max(d):.3f} |")
        return 0
    if args.cmd == "subset":
        r = changed_subset(args.before_plan, args.after_plan, args.out, args.check, args.reseed)
        print(f"{len(r['changed'])} changed identities {r['changed']}, checked {r['unchanged_checked']}: "
              f"plan {r['plan_hash'][:16]} at {args.out}")
        return 0
    if args.cmd == "compare":
        before, after = judged_set(args.before), judged_set(args.after)
        if args.fill:
            after = filled(before, after, *args.fill)
        r = compare_sets(before, after)
        print(f"frames found in both: {r['frames']}; changed identities {len(r['changed_identities'])} "
              f"({r['changed_frames']} frames): {r['changed_identities']}")
        print(f"different-identity pairs under {THRESHOLD}: {r['fraction_before']:.1%} -> {r['fraction_after']:.1%} "
              f"({100 * r['change']:+.1f} points); crossed up {r['crossed_up']}, down {r['crossed_down']}")
        print(f"median different-identity distance {r['median_different_before']:.3f} -> "
              f"{r['median_different_after']:.3f}")
        print(f"pairs with a changed identity: {r['pairs_touched']}, median distance {r['median_before_touched']:.3f}"
              f" -> {r['median_after_touched']:.3f} (median change {r['median_change_touched']:+.3f})")
        if args.json:
            args.json.write_text(json.dumps(r, indent=1))
        return 0
    variants = list(dict.fromkeys([*args.variants, "shape", "b_view"]))  # the pairs and D need these two
    plans = make_plans(args.base, args.work, variants)
    for v, p in plans.items():
        print(f"{v}: {len(p['pairs'])} what-if identities, plan {str(p['plan_hash'])[:12]}"
              + (f"; rule conflicts {p['conflicts']}" if p["conflicts"] else ""))
    if args.cmd == "plan":
        return 0
    res, emb = measure(args.base, args.work, plans, args.judge_python)
    print_report(res, plans)
    out = {"analysis": res, "plans": plans}
    if args.real:
        base = emb["base"]
        render_v0 = np.stack([base[i][0] for i in sorted(base)])
        real = real_faces(args.real, args.judge_python, args.work)
        out["real"] = real_vs_render(render_v0, real)
        print_real(out["real"])
        for px in args.real_face_px:
            out[f"real_{px}px"] = real_vs_render(render_v0, real_faces(args.real, args.judge_python, args.work,
                                                                       face_px=px))
            print(f"\nreal faces {px} px wide:")
            print_real(out[f"real_{px}px"])
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    from benchmarks.runner import run_cli

    run_cli(main)
