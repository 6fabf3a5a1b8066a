"""Trajectory layer: marker positions over time, read from and written to files.

``read_trajectory`` and ``write_trajectory`` dispatch on the file extension
(.csv, .trc, .c3d, .npz, .mat); :func:`describe` summarises a trajectory for the ``info``
command.
"""

from __future__ import annotations

import numpy as np

from activebonds.data.coverage import coverage
from activebonds.data.orientation import (
    AXES,
    agree,
    confident,
    guess_gravity,
    guess_ground,
    vertical_doubts,
)
from activebonds.data.readers import read_trajectory
from activebonds.data.trajectory import Trajectory
from activebonds.data.writers import write_trajectory

__all__ = ["Trajectory", "describe", "read_trajectory", "write_trajectory"]


def describe(traj: Trajectory, markers: list[str] | None = None) -> dict:
    """JSON-ready summary: markers, frames, rate, dt, duration, units, dimension, gaps.

    ``duration`` is the time from the first to the last frame, ``(frames - 1) / rate``;
    ``units`` the length unit of the source file (positions are always in metres);
    ``gaps`` maps each marker to its number of missing frames; ``ground`` the vertical axis
    and ground level guessed from the markers (:mod:`activebonds.data.orientation`), or None;
    ``gravity`` the vertical guessed from the markers' acceleration in flight (``up`` None and
    ``text`` saying why when there is no flight phase), ``vertical_agree`` whether the two
    guesses name the same up (None unless both found one), ``vertical_confident`` whether
    neither has a doubt (the ground's ``doubts`` say why); ``coverage`` where the data is
    (:func:`activebonds.data.coverage.coverage`; ``chosen`` for the names in ``markers``).
    """
    if markers is not None:
        traj.check_markers(markers, "the trajectory")
    missing = np.count_nonzero(~traj.mask, axis=0)
    ground = guess_ground(traj)
    gravity = guess_gravity(traj)
    return {
        "source": traj.source,
        "markers": list(traj.markers),
        "frames": traj.n_frames,
        "rate": traj.rate,
        "dt": traj.dt,
        "start_time": traj.start_time,
        "duration": traj.duration,
        "units": traj.source_units,
        "dimension": traj.dimension,
        "gaps": {name: int(n) for name, n in zip(traj.markers, missing, strict=True)},
        "total_gaps": traj.n_gaps,
        "ground": None
        if ground is None
        else {
            "up": ("+" if ground.up > 0 else "-") + AXES[ground.axis],
            "normal": ground.normal,
            "height": ground.height,
            "clear": ground.clear,
            "lowest_marker": ground.lowest,
            "feet": list(ground.feet),
            "text": ground.describe(gravity),
            "doubts": vertical_doubts(ground, gravity),
        },
        "gravity": {
            "up": None
            if not gravity.found
            else ("+" if gravity.up > 0 else "-") + AXES[gravity.axis],
            "normal": gravity.normal,
            "acceleration": None if not gravity.found else list(gravity.acceleration),
            "along_up": gravity.along_up,
            "flight_frames": gravity.flight_frames,
            "phases": gravity.phases,
            "text": gravity.describe(),
        },
        "vertical_agree": agree(ground, gravity),
        "vertical_confident": confident(ground, gravity),
        "coverage": coverage(traj, markers),
    }
