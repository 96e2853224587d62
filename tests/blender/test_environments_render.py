"""A render of two lighting environments per expression (`--environments 2`, `ci`: 64x64, 4 spp;
1 identity, 1 expression, 2 views): it validates, each frame's JSON says its environment and
lighting, the same view differs between the environments only in light, and the Cafca export
writes EXP_ENV 000 and 001 with their environment.json."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

from tests.support.farm_helpers import synth  # noqa: E402


def test_two_environments_render_validate_and_export(tmp_path):
    from PIL import Image

    from synth.dataset.reader import list_frames

    out = tmp_path / "ds"
    synth("render", "--identities", 1, "--expressions", 1, "--views", 2, "--environments", 2, "--preset", "ci",
          "--seed", "3", "--out", out, "-q")
    synth("validate", out)
    frames = {r.key: r.read() for r in list_frames(out)}
    assert sorted(frames) == ["id000000_ex00_en00_v00", "id000000_ex00_en00_v01", "id000000_ex00_en01_v00",
                              "id000000_ex00_en01_v01"]
    for key, f in frames.items():
        assert f.environment_index == int(key[16:18]) and f.meta["environment_index"] == f.environment_index
    a, b = frames["id000000_ex00_en00_v01"], frames["id000000_ex00_en01_v01"]
    la, lb = a.meta["lighting"], b.meta["lighting"]
    assert la["environment"] == lb["environment"] == "studio"
    assert la["rotation_deg"] == 0.0 and lb["rotation_deg"] != 0.0  # the fixed studio; one turned at random
    assert a.meta["camera"] == b.meta["camera"] and a.meta["seed"] == b.meta["seed"]
    assert np.array_equal(a.segmentation, b.segmentation)  # the same scene and view ...
    assert np.abs(a.rgb_premultiplied - b.rgb_premultiplied).max() > 0.02  # ... in another light

    synth("export", "cafca", out, "--out", tmp_path / "cafca")
    scene = tmp_path / "cafca" / "00000"
    assert sorted(p.name for p in scene.iterdir()) == ["00000_000", "00000_001"]
    envs = [json.loads((scene / f"00000_{k:03d}" / "color_image" / "environment.json").read_text()) for k in (0, 1)]
    assert [e["environment_index"] for e in envs] == [0, 1]
    assert envs[0]["synth_lighting"] == a.meta["lighting"] and envs[1]["synth_lighting"] == b.meta["lighting"]
    for k in (0, 1):
        d = scene / f"00000_{k:03d}"
        assert sorted(p.name for p in (d / "color_image").glob("C*.png")) == ["C00.png", "C01.png"]
        cam = json.loads((d / "cameras_json" / "C01.json").read_text())
        assert np.allclose(cam["world2cam"], a.world_to_camera)
    c0, c1 = (np.asarray(Image.open(scene / f"00000_{k:03d}" / "color_image" / "C01.png")) for k in (0, 1))
    assert c0.shape == (64, 64, 3) and not np.array_equal(c0, c1)


def test_a_resume_inside_the_second_environment_gives_the_same_bytes(tmp_path):
    """Staged: both views of environment 0 and view 0 of environment 1 (what a kill leaves);
    the rerun lights the scene with environment 1 before its last view, as the one-go run did."""
    import shutil

    from renderer_jobs.submit import prepare_plan
    from synth.dataset.shards import open_dataset
    from synth.plan.io import load_plan
    from tests.support.farm_helpers import compare

    args = ["--identities", 1, "--expressions", 1, "--views", 2, "--environments", 2, "--preset", "ci", "--seed", 3]
    one_go = tmp_path / "one_go"
    synth("render", *args, "--out", one_go, "-q")
    out = tmp_path / "ds"
    pdir = prepare_plan(out, 1, None, ["dataset.expressions_per_identity=1", "dataset.views_per_expression=2",
                                       "dataset.environments_per_expression=2", 'render.preset="ci"'], 3, None)
    plan = load_plan(pdir)
    ds = open_dataset(out, plan.plan_hash, plan.expected())
    dst = ds.staging_dir("shard_000000")
    dst.mkdir(parents=True, exist_ok=True)
    for k in ds.expected["shard_000000"][:3]:
        for ext in ("exr", "json"):
            shutil.copyfile(one_go / "shards" / "shard_000000" / f"{k}.{ext}", dst / f"{k}.{ext}")
    p = synth("render", *args, "--out", out, "-q")
    assert "rendered 1 now" in p.stdout
    rc, text = compare(one_go, out)
    assert rc == 0, text
