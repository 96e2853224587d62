"""Geometry helpers, one home each (numpy/scipy, no Blender), tested against scipy and trimesh:

- :mod:`synth.geometry.rotations`: axis-angle <-> matrix, rigid (Kabsch) fit, screw axis;
- :mod:`synth.geometry.normals`: unit vectors, face normals, area/angle-weighted vertex normals;
- :mod:`synth.geometry.raycast`: ray-triangle intersection (hit counts, first/last hit).

OBJ reading lives in :mod:`synth.model.importers.obj`; general mesh utilities (sphere fits,
connectivity, boundaries, sampling) in :mod:`synth.model.meshutil`.
"""

from synth.geometry.normals import face_normals, normalize, vertex_normals
from synth.geometry.raycast import first_hits, ray_hit_counts
from synth.geometry.rotations import axis_angle_to_matrix, fit_rigid, matrix_to_axis_angle, rotation_pivot

__all__ = ["axis_angle_to_matrix", "face_normals", "first_hits", "fit_rigid", "matrix_to_axis_angle", "normalize",
           "ray_hit_counts", "rotation_pivot", "vertex_normals"]
