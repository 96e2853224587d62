"""Named vertex regions of the default model. The anatomical features (eyeballs, lid margins,
lips, sockets, ears, nose) come first, from hm08 edge loops and MakeHuman's modifier
targets; the face, neck, scalp, brow and beard regions follow from the ibug68 landmarks."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from synth.model.builders.makehuman.mesh import EYE_LIMBUS_DEG, EYE_PUPIL_DEG, Mesh
from synth.model.builders.makehuman.sources import read_target
from synth.model.builders.makehuman.surface import Topology, polyline_at, split_loop
from synth.model.builders.makehuman.targets import TargetSpace

# Seeds of hm08 edge loops, read off the base mesh (see docs/default-model.md): 7748 is the
# upper-lid margin vertex straight above the left eye centre; its loop is the lid margin.
HM08_LID_SEED = 7748
# Lip contours are hm08 edge loops, seeded at midline vertices read off the midline profile
# (see docs/default-model.md): 474 is the upper-lip vertex of the lip-contact loop (its loop
# also holds the lower-lip contact vertex 493); the vermilion border is found as the ring
# with the largest backward step of the profile (loop 5, through 455 and 492).
HM08_STOMION_UPPER = 474
BROW_BAND_M = 0.007  # brow region: skin within this distance of the brow polyline
HAIRLINE_FACTOR = 1.1  # face region: the hairline above the nasion, in nasion-to-upper-lip-hollow heights


@dataclass
class Features:
    """Regions and contours found on the template before the landmarks."""

    reg: dict[str, np.ndarray]  # region name -> vertex indices
    skin: np.ndarray  # (V,) bool: body surface (no eyeballs, no helpers)
    hidden: np.ndarray  # (V,) bool: mouth cavity and eye sockets
    visible: np.ndarray  # (V,) bool: skin that is not hidden and not an ear
    vis_tris: np.ndarray  # (T,) bool: triangles with all corners visible
    nose: np.ndarray  # (V,) bool
    lids: dict[str, dict]  # "l"/"r" -> split_loop of the lid margin
    lip_rings: list[list[int]]  # concentric loops around the mouth, lip contact first
    lip_outer: int  # index of the vermilion border in lip_rings


def mask(idx, n: int) -> np.ndarray:
    m = np.zeros(n, bool)
    m[np.asarray(idx, np.int64)] = True
    return m


def ring_midpoints(X: np.ndarray, ring: list[int]) -> tuple[int, int]:
    """Highest and lowest midline (x = 0) vertices of a loop."""
    m = [v for v in ring if X[v, 0] == 0.0]
    return max(m, key=lambda v: X[v, 2]), min(m, key=lambda v: X[v, 2])


def midline(f: Features, X: np.ndarray, joint_rest: np.ndarray) -> np.ndarray:
    """Visible vertices on x = 0 in front of the eyes."""
    return np.nonzero(f.visible & (X[:, 0] == 0.0) & (X[:, 1] < joint_rest[3, 1]))[0]


def feature_regions(mesh: Mesh, X: np.ndarray, tris: np.ndarray, space: TargetSpace, data: Path) -> Features:
    V, nk = len(X), len(mesh.kept)
    L = mesh.lookup
    skin = np.zeros(V, bool)
    skin[:nk] = True
    for r in mesh.helper_rows.values():
        skin[r] = False
    topo = Topology([p for p in mesh.polys if skin[p].all()], V)
    reg: dict[str, np.ndarray] = {}

    # ---- eyeballs and helpers
    th = mesh.eye_theta
    for side, t in (("eye_l", "l"), ("eye_r", "r")):
        idx = np.arange(mesh.eye_slices[side].start, mesh.eye_slices[side].stop)
        reg[side] = idx
        reg[f"iris_{t}"] = idx[th <= np.deg2rad(EYE_LIMBUS_DEG) + 1e-9]
        reg[f"pupil_{t}"] = idx[th <= np.deg2rad(EYE_PUPIL_DEG) + 1e-9]
        reg[f"sclera_{t}"] = idx[th > np.deg2rad(EYE_LIMBUS_DEG) + 1e-9]
    reg["eyes"] = np.concatenate([reg["eye_l"], reg["eye_r"]])
    h = mesh.helper_rows
    reg["teeth_upper"], reg["teeth_lower"] = h["helper-upper-teeth"], h["helper-lower-teeth"]
    reg["teeth"] = np.concatenate([reg["teeth_upper"], reg["teeth_lower"]])
    reg["tongue"] = h["helper-tongue"]
    # hm08 eyelash helpers: "-2" strips run along the upper lids, "-1" along the lower lids
    for t, s in (("l", "l"), ("r", "r")):
        reg[f"lash_helper_{t}_upper"] = h[f"helper-{s}-eyelashes-2"]
        reg[f"lash_helper_{t}_lower"] = h[f"helper-{s}-eyelashes-1"]

    # ---- lid margins (edge loop through a seed vertex) and the hidden eye sockets behind them
    lids = {}
    sockets = []
    for t, seed in (("l", L[HM08_LID_SEED]), ("r", mesh.mirror[L[HM08_LID_SEED]])):
        loop = topo.horizontal_loop(mesh.base, int(seed))  # topology: the base mesh's edges
        lids[t] = split_loop(X, loop)
        sockets.append(topo.enclosed(loop, skin))
        medial_first = (lambda a: a) if t == "l" else (lambda a: a[::-1])  # medial -> lateral
        reg[f"eyelid_{t}_upper"] = np.array(medial_first(lids[t]["upper"]))
        reg[f"eyelid_{t}_lower"] = np.array(medial_first(lids[t]["lower"]))
    reg["eye_socket"] = np.concatenate(sockets)
    reg["eyelash_lines"] = np.unique(np.concatenate(
        [reg[f"eyelid_{t}_{u}"] for t in "lr" for u in ("upper", "lower")] +
        [reg[f"lash_helper_{t}_{u}"] for t in "lr" for u in ("upper", "lower")]))

    # ---- lips: concentric edge loops around the mouth, starting at the lip-contact loop
    rings = []
    cur = int(L[HM08_STOMION_UPPER])
    for _ in range(9):
        ring = topo.horizontal_loop(X, cur, required=False)
        if ring is None:
            break
        rings.append(ring)
        used = set().union(*map(set, rings))
        up = [n for n in topo.nbr[cur] if X[n, 0] == 0.0 and n not in used and X[n, 2] > X[cur, 2]]
        if not up:
            break
        cur = up[0]
    # vermilion border: the ring after which the midline profile steps back the most
    mids = {k: ring_midpoints(X, rings[k]) for k in range(2, len(rings))}
    steps = [X[mids[k + 1][0], 1] - X[mids[k][0], 1] + X[mids[k + 1][1], 1] - X[mids[k][1], 1]
             for k in range(2, len(rings) - 1)]
    k_out = 2 + int(np.argmax(steps))
    reg["lips"] = np.unique(np.concatenate(rings[: k_out + 1]))
    reg["mouth_cavity"] = topo.enclosed(rings[0], skin)
    reg["mouth_interior"] = np.concatenate([reg["mouth_cavity"], reg["tongue"]])
    hidden = mask(np.concatenate([reg["mouth_cavity"], reg["eye_socket"]]), V)

    # ---- parts moved as a whole by MakeHuman's modifier targets
    def moved(names, frac):
        m = np.ones(V, bool)
        for n in names:
            off, _ = space.dense(*read_target(data / "mpfb2/targets" / n))
            d = np.linalg.norm(off, axis=1)
            m &= d >= frac * d.max()
        return m & skin

    ears = {}
    for t in "lr":
        ears[t] = np.nonzero(moved([f"ears/{t}-ear-trans-{d}.target.gz" for d in ("up", "down", "forward", "backward")],
                                   0.999))[0]
        reg[f"ear_{t}"] = ears[t]
    reg["ears"] = np.concatenate([ears["l"], ears["r"]])
    nose = moved(["nose/nose-trans-forward.target.gz"], 0.5) & ~hidden
    reg["nose"] = np.nonzero(nose)[0]
    visible = skin & ~hidden & ~mask(reg["ears"], V)
    return Features(reg, skin, hidden, visible, visible[tris].all(1), nose, lids, rings, k_out)


def landmark_regions(f: Features, X: np.ndarray, family: np.ndarray, joint_rest: np.ndarray,
                     pts: dict[int, np.ndarray], jaw_line: np.ndarray) -> None:
    """Add face, neck, shoulders, scalp, skin, brow and beard to ``f.reg``, bounded by the
    ibug68 points ``pts`` (before they are snapped to triangles) and, below, by ``jaw_line`` ((9, 3),
    the right side's outline down to the chin; landmarks.region_jaw_line)."""
    V = len(X)
    reg, skin, visible = f.reg, f.skin, f.visible
    # hairline estimate: forehead height ~ the height from the nasion down to the hollow of the upper
    # lip's profile (the deepest midline point between the nose tip and the upper lip)
    lip = midline(f, X, joint_rest)
    lip = lip[(X[lip, 2] < pts[30][2]) & (X[lip, 2] > pts[51][2])]
    z_trichion = pts[27][2] + HAIRLINE_FACTOR * (pts[27][2] - X[lip[np.argmax(X[lip, 1])], 2])
    jx = np.abs(jaw_line[:, 0])[::-1]
    jz = jaw_line[:, 2][::-1]
    below_jaw = X[:, 2] < np.interp(np.abs(X[:, 0]), jx, jz)
    head = skin & (family == 2)
    front = X[:, 1] < X[reg["ears"], 1].min()
    reg["face"] = np.nonzero(head & visible & front & ~below_jaw & (X[:, 2] < z_trichion))[0]
    neck = skin & ((family == 1) | (head & front & below_jaw)) & ~f.hidden
    reg["neck"] = np.nonzero(neck)[0]
    reg["shoulders"] = np.nonzero(skin & (family == 0))[0]
    reg["scalp"] = np.nonzero(head & visible & ~mask(reg["face"], V) & ~neck)[0]
    reg["skin"] = np.nonzero(skin)[0]
    # brow bands
    from scipy.spatial import cKDTree

    for t, ids in (("l", range(22, 27)), ("r", range(17, 22))):
        line = polyline_at(np.array([pts[i] for i in ids]), np.linspace(0, 1, 40))
        d, _ = cKDTree(line).query(X)
        reg[f"brow_{t}"] = np.nonzero(visible & (d < BROW_BAND_M) & mask(reg["face"], V))[0]
    reg["brow"] = np.concatenate([reg["brow_l"], reg["brow_r"]])
    # beard: below the cheek line (alar base -> the jaw line's top), lower face and upper neck, no lips/nose
    cx = np.array([0.0, abs(pts[31][0]), abs(jaw_line[0, 0]), 1.0])
    cz = np.array([pts[33][2], pts[31][2], jaw_line[0, 2], jaw_line[0, 2]])
    under_cheek = X[:, 2] < np.interp(np.abs(X[:, 0]), cx, cz)
    neck_mid = pts[8][2] - 0.5 * (pts[8][2] - joint_rest[0, 2])
    beard = visible & ~mask(reg["lips"], V) & ~f.nose & (
        (mask(reg["face"], V) & under_cheek) | (neck & front & (X[:, 2] > neck_mid)))
    reg["beard"] = np.nonzero(beard)[0]
