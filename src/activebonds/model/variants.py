"""Standard vs mechanical-neural variants of a model (the paper's Series 1 and Series 2)."""

from __future__ import annotations

from .model import Model, build
from .values import Param, Weights


def as_standard(model: Model) -> Model:
    """Every binary bond a plain viscoelastic bond: neurons (and their drive) removed."""
    off = {"neural": False, "gain": None, "weights": None, "threshold": None}
    off |= {"drive_weight": None, "drive_phase": None}
    bonds = [b.model_copy(update=off) if b.kind == "binary" else b for b in model.spec.bond]
    return build(model.spec.model_copy(update={"bond": bonds}), disable=model.disabled)


def as_neural(model: Model, *, gain: Param | None = None) -> Model:
    """Every binary bond mechanical-neural; its neuron reads all other binary bonds (§2).

    Neural parameters already in the file are kept; missing ones become free with defaults:
    gain in [0, 100] N, threshold in [-5, 5], weights in [-10, 10].
    """
    gain = gain or Param(value=1.0, min=0.0, max=100.0)
    bonds = []
    for b in model.spec.bond:
        if b.kind == "binary":
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
        bonds.append(b)
    return build(model.spec.model_copy(update={"bond": bonds}), disable=model.disabled)
