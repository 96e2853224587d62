"""The evaluated head (vertices, landmarks, joint frames), the camera projection and the plan are
the same bits whatever BLAS kernel, SIMD loops or numpy version computes them: frame labels and
plans do not depend on the node that made them (synth.geometry.exact; docs/determinism.md)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NP2 = ROOT / ".venv-np2" / "bin" / "python"

SCRIPT = """
import hashlib, numpy as np
from synth.model.default import default_model_path
from synth.model.format import read_model
from synth.model.head import HeadModel
d = read_model(default_model_path())
rng = np.random.default_rng(5)
B = 3
codes = (rng.normal(size=(B, d.identity_dims)) * 2.0, rng.normal(size=(B, d.expression_dims)),
         rng.normal(size=(B, len(d.joint_names), 3)) * 0.2, rng.normal(size=(B, 3)) * 0.01)
h = hashlib.sha256()
for dt in (np.float32, np.float64):
    ev = HeadModel(d, dt).evaluate(*codes)
    for a in (ev.vertices, ev.joint_transforms, *(ev.landmarks[k] for k in sorted(ev.landmarks))):
        h.update(np.ascontiguousarray(a).tobytes())
from synth.conventions import intrinsics, invert_rigid, orbit_camera_to_world, project
c2w = orbit_camera_to_world(rng.uniform(-180, 180, 40), rng.uniform(-60, 60, 40), rng.uniform(0.5, 2.0, 40),
                            np.zeros(3), rng.uniform(-10, 10, 40))
lm = np.broadcast_to(ev.landmarks["ibug68"][0].astype(np.float64), (40, 68, 3))
uv, depth = project(intrinsics(256, 256, 50.0), invert_rigid(c2w), lm)
h.update(c2w.tobytes() + uv.tobytes() + depth.tobytes())
print(h.hexdigest())
"""

PLAN = """
import hashlib, json, sys, tempfile
import numpy as np
from types import SimpleNamespace
from synth.cli.main import main
from synth.model.default import default_model_path
from synth.model.format import read_model
from synth.plan.cameras import uniforms_to_spherical
from synth.plan.expressions import truncated_normal_ppf
from synth.plan.head_shapes import measure_codes
from synth.plan.identities import look_at_targets, prior_of, sample_identities
# the plan rounds its floats to 8 decimals, which hides most last-bit differences: hash the values
# before rounding too
d = read_model(default_model_path())
codes = sample_identities(3, np.arange(300), prior_of(d), None)
u = np.random.default_rng(1).random((2000, 3))
cam = SimpleNamespace(azimuth_deg=(-90.0, 90.0), elevation_deg=(-35.0, 55.0), radius_m=(0.6, 1.2),
                      elevation_sampling="area")
raw = hashlib.sha256(codes.tobytes() + look_at_targets(d, codes, "eyes", 0.0).tobytes()
                     + b"".join(v.tobytes() for v in measure_codes(d, codes).values())  # head-shape redraws
                     + b"".join(a.tobytes() for a in uniforms_to_spherical(u, cam))
                     + truncated_normal_ppf(u[:, 0], -2.5, 1.7).tobytes()).hexdigest()
out = tempfile.mkdtemp()
try:
    main(["plan", "-n", "40", "--seed", "11", "-o", out, "-q"])
except SystemExit as e:
    assert not e.code, e.code
print(raw, json.load(open(out + "/plan.json"))["plan_hash"])
"""

NO_AVX512 = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL"
SETTINGS = [
    ("this machine", sys.executable, {}),
    ("OpenBLAS Haswell, 1 thread", sys.executable, {"OPENBLAS_CORETYPE": "Haswell", "OPENBLAS_NUM_THREADS": "1"}),
    ("OpenBLAS Prescott, 2 threads", sys.executable, {"OPENBLAS_CORETYPE": "Prescott", "OPENBLAS_NUM_THREADS": "2"}),
    ("numpy without AVX-512 loops", sys.executable, {"NPY_DISABLE_CPU_FEATURES": NO_AVX512}),
    # the C library's exp/log/sin without its FMA/AVX2 variants (what a CPU without them runs)
    ("glibc without FMA/AVX2", sys.executable, {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F"}),
]
if NP2.is_file():
    SETTINGS.append(("numpy 2.x", str(NP2), {}))
    SETTINGS.append(("numpy 2.x without AVX2/FMA3", str(NP2), {"NPY_DISABLE_CPU_FEATURES": NO_AVX512 + " AVX2 FMA3"}))


def _digest(python: str, extra: dict, script: str = SCRIPT) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OPENBLAS_", "NPY_"))}
    env.update(extra, PYTHONPATH=str(ROOT))
    p = subprocess.run([python, "-c", script], capture_output=True, text=True, cwd=ROOT, env=env, timeout=600)
    assert p.returncode == 0, p.stderr
    return p.stdout.strip().splitlines()[-1]


@pytest.mark.slow
def test_head_evaluation_is_the_same_bits_under_every_kernel_and_numpy_version():
    digests = {name: _digest(python, extra) for name, python, extra in SETTINGS}
    assert len(set(digests.values())) == 1, digests


@pytest.mark.slow
def test_a_plan_is_the_same_bits_under_every_kernel_and_numpy_version():
    digests = {name: _digest(python, extra, PLAN) for name, python, extra in SETTINGS}
    assert len(set(digests.values())) == 1, digests
