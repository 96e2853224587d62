"""benchmarks/render_cost.py: the study's frames are the cases it names, and its crops lie where it says."""

from __future__ import annotations

import argparse
import json

import numpy as np

from tests.support.scripts import load_script

rc = load_script("benchmarks/render_cost.py", "render_cost")


def test_crop_windows_cover_the_eyes_and_the_top_of_the_head():
    h = w = 512
    alpha = np.zeros((h, w))
    yy, xx = np.mgrid[0:h, 0:w]
    alpha[(xx - 256) ** 2 / 150 ** 2 + (yy - 300) ** 2 / 200 ** 2 <= 1] = 1.0  # a head, top at row 100
    lm = np.zeros((68, 2))
    lm[:, 0], lm[:, 1] = 256, 330
    lm[36:42] = [[200, 250]] * 6  # eyes
    lm[42:48] = [[312, 250]] * 6
    lm[17:27] = [[256, 225]] * 10  # brows
    win = rc.crop_windows(lm.tolist(), alpha)
    for x0, y0, x1, y1 in win.values():
        assert (x1 - x0, y1 - y0) == (128, 128) and 0 <= x0 and x1 <= w and 0 <= y0 and y1 <= h
    x0, y0, x1, y1 = win["eyes"]
    assert x0 <= 200 and 312 <= x1 and y0 <= 225 and 250 <= y1  # both eyes and the brows
    x0, y0, x1, y1 = win["hairline"]
    assert y0 < 100 < y1 and alpha[y0:y1, x0:x1].min() == 0 and alpha[y0:y1, x0:x1].max() == 1  # the outline
    small = rc.crop_windows(lm.tolist(), alpha[::8, ::8])  # scaled with the resolution, never under 16 px
    assert all(x1 - x0 == 16 for x0, _, x1, _ in small.values())


def test_pick_finds_every_case_with_an_open_expression(tmp_path):
    args = argparse.Namespace(work=str(tmp_path), preset="ci", expressions=13, views=3, candidates=120, seed=11)
    rc.pick(args)
    meta = json.loads((tmp_path / "frames.json").read_text())
    names = [f["name"] for f in meta["frames"]]
    assert names == [f"{c}_{t}" for c in rc.CASES for t in ("neutral", "open")]
    assert len({f["shard"] for f in meta["frames"]}) == len(rc.CASES)  # one identity per case
    for f in meta["frames"]:
        if f["name"].endswith("_open"):
            assert f["jaw"] >= rc.OPEN_JAW
    bare = [f for f in meta["frames"] if f["case"] == "bare"][0]
    assert not {"hair", "beard", "glasses", "headwear"} & set(bare["assets"])
    rc.pick(args)  # a second run keeps the first's choice
    assert json.loads((tmp_path / "frames.json").read_text()) == meta


def test_reference_noise_is_taken_out_of_the_error():
    rng = np.random.default_rng(0)
    truth = np.concatenate([rng.uniform(0.2, 0.8, (256, 256, 3)), np.ones((256, 256, 1))], -1)
    noise = lambda s: np.concatenate([rng.normal(0, s, (256, 256, 3)), np.zeros((256, 256, 1))], -1)  # noqa: E731
    a, b = truth + noise(0.01), truth + noise(0.01)  # the reference's two halves
    ref, half_diff = 0.5 * (a + b), a - b
    img = truth + noise(0.005)  # a good render: the reference's own noise would dominate its error
    mask = np.ones((256, 256), bool)
    raw, corr, ref_db = rc.psnr_vs_ref(img, ref, half_diff, mask)
    true_db = rc.psnr_vs_ref(img, truth, None, mask)[0]
    assert raw < true_db - 1.0  # uncorrected, the reference's noise hides a third of the error
    assert abs(corr - true_db) < 0.25 and corr > raw
    assert abs(ref_db - rc.psnr_vs_ref(ref, truth, None, mask)[0]) < 0.25  # its own noise, estimated
    assert rc.psnr_vs_ref(ref, ref, np.zeros_like(ref), mask)[1] == float("inf")  # identical, noiseless


def test_a_class_is_hidden_only_in_frames_that_have_it():
    frame = {"assets": ["eyebrows", "eyelashes", "garment", "hair", "iris", "skin"]}
    assert rc._shows("base", frame) and rc._shows("spp64+ribbons", frame)
    assert rc._shows("hidehair", frame) and rc._shows("hideclothing", frame)
    assert not rc._shows("hideglasses", frame) and not rc._shows("hidebeard+hideheadwear", frame)
    assert rc._shows("hidebeard+hidehair", frame)


def test_a_variant_is_within_only_if_every_measure_is():
    def row(cpu, psnr, lpips, eyes=None):
        r = {"seconds": cpu / 2, "cpu_seconds": cpu, "fringe": 0.01}
        for suffix in ("", "_eyes", "_hairline"):
            r["psnr_c" + suffix] = psnr if not (suffix == "_eyes" and eyes is not None) else eyes
            r["lpips" + suffix] = lpips
        return r

    by_v = {"base": {"a": row(100, 40.0, 0.05), "b": row(300, 38.0, 0.07)},
            "cheap": {"a": row(20, 39.7, 0.055), "b": row(60, 37.8, 0.075)},
            "blurry": {"a": row(10, 39.9, 0.07), "b": row(30, 37.9, 0.09)},  # LPIPS +0.02
            "eyes": {"a": row(20, 40.0, 0.05, eyes=38.0), "b": row(60, 38.0, 0.07, eyes=36.0)},  # an eye crop -2 dB
            "partial": {"a": row(50, 40.0, 0.05)}}
    rows = {r["variant"]: r for r in rc.compare_to_base(by_v)}
    assert rows["base"]["within"] and rows["base"]["cpu_ratio"] == 1.0
    assert rows["cheap"]["within"] and abs(rows["cheap"]["cpu_ratio"] - 0.2) < 1e-12
    assert abs(rows["cheap"]["d_psnr_c"] - (-0.25)) < 1e-9
    assert not rows["blurry"]["within"] and not rows["eyes"]["within"]
    assert rows["partial"]["frames"] == 1 and rows["partial"]["cpu_ratio"] == 0.5  # paired on its frame only
    assert [r["variant"] for r in rc.compare_to_base(by_v)][0] == "blurry"  # cheapest first


def test_a_study_refuses_renders_from_another_commit(tmp_path, monkeypatch):
    versions = iter([{"commit": "a" * 40, "dirty": False}, {"commit": "a" * 40, "dirty": False},
                     {"commit": "b" * 40, "dirty": False}, {"commit": "a" * 40, "dirty": True},
                     {"commit": "b" * 40, "dirty": False}])
    monkeypatch.setattr(rc, "code_version", lambda: next(versions))
    rc.check_code(tmp_path)  # the first stage records the commit
    assert json.loads((tmp_path / "code.json").read_text())["commit"] == "a" * 40
    rc.check_code(tmp_path)  # the same commit: fine
    for _ in range(2):  # another commit, or the same one with changes
        try:
            rc.check_code(tmp_path)
        except SystemExit as e:
            assert "worktree" in str(e)
        else:
            raise AssertionError("renders from other code were let in")
    rc.check_code(tmp_path, force=True)  # taken at the user's risk
    dirty = tmp_path / "new"
    dirty.mkdir()
    monkeypatch.setattr(rc, "code_version", lambda: {"commit": "c" * 40, "dirty": True})
    try:
        rc.check_code(dirty)
    except SystemExit as e:
        assert "uncommitted" in str(e) and not (dirty / "code.json").exists()
    else:
        raise AssertionError("a study was started from a changed tree")
