"""The identity space: MakeHuman macro targets and face/head modifiers, random identities drawn
as target weights (macro interpolation as in MakeHuman), and an exact PCA of the samples and
their mirror images in target space."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from synth.errors import SynthError
from synth.model.builders.makehuman.sources import check_files

#: the builder's one random generator seed (``np.random.default_rng(SEED)``): the head's and the
#: bust's identity samples are the same draws
SEED = 20241128
N_SAMPLES = 3000  # identity samples before mirroring (the PCA sees 2 * N_SAMPLES)
AGE_YEARS = (18.0, 80.0)
MODIFIER_SIGMA = 0.3  # std-dev of two-sided face/head modifiers (MakeHuman slider units, clipped to [-1, 1])
ONE_SIDED_SIGMA = 0.25  # half-normal scale of one-sided shape modifiers (head-oval, chin-triangle, ...)
#: the modifier groups of the inner face, whose two-sided modifiers a build may draw wider
#: (``feature_sigma``; benchmarks/identity_diversity.py, docs/realism.md "Identity diversity")
FEATURE_GROUPS = ("nose", "mouth", "eyes", "ears", "chin", "cheek", "eyebrows")
ASYMMETRY_SIGMA = 0.05  # per-side deviation of left/right modifiers
MODIFIER_GROUPS = ("head", "neck", "nose", "mouth", "eyes", "ears", "chin", "cheek", "forehead", "eyebrows")
# pose-like or sideways modifiers that are not identity features
EXCLUDED_MODIFIERS = ("head-angle-in-out", "head-trans-in-out", "neck-trans-in-out", "nose-trans-in-out",
                      "mouth-trans-in-out")

_MACRO_AGES = ("baby", "child", "young", "old")
_MACRO_LEVELS = ("min", "average", "max")
_SIDED_KEYS = ("negative-left", "positive-left", "negative-right", "positive-right")


def macro_value_weights(age: np.ndarray, gender: np.ndarray, muscle: np.ndarray, weight: np.ndarray,
                        prop: np.ndarray, ethnic: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """MakeHuman's macro interpolation (apps/humanmodifier.py): piecewise-linear weights per value."""
    babyv = np.where(age < 0.5, np.maximum(0.0, 1 - age * 5.333), 0.0)
    youngv = np.where(age < 0.5, np.maximum(0.0, (age - 0.1875) * 3.2), 1 - np.maximum(0.0, age * 2 - 1))
    childv = np.where(age < 0.5, np.maximum(0.0, np.minimum(1.0, 5.333 * age) - youngv), 0.0)
    oldv = np.where(age < 0.5, 0.0, np.maximum(0.0, age * 2 - 1))

    def three(x):
        lo = np.where(x < 0.5, 1 - 2 * x, 0.0)
        hi = np.where(x < 0.5, 0.0, 2 * x - 1)
        return {"min": lo, "average": 1 - lo - hi, "max": hi}

    return {
        "gender": {"female": 1 - gender, "male": gender},
        "age": {"baby": babyv, "child": childv, "young": youngv, "old": oldv},
        "muscle": three(muscle),
        "weight": three(weight),
        "proportions": {"uncommon": np.where(prop < 0.5, 1 - 2 * prop, 0.0),
                        "ideal": np.where(prop < 0.5, 0.0, 2 * prop - 1)},
        "race": {"african": ethnic[:, 0], "asian": ethnic[:, 1], "caucasian": ethnic[:, 2]},
    }


def macro_targets(data: Path) -> list[tuple[Path, tuple[tuple[str, str], ...]]]:
    """(file, ((variable, value), ...)) for every macro target used; weight = product of values."""
    md = data / "mpfb2/targets/macrodetails"
    out = []
    for race in ("african", "asian", "caucasian"):
        for g in ("female", "male"):
            for a in _MACRO_AGES:
                out.append((md / f"{race}-{g}-{a}.target.gz", (("race", race), ("gender", g), ("age", a))))
    for g in ("female", "male"):
        for a in _MACRO_AGES:
            for mu in _MACRO_LEVELS:
                for w in _MACRO_LEVELS:
                    key = (("gender", g), ("age", a), ("muscle", mu), ("weight", w))
                    out.append((md / f"universal-{g}-{a}-{mu}muscle-{w}weight.target.gz", key))
                    for pr in ("ideal", "uncommon"):
                        p = md / "proportions" / f"{g}-{a}-{mu}muscle-{w}weight-{pr}proportions.target.gz"
                        if p.is_file():  # there are no baby proportions targets
                            out.append((p, key + (("proportions", pr),)))
    check_files([p for p, _ in out], "MakeHuman macro target")
    return out


def modifiers(data: Path) -> list[dict]:
    """Face/head modifiers from targets/target.json: name, group, sided, neg/pos target files."""
    tj = json.loads((data / "mpfb2/targets/target.json").read_text())
    root = data / "mpfb2/targets"
    mods = []
    for grp in MODIFIER_GROUPS:
        for c in tj[grp]["categories"]:
            if c["name"] in EXCLUDED_MODIFIERS:
                continue
            o = c.get("opposites")
            t = c["targets"]
            if o is None and c["has_left_and_right"]:  # eye-eyefold-concave-convex lists no opposites
                _, neg, pos = c["name"].rsplit("-", 2)
                neg_l = next(x for x in t if x.startswith("l-") and x.endswith(neg))
                pos_l = next(x for x in t if x.startswith("l-") and x.endswith(pos))
                o = {"negative-left": neg_l, "positive-left": pos_l, "negative-right": "r" + neg_l[1:],
                     "positive-right": "r" + pos_l[1:]}
            if o is None:  # one-sided shape modifier
                mods.append({"name": c["name"], "group": grp, "sided": False, "one_sided": True,
                             "files": {"pos": root / grp / f"{t[0]}.target.gz"}})
            elif c["has_left_and_right"]:
                mods.append({"name": c["name"], "group": grp, "sided": True, "one_sided": False, "files": {
                    k: root / grp / f"{o[k]}.target.gz" for k in _SIDED_KEYS}})
            else:
                mods.append({"name": c["name"], "group": grp, "sided": False, "one_sided": False, "files": {
                    "neg": root / grp / f"{o['negative-unsided']}.target.gz",
                    "pos": root / grp / f"{o['positive-unsided']}.target.gz"}})
    check_files([p for m in mods for p in m["files"].values()], "MakeHuman target")
    return mods


def modifier_files(mods: list) -> list[Path]:
    """The target files of the modifiers, in the column order of :func:`sample_identity_weights`."""
    out = []
    for m in mods:
        if m["one_sided"]:
            out.append(m["files"]["pos"])
        elif m["sided"]:
            out += [m["files"][k] for k in _SIDED_KEYS]
        else:
            out += [m["files"]["neg"], m["files"]["pos"]]
    return out


def sample_identity_weights(rng: np.random.Generator, n: int, macro: list, mods: list,
                            feature_sigma: float = MODIFIER_SIGMA) -> np.ndarray:
    """(n, n_targets) target weights: macro targets first, then each modifier's files in order.
    Two-sided modifiers of the :data:`FEATURE_GROUPS` are drawn with ``feature_sigma``, the others
    with :data:`MODIFIER_SIGMA`; with the same generator state the draws are the same people,
    their features scaled (numpy draws N(0, s) as s times one standard normal)."""
    years = rng.uniform(*AGE_YEARS, n)
    age = np.where(years < 25.0, 0.1875 + (years - 11.0) / 14.0 * 0.3125, 0.5 + (years - 25.0) / 65.0 * 0.5)
    gender = rng.beta(0.5, 0.5, n)
    muscle = rng.beta(2.0, 2.0, n)
    weight = rng.beta(2.0, 2.0, n)
    prop = rng.uniform(0.0, 1.0, n)
    ethnic = rng.dirichlet([0.5, 0.5, 0.5], n)
    vals = macro_value_weights(age, gender, muscle, weight, prop, ethnic)
    cols = []
    for _, key in macro:
        w = np.ones(n)
        for var, val in key:
            w = w * vals[var][val]
        cols.append(w)
    for m in mods:
        sigma = feature_sigma if m["group"] in FEATURE_GROUPS else MODIFIER_SIGMA
        if m["one_sided"]:
            cols.append(np.abs(rng.normal(0.0, ONE_SIDED_SIGMA, n)).clip(0, 1))
        elif m["sided"]:
            common = rng.normal(0.0, sigma, n)
            for side in ("left", "right"):
                v = np.clip(common + rng.normal(0.0, ASYMMETRY_SIGMA, n), -1, 1)
                cols += [np.maximum(-v, 0.0), np.maximum(v, 0.0)]
        else:
            v = np.clip(rng.normal(0.0, sigma, n), -1, 1)
            cols += [np.maximum(-v, 0.0), np.maximum(v, 0.0)]
    return np.stack(cols, 1)


def identity_pca(W: np.ndarray, T: np.ndarray, TJ: np.ndarray, Tm: np.ndarray, TJm: np.ndarray, k: int,
                 W_mean: np.ndarray | None = None):
    """Exact PCA of the samples X = [W T; W Tm] (rows: samples, mirrored samples) without forming X.
    The returned mean (the template's offset) is that of ``W_mean``'s samples when given (the
    components and codes stay those of ``W`` about its own mean): a wider spread about the same
    template.

    Returns mean (3V,), joint mean (3J,), basis (k, 3V) orthonormal, std (k,), joint basis
    (k, 3J), codes of all samples (2N, k), rank, fraction of the variance the k components explain.
    """
    n, nt = W.shape
    T2 = np.concatenate([T, Tm])  # (2nt, 3V)
    J2 = np.concatenate([TJ, TJm])
    # Gram matrix of the targets; mirroring is orthogonal, so Tm Tm^T = T T^T
    K11 = T @ T.T
    K12 = T @ Tm.T
    K = np.block([[K11, K12], [K12.T, K11]])
    W2 = np.zeros((2 * n, 2 * nt))
    W2[:n, :nt] = W
    W2[n:, nt:] = W
    wbar = W2.mean(0)
    Wc = W2 - wbar
    if W_mean is not None:
        W2[:n, :nt] = W_mean
        W2[n:, nt:] = W_mean
        wbar = W2.mean(0)
    Sw = Wc.T @ Wc / (2 * n - 1)  # covariance of target weights
    lam, E = np.linalg.eigh(K)
    good = lam > lam.max() * 1e-12
    lam, E = lam[good], E[:, good]
    sq = np.sqrt(lam)
    M = (E * sq).T @ Sw @ (E * sq)
    M = 0.5 * (M + M.T)
    ev, Z = np.linalg.eigh(M)
    order = np.argsort(ev)[::-1]
    ev, Z = ev[order], Z[:, order]
    rank = int(np.sum(ev > ev[0] * 1e-10))
    if k > rank:
        raise SynthError(f"identity_dims={k} exceeds the {rank} identity components the MakeHuman targets span",
                         "build_makehuman_head", f"choose identity_dims <= {rank}")
    A = E @ (Z[:, :k] / sq[:, None])  # (2nt, k): basis_k = A[:, k] . T2
    basis = A.T @ T2
    basis *= canonical_signs(basis)[:, None]  # eigenvectors are defined up to sign
    std = np.sqrt(ev[:k])
    codes = (Wc @ (T2 @ basis.T)) / std
    # joints: the same combination of samples as the mesh basis (regression of joints on codes)
    joint_basis = (codes.T @ (Wc @ J2)) / (2 * n - 1) / std[:, None]
    explained = float(ev[:k].sum() / ev[ev > 0].sum())
    return wbar @ T2, wbar @ J2, basis, std, joint_basis, codes, rank, explained


#: entries within this fraction of a row's largest magnitude count as tied for :func:`canonical_signs`
SIGN_TIE_REL = 1e-6


def canonical_signs(basis: np.ndarray) -> np.ndarray:
    """+1 / -1 per row of ``basis`` (K, D) such that the row's first entry, in index order, whose
    magnitude is within :data:`SIGN_TIE_REL` of the row's largest is positive. A mirror-symmetric
    component has its largest magnitude twice, at a vertex's x and at its mirror image's with the
    opposite sign, equal but for the last bits; taking the plain argmax let those bits choose, and
    OpenBLAS's kernels for another CPU flipped components 28, 30 and 44 of the default model (a
    +-3 SD head 15.7 mm apart; docs/default-model.md)."""
    a = np.abs(np.asarray(basis, np.float64))
    first = np.argmax(a >= a.max(axis=1, keepdims=True) * (1.0 - SIGN_TIE_REL), axis=1)
    s = np.sign(np.asarray(basis, np.float64)[np.arange(len(a)), first])
    return np.where(s == 0, 1.0, s)
