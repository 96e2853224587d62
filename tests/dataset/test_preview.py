"""``synth preview``: a contact sheet of a shard (rows: expressions, columns: views)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from tests.support import fake_frames as ff
from synth.cli.main import main
from synth.appearance.srgb import linear_to_srgb, srgb_to_linear
from synth.dataset.preview import colour_tile, contact_sheet, depth_tile, seg_tile
from synth.errors import SynthError
from synth.dataset.segmentation import PALETTE
from synth.dataset.shards import open_dataset

Image = pytest.importorskip("PIL.Image")
pytest.importorskip("OpenEXR")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("prev") / "ds"
    ds = open_dataset(root, "b" * 64, ff.plan(2, 3, 4))
    ff.render_dataset(ds, shards=["shard_000001"])
    return root


def test_default_sheet_layout(dataset, tmp_path):
    out = contact_sheet(dataset, out=tmp_path / "a.png", tile=20)
    im = Image.open(out)
    assert im.mode == "RGB"
    w, h = im.size
    # 4 views x (3 tiles of 20 px + 2 gaps) and 3 expressions x 20 px, plus labels and padding
    assert w == 44 + 4 * (3 * 20 + 4 + 8) + 8 and h == 32 + 3 * (20 + 8) + 8
    a = np.asarray(im)
    # the segmentation tile of the first cell shows skin and hair colours from the palette
    seg = a[32:52, 44 + 22:44 + 42].reshape(-1, 3)
    colours = {tuple(c) for c in seg}
    assert PALETTE[1] in colours and PALETTE[5] in colours and PALETTE[0] in colours


def test_cli_default_output_and_options(dataset, capsys):
    rc = main(["preview", str(dataset), "--shard", "shard_000001", "--max-views", "2", "--tile", "16"])
    out = capsys.readouterr().out.strip()
    assert rc == 0 and out == str(dataset / "preview_shard_000001.png")
    assert Image.open(out).size[0] == 44 + 2 * (3 * 16 + 4 + 8) + 8
    assert not [n for n in os.listdir(dataset) if n.endswith(".tmp")]


def test_errors(dataset, tmp_path, capsys):
    with pytest.raises(SynthError, match="shard_000000 is not committed"):
        contact_sheet(dataset, "shard_000000")
    empty = tmp_path / "empty"
    open_dataset(empty, "c" * 64, ff.plan(1))
    with pytest.raises(SynthError, match="no committed shard"):
        contact_sheet(empty)
    assert main(["preview", str(tmp_path / "missing")]) == 2
    assert "dataset directory not found" in capsys.readouterr().err


def test_unreadable_frame_gets_a_red_tile(dataset, tmp_path):
    import shutil

    root = tmp_path / "ds"
    shutil.copytree(dataset, root)
    p = root / "shards" / "shard_000001" / "id000001_ex00_v00.exr"
    os.chmod(p, 0o644)
    p.write_bytes(b"garbage")
    a = np.asarray(Image.open(contact_sheet(root, tile=10)))
    assert tuple(a[32 + 5, 44 + 5]) == (160, 0, 0)


def test_tile_helpers():
    x = np.linspace(0, 1, 11)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    rgba = np.zeros((2, 2, 4), np.float16)
    rgba[0, 0] = [1, 1, 1, 1]
    c = colour_tile(rgba)
    assert tuple(c[0, 0]) == (255, 255, 255) and tuple(c[1, 1]) == (128, 128, 128)  # over mid grey
    s = seg_tile(np.array([[0, 1], [11, 500]], np.uint32))
    assert tuple(s[0, 1]) == PALETTE[1] and tuple(s[1, 1]) == (255, 255, 255)  # unknown: white
    d = depth_tile(np.array([[1.0, 2.0], [0.0, 1.5]], np.float32), np.array([[1, 1], [0, 1]], np.float32))
    assert d[0, 0, 0] == 255 and d[1, 0, 0] == 0 and d[0, 1, 0] < d[1, 1, 0] < d[0, 0, 0]


def test_overview_sheet_one_block_per_committed_shard(tmp_path):
    from synth.dataset.preview import overview_sheet

    root = tmp_path / "ds"
    ds = open_dataset(root, "c" * 64, ff.plan(3, 2, 4))
    ff.render_dataset(ds, shards=["shard_000000", "shard_000002"])
    out = overview_sheet(root, tmp_path / "o.png", views=2, tile=20, columns=2)
    im = np.asarray(Image.open(out))
    # 2 blocks side by side, each 2 views x (2 tiles of 20 + gap + pad), one block row
    assert im.shape[1] == 8 + 2 * (2 * (2 * 20 + 2 + 8) + 8) and im.shape[0] == 8 + (14 + 20 + 8)
    # second block's first segmentation tile shows the palette's skin colour
    x = 8 + (2 * (2 * 20 + 2 + 8) + 8) + 22
    colours = {tuple(c) for c in im[8 + 14:8 + 34, x:x + 20].reshape(-1, 3)}
    assert PALETTE[1] in colours
    assert main(["preview", str(root), "--overview", "--shard", "shard_000000"]) == 2
