"""Particle-bond models: the model file, its validation, topology and genome layout."""

from .io import dumps_model, load_model, loads_model, parse_model, save_model
from .layout import Gene, Layout
from .model import Model, build
from .params import Params, Topology
from .schema import ModelSpec
from .variants import as_neural, as_standard

__all__ = [
    "Gene",
    "Layout",
    "Model",
    "ModelSpec",
    "Params",
    "Topology",
    "as_neural",
    "as_standard",
    "build",
    "dumps_model",
    "load_model",
    "loads_model",
    "parse_model",
    "save_model",
]
