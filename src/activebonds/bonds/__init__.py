"""Bond kinds: one module per kind, declared once and found through the registry.

Adding a kind is a module defining a :class:`BondKind` and one ``register(...)`` line (below,
or in the code that uses it); the model file, genome layout, physics, least squares and
report follow from its declaration.
"""

from . import binary, contact, periodic, ternary, unary
from .kind import (
    ANGLE,
    NON_NEGATIVE,
    POSITIVE,
    BondKind,
    Check,
    LinearPart,
    MujocoForm,
    Parameter,
    PopulationForm,
    spread,
)
from .registry import drive_kind, drive_kinds, get, kinds, names, register, registered, unregister

register(unary.KIND)
register(binary.KIND)
register(ternary.KIND)
register(contact.KIND)
register(periodic.KIND)

__all__ = [
    "ANGLE",
    "NON_NEGATIVE",
    "POSITIVE",
    "BondKind",
    "Check",
    "LinearPart",
    "MujocoForm",
    "Parameter",
    "PopulationForm",
    "drive_kind",
    "drive_kinds",
    "get",
    "kinds",
    "names",
    "register",
    "registered",
    "spread",
    "unregister",
]
