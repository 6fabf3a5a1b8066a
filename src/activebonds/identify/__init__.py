"""Identification of particle-bond parameters with the paper's self-adaptive ES.

The public names are imported when first used, so that reading the settings
(:mod:`.settings`, e.g. for the command line's defaults) does not import JAX.
"""

_PUBLIC = {
    "FitResult": "activebonds.identify.driver",
    "fit": "activebonds.identify.driver",
    "resume": "activebonds.identify.driver",
    "FitSettings": "activebonds.identify.settings",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        import importlib

        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'activebonds.identify' has no attribute '{name}'")


def __dir__():
    return sorted([*globals(), *_PUBLIC])
