"""Scalp hair, measured per style: how much of the scalp the strands hide seen from above and
from the front, how far the hair stands off the scalp, and how many strands a frame carries.

    .venv/bin/python benchmarks/hair_coverage.py [--picks 3] [--resolution 512] [--seed 0]

No rendering and no Blender: each style's groom is made by the worker's own numpy groomer
(:func:`synth.assets.fit.hair.groom`) on the default head model, neutral, at the strand counts of
``--resolution`` (``synth.assets.fit.hair.counts``), with ``--picks`` parameter draws per style
as the planner makes them (:func:`synth.plan.assets.sample_assets` over identities of ``--seed``
until each style has its picks).

- **Covered scalp** (from above: looking down the head's vertical axis; from the front: looking
  along the face's axis): points sampled uniformly by area over the scalp where the groom plants
  roots (``hair_grows``: the scalp region less the pick's receding hairline), facing the view and
  not hidden behind the head itself (the ears, the neck: :func:`unhidden`); a point
  is covered when a strand segment in front of it passes over it, that is within the strand's
  radius (``Styling.root_radius`` tapered to the tip as the rig tapers it) of the point's line of
  sight. Hair is treated as opaque, so the covered fraction is the share of the scalp's pixels a
  render at any resolution would show as hair (each pixel's share of scalp, averaged). The rest is
  scalp seen between strands (or at a parting; the measure does not tell them apart).
- **Volume**: the median over strand points (roots excluded) of their distance from the nearest
  scalp sample (mm), and its 90th percentile.
- **Strands**: the groom's strand count (children and guides as the rig makes them).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: the hair styles of assets_manifest/hair.toml, in its order
STYLES = ("buzz_cut", "short_straight", "short_curly", "undercut", "short_back_and_sides", "medium_wavy", "bob",
          "long_straight", "long_layered", "long_curly", "afro", "bun", "ponytail", "braids", "locs")
UP = np.array([0.0, 0.0, 1.0])  # the head model's vertical axis
FRONT = np.array([0.0, -1.0, 0.0])  # the direction the face looks
VIEWS = {"above": -UP, "front": -FRONT}  # the direction of the line of sight (viewer to head)


def picks_per_style(seed: int, n: int, limit: int = 20000) -> dict[str, list[dict]]:
    """``n`` planner picks of each style (the first identities of ``seed`` that wear it)."""
    from synth.assets.catalogue import load_catalogue
    from synth.plan.assets import sample_assets_batch

    cat = load_catalogue()
    out: dict[str, list[dict]] = {s: [] for s in STYLES}
    for start in range(0, limit, 500):
        for a in sample_assets_batch(seed, range(start, start + 500), cat):
            h = a.get("hair")
            if h is not None and h["id"] in out and len(out[h["id"]]) < n:
                out[h["id"]].append({"id": h["id"], "params": dict(h["params"])})
        if all(len(v) >= n for v in out.values()):
            break
    return out


def radii(styling, n_points: int) -> np.ndarray:
    """(P,) strand radius from root to tip as the rig sets it (``synth.assets.fit.groom.profile``:
    Blender's "Set Hair Curve Profile" with ``Styling.tip_shape``, 0 at the tip)."""
    from synth.assets.fit.groom import profile

    return styling.root_radius * profile(np.linspace(0.0, 1.0, n_points), styling.tip_shape)


def _basis(view: np.ndarray) -> np.ndarray:
    """(2, 3) image-plane axes orthogonal to ``view``."""
    a = np.array([1.0, 0.0, 0.0]) if abs(view[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(view, a)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(view, u)])


def covered(samples: np.ndarray, normals: np.ndarray, pts: np.ndarray, rad: np.ndarray, view: np.ndarray,
            cell: float = 0.002, where: bool = False):
    """(scalp samples facing the view, how many of them a strand segment in front covers); with
    ``where`` also the (samples,) mask of the covered ones (False where not facing the view)."""
    facing = normals @ view < 0.0
    S = samples[facing]
    if len(S) == 0 or pts.size == 0:
        return (int(len(S)), 0, np.zeros(len(samples), bool)) if where else (int(len(S)), 0)
    B = _basis(view)
    s2, sd = S @ B.T, S @ view  # image-plane position; depth (larger: farther from the viewer)
    a, b = pts[:, :-1].reshape(-1, 3), pts[:, 1:].reshape(-1, 3)
    r = np.broadcast_to(0.5 * (rad[:-1] + rad[1:]), pts[:, :-1, 0].shape).reshape(-1)
    a2, b2, ad, bd = a @ B.T, b @ B.T, a @ view, b @ view
    # each segment goes into the grid cells its points at half-cell steps fall in (segments are
    # far longer than thick: the radius, under 0.4 mm, is covered by also looking in the
    # neighbouring cells of a sample)
    lo = np.minimum(s2.min(0), np.minimum(a2.min(0), b2.min(0))) - 2 * cell
    steps = np.maximum(1, np.ceil(np.linalg.norm(b2 - a2, axis=1) / (0.5 * cell)).astype(np.int64))
    seg = np.repeat(np.arange(len(a2)), steps + 1)
    first = np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)
    frac = (np.arange(len(seg)) - first) / np.repeat(steps, steps + 1)
    ij = np.floor((a2[seg] + frac[:, None] * (b2[seg] - a2[seg]) - lo) / cell).astype(np.int64)
    W, H = int(ij[:, 0].max()) + 3, int(ij[:, 1].max()) + 3
    pair = np.unique(ij[:, 1] * W + ij[:, 0] + seg * (W * H), return_index=False)
    cells, segs_of = pair % (W * H), pair // (W * H)
    order = np.argsort(cells, kind="stable")
    cells, segs_of = cells[order], segs_of[order]
    starts = np.searchsorted(cells, np.arange(W * H + 1))
    sij = np.floor((s2 - lo) / cell).astype(np.int64)
    hit = np.zeros(len(S), bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            c = np.clip(sij[:, 1] + dj, 0, H - 1) * W + np.clip(sij[:, 0] + di, 0, W - 1)
            n = starts[c + 1] - starts[c]
            for chunk in np.array_split(np.arange(len(S)), max(1, int(n.sum()) // 200000 + 1)):
                cn = n[chunk]
                if not cn.sum():
                    continue
                who = np.repeat(chunk, cn)
                off = np.arange(int(cn.sum())) - np.repeat(np.cumsum(cn) - cn, cn)
                sg = segs_of[starts[c[who]] + off]
                d = b2[sg] - a2[sg]
                w = s2[who] - a2[sg]
                t = np.clip((w * d).sum(1) / np.maximum((d * d).sum(1), 1e-18), 0.0, 1.0)
                dist = np.linalg.norm(w - t[:, None] * d, axis=1)
                depth = ad[sg] + t * (bd[sg] - ad[sg])
                ok = (dist <= r[sg]) & (depth < sd[who] - 1e-4)
                hit[who[ok]] = True
    if where:
        out = np.zeros(len(samples), bool)
        out[facing] = hit
        return int(len(S)), int(hit.sum()), out
    return int(len(S)), int(hit.sum())


def scalp_samples(ctx, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(points, outward normals) sampled uniformly by area where the groom plants roots."""
    from synth.assets.fit.groom import head_frame
    from synth.assets.fit.masks import hair_grows
    from synth.assets.fit.strands import Surface

    surface = Surface(ctx)
    tris = surface.region_triangles("scalp", "all")
    rng = np.random.default_rng([0x5CA1, seed])
    t, b = surface.sample(tris, 3 * n, rng)
    p = surface.points(t, b)
    keep = hair_grows(p, head_frame(ctx), 0.0)
    V, F = surface.V, surface.T
    tri = F[t[keep]]
    nrm = np.cross(V[tri[:, 1]] - V[tri[:, 0]], V[tri[:, 2]] - V[tri[:, 0]])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    c = head_frame(ctx)["centre"]
    p = p[keep]
    nrm *= np.sign(((p - c) * nrm).sum(1))[:, None]  # outward
    return p[:n], nrm[:n]


def unhidden(ctx, samples: np.ndarray, view: np.ndarray, eps: float = 1e-3) -> np.ndarray:
    """(samples,) True where no head triangle lies between the sample and a viewer looking along
    ``view`` (an orthographic ray toward the viewer crosses none of the head's exterior triangles
    more than ``eps`` in front of it): scalp behind the ears or the neck is not seen."""
    from synth.assets.fit.strands import Surface
    from synth.geometry.raycast import RayGrid

    surface = Surface(ctx)
    t = RayGrid(surface.V, surface.T[surface.ext_tris], view).hits(samples)
    return ~np.any(t < -eps, axis=1)


def measure(ctx, picks: dict[str, list[dict]], n_samples: int) -> dict[str, dict]:
    from scipy.spatial import cKDTree

    from synth.assets.fit.groom import head_frame
    from synth.assets.fit.hair import groom
    from synth.assets.fit.masks import hair_grows

    samples, normals = scalp_samples(ctx, n_samples, 0)
    hf = head_frame(ctx)
    seen = {name: unhidden(ctx, samples, view) for name, view in VIEWS.items()}
    tree = cKDTree(samples)
    out = {}
    for style, entries in picks.items():
        rows = []
        for e in entries:
            t0 = time.perf_counter()
            g = groom(ctx, e)
            dt = time.perf_counter() - t0
            pts = np.asarray(g.pts, np.float64)
            rad = radii(g.styling, pts.shape[1])
            cov = {}
            # the scalp this pick plants roots on (a receded hairline is bare skin, not scalp
            # between strands)
            grows = hair_grows(samples, hf, float(e["params"].get("hairline_recession", 0.0)))
            for name, view in VIEWS.items():
                s = grows & seen[name]
                total, hit = covered(samples[s], normals[s], pts, rad, view)
                cov[name] = hit / max(total, 1)
            d = tree.query(pts[:, 1:].reshape(-1, 3))[0] * 1000.0
            rows.append({"strands": int(pts.shape[0]), "above": cov["above"], "front": cov["front"],
                         "volume_mm": float(np.median(d)), "volume_p90_mm": float(np.percentile(d, 90)),
                         "root_radius_mm": 1000.0 * g.styling.root_radius, "groom_s": dt,
                         "params": {k: e["params"][k] for k in ("length_m", "density", "parting", "hairline_recession")
                                    if k in e["params"]}})
        out[style] = rows
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--picks", type=int, default=3, help="parameter draws per style")
    ap.add_argument("--resolution", type=int, default=512, help="the frame size the strand counts are for")
    ap.add_argument("--seed", type=int, default=0, help="the plan seed the picks are drawn with")
    ap.add_argument("--samples", type=int, default=20000, help="scalp sample points")
    ap.add_argument("--styles", nargs="+", choices=STYLES, default=list(STYLES), help="the styles to measure")
    a = ap.parse_args(argv)
    from synth.model.default import load_default_model
    from synth.model.head import HeadModel
    from tests.support import asset_scene

    ctx = asset_scene.head_arrays(HeadModel(load_default_model()), "neutral", a.resolution, 0, a.seed)
    picks = picks_per_style(a.seed, a.picks)
    res = measure(ctx, {s: picks[s] for s in STYLES if s in a.styles}, a.samples)
    print(f"default head, neutral; strand counts for {a.resolution}^2; {a.picks} planner picks per style (seed "
          f"{a.seed}); {a.samples} scalp samples\n")
    print("| style | strands | root radius (mm) | scalp covered from above | from the front | volume: median "
          "strand-point distance from the scalp (mm) | 90th percentile (mm) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for style, rows in res.items():
        def col(k, f):
            return " / ".join(f.format(r[k]) for r in rows)
        print(f"| {style} | {col('strands', '{:,}')} | {col('root_radius_mm', '{:.3f}')} | {col('above', '{:.0%}')} | "
              f"{col('front', '{:.0%}')} | {col('volume_mm', '{:.1f}')} | {col('volume_p90_mm', '{:.0f}')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
