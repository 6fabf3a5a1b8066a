"""Whether a body walks over a floor, from its markers alone: the floor under the lowest
markers (:func:`~activebonds.data.orientation.guess_ground`, or the vertical given), the
markers that touch it, the velocity of the surface they stand on while they touch it (zero
for the ground, a belt's on a treadmill) and the body's velocity over that surface.

A marker touches the floor where it is within :data:`~..gravity.CONTACT_REACH` of the floor
level along the vertical; the markers that do in at least :data:`~..gravity.CONTACT_SHARE` of
the frames are the feet. The surface's velocity is the median of the feet's horizontal
velocities while they touch (a foot in stance stands still on it). The body's velocity is
its centre's least-squares straight line in time, horizontal; it walks over the floor where
the two differ by more than :data:`TRAVEL_SHARE` of the body's size a stride (overground the
centre travels; on a treadmill the surface does). Nothing here reads a marker's name, the rate
or the frame count but as numbers of the data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ....nanstats import nanmean
from ..gravity import CONTACT_REACH, CONTACT_SHARE

# the body walks where it moves over the floor by more than this share of its size (the RMS
# distance of its markers from their centre) a stride
TRAVEL_SHARE = 0.5
# a stance foot stands still on the ground (the surface still) or on a belt under a body that
# stays (the body still in the room): the slower of the two at most this share of the
# body's speed over the surface
STILL_SHARE = 0.25


@dataclass(frozen=True)
class Floor:
    """The floor of a recording: the vertical ``axis`` and its sign ``up``, the floor's
    ``height`` along up, the ``feet`` (marker indices touching it), the ``surface`` velocity
    (m/s per axis), the body's velocity over the surface (``over``, m/s per axis) and the
    body's ``size`` (m)."""

    axis: int
    up: float
    height: float
    feet: tuple[int, ...]
    surface: tuple[float, ...]
    over: tuple[float, ...]
    size: float

    @property
    def speed(self) -> float:
        """The body's speed over the surface (m/s)."""
        return float(np.linalg.norm(self.over))

    def walks(self, period_s: float) -> bool:
        """Whether the body travels over the floor by more than :data:`TRAVEL_SHARE` of its
        size in a stride of ``period_s`` seconds, on feet."""
        return bool(self.feet) and self.speed * period_s > TRAVEL_SHARE * self.size

    @property
    def room_speed(self) -> float:
        """The body's speed in the room (m/s): over the surface plus the surface's."""
        return float(np.linalg.norm(np.add(self.over, self.surface)))

    def stands(self) -> bool:
        """Whether the feet stand still on what they touch: the surface still (overground) or
        the body still in the room (a treadmill), within :data:`STILL_SHARE` of the body's
        speed over the surface. A body sliding or tumbling over the floor does neither."""
        still = min(float(np.linalg.norm(self.surface)), self.room_speed)
        return still <= STILL_SHARE * self.speed

    def line(self, names: Sequence[str]) -> str:
        feet = ", ".join(names[i] for i in self.feet) or "none"
        return (
            f"floor at {self.height:.4g} m along {'+' if self.up > 0 else '-'}axis "
            f"{self.axis}, touched by {len(self.feet)} marker(s) ({feet}); the surface moves at "
            f"{np.linalg.norm(self.surface):.3g} m/s, the body over it at {self.speed:.3g} m/s"
        )


def find_floor(positions: np.ndarray, rate: float, names: Sequence[str], up=None) -> Floor | None:
    """The floor of ``positions`` [F, P, D] (NaN where missing) at ``rate`` Hz, ``up`` a
    vertical vector where known (else guessed); None where no floor is found."""
    from ....data import Trajectory
    from ....data.orientation import ground_level, guess_ground

    x = np.asarray(positions, np.float64)
    f, p, d = x.shape
    if f < 3 or p < 2:
        return None
    if up is not None:
        axis = int(np.argmax(np.abs(up)))
        sign = float(np.sign(up[axis]))
        height = ground_level(sign * x[..., axis])
    else:
        mask = np.isfinite(x).all(axis=-1)
        traj = Trajectory(positions=x, mask=mask, markers=tuple(names), rate=float(rate))
        ground = guess_ground(traj)
        if ground is None:
            return None
        axis, sign, height = ground.axis, float(ground.up), float(ground.plane_height)
    h = sign * x[..., axis] - height  # [F, P] above the floor
    with np.errstate(invalid="ignore"):
        touching = h <= CONTACT_REACH
    present = np.isfinite(h)
    share = touching.sum(axis=0) / np.maximum(present.sum(axis=0), 1)
    feet = tuple(int(i) for i in np.flatnonzero(share >= CONTACT_SHARE))
    flat = [a for a in range(d) if a != axis]
    v = np.diff(x, axis=0) * rate  # [F-1, P, D]
    on = touching[1:] & touching[:-1]
    surface = np.zeros(d)
    if feet:
        sel = on[:, list(feet)]
        vf = v[:, list(feet)][sel]  # [N, D]
        vf = vf[np.isfinite(vf).all(axis=1)]
        if len(vf):
            surface[flat] = np.median(vf[:, flat], axis=0)
    centre = nanmean(x, axis=1)
    ok = np.isfinite(centre).all(axis=1)
    body = np.zeros(d)
    if ok.sum() >= 3:
        t = np.arange(f, dtype=np.float64) / rate
        body[flat] = np.polyfit(t[ok], centre[ok][:, flat], 1)[0]
    size = float(np.sqrt(nanmean(np.sum((x - centre[:, None]) ** 2, axis=-1))))
    return Floor(
        axis, sign, float(height), feet, tuple(surface.tolist()), tuple((body - surface).tolist()),
        size,
    )  # fmt: skip
