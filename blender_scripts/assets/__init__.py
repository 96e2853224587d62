"""Asset rigs: one module per class, one small shared interface.

The classes, their rig modules, segmentation ids and build order are the registry's
(:mod:`synth.assets.classes`); nothing here lists them. A rig module
``blender_scripts.assets.<CLASSES[cls].rig>`` exposes::

    def build(ctx: HeadContext, entry: AssetPick) -> Rig

``entry`` is the plan's choice for the class, a :class:`synth.plan.records.AssetPick`: its
``id``, ``generator``, typed ``params`` (:mod:`synth.assets.params`, where every default
lives) and, for an external pack, ``pack`` (see the shard spec, docs/plan-format.md). ``build`` creates only what that asset needs, links its
objects into the scene, gives every material ``pass_index = CLASSES[cls].segmentation_id``,
and returns a :class:`Rig`. After an expression change the worker updates the head mesh in
place and calls ``rig.update(ctx)``; rigs attached to the surface (hair curves with
Deform Curves on Surface) may have nothing to do there. Shader-layer classes
(``CLASSES[cls].shader_layer``: makeup, iris, skin) edit ``ctx.materials`` instead of creating objects.

Randomness inside a rig (strand roots, jitter) comes only from ``ctx.rng(cls)``, a
generator derived from (run seed, identity index, class slot; ``synth.assets.classes.rig_rng``):
never from a global RNG. The numpy geometry of the rigs lives in :mod:`synth.assets.fit`.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from synth.assets.classes import BUILD_ORDER, CLASSES, rig_rng
from synth.assets.params import AssetPick


@dataclass
class HeadContext:
    """What a rig may read about the head it dresses. Arrays are float64, world metres."""

    data: Any  # synth.model.format.HeadModelData (regions, triangles, uvs, landmarks, extra)
    head: Any  # bpy Object of the head mesh (vertices updated in place per expression)
    materials: dict[int, Any]  # head materials by segmentation class id
    rest_vertices: np.ndarray  # (V, 3) identity applied, neutral expression, no joint rotation
    vertices: np.ndarray  # (V, 3) the current expression
    joint_transforms: np.ndarray  # (J, 4, 4) current
    joint_index: dict[str, int]
    landmarks: dict[str, np.ndarray]  # set -> (L, 3), current
    resolution: int  # max(width, height) of the render, pixels (strand counts scale with it)
    identity_index: int
    run_seed: int
    assets: dict[str, AssetPick] = field(default_factory=dict)  # the identity's chosen assets (class -> pick)
    pixel_m: float | None = None  # metres per pixel on the face in the finest view (None: no resolution rule)

    def rng(self, cls: str) -> np.random.Generator:
        return rig_rng(self.run_seed, self.identity_index, cls)

    def pick(self, cls: str) -> AssetPick | None:
        """The identity's pick of class ``cls`` (None where absent)."""
        e = (self.assets or {}).get(cls)
        return None if not e else AssetPick.coerce(cls, e)


class Rig:
    """Base rig: objects it created, an update hook, and a JSON record of what was built."""

    cls: str = ""

    def __init__(self, cls: str, objects: list | None = None, info: dict | None = None):
        self.cls = cls
        self.objects = list(objects or [])
        self.info = dict(info or {})

    def update(self, ctx: HeadContext) -> None:  # noqa: D401 - hook
        """Follow an expression change (ctx.vertices already applied to ctx.head)."""

    def record(self) -> dict:
        """JSON-able facts about the built asset (strand counts, fitted pose...), for the frame JSON."""
        return dict(self.info)


def rig_module(cls: str, entry: AssetPick):
    if entry.external:
        return importlib.import_module(f"{__name__}.external")
    return importlib.import_module(f"{__name__}.{CLASSES[cls].rig}")


def dress(ctx: HeadContext, assets: Mapping[str, AssetPick | Mapping | None]) -> dict[str, Rig]:
    """Build the chosen assets (only those; absent classes are None) in BUILD_ORDER. Picks
    given as plan-style objects (tests, benchmarks) are checked into records first."""
    ctx.assets = {c: AssetPick.coerce(c, e) for c, e in assets.items() if e}
    rigs: dict[str, Rig] = {}
    for cls in BUILD_ORDER:
        entry = ctx.assets.get(cls)
        if entry is None:
            continue
        mod = rig_module(cls, entry)
        rigs[cls] = mod.build(ctx, entry)
    keep = getattr(rigs.get("garment"), "arm_keep_out", None)
    if keep is not None and hasattr(rigs.get("hair"), "keep_out_of"):
        # hair is groomed before the garment, clear of the skin: it keeps off the sleeves over the
        # upper arms from here on (synth.assets.fit.arms.ArmKeepOut)
        rigs["hair"].keep_out_of(keep, ctx)
    return rigs


def update(rigs: dict[str, Rig], ctx: HeadContext) -> None:
    for cls in BUILD_ORDER:
        if cls in rigs:
            rigs[cls].update(ctx)
