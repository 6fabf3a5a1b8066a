"""Public names of a package imported when first used (PEP 562), so that importing the
package, or a light module of it, imports nothing heavy (JAX) by itself."""

from __future__ import annotations

import importlib
from collections.abc import Callable


def exports(package: str, public: dict[str, str]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` of ``package`` for its ``public`` names (name -> the module
    that defines it)."""
    namespace = vars(importlib.import_module(package))

    def getattr_(name: str):
        if name in public:
            value = getattr(importlib.import_module(public[name]), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module '{package}' has no attribute '{name}'")

    def dir_():
        return sorted([*namespace, *public])

    return getattr_, dir_
