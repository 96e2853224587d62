"""Head shapes (synth.plan.head_shapes) and the plan's rule that keeps them inside adult ranges
(identity.head_shape, synth.plan.identities.planned_codes)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from synth import seeds
from synth.config import load_config
from synth.configkit import ConfigError
from synth.errors import SynthError
from synth.plan import head_shapes as hs
from synth.plan import identities


def _ellipsoid(a: float, b: float, c: float, n_lat: int = 24, n_lon: int = 48) -> np.ndarray:
    """Vertices of a UV ellipsoid with half axes a (x), b (y), c (z); the rings include the equator
    and the meridians x = 0 and y = 0, so the extreme points are vertices."""
    th = np.pi * np.arange(n_lat + 1) / n_lat
    ph = 2.0 * np.pi * np.arange(n_lon) / n_lon
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = np.stack([a * np.sin(T) * np.sin(P), -b * np.sin(T) * np.cos(P), c * np.cos(T)], -1).reshape(-1, 3)
    return v


def _vertex(i: int) -> tuple[np.ndarray, np.ndarray]:
    return np.array([i, i, i]), np.array([1.0, 0.0, 0.0])


def test_measures_of_an_ellipsoid_are_its_axes():
    a, b, c = 0.074, 0.097, 0.118
    v = _ellipsoid(a, b, c)
    top, bottom = int(np.argmax(v[:, 2])), int(np.argmin(v[:, 2]))
    upper = np.nonzero(v[:, 2] >= -1e-12)[0]
    sets = hs.MeasureSets(breadth=upper, length=upper[np.abs(v[upper, 0]) <= 0.02], width=np.arange(len(v)),
                          nasion=_vertex(top), menton=_vertex(bottom))
    m = hs.measure(v, sets)
    assert m["head_breadth_mm"] == pytest.approx(2000 * a, abs=1e-9)
    assert m["head_length_mm"] == pytest.approx(2000 * b, abs=1e-9)
    assert m["face_height_mm"] == pytest.approx(2000 * c, abs=1e-9)
    assert m["face_width_mm"] == pytest.approx(2000 * a, abs=1e-9)
    assert m["cephalic_index"] == pytest.approx(100 * a / b, rel=1e-12)
    assert m["facial_index"] == pytest.approx(100 * c / a, rel=1e-12)
    # a batch of shapes: scaled copies measure scaled
    mb = hs.measure(np.stack([v, 1.1 * v]), sets)
    assert mb["head_breadth_mm"] == pytest.approx([2000 * a, 2200 * a], abs=1e-9)
    assert mb["cephalic_index"] == pytest.approx([100 * a / b] * 2, rel=1e-12)


def test_the_exact_path_measures_what_the_evaluated_head_has(default_model):
    from synth.model.head import HeadModel

    codes = identities.sample_identities(5, np.arange(6), identities.prior_of(default_model), 12.0)
    sets = hs.measure_sets(default_model)
    ev = HeadModel(default_model, np.float64).evaluate(codes, np.zeros(default_model.expression_dims),
                                                       np.zeros((len(default_model.joint_names), 3)), landmarks=False)
    got, want = hs.measure_codes(default_model, codes, sets), hs.measure(ev.vertices, sets)
    for n in hs.NAMES:
        np.testing.assert_allclose(got[n], want[n], atol=1e-4)  # mm (and index points)


def test_the_default_templates_sets_and_figures_are_anatomical(default_model):
    sets = hs.measure_sets(default_model)
    t = default_model.template
    ears = set(np.asarray(default_model.regions["ears"]).tolist())
    assert not ears.intersection(sets.breadth.tolist()) and not ears.intersection(sets.width.tolist())
    # the eurion is above the ears and behind the face; the zygion in front of the ears
    eu = sets.breadth[np.argmax(t[sets.breadth, 0])]
    assert t[eu, 2] > t[np.asarray(default_model.regions["ears"]), 2].mean()
    m = hs.measure(t, sets)
    assert 140 < m["head_breadth_mm"] < 160 and 180 < m["head_length_mm"] < 205
    assert 95 < m["face_height_mm"] < 130 and 130 < m["face_width_mm"] < 155


def test_planned_heads_stay_inside_the_ranges_for_many_identities_and_extreme_seeds(default_model):
    cfg = load_config().identity
    bounds = hs.bounds_of(cfg)
    for seed, n in ((0, 1500), (seeds.MAX_SEED, 400), (123456789, 400)):
        codes = identities.planned_codes(seed, np.arange(n), default_model, cfg)
        m = hs.measure_codes(default_model, codes)
        assert hs.inside(m, bounds).all(), seed
    # without the rule, the same sampler leaves them (the reason for it)
    raw = identities.planned_codes(0, np.arange(1500), default_model, dataclasses.replace(cfg, head_shape="none"))
    assert (~hs.inside(hs.measure_codes(default_model, raw), bounds)).mean() > 0.1


def test_the_rule_is_deterministic_per_identity_and_keeps_first_draws_inside(default_model):
    cfg = load_config().identity
    a = identities.planned_codes(7, np.arange(300), default_model, cfg)
    assert np.array_equal(a, identities.planned_codes(7, np.arange(300), default_model, cfg))
    assert np.array_equal(identities.planned_codes(7, np.arange(120, 140), default_model, cfg), a[120:140])
    first = identities.sample_identities(7, np.arange(300), identities.prior_of(default_model),
                                         identities.truncation_radius(default_model.identity_dims, cfg))
    ok = hs.inside(hs.measure_codes(default_model, first), hs.bounds_of(cfg))
    assert np.array_equal(a[ok], first[ok]) and not np.any(np.all(a[~ok] == first[~ok], axis=1))
    none = identities.planned_codes(7, np.arange(300), default_model, dataclasses.replace(cfg, head_shape="none"))
    assert np.array_equal(none, first)


def test_when_every_redraw_fails_the_closest_draw_is_kept(default_model):
    cfg = dataclasses.replace(load_config().identity, head_shape_attempts=1, cephalic_index=(76.0, 79.0))
    ids = np.arange(200)
    prior = identities.prior_of(default_model)
    r = identities.truncation_radius(default_model.identity_dims, cfg)
    first = identities.sample_identities(3, ids, prior, r)
    got = identities.planned_codes(3, ids, default_model, cfg)
    b = hs.bounds_of(cfg)
    x0, x1 = hs.excess(hs.measure_codes(default_model, first), b), hs.excess(hs.measure_codes(default_model, got), b)
    assert np.all(x1 <= x0) and np.any(x1 > 0)  # one redraw is not always enough: the better one is kept
    redraw = np.stack([prior.sample(seeds.generator(3, seeds.Stream.IDENTITY_REDRAW, int(i), 1), 1, r)[0]
                       for i in ids])
    xr = hs.excess(hs.measure_codes(default_model, redraw), b)
    assert np.array_equal(got, np.where((xr < x0)[:, None], redraw, first))


@pytest.mark.parametrize("override, match", [
    ("identity.head_breadth_mm=[180, 131]", "head_breadth_mm"),
    ('identity.head_shape="anthropometrics"', "head_shape"),
    ("identity.head_shape_attempts=0", "head_shape_attempts"),
])
def test_a_bad_config_value_is_one_line(override, match):
    with pytest.raises(ConfigError, match=match) as e:
        load_config(overrides=[override])
    assert "\n" not in str(e.value)


def test_ranges_that_exclude_the_models_mean_head_are_refused_or_skipped(default_model):
    tight = dataclasses.replace(load_config().identity, head_shape="anthropometric", face_height_mm=(115.0, 156.0))
    with pytest.raises(SynthError, match="face_height_mm") as e:
        identities.planned_codes(0, np.arange(3), default_model, tight)
    assert "\n" not in str(e.value)
    auto = dataclasses.replace(tight, head_shape="auto")  # auto keeps every draw for such a model
    none = dataclasses.replace(tight, head_shape="none")
    assert np.array_equal(identities.planned_codes(0, np.arange(20), default_model, auto),
                          identities.planned_codes(0, np.arange(20), default_model, none))


def test_the_cli_refuses_an_unmeetable_range_in_one_line(tmp_path, capsys):
    from synth.cli.main import main

    out = tmp_path / "p"
    rc = main(["plan", "-n", "1", "--out", str(out), "-q", "--set", 'identity.head_shape="anthropometric"',
               "--set", "identity.head_length_mm=[200, 225]"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "head_length_mm" in err[0] and not out.exists()
