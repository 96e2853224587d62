"""The shard specs' frames are written as JSON text (planner.ShardSpecs): the text equals
orjson's serialisation of the frame objects built as dicts, the way a reader sees them."""

from __future__ import annotations

import orjson
import pytest

from synth.assets.catalogue import load_catalogue
from synth.config import load_config
from synth.dataset.layout import frame_key
from synth.plan import io, planner
from tests.support.toy_model import write_toy_model


def frame_dicts(specs: planner.ShardSpecs, n: int, e: int) -> list[dict]:
    """The frames of expression e of identity n as dicts (numpy values), built directly."""
    arr, E, V, N = specs.arr, specs.E, specs.V, specs.N
    p = n * E + e
    i = int(arr.identity[n])
    out = []
    for k in range(N):
        for v in range(V):
            f = {"frame_id": frame_key(i, e, v, k if N > 1 else None), "identity_index": i, "expression_index": e}
            if N > 1:
                f["environment_index"] = k
            f["view_index"] = v
            f["seed"] = int(arr.frame_seeds[p, v])
            f["camera"] = {
                "K": planner._rn(arr.K[p, v]), "world_to_camera": planner._rn(arr.w2c[p, v]),
                "camera_to_world": planner._rn(arr.c2w[p, v]), "width": arr.width, "height": arr.height,
                "near": specs.near, "far": specs.far, "azimuth_deg": planner._r(arr.views.azimuth_deg)[p][v],
                "elevation_deg": planner._r(arr.views.elevation_deg)[p][v],
                "radius_m": planner._r(arr.views.radius_m)[p][v], "target": planner._r(arr.targets[n])}
            out.append(f)
    return out


@pytest.mark.parametrize("environments, expressions, views", [(1, 3, 4), (3, 3, 4), (1, 1, 1), (2, 1, 1)])
def test_frames_text_is_orjsons_text_of_the_frame_objects(tmp_path, environments, expressions, views):
    """(With one view and expression, the second shard's arrays hold one frame.)"""
    toy = write_toy_model(tmp_path / "toy.npz")
    cfg = load_config(None, [f"dataset.expressions_per_identity={expressions}", f"dataset.views_per_expression={views}",
                             "dataset.identities_per_shard=2", "camera.principal_point_jitter_px=3.5",
                             "camera.roll_deg=[-20, 20]", f"dataset.environments_per_expression={environments}"])
    model, _ = planner.model_record(toy)
    arr = planner.sample_plan(cfg, model, load_catalogue(), 11, 4, 3)
    specs = planner.ShardSpecs(cfg, arr, 11)
    got = list(specs.specs())
    assert [sid for sid, _ in got] == ["shard_000002", "shard_000003"]
    n = 0
    for _, spec in got:
        for ident in spec["identities"]:
            for e, rec in enumerate(ident["expressions"]):
                text = orjson.dumps(rec["frames"])
                want = io.dumps_compact(frame_dicts(specs, n, e))
                assert text == want
                assert orjson.dumps(orjson.loads(text)) == text  # as a reader round-trips it
            n += 1
    assert n == 3
