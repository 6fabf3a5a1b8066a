"""A fitted gait on the bundled horse (issues 28 and 25): springs, anchors and a periodic
force per marker driven by an entrained phase, its free run scored as a gait.

    python scripts/horse_gait.py [--json docs/results/horse_gait.json] [--gait trot|walk|both]
                                 [--out runs/gait] [--harmonics 3] [--refine]

For each gait of the bundled VHDC horse (Horse1_M1 trot1 and walk1, all 7 markers), fitted on
frames 0-299 and judged on frames 300-599:

1. the model: ``activebonds scaffold``'s complete graph (21 binary spring-dampers and an
   anchor per marker, no gravity), plus a ``periodic`` force on every marker (a Fourier series
   of ``--harmonics`` harmonics in the drive's phase), the drive entrained by the left fore
   hoof's height (``[drive] coupling``: d psi/dt = 2 pi f - sigma (z_HFL - z0) cos psi, z0 the
   hoof's mean height over 0-299, f the fit range's stride frequency);
2. the fit: for each drive gain sigma of a grid (and each start phase), the exact one-step
   least squares of every spring, anchor and coefficient (identify/lsq.py, the phase tracked
   along frames 0-299); kept: the lowest one-step RMS on the validation tail 240-299 of a fit
   on 0-239 (nothing held out is looked at), then refitted on 0-299;
3. optionally (``--refine``) ``fit --refine lm --cost shooting --horizon 10,30`` from it;
4. the scores, each beside the zero-force predictor's: ``activebonds evaluate --frames 300:600
   --horizon 10 --body Head,Withers,Sacrum --gait`` (one step, 10 ahead, frames within 50 mm,
   body frames, the gait metrics of issue 28), and the gait metrics of the recording itself.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GAITS = {"trot": "horse-trot", "walk": "horse-walk"}
FIT, TEST, TRAIN, TAIL = (0, 300), (300, 600), (0, 240), (240, 300)
BODY = ("Head", "Withers", "Sacrum")
SIGNAL = "HFL"  # the hoof whose height entrains the drive
GAINS = (0.0, 5.0, 10.0, 20.0, 40.0, 80.0)  # rad/s per m


def drive_text(frequency: float, gain: float, offset: float, start: float) -> str:
    return (
        "\n[drive]\n"
        f"frequency = {frequency:.6g}  # Hz: the fit range's stride (the hoof height's period)\n"
        f'coupling = {{ particle = "{SIGNAL}", gain = {gain:.6g}, offset = {offset:.6g}, '
        f"start_phase = {start:.6g} }}  # {SIGNAL}'s mean height over the fit range\n"
    )


def periodic_text(names, masses, accelerations, harmonics: int) -> str:
    """A periodic force on every particle, coefficients free within 3 x m x its largest
    recorded acceleration."""
    out = []
    for name, m, a in zip(names, masses, accelerations, strict=True):
        bound = 3.0 * m * a
        lines = [
            f"\n# {name}: a periodic force, bounds 3 x its mass x its largest acceleration "
            f"{a:.3g} m/s^2",
            "[[bond]]",
            'kind = "periodic"',
            f'particles = ["{name}"]',
        ]
        for h in range(1, harmonics + 1):
            for wave in ("cos", "sin"):
                lines.append(
                    f"{wave}{h} = {{ value = [0.0, 0.0, 0.0], min = {-bound:.6g}, max = {bound:.6g} }}"
                )
        out.append("\n".join(lines) + "\n")
    return "".join(out)


def model_text(traj, harmonics: int, gain: float, start: float = 0.0) -> str:
    """The scaffold's complete graph and anchors, no gravity, a periodic force per marker and
    the entrained drive; every number from frames 0-299."""
    from activebonds.identify.scaffold import scaffold
    from activebonds.report import gait as g

    base = scaffold(traj, frames=FIT, gravity=False).text
    x = np.asarray(traj.positions, np.float64)[FIT[0] : FIT[1]]
    names = list(traj.markers)
    z = x[:, names.index(SIGNAL), 2]
    period = g.dominant_period(z)
    frequency = traj.rate / period
    acc = np.linalg.norm(np.diff(x, 2, axis=0), axis=-1).max(axis=0) * traj.rate**2
    masses = [1.0] * len(names)  # the scaffold's (1 kg a marker)
    header, _, bodies = base.partition("\n[[particle]]")
    text = header + drive_text(frequency, gain, float(z.mean()), start) + "\n[[particle]]" + bodies
    return text + periodic_text(names, masses, acc, harmonics)


def variant_spec(text: str, traj, springs: str):
    """The model of ``text`` with its springs as ``springs`` says: "free" (rest lengths and
    anchors free, as the scaffold writes them), "fixed" (rest lengths and anchors fixed at
    their means over the fit range: the springs pull towards the fit range's mean pose) or
    "anchors" (no binary spring: each marker on its own anchor, forced)."""
    from activebonds.model import loads_model

    spec = loads_model(text).spec
    x = np.asarray(traj.positions, np.float64)[FIT[0] : FIT[1]]
    names = [p.name for p in spec.particle]
    out = []
    for b in spec.bond:
        if b.kind == "binary" and springs == "anchors":
            continue
        if springs in ("fixed", "anchors") and b.kind in ("binary", "unary"):
            ends = [x[:, names.index(n)] for n in b.particles]
            if b.kind == "binary":
                d = float(np.nanmean(np.linalg.norm(ends[1] - ends[0], axis=-1)))
                b = b.model_copy(update={"rest_length": d})
            else:
                b = b.model_copy(update={"anchor": [float(v) for v in np.nanmean(ends[0], axis=0)]})
        out.append(b)
    return spec.model_copy(update={"bond": out})


def solved(spec, traj, frames):
    """Every candidate kept, solved by the exact least squares on ``frames``: a Model."""
    from activebonds.identify.settings import FitSettings
    from activebonds.identify.structure import structure_of
    from activebonds.model import build

    found = structure_of(build(spec), traj, FitSettings(frames=frames), 0, False)
    return build(found.spec)


def one_step_rms(model, traj, offset: int) -> float:
    from activebonds.identify.predictions import one_step

    rec = np.asarray(traj.positions, np.float64)
    err2 = np.sum((one_step(model, rec, traj.dt, offset=offset) - rec) ** 2, axis=-1)
    return float(np.sqrt(np.nanmean(err2)) * 1000.0)
