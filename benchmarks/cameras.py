"""Camera rejection sampling: speed and acceptance rate against the minimum angle.

    .venv/bin/python benchmarks/cameras.py            # print the tables (markdown)
    .venv/bin/python benchmarks/cameras.py --write    # also write docs/performance-cameras.md

For each camera region and minimum angle (5 degrees up to the packing-bound limit for 30
views), samples 30 views for 1,300 expressions (100 identities x 13) with the default
budget (20,000 candidates, 8 restarts) and reports: the packing bound, acceptance rate
(views placed / candidates drawn), candidates per expression (mean, 99th percentile),
restarts, expressions that could not be filled, and time per 1,000 expressions.
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from synth.config import CameraConfig  # noqa: E402
from synth.plan import cameras  # noqa: E402

V = 30
N_ID, N_EX = 100, 13
REGIONS = {
    "default: azimuth [-180, 180], elevation [-45, 70]": CameraConfig(),
    "front: azimuth [-90, 90], elevation [-30, 45]": CameraConfig(azimuth_deg=(-90.0, 90.0),
                                                                  elevation_deg=(-30.0, 45.0)),
}


def limit_angle(cam: CameraConfig, n: int) -> float:
    """Largest angle (0.1 degree steps) at which the packing bound still allows n views."""
    lo, hi = 0.1, 180.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if cameras.max_views(cam.azimuth_deg, cam.elevation_deg, mid) >= n:
            lo = mid
        else:
            hi = mid
    return float(np.floor(lo * 10) / 10)


def run(cam: CameraConfig, angle: float) -> dict:
    c = dataclasses.replace(cam, min_separation_deg=angle)
    ii = np.repeat(np.arange(N_ID), N_EX)
    ee = np.tile(np.arange(N_EX), N_ID)
    cameras.sample_views(0, ii[:50], ee[:50], V, c, strict=False)  # warm-up
    t = time.perf_counter()
    v = cameras.sample_views(7, ii, ee, V, c, strict=False)
    dt = time.perf_counter() - t
    ok = v.filled
    return {"angle": angle, "bound": cameras.max_views(c.azimuth_deg, c.elevation_deg, angle),
            "acceptance": V * ok.sum() / max(1, v.candidates[ok].sum()) if ok.any() else 0.0,  # filled ones
            "mean": v.candidates[ok].mean() if ok.any() else float("nan"),
            "p99": np.percentile(v.candidates[ok], 99) if ok.any() else float("nan"),
            "restarts": int(v.restarts.sum()), "failed": int((~ok).sum()), "ms_per_1000": 1e3 * dt / ii.size * 1000}


def table(name: str, cam: CameraConfig) -> str:
    lim = limit_angle(cam, V)
    angles = [a for a in (5, 10, 15, 20, 22.5, 25, 27.5, 30, 35, 40, 45, 50) if a < lim] + [lim]
    rows = [f"**{name}** — {V} views per expression; the packing bound allows {V} views up to {lim}°.", "",
            "| min angle | packing bound | acceptance | candidates/expr (mean) | p99 | restarts | unfilled | "
            "ms / 1000 expr |", "|---|---|---|---|---|---|---|---|"]
    for a in angles:
        r = run(cam, float(a))
        filled = r["failed"] < N_ID * N_EX
        acc, mean, p99 = ((f"{r['acceptance']:.3f}", f"{r['mean']:.0f}", f"{r['p99']:.0f}") if filled
                          else ("—", "—", "—"))
        rows.append(f"| {a:g}° | {r['bound']} | {acc} | {mean} | {p99} | "
                    f"{r['restarts']} | {r['failed']} / {N_ID * N_EX} | {r['ms_per_1000']:.0f} |")
    return "\n".join(rows) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="write the table into docs/performance.md (after its '<!-- table -->' marker)")
    args = ap.parse_args()
    parts = [table(name, cam) for name, cam in REGIONS.items()]
    text = "\n".join(parts)
    print(text)
    if args.write:
        doc = Path(__file__).resolve().parents[1] / "docs" / "performance.md"
        head = doc.read_text().split("<!-- table -->")[0] if doc.exists() else "# Performance\n\n"
        machine = f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, " \
                  f"numpy {np.__version__}"
        tail = doc.read_text().split("<!-- /table -->", 1)[1] if "<!-- /table -->" in doc.read_text() else "\n"
        doc.write_text(f"{head}<!-- table -->\nMeasured with `benchmarks/cameras.py --write` ({machine}).\n\n{text}"
                       f"\n<!-- /table -->{tail}")


if __name__ == "__main__":
    main()
