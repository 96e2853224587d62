"""The typed configuration: paper defaults, TOML + --set overrides, one-line refusals."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import pytest

from synth.cli.main import main
from synth.config import RENDER_PRESETS, Config, explain, load_config, markdown, to_toml
from synth.errors import SynthError

DOCS = Path(__file__).resolve().parents[1] / "docs" / "config.md"


def test_defaults_mirror_the_paper():
    c = Config()
    assert c.dataset.expressions_per_identity == 13
    assert c.dataset.views_per_expression == 30
    assert c.camera.min_separation_deg == 25.0
    # one environment for every identity, soft ("chosen to minimize shadows on the face")
    assert c.lighting.environment == "studio" and c.lighting.studio_rotation_deg == (0.0, 0.0)
    assert c.lighting.hdri_files == ()
    assert c.render.preset == "preview" and c.dataset.identities_per_shard == 1


def test_render_presets_resolve_and_can_be_overridden():
    r = load_config().resolved().render
    assert r.resolution == (256, 256) and r.samples == 16 and r.denoise is True
    ci = load_config(overrides=["render.preset=ci"]).resolved().render
    assert (ci.resolution, ci.samples) == ((64, 64), 4) and ci.samples <= 4
    prod = load_config(overrides=["render.preset=production", "render.samples=64"]).resolved().render
    assert prod.resolution == (512, 512) and prod.adaptive_sampling and prod.denoise and prod.samples == 64
    assert set(RENDER_PRESETS) == {"ci", "preview", "production", "production-max"}
    pmax = load_config(overrides=["render.preset=production-max"]).resolved().render
    assert (pmax.samples, pmax.adaptive_threshold, pmax.path_guiding) == (256, 0.01, None)
    assert prod.path_guiding is True


def test_light_path_settings_are_recorded_only_when_set():
    """A plan header leaves the light-path and denoiser settings out while they are unset (plans made
    before they existed keep their hash and render with Cycles' own values); set, they are recorded."""
    from synth.plan.planner import header_config
    from synth.plan.records import RenderSettings

    plain = header_config(load_config(overrides=["render.preset=production-max"]).resolved())["render"]
    assert not {"diffuse_bounces", "hair_shape", "light_tree", "denoise_quality"} & set(plain)
    assert RenderSettings.from_json(plain).transparent_bounces == 8
    cfg = load_config(overrides=["render.preset=production-max", "render.diffuse_bounces=2", "render.hair_shape=thick",
                                 "render.light_tree=false", "render.denoise_prefilter=fast"])
    rec = header_config(cfg.resolved())["render"]
    assert (rec["diffuse_bounces"], rec["hair_shape"], rec["light_tree"], rec["denoise_prefilter"]) == (
        2, "thick", False, "fast")
    s = RenderSettings.from_json(rec)
    assert (s.diffuse_bounces, s.glossy_bounces, s.hair_shape, s.light_tree) == (2, 4, "thick", False)
    with pytest.raises(SynthError, match="render.hair_shape"):
        load_config(overrides=["render.hair_shape=cubes"])


def test_toml_then_overrides(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('[camera]\nfov_deg = 30\nazimuth_deg = [-90, 90]\n[dataset]\nviews_per_expression = 12\n')
    c = load_config(f, ["camera.fov_deg=40", "lighting.environment=uniform", "expression.presets=['smile']"])
    assert c.camera.fov_deg == 40.0 and c.camera.azimuth_deg == (-90.0, 90.0)
    assert c.dataset.views_per_expression == 12 and c.expression.presets == ("smile",)
    assert c.fov_deg == 40.0
    assert abs(Config().fov_deg - 23.9) < 0.1  # 85 mm on a 36 mm sensor


def test_round_trip_through_toml(tmp_path):
    c = load_config(overrides=["camera.roll_deg=[-5, 5]", "render.preset=ci", "identity.max_mahalanobis=4"])
    f = tmp_path / "r.toml"
    f.write_text(to_toml(c.resolved()))
    assert load_config(f) == c.resolved()


@pytest.mark.parametrize("text, key", [
    ("[camera]\nfovv_deg = 3\n", "camera.fovv_deg"),
    ("[cameras]\nfov_deg = 3\n", "cameras"),
    ("[camera]\nmin_separation_deg = 200\n", "camera.min_separation_deg"),
    ("[camera]\nelevation_deg = [-100, 10]\n", "camera.elevation_deg"),
    ("[camera]\nradius_m = [2.0, 1.0]\n", "camera.radius_m"),
    ("[camera]\nelevation_sampling = 'cube'\n", "camera.elevation_sampling"),
    ("[dataset]\nviews_per_expression = 2.5\n", "dataset.views_per_expression"),
    ("[dataset]\nseed = -1\n", "dataset.seed"),
    ("[render]\ndenoise = 1\n", "render.denoise"),
    ("[camera]\nnear_m = 2.0\n", "camera.near_m"),
    ("[lighting]\nenvironment = 'hdri'\n", "lighting.hdri_files"),
    ("[expression]\npresets = ['grin']\n", "expression.presets"),
    ("[assets]\ndisabled_classes = ['shoes']\n", "assets.disabled_classes"),
])
def test_bad_files_are_refused_naming_the_key(tmp_path, text, key):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(SynthError) as e:
        load_config(f)
    msg = str(e.value)
    assert key in msg and "\n" not in msg and str(f) in msg


def test_bad_overrides_are_refused():
    for item, key in (("camera.nope=1", "camera.nope"), ("camera.fov_deg=500", "camera.fov_deg"),
                      ("nosection", "nosection"), ("render.resolution=[64]", "render.resolution")):
        with pytest.raises(SynthError) as e:
            load_config(overrides=[item])
        assert key in str(e.value) and "--set" in str(e.value)


def test_every_field_is_documented_and_docs_are_in_sync():
    rows = explain()
    n_fields = sum(len(dataclasses.fields(getattr(Config(), f.name))) for f in dataclasses.fields(Config))
    assert len(rows) == n_fields
    assert all(doc for _, _, _, doc in rows)
    text = DOCS.read_text()
    for key, *_ in rows:
        assert f"`{key}`" in text, f"docs/config.md lacks {key}: regenerate it (see its first lines)"
    assert markdown() in text, "docs/config.md's table is stale: regenerate it (see its first lines)"


def test_cli_config_show(tmp_path, capsys):
    assert main(["config", "show", "--set", "camera.fov_deg=30"]) == 0
    out = capsys.readouterr().out
    data = tomllib.loads(out)
    assert data["camera"]["fov_deg"] == 30.0 and data["render"]["resolution"] == [256, 256]
    f = tmp_path / "c.toml"
    f.write_text("[dataset]\nexpressions_per_identity = 3\n")
    assert main(["config", "show", "--config", str(f)]) == 0
    assert tomllib.loads(capsys.readouterr().out)["dataset"]["expressions_per_identity"] == 3
    assert main(["config", "show", "--explain"]) == 0
    assert "camera.min_separation_deg" in capsys.readouterr().out


def test_cli_config_errors_are_one_line(tmp_path, capsys):
    assert main(["config", "show", "--set", "camera.min_separation_deg=-3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera.min_separation_deg" in err[0] and "out of range" in err[0]
    assert main(["config", "show", "--config", str(tmp_path / "missing.toml")]) == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.parametrize("order", [1, -1])
def test_override_order_does_not_matter(order):
    """Every override is applied before the rules between keys are checked (issue 15, item 4)."""
    sets = ['lighting.environment="hdri"', 'lighting.hdri_files=["studio.exr", "sky.exr"]',
            "camera.radius_m=[0.02, 0.03]", "camera.near_m=0.01"][::order]
    c = load_config(None, sets)
    assert c.lighting.environment == "hdri" and c.lighting.hdri_files == ("studio.exr", "sky.exr")
    assert c.camera.near_m == 0.01 and c.camera.radius_m == (0.02, 0.03)
    assert main(["config", "show", *(a for s in sets for a in ("--set", s))]) == 0


def test_an_override_may_repair_the_file(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text("[lighting]\nenvironment = 'hdri'\n")
    assert load_config(f, ["lighting.hdri_files=['a.exr']"]).lighting.hdri_files == ("a.exr",)


def test_an_invalid_final_state_is_one_line(capsys):
    sets = ["lighting.hdri_files=['a.exr']", 'lighting.environment="hdri"', "lighting.hdri_files=[]"]
    assert main(["config", "show", *(a for s in sets for a in ("--set", s))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lighting.hdri_files is empty but lighting.environment = 'hdri'" in err[0]


def test_config_file_that_is_not_utf8_is_one_line(tmp_path, capsys):
    f = tmp_path / "c.toml"
    f.write_bytes(b"[camera]\nfov_deg = 30 # \xe9\n")
    assert main(["config", "show", "--config", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not UTF-8" in err[0] and str(f) in err[0]
