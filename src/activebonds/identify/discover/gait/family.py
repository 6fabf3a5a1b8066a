"""The gait family: a model that walks, trots or swings on its own, built from a recording.

Each marker is held by an anchor (a unary spring-damper to its mean position over the fitted
frames, the anchor moving at the body's mean velocity where the body travels,
:func:`~.rhythm.body_velocity`) and pushed by a periodic force, a Fourier series of
``harmonics`` in the drive's phase psi (DESIGN.md §2, "Periodic force"). The drive's frequency
is the recording's stride (:mod:`.rhythm`); its phase is a state of the model entrained by the
most periodic signal of the body (:mod:`.signals`), with its quarter-stride partner where
there is one: ``d psi/dt = 2 pi f - sigma s cos psi - sigma_b s_b sin psi``. Every anchor's
damping is at least ``2 m f decay`` (``decay`` e-folds of a free transient per stride: the
body forgets a disturbance within the stride and settles on the drive's orbit).

Given psi tracked along the recording, every force is linear in its parameters: the exact
one-step least squares (:func:`~..structure.structure_of`, every bond kept) solves the
stiffnesses, dampings and coefficients at once (:func:`solve`). Nothing here reads a marker's
name, the rate or the frame count but as numbers of the data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .... import bonds
from ....nanstats import nanmean
from .rhythm import Rhythm
from .signals import Signal, balanced_gain, gain_for, partner

# The coefficients' bounds: this many times a marker's mass times its largest acceleration
FORCE_REACH = 3.0


@dataclass(frozen=True)
class GaitVariant:
    """One model of the family: ``harmonics`` of the periodic forces, the coupling strength
    ``kappa`` (0: a clock), the anchors' damping floor in e-folds per stride (``decay``) and
    whether the drive also reads the first signal's quarter-stride partner."""

    harmonics: int = 6
    kappa: float = 0.16
    decay: float = 4.0
    quadrature: bool = True

    def text(self) -> str:
        pair = " with its quarter-stride partner" if self.quadrature else ""
        drive = "a clock" if self.kappa == 0 else f"coupling strength {self.kappa:g}{pair}"
        return (
            f"{self.harmonics} harmonics, {drive}, anchors' damping {self.decay:g} e-folds a stride"
        )


def gait_spec(
    positions: np.ndarray,
    names: Sequence[str],
    rhythm: Rhythm,
    signals: list[Signal],
    variant: GaitVariant,
    mass: float = 1.0,
    name: str = "gait",
):
    """The model of ``variant`` for ``positions`` [F, P, D] (the frames it will be fitted
    on; ``names``: one per particle, the markers'), its drive read from ``signals`` (most
    periodic first, :func:`~.signals.survey` over the same frames): a ModelSpec to solve."""
    from ....model.schema import ModelSpec

    x = np.asarray(positions, np.float64)
    f = rhythm.frequency
    dt = 1.0 / rhythm.rate
    first = signals[0]
    second = partner(signals, first) if variant.quadrature and variant.kappa > 0 else None
    gain = gain_for(first, variant.kappa, f) if variant.kappa > 0 else 0.0
    coupling = first.table(names, gain) | {"start_phase": 0.0}
    if second is not None:
        coupling["quadrature"] = second.table(names, balanced_gain(first, gain, second))
    u = np.asarray(rhythm.velocity, np.float64)
    t = np.arange(x.shape[0]) * dt
    centre = nanmean(x - u * t[:, None, None], axis=0)  # [P, D]: the anchors at t = 0
    floor = 2.0 * mass * f * variant.decay
    held = []
    for i, n in enumerate(names):
        acc = np.linalg.norm(np.diff(x[:, i], 2, axis=0), axis=-1) / dt**2
        bound = FORCE_REACH * mass * float(np.nanmax(acc)) if np.isfinite(acc).any() else 1.0
        held.append(_anchor(n, centre[i], u, mass, rhythm, floor))
        held.append(_periodic(n, variant.harmonics, bound, x.shape[2]))
    particles = [
        {"name": n, "mass": mass, "position": _first(x[:, i]), "velocity": [0.0] * x.shape[2]}
        for i, n in enumerate(names)
    ]
    return ModelSpec.model_validate(
        {
            "name": name,
            "dimension": x.shape[2],
            "drive": {"frequency": f, "coupling": coupling},
            "particle": particles,
            "bond": held,
        }
    )


def _first(xi: np.ndarray) -> list[float]:
    """A marker's first recorded position."""
    ok = np.isfinite(xi).all(axis=1)
    return [float(v) for v in xi[np.argmax(ok)]] if ok.any() else [0.0] * xi.shape[1]


def _anchor(name: str, centre, velocity, mass: float, rhythm: Rhythm, floor: float) -> dict:
    """A marker's anchor: stiffness and damping free within a spring's bounds for ``mass``
    over the recording (a tenth of the stride's stiffness to a tenth of the rate's), the
    damping at least ``floor``."""
    w = 2.0 * np.pi * rhythm.frequency
    k_lo, k_hi = mass * w**2 / 100.0, 10.0 * mass * (np.pi * rhythm.rate) ** 2
    c_hi = max(20.0 * mass * rhythm.rate, 2.0 * floor)
    c_lo = max(floor, 2.0 * mass * rhythm.frequency / 100.0)
    out = {
        "kind": bonds.unary.KIND.name,
        "particles": [name],
        "optional": True,
        "anchor": [float(v) for v in centre],
        "stiffness": {"value": float(np.sqrt(k_lo * k_hi)), "min": k_lo, "max": k_hi},
        "damping": {"value": c_lo, "min": c_lo, "max": c_hi},
    }
    if np.any(velocity != 0):
        out["anchor_velocity"] = [float(v) for v in velocity]
    return out


def _periodic(name: str, harmonics: int, bound: float, dimension: int) -> dict:
    out = {"kind": bonds.periodic.KIND.name, "particles": [name], "optional": True}
    for h in range(1, harmonics + 1):
        for wave in ("cos", "sin"):
            out[f"{wave}{h}"] = {"value": [0.0] * dimension, "min": -bound, "max": bound}
    return out


def solve(spec, recording, frames: tuple[int, int]):
    """The model of ``spec`` with every stiffness, damping and coefficient at the exact one-step
    least squares on ``frames`` of ``recording`` (the drive's phase tracked along it): a
    Model. Where the bonds split the particles into groups no force joins (:func:`groups`),
    each group is solved on its own: the same optimum (the one-step cost is a sum over the
    groups, their unknowns apart), a problem the size of one group at a time."""
    from ....model import build

    parts = groups(spec)
    if len(parts) == 1:
        return build(_solved(spec, recording, frames))
    solved = list(spec.bond)
    for particles, held in parts:
        if not held:  # a marker no force acts on: nothing to solve
            continue
        sub = spec.model_copy(
            update={
                "particle": [spec.particle[k] for k in particles],
                "bond": [spec.bond[i] for i in held],
            }
        )
        for i, bond in zip(held, _solved(sub, recording, frames).bond, strict=True):
            solved[i] = bond
    return build(spec.model_copy(update={"bond": solved}))


def _solved(spec, recording, frames: tuple[int, int]):
    from ....model import build
    from ...settings import FitSettings
    from ..structure import structure_of

    return structure_of(build(spec), recording, FitSettings(frames=frames), 0, False).spec


def groups(spec) -> list[tuple[list[int], list[int]]]:
    """The particles of ``spec`` in groups no force joins, each with its bonds: (particle
    indices, bond indices) per group, the connected components of the bonds. One group where
    something else joins them: a drive entrained by the body (its phase reads markers), a
    free gravity (one magnitude for all), bonds sharing parameters by type, or a bond with
    no particle."""
    from ....model.schema import GravityParam

    coupled = spec.drive is not None and spec.drive.coupling is not None
    if coupled or isinstance(spec.gravity, GravityParam) or any(b.type for b in spec.bond):
        return [(list(range(len(spec.particle))), list(range(len(spec.bond))))]
    index = {p.name: k for k, p in enumerate(spec.particle)}
    root = list(range(len(spec.particle)))

    def find(k: int) -> int:
        while root[k] != k:
            root[k] = root[root[k]]
            k = root[k]
        return k

    for b in spec.bond:
        ends = [index[n] for n in b.particles]
        if not ends:
            return [(list(range(len(spec.particle))), list(range(len(spec.bond))))]
        for k in ends[1:]:
            root[find(k)] = find(ends[0])
    members: dict[int, tuple[list[int], list[int]]] = {}
    for k in range(len(spec.particle)):
        members.setdefault(find(k), ([], []))[0].append(k)
    for i, b in enumerate(spec.bond):
        members[find(index[b.particles[0]])][1].append(i)
    return list(members.values())
