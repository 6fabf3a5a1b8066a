"""Which way is up, and where the ground is, as the recorded markers say.

A model with gravity and ground contact must be written the right way up, in the recording's
own axes. On a standing or walking body, some marker (a hoof, a heel, a toe) is on the ground
in nearly every frame, so along the vertical axis the lowest marker of each frame stays at
almost the same height, while the markers themselves are spread over the body's height. Along
a horizontal axis the lowest coordinate moves with the gait (or the spread is small).

:func:`guess_ground` scores each axis by how flat the per-frame minimum is relative to the
markers' spread (``flatness = std_t(min_p x_a) / spread_a``, spread = range of the markers'
mean positions), picks the flattest, signs it so that the markers' mean lies above the
minimum, and takes the ground height as the 5th percentile of the per-frame minimum. The
guess says how sure it is (its score beside the next axis's): a recording of a body in the
air, or of markers at one height, has no clear answer and is reported as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .trajectory import Trajectory

AXES = "XYZ"
CLEAR = 0.5  # the flattest axis must score at most this fraction of the next one


@dataclass(frozen=True)
class Ground:
    axis: int  # index of the vertical axis
    up: float  # +1.0 if up is the axis' positive direction, else -1.0
    height: float  # ground level along the axis, m (the 5th percentile of the lowest marker)
    flatness: tuple[float, ...]  # the score of every axis (lower: flatter)
    clear: bool  # the flattest axis is clearly flatter than the others
    lowest: str  # the marker most often lowest (a foot)

    @property
    def normal(self) -> list[float]:
        """The upward unit vector, as a contact bond's ``normal``."""
        n = [0.0] * len(self.flatness)
        n[self.axis] = self.up
        return n

    @property
    def plane_height(self) -> float:
        """The ground's offset along ``normal`` (a contact bond's ``height``)."""
        return self.up * self.height

    def describe(self) -> str:
        sign = "+" if self.up > 0 else "-"
        text = (
            f"up = {sign}{AXES[self.axis]}, ground at {self.height:.4f} m (lowest: {self.lowest})"
        )
        return text if self.clear else text + " (uncertain)"


def guess_ground(traj: Trajectory) -> Ground | None:
    """The vertical axis and ground level of a recording, or None if fewer than two markers
    or frames are present."""
    x = np.asarray(traj.positions, np.float64)  # [F, P, D], NaN where missing
    if x.shape[1] < 2 or x.shape[0] < 2:
        return None
    d = x.shape[2]
    means = np.nanmean(x, axis=0)  # [P, D]
    present = ~np.isnan(x).any(axis=2)
    rows = present.sum(axis=1) >= 2
    if rows.sum() < 2:
        return None
    scores, signs = [], []
    for a in range(d):
        spread = float(np.nanmax(means[:, a]) - np.nanmin(means[:, a]))
        # the lowest marker along +a and along -a, per frame
        low_pos = np.nanmin(x[rows, :, a], axis=1)
        low_neg = np.nanmax(x[rows, :, a], axis=1)
        best = []
        for sign, low in ((1.0, low_pos), (-1.0, low_neg)):
            score = float(np.std(low)) / spread if spread > 0 else np.inf
            best.append((score, sign))
        score, sign = min(best)
        scores.append(score)
        signs.append(sign)
    order = np.argsort(scores)
    axis = int(order[0])
    up = signs[axis]
    coord = up * x[rows, :, axis]
    low = np.nanmin(coord, axis=1)
    lowest_marker = np.nanargmin(np.where(np.isnan(coord), np.inf, coord), axis=1)
    counts = np.bincount(lowest_marker, minlength=x.shape[1])
    height = up * float(np.percentile(low, 5))
    second = float(scores[order[1]]) if d > 1 else np.inf
    return Ground(
        axis=axis,
        up=up,
        height=height,
        flatness=tuple(float(s) for s in scores),
        clear=bool(scores[axis] <= CLEAR * second),
        lowest=traj.markers[int(np.argmax(counts))],
    )
