"""synth: procedural synthetic face data (bpy-free core)."""

__version__ = "0.1.0"
