"""Float arithmetic whose bits do not depend on the machine.

numpy's matrix products go to BLAS (the kernel, its FMA use and the thread count pick the summation
order), its transcendental ufuncs (sin, arcsin, exp, ...) use SIMD loops chosen at run time (AVX-512
and SVML on some CPUs, others elsewhere), and einsum's inner loops use fused multiply-adds on some
architectures. Each gives results that differ in the last bits between machines. This module computes
the same things from operations that IEEE 754 rounds exactly on every machine: element-wise ``+ - * /``,
``sqrt``, ``floor``, ``frexp``/``ldexp`` and comparisons, each a separate numpy ufunc (so nothing is
fused), in a fixed order. Used where the result is stored (frame labels, the plan) or decides something
discrete; docs/determinism.md lists the sites.

Accuracy: the transcendental functions are within a few units in the last place of the correctly
rounded value on their documented domains (tests/geometry/test_exact.py measures it against numpy).
"""

from __future__ import annotations

from decimal import Decimal, getcontext
from math import factorial

import numpy as np

# ---- constants, split so that k * HI is exact for the integers k that occur -------------------------

_PI_DIGITS = "3.14159265358979323846264338327950288419716939937510582097494459"
_LN2_DIGITS = "0.69314718055994530941723212145817656807550013436025525412068000"


def _split(digits: str, scale: Decimal, bits: int) -> tuple[float, float, float]:
    """(hi, mid, lo) floats summing to the constant, hi and mid with ``bits`` significant bits."""
    getcontext().prec = 60
    x = Decimal(digits) * scale
    parts = []
    for _ in range(2):
        f = float(x)
        m, e = np.frexp(f)
        f = float(np.ldexp(np.floor(np.ldexp(m, bits)), int(e) - bits))  # truncate to `bits` bits
        parts.append(f)
        x -= Decimal(f)
    parts.append(float(x))
    return parts[0], parts[1], parts[2]


_PIO2 = _split(_PI_DIGITS, Decimal(1) / Decimal(2), 30)
_LN2 = _split(_LN2_DIGITS, Decimal(1), 30)
PI = float(Decimal(_PI_DIGITS))
PIO2 = float(Decimal(_PI_DIGITS) / 2)
_PIO2_LO = float(Decimal(_PI_DIGITS) / 2 - Decimal(PIO2))
_INV_PIO2 = float(2 / Decimal(_PI_DIGITS))
_INV_LN2 = float(1 / Decimal(_LN2_DIGITS))
#: |x| above which whole turns are taken off first (the 3-part reduction is exact for |k| < 2**23).
TRIG_MAX = 4.0e6

_SIN = [(-1) ** n / factorial(2 * n + 1) for n in range(1, 10)]
_COS = [(-1) ** n / factorial(2 * n) for n in range(1, 10)]
_EXP = [1 / factorial(n) for n in range(2, 19)]
_ATAN = [(-1.0) ** n / (2 * n + 1) for n in range(1, 24)]
_TAN_PI8 = 0.41421356237309503  # sqrt(2) - 1
_ATANH = [1.0 / (2 * n + 1) for n in range(1, 13)]


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _horner(z: np.ndarray, coeffs: list[float]) -> np.ndarray:
    """c0 + z (c1 + z (c2 + ...)), element-wise, highest term first."""
    acc = np.full_like(z, coeffs[-1])
    for c in reversed(coeffs[:-1]):
        acc = acc * z
        acc = acc + c
    return acc


# ---- trigonometry --------------------------------------------------------------------------------

def _reduce_pio2(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x = k * pi/2 + r with |r| <= pi/4 (plus rounding); returns (r, k mod 4)."""
    if x.size and not np.all(np.abs(x) <= TRIG_MAX):
        # whole turns off first: fmod is exact, and the float 2 pi's error (2.4e-16) costs at most
        # 4e-10 rad per 1e7 rad, below the input's own spacing there
        x = np.where(np.abs(x) <= TRIG_MAX, x, np.fmod(x, 2.0 * PI))
    k = np.floor(x * _INV_PIO2 + 0.5)
    r = x - k * _PIO2[0]
    r = r - k * _PIO2[1]
    r = r - k * _PIO2[2]
    return r, np.mod(k, 4.0).astype(np.int64)


def _sin_poly(r: np.ndarray) -> np.ndarray:
    z = r * r
    return r + (r * z) * _horner(z, _SIN)


def _cos_poly(r: np.ndarray) -> np.ndarray:
    z = r * r
    return 1.0 + z * _horner(z, _COS)


def sin(x) -> np.ndarray:
    r, q = _reduce_pio2(_f64(x))
    s, c = _sin_poly(r), _cos_poly(r)
    return np.select([q == 0, q == 1, q == 2], [s, c, -s], -c)


def cos(x) -> np.ndarray:
    r, q = _reduce_pio2(_f64(x))
    s, c = _sin_poly(r), _cos_poly(r)
    return np.select([q == 0, q == 1, q == 2], [c, -s, -c], s)


def tan(x) -> np.ndarray:
    """sin(x) / cos(x), both from one reduction."""
    r, q = _reduce_pio2(_f64(x))
    s, c = _sin_poly(r), _cos_poly(r)
    odd = (q % 2) == 1
    return np.where(odd, -c / s, s / c)


def _atan_unit(t: np.ndarray) -> np.ndarray:
    """atan(t) for 0 <= t <= 1: above tan(pi/8), pi/4 + atan((t - 1) / (t + 1)); then the series on
    |t| <= tan(pi/8). Both sides agree at the switch to rounding, so it decides nothing discrete."""
    shift = t > _TAN_PI8
    t = np.where(shift, (t - 1.0) / (t + 1.0), t)
    z = t * t
    a = t + (t * z) * _horner(z, _ATAN)
    return np.where(shift, (0.5 * PIO2 + a) + 0.5 * _PIO2_LO, a)


def atan2(y, x) -> np.ndarray:
    """Angle of (x, y) in [-pi, pi]; atan2(0, 0) = 0 and the sign of y's zero is kept, as in C."""
    y, x = np.broadcast_arrays(_f64(y), _f64(x))
    ay, ax = np.abs(y), np.abs(x)
    steep = ay > ax
    num = np.where(steep, ax, ay)
    den = np.where(steep, ay, ax)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), 0.0)
    a = _atan_unit(t)
    a = np.where(steep, (PIO2 - a) + _PIO2_LO, a)
    a = np.where(np.signbit(x), (PI - a) + 2.0 * _PIO2_LO, a)
    return np.copysign(a, y)


def atan(x) -> np.ndarray:
    return atan2(x, np.ones_like(_f64(x)))


def asin(x) -> np.ndarray:
    x = np.clip(_f64(x), -1.0, 1.0)
    return atan2(x, np.sqrt((1.0 - x) * (1.0 + x)))


def acos(x) -> np.ndarray:
    x = np.clip(_f64(x), -1.0, 1.0)
    return atan2(np.sqrt((1.0 - x) * (1.0 + x)), x)


# ---- exponential and logarithm ---------------------------------------------------------------------

def exp(x) -> np.ndarray:
    x = _f64(x)
    over, under = x > 709.0, x < -745.0
    xc = np.clip(np.where(np.isnan(x), 0.0, x), -745.0, 709.0)
    k = np.floor(xc * _INV_LN2 + 0.5)
    r = xc - k * _LN2[0]
    r = r - k * _LN2[1]
    r = r - k * _LN2[2]
    p = 1.0 + (r + (r * r) * _horner(r, _EXP))
    out = np.ldexp(p, k.astype(np.int64))
    out = np.where(over, np.inf, np.where(under, 0.0, out))
    return np.where(np.isnan(x), np.nan, out)


def log(x) -> np.ndarray:
    """Natural log; log(0) = -inf, log(x < 0) = nan (numpy's values, without its warnings)."""
    x = _f64(x)
    pos = x > 0.0
    m, e = np.frexp(np.where(pos & np.isfinite(x), x, 1.0))  # m in [0.5, 1)
    low = m < 0.70710678118654752
    m = np.where(low, m * 2.0, m)
    e = (e - low).astype(np.float64)
    s = (m - 1.0) / (m + 1.0)
    z = s * s
    lm = 2.0 * s + (2.0 * s * z) * _horner(z, _ATANH)
    out = (e * _LN2[0] + (e * _LN2[1] + lm)) + e * _LN2[2]
    out = np.where(x == 0.0, -np.inf, out)
    out = np.where(np.isposinf(x), np.inf, out)
    return np.where((x < 0.0) | np.isnan(x), np.nan, out)



# ---- the normal distribution -----------------------------------------------------------------------

_SQRT_PI = float(Decimal(_PI_DIGITS).sqrt())
_SQRT_2PI = float((2 * Decimal(_PI_DIGITS)).sqrt())
_SQRT1_2 = float(1 / Decimal(2).sqrt())
#: erfc: the series below this argument, the continued fraction above (both accurate to ~1e-15 there)
_ERFC_SWITCH = 1.5
_ERF_TERMS, _ERFC_CF_TERMS = 60, 100


def erfc(x) -> np.ndarray:
    """Complementary error function, accurate relative to ~1e-14 also far in the upper tail."""
    x = _f64(x)
    z = np.abs(x)
    out = np.empty_like(z)
    lo = z < _ERFC_SWITCH
    zl = z[lo]  # erf(z) = 2/sqrt(pi) exp(-z^2) sum_n 2^n z^(2n+1) / (2n+1)!!  (all terms positive)
    t = zl.copy()
    acc = zl.copy()
    for n in range(1, _ERF_TERMS):
        t = t * (2.0 * (zl * zl)) / (2 * n + 1)
        acc = acc + t
    out[lo] = 1.0 - (2.0 / _SQRT_PI) * exp(-(zl * zl)) * acc
    zh = z[~lo]  # erfc(z) = exp(-z^2) / sqrt(pi) / (z + (1/2) / (z + 1 / (z + (3/2) / (z + ...))))
    f = zh.copy()
    for k in range(_ERFC_CF_TERMS, 0, -1):
        f = zh + (0.5 * k) / f
    out[~lo] = exp(-(zh * zh)) / _SQRT_PI / f
    return np.where(x < 0.0, 2.0 - out, out)


def ndtr(x) -> np.ndarray:
    """Standard normal CDF."""
    return 0.5 * erfc(-_f64(x) * _SQRT1_2)


def truncated_normal_ppf(u, a: float, b: float, bisections: int = 12, newton: int = 5) -> np.ndarray:
    """Inverse CDF of the standard normal truncated to [a, b] at ``u`` in [0, 1] (u <= 0 gives a,
    u >= 1 gives b). Solved where it is accurate: on the lower tail's CDF where the target is at
    most 1/2, else on the upper tail's, by a fixed number of bisections in the bracket and then
    Newton steps (fixed counts: the result is the same bits on every machine)."""
    u = _f64(u)
    a, b = float(a), float(b)
    lo_b, hi_b = max(a, -40.0), min(b, 40.0)  # beyond |x| = 40 the CDF is 0 or 1 in float64
    pa, pb = float(ndtr(a)), float(ndtr(b))
    qa, qb = float(ndtr(-a)), float(ndtr(-b))
    inner = (u > 0.0) & (u < 1.0)
    uu = np.where(inner, u, 0.5)
    p = pa + uu * (pb - pa)
    q = qb + (1.0 - uu) * (qa - qb)
    upper = p > 0.5
    # solve ndtr(s * x) = target with s = -1 on the upper tail: y = s * x in [L, H]
    target = np.where(upper, q, p)
    s = np.where(upper, -1.0, 1.0)
    L = np.where(upper, -hi_b, lo_b)
    H = np.where(upper, -lo_b, hi_b)
    for _ in range(bisections):
        mid = 0.5 * (L + H)
        below = ndtr(mid) < target
        L, H = np.where(below, mid, L), np.where(below, H, mid)
    y = 0.5 * (L + H)
    for _ in range(newton):
        dens = exp(-0.5 * (y * y)) / _SQRT_2PI
        step = (ndtr(y) - target) / np.maximum(dens, 1e-300)
        y = np.clip(y - step, L, H)
    x = np.clip(s * y, a, b)
    return np.where(inner, x, np.where(u <= 0.0, a, b))

# ---- linear algebra in a fixed order ---------------------------------------------------------------

def lincomb(coeffs, rows) -> np.ndarray:
    """``coeffs @ rows`` summed term by term in index order: (..., K) x (K, N) -> (..., N)."""
    c = np.asarray(coeffs)
    r = np.asarray(rows)
    dt = np.result_type(c, r)
    out = np.zeros(c.shape[:-1] + r.shape[1:], dt)
    for k in range(r.shape[0]):
        out += c[..., k, None].astype(dt) * r[k]
    return out


def matvec3(A, v) -> np.ndarray:
    """(..., 3, 3) x (..., 3) -> (..., 3), each row summed left to right."""
    A, v = np.asarray(A), np.asarray(v)
    return (A[..., 0] * v[..., None, 0] + A[..., 1] * v[..., None, 1]) + A[..., 2] * v[..., None, 2]


def matmul3(A, B) -> np.ndarray:
    """(..., 3, 3) x (..., 3, 3) -> (..., 3, 3), each entry summed left to right."""
    A, B = np.asarray(A), np.asarray(B)
    return (A[..., :, 0, None] * B[..., None, 0, :] + A[..., :, 1, None] * B[..., None, 1, :]) \
        + A[..., :, 2, None] * B[..., None, 2, :]


def points_times_matrix(P, M) -> np.ndarray:
    """Row vectors times a 3x3 matrix: (..., N, 3) x (..., 3, 3) -> (..., N, 3), fixed order."""
    P, M = np.asarray(P), np.asarray(M)
    return (P[..., :, 0, None] * M[..., None, 0, :] + P[..., :, 1, None] * M[..., None, 1, :]) \
        + P[..., :, 2, None] * M[..., None, 2, :]


def cholesky(A) -> np.ndarray:
    """Lower Cholesky factor of symmetric positive-definite matrices (..., D, D), fixed order.

    Raises ``np.linalg.LinAlgError`` as numpy does when a matrix is not positive definite."""
    A = _f64(A)
    D = A.shape[-1]
    L = np.zeros_like(A)
    for j in range(D):
        s = A[..., j, j].copy()
        for k in range(j):
            s = s - L[..., j, k] * L[..., j, k]
        if not np.all(s > 0.0):
            raise np.linalg.LinAlgError("Matrix is not positive definite")
        d = np.sqrt(s)
        L[..., j, j] = d
        for i in range(j + 1, D):
            t = A[..., i, j].copy()
            for k in range(j):
                t = t - L[..., i, k] * L[..., j, k]
            L[..., i, j] = t / d
    return L


def squared_distances(A, B) -> np.ndarray:
    """(n, m) squared distances between rows of A (n, 3) and B (m, 3), summed x, y, z in order."""
    A, B = _f64(A), _f64(B)
    d = A[:, None, 0] - B[None, :, 0]
    out = d * d
    for c in (1, 2):
        d = A[:, None, c] - B[None, :, c]
        out = out + d * d
    return out


def nearest_index(queries, points, chunk_elements: int = 1 << 22) -> np.ndarray:
    """Index of the nearest of ``points`` (m, 3) to each query (n, 3): brute force on exact squared
    distances, the lowest index on an exact tie. Memory is bounded by ``chunk_elements``."""
    Q, P = _f64(queries), _f64(points)
    out = np.empty(len(Q), np.int64)
    step = max(1, chunk_elements // max(1, len(P)))
    for s in range(0, len(Q), step):
        out[s:s + step] = np.argmin(squared_distances(Q[s:s + step], P), axis=1)
    return out

