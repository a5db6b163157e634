"""Versioned parameter files (models/*.yaml, fits/*.yaml): load, validate, save, reduce."""

from hframe_id.parameters.files import (
    FORMAT_VERSION,
    ParameterSet,
    load_parameter_file,
    save_parameter_file,
)

__all__ = ["FORMAT_VERSION", "ParameterSet", "load_parameter_file", "save_parameter_file"]
