"""Counter-based seeds, the ban on global RNGs and wall-clock seeds (synth/, blender_scripts/,
renderer_jobs/, prior/), and plan determinism (byte-identical files, independence of order,
workers and shard size)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth import seeds
from synth.config import load_config
from synth.plan import planner
from synth.plan.io import load_plan
from tests.support.toy_model import write_toy_model

SYNTH = Path(__file__).resolve().parents[1] / "synth"
U64 = st.integers(0, 2**64 - 1)

# --------------------------------------------------------------------------- the ban

ALLOWED_NP_RANDOM = r"(?:Generator|Philox|PCG64|PCG64DXSM|SFC64|MT19937|SeedSequence|BitGenerator|default_rng)\b"
BANNED = [
    (re.compile(r"^\s*(?:import\s+random\b|from\s+random\s+import\b)", re.M), "stdlib random module"),
    (re.compile(r"(?<![\w.])random\.(?:random|randint|randrange|choice|choices|shuffle|seed|uniform|gauss|sample)\("),
     "stdlib random function"),
    (re.compile(r"\b(?:np|numpy)\.random\.(?!" + ALLOWED_NP_RANDOM + r")\w+"), "global numpy RNG"),
    (re.compile(r"\b(?:default_rng|SeedSequence|Philox|PCG64|RandomState)\(\s*\)"), "OS-entropy seeding"),
    (re.compile(r"(?:default_rng|SeedSequence|Philox|PCG64|Generator|\bseed|\bkey|entropy)\w*\s*[(=][^\n]*"
                r"\b(?:time\.time|time_ns|perf_counter|monotonic|datetime\.now|utcnow|os\.urandom|uuid\d?\()"),
     "wall-clock or OS seed"),
]


def violations(text: str) -> list[str]:
    out = []
    for rx, what in BANNED:
        for m in rx.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            out.append(f"line {line}: {what}: {m.group(0).strip()[:60]}")
    return out


@pytest.mark.parametrize("snippet", [
    "import random\n", "from random import shuffle\n", "x = random.random()\n", "np.random.seed(3)\n",
    "a = np.random.rand(3)\n", "rng = numpy.random.RandomState(1)\n", "g = np.random.default_rng()\n",
    "rng = default_rng(int(time.time()))\n", "seed = time.time_ns()\n", "ss = SeedSequence()\n",
    "key = hash(datetime.now())\n",
])
def test_the_ban_catches(snippet):
    assert violations(snippet)


@pytest.mark.parametrize("snippet", [
    "rng = np.random.default_rng(SEED)\n", "np.random.Generator(np.random.Philox(key=[1, 2]))\n",
    "def f(rng: np.random.Generator): rng.random()\n", "t0 = time.time()\n", "self.random_words = 3\n",
    "created = datetime.now(timezone.utc)\n",
])
def test_the_ban_allows(snippet):
    assert not violations(snippet)


@pytest.mark.parametrize("package", ["synth", "blender_scripts", "renderer_jobs", "prior"])
def test_no_global_rng_or_wall_clock_seed(package):
    files = sorted((SYNTH.parent / package).rglob("*.py"))
    assert files, package
    bad = {str(p.relative_to(SYNTH.parent)): v for p in files if (v := violations(p.read_text(encoding="utf-8")))}
    assert not bad, f"global RNG / wall-clock seeding in {package}/: {bad}"


# --------------------------------------------------------------------------- seeds

@settings(max_examples=60, deadline=None)
@given(seed=U64, stream=U64, c=st.lists(U64, min_size=3, max_size=3))
def test_vectorised_philox_equals_numpy(seed, stream, c):
    ref = np.random.Philox(counter=np.array([0, *c], np.uint64), key=np.array([seed, stream], np.uint64))
    want = ref.random_raw(8)
    got = seeds.philox4x64(np.array([1, 2], np.uint64), c[0], c[1], c[2], seed, stream).ravel()
    assert np.array_equal(want, got)


@settings(max_examples=30, deadline=None)
@given(seed=U64, i=st.integers(0, 10**6), e=st.integers(-1, 99), v=st.integers(-1, 99))
def test_generator_and_uniforms_agree(seed, i, e, v):
    g = seeds.generator(seed, seeds.Stream.EXPRESSION, i, e, v)
    assert np.array_equal(g.random(7), seeds.uniforms(seed, seeds.Stream.EXPRESSION, i, e, v, n=7))


def test_frame_seeds_are_pure_and_in_range():
    i, e, v = np.meshgrid(np.arange(20), np.arange(13), np.arange(30), indexing="ij")
    s = seeds.frame_seeds(7, i, e, v)
    assert s.min() >= 0 and s.max() < 2**31 and len(np.unique(s)) == s.size
    assert seeds.frame_seed(7, 3, 4, 5) == s[3, 4, 5]
    assert seeds.frame_seed(8, 3, 4, 5) != s[3, 4, 5]
    raw = seeds.generator(7, seeds.Stream.FRAME, 3, 4, 5).bit_generator.random_raw()
    assert int(raw) >> 33 == s[3, 4, 5]
    with pytest.raises(ValueError):
        seeds.check_seed(-1)


# --------------------------------------------------------------------------- plans

@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return write_toy_model(tmp_path_factory.mktemp("model") / "toy.npz")


def _files(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def _frames(d: Path) -> dict[str, dict]:
    out = {}
    plan = load_plan(d)
    for sid in plan.shard_ids():
        for ident in plan.shard(sid)["identities"]:
            for e in ident["expressions"]:
                for f in e["frames"]:
                    out[f["frame_id"]] = (ident["identity_code"], ident["assets"], e["expression_code"],
                                          e["joint_rotations"], f)
    return out


def test_same_seed_byte_identical_other_seed_different(tmp_path, toy):
    cfg = load_config(overrides=["dataset.expressions_per_identity=3", "dataset.views_per_expression=6"])
    a = planner.run_plan(cfg, 4, tmp_path / "a", seed=11, model_path=toy, jobs=1)[0]
    b = planner.run_plan(cfg, 4, tmp_path / "b", seed=11, model_path=toy, jobs=2)[0]
    c = planner.run_plan(cfg, 4, tmp_path / "c", seed=12, model_path=toy, jobs=1)[0]
    fa, fb, fc = _files(tmp_path / "a"), _files(tmp_path / "b"), _files(tmp_path / "c")
    assert fa == fb and a["plan_hash"] == b["plan_hash"]
    assert a["plan_hash"] != c["plan_hash"]
    assert all(fa[k] != fc[k] for k in fa if k.startswith("shards/"))


def test_replanning_alone_and_shard_size_change_nothing(tmp_path, toy):
    base = ["dataset.expressions_per_identity=2", "dataset.views_per_expression=5"]
    full = planner.run_plan(load_config(overrides=base), 6, tmp_path / "full", seed=3, model_path=toy, jobs=2)
    one = planner.run_plan(load_config(overrides=base), 1, tmp_path / "one", seed=3, first_identity=4,
                           model_path=toy, jobs=1)
    big = planner.run_plan(load_config(overrides=base + ["dataset.identities_per_shard=3"]), 6,
                           tmp_path / "big", seed=3, model_path=toy, jobs=1)
    assert len(full[0]["shards"]) == 6 and len(big[0]["shards"]) == 2 and one[0]["shards"][0]["shard_id"] == \
        "shard_000004"
    ff, fo, fbig = _frames(tmp_path / "full"), _frames(tmp_path / "one"), _frames(tmp_path / "big")
    assert ff == fbig
    assert fo and all(ff[k] == v for k, v in fo.items())
    # the single-identity shard file is byte-identical to the same shard of the full plan
    assert (tmp_path / "one/shards/shard_000004.json").read_bytes() == \
        (tmp_path / "full/shards/shard_000004.json").read_bytes()


def test_a_single_frame_can_be_replanned_alone(tmp_path, toy):
    from synth.assets.catalogue import load_catalogue
    from synth.plan.planner import model_record

    cfg = load_config(overrides=["dataset.expressions_per_identity=3", "dataset.views_per_expression=4"])
    planner.run_plan(cfg, 3, tmp_path / "p", seed=21, model_path=toy)
    want = _frames(tmp_path / "p")["id000002_ex01_v03"][-1]
    got = planner.replan_frame(cfg, model_record(toy)[0], load_catalogue(), 21, 2, 1, 3)
    assert got == want


def test_identity_data_is_independent_of_the_number_of_expressions(tmp_path, toy):
    """Identity codes, assets and the views of expression e do not move when more expressions are planned."""
    a = planner.run_plan(load_config(overrides=["dataset.expressions_per_identity=2"]), 2, tmp_path / "a",
                         seed=5, model_path=toy)
    b = planner.run_plan(load_config(overrides=["dataset.expressions_per_identity=4"]), 2, tmp_path / "b",
                         seed=5, model_path=toy)
    assert a and b
    sa = load_plan(tmp_path / "a").shard("shard_000001")["identities"][0]
    sb = load_plan(tmp_path / "b").shard("shard_000001")["identities"][0]
    assert sa["identity_code"] == sb["identity_code"] and sa["assets"] == sb["assets"]
    assert orjson.dumps(sa["expressions"]) == orjson.dumps(sb["expressions"][:2])
