"""Eye-glasses: parametric frame geometry and a contact solver, in plain numpy (no bpy).

The rig (``blender_scripts.assets.glasses``) only turns the result into Blender meshes.
Geometry is in metres, world axes: Z up, the face looks toward -Y, +X is the subject's left.

* :mod:`.spec`: styles, colours and the frame description completed from the plan's
  parameters (:func:`.spec.frame_spec`);
* :mod:`.shapes`: lens outlines (superellipse ``|u/a|^n + |z/b|^n = 1`` with per-style
  edits: aviator tear-drop, cat-eye wing lift), swept tubes, ellipsoids, polylines;
* :mod:`.front`: rims, lenses, bridge, end pieces and hinges in frame space;
* :mod:`.contact`: ear rests, the path behind the ear, the nose bridge, the head query
  (signed distance from :mod:`synth.geometry.sdf`, parity rays from
  :class:`synth.geometry.raycast.RayGrid`);
* :mod:`.solve`: the pose solve (:func:`.solve.fit_glasses`: front slid back to first
  contact, nose pads on the nose, temples to the ear rests) and its contact measures.
"""
