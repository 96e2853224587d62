"""``synth export cafca`` read by a loader written from the Cafca release's own description
(syntec-research/Cafca: Dataset.md and its notebook's ``load_example``), not by synth's reader:
``SUBJECT/EXP_ENV/{cameras_json,color_image,foreground_mask,segmentation}/Cvv.{json,png}``,
5-digit subject and expression, 3-digit environment, OpenCV cameras whose ``P`` projects,
masks read as /255, 16-bit segmentation, ``environment.json`` in ``color_image``."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from synth.errors import SynthError
from synth.export.cafca import export_cafca
from tests.support.datasets import marked_dataset, marked_pixels

pytest.importorskip("OpenEXR")


def load_example(base: Path, subject: str, expression: str, environment: str, camera: str) -> dict:
    """As the release's notebook loads a scene (with PIL in place of mediapy)."""
    d = base / subject / f"{expression}_{environment}"
    return {"rgb": np.asarray(Image.open(d / "color_image" / f"{camera}.png")),
            "segmentation": Image.open(d / "segmentation" / f"{camera}.png"),
            "foreground_mask": np.asarray(Image.open(d / "foreground_mask" / f"{camera}.png")).astype(float) / 255.0,
            "camera": json.loads((d / "cameras_json" / f"{camera}.json").read_text())}


def scenes(base: Path) -> list[tuple[str, str, str]]:
    out = []
    for s in sorted(p for p in base.iterdir() if p.is_dir()):
        assert re.fullmatch(r"\d{5}", s.name), s
        for e in sorted(s.iterdir()):
            m = re.fullmatch(r"(\d{5})_(\d{3})", e.name)
            assert m and sorted(x.name for x in e.iterdir()) == ["cameras_json", "color_image", "foreground_mask",
                                                                  "segmentation"], e
            assert (e / "color_image" / "environment.json").is_file()
            out.append((s.name, m[1], m[2]))
    return out


def test_a_loader_written_for_the_release_reads_the_export(tmp_path):
    ds = marked_dataset(tmp_path / "ds")
    s = export_cafca(ds, tmp_path / "cafca")
    base = tmp_path / "cafca"
    assert scenes(base) == [("00000", "00000", "000"), ("00000", "00001", "000"), ("00001", "00000", "000")]
    assert s["frames"] == 5
    frames = {p.stem: json.loads(p.read_text()) for p in ds.glob("shards/*/*.json") if p.name != "manifest.json"}
    for key, fj in frames.items():
        i, e, v = (int(x) for x in re.fullmatch(r"id(\d+)_ex(\d+)_v(\d+)", key).groups())
        ex = load_example(base, f"{i:05d}", f"{e:05d}", "000", f"C{v:02d}")
        cam = ex["camera"]
        K, w2c, c2w, P = (np.asarray(cam[k]) for k in ("K", "world2cam", "cam2world", "P"))
        assert np.allclose(P, K @ w2c[:3]) and np.allclose(c2w @ w2c, np.eye(4))
        R = np.asarray(cam["orientation"])
        assert np.allclose(np.asarray(cam["position"]), c2w[:3, 3]) and np.allclose(R @ R.T, np.eye(3))
        # OpenCV: +z of the camera (orientation's third row) points from the camera at the scene
        X = np.asarray(fj["landmarks_3d"])
        uvw = (P @ np.c_[X, np.ones(len(X))].T).T
        assert (uvw[:, 2] > 0).all() and np.allclose(uvw[:, 2], (X - c2w[:3, 3]) @ R[2])
        assert np.abs(uvw[:, :2] / uvw[:, 2:] - np.asarray(fj["landmarks_2d"])).max() < 1e-6
        rgb, mask, seg = ex["rgb"], ex["foreground_mask"], ex["segmentation"]
        assert rgb.shape == (cam["height"], cam["width"], 3) and rgb.dtype == np.uint8
        assert seg.mode.startswith("I") and np.asarray(seg).dtype in (np.int32, np.uint16, np.int64)
        for _, c, r in marked_pixels(fj):
            assert tuple(rgb[r, c]) == (128, 128, 128) and mask[r, c] == 1.0 and np.asarray(seg)[r, c] == 1
        assert mask.sum() == len(marked_pixels(fj)) and rgb[mask == 0].max() == 0


def test_refusals_leave_nothing_and_cli_json(tmp_path):
    ds = marked_dataset(tmp_path / "ds")
    with pytest.raises(SynthError, match="no committed frames of identity 7"):
        export_cafca(ds, tmp_path / "x", identity=7)
    assert not (tmp_path / "x").exists()
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", "export", "cafca", str(ds), "--out",
                        str(tmp_path / "c"), "-i", "1", "--json"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["scenes"] == ["00001/00000_000"]
