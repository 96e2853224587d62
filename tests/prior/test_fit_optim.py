"""Warm-up inversion, fine-tuning and novel-view expression codes on a tiny field (CPU, seconds)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from prior import losses
from prior.fit import config as fc
from prior.fit.finetune import finetune
from prior.fit.interpolate import interpolation_weights
from prior.fit.invert import invert_latent
from prior.fit.views import ViewSet, prior_resolution
from prior.train import config as rc
from prior.train.setup import build_model
from synth.errors import SynthError
from tests.prior import face_scene as fs
from tests.prior.scene import TINY

C = fs.IDENTITY_DIMS + len(fs.MODEL.expression_names) + 9


@pytest.fixture(scope="module")
def views():
    frames = [fs.frame(7, 0, v, 6, 24, "0" * 64, fs.INPUT_ANGLES[v])[2] for v in range(3)]
    pix = [fs.frame(7, 0, v, 6, 24, "0" * 64, fs.INPUT_ANGLES[v])[1][0] for v in range(3)]
    codes = []
    for m in frames:
        rot = m["model"]["joint_rotations"]
        codes.append(np.concatenate([m["model"]["identity"], m["model"]["expression"], rot["jaw"], rot["eye_l"],
                                     rot["eye_r"]]))
    return ViewSet(np.stack([p[..., :3] for p in pix]), np.stack([m["camera"]["K"] for m in frames]),
                   np.stack([m["camera"]["camera_to_world"] for m in frames]), np.stack(codes).astype(np.float32),
                   np.zeros(3), 0.16)


def tiny_model(seed=0):
    cfg = rc.load("small", None, [s for s in TINY if s.startswith(("model.", "sampling."))]
                  + [f"model.init_seed={seed}", "model.scene_radius=0.16"])
    return build_model(cfg, C, 3)


def full_loss(model, views, w) -> float:
    """Deterministic L1 over every pixel of every view (the quantity both stages lower)."""
    H, W = views.size
    vi, pix = np.divmod(np.arange(len(views) * H * W), H * W)
    b = views.rays(vi, pix)
    with torch.no_grad():
        out = model(b.rays.with_latent(w))
    return float(losses.l1_loss(out["rgb"], b.target, b.valid))


def test_views_rays_and_resize(views):
    H, W = views.size
    b = views.rays(np.array([1, 1]), np.array([0, H * W - 1]))
    np.testing.assert_allclose(b.target.numpy(), views.target[1].reshape(-1, 3)[[0, H * W - 1]])
    assert np.allclose(np.linalg.norm(b.rays.directions.numpy(), axis=1), 1, atol=1e-6)
    assert b.rays.latent_ids is None and b.rays.latents is None and len(b.rays) == 2
    low = views.resized(12, 12)
    assert low.size == (12, 12) and np.allclose(low.K[:, 0, 0], views.K[:, 0, 0] / 2)
    # area averaging keeps the mean colour
    np.testing.assert_allclose(low.target.mean((1, 2)), views.target.mean((1, 2)), atol=1e-5)
    assert prior_resolution(64, 32, (16, 16)) == (16, 8) and prior_resolution(8, 8, (16, 16)) == (8, 8)


FT = dict(steps=30, rays_per_step=256, warmup_steps=3, lr_init=1e-2, lr_final=1e-3, grad_clip=0.0)
W_STAR = torch.tensor([1.5, -1.0, 0.8, -1.2])


@pytest.fixture(scope="module")
def tuned(views):
    """A tiny field fine-tuned on the views with the latent W_STAR (so its output depends on w)."""
    model = tiny_model()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    start = full_loss(model, views, W_STAR)
    w, hist = finetune(model, views, W_STAR, dataclasses.replace(fc.preset("small").finetune, **FT), seed=2)
    return model, before, start, w, hist


def test_finetuning_moves_the_weights_and_lowers_the_loss(views, tuned):
    model, before, start, w, hist = tuned
    assert full_loss(model, views, w) < 0.8 * start
    assert not torch.equal(w, W_STAR)
    moved = [k for k, v in model.state_dict().items() if not torch.equal(v, before[k])]
    assert any(k.startswith("proposal.") for k in moved) and any(k.startswith("nerf.") for k in moved)
    assert not any(k.startswith("codebook.") for k in moved)  # the codebook is not the fitted latent
    assert {"l1", "proposal", "distortion", "view", "normal", "loss", "psnr"} <= set(hist[-1])
    assert hist[-1]["step"] == 30
    cfg = dataclasses.replace(fc.preset("small").finetune, **{**FT, "steps": 2})
    runs = [(m := tiny_model(), finetune(m, views, W_STAR, cfg, seed=2)[0]) for _ in range(2)]
    assert torch.equal(runs[0][1], runs[1][1])  # deterministic from the seed
    assert all(torch.equal(a, b) for a, b in zip(runs[0][0].parameters(), runs[1][0].parameters()))


@pytest.mark.parametrize("lpips_weight", [0.0, 0.1])
def test_inversion_lowers_the_loss_and_moves_only_w(views, tuned, lpips_weight):
    model = tuned[0]
    before = {k: v.clone() for k, v in model.state_dict().items()}
    codes = views.codes.copy()
    w0 = torch.zeros(4)
    steps = 6 if lpips_weight else 25
    cfg = dataclasses.replace(fc.preset("small").inversion, steps=steps, patch_size=16, patches=1, lr_init=1e-1,
                              lr_final=1e-2, lpips_weight=lpips_weight)
    w, hist = invert_latent(model, views, w0, cfg, seed=1)
    assert len(hist) == steps and not torch.equal(w, w0)
    if not lpips_weight:  # (with LPIPS the L1 alone need not fall)
        assert full_loss(model, views, w) < full_loss(model, views, w0)
    else:
        assert all(h["lpips"] > 0 for h in hist)
    for k, v in model.state_dict().items():
        assert torch.equal(v, before[k]), k
    assert all(p.requires_grad for p in model.parameters())  # restored
    np.testing.assert_array_equal(views.codes, codes)
    short = dataclasses.replace(cfg, steps=2)
    assert torch.equal(invert_latent(model, views, w0, short, seed=1)[0],
                       invert_latent(model, views, w0, short, seed=1)[0])  # deterministic from the seed


def test_inversion_refuses_patches_too_small_for_lpips(views):
    cfg = dataclasses.replace(fc.preset("small").inversion, steps=1, lpips_net="alex", patch_size=32)
    with pytest.raises(SynthError, match="at least 32 px"):
        invert_latent(tiny_model(), views, torch.zeros(4), cfg)


def test_loss_terms_follow_their_weights(views):
    from prior.fit.finetune import fit_loss

    model = tiny_model()
    b = views.rays(np.zeros(64, np.int64), np.arange(64) * 7)
    out = model(b.rays.with_latent(torch.zeros(4)), compute_normals=True)
    cfg = fc.preset("small").finetune
    t = fit_loss(model, out, b.target, b.valid, cfg)
    want = (t["l1"] + cfg.proposal_weight * t["proposal"] + cfg.normal_weight * t["normal"]
            + cfg.view_weight * t["view"] + cfg.distortion_weight * t["distortion"])
    assert float(t["loss"].detach()) == pytest.approx(float(want.detach()), rel=1e-6)
    assert float(t["view"]) == pytest.approx(float(model.nerf.view.blocks[1].weight.square().sum()), rel=1e-6)


def test_novel_views_interpolate_the_expression(views, tmp_path):
    """At an input camera the code is that image's; between cameras it is the Eq. 8 mix, and the
    rendered pixels are those of the mixed code."""
    from prior.fit.fitdir import FittedFace
    from prior.fit.novel import render_fit_view, view_code
    from prior.render_views import render_image

    codes = views.codes.copy()
    codes[:, fs.IDENTITY_DIMS:] += np.arange(3)[:, None] * 0.3  # three clearly different expressions
    info = {"codes": codes.tolist(), "bounds": {"centre": [0, 0, 0], "radius": 0.16},
            "cameras": [{"K": views.K[i].tolist(), "camera_to_world": views.c2w[i].tolist(), "width": 24,
                         "height": 24} for i in range(3)]}
    fit = FittedFace(tmp_path, info, tiny_model(), torch.zeros(4), None)
    for i in range(3):
        code, w = view_code(fit, views.c2w[i])
        np.testing.assert_allclose(code, codes[i], atol=1e-5)
    mid = views.c2w[0].copy()
    mid[:3, 3] = 0.5 * (views.c2w[0, :3, 3] + views.c2w[1, :3, 3])
    code, w = view_code(fit, mid)
    np.testing.assert_allclose(w, interpolation_weights(mid[:3, 3], views.c2w[:, :3, 3])[0])
    assert w[0] == pytest.approx(w[1]) and w[0] > w[2] > 0
    np.testing.assert_allclose(code, w @ codes, atol=1e-6)
    img = render_fit_view(fit, views.K[0], mid, 8, 8)
    ref = render_image(fit.model, views.K[0], mid, 8, 8, w @ codes, None, np.zeros(3), 0.16, latent=torch.zeros(4))
    np.testing.assert_allclose(img["rgb"], ref["rgb"], atol=1e-6)
    other = render_image(fit.model, views.K[0], mid, 8, 8, codes[0], None, np.zeros(3), 0.16, latent=torch.zeros(4))
    assert np.abs(other["rgb"] - img["rgb"]).max() > 1e-4  # the code matters


def test_render_image_skips_rays_that_miss_the_bounds(views):
    """Rays outside the bounding sphere are not sent through the field; the image equals the
    field evaluated on every ray (the misses see nothing: zero colour and opacity)."""
    from prior.data.bounds import intersect_sphere
    from prior.data.sampler import pixel_radius
    from prior.rays import RayBundle
    from prior.render_views import render_image
    from synth.dataset.reader import camera_rays

    model, K, c2w, lat = tiny_model(), views.K[0], views.c2w[0], torch.full((4,), 0.1)
    code = views.codes[0]
    img = render_image(model, K, c2w, 12, 10, code, None, np.zeros(3), 0.1, latent=lat, chunk=7)
    r = camera_rays(K, c2w, 12, 10)
    o, d = r.origins.reshape(-1, 3), r.directions.reshape(-1, 3)
    near, far = intersect_sphere(o, d, np.zeros(3), 0.1)
    miss = far <= near
    assert 0 < miss.sum() < miss.size  # both kinds of rays in the image
    n = o.shape[0]
    rays = RayBundle.from_numpy(o, d, near, far, np.repeat(code[None], n, axis=0),
                                radii=np.full(n, pixel_radius(K), np.float32)).with_latent(lat)
    with torch.no_grad():
        ref = model(rays, randomized=False)
    np.testing.assert_allclose(img["rgb"].reshape(-1, 3), ref["rgb"].clamp(0, 1).numpy(), atol=1e-6)
    np.testing.assert_allclose(img["acc"].reshape(-1), ref["acc"].numpy(), atol=1e-6)
    assert (img["rgb"].reshape(-1, 3)[miss] == 0).all() and (img["depth"].reshape(-1)[miss] == 0).all()


def test_face_region_is_the_grown_hull_of_the_landmarks():
    from prior.fit.views import face_region

    sq = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 30.0], [20.0, 20.0], [np.nan, np.nan]])
    m = face_region(sq, 40, 40)
    # pixel centres (x + 0.5) inside the hull: columns and rows 10..29
    assert m.sum() == 20 * 20 and m[10, 10] and m[29, 29] and not m[9, 20] and not m[30, 20]
    grown = face_region(sq, 40, 40, grow=0.5)  # half-side 10 -> 15 about (20, 20)
    assert grown.sum() == 30 * 30 and grown[5, 5] and not grown[4, 5]
    assert face_region(sq, 24, 24).sum() == 14 * 14  # cut by the image
    assert not face_region(np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]), 8, 8).any()  # no area
    assert not face_region(np.zeros((2, 2)), 8, 8).any()


def test_fine_tuning_rays_drawn_on_the_face(views):
    from prior.fit.finetune import draw_rays, face_pixels

    H, W = views.size
    # without a face region (or a share of 0) the draws are the uniform ones
    rng = np.random.default_rng([0xF17E, 3, 5])
    uniform = np.divmod(rng.integers(0, len(views) * H * W, 100), H * W)
    for args in ((), (0.5, None), (0.0, np.arange(10))):
        got = draw_rays(views, 5, 3, 100, *args)
        assert all(np.array_equal(a, b) for a, b in zip(got, uniform))
    face = np.zeros((len(views), H, W), bool)
    face[1, 4:8, 6:10] = True
    fv = dataclasses.replace(views, face=face)
    pix = face_pixels(fv)
    assert pix.size == 16
    v, p = draw_rays(fv, 5, 3, 100, 0.5, pix)
    on_face = face[v, p // W, p % W]
    assert on_face.sum() >= 50 and (v[on_face] == 1).all()
    # the same step and seed draw the same rays
    v2, p2 = draw_rays(fv, 5, 3, 100, 0.5, pix)
    assert np.array_equal(v, v2) and np.array_equal(p, p2)
    # the region follows a resize (kept where at least half of a low-resolution pixel was face)
    low = fv.resized(W // 2, H // 2)
    assert low.face.shape == (len(views), H // 2, W // 2) and low.face[1].sum() == 4


def test_whole_image_l1_is_the_fixed_measure_of_the_inversion(views):
    from prior.fit.invert import whole_l1

    model = tiny_model(seed=3)
    w = torch.tensor([0.3, -0.2, 0.1, 0.0])
    expect = full_loss(model, views, w.reshape(1, -1))
    assert whole_l1(model, views, w, chunk=97) == pytest.approx(expect, rel=1e-5)
    assert whole_l1(model, views, w, chunk=97) == whole_l1(model, views, w, chunk=97)
