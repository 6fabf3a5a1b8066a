"""Standard vs mechanical-neural variants of a model (the paper's Series 1 and Series 2).

The bonds switched are those of the kinds whose bonds may carry a neuron (a kind declaring an
``activity``: the binary bonds).
"""

from __future__ import annotations

from .. import bonds
from .model import Model, build
from .values import Param, Weights


def _may_be_neural(bond) -> bool:
    """Whether the bond's kind declares a neuron (:attr:`~activebonds.bonds.kind.BondKind.activity`)."""
    return bonds.get(bond.kind).activity is not None


def as_standard(model: Model) -> Model:
    """Every binary bond a plain viscoelastic bond: neurons (and their drive) removed."""
    off = {"neural": False, "gain": None, "weights": None, "threshold": None}
    off |= {"drive_weight": None, "drive_phase": None}
    changed = [b.model_copy(update=off) if _may_be_neural(b) else b for b in model.spec.bond]
    return build(model.spec.model_copy(update={"bond": changed}), disable=model.disabled)


def as_neural(model: Model, *, gain: Param | None = None) -> Model:
    """Every binary bond mechanical-neural; its neuron reads all other binary bonds (§2).

    Neural parameters already in the file are kept; missing ones become free with defaults:
    gain in [0, 100] N, threshold in [-5, 5], weights in [-10, 10].
    """
    gain = gain or Param(value=1.0, min=0.0, max=100.0)
    changed = []
    for b in model.spec.bond:
        if _may_be_neural(b):
            b = b.model_copy(
                update={
                    "neural": True,
                    "gain": b.gain if b.gain is not None else gain,
                    "threshold": b.threshold
                    if b.threshold is not None
                    else Param(value=0.0, min=-5.0, max=5.0),
                    "weights": b.weights if b.weights is not None else Weights(),
                }
            )
        changed.append(b)
    return build(model.spec.model_copy(update={"bond": changed}), disable=model.disabled)
