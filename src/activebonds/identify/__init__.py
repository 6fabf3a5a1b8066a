"""Identification of particle-bond parameters with the paper's self-adaptive ES.

The public names are imported when first used, so that reading the settings
(:mod:`.settings`, e.g. for the command line's defaults) does not import JAX.
"""

from ..lazy import exports

_PUBLIC = {
    "FitResult": "activebonds.identify.driver",
    "fit": "activebonds.identify.driver",
    "resume": "activebonds.identify.driver",
    "FitSettings": "activebonds.identify.settings",
}

__all__ = sorted(_PUBLIC)


__getattr__, __dir__ = exports(__name__, _PUBLIC)
