"""End to end: `synth render` at the `ci` preset into a sharded dataset, then validate.

Covers: layers/sizes/schema, camera truth from the files alone (JSON K/world_to_camera vs
landmarks_2d vs EXR depth and alpha), determinism of the frame JSON, refusal of a different
plan in the same directory, and resume after a kill -9 in the middle of a shard.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

SYNTH = [sys.executable, "-m", "synth.cli.main"]


def synth(*args, check=True, **kw) -> subprocess.CompletedProcess:
    p = subprocess.run([*SYNTH, *map(str, args)], capture_output=True, text=True, **kw)
    if check and p.returncode != 0:
        raise AssertionError(f"synth {' '.join(map(str, args))} -> {p.returncode}\n{p.stdout}\n{p.stderr}")
    return p


def frames(root: Path) -> dict[str, Path]:
    return {p.stem: p for p in sorted(root.glob("shards/*/*.json")) if p.name != "manifest.json"}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("e2e") / "ds"
    synth("render", "--identities", 1, "--expressions", 2, "--views", 3, "--preset", "ci", "--out", out, "-q")
    return out


def test_render_validates_with_expected_layers_and_sizes(rendered):
    from synth.assets.classes import CLASSES, RECORD_ORDER
    from synth.dataset.exr import CHANNELS, read_frame_exr
    from synth.dataset.frame_json import validate_frame_json
    from synth.dataset.layout import frame_key

    synth("validate", rendered)
    fr = frames(rendered)
    assert sorted(fr) == [frame_key(0, e, v) for e in range(2) for v in range(3)]
    for key, jp in fr.items():
        fj = json.loads(jp.read_text())
        assert validate_frame_json(fj) == [], jp
        assert fj["image"]["layers"] == list(CHANNELS)
        assert (fj["image"]["width"], fj["image"]["height"]) == (64, 64)
        assert fj["render"]["samples"] <= 4 and fj["render"]["preset"] == "ci"
        assert list(fj["assets"]) == list(RECORD_ORDER)
        ex = read_frame_exr(jp.with_suffix(".exr"))
        assert ex["rgba"].shape == (64, 64, 4) and ex["rgba"].dtype == np.float16
        assert ex["depth"].dtype == np.float32 and ex["segmentation"].dtype == np.uint32
        a = ex["rgba"][..., 3].astype(np.float32)
        assert 0.02 < (a > 0.5).mean() < 0.95, "head should cover part of the image"
        assert np.isfinite(ex["rgba"].astype(np.float32)).all()
        # segmentation: background exactly where alpha is zero, skin present
        seg = ex["segmentation"]
        assert (seg[a <= 0.0] == 0).all() and (seg == 1).any()
    # every chosen asset was built (its record is in the JSON) and the large ones are rendered
    # into their own segmentation IDs
    fj = json.loads(next(iter(fr.values())).read_text())
    seen = set()
    for jp in fr.values():
        seen |= set(np.unique(read_frame_exr(jp.with_suffix(".exr"))["segmentation"]).tolist())
    thin = ("eyebrows", "eyelashes")  # may cover no pixel centre at 64 px
    for cls, entry in fj["assets"].items():
        if entry is None:
            continue
        assert isinstance(entry.get("build"), dict) and entry["id"], cls
        if not CLASSES[cls].shader_layer and cls not in thin:
            assert CLASSES[cls].segmentation_id in seen, f"{cls} ({entry['id']}) not in the segmentation"
    assert fj["assets"]["hair"] is not None and fj["assets"]["garment"] is not None
    synth("preview", rendered, "-o", rendered / "sheet.png")
    assert (rendered / "sheet.png").stat().st_size > 1000


def test_camera_truth_from_files(rendered):
    """Landmarks projected with the JSON's K and world_to_camera land within 0.5 px of its 2D
    landmarks; at visible ones the EXR depth matches the landmark's camera z, and alpha > 0.5."""
    from synth.dataset.exr import read_frame_exr

    n_visible = 0
    for key, jp in frames(rendered).items():
        fj = json.loads(jp.read_text())
        K = np.asarray(fj["camera"]["K"], np.float64)
        w2c = np.asarray(fj["camera"]["world_to_camera"], np.float64)
        c2w = np.asarray(fj["camera"]["camera_to_world"], np.float64)
        np.testing.assert_allclose(w2c @ c2w, np.eye(4), atol=1e-6)
        X = np.asarray(fj["landmarks_3d"], np.float64)
        Xc = X @ w2c[:3, :3].T + w2c[:3, 3]
        uv = (Xc @ K.T)[:, :2] / Xc[:, 2:3]
        assert np.abs(uv - np.asarray(fj["landmarks_2d"])).max() < 0.5
        ex = read_frame_exr(jp.with_suffix(".exr"))
        vis = np.asarray(fj["landmarks_visible"], bool)
        H, W = ex["depth"].shape
        for i in np.nonzero(vis)[0]:
            c, r = int(np.floor(uv[i, 0])), int(np.floor(uv[i, 1]))
            assert float(ex["rgba"][r, c, 3]) > 0.5
            win = ex["depth"][max(0, r - 1):r + 2, max(0, c - 1):c + 2]
            win = win[win > 0]
            assert np.min(np.abs(win - Xc[i, 2])) <= max(0.004, 0.01 * Xc[i, 2]), (key, i)
        n_visible += int(vis.sum())
    assert n_visible > 50, "some landmarks must be visible over six views"


def test_frame_json_is_deterministic(rendered, tmp_path):
    out = tmp_path / "again"
    synth("render", "--identities", 1, "--expressions", 2, "--views", 3, "--preset", "ci", "--out", out, "-q")
    a, b = frames(rendered), frames(out)
    assert sorted(a) == sorted(b)
    for k in a:
        assert a[k].read_bytes() == b[k].read_bytes(), f"{k}.json differs between two runs"


def test_rerun_resumes_and_different_plan_is_refused(rendered):
    before = {k: p.stat().st_mtime_ns for k, p in frames(rendered).items()}
    p = synth("render", "--identities", 1, "--expressions", 2, "--views", 3, "--preset", "ci", "--out", rendered, "-q")
    assert "rendered 0 now" in p.stdout
    assert {k: p.stat().st_mtime_ns for k, p in frames(rendered).items()} == before
    bad = synth("render", "--identities", 1, "--expressions", 2, "--views", 3, "--preset", "ci", "--seed", 7,
                "--out", rendered, check=False)
    assert bad.returncode == 2
    assert "different plan" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    assert {k: p.stat().st_mtime_ns for k, p in frames(rendered).items()} == before


def test_kill_mid_shard_then_resume(tmp_path):
    """kill -9 the whole render (CLI and worker) once a few frames of the shard are staged; the
    rerun keeps those frames (not re-rendered), finishes, and the dataset validates with every
    frame present exactly once."""
    out = tmp_path / "ds"
    args = ["render", "--identities", 1, "--expressions", 3, "--views", 8, "--preset", "ci", "--out", out, "-q"]
    proc = subprocess.Popen([*SYNTH, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    staging = out / ".staging"
    deadline = time.time() + 120
    staged: list[Path] = []
    while time.time() < deadline and proc.poll() is None:
        staged = sorted(staging.glob("*/id*.json")) if staging.is_dir() else []
        if len(staged) >= 3:
            break
        time.sleep(0.005)
    assert proc.poll() is None, "the render finished before it could be killed"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert len(staged) >= 3, "the render should have staged frames before the kill"
    assert not list(out.glob("shards/*/manifest.json")), "the shard must not be committed before the kill"
    kept = {p.stem: p.with_suffix(".exr").stat().st_mtime_ns for p in sorted(staging.glob("*/id*.json"))}
    assert kept
    synth(*args)
    synth("validate", out)
    fr = frames(out)
    assert len(fr) == 24 and len(set(fr)) == 24
    exrs = sorted(out.glob("shards/*/*.exr"))
    assert len(exrs) == 24
    for k, mt in kept.items():
        assert fr[k].with_suffix(".exr").stat().st_mtime_ns == mt, f"{k} was rendered again after the resume"
    man = json.loads(next(out.glob("shards/*/manifest.json")).read_text())
    assert sorted(man["frames"]) == sorted(fr)
