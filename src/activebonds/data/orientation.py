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
air, or of markers at one height, has no clear answer and is reported as such. Gaps are a
second doubt: in a frame whose foot markers are missing, the lowest marker present may be the
head, and enough such frames turn the guess upside down; so a gappy recording's guess is
checked against its frames with every marker (:func:`ground_doubts`).

:func:`guess_gravity` is a second, independent guess, from the acceleration: only in flight
(a ballistic phase, no marker on the ground) do the markers fall freely, their mean
accelerating at about g downwards (over a whole stride on the ground it averages to about 0,
so the acceleration says nothing there). For each axis and sign taken as up, the flight
frames are those whose lowest marker is more than :data:`FLIGHT_MARGIN` above the ground (the
5th percentile of the lowest marker); over each run of at least :data:`MIN_PHASE` such frames,
the mean position of the markers present throughout is fitted by one parabola in time per run
(a shared acceleration, each run its own position and velocity). The direction whose flight
acceleration is within :data:`GRAVITY_TOLERANCE` of ``-g * up`` (as a vector: sideways
acceleration counts too) is the guess; when none is, there is no guess ("no flight phase
found"), never a forced one.

The vertical is **uncertain** (:func:`vertical_doubts`, :meth:`Ground.describe` given the
gravity guess, "(uncertain: why)") when the ground guess has a doubt, when the feet cue
disagrees with it and the flight does not confirm it, or when the two guesses disagree or the
second is missing; :func:`confident` says when it is not.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..axes import AXES  # noqa: F401 (the table, named here for the readers of orientation)
from ..errors import InputError
from ..nanstats import nanmean
from .trajectory import Trajectory

CLEAR = 0.5  # the flattest axis must score at most this fraction of the next one
G = 9.81  # m/s^2
FLIGHT_MARGIN = 0.03  # m: in flight, the lowest marker is at least this far above the ground
MIN_PHASE = 5  # frames: the shortest flight phase used (a parabola needs a few frames)
GRAVITY_TOLERANCE = 0.25  # the flight acceleration is within this fraction of g of -g * up
MIN_COMPLETE = 10  # frames with every marker needed to check a guess made through gaps
LOW_PERCENTILE = 10  # %: a marker's low level is the height it is at or below this often
FOOT_REACH = 0.02  # m: a foot's low level is within this of the lowest marker's


def parse_up(text: str, dimension: int, numbers: bool = False) -> tuple[float, ...]:
    """The up direction (``--up``) as a vector of ``dimension`` components: an axis, 'Z',
    '+Z' or '-y' (a unit vector); with ``numbers`` also its components, '0,0,1' (not all
    zero). InputError naming ``--up`` otherwise."""
    t = text.strip().upper()
    sign = -1.0 if t.startswith("-") else 1.0
    axis = t.lstrip("+-")
    axes = AXES[:dimension]
    if len(axis) == 1 and axis in axes:
        out = [0.0] * dimension
        out[axes.index(axis)] = sign
        return tuple(out)
    if not numbers:
        raise InputError(
            "--up", f"expected an axis {', '.join(axes)} (optionally + or -), got '{text}'"
        )
    try:
        vec = tuple(float(v) for v in text.split(","))
    except ValueError:
        vec = ()
    if len(vec) != dimension or not np.any(vec):
        raise InputError("--up", f"expected an axis (+Z, -Y) or {dimension} numbers, got {text!r}")
    return vec


@dataclass(frozen=True)
class Ground:
    axis: int  # index of the vertical axis
    up: float  # +1.0 if up is the axis' positive direction, else -1.0
    height: float  # ground level along the axis, m (the 5th percentile of the lowest marker)
    flatness: tuple[float, ...]  # the score of every axis (lower: flatter)
    clear: bool  # the flattest axis is clearly flatter than the others
    lowest: str  # the marker most often lowest (a foot)
    # why the guess may be wrong, from the recording alone (see :func:`ground_doubts`)
    doubts: tuple[str, ...] = ()
    feet: tuple[str, ...] = ()  # the markers the ground rests on (:func:`feet`)
    # the feet cue disagreeing (the ground rests on one marker, another direction has several
    # feet), or "": a doubt unless the acceleration in flight confirms the guess
    against: str = ""

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

    @property
    def up_text(self) -> str:
        return ("+" if self.up > 0 else "-") + AXES[self.axis]

    def describe(self, gravity: Gravity | None = None) -> str:
        """``up = +Z, ground at -0.0105 m (lowest: HFL)``, then ``(uncertain: why)`` when
        there is a doubt: the ground's own (:attr:`doubts`) and, given the ``gravity`` guess,
        :func:`vertical_doubts`."""
        text = f"up = {self.up_text}, ground at {self.height:.4f} m (lowest: {self.lowest})"
        if gravity is None:
            doubts = list(self.doubts) + ([self.against] if self.against else [])
        else:
            doubts = vertical_doubts(self, gravity)
        return text + (f" (uncertain: {'; '.join(doubts)})" if doubts else "")


def guess_ground(traj: Trajectory) -> Ground | None:
    """The vertical axis and ground level of a recording, or None if fewer than two markers
    or frames are present; its :attr:`Ground.doubts` from :func:`ground_doubts`."""
    found = _guess_ground(traj)
    if found is None:
        return None
    return replace(found, doubts=ground_doubts(traj, found))


def ground_doubts(traj: Trajectory, ground: Ground) -> tuple[str, ...]:
    """Why the ground guess may be wrong, from the recording alone: the flattest axis is not
    clearly flatter than the next; or markers are missing in some frames (there the lowest
    *present* marker may be a head: a gap can turn the guess upside down) and the frames with
    every marker say otherwise, or there are too few of them (fewer than
    :data:`MIN_COMPLETE`) to check."""
    out = []
    if not ground.clear:
        out.append("the flattest axis is not clearly flatter than the next")
    mask = np.asarray(traj.mask, bool)
    if mask.all():
        return tuple(out)
    complete = mask.all(axis=1)
    share = f"markers missing in {100 * (1 - complete.mean()):.0f} % of frames"
    if complete.sum() < MIN_COMPLETE:
        out.append(f"{share}, too few frames with every marker to check the guess")
        return tuple(out)
    whole = _guess_ground(_frames(traj, complete))
    if whole is not None and (whole.axis, whole.up) != (ground.axis, ground.up):
        out.append(f"{share}; the frames with every marker say up = {whole.up_text}")
    return tuple(out)


def _frames(traj: Trajectory, keep: np.ndarray) -> Trajectory:
    return Trajectory(
        positions=np.asarray(traj.positions)[keep],
        mask=np.asarray(traj.mask)[keep],
        markers=traj.markers,
        rate=traj.rate,
    )


def feet(h: np.ndarray) -> np.ndarray:
    """The indices of the markers the ground rests on, given their heights ``h`` [F, P] along a
    candidate up (NaN where missing): those whose low level (the :data:`LOW_PERCENTILE` th
    percentile of their heights) is within :data:`FOOT_REACH` of the lowest low level. A
    marker that is lowest in fewer than that share of its frames is no foot."""
    present = ~np.isnan(h).all(axis=0)
    low = np.full(h.shape[1], np.inf)
    if present.any():
        low[present] = np.nanpercentile(h[:, present], LOW_PERCENTILE, axis=0)
    return np.flatnonzero(low <= low.min() + FOOT_REACH)


def ground_level(h: np.ndarray, on: np.ndarray | None = None) -> float:
    """The ground's height along up: the 5th percentile of the lowest of the feet ``on``
    (default :func:`feet`) in each frame where one of them is present; ``h`` [F, P] the
    heights along up, NaN where missing."""
    on = feet(h) if on is None else on
    hf = h[:, on]
    some = ~np.isnan(hf).all(axis=1)
    return float(np.percentile(np.nanmin(hf[some], axis=1), 5))


def _guess_ground(traj: Trajectory) -> Ground | None:
    x = np.asarray(traj.positions, np.float64)  # [F, P, D], NaN where missing
    if x.shape[1] < 2 or x.shape[0] < 2:
        return None
    d = x.shape[2]
    means = nanmean(x, axis=0)  # [P, D]
    present = ~np.isnan(x).any(axis=2)
    rows = present.sum(axis=1) >= 2
    if rows.sum() < 2:
        return None
    scores, signs, on_feet = [], [], []
    for a in range(d):
        spread = float(np.nanmax(means[:, a]) - np.nanmin(means[:, a]))
        best = []
        for sign in (1.0, -1.0):
            # the lowest foot along sign * a, per frame where a foot is present
            h = sign * x[rows, :, a]
            on = feet(h)
            some = ~np.isnan(h[:, on]).all(axis=1)
            low = np.nanmin(h[some][:, on], axis=1)
            score = float(np.std(low)) / spread if spread > 0 and some.any() else np.inf
            best.append((score, sign, on))
        score, sign, on = min(best, key=lambda b: (b[0], -b[1]))
        scores.append(score)
        signs.append(sign)
        on_feet.append(on)
    order = np.argsort(scores, kind="stable")
    axis = int(order[0])
    up = signs[axis]
    coord = up * x[rows, :, axis]
    lowest_marker = np.nanargmin(np.where(np.isnan(coord), np.inf, coord), axis=1)
    counts = np.bincount(lowest_marker, minlength=x.shape[1])
    on = on_feet[axis]
    second = float(scores[order[1]]) if d > 1 else np.inf
    return Ground(
        axis=axis,
        up=up,
        height=up * ground_level(coord, on),
        flatness=tuple(float(s) for s in scores),
        clear=bool(scores[axis] <= CLEAR * second),
        lowest=traj.markers[int(np.argmax(counts))],
        feet=tuple(traj.markers[i] for i in on),
        against=_against(traj, x[rows], axis, up, on),
    )


def _against(traj: Trajectory, x: np.ndarray, axis: int, up: float, on: np.ndarray) -> str:
    """The feet cue's doubt about the flattest direction, or "" (see the module): the ground
    rests on one marker alone while another direction has several feet, or has none with
    more (one marker "on the ground" in every frame may be the top of a hanging body)."""
    if len(on) != 1:
        return ""
    best = None
    for a in range(x.shape[2]):
        for sign in (1.0, -1.0):
            if (a, sign) == (axis, up):
                continue
            other = feet(sign * x[:, :, a])
            if len(other) >= 2 and (best is None or len(other) > len(best[2])):
                best = (a, sign, other)
    if best is None:  # one foot and no direction with more: a body hanging from it (a
        # pendulum, an arm, a chain from a pivot) looks the same upside down
        return (
            f"the ground rests on {traj.markers[on[0]]} alone: a body hanging from it would "
            "look the same upside down"
        )
    a, sign, other = best
    names = ", ".join(traj.markers[i] for i in other)
    return (
        f"the ground rests on {traj.markers[on[0]]} alone, but along "
        f"{'+' if sign > 0 else '-'}{AXES[a]} {len(other)} markers ({names}) reach the "
        f"lowest height in at least {LOW_PERCENTILE:g} % of their frames"
    )


@dataclass(frozen=True)
class Gravity:
    """The vertical as the acceleration in flight says, or none (``axis`` None) and why."""

    axis: int | None  # index of the vertical axis, None if no flight phase was found
    up: float | None  # +1.0 or -1.0
    acceleration: tuple[float, ...] | None  # the markers' mean acceleration in flight, m/s^2
    flight_frames: int  # frames of the flight phases used
    phases: int  # flight phases (runs of at least MIN_PHASE flight frames) used
    reason: str = ""  # why there is no guess

    @property
    def found(self) -> bool:
        return self.axis is not None

    @property
    def normal(self) -> list[float] | None:
        if self.axis is None:
            return None
        n = [0.0] * len(self.acceleration)
        n[self.axis] = self.up
        return n

    @property
    def along_up(self) -> float | None:
        """The flight acceleration along up (about -9.81 m/s^2)."""
        return None if self.axis is None else self.up * self.acceleration[self.axis]

    def describe(self) -> str:
        if self.axis is None:
            return f"none ({self.reason})"
        sign = "+" if self.up > 0 else "-"
        return (
            f"up = {sign}{AXES[self.axis]}: the markers accelerate at {self.along_up:.2f} m/s^2 "
            f"along it in {self.flight_frames} flight frames ({self.phases} phase"
            f"{'s' if self.phases != 1 else ''})"
        )


def _flight_acceleration(x: np.ndarray, mask: np.ndarray, height: np.ndarray, dt: float):
    """(acceleration [D] or None, frames, phases) over the flight frames of one candidate
    up direction (``height`` [F, P], NaN where missing)."""
    from .coverage import present_windows

    some = mask.any(axis=1)
    lowest = np.full(height.shape[0], np.nan)
    lowest[some] = np.nanmin(height[some], axis=1)
    if not some.any():
        return None, 0, 0
    ground = float(np.percentile(lowest[some], 5))
    flight = some & (np.where(some, lowest, -np.inf) > ground + FLIGHT_MARGIN)
    rows, ys, segments = [], [], 0
    for start, stop in present_windows(flight, MIN_PHASE):
        cols = mask[start:stop].all(axis=0)
        if not cols.any():
            continue
        mean = x[start:stop, cols].mean(axis=1)  # [L, D]
        t = (np.arange(stop - start) - (stop - start - 1) / 2) * dt
        rows.append((segments, t))
        ys.append(mean)
        segments += 1
    if not segments:
        return None, 0, 0
    n = sum(len(t) for _, t in rows)
    design = np.zeros((n, 1 + 2 * segments))
    i = 0
    for k, t in rows:
        design[i : i + len(t), 0] = 0.5 * t**2
        design[i : i + len(t), 1 + 2 * k] = 1.0
        design[i : i + len(t), 2 + 2 * k] = t
        i += len(t)
    coef = np.linalg.lstsq(design, np.concatenate(ys), rcond=None)[0]
    return coef[0], n, segments


def guess_gravity(traj: Trajectory) -> Gravity:
    """The vertical axis from the acceleration of the markers in flight (see the module's
    docstring), or a :class:`Gravity` without axis saying why there is none."""
    x = np.asarray(traj.positions, np.float64)  # [F, P, D], NaN where missing
    mask = np.asarray(traj.mask, bool)
    d = x.shape[2]
    if x.shape[0] < MIN_PHASE:
        return Gravity(None, None, None, 0, 0, f"fewer than {MIN_PHASE} frames")
    best, any_flight = None, 0
    for axis in range(d):
        for up in (1.0, -1.0):
            acc, frames, phases = _flight_acceleration(x, mask, up * x[:, :, axis], traj.dt)
            if acc is None:
                continue
            any_flight = max(any_flight, frames)
            expected = np.zeros(d)
            expected[axis] = -up * G
            miss = float(np.linalg.norm(acc - expected))
            if miss <= GRAVITY_TOLERANCE * G and (best is None or miss < best[0]):
                best = (miss, axis, up, acc, frames, phases)
    if best is None:
        reason = (
            "no flight phase found: the lowest marker never leaves the ground"
            if not any_flight
            else f"no flight phase found: the markers never fall at about {G} m/s^2 while "
            "the lowest is off the ground"
        )
        return Gravity(None, None, None, 0, 0, reason)
    _, axis, up, acc, frames, phases = best
    return Gravity(axis, up, tuple(float(a) for a in acc), frames, phases)


def vertical_doubts(ground: Ground, gravity: Gravity) -> list[str]:
    """Why the vertical may be wrong: the ground guess's own doubts, the feet cue disagreeing
    with it (:attr:`Ground.against`) unless the acceleration in flight confirms it, and the
    second guess (the acceleration in flight) disagreeing or missing."""
    out = list(ground.doubts)
    if ground.against and not agree(ground, gravity):
        out.append(ground.against)
    if not gravity.found:
        out.append("no flight phase to check it against")
    elif not agree(ground, gravity):
        sign = "+" if gravity.up > 0 else "-"
        out.append(f"the acceleration in flight says up = {sign}{AXES[gravity.axis]}")
    return out


def confident(ground: Ground | None, gravity: Gravity) -> bool:
    """Whether the vertical is known without doubt: a ground guess with no doubt, which the
    acceleration in flight confirms."""
    return ground is not None and not vertical_doubts(ground, gravity)


def agree(ground: Ground | None, gravity: Gravity) -> bool | None:
    """Whether the two guesses name the same up (None unless both found one)."""
    if ground is None or not gravity.found:
        return None
    return ground.axis == gravity.axis and ground.up == gravity.up
