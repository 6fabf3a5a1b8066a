"""Whether a recording is a walk, from its data alone: a stride repeats (:mod:`.stride`,
trusted), markers touch a floor and the body travels over it by more than half its size a
stride (:mod:`.floor`: overground the body moves, on a treadmill the belt), while a stance
foot stands still on the ground or on a belt under a body that stays. A body swinging,
sliding or stepping in place, a recording with no floor under it or no repeating stride is no walk.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .floor import Floor, find_floor
from .stride import Stride, find_stride


@dataclass(frozen=True)
class Walk:
    """A recording found to walk: its stride and its floor."""

    stride: Stride
    floor: Floor

    def lines(self, names: Sequence[str]) -> list[str]:
        return [self.stride.line(), self.floor.line(names)]


def recognise(positions: np.ndarray, rate: float, names: Sequence[str], up=None) -> Walk | str:
    """The walk of ``positions`` [F, P, D] (NaN where missing) at ``rate`` Hz, or why it is
    none (one line); ``up``: the vertical vector where known."""
    stride = find_stride(positions, rate)
    if stride is None:
        return "no stride repeats within the frames (they must hold more than one)"
    if not stride.trusted:
        return f"no stride repeats clearly: {stride.line()}"
    floor = find_floor(positions, rate, names, up)
    if floor is None or not floor.feet:
        return "no marker touches a floor"
    period_s = stride.period / stride.rate
    if not floor.walks(period_s):
        return (
            f"the body does not travel over its floor: {floor.speed:.3g} m/s over it, "
            f"{floor.speed * period_s:.3g} m a stride for a body of {floor.size:.3g} m"
        )
    if not floor.stands():
        return (
            f"the feet do not stand on the floor: the surface under them moves at "
            f"{np.linalg.norm(floor.surface):.3g} m/s and the body in the room at "
            f"{floor.room_speed:.3g} m/s (a walk holds one of them still)"
        )
    return Walk(stride, floor)
