"""Counter-based random numbers: every draw is a pure function of (run seed, stream,
identity, expression, view, draw index).

The scheme is Philox4x64-10 (Salmon et al. 2011, the generator numpy ships as
``np.random.Philox``) used as a keyed block function::

    block = Philox4x64_10(counter=[draw, view, expression, identity], key=[run_seed, stream])

Indices that do not apply (e.g. the view of an identity-level draw) are ``NA`` (2**64-1).
Because nothing is sequential across frames, any frame can be re-planned alone and the
plan does not depend on the number of workers or their order.

Two equivalent entry points:

- :func:`generator` returns a ``np.random.Generator`` over numpy's own Philox started at
  ``counter=[0, view, expression, identity]``; its first block is ``draw = 1``. Use it
  where a sequential API is convenient (e.g. the Gaussian-mixture sampler).
- :func:`blocks` / :func:`uniforms` evaluate the same block function vectorised in numpy
  over many counters at once (used for cameras, expressions and frame seeds). A test
  checks that both agree bit for bit with numpy's implementation.

Nothing in ``synth/``, ``blender_scripts/``, ``renderer_jobs/`` or ``prior/`` may use the global
RNGs (stdlib ``random``, ``np.random.<fn>``) or wall-clock seeds;
``tests/test_seeds_determinism.py`` enforces it.
"""

from __future__ import annotations

import enum

import numpy as np

NA = (1 << 64) - 1  # "index not applicable"
MAX_SEED = (1 << 64) - 1
#: Cycles' seed property is a signed 32-bit int; frame seeds are in [0, 2**31).
FRAME_SEED_BITS = 31

_M0 = np.uint64(0xD2E7470EE14C6C93)
_M1 = np.uint64(0xCA5A826395121157)
_W0 = np.uint64(0x9E3779B97F4A7C15)
_W1 = np.uint64(0xBB67AE8584CAA73B)
_LO32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)


class Stream(enum.IntEnum):
    """One stream per kind of decision; adding a stream never changes the others."""

    IDENTITY = 1
    EXPRESSION = 2
    ASSETS = 3
    CAMERA = 4  # viewpoint candidates (per expression)
    CAMERA_EXTRA = 5  # per-frame roll and principal-point jitter
    FRAME = 6  # the per-frame render seed
    LIGHTING = 7
    ASSET_GEOMETRY = 8  # per-identity, per-class geometry randomness of asset rigs (strand roots, ...)
    SKIN = 9  # per-identity skin tone (the ITA target, synth.plan.skin)
    ENVIRONMENT = 10  # environments 1.. of an expression (identity, expression, environment in the view slot)
    IDENTITY_REDRAW = 11  # redraws of an identity code outside the head-shape ranges (attempt in the expression slot)


def check_seed(seed: int) -> int:
    seed = int(seed)
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"run seed must be in [0, 2**64 - 1], got {seed}")
    return seed


def _idx(x) -> np.ndarray:
    """Indices as uint64; -1 (or None) means NA."""
    if x is None:
        return np.array(NA, dtype=np.uint64)
    a = np.asarray(x)
    if a.dtype.kind == "u":
        return a.astype(np.uint64)
    a = a.astype(np.int64)
    return np.where(a < 0, np.uint64(NA), a.astype(np.uint64))


def _mulhilo(a: np.uint64, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hi, lo) 64-bit halves of the 128-bit product a * b (a scalar constant), in uint64 pieces."""
    a0, a1 = a & _LO32, a >> _S32
    b0 = b & _LO32
    b1 = b >> _S32
    p00 = b0 * a0
    p01 = b1 * a0
    p10 = b0 * a1
    hi = b1 * a1
    np.right_shift(p00, _S32, out=p00)
    p00 += p01 & _LO32
    p00 += p10 & _LO32
    np.right_shift(p00, _S32, out=p00)
    hi += p01 >> _S32
    hi += p10 >> _S32
    hi += p00
    return hi, b * a


_CHUNK = 16384  # elements per pass: keeps the ~20 temporaries in cache (3x faster than one pass)


def philox4x64(c0, c1, c2, c3, k0: int, k1: int) -> np.ndarray:
    """Philox4x64-10 block function, vectorised: counters broadcast together, returns (..., 4) uint64."""
    c = np.broadcast_arrays(*(np.asarray(x, dtype=np.uint64) for x in (c0, c1, c2, c3)))
    shape = c[0].shape
    flat = [np.ascontiguousarray(a).reshape(-1) for a in c]
    n = flat[0].size
    out = np.empty((n, 4), np.uint64)
    with np.errstate(over="ignore"):
        for s in range(0, n, _CHUNK):
            x0, x1, x2, x3 = (f[s:s + _CHUNK].copy() for f in flat)
            key0, key1 = np.uint64(k0), np.uint64(k1)
            for r in range(10):
                if r:
                    key0 = key0 + _W0
                    key1 = key1 + _W1
                hi0, lo0 = _mulhilo(_M0, x0)
                hi1, lo1 = _mulhilo(_M1, x2)
                hi1 ^= x1
                hi1 ^= key0
                hi0 ^= x3
                hi0 ^= key1
                x0, x1, x2, x3 = hi1, lo1, hi0, lo0
            out[s:s + _CHUNK, 0] = x0
            out[s:s + _CHUNK, 1] = x1
            out[s:s + _CHUNK, 2] = x2
            out[s:s + _CHUNK, 3] = x3
    return out.reshape(shape + (4,))


def blocks(seed: int, stream: int, identity, expression=None, view=None, draw=1) -> np.ndarray:
    """Random 64-bit words (..., 4) for broadcast index arrays; ``draw`` counts blocks from 1
    (block ``d`` is what ``generator(...)`` produces as its ``d``-th block)."""
    seed = check_seed(seed)
    return philox4x64(_idx(draw), _idx(view), _idx(expression), _idx(identity), seed, int(stream))


def to_unit(words: np.ndarray) -> np.ndarray:
    """uint64 words -> float64 in [0, 1) (53 high bits), like numpy's ``Generator.random``."""
    return (words >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def uniforms(seed: int, stream: int, identity, expression=None, view=None, n: int = 4,
             first_draw: int = 1) -> np.ndarray:
    """(..., n) floats in [0, 1) for broadcast indices: words of blocks first_draw, first_draw+1, ..."""
    nb = -(-n // 4)
    draws = np.arange(first_draw, first_draw + nb, dtype=np.uint64)
    ident, expr, vw = (np.asarray(_idx(a))[..., None] for a in (identity, expression, view))
    w = philox4x64(draws, vw, expr, ident, check_seed(seed), int(stream))  # (..., nb, 4)
    return to_unit(w.reshape(w.shape[:-2] + (nb * 4,))[..., :n])


def generator(seed: int, stream: int, identity=None, expression=None, view=None) -> np.random.Generator:
    """A sequential Generator whose blocks are ``blocks(seed, stream, identity, expression, view, draw=1, 2, ...)``."""
    ctr = np.array([0, _idx(view), _idx(expression), _idx(identity)], dtype=np.uint64)
    key = np.array([check_seed(seed), int(stream)], dtype=np.uint64)
    return np.random.Generator(np.random.Philox(counter=ctr, key=key))


def frame_seeds(seed: int, identity, expression, view) -> np.ndarray:
    """Per-frame render seeds in [0, 2**31) (int64 array), a pure function of (seed, i, e, v)."""
    w = blocks(seed, Stream.FRAME, identity, expression, view, draw=1)[..., 0]
    return (w >> np.uint64(64 - FRAME_SEED_BITS)).astype(np.int64)


def frame_seed(seed: int, identity: int, expression: int, view: int) -> int:
    return int(frame_seeds(seed, identity, expression, view))
