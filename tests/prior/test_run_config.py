"""prior.train.config: presets, TOML and --set overrides, validation, the saved form, the docs table."""

from __future__ import annotations

from pathlib import Path

import pytest

from prior.train import config as rc
from synth.errors import SynthError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "prior.md"


def test_presets_and_override_order(tmp_path):
    small, paper = rc.preset("small"), rc.preset("paper")
    assert paper.rays_per_step == 256 * 8 * 64 and small.rays_per_step == 2 * 4 * 128
    assert paper.model.nerf_width == 1024 and paper.sampling.samples_per_level == (128, 128, 128)
    f = tmp_path / "c.toml"
    f.write_text('[train]\nsteps = 7\nlr_init = 1e-3\n[sampling]\nproposal_samples = [8, 4]\n[data]\njoints = ["jaw"]\n')
    cfg = rc.load("small", f, ["train.steps=9", "train.background=[1, 1, 1]", "model.latent_dim=8"])
    assert cfg.train.steps == 9 and cfg.train.lr_init == 1e-3 and cfg.sampling.proposal_samples == (8, 4)
    assert cfg.train.background == (1.0, 1.0, 1.0) and cfg.model.latent_dim == 8 and cfg.data.joints == ("jaw",)
    assert rc.from_dict(cfg.to_dict(), "saved") == cfg  # the saved form round-trips
    import tomllib

    assert rc.from_dict(tomllib.loads(rc.to_toml(cfg)), "toml") == cfg


@pytest.mark.parametrize("sets, match", [
    (["train.stepz=3"], "did you mean 'train.steps'"),
    (["trian.steps=3"], "did you mean 'train'"),
    (["train.steps=3.5"], "not an integer"),
    (["train.steps=true"], "not an integer"),
    (["train.lr_init=nan"], "finite number"),
    (["train.background=[1, 2]"], "list of 3"),
    (["train.compile=1"], "true or false"),
    (["train.bf16=1"], "choose one of false, true, auto"),
    (["train.bf16=yes"], "choose one of false, true, auto"),
    (["steps=3"], "bad override"),
    (["train.steps=0"], "train.steps = 0 must be >= 1"),
    (["train.lr_final=1.0"], "lr_final"),
    (["train.grad_accum=3"], "does not divide train.identities_per_batch"),
    (["data.pixel_dtype=float64"], "pixel_dtype"),
    (["model.skip_layer=9"], "skip_layer"),
    (["sampling.nerf_samples=1"], "nerf_samples = 1 must be >= 2"),
    (["sampling.proposal_samples=[8, 1]"], "proposal_samples = 1 must be >= 2"),
    (["train.adam_beta1=1.0"], r"adam_beta1 = 1.0 is out of range \[0.0, 1.0\)"),
    (["data.joints=['jaw', 'jaw']"], "lists a joint twice"),
])
def test_bad_values_are_one_line_errors(sets, match):
    with pytest.raises(SynthError, match=match) as e:
        rc.load("small", None, sets)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("order", [1, -1])
def test_override_order_does_not_matter(order):
    """Each state along the way may break a rule between keys; only the final one is judged."""
    sets = ["train.lr_final=0.01", "train.lr_init=0.1", "train.identities_per_batch=6", "train.grad_accum=3",
            "model.skip_layer=5", "model.nerf_depth=6"][::order]
    cfg = rc.load("small", None, sets)
    assert (cfg.train.lr_init, cfg.train.lr_final, cfg.train.grad_accum) == (0.1, 0.01, 3)
    assert (cfg.model.skip_layer, cfg.model.nerf_depth) == (5, 6)
    with pytest.raises(SynthError, match=r"lr_final = 0.5 exceeds train.lr_init = 0.1 \(--set\)"):
        rc.load("small", None, [*sets, "train.lr_final=0.5"])


def test_seeds_are_bounded_like_every_seed_of_the_project():
    assert rc.load("small", None, [f"model.init_seed={2**64 - 1}", f"train.seed={2**64 - 1}"]).train.seed == 2**64 - 1
    for key in ("model.init_seed", "train.seed"):
        with pytest.raises(SynthError, match=rf"{key} = {2**64} is out of range"):
            rc.load("small", None, [f"{key}={2**64}"])


def test_model_configs_refuse_bad_sizes_as_value_errors():
    from prior.config import ModelConfig, SamplingConfig

    with pytest.raises(ValueError, match="model.nerf_width = 0 must be >= 1"):
        ModelConfig(nerf_width=0).validate()
    with pytest.raises(ValueError, match="must lie below model.nerf_depth"):
        ModelConfig(skip_layer=8).validate()
    with pytest.raises(ValueError, match="sampling.nerf_samples = 1 must be >= 2"):
        SamplingConfig(nerf_samples=1).validate()


def test_errors_in_files_and_presets(tmp_path):
    with pytest.raises(SynthError, match="unknown preset"):
        rc.preset("huge")
    with pytest.raises(SynthError, match="not found"):
        rc.load("small", tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[train\n")
    with pytest.raises(SynthError, match="not valid TOML"):
        rc.load("small", bad)
    bad.write_text("train = 3\n")
    with pytest.raises(SynthError, match="must be a table"):
        rc.load("small", bad)
    bad.write_bytes(b"[train]\nsteps = 3 # \xe9\n")
    with pytest.raises(SynthError, match="not UTF-8"):
        rc.load("small", bad)
    with pytest.raises(SynthError, match="not found"):
        rc.load("small", tmp_path)  # a directory


def test_resume_may_change_only_train():
    cfg = rc.preset("small")
    assert rc.with_sets(cfg, ["train.steps=11"], allowed=("train",)).train.steps == 11
    with pytest.raises(SynthError, match=r"cannot change \[model\]"):
        rc.with_sets(cfg, ["model.nerf_width=8"], allowed=("train",))


def test_docs_list_every_key():
    text = DOCS.read_text(encoding="utf-8")
    for line in rc.reference().splitlines()[2:]:
        assert line.split("|")[1].strip() in text, line
    assert rc.reference() in text, "docs/prior.md's config table is stale: regenerate it"
