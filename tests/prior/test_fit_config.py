"""prior.fit.config: presets, TOML and --set overrides (synth.configkit), validation,
the saved form and the docs table."""

from __future__ import annotations

from pathlib import Path

import pytest

from prior.fit import config as fc
from synth.errors import SynthError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "prior.md"


def test_presets_and_override_order(tmp_path):
    small, paper = fc.preset("small"), fc.preset("paper")
    assert paper.inversion.steps == 1500 and paper.inversion.patches * paper.inversion.patch_size ** 2 == 4096
    assert paper.finetune.steps == 50_000 and paper.finetune.rays_per_step == 4096
    assert paper.finetune.lr_init == 2e-3 and paper.finetune.lr_final == 2e-5 and paper.finetune.grad_clip == 1e-3
    assert small.finetune.steps < paper.finetune.steps
    f = tmp_path / "c.toml"
    f.write_text('[fit]\nseed = 4\n[finetune]\nsteps = 7\nnormal_weight = 0.0\n[inversion]\nlpips_net = "alex"\n')
    cfg = fc.load("small", f, ["finetune.steps=9", "fit.seed=5", "landmarks.per_image_expression=false"])
    assert cfg.finetune.steps == 9 and cfg.finetune.normal_weight == 0.0 and cfg.inversion.lpips_net == "alex"
    assert cfg.fit.seed == 5 and cfg.landmarks.per_image_expression is False
    assert fc.from_dict(cfg.to_dict(), "saved") == cfg


@pytest.mark.parametrize("sets, match", [
    (["finetune.stepz=3"], "did you mean 'finetune.steps'"),
    (["finetun.steps=3"], "did you mean 'finetune'"),
    (["finetune.steps=3.5"], "not an integer"),
    (["fit.seed=-1"], "fit.seed"),
    (["inversion.lpips_net=squeeze"], "lpips_net"),
    (["inversion.lr_init=1e-4"], "inversion.lr_final = 0.001 exceeds"),
    (["inversion.lr_final=1.0"], "inversion.lr_final"),
    (["finetune.normal_weight=-1"], "finetune.normal_weight"),
    (["inversion.patch_size=4"], "patch_size"),
    (["landmarks.sigma_px=0"], "sigma_px"),
    (["steps=3"], "bad override"),
])
def test_bad_values_are_one_line_errors(sets, match):
    with pytest.raises(SynthError, match=match) as e:
        fc.load("small", None, sets)
    assert "\n" not in str(e.value)


def test_unknown_preset():
    with pytest.raises(SynthError, match="unknown preset"):
        fc.preset("huge")


def test_every_key_is_documented():
    text = DOCS.read_text()
    for line in fc.reference().splitlines()[2:]:
        key = line.split("|")[1].strip()
        assert key in text, f"{key} missing from docs/prior.md (regenerate with prior.fit.config.reference())"


def test_overrides_are_checked_together():
    """Every --set is applied before the rules between fields: lowering lr_init below the current
    lr_final and then lr_final is fine in either order."""
    for sets in (["inversion.lr_init=1e-4", "inversion.lr_final=1e-5"],
                 ["inversion.lr_final=1e-5", "inversion.lr_init=1e-4"]):
        cfg = fc.load("small", None, sets)
        assert (cfg.inversion.lr_init, cfg.inversion.lr_final) == (1e-4, 1e-5)
