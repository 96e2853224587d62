"""benchmarks/realism/eyes.py: the eyes' proportions against published measurements (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.realism import eyes


@pytest.fixture(scope="module")
def E():
    return eyes

def _eyes(fissure_mm, gap_mm, height_mm):
    """(1, 68, 3) points in metres: two eyes on the x axis, medial corners ``gap_mm`` apart, each
    ``fissure_mm`` long, lids ``height_mm`` apart at the thirds, rotated off the axes."""
    p = np.zeros((68, 3))
    g, f, h = gap_mm / 2000, fissure_mm / 1000, height_mm / 1000
    for s, (lat, up1, up2, med, lo2, lo1) in ((-1, range(36, 42)), (1, (45, 44, 43, 42, 47, 46))):
        p[med] = [s * g, 0, 0]
        p[lat] = [s * (g + f), 0, 0]
        for up, lo, t in ((up1, lo1, 2 / 3), (up2, lo2, 1 / 3)):  # at a third and two thirds from the medial corner
            x = s * (g + t * f)
            p[up], p[lo] = [x, 0, h / 2], [x, 0, -h / 2]
    c, sn = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])  # distances do not depend on the head's pose
    return (p @ R.T + [0.1, -0.2, 1.5])[None]

def test_measures_of_known_eyes(E):
    v = E.eye_measures(np.concatenate([_eyes(27.0, 32.0, 10.0), _eyes(22.0, 39.0, 8.0)]))
    np.testing.assert_allclose(v["en-en"], [32.0, 39.0], atol=1e-9)
    np.testing.assert_allclose(v["ex-ex"], [86.0, 83.0], atol=1e-9)
    np.testing.assert_allclose(v["ex-en"], [27.0, 22.0], atol=1e-9)
    np.testing.assert_allclose(v["ps-pi"], [10.0, 8.0], atol=1e-9)
    np.testing.assert_allclose(v["canthal index"], [100 * 32 / 86, 100 * 39 / 83], atol=1e-9)
    np.testing.assert_allclose(v["fissure height / length"], [100 * 10 / 27, 100 * 8 / 22], atol=1e-9)

def test_table_says_how_far_outside_the_published_means(E):
    lo, hi = E.reference_range("ex-en")
    sd = max(m["ex-en"][1] for _, _, m in E.REFERENCES if "ex-en" in m and m["ex-en"][1])
    inside = E.eye_measures(_eyes((lo + hi) / 2, 34.0, 10.0))
    short = E.eye_measures(np.repeat(_eyes(lo - 2 * sd, 34.0, 10.0), 3, axis=0))
    rows_in = {r["measure"]: r for r in E.table(inside)}
    rows_short = {r["measure"]: r for r in E.table(short)}
    assert rows_in["ex-en"]["sd_outside"] == 0.0
    assert rows_short["ex-en"]["sd_outside"] == pytest.approx(-2.0)
    assert rows_short["ex-en"]["median"] == pytest.approx(lo - 2 * sd)
    assert (rows_in["ex-en"]["published_low"], rows_in["ex-en"]["published_high"]) == (lo, hi)


def test_margin_reflex_distances_take_the_margin_above_and_below_the_pupil(E):
    """Two eyes; each lid has a margin vertex over the pupil and, beyond the half-width sideways,
    vertices nearer the pupil's height (the canthi) that must not count."""
    V, regions = [], {}

    def add(name, pts):
        regions.setdefault(name, []).extend(range(len(V), len(V) + len(pts)))
        V.extend(pts)

    for s, x0 in (("l", 0.032), ("r", -0.032)):
        z0 = 0.70
        add(f"pupil_{s}", [[x0 + dx, -0.11, z0 + dz] for dx, dz in ((-0.001, 0), (0.001, 0), (0, -0.001), (0, 0.001))])
        add(f"eyelid_{s}_upper", [[x0 + 0.0005, -0.112, z0 + 0.004], [x0 - 0.001, -0.112, z0 + 0.0045],
                                  [x0 + 0.004, -0.110, z0 + 0.001], [x0 + 0.0002, -0.115, z0 + 0.009]])
        add(f"eyelid_{s}_lower", [[x0 - 0.0003, -0.112, z0 - 0.0055], [x0 + 0.001, -0.112, z0 - 0.006],
                                  [x0 - 0.005, -0.110, z0 - 0.0005], [x0, -0.114, z0 - 0.012]])
    V = np.asarray(V)
    heads = np.stack([V, V + [0.0, 0.0, 0.3]])  # the same head raised: the distances do not change
    m = E.margin_reflex_distances(heads, regions)
    np.testing.assert_allclose(m["MRD1"], [4.0, 4.0], atol=1e-9)
    np.testing.assert_allclose(m["MRD2"], [5.5, 5.5], atol=1e-9)


def test_eyeball_diameter_of_known_spheres(E):
    """Two heads whose scleras are caps of spheres of 24 and 30 mm diameter (different centres per
    eye, points on less than a hemisphere, as the visible-and-hidden sclera region is not a whole
    sphere) read those diameters."""
    rng = np.random.default_rng(0)
    V = np.zeros((2, 400, 3))
    regions = {"sclera_l": np.arange(0, 200), "sclera_r": np.arange(200, 400)}
    for n, d in enumerate((24.0, 30.0)):
        for half, c in ((slice(0, 200), [0.03, -0.1, 1.6]), (slice(200, 400), [-0.03, -0.1, 1.6])):
            u = rng.normal(size=(200, 3))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            u[:, 1] = -np.abs(u[:, 1])  # one side only
            V[n, half] = np.asarray(c) + d / 2000 * u
    np.testing.assert_allclose(E.eyeball_diameters(V, regions), [24.0, 30.0], atol=1e-6)
