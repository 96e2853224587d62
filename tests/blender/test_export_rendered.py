"""The exports on a real `ci` render: nerfstudio's camera model puts the visible landmarks onto
covered pixels at the rendered depth, USD cameras project the head mesh's landmarks onto
landmarks_2d, and the shell assets (garment, headwear, glasses) are rebuilt as rendered.

The catalogue is a copy with glasses and headwear always present and hair disabled (so the
rules let headwear in), so every rebuildable class is exercised by one small render.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

from tests.support.export_oracles import check_stage, ns_project  # noqa: E402


def synth(*args) -> subprocess.CompletedProcess:
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, f"synth {args} -> {p.returncode}\n{p.stdout}\n{p.stderr}"
    return p


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    from synth.assets.catalogue import default_manifest_dir

    root = tmp_path_factory.mktemp("export_ci")
    cat = root / "catalogue"
    shutil.copytree(default_manifest_dir(), cat)
    for cls in ("glasses", "headwear"):
        p = cat / f"{cls}.toml"
        p.write_text(re.sub(r"(?m)^presence = .*$", "presence = 1.0", p.read_text()))
    out = root / "ds"
    synth("render", "--identities", 1, "--expressions", 2, "--views", 3, "--preset", "ci", "--out", out, "-q",
          "--set", f"assets.manifest_dir={cat}", "--set", 'assets.disabled_classes=["hair"]')
    return out


def _frames(ds: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(ds.glob("shards/*/*.json")) if p.name != "manifest.json"}


def test_nerfstudio_on_a_render(rendered, tmp_path):
    from PIL import Image

    synth("export", "nerfstudio", rendered, "--out", tmp_path / "ns", "--identity", 0, "--expression", 1)
    meta = json.loads((tmp_path / "ns" / "transforms.json").read_text())
    frames = _frames(rendered)
    assert len(meta["frames"]) == 3
    n_visible = 0
    for fr in meta["frames"]:
        fj = frames[fr["synth_key"]]
        X = np.asarray(fj["landmarks_3d"])
        uv, z = ns_project(meta, fr, X)
        assert np.abs(uv - np.asarray(fj["landmarks_2d"])).max() < 0.5  # measured: ~1e-6 px
        mask = np.asarray(Image.open(tmp_path / "ns" / fr["mask_path"]))
        depth = np.asarray(Image.open(tmp_path / "ns" / fr["depth_file_path"])).astype(np.float64) * 1e-3
        for (u, v), zi, vis in zip(uv, z, fj["landmarks_visible"]):
            if not vis:
                continue
            n_visible += 1
            c, r = int(np.floor(u)), int(np.floor(v))
            assert mask[r, c] == 255  # visible landmarks lie on the head in the exported mask
            # and the exported depth there (3x3, as labels.visibility decides) is the landmark's
            d = depth[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
            assert np.abs(d[d > 0] - zi).min() <= max(0.004, 0.01 * zi) + 0.0005
    assert n_visible >= 30


def test_usd_on_a_render(rendered, tmp_path):
    pytest.importorskip("pxr", reason="usd-core is not installed (the `export` extra)")
    from pxr import Usd, UsdGeom

    from synth.plan.io import load_plan

    out = tmp_path / "scene.usdc"
    s = json.loads(synth("export", "usd", rendered, "--out", out, "--json").stdout)
    frames = _frames(rendered)
    stage = Usd.Stage.Open(str(out))
    data = load_plan(rendered / "plan").model_data()
    assert check_stage(stage, frames, data) < 0.01  # measured: ~1e-5 px
    ident = s["identities"][0]
    gid = frames["id000000_ex00_v00"]["assets"]["garment"]["id"]
    assert sorted(ident["assets"]) == ["garment_" + gid, "garment_" + gid + "_torso",
                                       "glasses_frame", "glasses_lenses",
                                       "headwear_" + frames["id000000_ex00_v00"]["assets"]["headwear"]["id"]]
    rec = frames["id000000_ex00_v00"]["assets"]
    for cls in ("garment", "headwear"):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/id000000/assets/{cls}_{rec[cls]['id']}"))
        for t in (0, 1):
            assert len(mesh.GetPointsAttr().Get(t)) == rec[cls]["build"]["vertices"]
            assert len(mesh.GetFaceVertexCountsAttr().Get(t)) == rec[cls]["build"]["faces"]
    torso = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/id000000/assets/garment_{gid}_torso"))
    assert len(torso.GetPointsAttr().Get(0)) == rec["garment"]["build"]["torso_vertices"]
    assert "eyebrows" in ident["skipped"] and "glasses" not in ident["skipped"]
