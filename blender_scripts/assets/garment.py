"""Procedural upper-body garments (``procedural:garment_shell``), fitted non-rigidly to the bust.

Every garment is one mesh object (segmentation class ``clothing``, pass index 9) built from
the body itself, so it fits any identity (tested at +-3 SD):

1. **Shell**: the skin triangles of the ``neck`` and ``shoulders`` regions are clipped exactly
   at a neckline field ``z_nl(theta) - z`` (``fitting.clip_by_field``; theta is the angle
   around the neck base ring, ``fitting.NeckFrame``), subdivided once, and offset along the
   interpolated body normals by the fabric thickness plus small outward-only wrinkles. The
   neckline per garment: crew, V (depth from ``neckline_depth_m``), turtleneck collar
   (``collar_height_m``, capped 1.2 cm under the jaw line), deep V with raised lapels
   (``lapel_width_m``) for jackets and coats, scoop + straps (``strap_width_m``) for tank tops.
2. **Add-ons**: ribbed / rolled rims as tubes along the neckline loop, shirt collars (a band
   clipped from the neck surface plus swept leaves folded outward), hoods (up: a smoothed
   offset of the head behind the face opening; down: a flattened tube on the upper back),
   drawstrings, ties, scarves (loop / drape / knot, ``scarf_thickness_m``) as swept tubes.
3. **Fit**: vertices deep inside another body part (a chin sunk into the chest at -3 SD) are
   trimmed with their faces; every other vertex closer than ``CLEARANCE`` to the skin (or
   inside it) is moved to the closest skin point + ``CLEARANCE`` along the normal
   (``fitting.push_out``, signed distance from the interpolated normal at the closest point).
4. **Update**: every vertex is bound (``fitting.Binding``) to its closest neck/shoulder (or,
   for hoods, head) triangle in a local frame; ``update`` re-applies the binding to the new
   head vertices and runs the push-out again (about 0.1 s), so the garment follows expressions
   and a jaw opening never pushes the chin through the collar.

Materials: Principled BSDF per ``fabric`` (roughness, sheen, knit stitches at
``knit_scale_m``, twill, fleece fuzz, leather grain) with procedural wrinkle bump; colour from
``colour_hsv`` (a name in :data:`COLOURS` or an ``[h, s, v]`` triple; ``striped_blue``,
``check`` and ``tartan`` are patterns).
"""

from __future__ import annotations

import colorsys

import numpy as np

from blender_scripts.assets import HeadContext, Rig, SEGMENTATION_CLASS
from blender_scripts.assets import fitting as fit
from synth.dataset.segmentation import CLASSES

#: minimum distance (m) kept between every garment vertex and the skin
CLEARANCE = 0.0015
#: vertices deeper than this inside the skin after shaping are trimmed, not pushed
TRIM_DEPTH = 0.006

#: colour names -> sRGB HSV (h, s, v in [0, 1])
COLOURS = {
    "white": (0.0, 0.0, 0.92), "black": (0.0, 0.0, 0.06), "grey": (0.0, 0.0, 0.45), "charcoal": (0.6, 0.05, 0.22),
    "navy": (0.62, 0.7, 0.28), "red": (0.99, 0.8, 0.7), "green": (0.36, 0.6, 0.45), "blue": (0.6, 0.7, 0.7),
    "yellow": (0.14, 0.8, 0.9), "brown": (0.07, 0.65, 0.35), "pink": (0.95, 0.35, 0.95), "cream": (0.12, 0.15, 0.92),
    "burgundy": (0.97, 0.75, 0.38), "camel": (0.09, 0.5, 0.72), "light_blue": (0.58, 0.3, 0.92),
    "striped_blue": (0.6, 0.6, 0.75), "check": (0.0, 0.7, 0.6), "beige": (0.1, 0.25, 0.82), "olive": (0.2, 0.6, 0.4),
    "teal": (0.5, 0.7, 0.5), "tartan": (0.0, 0.75, 0.55), "mustard": (0.13, 0.8, 0.8), "khaki": (0.12, 0.35, 0.7),
}

#: fabric -> (thickness m, roughness, sheen weight, surface kind)
FABRICS = {
    "cotton_jersey": (0.0025, 0.85, 0.3, "jersey"), "wool_knit": (0.005, 0.95, 0.6, "knit"),
    "cotton_knit": (0.004, 0.9, 0.4, "knit"), "cotton_fleece": (0.006, 0.95, 0.7, "fleece"),
    "cotton_poplin": (0.002, 0.6, 0.15, "woven"), "oxford": (0.0025, 0.7, 0.2, "twill"),
    "linen": (0.0025, 0.8, 0.2, "woven"), "wool_suiting": (0.004, 0.7, 0.3, "twill"),
    "tweed": (0.005, 0.95, 0.4, "tweed"), "cotton_twill": (0.0035, 0.8, 0.2, "twill"),
    "wool_felt": (0.006, 0.9, 0.5, "felt"), "gabardine": (0.004, 0.6, 0.2, "twill"),
    "leather": (0.003, 0.35, 0.0, "leather"), "denim": (0.004, 0.85, 0.1, "twill"),
    "pique": (0.003, 0.85, 0.25, "knit"), "scrub": (0.0025, 0.75, 0.15, "woven"),
}

_DEFAULT_FABRIC = {"tshirt_crew": "cotton_jersey", "tshirt_vneck": "cotton_jersey", "sweater": "wool_knit",
                   "turtleneck": "wool_knit", "hoodie": "cotton_fleece", "shirt_collar": "cotton_poplin",
                   "jacket_blazer": "wool_suiting", "coat": "wool_felt", "uniform": "scrub",
                   "tank_top": "cotton_jersey", "scarf_over_sweater": "wool_knit"}


# ----------------------------------------------------------------------------- colours & materials

def colour_rgb(value) -> tuple[float, float, float]:
    """Linear RGB from a colour name or an (h, s, v) triple (sRGB-encoded HSV)."""
    if isinstance(value, str):
        hsv = COLOURS.get(value, COLOURS["grey"])
    else:
        hsv = tuple(float(x) for x in value)[:3]
    r, g, b = colorsys.hsv_to_rgb(*hsv)

    def lin(c):
        return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4

    return (lin(r), lin(g), lin(b))


def cloth_material(name: str, cls: str, colour, fabric: str, knit_scale: float = 0.005, seed: float = 0.0):
    """Principled cloth: colour (or pattern), roughness and sheen per fabric, a procedural
    stitch / weave bump and low-frequency wrinkle bump (object space, so it follows the mesh)."""
    import bpy

    thick, rough, sheen, kind = FABRICS.get(fabric, FABRICS["cotton_jersey"])
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.pass_index = CLASSES[cls]
    nt = mat.node_tree
    nodes, links = nt.nodes, nt.links
    bsdf = nodes["Principled BSDF"]
    coord = nodes.new("ShaderNodeTexCoord")
    rgb = colour_rgb(colour)
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    if isinstance(colour, str) and colour in ("striped_blue", "check", "tartan"):
        if colour == "striped_blue":
            tex = nodes.new("ShaderNodeTexWave")
            tex.wave_type = "BANDS"
            tex.bands_direction = "X"
            tex.inputs["Scale"].default_value = 60.0
            step = nodes.new("ShaderNodeMath")
            step.operation = "GREATER_THAN"
            step.inputs[1].default_value = 0.7
            links.new(tex.outputs["Fac"], step.inputs[0])
            fac = step.outputs["Value"]
            c2 = (0.85, 0.85, 0.85)
        else:
            tex = nodes.new("ShaderNodeTexChecker")
            tex.inputs["Scale"].default_value = 40.0 if colour == "check" else 25.0
            fac = tex.outputs["Fac"]
            c2 = (0.8, 0.8, 0.78) if colour == "check" else (0.02, 0.08, 0.03)
        links.new(coord.outputs["Object"], tex.inputs["Vector"])
        mix = nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        mix.inputs["A"].default_value = (*rgb, 1.0)
        mix.inputs["B"].default_value = (*c2, 1.0)
        links.new(fac, mix.inputs["Factor"])
        links.new(mix.outputs["Result"], bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = rough
    bsdf.inputs["Sheen Weight"].default_value = sheen
    bsdf.inputs["Sheen Roughness"].default_value = 0.5
    # wrinkles: stretched low-frequency noise
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (1.0, 1.0, 0.35)
    links.new(coord.outputs["Object"], mapping.inputs["Vector"])
    wr = nodes.new("ShaderNodeTexNoise")
    wr.noise_dimensions = "4D"
    wr.inputs["W"].default_value = float(seed)
    wr.inputs["Scale"].default_value = 18.0
    wr.inputs["Detail"].default_value = 2.0
    links.new(mapping.outputs["Vector"], wr.inputs["Vector"])
    bump1 = nodes.new("ShaderNodeBump")
    bump1.inputs["Strength"].default_value = 0.35
    bump1.inputs["Distance"].default_value = 0.002
    links.new(wr.outputs["Fac"], bump1.inputs["Height"])
    # fine structure per fabric
    scale = 1.0 / max(float(knit_scale), 1e-3)
    if kind == "knit":
        fine = nodes.new("ShaderNodeTexWave")
        fine.wave_type = "BANDS"
        fine.bands_direction = "X"
        fine.inputs["Scale"].default_value = scale * 0.5
        fine.inputs["Distortion"].default_value = 2.0
        strength, dist = 0.6, 0.001
    elif kind in ("twill", "tweed"):
        fine = nodes.new("ShaderNodeTexWave")
        fine.wave_type = "BANDS"
        fine.bands_direction = "DIAGONAL"
        fine.inputs["Scale"].default_value = 250.0
        strength, dist = 0.25 if kind == "twill" else 0.5, 0.0003
    else:
        fine = nodes.new("ShaderNodeTexNoise")
        fine.inputs["Scale"].default_value = {"fleece": 400.0, "felt": 600.0, "leather": 300.0}.get(kind, 800.0)
        strength, dist = {"fleece": 0.3, "felt": 0.2, "leather": 0.15}.get(kind, 0.1), 0.0003
    links.new(coord.outputs["Object"], fine.inputs["Vector"])
    bump2 = nodes.new("ShaderNodeBump")
    bump2.inputs["Strength"].default_value = strength
    bump2.inputs["Distance"].default_value = dist
    links.new(fine.outputs["Fac"], bump2.inputs["Height"])
    links.new(bump1.outputs["Normal"], bump2.inputs["Normal"])
    links.new(bump2.outputs["Normal"], bsdf.inputs["Normal"])
    mat["fabric"] = fabric
    return mat


# ----------------------------------------------------------------------------- mesh object helpers

def mesh_object(name: str, P: np.ndarray, faces: np.ndarray, mat_index: np.ndarray, materials: list):
    from blender_scripts.mesh import link_object, new_triangle_mesh

    return link_object(name, new_triangle_mesh(name, P, faces, mat_index), materials)


class Parts:
    """Accumulates mesh parts: (positions, faces, material slot, trimmable)."""

    def __init__(self):
        self.P, self.F, self.M, self.T = [], [], [], []

    def add(self, P, F, slot: int = 0, trim: bool = False):
        if len(F) == 0:
            return
        self.P.append(np.asarray(P, np.float64))
        self.F.append(np.asarray(F, np.int64))
        self.M.append(np.full(len(F), slot, np.int32))
        self.T.append(np.full(len(P), trim))

    def merged(self):
        off = np.cumsum([0] + [len(p) for p in self.P])
        P = np.concatenate(self.P)
        F = np.concatenate([f + o for f, o in zip(self.F, off[:-1])])
        return P, F, np.concatenate(self.M), np.concatenate(self.T)


class FittedRig(Rig):
    """A mesh bound to body triangles; ``update`` re-applies the binding and pushes out."""

    def __init__(self, cls, ob, binding, body_tris, clearance, info):
        super().__init__(cls, [ob], info)
        self.binding = binding
        self.body_tris = body_tris
        self.clearance = clearance

    def update(self, ctx: HeadContext) -> None:
        P = self.binding.apply(ctx.vertices)
        q = fit.SurfaceQuery(ctx.vertices, ctx.data.triangles, self.body_tris)
        P = fit.push_out(P, q, self.clearance, iterations=6)
        from blender_scripts.mesh import set_positions

        set_positions(self.objects[0], P)


def finish(ctx: HeadContext, parts: Parts, body: "Body", anchor_tris: np.ndarray, name: str, materials: list,
           cls: str, clearance: float, info: dict) -> FittedRig:
    """Trim deep vertices of trimmable parts, push out, bind, create the object."""
    P, F, M, T = parts.merged()
    sd = body.query.signed_distance(P)
    deep = T & (sd < -TRIM_DEPTH)
    keep = ~deep[F].any(1)
    P, F, used = fit.remove_faces(P, F, keep)
    M = M[keep]
    P = fit.push_out(P, body.query, clearance, iterations=6)
    binding = fit.Binding(ctx.vertices, ctx.data.triangles, anchor_tris, P)
    ob = mesh_object(name, P, F, M, materials)
    info = dict(info, vertices=int(len(P)), faces=int(len(F)), trimmed_vertices=int(deep.sum()))
    return FittedRig(cls, ob, binding, body.skin_tris, clearance, info)


# ----------------------------------------------------------------------------- body

class Body:
    """Body arrays for one build: skin query, source triangles, neck frame, normals."""

    def __init__(self, ctx: HeadContext):
        d = ctx.data
        self.V = np.asarray(ctx.vertices, np.float64)
        self.F = np.asarray(d.triangles, np.int64)
        n = len(self.V)
        skin = fit.region_mask(n, d.regions, ["skin"])
        self.skin_tris = np.nonzero(skin[self.F].all(1))[0]
        self.query = fit.SurfaceQuery(self.V, self.F, self.skin_tris)
        self.N = fit.vertex_normals(self.V, self.F[self.skin_tris])
        ns = fit.region_mask(n, d.regions, ["neck", "shoulders"]) & skin
        self.torso_tris = np.nonzero(ns[self.F].all(1))[0]
        hd = fit.region_mask(n, d.regions, ["neck", "scalp", "ears", "face"]) & skin
        self.head_tris = np.nonzero(hd[self.F].all(1))[0]
        self.frame = fit.NeckFrame(self.V, self.F, d.regions, ctx.landmarks["ibug68"])
        self.lm = np.asarray(ctx.landmarks["ibug68"], np.float64)

    def shell(self, tris: np.ndarray, field: np.ndarray, offset_fn, subdiv: int = 1):
        """Clip ``tris`` at ``field >= 0``, subdivide, offset by ``offset_fn(base points, normals)``.
        Returns (P, faces, cut mask)."""
        W, faces, cut = fit.clip_by_field(self.F[tris], field, len(self.V))
        if len(faces) == 0:
            return np.zeros((0, 3)), faces, cut
        for _ in range(subdiv):
            W, faces, cut = fit.subdivide(W, faces, cut)
        base = np.asarray(W @ self.V)
        nrm = fit.normalize(np.asarray(W @ self.N))
        P = base + nrm * np.asarray(offset_fn(base, nrm))[:, None]
        return P, faces, cut

    def neck_loop(self, z_fn, n: int = 48, angle0: float = 0.0) -> np.ndarray:
        """Loop on the neck/shoulder surface where ``z == z_fn(theta)``, resampled at ``n``
        equal angles around the neck (index 0 at theta = angle0 - pi)."""
        f = z_fn(self.frame.theta(self.V)) - self.V[:, 2]
        pts = fit.level_points(self.V, self.F[self.torso_tris], f)
        return fit.resample_loop(pts, self.frame.center, n, angle0)


# ----------------------------------------------------------------------------- garment pieces

def _front(th):
    return np.maximum(np.cos(th), 0.0)


def _crew(body: Body, rise: float, drop: float):
    fr = body.frame

    def z(th):
        return np.minimum(fr.z_ring(th) + rise + 0.008 * (1 - np.cos(th)) - drop * _front(th) ** 3, fr.z_cap(th))
    return z


def _vee(body: Body, rise: float, depth: float, half_angle: float):
    fr = body.frame

    def z(th):
        v = depth * np.maximum(0.0, 1.0 - np.abs(th) / half_angle)
        return np.minimum(fr.z_ring(th) + rise + 0.008 * (1 - np.cos(th)) - v, fr.z_cap(th))
    return z


def _wrinkle_offset(rng, base_off: float, amp: float, wavelength: float = 0.05):
    noise = fit.WaveNoise(rng, wavelength, 14, stretch=(1.0, 1.0, 0.35))

    def off(P, N):
        return base_off + amp * (0.5 + 0.5 * noise(P))
    return off


def _shell_part(body: Body, parts: Parts, z_fn, off_fn, slot=0, extra_field=None, rim: float = 0.0,
                rim_slot=None, rim_flatten: float = 1.0):
    """Torso shell under the neckline ``z_fn``, with an optional rim tube on the cut."""
    th = body.frame.theta(body.V)
    f = z_fn(th) - body.V[:, 2]
    if extra_field is not None:
        f = extra_field(f)
    P, F, cut = body.shell(body.torso_tris, f, off_fn)
    parts.add(P, F, slot, trim=True)
    if rim > 0 and len(F):
        for loop in fit.boundary_loops(F):
            if cut[loop].mean() < 0.8 or len(loop) < 8:
                continue
            path = P[loop]
            # push the rim centre out so the tube sits on the shell
            c, _, _, _, n = body.query.closest(path)
            path = path + fit.normalize(path - c) * rim * 0.6
            Vt, Ft = fit.sweep_tube(path[::2] if len(path) > 60 else path, rim, 8, closed=True, flatten=rim_flatten)
            parts.add(Vt, Ft, slot if rim_slot is None else rim_slot)
    return P, F, cut


def _shirt_collar(body: Body, parts: Parts, slot: int, base_off: float, open_front: bool, band_h: float = 0.03,
                  leaf: float = 0.045, n: int = 56):
    """Standing band on the neck (clipped from the neck surface) + leaves folded down/out."""
    fr = body.frame
    gap = 0.22 if open_front else 0.07

    def z_lo(t):
        return np.minimum(fr.z_ring(t) + 0.004 + 0.008 * (1 - np.cos(t)), fr.z_cap(t) - band_h)

    def z_hi(t):
        return np.minimum(z_lo(t) + band_h, fr.z_cap(t))

    th = fr.theta(body.V)
    z = body.V[:, 2]
    f = np.minimum(np.minimum(z - z_lo(th), z_hi(th) - z), np.abs(th) - gap)
    P, F, _ = body.shell(body.torso_tris, f, lambda p, nrm: np.full(len(p), base_off + 0.002))
    parts.add(P, F, slot, trim=True)
    # leaves: from the band top outward and down
    top = body.neck_loop(z_hi, n, angle0=np.pi)  # index 0 at theta = 0 (front), seam in front
    tt = fr.theta(top)
    keep = np.abs(tt) >= gap
    # order from +gap ... around the back ... to -gap
    order = np.argsort(np.mod(tt[keep], 2 * np.pi))
    top = top[keep][order]
    c, _, _, _, _ = body.query.closest(top)
    top = c + fr.outward(top) * (base_off + 0.004)
    out = fr.outward(top)
    front = _front(fr.theta(top))
    rows = []
    for s in np.linspace(0.0, 1.0, 5):
        down = leaf * (1.0 + 0.5 * front ** 4) * np.sin(s * np.pi / 2)
        o = (0.004 + 0.018 * s) * (1.0 + 0.5 * front)
        rows.append(top + out * o[:, None] - np.outer(down, [0.0, 0.0, 1.0]))
    G = np.stack(rows, 1)  # (n_around, 5, 3)
    Pl = G.reshape(-1, 3)
    Pl = fit.push_out(Pl, body.query, base_off + 0.003)
    parts.add(Pl, fit.grid_faces(G.shape[0], G.shape[1]), slot)
    return top


def _tie(body: Body, parts: Parts, slot: int, base_off: float):
    fr = body.frame
    knot_z = min(float(fr.z_ring(0.0)) + 0.012, float(fr.z_cap(0.0)) - 0.02)
    top = body.neck_loop(lambda t: np.full_like(t, knot_z), 48, angle0=np.pi)[0]
    zs = np.linspace(knot_z - 0.015, body.V[:, 2].min() + 0.005, 12)
    path = np.stack([np.zeros_like(zs) + top[0], np.full_like(zs, top[1] - 0.03), zs], 1)
    path = fit.push_out(path, body.query, base_off + 0.006)
    path = fit.laplacian_smooth(path, np.stack([np.arange(11), np.arange(1, 12), np.arange(1, 12)], 1), 3, 0.5,
                                pinned=np.isin(np.arange(12), [0, 11]))
    w = np.linspace(0.018, 0.04, len(zs))
    Vt, Ft = fit.sweep_tube(path, w, 8, closed=False, flatten=0.12, up_hint=np.array([0.0, 1.0, 0.0]))
    parts.add(fit.push_out(Vt, body.query, base_off + 0.003), Ft, slot)
    Vs, Fs = fit.icosphere(2)
    knot = top + np.array([0.0, -0.008, -0.005]) + fr.outward(top[None])[0] * base_off
    Vk = knot + Vs * np.array([0.016, 0.009, 0.014])
    parts.add(fit.push_out(Vk, body.query, base_off + 0.003), Fs, slot)


def _neck_tube(body: Body, parts: Parts, slot: int, z_fn, radial: float, radius_v: float, angles=None,
               n: int = 48, taper: bool = False):
    """Tube around (part of) the neck at height z_fn(theta): section ``radius_v`` high and
    ``radial`` thick, sitting ``radial`` outside the skin."""
    fr = body.frame
    loop = body.neck_loop(z_fn, n, angle0=np.pi)
    th = fr.theta(loop)
    if angles is not None:
        lo, hi = angles
        m = (np.mod(th, 2 * np.pi) >= lo) & (np.mod(th, 2 * np.pi) <= hi)
        loop = loop[m][np.argsort(np.mod(th[m], 2 * np.pi))]
    c, _, _, _, _ = body.query.closest(loop)
    path = c + fr.outward(loop) * (radial + 0.003)
    closed = angles is None
    r = np.full(len(path), radius_v)
    if taper and not closed:
        s = np.linspace(0, 1, len(path))
        r = radius_v * np.clip(np.sin(np.pi * s) * 1.6, 0.15, 1.0)
    Vt, Ft = fit.sweep_tube(path, r, 12, closed=closed, flatten=radial / radius_v)
    parts.add(Vt, Ft, slot)
    return path


def _hanging(body: Body, parts: Parts, slot: int, start: np.ndarray, length: float, width: float, thick: float,
             clearance: float, n: int = 10):
    """A flat strip/tail hanging down the chest from ``start`` (scarf ends, drawstrings)."""
    zs = start[2] - np.linspace(0.0, length, n)
    zs = np.maximum(zs, body.V[:, 2].min() + 0.01)
    path = np.stack([np.full(n, start[0]), np.full(n, start[1]), zs], 1)
    path = fit.push_out(path, body.query, clearance + thick, iterations=4)
    Vt, Ft = fit.sweep_tube(path, width, 8, closed=False, flatten=thick / width, up_hint=np.array([0.0, 1.0, 0.0]))
    parts.add(Vt, Ft, slot)


def _hood_up(body: Body, parts: Parts, slot: int, base_off: float):
    lm = body.lm
    brow = 0.5 * (lm[19] + lm[24])
    ear_y = 0.5 * (lm[0, 1] + lm[16, 1]) + 0.012
    z0, z1 = 0.5 * (lm[0, 2] + lm[16, 2]), brow[2] + 0.045
    y1 = brow[1] + 0.03
    V = body.V
    t = np.clip((V[:, 2] - z0) / (z1 - z0), 0.0, 1.0)
    y_open = ear_y + (y1 - ear_y) * t
    fr = body.frame
    f = np.minimum(V[:, 1] - y_open, V[:, 2] - (fr.z_ring(fr.theta(V)) + 0.02))
    P, F, cut = body.shell(body.head_tris, f, lambda p, n: np.full(len(p), 0.022), subdiv=1)
    P = fit.laplacian_smooth(P, F, 12, 0.5)
    P = fit.push_out(P, body.query, 0.01)
    P = fit.laplacian_smooth(P, F, 4, 0.5)
    P = fit.push_out(P, body.query, 0.008)
    parts.add(P, F, slot)
    for loop in fit.boundary_loops(F):
        if cut[loop].mean() > 0.5 and len(loop) > 8:
            Vt, Ft = fit.sweep_tube(P[loop][::2], 0.006, 8, closed=True)
            parts.add(fit.push_out(Vt, body.query, 0.004), Ft, slot)


# ----------------------------------------------------------------------------- build

def _params(entry: dict) -> dict:
    return dict(entry.get("params") or entry.get("parameters") or {})


def _num(p: dict, key: str, default: float) -> float:
    v = p.get(key, default)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else float(default)


def build(ctx: HeadContext, entry: dict) -> Rig:
    aid = str(entry.get("id", "tshirt_crew"))
    p = _params(entry)
    cls = SEGMENTATION_CLASS["garment"]
    rng = ctx.rng("garment")
    body = Body(ctx)
    fr = body.frame
    fabric = str(p.get("fabric", _DEFAULT_FABRIC.get(aid, "cotton_jersey")))
    style = str(p.get("style", ""))
    if aid == "uniform":
        fabric = {"scrubs": "scrub", "work_shirt": "cotton_twill", "polo": "pique"}.get(style, "scrub")
    if aid == "tank_top" and "fabric" not in p:
        fabric = "cotton_jersey"
    colour = p.get("colour_hsv", "grey")
    knit = _num(p, "knit_scale_m", 0.005)
    thick = FABRICS.get(fabric, FABRICS["cotton_jersey"])[0]
    seed = float(rng.uniform(0, 100))
    mats = [cloth_material(f"garment_{aid}", cls, colour, fabric, knit, seed)]
    parts = Parts()
    info = {"id": aid, "fabric": fabric, "colour": colour if isinstance(colour, str) else list(colour)}

    def wr(base, amp=0.0015):
        return _wrinkle_offset(rng, base, amp)

    if aid in ("tshirt_crew", "sweater", "hoodie", "scarf_over_sweater") or (aid == "uniform" and style not in (
            "scrubs", "work_shirt", "polo")):
        depth = _num(p, "neckline_depth_m", 0.01)
        base = thick + 0.0015
        rim = 0.0035 if aid != "tshirt_crew" else 0.002
        _shell_part(body, parts, _crew(body, 0.008, depth), wr(base), rim=rim, rim_flatten=0.8)
        if aid == "hoodie":
            if bool(p.get("hood_up", False)):
                _hood_up(body, parts, 0, base)
            else:
                _neck_tube(body, parts, 0, lambda t: fr.z_ring(t) + 0.02, 0.012 + base, 0.022,
                           angles=(np.pi - 2.0, np.pi + 2.0), taper=True)
            if bool(p.get("drawstrings", False)):
                for sx in (-1, 1):
                    start = body.neck_loop(_crew(body, 0.008, depth), 48, angle0=np.pi)
                    k = int(np.argmin(np.abs(fr.theta(start) - sx * 0.35)))
                    _hanging(body, parts, 0, start[k], 0.11, 0.0025, 0.0025, base + 0.002, n=8)
        if aid == "scarf_over_sweater":
            st = _num(p, "scarf_thickness_m", 0.02)
            wrap = str(p.get("wrap", "loop"))
            smat = cloth_material("garment_scarf", cls, colour, "wool_knit", 0.006, seed + 1)
            mats.append(smat)

            def zc(t):
                return np.minimum(fr.z_ring(t) + 0.035, fr.z_cap(t) - 0.03)
            if wrap in ("loop", "knot"):
                _neck_tube(body, parts, 1, zc, st / 2 + base, 0.03)
            else:
                _neck_tube(body, parts, 1, zc, st / 2 + base, 0.03, angles=(np.pi - 2.2, np.pi + 2.2))
            loop = body.neck_loop(zc, 48, angle0=np.pi)
            if wrap == "knot":
                Vs, Fs = fit.icosphere(2)
                k0 = loop[0]
                ctr = k0 + fr.outward(k0[None])[0] * (st + 0.02) + np.array([0, 0, -0.035])
                parts.add(fit.push_out(ctr + Vs * np.array([0.035, 0.025, 0.03]), body.query, base + 0.004), Fs, 1)
                _hanging(body, parts, 1, ctr + np.array([0.01, 0, -0.02]), 0.14, 0.035, st / 2, base + 0.004)
            elif wrap == "drape":
                for sx in (-1, 1):
                    k = int(np.argmin(np.abs(fr.theta(loop) - sx * 2.2 / 1.0 * 0.5)))
                    _hanging(body, parts, 1, loop[k] + np.array([0, -0.01, -0.02]), 0.17, 0.03, st / 2, base + 0.004)
            else:
                _hanging(body, parts, 1, loop[0] + np.array([0.015, -0.01, -0.03]), 0.12, 0.03, st / 2, base + 0.004)
        info["neckline_depth_m"] = depth
    elif aid in ("tshirt_vneck",) or (aid == "uniform" and style == "scrubs"):
        depth = _num(p, "neckline_depth_m", 0.07)
        base = thick + 0.0015
        _shell_part(body, parts, _vee(body, 0.008, depth, 0.75), wr(base), rim=0.002, rim_flatten=0.8)
        info["neckline_depth_m"] = depth
    elif aid == "turtleneck":
        h = _num(p, "collar_height_m", 0.06)
        base = thick + 0.0015
        wrf = wr(base, 0.002)

        def off(P, N):
            up = fit.smoothstep(0.0, 0.02, P[:, 2] - (fr.z_ring(fr.theta(P)) + 0.005))
            return wrf(P, N) + 0.003 * up
        z = lambda t: np.minimum(fr.z_ring(t) + h, fr.z_cap(t))  # noqa: E731
        _shell_part(body, parts, z, off, rim=0.006, rim_flatten=0.9)
        # folded roll: a second tube a little under the top
        _neck_tube(body, parts, 0, lambda t: z(t) - 0.018, base + 0.009, 0.012)
        info["collar_height_m"] = h
    elif aid in ("shirt_collar",) or (aid == "uniform" and style in ("work_shirt", "polo")):
        tie = bool(p.get("tie", False)) and aid == "shirt_collar"
        open_top = bool(p.get("top_button_open", style == "polo")) and not tie
        base = thick + 0.001
        depth = 0.045 if open_top else 0.0
        _shell_part(body, parts, _vee(body, 0.006, depth, 0.35), wr(base, 0.001), rim=0.0)
        _shirt_collar(body, parts, 0, base, open_top, leaf=0.035 if style == "polo" else 0.045)
        if tie:
            mats.append(cloth_material("garment_tie", cls, (rng.uniform(), 0.7, 0.5), "linen", 0.005, seed + 2))
            _tie(body, parts, 1, base + 0.004)
        info.update(tie=tie, top_button_open=open_top)
    elif aid in ("jacket_blazer", "coat"):
        under = str(p.get("undershirt", "shirt")) if aid == "jacket_blazer" else "shirt"
        if under != "none":
            ufab = "cotton_poplin" if under == "shirt" else "cotton_jersey"
            mats.append(cloth_material("garment_under", cls, "white" if under == "shirt" else "grey", ufab, 0.005,
                                       seed + 3))
            ub = FABRICS[ufab][0] + 0.001
            if under == "shirt":
                _shell_part(body, parts, _vee(body, 0.006, 0.0, 0.35), wr(ub, 0.0008), slot=1)
                _shirt_collar(body, parts, 1, ub, False, band_h=0.028, leaf=0.035)
            else:
                _shell_part(body, parts, _crew(body, 0.006, 0.01), wr(ub, 0.0008), slot=1, rim=0.002)
        coat = aid == "coat"
        base = (0.014 if coat else 0.009) + thick
        lw = _num(p, "lapel_width_m", 0.08 if coat else 0.07)
        depth, half = (0.10, 0.9) if coat else (0.14, 0.85)
        zfn = _vee(body, 0.02, depth, half)
        wrf = wr(base, 0.002)
        # lapels: a raised band (+5 mm) along the V edge on the front
        def off(P, N):
            th = fr.theta(P)
            r = fr.rxy(P)
            zr = fr.z_ring(th) + 0.02 + 0.008 * (1 - np.cos(th))
            frac = np.clip((zr - P[:, 2]) / depth, 0.0, 1.0)
            edge = half * (1.0 - frac)  # theta of the V edge at this height
            s = (np.abs(th) - edge) * r
            band = fit.smoothstep(-0.002, 0.004, s) * (1.0 - fit.smoothstep(lw - 0.008, lw, s))
            band = band * (np.cos(th) > 0.2) * (frac < 0.999)
            return wrf(P, N) + 0.005 * band
        _shell_part(body, parts, zfn, off, rim=0.003, rim_flatten=0.7)
        if coat and bool(p.get("collar_up", False)):
            _neck_tube(body, parts, 0, lambda t: np.minimum(fr.z_ring(t) + 0.04, fr.z_cap(t) - 0.02), base, 0.03,
                       angles=(0.6, 2 * np.pi - 0.6))
        else:
            _neck_tube(body, parts, 0, lambda t: fr.z_ring(t) + 0.03, base * 0.6, 0.015,
                       angles=(np.pi - 1.9, np.pi + 1.9))
        info.update(undershirt=under, lapel_width_m=lw, collar_up=bool(p.get("collar_up", False)))
    elif aid == "tank_top":
        w = _num(p, "strap_width_m", 0.03)
        base = thick + 0.0015
        xs = 0.5 * fr.radius + 0.045

        def extra(fnl):
            V = body.V
            th = fr.theta(V)
            zr = fr.z_ring(th)
            torso = np.minimum(zr - 0.05 - 0.04 * _front(th) - V[:, 2], 0.13 - np.abs(V[:, 0]))
            strap = np.minimum(w / 2 - np.abs(np.abs(V[:, 0]) - xs), zr + 0.01 - V[:, 2])
            return np.maximum(torso, strap)
        _shell_part(body, parts, lambda t: fr.z_ring(t), wr(base, 0.001), extra_field=extra, rim=0.0)
        info["strap_width_m"] = w
    else:
        raise ValueError(f"unknown garment id '{aid}'")

    anchors = np.union1d(body.torso_tris, body.head_tris) if aid == "hoodie" else body.torso_tris
    return finish(ctx, parts, body, anchors, f"garment_{aid}", mats, "garment", CLEARANCE, info)
