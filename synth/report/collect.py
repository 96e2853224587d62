"""What ``synth report`` reads: the committed frames' JSON, the dataset's plan and the render logs.

Only committed shards are read (a dataset in progress reports what is committed, and counts
what is planned and staged); pixels are not decoded (the contact sheet does that, for a few
frames). :func:`collect` returns a :class:`Collected` of plain arrays and tables;
:meth:`Collected.summary` is the JSON report (``synth report --json``).
"""

from __future__ import annotations

import os
from array import array
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from synth.appearance.skin import individual_typology_angle
from synth.assets.classes import RECORD_ORDER
from synth.dataset.layout import LOGS_DIR, STAGING_DIR, parse_frame_key_env
from synth.dataset.reader import shard_frames
from synth.dataset.shards import load_dataset
from synth.io import loads_json

REPORT_FORMAT = "synth-report/1"


@dataclass
class Collected:
    root: str
    progress: dict
    min_separation_deg: float | None
    identity_codes: np.ndarray  # (identities, Ki)
    expression_codes: np.ndarray  # (identities x expressions, Ke)
    expression_names: list[str]
    expression_kinds: Counter
    expression_presets: Counter
    azimuth_deg: np.ndarray  # (frames,)
    elevation_deg: np.ndarray
    smallest_angle_deg: np.ndarray  # (identities x expressions,): the closest two views
    assets: dict[str, Counter]  # class -> style id (None: absent) -> identities
    ita_deg: np.ndarray  # (identities,)
    visible_landmarks: np.ndarray  # (frames,) fraction of the 68 marked visible
    render: dict = field(default_factory=dict)  # from the logs (synth.report.logs)
    read: dict = field(default_factory=dict)  # what was read: {"shards", "frames"} (all committed, or a sample)

    def summary(self) -> dict:
        """The JSON report: counts, distributions as quantiles, frequency tables."""
        def q(a) -> dict | None:
            a = np.asarray(a, np.float64)
            if a.size == 0:
                return None
            p = np.percentile(a, [0, 5, 50, 95, 100])
            return {"n": int(a.size), "mean": float(a.mean()), "std": float(a.std()), "min": float(p[0]),
                    "p5": float(p[1]), "median": float(p[2]), "p95": float(p[3]), "max": float(p[4])}

        n_id = len(self.identity_codes)
        act = np.abs(self.expression_codes) > 1e-6
        return {
            "format": REPORT_FORMAT, "dataset": self.root, "progress": self.progress, "read": self.read,
            "identities": {"count": n_id, "code_norm": q(np.linalg.norm(self.identity_codes, axis=1)),
                           "first_components": [q(self.identity_codes[:, k]) for k in
                                                range(min(3, self.identity_codes.shape[1] if n_id else 0))]},
            "expressions": {"count": len(self.expression_codes), "kinds": dict(self.expression_kinds),
                            "presets": dict(self.expression_presets),
                            "active_components": q(act.sum(axis=1)) if act.size else None,
                            "activation_rate": {n: float(r) for n, r in zip(self.expression_names, act.mean(axis=0))}
                            if act.size else {}},
            "cameras": {"frames": int(self.azimuth_deg.size), "azimuth_deg": q(self.azimuth_deg),
                        "elevation_deg": q(self.elevation_deg),
                        "smallest_pairwise_angle_deg": q(self.smallest_angle_deg),
                        "min_separation_deg": self.min_separation_deg},
            "assets": {cls: {"present": sum(v for k, v in c.items() if k is not None) / max(n_id, 1),
                             "styles": {str(k): v for k, v in sorted(c.items(), key=lambda kv: -kv[1]) if k is not None}}
                       for cls, c in self.assets.items()},
            "skin_ita_deg": q(self.ita_deg),
            "landmarks_visible_fraction": q(self.visible_landmarks),
            "render": {**{k: v for k, v in self.render.items() if not k.endswith("_seconds")},
                       "frames_timed": len(self.render.get("frame_seconds", {})),
                       "frame_seconds": q(list(self.render.get("frame_seconds", {}).values())),
                       "shard_seconds": q(list(self.render.get("shard_seconds", {}).values())),
                       "seconds_by_shard": self.render.get("shard_seconds", {})},
        }


def _progress(root: Path, ds) -> dict:
    committed = ds.committed_shards() & set(ds.expected)
    staged_frames = staged_shards = 0
    st = root / STAGING_DIR
    if st.is_dir():
        for name in os.listdir(st):
            d = st / name
            if d.is_dir() and name in ds.expected:
                n = sum(1 for f in os.listdir(d) if f.endswith(".json"))
                staged_shards += 1
                staged_frames += n
    return {"shards_planned": len(ds.expected), "shards_committed": len(committed),
            "frames_planned": sum(len(v) for v in ds.expected.values()),
            "frames_committed": sum(len(ds.expected[s]) for s in committed),
            "shards_staged": staged_shards, "frames_staged": staged_frames,
            "complete": len(committed) == len(ds.expected)}


def _min_separation(root: Path) -> float | None:
    p = root / "plan" / "plan.json"
    try:
        return float(loads_json(p.read_bytes())["config"]["camera"]["min_separation_deg"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _view_direction(cam: dict) -> tuple[float, float, float]:
    """The unit viewing direction (camera -> look-at target) of a frame's camera."""
    pos = np.asarray(cam["camera_to_world"], np.float64)[:3, 3]
    v = np.asarray(cam.get("target", (0.0, 0.0, 0.0)), np.float64) - pos
    return tuple((v / np.linalg.norm(v)).tolist())


def _smallest_angles(dirs: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Per (identity, expression) of ``keys`` (N, 2), sorted: the smallest angle between two of
    its views' unit directions ``dirs`` (N, 3); NaN for a single view."""
    if not len(keys):
        return np.zeros(0)
    order = np.lexsort((keys[:, 1], keys[:, 0]))
    k, d = keys[order], dirs[order]
    starts = np.flatnonzero(np.r_[True, (k[1:] != k[:-1]).any(1)])
    out = []
    for a, b in zip(starts, np.r_[starts[1:], len(k)]):
        if b - a < 2:
            out.append(float("nan"))
            continue
        cos = np.clip(d[a:b] @ d[a:b].T, -1.0, 1.0)
        out.append(float(np.degrees(np.arccos(cos[np.triu_indices(b - a, 1)].max()))))
    return np.array(out)


def collect(root, *, max_shards: int | None = None, progress=None) -> Collected:
    """Read a dataset (committed shards only; the first ``max_shards`` of them when given) into
    a :class:`Collected`. The progress counts always cover the whole dataset. Memory: per frame
    a few numbers (angles, landmark visibility, view direction), one shard's references at a
    time."""
    from synth.report.logs import render_log_stats

    root = Path(root)
    ds = load_dataset(root)
    committed = sorted(ds.committed_shards())
    shards = committed[:max_shards]
    total = sum(len(ds.expected[s]) for s in shards)
    ident_codes, ident_seen = {}, {}
    expr_rows, expr_seen = [], set()
    kinds, presets = Counter(), Counter()
    az, el, vis, dirs, dir_keys = array("d"), array("d"), array("d"), array("d"), array("q")
    key_shard: dict[str, str] | None = {} if (root / LOGS_DIR).is_dir() else None  # for the render times
    assets = {c: Counter() for c in RECORD_ORDER}
    ita = {}
    names: list[str] = list((ds.info.get("meta") or {}).get("model", {}).get("expression_names") or [])
    n = 0
    read_shards = set()
    for refs in (shard_frames(root, shards=shards) if shards else ()):
        for ref in refs:
            fj = ref.meta()
            i, e, k, _ = parse_frame_key_env(ref.key)
            read_shards.add(ref.shard)
            if key_shard is not None:
                key_shard[ref.key] = ref.shard
            m, cam = fj["model"], fj["camera"]
            if i not in ident_seen:
                ident_seen[i] = True
                ident_codes[i] = np.asarray(m["identity"], np.float64)
                for c in RECORD_ORDER:
                    rec = (fj.get("assets") or {}).get(c)
                    assets[c][rec.get("id") if rec else None] += 1
                alb = (fj.get("skin") or {}).get("albedo_linear_srgb")
                if alb is not None:
                    ita[i] = float(individual_typology_angle(alb))
            if (i, e) not in expr_seen:
                expr_seen.add((i, e))
                expr_rows.append(np.asarray(m["expression"], np.float64))
                kinds[m.get("expression_kind") or "unknown"] += 1
                if m.get("expression_preset"):
                    presets[m["expression_preset"]] += 1
            az.append(float(cam.get("azimuth_deg", np.nan)))
            el.append(float(cam.get("elevation_deg", np.nan)))
            if k == 0:  # every environment of an expression has the same cameras
                dirs.extend(_view_direction(cam))
                dir_keys.extend((i, e))
            vis.append(float(np.mean(fj["landmarks_visible"])))
            if progress and n % 500 == 0:
                progress(n, total)
            n += 1
    ki = len(next(iter(ident_codes.values()))) if ident_codes else 0
    ke = len(expr_rows[0]) if expr_rows else len(names)
    if len(names) != ke:
        names = [f"e{k}" for k in range(ke)]
    return Collected(
        root=str(root), progress=_progress(root, ds), min_separation_deg=_min_separation(root),
        identity_codes=np.array([ident_codes[i] for i in sorted(ident_codes)]).reshape(len(ident_codes), ki),
        expression_codes=np.array(expr_rows).reshape(len(expr_rows), ke), expression_names=names, expression_kinds=kinds,
        expression_presets=presets, azimuth_deg=np.array(az, np.float64), elevation_deg=np.array(el, np.float64),
        smallest_angle_deg=_smallest_angles(np.frombuffer(dirs).reshape(-1, 3),
                                            np.frombuffer(dir_keys, np.int64).reshape(-1, 2)),
        assets=assets, ita_deg=np.array([ita[i] for i in sorted(ita)]), visible_landmarks=np.array(vis),
        render=render_log_stats(root / LOGS_DIR, committed=key_shard),
        read={"shards": len(read_shards), "frames": n})
