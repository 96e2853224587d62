"""The plan summary: deterministic statistics (no timings), computed per chunk of identities
and merged, so the summary is the same whatever the number of processes."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from synth.plan import cameras, expressions


def partial(arr) -> dict[str, Any]:
    """Mergeable statistics of one chunk (a PlanArrays)."""
    ex, vw = arr.expr, arr.views
    assets: dict[str, dict[str, int]] = {}
    for a in arr.assets:
        for cls, pick in a.items():
            key = pick["id"] if pick else "none"
            assets.setdefault(cls, {})
            assets[cls][key] = assets[cls].get(key, 0) + 1
    V = vw.azimuth_deg.shape[1]
    min_ang = float(cameras.min_pairwise_angle_deg(vw.azimuth_deg, vw.elevation_deg).min()) if V > 1 else 180.0
    return {
        "identities": int(arr.identity.size), "expressions": int(ex.kind.size),
        "kinds": np.bincount(ex.kind, minlength=len(expressions.KINDS)).tolist(),
        "presets": {name: int((ex.preset == j).sum()) for j, name in enumerate(arr.expr_model.preset_names)},
        "skipped": list(arr.expr_model.skipped_presets), "assets": assets, "min_angle": min_ang,
        "candidates": int(vw.candidates.sum()), "candidates_max": int(vw.candidates.max()),
        "restarts": int(vw.restarts.sum()), "code_norms": np.linalg.norm(arr.codes, axis=1).tolist(),
    }


def merge(cfg, parts: list[dict[str, Any]]) -> dict[str, Any]:
    """The summary of a plan from the partial statistics of its chunks (in order)."""
    cam = cfg.camera
    V, N = cfg.dataset.views_per_expression, cfg.dataset.environments_per_expression
    n_id = sum(p["identities"] for p in parts)
    n_ex = sum(p["expressions"] for p in parts)
    kinds = np.sum([p["kinds"] for p in parts], axis=0).tolist()
    presets: dict[str, int] = {}
    assets: dict[str, dict[str, int]] = {}
    for p in parts:
        for k, v in p["presets"].items():
            presets[k] = presets.get(k, 0) + v
        for cls, counts in p["assets"].items():
            dst = assets.setdefault(cls, {})
            for k, v in counts.items():
                dst[k] = dst.get(k, 0) + v
    cand = sum(p["candidates"] for p in parts)
    out = {
        "identities": n_id, "expressions": n_ex, "frames": n_ex * N * V,
        "expression_kinds": dict(zip(expressions.KINDS, map(int, kinds))),
        "expression_presets": presets,
        "presets_unavailable_in_model": parts[0]["skipped"] if parts else [],
        "assets": {c: dict(sorted(v.items())) for c, v in sorted(assets.items())},
        "cameras": {
            "views_per_expression": V,
            "min_separation_deg": cam.min_separation_deg,
            "packing_bound": cameras.max_views(cam.azimuth_deg, cam.elevation_deg, cam.min_separation_deg),
            "smallest_pairwise_angle_deg": round(min(p["min_angle"] for p in parts), 6),
            "candidates_total": cand,
            "acceptance_rate": round(n_ex * V / max(1, cand), 6),
            "candidates_max_per_expression": max(p["candidates_max"] for p in parts),
            "restarts": sum(p["restarts"] for p in parts),
        },
        # fsum is exactly rounded, so the mean does not depend on how the identities were chunked
        "identity_code_norm_mean": round(math.fsum(x for p in parts for x in p["code_norms"]) / max(1, n_id), 6),
    }
    if N > 1:  # (a one-environment summary keeps its bytes)
        out["environments_per_expression"] = N
    return out
