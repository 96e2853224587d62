"""The USD export read by Blender's own importer (bpy 4.5, in a subprocess: bpy bundles its own
USD, apart from usd-core's pxr): every camera keeps its parent (the ``cameras`` Scope), the time
codes become frames one to one at Blender's 24 fps, and the head at frame e is the exported
head at time code e (docs/export.md, "USD")."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("bpy")
pytest.importorskip("pxr", reason="usd-core is not installed (the `export` extra)")

pytestmark = pytest.mark.blender

PROBE = """
import json, sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1])
sc = bpy.context.scene
out = {"fps": sc.render.fps / sc.render.fps_base, "range": [sc.frame_start, sc.frame_end],
       "parents": {o.name: o.parent.name if o.parent else None for o in bpy.data.objects}, "head": {}}
head = bpy.data.objects["head"]
for f in range(sc.frame_start, sc.frame_end + 1):
    sc.frame_set(f)
    me = head.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    out["head"][f] = [list(v.co) for v in me.vertices[:50]]
print("PROBE" + json.dumps(out))
"""


def test_blender_imports_cameras_under_their_scope_and_time_codes_as_frames(tmp_path):
    from pxr import Usd, UsdGeom

    from synth.export.usd import export_usd
    from tests.support.datasets import model_dataset

    ds, model = model_dataset(tmp_path / "ds", identities=1, expressions=3, views=2)
    export_usd(ds, tmp_path / "s.usdc", model=model)
    p = subprocess.run([sys.executable, "-c", PROBE, str(tmp_path / "s.usdc")], capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.split("PROBE", 1)[1])
    assert got["parents"]["v00"] == got["parents"]["v01"] == "cameras"
    assert got["parents"]["cameras"] == "id000000"
    assert got["fps"] == 24 and got["range"] == [0, 2]
    stage = Usd.Stage.Open(str(tmp_path / "s.usdc"))
    head = UsdGeom.Mesh(stage.GetPrimAtPath("/World/id000000/head"))
    for e in range(3):
        want = np.asarray(head.GetPointsAttr().Get(e))[:50]
        assert np.abs(np.asarray(got["head"][str(e)]) - want).max() < 1e-6, e
