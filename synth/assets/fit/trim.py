"""Trimming a garment part where another body part sinks into it, and pushing its smooth
boundary loops out of the skin as whole loops (pure numpy).

At -3 SD the chin sinks into the chest: the torso shell built from the neck and shoulder skin
runs through the chin. Such a part is cut where it lies deeper than :data:`TRIM_DEPTH` inside
the skin, or where it lies in a crease (the skin across from its closest skin point nearer than
:data:`CREASE_GAP`: the chin resting on the chest, where no neckline fits outside both sheets);
what stays is pushed out by the fit (:func:`synth.assets.fit.body.fit_shell`).

The cut is made so that the opening stays one smooth loop (``docs/realism-eyes-garments.md``):

1. that field (depth plus ``TRIM_DEPTH``, or the crease's gap) is averaged
   :data:`FIELD_SMOOTHING` times over the part's neighbours (the depth jumps where the closest
   skin changes from the neck to the chin, and single deep vertices would leave pinholes);
2. a region to cut that does not reach the part's smooth edge (the neckline) is left (it would
   be a hole: a second opening); its vertices are pushed out instead;
3. the part is clipped exactly at the zero level of the field
   (:func:`synth.assets.fit.meshops.clip_by_field`), which merges with the neckline opening;
4. only as many pieces as the part had are kept (islands left between cuts would be openings
   too), and none under :data:`MIN_PIECE` of the faces;
5. every boundary loop the cut touched is smoothed along itself (:data:`LOOP_SMOOTHING`
   passes; :func:`synth.assets.fit.hem.smooth_loops`).

:func:`push_out_edges` then pushes the part out of the skin, its necklines as whole loops
(:func:`fair_push`), and :func:`add_rims` lays the part's rim tubes (ribbed / rolled edges) on
the necklines where they ended up: a rim made before the trim stayed on the neckline as
designed, up to 12 cm from where the trim and the push-out left it (a dark slit between rim and
shell where the crease trim lowered a crew neck's front by 4 mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.assets.fit.attach import push_out
from synth.assets.fit.hem import neighbour_mean_matrix, relax_loop, smooth_loops
from synth.assets.fit.meshops import clip_by_field, negative_regions, oriented_boundary_loops, remove_faces, sweep_tube
from synth.geometry.normals import normalize

#: vertices of trimmable parts deeper than this inside the skin after shaping are cut away
TRIM_DEPTH = 0.006
#: parts are also cut where the skin across from their closest skin point (along its normal) is
#: nearer than this (m): a crease, where the chin rests on the chest at -3 SD; a neckline left in
#: it has no room to lie smoothly outside both sheets
CREASE_GAP = 0.016
#: slack (m) on that test, so that a single sheet is never taken for a crease
CREASE_TOLERANCE = 0.0005
#: passes of neighbour averaging of the depth field before the cut
FIELD_SMOOTHING = 4
#: passes of averaging along each boundary loop the cut touched
LOOP_SMOOTHING = 24
#: passes of averaging along a loop the push-out moved, before it is pushed out as a whole
RELAX_PASSES = 4
#: Gaussian (vertices) over which a loop's motion is averaged when it follows the body
FOLLOW_SIGMA = 4.0
#: steps of (push-out, averaging) of a loop's displacement (:func:`fair_push`)
FAIR_ITERATIONS = 100
#: fraction of the shortfall a step pushes out (damped: pushes from two surfaces balance)
FAIR_STEP = 0.5
#: averaging passes of the displacement per step
FAIR_PASSES = 2
#: shrinking of the displacement per averaging pass (its reach: ~ sqrt(0.25 / FAIR_DECAY) vertices)
FAIR_DECAY = 0.01
#: the loop is pushed to the clearance plus this (m), so the last averaging leaves it outside
FAIR_MARGIN = 0.001
#: rounds of (push what the steps left inside out, average the loop, steps again) before the
#: rest is pushed out vertex by vertex
FAIR_ROUNDS = 3
#: averaging passes along the loop in each of those rounds
FAIR_ROUND_PASSES = 4
#: pieces with fewer than this fraction of the part's faces are dropped after the cut
MIN_PIECE = 0.02
#: sides of a rim tube's section
RIM_SIDES = 8
#: a rim's centre line lies this fraction of its radius outside its neckline (away from the skin)
RIM_OUT = 0.6
#: necklines longer than this (vertices) carry a rim on every other vertex
RIM_STRIDE_ABOVE = 60


def _pieces(F: np.ndarray, n: int) -> np.ndarray:
    """Connected component of every face (faces sharing a vertex are connected)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    r = np.repeat(np.arange(len(F)), 3)
    A = coo_matrix((np.ones(len(r)), (r, F.ravel())), shape=(len(F), n)).tocsr()
    _, lab = connected_components(A @ A.T, directed=False)
    return lab


def _open_only(F: np.ndarray, g: np.ndarray, smooth: np.ndarray) -> np.ndarray:
    """``g`` with every region to cut (``g < 0``, connected over the part's edges) that does not
    reach a smooth-edge boundary vertex (the neckline) lifted to ``+0``: such a region would
    leave a hole, a second opening, in the garment; its vertices are pushed out instead."""
    neg = g < 0
    lab = negative_regions(F, g)
    n = len(g)
    edge = np.zeros(n, bool)
    for lo in oriented_boundary_loops(F):
        edge[lo] = smooth[lo]
    opening = np.zeros(lab.max() + 1, bool)
    opening[lab[neg & edge]] = True
    g = g.copy()
    g[neg & ~opening[lab]] = 0.0
    return g


def trim_part(query, P: np.ndarray, F: np.ndarray, smooth: np.ndarray, no_crease: np.ndarray | None = None):
    """Cut the part (P, F) where it lies deeper than ``TRIM_DEPTH`` in the skin (``query``: a
    :class:`synth.geometry.sdf.SignedDistance`; see the module docstring). ``smooth``: per
    vertex, off the hem (``Parts.add``'s ``smooth_edge``). ``no_crease``: per body triangle, the
    skin whose creases are not cut (the bust's upper arms, which hang against the torso along
    their length: a sleeve there is cloth in the armpit, not a neckline under a chin). Returns the
    new (P, F, smooth) and how many of the part's vertices were cut away."""
    P = np.asarray(P, np.float64)
    F = np.asarray(F, np.int64)
    h = query.query(P)
    probe = 0.5 * CREASE_GAP
    hit = query.query(h.point + h.normal * probe)
    across = np.asarray(hit.signed, np.float64)
    if no_crease is not None:
        across = np.where(no_crease[h.face] | no_crease[hit.face], np.inf, across)
    g = np.minimum(h.signed + TRIM_DEPTH, across - (probe - CREASE_TOLERANCE))
    if (g >= 0).all():
        return P, F, smooth, 0
    M = neighbour_mean_matrix(F, len(P))
    for _ in range(FIELD_SMOOTHING):
        g = M @ g
    if (g >= 0).all():
        return P, F, smooth, 0
    g = _open_only(F, g, np.asarray(smooth, bool))
    if (g >= 0).all():
        return P, F, smooth, 0
    W, Fc, cut = clip_by_field(F, g, len(P))
    Pc = np.asarray(W @ P)
    Sc = np.asarray(W @ np.asarray(smooth, np.float64)) > 0.5
    designed = len(np.unique(_pieces(F, len(P))))
    lab = _pieces(Fc, len(Pc))
    size = np.bincount(lab)
    largest = np.argsort(-size, kind="stable")[:designed]
    keep = np.isin(lab, largest) & (size[lab] >= MIN_PIECE * len(Fc))
    Pc, Fc, used = remove_faces(Pc, Fc, keep)
    cut, Sc = cut[used], Sc[used]
    Pc = smooth_loops(Pc, Fc, cut & Sc, LOOP_SMOOTHING, min_fraction=0.0, resample=True)
    return Pc, Fc, Sc, int((g < 0).sum())


def fair_push(Q: np.ndarray, query, clearance: float) -> np.ndarray:
    """A closed loop (a neckline) moved out of the skin to ``clearance`` as a whole, so that it
    stays smooth.

    Pushing every vertex to its closest skin point (:func:`push_out`) puts neighbours on two
    surfaces where the loop crosses a crease (a -3 SD chin on the chest, a jaw closing on a
    collar): a spike. Here the loop's displacement ``U`` is relaxed instead: in each of
    :data:`FAIR_ITERATIONS` steps the vertices closer than ``clearance + FAIR_MARGIN`` are
    pushed out by :data:`FAIR_STEP` of their shortfall, then ``U`` is averaged along the loop :data:`FAIR_PASSES` times and
    shrunk by :data:`FAIR_DECAY` per pass. The pushes from two surfaces balance into a loop that
    bridges the crease; away from the contact the displacement fades over ~5 vertices (a screened
    string). What the steps leave inside the skin (a crease the damped pushes did
    not resolve) is pushed out vertex by vertex."""
    X = _fair_steps(np.asarray(Q, np.float64), query, clearance)
    for _ in range(FAIR_ROUNDS):
        left = query(X) < 0.0
        if not left.any():
            break
        X[left] = push_out(X[left], query, clearance, iterations=3)
        for _ in range(FAIR_ROUND_PASSES):
            X = 0.5 * X + 0.25 * (np.roll(X, 1, 0) + np.roll(X, -1, 0))
        X = _fair_steps(X, query, clearance)
    left = query(X) < 0.0
    X[left] = push_out(X[left], query, clearance, iterations=3)
    return X


def _fair_steps(Q: np.ndarray, query, clearance: float) -> np.ndarray:
    """``Q`` plus its relaxed push-out displacement (:func:`fair_push`'s steps)."""
    U = np.zeros_like(Q)
    target = clearance + FAIR_MARGIN
    for _ in range(FAIR_ITERATIONS):
        h = query.query(Q + U)
        short = target - h.signed
        bad = short > 1e-7
        if not bad.any():
            break
        U[bad] += FAIR_STEP * short[bad, None] * h.normal[bad]
        for _ in range(FAIR_PASSES):
            U = (1.0 - FAIR_DECAY) * (0.5 * U + 0.25 * (np.roll(U, 1, 0) + np.roll(U, -1, 0)))
    return Q + U


def push_out_edges(P: np.ndarray, query, clearance: float, inside: np.ndarray | None, loops,
                   rest: np.ndarray | None = None) -> np.ndarray:
    """Push every vertex not ``inside`` out of the skin to ``clearance``
    (:func:`synth.assets.fit.attach.push_out`), except the vertices of ``loops`` (smooth
    boundary loops: necklines), which are pushed out as whole loops (:func:`fair_push`): where
    a chin presses on a neckline, vertices pushed one by one jump onto the chin while their
    neighbours stay, a spike in the loop.

    ``rest``: the positions the loops were smooth at (the build, for
    :meth:`~synth.assets.fit.body.FittedShell.follow`): a loop then starts from those plus its
    motion since, averaged along the loop (Gaussian, :data:`FOLLOW_SIGMA` vertices): neighbours
    bound to body triangles that move apart (the -3 SD neck folds where the chin sinks in)
    would fold the loop. Without ``rest`` a loop the push moved is first smoothed
    (:data:`RELAX_PASSES`, :func:`synth.assets.fit.hem.relax_loop`)."""
    from scipy.ndimage import gaussian_filter1d

    P = np.array(P, np.float64, copy=True)
    out = np.ones(len(P), bool) if inside is None else ~np.asarray(inside, bool)
    before = P.copy()
    P[out] = push_out(P[out], query, clearance, iterations=6)
    for lo in loops:
        if rest is not None:
            move = gaussian_filter1d(before[lo] - rest[lo], FOLLOW_SIGMA, axis=0, mode="wrap")
            P[lo] = fair_push(rest[lo] + move, query, clearance)
        elif np.any(P[lo] != before[lo]):
            P[lo] = fair_push(relax_loop(before[lo], RELAX_PASSES), query, clearance)
    return P


@dataclass(frozen=True)
class Rim:
    """A tube laid along a neckline (a ribbed or rolled edge): its loop's vertex indices in the
    shell, the tube's vertices ``start:stop`` in the shell, its radius and flattening."""

    loop: np.ndarray
    start: int
    stop: int
    radius: float
    flatten: float


def rim_tube(L: np.ndarray, query, radius: float, flatten: float, clearance: float):
    """(vertices, faces) of a closed tube of ``radius`` along the neckline points ``L``, its
    centre line :data:`RIM_OUT` of the radius outside the neckline (away from the closest skin
    point), pushed out of the skin to ``clearance``."""
    path = L[::2] if len(L) > RIM_STRIDE_ABOVE else L
    path = path + normalize(path - query.query(path).point) * radius * RIM_OUT
    Vt, Ft = sweep_tube(path, radius, RIM_SIDES, closed=True, flatten=flatten)
    return push_out(Vt, query, clearance, iterations=6), Ft


def add_rims(P: np.ndarray, F: np.ndarray, M: np.ndarray, specs, query, clearance: float):
    """The shell (P, F, M) with a rim tube along each fitted neckline of ``specs`` (``(loop,
    (radius, flatten, slot))``; loops under 8 vertices get none), and the :class:`Rim` list."""
    Ps, Fs, Ms, rims = [P], [F], [M], []
    n = len(P)
    for lo, (radius, flatten, slot) in specs:
        if len(lo) < 8:
            continue
        Vt, Ft = rim_tube(P[lo], query, radius, flatten, clearance)
        rims.append(Rim(np.asarray(lo), n, n + len(Vt), float(radius), float(flatten)))
        Ps.append(Vt)
        Fs.append(Ft + n)
        Ms.append(np.full(len(Ft), slot, M.dtype))
        n += len(Vt)
    return np.concatenate(Ps), np.concatenate(Fs), np.concatenate(Ms), rims


def place_rims(P: np.ndarray, rims, query, clearance: float) -> np.ndarray:
    """``P`` with every rim's tube laid anew along its neckline's current positions (after
    :meth:`~synth.assets.fit.body.FittedShell.follow`'s push-out)."""
    P = np.array(P, np.float64, copy=True)
    for r in rims:
        P[r.start:r.stop] = rim_tube(P[r.loop], query, r.radius, r.flatten, clearance)[0]
    return P
