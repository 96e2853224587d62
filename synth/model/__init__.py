"""Linear 3D morphable head models: file format, evaluation, prior, builders, importers."""

from synth.model.format import HeadModelData, read_model, write_model, validate_model
from synth.model.head import HeadModel

__all__ = ["HeadModelData", "HeadModel", "read_model", "write_model", "validate_model"]
