"""python -m benchmarks.realism hair-mix: the planner's hair mix, shares that add up and follow the
manifest (every style of assets_manifest/hair.toml drawn, the bald share near 1 - presence)."""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

from benchmarks.realism import assets

MANIFEST = Path(__file__).resolve().parents[2] / "assets_manifest" / "hair.toml"


def test_the_hair_mix_adds_up_and_follows_the_manifest(capsys):
    res = assets.hair_mix(argparse.Namespace(identities=3000, seed=0))
    shares = {s: r["share"] for s, r in res["styles"].items()}
    assert abs(sum(shares.values()) - 1.0) < 1e-9 and abs(sum(res["colours"].values()) - 1.0) < 1e-9
    man = tomllib.loads(MANIFEST.read_text())
    assert {a["id"] for a in man["assets"]} <= set(shares)
    bald = shares["(none: bald or shaved)"]
    assert abs(bald - (1.0 - man["presence"])) < 0.03  # rules may take a little more
    assert "| style | share |" in capsys.readouterr().out
