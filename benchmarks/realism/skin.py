"""``skin`` and ``plot-skin``: the ITA histogram and CIELAB range of the planned skin albedos and of
rendered skin pixels (docs/realism.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import CATS, _cat

def _lab_table(lab: np.ndarray, ita: np.ndarray) -> None:
    from synth.appearance.skin import ita_category

    h = np.bincount(ita_category(ita), minlength=6)
    print("| " + " | ".join(CATS) + " |\n|" + "---:|" * 6)
    print("| " + " | ".join(str(int(x)) for x in h) + " |\n")
    print("| | min | median | max |\n|---|---:|---:|---:|")
    for k, name in enumerate(("L*", "a*", "b*")):
        print(f"| {name} | {lab[:, k].min():.1f} | {np.median(lab[:, k]):.1f} | {lab[:, k].max():.1f} |")
    print(f"| ITA | {ita.min():.1f} | {np.median(ita):.1f} | {ita.max():.1f} |\n")


def _lips_table(assets, lab: np.ndarray, ita: np.ndarray) -> dict:
    """The lips' albedo (synth.appearance.lips) against the skin's, by ITA category: CIELAB
    lightness, chroma and hue differences (median, min..max)."""
    from synth.appearance.lips import lip_albedo
    from synth.appearance.skin import cielab, ita_category

    lips = cielab(np.array([lip_albedo(a["skin"]["params"]["melanin"], a["skin"]["params"]["haemoglobin"])
                            for a in assets]))

    def lch(x):
        return x[:, 0], np.hypot(x[:, 1], x[:, 2]), np.degrees(np.arctan2(x[:, 2], x[:, 1]))

    (ls, cs, hs), (ll, cl, hl) = lch(lab), lch(lips)
    d = {"dL": ll - ls, "dC": cl - cs, "dh": hl - hs}
    cat = ita_category(ita)
    print("Lips against the skin (lip albedo minus skin albedo, CIELAB; median, min..max):\n")
    print("| ITA category | identities | lips L\\* | ΔL\\* | ΔC\\* | Δh, degrees |\n|---|---:|---:|---:|---:|---:|")
    for k, name in enumerate(CATS):
        m = cat == k
        if not m.any():
            continue
        cells = [f"{np.median(v[m]):+.1f} ({v[m].min():+.1f}..{v[m].max():+.1f})" for v in d.values()]
        print(f"| {name} | {int(m.sum())} | {np.median(ll[m]):.1f} | " + " | ".join(cells) + " |")
    print()
    return {"lab": lips.tolist(), **{k: v.tolist() for k, v in d.items()}}


def skin(args) -> dict:
    from synth.appearance.skin import cielab, individual_typology_angle, skin_albedo
    from synth.assets.catalogue import load_catalogue
    from synth.config import load_config
    from synth.plan.assets import sample_assets_batch

    ids = np.arange(args.identities)
    cfg = load_config()
    assets = sample_assets_batch(args.seed, ids, load_catalogue(None))
    try:
        from synth.plan.skin import apply_skin_tones
        apply_skin_tones(args.seed, ids, assets, cfg.skin)
    except ImportError:  # a checkout without skin-tone sampling (the start): melanin as sampled
        pass
    alb = np.array([skin_albedo(a["skin"]["params"]["melanin"], a["skin"]["params"]["haemoglobin"]) for a in assets])
    lab, ita = cielab(alb), individual_typology_angle(alb)
    print(f"\n### Skin albedo of {len(ids)} planned identities (seed {args.seed})\n")
    _lab_table(lab, ita)
    out = {"albedo": {"lab": lab.tolist(), "ita": ita.tolist()}, "lips": _lips_table(assets, lab, ita)}
    if args.frames:
        rows = _skin_pixels(args.frames)
        if rows:
            a, p = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
            ita_a, ita_p = individual_typology_angle(a), individual_typology_angle(p)
            print(f"### Mean skin pixel of {len(rows)} near-frontal frames (uniform environment)\n")
            _lab_table(cielab(p), ita_p)
            print(f"ITA of the mean skin pixel vs ITA of the albedo: correlation "
                  f"{np.corrcoef(ita_a, ita_p)[0, 1]:.3f}, median difference {np.median(ita_p - ita_a):+.1f} deg, "
                  f"category agreement {np.mean(_cat(ita_a) == _cat(ita_p)):.0%}\n")
            out["pixels"] = {"albedo_ita": ita_a.tolist(), "pixel_ita": ita_p.tolist(), "pixel_lab": cielab(p).tolist()}
    return out


def _polygon_mask(poly: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W) pixels whose centres (synth convention, +0.5) lie inside the polygon (pixels)."""
    y, x = np.mgrid[0:height, 0:width] + 0.5
    inside = np.zeros((height, width), bool)
    p = np.asarray(poly, np.float64)
    for (x0, y0), (x1, y1) in zip(p, np.roll(p, -1, axis=0)):  # even-odd rule, rays toward +x
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < xc)
    return inside


def _skin_pixels(sources) -> list:
    from synth.dataset.reader import iter_frames

    rows = []
    for src in sources:
        for fr in iter_frames(src):
            c = fr.meta["camera"]
            if abs(c["azimuth_deg"]) > 30 or abs(c["elevation_deg"]) > 30 or fr.meta.get("skin") is None:
                continue
            m = (fr.segmentation == 1) & (fr.alpha > 0.99)
            lm = np.asarray(fr.meta["landmarks_2d"], np.float64)
            m &= ~_polygon_mask(lm[48:60], fr.height, fr.width)  # the lips have their own colour
            # the face only: rows above the chin (ibug 8), so neck and bust do not count
            chin = float(lm[8, 1])
            m[int(np.clip(chin, 0, fr.height)):] = False
            if m.sum() < 20:
                continue
            rows.append((fr.meta["skin"]["albedo_linear_srgb"], fr.rgb[m].mean(axis=0)))
    return rows


def plot_skin(args) -> dict:
    """ITA histograms and the L*-b* plane of the planned albedos, before / after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    edges = [-90, -30, 10, 28, 41, 55, 120]
    for path, label in zip(args.inputs, args.labels):
        d = json.loads(Path(path).read_text())["albedo"]
        ita, lab = np.asarray(d["ita"]), np.asarray(d["lab"])
        h = np.histogram(ita, bins=edges)[0][::-1]
        ax[0].bar(np.arange(6) + (0.2 if label == args.labels[-1] else -0.2), h, width=0.4, label=label)
        ax[1].scatter(lab[:, 2], lab[:, 0], s=6, label=label)
    ax[0].set_xticks(np.arange(6), CATS, rotation=20)
    ax[0].set_ylabel("identities")
    ax[0].legend()
    ax[1].add_patch(plt.Rectangle((6, 28), 20, 54, fill=False, ls="--", color="k"))
    ax[1].set_xlabel("b*")
    ax[1].set_ylabel("L*")
    ax[1].set_title("dashed: envelope of published skin colour", fontsize=9)
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    return {}
