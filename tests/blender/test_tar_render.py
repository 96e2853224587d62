"""A real `ci` render with `--set dataset.shard_format=tar`: the tar shard validates, previews,
resumes as complete, and gives the same frames through the reader and through
`webdataset.WebDataset` as a `dir` render of the same seed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bpy")

pytestmark = [pytest.mark.blender, pytest.mark.slow]

ARGS = ["render", "--identities", 1, "--expressions", 1, "--views", 2, "--preset", "ci", "--seed", 11, "-q"]


def synth(*args) -> subprocess.CompletedProcess:
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, f"synth {args} -> {p.returncode}\n{p.stdout}\n{p.stderr}"
    return p


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("tar_render")
    synth(*ARGS, "--out", root / "dir")
    synth(*ARGS, "--set", "dataset.shard_format=tar", "--out", root / "tar")
    return root / "dir", root / "tar"


def test_tar_render_matches_the_dir_render(renders):
    from synth.dataset.reader import iter_frames

    d, t = renders
    assert sorted(os.listdir(t / "shards")) == ["shard_000000.tar", "shard_000000.tar.json"]
    synth("validate", t)
    a, b = list(iter_frames(d)), list(iter_frames(t, validate=True))
    assert [f.key for f in a] == [f.key for f in b] and len(a) == 2
    for x, y in zip(a, b):
        assert (x.shard, x.width, x.height) == (y.shard, 64, 64)
        for name in ("rgba", "depth", "normals", "segmentation"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name), err_msg=f"{x.key} {name}")
        np.testing.assert_array_equal(x.K, y.K)
        np.testing.assert_array_equal(x.world_to_camera, y.world_to_camera)


def test_webdataset_streams_the_rendered_tar(renders):
    wds = pytest.importorskip("webdataset")
    from synth.dataset.reader import decode_sample, iter_frames

    _, t = renders
    got = list(wds.WebDataset(str(t / "shards" / "shard_000000.tar"), shardshuffle=False).map(decode_sample))
    want = list(iter_frames(t))
    assert [f.key for f in got] == [f.key for f in want] and [f.shard for f in got] == ["shard_000000"] * 2
    for x, y in zip(got, want):
        np.testing.assert_array_equal(x.rgba, y.rgba)
        assert x.meta == y.meta


def test_tar_render_previews_and_resumes_as_complete(renders, tmp_path):
    _, t = renders
    before = (t / "shards" / "shard_000000.tar").read_bytes()
    synth("preview", t, "-o", tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 1000
    p = synth(*ARGS, "--set", "dataset.shard_format=tar", "--out", t)  # a rerun: nothing left to render
    assert (t / "shards" / "shard_000000.tar").read_bytes() == before, p.stdout
