"""Appearance models, pure numpy (no bpy): what colour skin, irises and hair are.

- :mod:`synth.appearance.skin`: skin albedo from melanin and haemoglobin;
- :mod:`synth.appearance.skin_optics`: subsurface radii, the two specular lobes, which skin
  details a render resolves;
- :mod:`synth.appearance.iris`: iris colour from melanin over a scattering stroma;
- :mod:`synth.appearance.pigment`: hair colours as melanin concentrations.

The Blender shaders that use them are in ``blender_scripts/`` (materials, asset rigs).
"""
