"""Identification of particle-bond parameters with the paper's self-adaptive ES."""

from .driver import FitResult, fit, resume
from .settings import FitSettings

__all__ = ["FitResult", "FitSettings", "fit", "resume"]
