"""Edge recovery on the NRI springs benchmark by structure identification.

Each trajectory of :mod:`.springs` is fitted with the candidate model (one optional spring per
pair of particles) by :func:`activebonds.identify.discover.structure.identify_structure`: backward
elimination under the BIC on the exact one-step least squares. The walls are known physics
that the model does not contain: the particle-frames near a wall (:func:`.springs.near_wall`)
are masked, as gaps, so no prediction across a bounce enters the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.smoothing import smooth_positions
from ..identify.costs.windows import make_windows
from ..identify.discover.structure import identify_structure
from ..model import loads_model
from .springs import FRAME_DT, candidate_model_toml, near_wall


@dataclass
class EdgeResult:
    correct: int  # pairs decided right (present vs absent)
    pairs: int
    truth: list[int]  # per candidate bond, in the model's order
    found: list[int]
    stiffness: list[float]  # identified stiffness of the pairs found present
    rms: float  # one-step RMS of the identified model (simulation units)


def recover_edges(positions: np.ndarray, edges: np.ndarray, smooth: int = 0) -> EdgeResult:
    """Identify the springs of one trajectory [F, N, 2] and compare with ``edges`` [N, N].
    ``smooth``: a Savitzky-Golay window (frames, 0: off) applied to the whole recording,
    targets included, before the fit: the one-step residual then regresses smoothed
    accelerations, SINDy's usual practice with noisy data."""
    n = positions.shape[1]
    model = loads_model(candidate_model_toml(n), "springs candidates")
    mask = ~near_wall(positions)
    if smooth:
        positions = smooth_positions(positions, np.ones(positions.shape[:2], bool), smooth)
    windows = make_windows(positions, mask, FRAME_DT, 1)  # masked positions are not read
    result = identify_structure(model, windows)
    truth, found, stiffness = [], [], []
    for d, bond in zip(result.decisions, result.spec.bond, strict=True):
        i, j = (int(p[1:]) for p in bond.particles)
        truth.append(int(edges[i, j]))
        found.append(int(d.present))
        if d.present:
            stiffness.append(float(bond.stiffness.value))
    correct = sum(int(a == b) for a, b in zip(truth, found, strict=True))
    return EdgeResult(
        correct=correct,
        pairs=len(truth),
        truth=truth,
        found=found,
        stiffness=stiffness,
        rms=result.rms_mm / 1000.0,
    )
