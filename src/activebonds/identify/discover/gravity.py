"""The scaffold's gravity and ground: the vertical (named by ``--up``, or guessed from the
recording: the ground's flattest axis, the acceleration in flight) and the ground contacts of
the markers that reach the ground, each block with the rule behind its numbers."""

from __future__ import annotations

import math
import warnings

import numpy as np

from ... import bonds
from ...data.orientation import AXES
from ...errors import InputError
from ...nanstats import nanmean
from .model_text import quoted, searched, vector

G = 9.81  # m/s^2
FLAT = 1e-3  # m: a recording whose markers span less than this along an axis is flat there
CONTACT_REACH = 0.02  # m: a marker this close to the ground touches it, at most ...
# ... and at most this share of the body's size (the median over frames of its markers' largest
# extent along an axis): 2 cm for a body of 0.29 m and larger (a human, a horse, MuJoCo's
# thrown body), 2.2 mm for a mouse of 3.2 cm, whose hip a fixed 2 cm put on the ground
CONTACT_REACH_SHARE = 0.07
CONTACT_SHARE = 0.05  # of the frames: a contact marker is on the ground at least this often
HEIGHT_RANGE = 0.05  # m: the ground's height is free within this of its guess (impacts go deep)
PENETRATION = 0.005  # m: the contacts hold the body's weight at this depth
BELT_SPEED = 0.1  # m/s: contact markers sliding faster than this ride a treadmill belt
BELT_SPREAD = 0.5  # a belt's velocity: the contacts' (interquartile range) within this share
FRICTION = (0.8, 0.0, 2.0)  # Coulomb coefficient: value, min, max


def _flat_axes(x: np.ndarray) -> list[int]:
    extent = np.nanmax(x, axis=(0, 1)) - np.nanmin(x, axis=(0, 1))
    return [a for a in range(x.shape[2]) if not extent[a] >= FLAT]


def gravity_axis(traj, up: str | None, gravity: bool | None, notes: list[str]):
    """(axis, sign) of up, gravity acting along -up, or None for no gravity: as ``up`` names
    it, else guessed from the recording (:func:`_guessed`); the note on it added to ``notes``."""
    from ...data.orientation import parse_up

    x = np.asarray(traj.positions)
    d = x.shape[2]
    flat = _flat_axes(x)
    source = traj.source or "the recording"
    asked = gravity is True or up is not None
    if gravity is False and up is not None:
        raise InputError(
            "--up",
            f"--up {up} names gravity's vertical and --no-gravity leaves gravity out: give one",
        )
    if gravity is False:
        notes.append("gravity: none (--no-gravity)")
        return None
    if up is not None:
        vector = parse_up(up, d)
        axis = int(np.argmax(np.abs(vector)))
        sign = vector[axis]
        if axis in flat:
            raise InputError(
                source,
                f"the recording is flat along {AXES[axis]} (its markers span less than "
                f"{FLAT * 1000:g} mm there): no vertical for gravity along --up {up}",
            )
        down = ("-" if sign > 0 else "+") + AXES[axis]
        notes.append(f"gravity: along {down} (--up {up})")
        return axis, sign
    if d == 2 or flat:
        why = (
            "a 2D recording"
            if d == 2
            else f"a flat recording (no extent along {', '.join(AXES[a] for a in flat)})"
        )
        if asked:
            raise InputError(
                source,
                f"{why}: its plane may be horizontal, so the vertical cannot be guessed for "
                "gravity; give --up AXIS or --no-gravity",
            )
        notes.append(f"gravity: none ({why}: give --up AXIS to add it)")
        return None
    return _guessed(traj, asked, source, notes)


def _guessed(traj, asked: bool, source: str, notes: list[str]):
    """(axis, sign) of up guessed from the ground and the acceleration in flight, or None
    where the vertical is uncertain (an InputError where gravity was ``asked`` for)."""
    from ...data.orientation import agree, guess_gravity, guess_ground

    ground = guess_ground(traj)
    fall = guess_gravity(traj)
    agrees = agree(ground, fall)
    # the ground guess alone when it is clear; a doubtful one when the acceleration in flight
    # (gravity itself, an independent cue) confirms it
    sure = (
        ground is not None
        and (ground.clear or agrees is True)
        and agrees is not False
        and not (ground.against and agrees is None)
    )
    if not sure and fall.found:  # (a flight that agreed would have made it sure)
        # gravity itself, measured in flight, names the vertical where the ground cue cannot
        # (a body at rest most of the time keeps every coordinate of its lowest marker flat)
        other = "no ground guess" if ground is None else f"the ground guess {ground.describe()}"
        notes.append(
            f"gravity: the vertical from the acceleration in flight, {fall.describe()}; "
            f"{other} is not used"
        )
        return fall.axis, fall.up
    if not sure:
        said = "no guess" if ground is None else ground.describe()
        if ground is not None and agrees is False:
            said += f", but the acceleration in flight says {fall.describe()}"
        elif ground is not None and not ground.clear and "(uncertain:" not in said:
            said += " (not clearly flatter than another axis)"  # once: its doubts say why
        if asked:
            raise InputError(
                source, f"the vertical is uncertain ({said}); give --up AXIS or --no-gravity"
            )
        notes.append(f"gravity: none (the vertical is uncertain: {said}; give --up AXIS)")
        return None
    confirmed = (
        "" if ground.clear else f"; confirmed by the acceleration in flight: {fall.describe()}"
    )
    notes.append(
        f"gravity: the vertical guessed from the recording, {ground.describe()}{confirmed}"
    )
    return ground.axis, ground.up


def _ground(x: np.ndarray, axis: int, sign: float) -> float:
    """The ground along up: the 5th percentile of the lowest foot of each frame (the feet:
    the markers that reach the lowest height often, :func:`~activebonds.data.orientation.feet`)."""
    from ...data.orientation import ground_level

    return ground_level(sign * x[:, :, axis])


def contact_reach(x: np.ndarray) -> float:
    """How close to the ground a marker touches it (m): :data:`CONTACT_REACH`, or
    :data:`CONTACT_REACH_SHARE` of the body's size where that is less (``x``: the markers'
    positions [F, P, D], NaN where missing; the size is the median over frames of their
    largest extent along an axis)."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame with no marker: NaN
        extent = np.nanmax(x, axis=1) - np.nanmin(x, axis=1)
        size = float(np.nanmedian(np.nanmax(extent, axis=1)))
    return min(CONTACT_REACH, CONTACT_REACH_SHARE * size) if np.isfinite(size) else CONTACT_REACH


def contact_blocks(x, mask, names, axis, sign, total, dt, notes) -> list[str]:
    """The ground contacts' [[bond]] blocks (the markers that reach the guessed ground)."""
    h = sign * x[:, :, axis]  # [F, P] height along up, NaN where missing
    ground = _ground(x, axis, sign)
    # within reach above or below (False where missing: NaN compares False); a marker far
    # below the ground (a dip, a swapped label) does not touch it
    reach = contact_reach(x)
    near = np.abs(h - ground) < reach
    share = near.sum(axis=0) / np.maximum(mask.sum(axis=0), 1)
    touching = [i for i in range(len(names)) if share[i] >= CONTACT_SHARE]
    if not touching:
        notes.append(f"contacts: none (no marker within {reach * 100:.3g} cm of the ground)")
        return []
    d = x.shape[2]
    normal = [0.0] * d
    normal[axis] = sign
    # the belt: the contact markers' median velocity along the ground while on it
    vel = (x[1:] - x[:-1]) / dt  # [F-1, P, D]
    on = near[1:] & near[:-1]
    tangential = [vel[on[:, i], i] for i in touching]
    tangential = np.concatenate(tangential) if tangential else np.zeros((0, d))
    body = nanmean(vel, axis=1)  # [F-1, D] the markers' mean velocity
    with_body = [body[on[:, i]] for i in touching]
    with_body = np.concatenate(with_body) if with_body else np.zeros((0, d))
    belt = None
    if len(tangential):
        med = np.median(tangential, axis=0)
        med[axis] = 0.0
        along = np.median(with_body, axis=0)
        along[axis] = 0.0
        # a belt carries the feet, not the body: a body sliding with its feet rides none;
        # and at one velocity: a low point swinging through (a pendulum's) rides none
        spread = np.subtract(*np.percentile(tangential, [75, 25], axis=0))
        spread[axis] = 0.0
        if (
            np.linalg.norm(med) > BELT_SPEED
            and np.linalg.norm(med - along) > BELT_SPEED
            and np.linalg.norm(spread) <= BELT_SPREAD * np.linalg.norm(med)
        ):
            belt = med
    n = len(touching)
    k = total * G / (n * PENETRATION)
    c = 0.1 * 2 * math.sqrt(k * total / n)
    height = sign * ground  # the plane's offset along the normal is the ground along up
    contact = bonds.contact.KIND.name
    notes.append(
        f"contacts: {n} marker(s) within {reach * 100:.3g} cm of the ground "
        f"(at {ground:.4g} m along up) in at least {100 * CONTACT_SHARE:g} % of the frames"
        + (f"; a treadmill belt at {vector(belt)} m/s" if belt is not None else "")
    )
    out = []
    for i in touching:
        block = [
            "",
            f"# {names[i]} on the ground: within {reach * 100:.3g} cm of it in "
            f"{100 * share[i]:.3g} % of the frames",
            "[[bond]]",
            f"kind = {quoted(contact)}",
            'type = "ground"',
            f"particles = [{quoted(names[i])}]",
            f"normal = {vector(normal)}  # up, as guessed (or --up)",
            f"height = {searched(height, height - HEIGHT_RANGE, height + HEIGHT_RANGE)}  # m: the "
            f"5th percentile of the lowest foot of each frame, +-{HEIGHT_RANGE * 100:g} cm",
            f"stiffness = {searched(k, k / 100, k * 100)}  # N/m: the weight {total:.4g} kg x g "
            f"over {n} contacts at {PENETRATION * 1000:g} mm; bounds x/100 .. x100",
            f"damping = {searched(c, c / 100, c * 100)}  # N s/m: 10 % of critical for "
            f"{total / n:.4g} kg; bounds x/100 .. x100",
            f"friction = {searched(*FRICTION)}  # Coulomb coefficient: a common guess",
        ]
        if belt is not None:
            block.append(
                f"surface_velocity = {vector(belt)}  # m/s: the contact markers' median velocity "
                "along the ground while on it (a treadmill belt)"
            )
        out.append("\n".join(block))
    return out
