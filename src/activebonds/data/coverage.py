"""Where the data is: which markers are present in which frames, and the gap-free windows.

A window is ``(start, stop)``, frames ``start`` to ``stop - 1`` (Python slice semantics, as
``fit --frames START:STOP`` reads it). :func:`present_windows` finds the maximal runs of
frames where a marker (or every one of a set) is present; :func:`coverage` summarises a
trajectory for ``activebonds info``: per marker the share of frames present, the missing
frames, the gaps (runs of missing frames) and the longest gap-free window; the longest windows
where every marker is present; and, for a chosen set of markers, the windows where all of them
are. NumPy only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

TOP = 5  # windows listed per set of markers


def present_windows(mask: np.ndarray, min_len: int = 1) -> list[tuple[int, int]]:
    """The maximal runs of present frames, as (start, stop) in order of start.

    ``mask`` is [F] (True where present) or [F, P] (a frame counts when all P are present);
    runs shorter than ``min_len`` frames are left out."""
    mask = np.asarray(mask, bool)
    if mask.ndim == 2:
        mask = mask.all(axis=1)
    if mask.ndim != 1:
        raise ValueError(f"mask must be [frames] or [frames, markers], got shape {mask.shape}")
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= min_len]


def longest(windows: Sequence[tuple[int, int]], n: int = TOP) -> list[tuple[int, int]]:
    """The ``n`` longest windows, longest first (the earlier one first among equals)."""
    return sorted(windows, key=lambda w: (-(w[1] - w[0]), w[0]))[:n]


def count_gaps(mask: np.ndarray) -> int:
    """The number of gaps (maximal runs of missing frames) in a [F] mask."""
    return len(present_windows(~np.asarray(mask, bool)))


def window_record(window: tuple[int, int]) -> dict:
    """A window as JSON: ``frames`` (START:STOP, for ``fit --frames``), start, stop, length."""
    start, stop = window
    return {"frames": f"{start}:{stop}", "start": start, "stop": stop, "length": stop - start}


def window_text(window: tuple[int, int]) -> str:
    """'120:480 (360 frames)'."""
    start, stop = window
    return f"{start}:{stop} ({stop - start} frames)"


def marker_coverage(mask: np.ndarray) -> dict:
    """Coverage of one marker's [F] mask: the share of frames present, the missing frames, the
    gaps, and the longest gap-free window (None if the marker is never present)."""
    mask = np.asarray(mask, bool)
    windows = longest(present_windows(mask), 1)
    return {
        "present": float(mask.mean()) if mask.size else 0.0,
        "missing_frames": int(np.count_nonzero(~mask)),
        "gaps": count_gaps(mask),
        "longest": window_record(windows[0]) if windows else None,
    }


def set_coverage(mask: np.ndarray, top: int = TOP) -> dict:
    """Where all markers of a [F, P] mask are present: the share of frames, and the ``top``
    longest windows (longest first)."""
    every = np.asarray(mask, bool).all(axis=1)
    return {
        "present": float(every.mean()) if every.size else 0.0,
        "windows": [window_record(w) for w in longest(present_windows(every), top)],
    }


def coverage(traj, markers: Sequence[str] | None = None, top: int = TOP) -> dict:
    """JSON-ready coverage of a trajectory (anything with ``mask`` [F, P] and ``markers``).

    ``markers``: per marker (in the trajectory's order) :func:`marker_coverage`; ``all``:
    :func:`set_coverage` of every marker; ``chosen`` (only if ``markers`` is given, a list of
    the trajectory's marker names, else None): the same for that set, with its names."""
    mask = np.asarray(traj.mask, bool)
    names = list(traj.markers)
    chosen = None
    if markers is not None:
        unknown = [m for m in markers if m not in names]
        if unknown:
            raise KeyError(unknown[0])
        cols = [names.index(m) for m in markers]
        chosen = {"markers": list(markers), **set_coverage(mask[:, cols], top)}
    return {
        "markers": {name: marker_coverage(mask[:, i]) for i, name in enumerate(names)},
        "all": set_coverage(mask, top),
        "chosen": chosen,
    }
