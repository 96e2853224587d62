"""What a strand rig builds, and how its strands stay attached; numpy, no bpy.

A groom module (``synth.assets.fit.hair``, ``beard``, ``eyebrows``, ``eyelashes``) starts from
:func:`setup` (the rig's generator, the style id, the head surface, reference points and the
pigment, drawn first) and returns a :class:`Groom`: the strands, their roots, the push-out
clearances, the Geometry Nodes :class:`Styling`, the pigment and the record. The Blender rig
(``blender_scripts.assets.strands.StrandRig``) turns a Groom into a Curves object.

Attachment. The head's UV map "UVMap" cannot drive Blender's Deform Curves on Surface: the
eye meshes' UVs cover the whole unit square, overlapping the skin islands, so a UV -> surface
lookup is ambiguous. Instead every strand stores the triangle and barycentric coordinates of
its root and its points in the local frame of that triangle (:func:`attach`).
:meth:`Attachment.positions` re-places every strand rigidly with the frame of its root
triangle on the current head vertices (roots land exactly on the surface; no rebuild, no new
random numbers) and pushes points that ended up inside the head back out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from synth.appearance import pigment as pig
from synth.assets.fit.keepout_solid import KeepOut
from synth.assets.fit.strands import Surface
from synth.assets.params import AssetPick, BeardParams, EyebrowParams, HairParams, Params


@dataclass
class Styling:
    """Geometry Nodes styling stack (Blender's bundled procedural hair node groups)."""

    root_radius: float = 4e-5
    tip_shape: float = 0.5  # Set Hair Curve Profile "Shape" (taper toward the tip)
    frizz: float = 0.0  # Frizz Hair Curves "Distance" (m)
    frizz_shape: float = 0.5
    clump: float = 0.0  # Clump Hair Curves "Factor"
    clump_distance: float = 0.01
    clump_shape: float = 0.5
    seed: int = 0


def profile(t, shape: float) -> np.ndarray:
    """A strand's radius over its root radius at spline parameter ``t`` (0 root, 1 tip) as
    Blender's bundled "Set Hair Curve Profile" sets it with Factor Min 0, Max 1 and ``shape``
    (``Styling.tip_shape``): ``(1 - t)^(-log2(1 - shape))`` for shape in [0, 0.5] (a full strand
    that thins toward the tip: 0 none, 0.5 linear), ``1 - t^(-log2 shape)`` for shape in
    [0.5, 1) (thin from near the root), mirrored (``t`` -> ``1 - t``) for negative shapes.
    Checked against the node group in tests/blender/test_strands.py."""
    t = np.asarray(t, np.float64)
    s = float(shape)
    if s < 0.0:
        return profile(1.0 - t, -s)
    if s <= 0.5:
        return (1.0 - t) ** (-np.log2(1.0 - s))
    return 1.0 - t ** (-np.log2(s))


def head_frame(ctx) -> dict:
    """Head-centric reference points from the scalp and landmarks (current vertices)."""
    V = np.asarray(ctx.vertices, np.float64)
    sc = V[ctx.data.regions["scalp"]]
    lo, hi = sc.min(0), sc.max(0)
    lm = ctx.landmarks.get("ibug68")
    top = hi[2]
    c = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), top - 0.095])
    f = {"centre": c, "top": top, "scalp_lo": lo, "scalp_hi": hi}
    if lm is not None:
        f["brow_z"] = float(lm[17:27, 2].max())
        f["eye_z"] = float(lm[36:48, 2].mean())
        f["chin"] = lm[8]
        f["lm"] = lm
    else:
        f["brow_z"] = c[2] + 0.01
        f["eye_z"] = c[2]
    return f


def _planned_colour(entry: AssetPick | None) -> str | None:
    """The pigment a hair, beard or eyebrow pick names (None: none, or not a known pigment)."""
    if entry is None or not isinstance(entry.params, (HairParams, BeardParams, EyebrowParams)):
        return None
    col = entry.params.colour
    return col if col in pig.COLOURS else None


def colour_of(entry: AssetPick | None, ctx, default: str = "dark_brown") -> str:
    """The pigment of a strand pick: its own colour, else the hair's, else ``default``."""
    return _planned_colour(entry) or _planned_colour(ctx.pick("hair")) or default


@dataclass
class StrandSetup:
    """What every strand rig starts from (the rng has already drawn the pigment)."""

    rng: np.random.Generator
    sid: str
    prm: Params
    surface: Surface
    hf: dict
    colour: str
    pg: object


def setup(ctx, entry: AssetPick | Mapping, cls: str, default_colour: str = "dark_brown") -> StrandSetup:
    """What a strand rig of class ``cls`` starts from (``entry``: the plan's pick; a plan-style
    object is checked into one)."""
    entry = AssetPick.coerce(cls, entry)
    rng = ctx.rng(cls)
    colour = colour_of(entry, ctx, default_colour)
    return StrandSetup(rng, entry.id, entry.params, Surface(ctx),
                       head_frame(ctx), colour, pig.sample(colour, rng))


@dataclass
class Groom:
    """The strands of one asset, ready for the rig."""

    cls: str  # asset class
    name: str  # object and material name
    surface: Surface
    pts: np.ndarray  # (N, P, 3) world points, roots first
    tri: np.ndarray  # (N,) root triangles
    bary: np.ndarray  # (N, 3) root barycentrics
    clearance: np.ndarray | float  # push-out clearance per strand or point
    styling: Styling
    info: dict
    pigment: pig.HairPigment
    roughness: float
    coat: float = 0.0
    exact: bool = False  # exact (per-triangle) push-out on update (small strand sets)
    keep_out: tuple[str, ...] = ()  # closed-mesh regions the strands pivot out of (lashes: eyeballs)
    keep_skin: bool = False  # the skin near the roots joins the keep-out; strands bend out of it (lashes)
    #: the shader's per-strand variation beyond the BSDF's own (blender_scripts.assets.strands.hair_material):
    #: the share of the melanin gone at the tip, and the +- range of the Melanin Redness per strand
    tip_lightening: float = 0.0
    redness_jitter: float = 0.0


@dataclass
class Attachment:
    """Strands attached by (root triangle, barycentrics) and triangle-local shapes."""

    tri: np.ndarray
    bary: np.ndarray
    local: np.ndarray  # (N, P, 3) points relative to the root, in the root triangle frame
    clearance: np.ndarray  # (N, P) push-out clearance per point (root: -inf)
    #: exact (per-triangle) collision push-out; the small strand sets (brows, lashes, beards)
    #: use it, scalp hair uses the fast nearest-vertex test only (update speed)
    exact: bool = False
    #: closed-mesh regions (the eyeballs for lashes) the strands stay out of: strands are turned
    #: about their roots out of them before the push-out and single points projected out after it
    keep_out: tuple[str, ...] = ()
    #: the skin near the roots joins the keep-out (lashes: the opposite lid of a closed eye):
    #: strands bend out of it joint by joint (``KeepOut.bend``)
    keep_skin: bool = False

    def keep(self, surface: Surface, root: np.ndarray) -> KeepOut | None:
        """The keep-out on ``surface``: the ``keep_out`` meshes and, with ``keep_skin``, the skin
        within twice the longest strand (plus 1 mm) of the roots, which holds the closest skin
        point of every strand point."""
        if not self.keep_out:
            return None
        reach = 2.0 * float(np.linalg.norm(np.diff(self.local, axis=1), axis=2).sum(1).max(initial=0.0)) + 1e-3
        return KeepOut(surface, self.keep_out, root if self.keep_skin else None, reach)

    def clear(self, keep: KeepOut | None, pts: np.ndarray) -> np.ndarray:
        """Strands turned out of the keep-out meshes (rigidly about the root), then bent out of
        the skin (joint by joint), as declared."""
        if keep is None:
            return pts
        pts = keep.pivot(pts, self.clearance)
        return keep.bend(pts, self.clearance) if self.keep_skin else pts

    def positions(self, ctx) -> np.ndarray:
        """The strands on the current head of ``ctx`` (``vertices``, ``data``)."""
        surface = Surface(ctx)
        root = surface.points(self.tri, self.bary)
        F = surface.frames(self.tri)
        pts = root[:, None] + np.einsum("ndk,npk->npd", F, self.local)
        fin = np.isfinite(self.clearance)
        keep = self.keep(surface, root)
        pts = self.clear(keep, pts)
        if fin.any() and not self.keep_skin:
            c = np.where(fin, self.clearance, -1.0)
            # the fast nearest-vertex test reads the tangent plane of a vertex across a thin lid
            # fold and pushes lash points through it into the eye: exact sets near a keep-out
            # mesh take the exact test alone
            fast = not (self.exact and keep is not None)
            moved = surface.push_out(pts, c, iterations=2) if fast else pts
            if self.exact:
                moved = surface.push_out_exact(moved, c)
            pts = np.where(fin[..., None], moved, pts)
        if keep is not None:
            pts = keep.project(pts, self.clearance)
        pts[:, 0] = root
        return pts


def attach(g: Groom) -> tuple[np.ndarray, Attachment]:
    """The groom's points with the roots put exactly on the surface, and their attachment."""
    pts = np.asarray(g.pts, np.float64)
    root = g.surface.points(g.tri, g.bary)
    pts[:, 0] = root
    if not np.all(np.isfinite(pts)):
        raise FloatingPointError(f"{g.cls}: non-finite strand points")
    F = g.surface.frames(g.tri)
    local = np.einsum("npd,ndk->npk", pts - root[:, None], F)
    clr = np.broadcast_to(np.asarray(g.clearance, np.float64), pts.shape[:2]).copy()
    clr[:, 0] = -np.inf
    return pts, Attachment(g.tri, g.bary, local, clr, bool(g.exact), tuple(g.keep_out), bool(g.keep_skin))
