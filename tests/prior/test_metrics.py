"""prior.metrics: PSNR and SSIM against scikit-image / pytorch-msssim and masked slow references."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from prior.metrics import psnr, ssim, ssim_map  # noqa: E402
from synth.errors import SynthError  # noqa: E402


def _pair(seed=0, shape=(40, 48, 3)):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 1, shape)
    a = 0.5 * a + 0.5 * np.roll(a, 1, axis=0)  # some spatial structure
    b = np.clip(a + rng.normal(0, 0.05, shape), 0, 1)
    return a, b


@pytest.fixture(scope="module")
def astronaut():
    skd = pytest.importorskip("skimage.data", reason="scikit-image (test extra) is needed for its sample images")
    img = skd.astronaut()[::4, ::4].astype(np.float64) / 255.0  # 128 x 128
    rng = np.random.default_rng(1)
    noisy = np.clip(img + rng.normal(0, 0.08, img.shape), 0, 1)
    dark = img * 0.7
    return img, [noisy, dark, np.roll(img, 3, axis=1)]


def test_psnr_matches_skimage(astronaut):
    from skimage.metrics import peak_signal_noise_ratio

    img, others = astronaut
    for o in others:
        assert float(psnr(img, o)) == pytest.approx(peak_signal_noise_ratio(img, o, data_range=1.0), abs=1e-10)


def test_psnr_masked_is_psnr_of_the_foreground_pixels():
    a, b = _pair()
    m = np.zeros(a.shape[:2])
    m[5:30, 10:40] = 1
    sel = m > 0
    mse = np.mean((a[sel] - b[sel]) ** 2)
    assert float(psnr(a, b, m)) == pytest.approx(10 * np.log10(1 / mse), abs=1e-10)
    # batched input, per-image masks
    A = torch.tensor(np.stack([a, b])).permute(0, 3, 1, 2)
    B = torch.tensor(np.stack([b, a])).permute(0, 3, 1, 2)
    out = psnr(A, B, torch.tensor(np.stack([m, m]))[:, None])
    assert out.shape == (2,) and float(out[0]) == pytest.approx(float(out[1]))


def test_ssim_matches_pytorch_msssim_and_skimage(astronaut):
    msssim = pytest.importorskip("pytorch_msssim", reason="pytorch-msssim (test extra) is the SSIM oracle")
    from skimage.metrics import structural_similarity

    img, others = astronaut
    for o in others:
        # pytorch-msssim builds its window in float32 whatever the input: compare in float32
        x = torch.tensor(img, dtype=torch.float32).permute(2, 0, 1)[None]
        y = torch.tensor(o, dtype=torch.float32).permute(2, 0, 1)[None]
        ref = float(msssim.ssim(x, y, data_range=1.0, size_average=True))
        assert float(ssim(x, y)) == pytest.approx(ref, abs=2e-6)
        got = float(ssim(img, o))  # float64
        sk = structural_similarity(img, o, data_range=1.0, channel_axis=-1, gaussian_weights=True, sigma=1.5,
                                   use_sample_covariance=False)
        assert got == pytest.approx(sk, abs=1e-9)
        assert got == pytest.approx(ref, abs=1e-5)
    assert float(ssim(img, img)) == pytest.approx(1.0, abs=1e-12)


def test_ssim_map_against_direct_window_sums():
    """Slow reference: each window's weighted means, variances and covariance summed directly."""
    a, b = _pair(2, (16, 18, 3))
    g = np.exp(-((np.arange(11) - 5.0) ** 2) / (2 * 1.5 ** 2))
    w = np.outer(g, g) / np.outer(g, g).sum()
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    ref = np.zeros((3, 6, 8))
    for c in range(3):
        for i in range(6):
            for j in range(8):
                x, y = a[i:i + 11, j:j + 11, c], b[i:i + 11, j:j + 11, c]
                mx, my = (w * x).sum(), (w * y).sum()
                vx, vy = (w * x * x).sum() - mx ** 2, (w * y * y).sum() - my ** 2
                cxy = (w * x * y).sum() - mx * my
                ref[c, i, j] = (2 * mx * my + c1) * (2 * cxy + c2) / ((mx ** 2 + my ** 2 + c1) * (vx + vy + c2))
    got = ssim_map(torch.tensor(a).permute(2, 0, 1)[None], torch.tensor(b).permute(2, 0, 1)[None])[0].numpy()
    np.testing.assert_allclose(got, ref, atol=1e-12)


def test_ssim_masked_rule():
    a, b = _pair(3)
    m = np.zeros(a.shape[:2])
    m[8:32, 6:30] = 1.0
    full = ssim_map(torch.tensor(a * m[..., None]).permute(2, 0, 1)[None],
                    torch.tensor(b * m[..., None]).permute(2, 0, 1)[None])[0].mean(0).numpy()
    centres = m[5:-5, 5:-5] > 0
    assert float(ssim(a, b, m)) == pytest.approx(full[centres].mean(), abs=1e-12)
    # what lies outside the mask does not matter
    b2 = b.copy()
    b2[m == 0] = 0.3
    assert float(ssim(a, b2, m)) == pytest.approx(float(ssim(a, b, m)), abs=1e-12)
    assert float(psnr(a, b2, m)) == pytest.approx(float(psnr(a, b, m)), abs=1e-12)


def test_bad_input():
    a, b = _pair()
    with pytest.raises(SynthError, match="differ in shape"):
        psnr(a, b[:-1])
    with pytest.raises(SynthError, match="selects no pixel"):
        ssim(a, b, np.zeros(a.shape[:2]))
    with pytest.raises(SynthError, match="does not fit"):
        psnr(a, b, np.ones((3, 3)))
    with pytest.raises(SynthError, match="smaller than"):
        ssim(a[:8, :8], b[:8, :8])
