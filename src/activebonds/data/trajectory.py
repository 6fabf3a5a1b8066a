"""The :class:`Trajectory`: marker positions over time, in metres, with a mask of missing samples.

A trajectory is immutable: its arrays are read-only copies, and every operation
(:meth:`~Trajectory.select`, :meth:`~Trajectory.window`, :meth:`~Trajectory.resample`)
returns a new one.  Missing samples (occlusions, blank fields) are NaN in ``positions`` and
``False`` in ``mask``; nothing in this module ever fills a gap.
"""

from __future__ import annotations

import dataclasses
import math
import operator
from dataclasses import dataclass, field

import numpy as np

from activebonds.errors import InputError


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Marker trajectories sampled at a constant rate.

    Attributes:
        positions: float64 array [frames, markers, D] in metres, NaN where missing.
        mask: bool array [frames, markers], True where the marker was seen.
        markers: marker names (unique, non-empty, no surrounding spaces or control chars).
        rate: sample rate in Hz (finite, > 0); the time step is always ``1 / rate``.
        start_time: time of the first frame in seconds.
        source_units: length unit used in the file the data came from ("mm", "cm", "m").
        source: path of that file, or None for data built in memory.
    """

    positions: np.ndarray
    mask: np.ndarray
    markers: tuple[str, ...]
    rate: float
    start_time: float = 0.0
    source_units: str = "m"
    source: str | None = field(default=None)

    def __post_init__(self) -> None:
        src = self.source or "trajectory"
        try:
            positions = np.array(self.positions, dtype=np.float64)
            mask = np.array(self.mask)
        except (TypeError, ValueError) as exc:
            raise InputError(src, f"positions and mask must be numeric arrays ({exc})") from None
        if mask.dtype != np.bool_:
            raise InputError(src, f"mask must be a boolean array, got dtype {mask.dtype}")
        if positions.ndim != 3 or min(positions.shape) < 1:
            raise InputError(
                src,
                f"positions must have shape [frames, markers, D] with all sizes >= 1, "
                f"got {positions.shape}",
            )
        if mask.shape != positions.shape[:2]:
            raise InputError(
                src, f"mask shape {mask.shape} does not match positions {positions.shape[:2]}"
            )
        markers = tuple(self.markers)
        if len(markers) != positions.shape[1]:
            raise InputError(
                src, f"{len(markers)} marker names for {positions.shape[1]} markers in positions"
            )
        check_marker_names(src, markers)
        try:
            rate = float(self.rate)
            start = float(self.start_time)
        except (TypeError, ValueError):
            raise InputError(src, "rate and start_time must be numbers") from None
        if not math.isfinite(rate) or rate <= 0:
            raise InputError(src, f"sample rate must be a positive finite number, got {rate!r}")
        if not math.isfinite(start):
            raise InputError(src, f"start_time must be finite, got {start!r}")
        finite = np.isfinite(positions)
        if not np.all(finite[mask]):
            raise InputError(src, "positions must be finite wherever the mask is True")
        if np.any(finite[~mask]):
            raise InputError(src, "positions must be NaN wherever the mask is False")
        positions.setflags(write=False)
        mask.setflags(write=False)
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "markers", markers)
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "start_time", start)
        object.__setattr__(self, "source_units", str(self.source_units))
        object.__setattr__(self, "source", None if self.source is None else str(self.source))

    def __repr__(self) -> str:
        """One line for notebooks: sizes, rate and gaps, never the arrays."""
        names = ", ".join(self.markers[:6]) + (", ..." if self.n_markers > 6 else "")
        source = f", source={self.source!r}" if self.source else ""
        return (
            f"Trajectory({self.n_frames} frames x {self.n_markers} markers [{names}], "
            f"{self.dimension}D, {self.rate:g} Hz, {self.duration:.4g} s, "
            f"{self.n_gaps} missing marker-frames{source})"
        )

    def _repr_html_(self) -> str:
        """A small table for notebooks: shape, markers, rate, gaps, source."""
        from activebonds.notebook import html_table, names, number

        share = 100.0 * self.n_gaps / max(self.mask.size, 1)
        rows = [
            ("shape", f"{self.n_frames} frames × {self.n_markers} markers × {self.dimension}D"),
            ("markers", names(self.markers)),
            ("rate", f"{self.rate:g} Hz (dt {number(self.dt, 's')})"),
            ("duration", number(self.duration, "s")),
            ("missing", f"{self.n_gaps} marker-frames ({share:.3g} %)"),
            ("units in the file", self.source_units),
        ]
        if self.source:
            rows.append(("source", self.source))
        return html_table("Trajectory", rows)

    # ------------------------------------------------------------------ properties
    @property
    def dt(self) -> float:
        """Time step in seconds, always ``1 / rate``."""
        return 1.0 / self.rate

    @property
    def times(self) -> np.ndarray:
        """Sample times ``start_time + arange(n_frames) / rate`` (never a rounded file column)."""
        return self.start_time + np.arange(self.n_frames) / self.rate

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_markers(self) -> int:
        return int(self.positions.shape[1])

    @property
    def dimension(self) -> int:
        return int(self.positions.shape[2])

    @property
    def n_gaps(self) -> int:
        """Number of missing (masked) marker-frames."""
        return int(np.count_nonzero(~self.mask))

    @property
    def duration(self) -> float:
        """Time from the first to the last frame, ``(n_frames - 1) / rate``."""
        return (self.n_frames - 1) / self.rate

    # ------------------------------------------------------------------ operations
    def with_positions(
        self, positions: np.ndarray, mask: np.ndarray | None = None, **changes: object
    ) -> Trajectory:
        """A copy with new positions (and mask, default: finite samples); other fields kept.

        ``changes`` may override ``markers``, ``rate``, ``start_time``, ``source_units``,
        ``source``.
        """
        positions = np.asarray(positions, dtype=np.float64)
        if mask is None:
            mask = np.all(np.isfinite(positions), axis=-1) if positions.ndim == 3 else None
        return dataclasses.replace(self, positions=positions, mask=mask, **changes)

    def check_markers(self, markers, unnamed: str = "the recording") -> None:
        """Refuse (an :class:`InputError` of ``--markers``) the first of ``markers`` that is
        not one of this trajectory's, naming its file (or ``unnamed``: read from none)."""
        unknown = [m for m in markers if m not in self.markers]
        if unknown:
            raise InputError(
                "--markers",
                f"marker {unknown[0]!r} not found in {self.source or unnamed}; "
                f"available: {', '.join(self.markers)}",
            )

    def select(self, markers: list[str] | tuple[str, ...]) -> Trajectory:
        """Keep only the named markers, in the order given."""
        src = self.source or "trajectory"
        names = [markers] if isinstance(markers, str) else list(markers)
        if not names:
            raise InputError(src, "no markers selected")
        index = {name: i for i, name in enumerate(self.markers)}
        for name in names:
            if name not in index:
                raise InputError(
                    src, f"marker {name!r} not found; available: {', '.join(self.markers)}"
                )
        if len(set(names)) != len(names):
            raise InputError(src, f"marker selected twice in {names}")
        cols = [index[name] for name in names]
        return dataclasses.replace(
            self, positions=self.positions[:, cols], mask=self.mask[:, cols], markers=tuple(names)
        )

    def window(self, start: int | None = None, stop: int | None = None) -> Trajectory:
        """Frames ``start:stop`` (Python slice semantics, negative indices allowed).

        Indices beyond the trajectory (|index| > n_frames) and empty windows are InputError.
        ``start_time`` moves to the first kept frame.
        """
        frames = frame_window(self.n_frames, start, stop, self.source or "trajectory")
        sl = slice(frames.start, frames.stop)
        return dataclasses.replace(
            self,
            positions=self.positions[sl],
            mask=self.mask[sl],
            start_time=self.start_time + frames.start / self.rate,
        )

    def resample(self, rate: float) -> Trajectory:
        """Linear interpolation in time onto ``rate`` Hz, from start_time to the last frame.

        A new sample is missing if either of the two original samples around it is missing
        (a sample that coincides with an original frame depends on that frame only), so gaps
        are never filled.
        """
        src = self.source or "trajectory"
        try:
            new_rate = float(rate)
        except (TypeError, ValueError):
            raise InputError(src, f"resample rate {rate!r} is not a number") from None
        if not math.isfinite(new_rate) or new_rate <= 0:
            raise InputError(src, f"resample rate must be a positive finite number, got {rate!r}")
        n_old = self.n_frames
        n_new = int(math.floor(self.duration * new_rate + 1e-9)) + 1
        u = np.arange(n_new) * (self.rate / new_rate)  # position in units of old frames
        nearest = np.rint(u)
        u = np.where(np.abs(u - nearest) < 1e-9, nearest, u)
        i0 = np.clip(np.floor(u).astype(np.int64), 0, n_old - 1)
        w = np.clip(u - i0, 0.0, 1.0)
        i1 = np.minimum(i0 + 1, n_old - 1)
        mask = self.mask[i0] & ((w == 0.0)[:, None] | self.mask[i1])
        filled = np.nan_to_num(self.positions, nan=0.0)
        wc = w[:, None, None]
        positions = (1.0 - wc) * filled[i0] + wc * filled[i1]
        positions[~mask] = np.nan
        return dataclasses.replace(self, positions=positions, mask=mask, rate=new_rate)


def check_marker_names(src: str, markers, where: str | None = None) -> None:
    """Marker names must be unique, non-empty, unpadded strings without control characters."""
    seen: set[str] = set()
    for name in markers:
        if not isinstance(name, str) or not name or name != name.strip():
            raise InputError(
                src,
                f"marker name {name!r} must be a non-empty string without surrounding spaces",
                where,
            )
        if any(ord(c) < 32 or ord(c) == 127 for c in name):
            raise InputError(src, f"marker name {name!r} contains control characters", where)
        if name in seen:
            raise InputError(
                src, f"marker name {name!r} appears twice; names must be unique", where
            )
        seen.add(name)


def frame_window(n: int, start: int | None, stop: int | None, source: str) -> range:
    """The frames ``start:stop`` of ``n`` (Python slice semantics, negative indices allowed):
    the one rule of every command's ``--frames``. An index beyond the frames (|index| > n)
    or an empty window is an InputError naming ``source``."""
    bounds = []
    for label, value in (("start", start), ("stop", stop)):
        if value is None:
            bounds.append(None)
            continue
        try:
            value = operator.index(value)
        except TypeError:
            raise InputError(source, f"window {label} {value!r} must be an integer frame") from None
        if not -n <= value <= n:
            raise InputError(
                source, f"window {label} {value} is out of range for {n} frames (0..{n})"
            )
        bounds.append(value)
    frames = range(n)[slice(*bounds)]
    if len(frames) == 0:
        raise InputError(source, f"window [{start}:{stop}] is empty for {n} frames")
    return frames
