"""Masses from a flight: the frames where a body is off the ground.

Off the ground, gravity and the bonds inside the body alone move it: no contact force hides
how much each particle weighs, and a model of springs between the particles can explain the
motion exactly. Fitted there by multiple shooting (the estimator that marker noise does not
bias, at substeps that resolve the springs), with the masses free under ``total_mass``, a
model's masses and internal bonds are identified together; the contacts, inactive there, are
then fitted on every frame with the masses held and every bond parameter the flight
determined well (the rest fitted there again). On MuJoCo's thrown body
(``scripts/mujoco_thrown.py``: 39 frames in flight) this gives the five masses within a few
per cent where the masses scaffolded as equal shares are 35-73 % off
(``tests/test_flight_masses.py``).

* :func:`longest_flight`: the longest run of frames in flight (every contact's particle off
  its plane: :func:`~.structure_choice.flight_frames`), at least :data:`MIN_FLIGHT` frames;
* :func:`freed`: a model's fixed masses made free (bounds a tenth to ten times each value,
  as every free mass given without bounds), their scale fixed by ``total_mass``, its anchors
  dropped (nothing in the room holds a body in flight);
* :func:`determined`: the bond parameters the flight determined within :data:`HOLD`;
* :func:`held`: a model whose masses and those parameters are fixed at the flight's values,
  the rest (the contacts, the flight's loose parameters) left free.
"""

from __future__ import annotations

import numpy as np

from ... import bonds
from ...model.schema import ModelSpec
from ...model.values import Param, VectorParam, Weights

# frames in flight in a row, at least: two of the shooting's 10-frame windows, so that the
# masses are seen through a continuity defect and not a single window's start
MIN_FLIGHT = 20
# a bond parameter the flight determines within this share of its value (its 95 % interval)
# is held on every frame; a looser one is fitted there again (a body whose springs the flight
# hardly stretches leaves them to the landing)
HOLD = 0.25


def longest_flight(spec: ModelSpec, positions, first: int = 0) -> tuple[int, int] | None:
    """The longest run of consecutive frames of ``positions`` [F, P, D] in which every contact
    of ``spec`` is off its plane, as absolute frames ``(start, stop)`` (``first``: the frame
    of ``positions[0]``); None without contacts or gravity, or where the longest run is
    shorter than :data:`MIN_FLIGHT`."""
    from ...model import build
    from .structure_choice import flight_frames

    if not np.any(np.asarray(build(spec).params.gravity) != 0.0):  # the model's own field
        return None
    flight = flight_frames(spec, positions)
    if flight is None:
        return None
    best, start = (0, 0), None
    for i, up in enumerate([*flight.tolist(), False]):
        if up and start is None:
            start = i
        elif not up and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    if best[1] - best[0] < MIN_FLIGHT:
        return None
    return first + best[0], first + best[1]


def anchors(spec: ModelSpec) -> int:
    """The number of ``spec``'s anchors (springs to a fixed point of the room)."""
    return sum(b.kind == bonds.unary.KIND.name for b in spec.bond)


def freed(spec: ModelSpec) -> ModelSpec:
    """``spec`` with every mass free from its value (bounds a tenth to ten times it), under
    ``total_mass`` (the masses' sum where it has none), and without anchors: a body in flight
    is held by nothing in the room, and an anchor there would stand for a force it does not
    feel."""
    from .structure_choice import mass_of

    particles = [p.model_copy(update={"mass": Param(value=mass_of(p))}) for p in spec.particle]
    total = spec.total_mass if spec.total_mass is not None else sum(map(mass_of, spec.particle))
    kept = [b for b in spec.bond if b.kind != bonds.unary.KIND.name]
    return spec.model_copy(update={"particle": particles, "total_mass": float(total), "bond": kept})


def _fixed(value):
    if isinstance(value, Param | VectorParam | Weights):
        return value.model_copy(update={"fixed": True})
    return value


def determined(estimates, genes, share: float = HOLD) -> set[tuple[int, str]]:
    """The bond parameters, as (the bond's index in the model file, its key), that a run's
    uncertainty record determined within ``share`` of their value (their 95 % interval inside
    ``value * (1 -+ share)``). ``estimates``: the record's (``RunDir(run).record
    ("uncertainty")["estimates"]``: dicts with ``name``, ``value``, ``low``, ``high``,
    ``determined``); ``genes``: the fitted model's layout's (:class:`~.model.genes.Gene`),
    which say what each estimate's parameter is: a bond's own scalar (one bond, no type, no
    axis) counts, a type's shared one, a mass or a vector's axis does not."""
    by_name = {g.name: g for g in genes}
    out = set()
    for e in estimates:
        gene = by_name.get(e.get("name"))
        if gene is None or gene.owner != "bond" or gene.type is not None or not e["determined"]:
            continue
        if len(gene.bonds) != 1 or gene.axis is not None or gene.part is not None:
            continue
        value, low, high = (e.get(k) for k in ("value", "low", "high"))
        if None in (value, low, high):
            continue
        if value > 0 and low >= value * (1.0 - share) and high <= value * (1.0 + share):
            out.add((gene.bonds[0], gene.key))
    return out


def held(spec: ModelSpec, masses: np.ndarray, hold: set[tuple[int, str]]) -> ModelSpec:
    """``spec`` with its masses fixed at ``masses`` [P] (kg) and the bond parameters in
    ``hold`` ((bond index, key): :func:`determined`) fixed at their values; the rest free."""
    particles = [
        p.model_copy(update={"mass": float(m)})
        for p, m in zip(spec.particle, np.asarray(masses, np.float64), strict=True)
    ]
    kept = [
        b.model_copy(
            update={
                name: _fixed(getattr(b, name)) for name in type(b).model_fields if (i, name) in hold
            }
        )
        for i, b in enumerate(spec.bond)
    ]
    return spec.model_copy(update={"particle": particles, "bond": kept})
