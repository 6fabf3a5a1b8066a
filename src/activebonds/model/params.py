"""Static topology apart from dynamic numbers (brax/MJX style).

``Topology`` holds index arrays (which particles each bond joins), kind by kind; ``Params``
holds the numbers of one individual, as array leaves that can be vmapped over a population:
``params.bonds["binary"]["stiffness"]`` is the [N] stiffness of the model's binary bonds.
Both list every kind registered when the model was built (:mod:`activebonds.bonds`), in
registry order, with empty arrays for kinds the model does not use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np


class Signal(NamedTuple):
    """A body signal (static): minus ``offset`` (m), the coordinate ``axis`` of particle
    ``particles[0]`` (one particle: a height) or the distance between ``particles`` (two: a
    length)."""

    particles: tuple[int, ...]
    axis: int
    offset: float


class Coupling(NamedTuple):
    """What pulls an entrained drive's phase (static): minus ``offset`` (m), the coordinate
    ``axis`` of particle ``particles[0]`` (one particle: a height) or the distance between
    ``particles`` (two: a length); the drive's shared numbers are read from the bond of kind
    ``kind`` at index ``holder`` among its kind's (the first that reads the drive: a neural
    bond, or a periodic force); ``quadrature`` a second signal, read against sin psi (None:
    the one signal)."""

    particles: tuple[int, ...]
    axis: int
    offset: float
    holder: int
    kind: str
    quadrature: Signal | None = None

    @property
    def read(self) -> tuple[int, ...]:
        """Every particle the coupling reads (the first signal's, then the second's)."""
        extra = () if self.quadrature is None else self.quadrature.particles
        return self.particles + tuple(p for p in extra if p not in self.particles)


@dataclass(frozen=True, eq=False)
class Topology:
    """Particle count, dimension and bond index arrays: fixed for a whole identification.

    ``bonds[kind]`` holds ``"particles"`` [N, arity] (int32; a ternary bond's angle is at its
    middle particle) and one [N] bool array per flag of the kind (``"neural"`` for binary
    bonds). The bonds of a kind in ``disabled`` exert no force and carry no genes."""

    n_particles: int
    dimension: int
    bonds: dict[str, dict[str, np.ndarray]]
    disabled: frozenset[str] = field(default_factory=frozenset)
    drive: Coupling | None = None  # an entrained drive's signal (None: a clock, or no drive)

    def count(self, kind: str) -> int:
        """Number of bonds of ``kind`` (0 for a kind the model does not know)."""
        arrays = self.bonds.get(kind)
        return 0 if arrays is None else int(arrays["particles"].shape[0])

    def particles(self, kind: str) -> np.ndarray:
        return self.bonds[kind]["particles"]

    def active(self) -> tuple[str, ...]:
        """Kinds with bonds that are not disabled, in registry order."""
        return tuple(k for k in self.bonds if k not in self.disabled and self.count(k))


class Params(NamedTuple):
    """The numbers of one model (SI units): masses [P], the uniform field [D] and, per bond
    kind, its parameters by field (``[N]`` scalars, ``[N, D]`` vectors, ``[N, N]`` weights)."""

    mass: np.ndarray
    gravity: np.ndarray
    bonds: dict[str, dict[str, np.ndarray]]
