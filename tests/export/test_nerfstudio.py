"""``synth export nerfstudio`` against nerfstudio's documented camera model (not installed):
the oracle in tests/support/export_oracles.py, from docs.nerf.studio "Data conventions".
Images are read back with PIL, as nerfstudio reads them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from synth.errors import SynthError
from synth.export.nerfstudio import export_nerfstudio
from tests.support.datasets import GREY, marked_dataset, marked_pixels
from tests.support.export_oracles import ns_project, ns_ray, ns_split, ns_value


def test_oracle_projection_inverts_its_rays():
    meta = {"fl_x": 50.0, "fl_y": 52.0, "cx": 20.3, "cy": 14.1}
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    R *= np.linalg.det(R)
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = R, [0.1, -0.4, 0.2]
    frame = {"transform_matrix": c2w.tolist()}
    o, d = ns_ray(meta, frame, 7, 11)
    uv, depth = ns_project(meta, frame, (o + 0.8 * d)[None])
    assert np.allclose(uv, [[7.5, 11.5]]) and depth[0] > 0


# ----------------------------------------------------------------------------- the export


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = tmp_path_factory.mktemp("ns")
    ds = marked_dataset(root / "ds")
    out = root / "ns"
    summary = export_nerfstudio(ds, out, val_views=0)  # scenes of one view: no split
    return ds, out, summary


def _frames(ds: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(ds.glob("shards/*/*.json")) if p.name != "manifest.json"}


def test_landmarks_reproject_onto_the_exported_pixels(exported):
    """Every covered pixel of an exported image is the pixel that nerfstudio's camera model puts
    the landmark that covered it into, within 0.5 px of its centre; depth and colour agree."""
    ds, out, _ = exported
    meta = json.loads((out / "transforms.json").read_text())
    src = _frames(ds)
    assert len(meta["frames"]) == len(src) == 5
    for fr in meta["frames"]:
        fj = src[fr["synth_key"]]
        img = np.asarray(Image.open(out / fr["file_path"]))
        mask = np.asarray(Image.open(out / fr["mask_path"]))
        depth = np.asarray(Image.open(out / fr["depth_file_path"])).astype(np.float64) * 1e-3
        assert img.shape == (ns_value(meta, fr, "h"), ns_value(meta, fr, "w"), 4) and img.dtype == np.uint8
        assert mask.shape == img.shape[:2] and depth.shape == img.shape[:2]
        marks = marked_pixels(fj)
        X = np.asarray(fj["landmarks_3d"])[[i for i, _, _ in marks]]
        uv, z = ns_project(meta, fr, X)
        got = {(int(c), int(r)) for r, c in zip(*np.nonzero(img[..., 3]))}
        assert got == {(c, r) for _, c, r in marks}
        assert got == {(int(c), int(r)) for r, c in zip(*np.nonzero(mask))}
        for (_, c, r), (u, v), zi in zip(marks, uv, z):
            assert max(abs(u - (c + 0.5)), abs(v - (r + 0.5))) < 0.5  # inside the covered pixel
            assert abs(depth[r, c] - zi) <= 0.5e-3 + 1e-9  # planar depth, millimetres
            assert tuple(img[r, c]) == (128, 128, 128, 255)
        # and the same projection as the frame's own landmarks_2d, to float precision
        assert np.abs(ns_project(meta, fr, np.asarray(fj["landmarks_3d"]))[0]
                      - np.asarray(fj["landmarks_2d"])).max() < 1e-6
        assert depth[img[..., 3] == 0].max() == 0.0  # no surface: 0


def test_per_frame_intrinsics_and_shared_size(exported):
    _, out, summary = exported
    meta = json.loads((out / "transforms.json").read_text())
    assert meta["camera_model"] == "OPENCV" and (meta["w"], meta["h"]) == (48, 36)
    # principal points differ per frame: each frame has its own; the focal length is shared
    assert "cx" not in meta and all("cx" in f and "cy" in f for f in meta["frames"])
    assert "fl_x" in meta and not any("fl_x" in f for f in meta["frames"])
    assert summary["frames"] == 5 and summary["scenes"] == [[0, 0], [0, 1], [1, 0]]
    for f in meta["frames"]:
        c2w = np.asarray(f["transform_matrix"])
        assert np.allclose(c2w[:3, :3] @ c2w[:3, :3].T, np.eye(3)) and np.allclose(c2w[3], [0, 0, 0, 1])


def test_straight_alpha_and_srgb(tmp_path):
    from synth.dataset.reader import Frame
    from synth.export.nerfstudio import colour_png, depth_png, mask_png
    import io

    rgba = np.zeros((2, 3, 4), np.float32)
    rgba[0, 0] = (GREY * 0.5, 0.0, 1.0 * 0.5, 0.5)  # premultiplied by alpha 0.5
    rgba[0, 1] = (4.0, 0.0, 0.0, 1.0)  # over-range colour clips to 255
    depth = np.array([[1.2344, 0.0001, 70.0], [0, 0, 0]], np.float32)
    fr = Frame("id000000_ex00_v00", {}, rgba, depth, np.zeros((2, 3, 3), np.float32), np.zeros((2, 3), np.uint32))
    img = np.asarray(Image.open(io.BytesIO(colour_png(fr))))
    assert tuple(img[0, 0]) == (128, 0, 255, 128) and tuple(img[0, 1]) == (255, 0, 0, 255)
    assert tuple(img[1, 0]) == (0, 0, 0, 0)
    assert np.asarray(Image.open(io.BytesIO(mask_png(fr)))).tolist() == [[255, 255, 0], [0, 0, 0]]
    with pytest.raises(SynthError, match="16-bit"):
        depth_png(fr, "here")
    depth[0, 2] = 2.0
    d = np.asarray(Image.open(io.BytesIO(depth_png(fr, "here"))))
    assert d.dtype == np.uint16 and d[0].tolist() == [1234, 1, 2000] and d[1].tolist() == [0, 0, 0]


def test_selection_and_refusals(exported, tmp_path):
    ds, out, _ = exported
    s = export_nerfstudio(ds, tmp_path / "one", identity=0, expression=0)
    assert s["frames"] == 3 and s["scenes"] == [[0, 0]]
    with pytest.raises(SynthError, match="no committed frames of identity 5"):
        export_nerfstudio(ds, tmp_path / "none", identity=5)
    assert not (tmp_path / "none").exists()
    with pytest.raises(SynthError, match="not empty"):
        export_nerfstudio(ds, out)


def test_cli_one_line_error_and_json(exported, tmp_path):
    ds, out, _ = exported
    cmd = [sys.executable, "-m", "synth.cli.main", "export", "nerfstudio"]
    p = subprocess.run([*cmd, str(ds), "--out", str(out)], capture_output=True, text=True)
    assert p.returncode == 2 and p.stderr.startswith("synth: error: nerfstudio output directory is not empty")
    assert len(p.stderr.strip().splitlines()) == 1
    p = subprocess.run([*cmd, str(ds), "--out", str(tmp_path / "j"), "-i", "1", "--val-views", "0", "--json"],
                       capture_output=True, text=True, check=True)
    assert json.loads(p.stdout)["scenes"] == [[1, 0]]


# ----------------------------------------------------------------------------- the split


def test_split_gives_nerfstudio_a_validation_set(tmp_path):
    """Read as nerfstudio's dataparser reads transforms.json (tests/support/export_oracles.py):
    without a split, 6 views give 6 training and no validation image; the export's split holds
    out the highest view indices for val and test (the prior's data.holdout_views picks them with
    the same function, synth.dataset.layout.held_out; tests/prior/test_data.py checks its split)."""
    ds = marked_dataset(tmp_path / "ds", views=6)
    export_nerfstudio(ds, tmp_path / "none", identity=0, expression=0, val_views=0)
    meta = json.loads((tmp_path / "none" / "transforms.json").read_text())
    assert len(ns_split(meta, "train")) == 6 and ns_split(meta, "val") == []  # what nerfstudio did before

    for n in (1, 2):
        s = export_nerfstudio(ds, tmp_path / f"v{n}", identity=0, expression=0, val_views=n)
        meta = json.loads((tmp_path / f"v{n}" / "transforms.json").read_text())
        train, val, test = (ns_split(meta, k) for k in ("train", "val", "test"))
        want = [f"images/id000000_ex00_v{v:02d}.png" for v in range(6 - n, 6)]
        assert val == test == want and s["val"] == [p[7:-4] for p in want]
        assert len(train) == 6 - n and not set(train) & set(val)
        assert all((tmp_path / f"v{n}" / p).is_file() for p in train + val)


def test_split_refuses_scenes_without_enough_views(tmp_path):
    ds = marked_dataset(tmp_path / "ds")  # (0, 1) and (1, 0) have one view each
    with pytest.raises(SynthError, match=r"identity 0 expression 1 has 1 view\(s\), not more than --val-views = 1"):
        export_nerfstudio(ds, tmp_path / "ns")
    assert not (tmp_path / "ns").exists()
    s = export_nerfstudio(ds, tmp_path / "ns", val_views=0)
    assert s["val"] == [] and "val_filenames" not in json.loads((tmp_path / "ns" / "transforms.json").read_text())
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", "export", "nerfstudio", str(ds), "--out",
                        str(tmp_path / "cli"), "-i", "0", "-e", "0", "--val-views", "2"],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "(2 held out for val/test)" in p.stdout
