"""Trimming a garment part where another body part sinks into it (pure numpy).

At -3 SD the chin sinks into the chest: the torso shell built from the neck and shoulder skin
runs through the chin. Such a part is cut where it lies deeper than :data:`TRIM_DEPTH` inside
the skin; what stays is pushed out by the fit (:func:`synth.assets.fit.body.fit_shell`).

The cut is made so that the opening stays one smooth loop (``docs/realism-eyes-garments.md``):

1. the signed depth of every vertex (``query``: the skin's signed distance) plus
   ``TRIM_DEPTH`` is averaged :data:`FIELD_SMOOTHING` times over the part's neighbours (the
   depth jumps where the closest skin changes from the neck to the chin, and single deep
   vertices would leave pinholes and dangling triangles);
2. the part is clipped exactly at the zero level of that field
   (:func:`synth.assets.fit.meshops.clip_by_field`), which merges with the neckline opening;
3. pieces cut off from the rest (fewer than :data:`MIN_PIECE` of the faces) are dropped;
4. every boundary loop the cut touched is smoothed along itself (:data:`LOOP_SMOOTHING`
   passes; :func:`synth.assets.fit.hem.smooth_loops`): the clip leaves tiny edges where the
   level set passes near a vertex, and a corner where it crosses the neckline.
"""

from __future__ import annotations

import numpy as np

from synth.assets.fit.attach import push_out
from synth.assets.fit.hem import neighbour_mean_matrix, relax_loop, smooth_loops
from synth.assets.fit.meshops import clip_by_field, remove_faces

#: vertices of trimmable parts deeper than this inside the skin after shaping are cut away
TRIM_DEPTH = 0.006
#: passes of neighbour averaging of the depth field before the cut
FIELD_SMOOTHING = 4
#: passes of averaging along each boundary loop the cut touched
LOOP_SMOOTHING = 24
#: rounds of (averaging along the loop, push-out) for a loop the push-out moved
RELAX_ROUNDS = 6
#: passes of averaging along the loop per round
RELAX_PASSES = 4
#: pieces with fewer than this fraction of the part's faces are dropped after the cut
MIN_PIECE = 0.02


def _pieces(F: np.ndarray, n: int) -> np.ndarray:
    """Connected component of every face (faces sharing a vertex are connected)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    r = np.repeat(np.arange(len(F)), 3)
    A = coo_matrix((np.ones(len(r)), (r, F.ravel())), shape=(len(F), n)).tocsr()
    _, lab = connected_components(A @ A.T, directed=False)
    return lab


def trim_part(query, P: np.ndarray, F: np.ndarray, smooth: np.ndarray):
    """Cut the part (P, F) where it lies deeper than ``TRIM_DEPTH`` in the skin (``query``: a
    :class:`synth.geometry.sdf.SignedDistance`; see the module docstring). ``smooth``: per
    vertex, off the hem (``Parts.add``'s ``smooth_edge``). Returns the new (P, F, smooth) and
    how many of the part's vertices were cut away."""
    P = np.asarray(P, np.float64)
    F = np.asarray(F, np.int64)
    g = np.asarray(query(P), np.float64) + TRIM_DEPTH
    if (g >= 0).all():
        return P, F, smooth, 0
    M = neighbour_mean_matrix(F, len(P))
    for _ in range(FIELD_SMOOTHING):
        g = M @ g
    if (g >= 0).all():
        return P, F, smooth, 0
    W, Fc, cut = clip_by_field(F, g, len(P))
    Pc = np.asarray(W @ P)
    Sc = np.asarray(W @ np.asarray(smooth, np.float64)) > 0.5
    lab = _pieces(Fc, len(Pc))
    size = np.bincount(lab)
    keep = size[lab] >= MIN_PIECE * len(Fc)
    Pc, Fc, used = remove_faces(Pc, Fc, keep)
    cut, Sc = cut[used], Sc[used]
    Pc = smooth_loops(Pc, Fc, cut & Sc, LOOP_SMOOTHING, min_fraction=0.0, resample=True)
    return Pc, Fc, Sc, int((g < 0).sum())


def push_out_edges(P: np.ndarray, query, clearance: float, inside: np.ndarray | None, loops) -> np.ndarray:
    """Push every vertex not ``inside`` out of the skin to ``clearance``
    (:func:`synth.assets.fit.attach.push_out`), then relax each of ``loops`` (smooth boundary
    loops: hems, necklines) the push moved: where a chin presses on a neckline, the pushed
    vertices jump onto the chin while their neighbours stay, a spike in the loop. Rounds of
    averaging along the loop and pushing out again turn it into a curve that bends around the
    chin."""
    P = np.array(P, np.float64, copy=True)
    out = np.ones(len(P), bool) if inside is None else ~np.asarray(inside, bool)
    before = P.copy()
    P[out] = push_out(P[out], query, clearance, iterations=6)
    for lo in loops:
        if not np.any(P[lo] != before[lo]):
            continue
        for _ in range(RELAX_ROUNDS):
            P[lo] = relax_loop(P[lo], RELAX_PASSES)
            P[lo] = push_out(P[lo], query, clearance, iterations=3)
    return P
