"""The eyes' proportions against published measurements of adult faces (issue 13): distances
between the model's ibug68 landmarks of planned identities (neutral expression, rest pose),
in millimetres, next to anthropometric studies of the same distances.

ibug68 points and the anthropometric landmarks they stand for (the builder's rules,
synth/model/builders/makehuman/landmarks.py): 36 / 45 the lateral ends of the lid margins
(exocanthion, ex), 39 / 42 the medial ends (endocanthion, en), 37 / 38 and 41 / 40 the upper and
lower lid margins at a third and two thirds of the eye's width (the lid opening there stands in
for palpebrale superius - inferius, ps-pi, which is taken at the opening's highest point: ours
reads a little lower).

Plain numpy; the command is ``python -m benchmarks.realism eyes`` (tested in
tests/benchmarks/test_realism_eyes.py).
"""

from __future__ import annotations

import numpy as np

from .common import _planned_heads

#: measurement -> (what it is, its ibug68 pairs: the mean of their distances)
MEASURES = {
    "en-en": ("intercanthal width", ((39, 42),)),
    "ex-ex": ("biocular width", ((36, 45),)),
    "ex-en": ("eye fissure length (mean of both eyes)", ((36, 39), (42, 45))),
    "ps-pi": ("eye fissure height at the thirds (mean of both eyes)", ((37, 41), (38, 40), (43, 47), (44, 46))),
}
#: derived: canthal index and fissure index, 100 x a / b
INDICES = {"canthal index": ("en-en", "ex-ex"), "fissure height / length": ("ps-pi", "ex-en")}

#: published measurements: (study, population, {measure: (mean, sd or None)}), mm
REFERENCES = (
    ("Wong et al. 2013, BioMed Res. Int. 821428 (3D photos)", "Hong Kong Chinese 18-35 y, 51 men",
     {"en-en": (40.61, 4.91), "ex-ex": (93.00, 5.56), "ex-en": (27.64, 1.67), "ps-pi": (11.55, 1.05),
      "canthal index": (43.95, 8.23), "fissure height / length": (41.84, 3.69)}),
    ("", "52 women",
     {"en-en": (38.27, 2.61), "ex-ex": (88.39, 3.74), "ex-en": (26.04, 1.83), "ps-pi": (11.94, 1.23),
      "canthal index": (43.29, 2.35), "fissure height / length": (45.89, 4.05)}),
    ("Knezi et al. 2020, Int. J. Morphol. 38(5) (photographs; right eye)", "Serbian, 19 y, 90",
     {"ex-en": (27.05, 1.71), "ps-pi": (9.35, 1.55)}),
    ("Malik et al. 2022, Ophthalmology Journal (ruler; means only)", "Pakistan, 15 y and over, 380",
     {"en-en": (31.7, None), "ex-en": (29.7, None), "ps-pi": (10.04, None)}),
    ("Read et al. 2006, Optom. Vis. Sci. 83(10) (photographs; primary gaze)", "white, young, 76",
     {"ps-pi": (9.7, 1.2)}),
    ("pooled review, 67 studies, Plast. Reconstr. Surg. Glob. Open 2022 (PMC9029890)", "White / African / Asian",
     {"en-en": (31.4, 2.5)}),
    ("", "African", {"en-en": (38.5, 3.2)}),
    ("", "Asian", {"en-en": (36.4, 1.6)}),
)


def eye_measures(ibug: np.ndarray) -> dict[str, np.ndarray]:
    """Measurements (mm) of ibug68 landmarks ``ibug`` (N, 68, 3) in metres: each of
    :data:`MEASURES` (the mean of its pairs' distances) and :data:`INDICES` (per identity)."""
    p = np.asarray(ibug, np.float64)
    out = {name: 1000.0 * np.mean([np.linalg.norm(p[:, a] - p[:, b], axis=-1) for a, b in pairs], axis=0)
           for name, (_, pairs) in MEASURES.items()}
    for name, (a, b) in INDICES.items():
        out[name] = 100.0 * out[a] / out[b]
    return out


#: how far sideways (m) of the pupil's centre the lid vertices count as the margin above / below it
MARGIN_HALF_WIDTH_M = 0.0015


def margin_reflex_distances(vertices: np.ndarray, regions: dict) -> dict[str, np.ndarray]:
    """MRD1 and MRD2 (mm, mean of both eyes) of heads ``vertices`` (N, V, 3), metres, +z up: the
    height of the upper lid margin above the centre of the ``pupil_l`` / ``pupil_r`` region and of
    the pupil's centre above the lower lid margin. A margin is the lowest ``eyelid_*_upper`` (highest
    ``eyelid_*_lower``) vertex within :data:`MARGIN_HALF_WIDTH_M` sideways of the pupil's centre
    (clinically measured from the corneal light reflex, in primary gaze)."""
    V = np.asarray(vertices, np.float64)
    mrd1, mrd2 = [], []
    for s in "lr":
        pupil = V[:, np.asarray(regions[f"pupil_{s}"])].mean(axis=1)  # (N, 3)
        for lid, out, sign in (("upper", mrd1, 1.0), ("lower", mrd2, -1.0)):
            L = V[:, np.asarray(regions[f"eyelid_{s}_{lid}"])]  # (N, k, 3)
            near = np.abs(L[..., 0] - pupil[:, None, 0]) <= MARGIN_HALF_WIDTH_M
            dz = sign * (L[..., 2] - pupil[:, None, 2])  # above the pupil (upper) / below it (lower)
            out.append(np.where(near, dz, np.inf).min(axis=1))
    return {"MRD1": 1000.0 * np.mean(mrd1, axis=0), "MRD2": 1000.0 * np.mean(mrd2, axis=0)}


#: adult eyeball, transverse diameter (mm): mean, and the range measured (Bekerman, Gottlieb and
#: Vaiman 2014, J. Ophthalmol. 503645: CT of 250 healthy adults, 24.2 mm transverse x 23.7 mm
#: sagittal x 22.0-24.8 mm axial; transverse 21-27 mm; no difference by sex, age or ethnicity)
EYEBALL_TRANSVERSE_MM = (24.2, 21.0, 27.0)


def eyeball_diameters(vertices: np.ndarray, regions: dict) -> np.ndarray:
    """(N,) eyeball diameter (mm, mean of both eyes) of heads ``vertices`` (N, V, 3), metres: twice
    the radius of the least-squares sphere (:func:`synth.model.meshutil.fit_sphere`) through each
    ``sclera_l`` / ``sclera_r`` region (the cornea, proud of it, is not in that region)."""
    from synth.model.meshutil import fit_sphere

    V = np.asarray(vertices, np.float64)
    d = [[2.0 * fit_sphere(head[np.asarray(regions[f"sclera_{s}"])])[1] for s in "lr"] for head in V]
    return 1000.0 * np.mean(d, axis=1)


def reference_range(name: str) -> tuple[float, float] | None:
    """The lowest and highest published mean of a measurement (:data:`REFERENCES`)."""
    means = [m[name][0] for _, _, m in REFERENCES if name in m]
    return (min(means), max(means)) if means else None


def table(values: dict[str, np.ndarray]) -> list[dict]:
    """Rows: measurement, our 5th / 50th / 95th percentiles, the published means' range and how
    many published standard deviations (their largest) our median lies outside that range."""
    rows = []
    for name in [*MEASURES, *INDICES]:
        v = values[name]
        lo, hi = reference_range(name) or (np.nan, np.nan)
        sds = [m[name][1] for _, _, m in REFERENCES if name in m and m[name][1]]
        med = float(np.median(v))
        outside = med - lo if med < lo else med - hi if med > hi else 0.0  # signed, mm (or index units)
        rows.append({"measure": name, "p5": float(np.percentile(v, 5)), "median": med,
                     "p95": float(np.percentile(v, 95)), "published_low": lo, "published_high": hi,
                     "sd_outside": outside / max(sds) if sds else np.nan})
    return rows


def eyes_table(args, ibug: np.ndarray, mrd: dict | None = None, eyeball: np.ndarray | None = None) -> dict:
    """Print and return the table for ``ibug`` (N, 68, 3), the planned identities of ``args``, and
    their margin-reflex distances ``mrd`` (:func:`margin_reflex_distances`) and eyeball diameters
    ``eyeball`` (:func:`eyeball_diameters`) if given."""
    values = eye_measures(ibug)
    rows = table(values)
    print(f"\n### The eyes against published measurements ({args.identities} planned identities of seed "
          f"{args.seed}, neutral; mm)\n")
    print("| measure | ours: 5 % / median / 95 % | published means | median outside them, in published SDs |")
    print("|---|---:|---:|---:|")
    for r in rows:
        pub = f"{r['published_low']:.1f} - {r['published_high']:.1f}" if r["published_low"] == r["published_low"] else "-"
        off = f"{r['sd_outside']:+.1f}" if r["sd_outside"] == r["sd_outside"] else "-"
        print(f"| {r['measure']} | {r['p5']:.1f} / {r['median']:.1f} / {r['p95']:.1f} | {pub} | {off} |")
    print("\nPublished: " + "; ".join(f"{s or '(same)'}: {pop}" for s, pop, _ in REFERENCES))
    out = {"rows": rows, "identities": args.identities, "seed": args.seed}
    if mrd is not None:
        print("\nMargin-reflex distances, gaze 0 (lid margins above / below the pupil's centre; clinical "
              "normal values are commonly given as about 4-4.5 mm / 5-5.5 mm):\n")
        print("| | 5 % / median / 95 % |\n|---|---:|")
        for k, v in mrd.items():
            print(f"| {k} | {np.percentile(v, 5):.1f} / {np.median(v):.1f} / {np.percentile(v, 95):.1f} |")
        out["mrd"] = {k: [float(np.percentile(v, q)) for q in (5, 50, 95)] for k, v in mrd.items()}
    if eyeball is not None:
        mean, lo, hi = EYEBALL_TRANSVERSE_MM
        q = [float(np.percentile(eyeball, p)) for p in (5, 50, 95)]
        print(f"\nEyeball diameter (sphere fitted to the sclera, mean of both eyes), 5 % / median / 95 %: "
              f"{q[0]:.1f} / {q[1]:.1f} / {q[2]:.1f} mm; adults (CT, Bekerman et al. 2014): {mean} mm "
              f"transverse, {lo}-{hi} mm")
        out["eyeball_mm"] = q
    return out


def eyes(args) -> dict:
    """The eyes' proportions of the first planned identities (neutral, rest pose) against
    published measurements (benchmarks/realism/eyes.py)."""

    model, hm, ids, codes = _planned_heads(args.seed, args.identities)
    n = len(ids)
    ev = hm.evaluate(codes, np.zeros((n, model.expression_dims)), np.zeros((n, hm.J, 3)))
    return eyes_table(args, np.asarray(ev.landmarks["ibug68"], np.float64),
                      margin_reflex_distances(ev.vertices, model.regions), eyeball_diameters(ev.vertices, model.regions))
