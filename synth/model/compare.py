"""How two head models differ: every discrete part (topology, UVs, regions, landmark triangles,
joint hierarchy, names, the eyelid rig's vertex lists) must be equal, every float within a
tolerance. It is how a rebuilt default model is checked against the shipped one
(``scripts/build_default_model.py --check``): builds on other CPUs, BLAS kernels, thread counts
or numpy versions agree on every discrete choice, and their floats differ in the last bits only.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from synth.model.format import HeadModelData, _to_members

#: float tolerance (absolute): metres for positions, unit-free for bases, weights, barycentrics and
#: the prior's parameters. Builds on different machines differ by at most about 1e-6 (a float32
#: barycentric's rounding); a real change of the model moves far more.
FLOAT_ATOL = 1e-5


def _diff_json(a: Any, b: Any, where: str, atol: float, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        if sorted(a) != sorted(b):
            out.append(f"{where}: keys {sorted(set(a) ^ set(b))} in one model only")
            return
        for k in sorted(a):
            _diff_json(a[k], b[k], f"{where}.{k}", atol, out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{where}: {len(a)} vs {len(b)} items")
            return
        for i, (x, y) in enumerate(zip(a, b)):
            _diff_json(x, y, f"{where}[{i}]", atol, out)
    elif isinstance(a, float) or isinstance(b, float):
        if not (isinstance(a, (int, float)) and isinstance(b, (int, float))) or abs(a - b) > atol:
            out.append(f"{where}: {a!r} vs {b!r}")
    elif a != b:
        out.append(f"{where}: {a!r} vs {b!r}")


def model_differences(a: HeadModelData, b: HeadModelData, atol: float = FLOAT_ATOL) -> list[str]:
    """One line per difference between ``a`` and ``b`` beyond ``atol`` (empty: the same model)."""
    ma, mb = _to_members(a), _to_members(b)
    out: list[str] = []
    for k in sorted(set(ma) ^ set(mb)):
        out.append(f"{k}: in one model only")
    for k in sorted(set(ma) & set(mb)):
        if k == "meta":
            continue
        x, y = ma[k], mb[k]
        if x.shape != y.shape or x.dtype != y.dtype:
            out.append(f"{k}: {x.dtype}{list(x.shape)} vs {y.dtype}{list(y.shape)}")
        elif x.dtype.kind == "f":
            d = np.abs(x.astype(np.float64) - y.astype(np.float64))
            if d.size and not d.max() <= atol:
                out.append(f"{k}: {int((d > atol).sum())} values differ by up to {d.max():.3g}")
        elif not np.array_equal(x, y):
            out.append(f"{k}: {int((x != y).sum())} of {x.size} entries differ")
    _diff_json(json.loads(ma["meta"].tobytes()), json.loads(mb["meta"].tobytes()), "meta", atol, out)
    return out
