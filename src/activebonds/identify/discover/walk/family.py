"""The walk family: a body that walks, each marker pushed by a force periodic in the phase of
the gait, nothing holding it to a place in the room.

Walking repeats: a marker's acceleration at a given phase of the stride is much the same each
stride (the swing leg's pendulum, the heel strike, the pelvis' rise and fall), and it is what
the zero-force (constant-velocity) predictor misses. Each marker carries a periodic force
(:mod:`~activebonds.bonds.periodic`), a Fourier series of ``harmonics`` in the drive's phase
``psi = 2 pi f t``, ``f`` the stride's frequency found from the data
(:mod:`.stride`), the model's time from the fitted frames' first. There is no anchor and no
spring to the room: the forces move the body as the gait does wherever it walks, overground or
on a treadmill. Optionally (``segments``) the markers of one body segment (pairs whose distance
varies by at most that share of its mean over the fitted frames) are joined by damped
springs at their mean distance.

Given the phase, every force is linear in its parameters: the exact one-step least squares
solves every coefficient (and the segments' stiffnesses and dampings) at once
(:func:`~..gait.family.solve`). Nothing here reads a marker's name, the rate or the frame count
but as numbers of the data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .... import bonds
from ....nanstats import nanmean
from ..gait.family import FORCE_REACH, _periodic
from .stride import Stride


@dataclass(frozen=True)
class WalkVariant:
    """One model of the family: the periodic forces' ``harmonics`` and the segments' spread
    (0: no segment springs)."""

    harmonics: int = 8
    segments: float = 0.0

    def text(self) -> str:
        seg = (
            f", markers of a segment (distance spread within {100 * self.segments:g} %) "
            "joined by damped springs"
            if self.segments
            else ""
        )
        return f"a periodic force per marker, {self.harmonics} harmonics of the stride{seg}"


def walk_spec(
    positions: np.ndarray,
    names: Sequence[str],
    stride: Stride,
    variant: WalkVariant = WalkVariant(),
    mass: float = 1.0,
    name: str = "walk",
    seen: Sequence[int] | None = None,
):
    """The model of ``variant`` for ``positions`` [F, P, D] (the frames it will be fitted on,
    NaN where missing; ``names``: one per particle, the markers'), its drive a clock at
    ``stride``'s frequency: a ModelSpec to solve (:func:`~..gait.family.solve`). ``seen``:
    each marker's harmonics where already found (:func:`harmonics_seen`)."""
    from ....model.schema import ModelSpec

    x = np.asarray(positions, np.float64)
    dt = 1.0 / stride.rate
    held = []
    if seen is None:
        seen = harmonics_seen(x, stride, variant.harmonics)
    for i, (n, h) in enumerate(zip(names, seen, strict=True)):
        if h == 0:
            continue  # too little of the stride seen: no force (constant velocity)
        acc = np.linalg.norm(np.diff(x[:, i], 2, axis=0), axis=-1) / dt**2
        bound = FORCE_REACH * mass * float(np.nanmax(acc)) if np.isfinite(acc).any() else 1.0
        held.append(_periodic(n, h, max(bound, 1e-6), x.shape[2]))
    if variant.segments > 0:
        held += segment_bonds(x, names, variant.segments, mass, stride.rate)
    particles = [{"name": n, "mass": mass} for n in names]
    return ModelSpec.model_validate(
        {
            "name": name,
            "dimension": x.shape[2],
            "drive": {"frequency": stride.frequency},
            "particle": particles,
            "bond": held,
        }
    )


def phase_gaps(positions: np.ndarray, stride: Stride) -> np.ndarray:
    """Each marker's largest gap in the stride's phase (a share of the stride, 0-1) among
    the frames of ``positions`` [F, P, D] where its one-step prediction counts (the frame
    before, the frame itself and the frame after present), the phase from the first frame;
    1 where it counts nowhere."""
    present = np.isfinite(np.asarray(positions, np.float64)).all(axis=-1)
    counts = present[:-2] & present[1:-1] & present[2:]  # [F-2, P]: frames 1..F-2
    phase = (np.arange(1, present.shape[0] - 1) / stride.period) % 1.0
    gaps = np.ones(present.shape[1])
    for i in range(present.shape[1]):
        seen = np.sort(phase[counts[:, i]])
        if len(seen):
            gaps[i] = float(np.diff(np.r_[seen, seen[0] + 1.0]).max())
    return gaps


def harmonics_seen(positions: np.ndarray, stride: Stride, harmonics: int) -> list[int]:
    """Each marker's harmonics: at most ``harmonics``, and at most ``1 / (2 gap)`` for its
    largest gap in the stride's phase (:func:`phase_gaps`): the highest harmonic's half
    cycle no longer than any stretch of the stride it was not seen in (a marker hidden over
    part of the stride, as a lab's cameras lose one, gets a smoother force there, not a
    guess). 0: no force."""
    gaps = phase_gaps(positions, stride)
    return [int(min(harmonics, np.floor(0.5 / max(g, 1e-9)))) for g in gaps]


def segment_bonds(x: np.ndarray, names, spread: float, mass: float, rate: float) -> list[dict]:
    """Damped springs at their mean length between the markers whose distance over ``x``
    [F, P, D] varies (standard deviation) by at most ``spread`` of its mean."""
    d = np.linalg.norm(x[:, :, None] - x[:, None, :], axis=-1)
    mean, sd = nanmean(d, axis=0), np.nanstd(d, axis=0)
    k_hi, c_hi = 10.0 * mass * (np.pi * rate) ** 2, 20.0 * mass * rate
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if np.isfinite(mean[i, j]) and mean[i, j] > 0 and sd[i, j] <= spread * mean[i, j]:
                out.append(
                    {
                        "kind": bonds.binary.KIND.name,
                        "particles": [names[i], names[j]],
                        "optional": True,
                        "rest_length": float(mean[i, j]),
                        "stiffness": {"value": 0.0, "min": 0.0, "max": k_hi},
                        "damping": {"value": 0.0, "min": 0.0, "max": c_hi},
                    }
                )
    return out
