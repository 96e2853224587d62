"""Measurements on rendered datasets: ``framing``, ``body-end``, ``fringe``, ``timing``, ``sheet``,
``scalp`` (docs/realism.md)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .common import HEAD_NOT_SKIN, _srgb8

def touches_border(seg: np.ndarray, chin_y: float) -> bool:
    """Head classes on the left, right or top border (see the module doc)."""
    top, left, right = seg[0], seg[:, 0], seg[:, -1]
    if np.isin(np.concatenate([top, left, right]), HEAD_NOT_SKIN).any() or (top == 1).any():
        return True
    above = slice(0, int(np.clip(np.floor(chin_y), 0, seg.shape[0])))
    return bool((left[above] == 1).any() or (right[above] == 1).any())


BODY = (1, 9)  # skin (neck, bust) and clothing


ELEVATION_BANDS = ((-90.0, -15.0), (-15.0, 15.0), (15.0, 45.0), (45.0, 90.0))


def body_ends_in_frame(seg: np.ndarray) -> bool:
    """The body (skin, clothing) is in the frame but does not reach its bottom row."""
    body = np.isin(seg, BODY)
    return bool(body.any() and not body[-1].any())


def body_end(args) -> dict:
    from synth.dataset.reader import iter_frames

    out = {}
    bands = " | ".join(f"elevation {a:+.0f} to {b:+.0f}" for a, b in ELEVATION_BANDS)
    print(f"\n| dataset | frames | body ends in the frame | {bands} |")
    print("|---|---:|---:|" + "---:|" * len(ELEVATION_BANDS))
    for src in args.datasets:
        rows = [(body_ends_in_frame(fr.segmentation), float(fr.meta["camera"]["elevation_deg"]))
                for fr in iter_frames(src)]
        flags = np.array([r[0] for r in rows], bool)
        el = np.array([r[1] for r in rows])
        cells, per = [], {}
        for a, b in ELEVATION_BANDS:
            m = (el >= a) & (el < b) if b < 90 else (el >= a)
            per[f"{a:+.0f}..{b:+.0f}"] = [int(flags[m].sum()), int(m.sum())]
            cells.append(f"{flags[m].sum()}/{m.sum()}")
        out[src] = {"frames": len(flags), "ends_in_frame": int(flags.sum()), "by_elevation": per}
        print(f"| {src} | {len(flags)} | {flags.sum()} ({flags.mean():.0%}) | " + " | ".join(cells) + " |")
    return out


def framing(args) -> dict:
    from synth.dataset.reader import iter_frames

    out = {}
    print("\n| dataset | frames | head at the border | fraction | any skin counted (neck, bust) |")
    print("|---|---:|---:|---:|---:|")
    for src in args.datasets:
        flags, loose = [], []
        for fr in iter_frames(src):
            flags.append(touches_border(fr.segmentation, float(np.asarray(fr.meta["landmarks_2d"])[8, 1])))
            loose.append(touches_border(fr.segmentation, fr.height))
        out[src] = {"frames": len(flags), "touching": int(sum(flags)), "touching_any_skin": int(sum(loose))}
        print(f"| {src} | {len(flags)} | {sum(flags)} | {np.mean(flags):.1%} | {np.mean(loose):.1%} |")
    return out


def fringe(args) -> dict:
    """Datasets against a reference dataset of the same plan (more samples): RMS errors over
    the reference's fringe pixels (0.02 < alpha < 0.98) of the composite over mid grey and of
    the alpha, and of the whole composite; median over the frames both have."""
    from synth.dataset.reader import iter_frames

    def comp(fr):
        return fr.rgb_premultiplied.astype(np.float64) + (1.0 - fr.alpha[..., None]) * 0.5

    ref = {fr.meta["frame_id"]: fr for fr in iter_frames(args.reference)}
    out = {}
    print("\n| dataset | frames | fringe pixels | composite, fringe | alpha, fringe | composite, whole image |")
    print("|---|---:|---:|---:|---:|---:|")
    for src in args.datasets:
        rows = []
        for fr in iter_frames(src):
            r = ref.get(fr.meta["frame_id"])
            if r is None:
                continue
            m = (r.alpha > 0.02) & (r.alpha < 0.98)
            e, ea = comp(fr) - comp(r), fr.alpha.astype(np.float64) - r.alpha
            rows.append((int(m.sum()), float(np.sqrt((e[m] ** 2).mean())) if m.any() else 0.0,
                         float(np.sqrt((ea[m] ** 2).mean())) if m.any() else 0.0, float(np.sqrt((e ** 2).mean()))))
        a = np.asarray(rows).reshape(-1, 4)
        out[src] = {"frames": len(rows), "fringe_pixels": int(a[:, 0].sum()), "composite_fringe": float(np.median(a[:, 1])),
                    "alpha_fringe": float(np.median(a[:, 2])), "composite": float(np.median(a[:, 3]))}
        o = out[src]
        print(f"| {src} | {o['frames']} | {o['fringe_pixels']} | {o['composite_fringe']:.4f} | {o['alpha_fringe']:.4f} | "
              f"{o['composite']:.4f} |")
    return out


def timing(args) -> dict:
    out = {}
    print("\n| dataset | frames | Cycles s/frame (median) | Cycles s/frame (mean) |\n|---|---:|---:|---:|")
    for src in args.datasets:
        secs = []
        for log in Path(src, "logs").rglob("*.log"):
            for line in log.read_text(errors="replace").splitlines():
                if line.startswith("{") and '"event": "frame"' in line:
                    m = re.search(r'"render_seconds": ([0-9.eE+-]+)', line)
                    if m:
                        secs.append(float(m.group(1)))
        out[src] = secs
        print(f"| {src} | {len(secs)} | {np.median(secs):.2f} | {np.mean(secs):.2f} |")
    return out


def sheet(args) -> dict:
    """The frames nearest to frontal of the first identities of each dataset, one row per dataset."""
    from PIL import Image

    from synth.dataset.reader import iter_frames

    rows = []
    for src in args.datasets:
        best: dict[int, tuple[float, object]] = {}
        for fr in iter_frames(src):
            c = fr.meta["camera"]
            a = abs(c["azimuth_deg"]) + abs(c["elevation_deg"])
            if fr.identity_index < args.identities and a < best.get(fr.identity_index, (1e9, None))[0]:
                best[fr.identity_index] = (a, fr)
        tiles = [_srgb8(best[i][1]) for i in sorted(best)]
        cols = args.columns or len(tiles)
        for k in range(0, len(tiles), cols):  # one dataset may wrap onto several rows
            row = tiles[k:k + cols]
            row += [np.zeros_like(tiles[0])] * (cols - len(row))
            rows.append(np.concatenate(row, axis=1))
    w = min(r.shape[1] for r in rows)
    Image.fromarray(np.concatenate([r[:, :w] for r in rows], axis=0)).save(args.out)
    return {}


def scalp_measure(seg, rgb_premultiplied, alpha, landmarks_2d, min_pixels: int = 20):
    """One frame of :func:`scalp`: (skin pixels more than 0.6 inter-ocular distances above the
    brows, their median luminance over the face skin's, the hair's over the face skin's), or None
    when scalp, face skin or hair has fewer than ``min_pixels`` pixels."""
    from synth.dataset.segmentation import CLASSES as SEG

    lm = np.asarray(landmarks_2d, np.float64)
    iod = float(np.linalg.norm(lm[45] - lm[36]))
    y = np.arange(seg.shape[0])[:, None]
    skin = seg == SEG["skin"]
    lum = (rgb_premultiplied / np.maximum(alpha[..., None], 1e-6)) @ np.array([0.2126, 0.7152, 0.0722])
    top = skin & (y < lm[17:27, 1].min() - 0.6 * iod)
    face = skin & (y > lm[[36, 45], 1].mean()) & (y < lm[51, 1])
    strands = seg == SEG["hair"]
    if min(top.sum(), face.sum(), strands.sum()) < min_pixels:
        return None
    f = float(np.median(lum[face]))
    return int(top.sum()), float(np.median(lum[top])) / f, float(np.median(lum[strands])) / f


def scalp(args) -> dict:
    """Scalp seen between hair strands: per frame with scalp hair, the skin-class pixels more
    than 0.6 inter-ocular distances above the brows (the scalp, between strands) and the median
    luminance of their colour (alpha divided out) over the face skin's (rows between the eyes
    and the upper lip); the hair's for reference. Medians over frames by hair colour."""
    from synth.dataset.reader import iter_frames

    rows = {}
    for fr in iter_frames(args.dataset):
        hair = (fr.meta["assets"].get("hair") or {})
        if not hair:
            continue
        m = scalp_measure(fr.segmentation, fr.rgb_premultiplied, fr.alpha, fr.meta["landmarks_2d"])
        if m is None:
            continue
        colour = str((hair.get("params") or {}).get("colour") or (hair.get("build") or {}).get("colour"))
        rows.setdefault(colour, []).append(m)
    print(f"\n### Scalp between strands ({args.dataset}; frames with at least 20 such pixels)\n")
    print("| hair colour | frames | scalp pixels (median) | scalp / face luminance | hair / face |\n|---|---:|---:|---:|---:|")
    out = {}
    for colour, r in sorted(rows.items()):
        a = np.asarray(r)
        out[colour] = {"frames": len(r), "pixels": float(np.median(a[:, 0])), "scalp_over_face": float(np.median(a[:, 1])),
                       "hair_over_face": float(np.median(a[:, 2]))}
        print(f"| {colour} | {len(r)} | {np.median(a[:, 0]):.0f} | {np.median(a[:, 1]):.2f} | {np.median(a[:, 2]):.2f} |")
    return out
