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

from .rhythm import Rhythm
from .signals import Signal, balanced_gain, gain_for, partner

# The coefficients' bounds: this many times a marker's mass times its largest acceleration
FORCE_REACH = 3.0
CALIBRATIONS = 5  # the drive frequency's bisection steps, at most
CALIBRATION_REACH = 0.15  # and its reach, a share of the recording's stride frequency
CALIBRATED = 0.003  # the free run's stride within this share of the recording's: done


@dataclass(frozen=True)
class GaitVariant:
    """One model of the family: ``harmonics`` of the periodic forces, the coupling strength
    ``kappa`` (0: a clock), the anchors' damping floor in e-folds per stride (``decay``) and
    whether the drive also reads the first signal's quarter-stride partner; ``calibrate``:
    the drive's frequency set for the free run's stride (:func:`calibrated`)."""

    harmonics: int = 6
    kappa: float = 0.16
    decay: float = 4.0
    quadrature: bool = True
    calibrate: bool = False

    def text(self) -> str:
        pair = " with its quarter-stride partner" if self.quadrature else ""
        drive = "a clock" if self.kappa == 0 else f"coupling strength {self.kappa:g}{pair}"
        calibrated = ", frequency calibrated" if self.calibrate else ""
        return (
            f"{self.harmonics} harmonics, {drive}, anchors' damping {self.decay:g} e-folds a "
            f"stride{calibrated}"
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
    centre = np.nanmean(x - u * t[:, None, None], axis=0)  # [P, D]: the anchors at t = 0
    floor = 2.0 * mass * f * variant.decay
    bonds = []
    for i, n in enumerate(names):
        acc = np.linalg.norm(np.diff(x[:, i], 2, axis=0), axis=-1) / dt**2
        bound = FORCE_REACH * mass * float(np.nanmax(acc)) if np.isfinite(acc).any() else 1.0
        bonds.append(_anchor(n, centre[i], u, mass, rhythm, floor))
        bonds.append(_periodic(n, variant.harmonics, bound, x.shape[2]))
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
            "bond": bonds,
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
        "kind": "unary",
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
    out = {"kind": "periodic", "particles": [name], "optional": True}
    for h in range(1, harmonics + 1):
        for wave in ("cos", "sin"):
            out[f"{wave}{h}"] = {"value": [0.0] * dimension, "min": -bound, "max": bound}
    return out


def solve(spec, recording, frames: tuple[int, int], rhythm: Rhythm | None = None):
    """The model of ``spec`` with every stiffness, damping and coefficient at the exact one-step
    least squares on ``frames`` of ``recording`` (the drive's phase tracked along it): a
    Model. With ``rhythm`` (the recording's over ``frames``), the drive's frequency is
    calibrated too (:func:`calibrated`)."""
    from ....model import build
    from ...settings import FitSettings
    from ..structure import structure_of

    model = build(structure_of(build(spec), recording, FitSettings(frames=frames), 0, False).spec)
    if rhythm is None or spec.drive.coupling is None:
        return model
    return calibrated(model, recording, frames, rhythm)


def calibrated(model, recording, frames: tuple[int, int], rhythm: Rhythm):
    """The solved gait ``model`` with its drive's frequency f set so that its free run keeps
    the recording's stride: the one-step least squares tracks the phase along the recording,
    where the body's signal holds it to the recorded stride whatever f, so it cannot tell f;
    in a free run the model's own signal pulls the phase, and the loop's stride is not f's.
    The free run's stride (:func:`free_frequency`) is brought to the recording's by bisection
    of f within :data:`CALIBRATION_REACH` of it (the model solved again at each f, up to
    :data:`CALIBRATIONS` times); the model whose free stride is nearest the recording's is
    kept (the loop may lock to the body's own rhythm, its stride jumping past the
    recording's)."""
    x = np.asarray(recording.positions, np.float64)[frames[0] : frames[1]]
    target = rhythm.frequency
    seen = []

    def at(f: float):
        m = model if f == target else _with_frequency(model, f, recording, frames)
        run = free_frequency(m, x, rhythm)
        seen.append((abs(run / target - 1.0) if np.isfinite(run) else np.inf, len(seen), m))
        return run

    run = at(target)
    if not np.isfinite(run) or abs(run / target - 1.0) <= CALIBRATED:
        return model
    # within half the coupling's lock range: the phase tracked along the recording stays locked
    reach = min(CALIBRATION_REACH, 0.5 * _kappa(model, x, rhythm))
    lo, hi = (target, target * (1 + reach))
    if run > target:
        lo, hi = target * (1 - reach), target
    for _ in range(CALIBRATIONS):
        mid = 0.5 * (lo + hi)
        run = at(mid)
        if not np.isfinite(run) or abs(run / target - 1.0) <= CALIBRATED:
            break
        lo, hi = (mid, hi) if run < target else (lo, mid)
    return min(seen, key=lambda t: t[:2])[2]


def _kappa(model, positions: np.ndarray, rhythm: Rhythm) -> float:
    """The coupling strength of ``model``'s first signal over ``positions``: sigma A / 2 /
    (2 pi f), A its fundamental's amplitude at the recorded stride."""
    from .signals import fundamental

    c = model.spec.drive.coupling
    gain = float(getattr(c.gain, "value", c.gain))
    topo = model.topology.drive
    s = _signal_values(topo, positions)
    _, amplitude, _ = fundamental(s, rhythm.frequency, rhythm.rate)
    return gain * amplitude / 2.0 / (2.0 * np.pi * rhythm.frequency)


def _signal_values(signal, positions: np.ndarray) -> np.ndarray:
    x = np.asarray(positions, np.float64)
    if len(signal.particles) == 1:
        return x[:, signal.particles[0], signal.axis]
    a, b = signal.particles
    return np.linalg.norm(x[:, b] - x[:, a], axis=-1)


def _with_frequency(model, f: float, recording, frames):
    """``model``'s spec at drive frequency ``f``, solved again."""
    from ....model import build
    from ...settings import FitSettings
    from ..structure import structure_of

    drive = model.spec.drive.model_copy(update={"frequency": float(f)})
    spec = build(model.spec.model_copy(update={"drive": drive}))
    return build(structure_of(spec, recording, FitSettings(frames=frames), 0, False).spec)


def free_frequency(model, positions: np.ndarray, rhythm: Rhythm, strides: float = 6.0) -> float:
    """The stride frequency (Hz) of ``model``'s free run from the first two frames of
    ``positions`` (the drive's phase tracked there): its phase's mean rate over the run's last
    two thirds (the first third lets it settle) over 2 pi; NaN where the run fails."""
    from ...judge.predictions import free_run

    dt = 1.0 / rhythm.rate
    n = int(np.ceil(strides * rhythm.period)) + 2
    _, _, psi = free_run(model, positions[:3], dt, n, with_phases=True)
    k = n // 3
    if not np.isfinite(psi[[k, n - 1]]).all():
        return float("nan")
    return float((psi[n - 1] - psi[k]) / ((n - 1 - k) * dt) / (2.0 * np.pi))
