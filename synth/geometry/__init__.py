"""Geometry helpers, one home each (numpy/scipy, no Blender), tested against scipy and trimesh:

- :mod:`synth.geometry.rotations`: axis-angle <-> matrix, rigid (Kabsch) fit, screw axis,
  minimal rotation between directions;
- :mod:`synth.geometry.normals`: dot products, unit vectors, face normals, area/angle-weighted
  vertex normals;
- :mod:`synth.geometry.closest`: closest points on triangles and on meshes;
- :mod:`synth.geometry.sdf`: signed distance to a mesh (pseudo-normal, vertex-normal or
  face-normal sign);
- :mod:`synth.geometry.raycast`: ray-triangle intersection (hit counts, first/last hit) and
  grid-accelerated parity rays along one axis.

The package imports only numpy; ``closest`` and ``sdf`` (scipy KD trees) are imported by name
when needed. OBJ reading lives in :mod:`synth.model.importers.obj`; general mesh utilities
(sphere fits, connectivity, boundaries, sampling) in :mod:`synth.model.meshutil`.
"""

from synth.geometry.normals import dot, face_normals, normalize, vertex_normals
from synth.geometry.raycast import RayGrid, first_hits, ray_hit_counts
from synth.geometry.rotations import (axis_angle_to_matrix, fit_rigid, matrix_to_axis_angle, rotate_between,
                                      rotation_pivot)

__all__ = ["RayGrid", "axis_angle_to_matrix", "dot", "face_normals", "first_hits", "fit_rigid", "matrix_to_axis_angle",
           "normalize", "ray_hit_counts", "rotate_between", "rotation_pivot", "vertex_normals"]
