"""Gap filling: which gaps a fill may touch, the fills labs use today, and the record of a fill.

A gap is a run of missing frames of one marker (:func:`activebonds.data.coverage.present_windows`
of the marker's missing frames). :func:`plan_fill` decides, for the chosen markers and frame
window, which gaps are filled and which are left, and why:

* a gap touching the first or the last frame of the window is left ("at the start", "at the
  end"): filling it is extrapolation, which none of these fills does honestly;
* a gap longer than ``max_gap`` frames is left ("longer than --max-gap N");
* a gap not inside the window is left ("outside --frames");
* a chosen marker never present in the window is refused (:class:`InputError`, naming it).

The baselines (the fills of Vicon Nexus, Qualisys, and of the literature), on positions [F, M, D]
of the window, filling only the samples of the planned gaps:

* ``linear``: straight lines between the samples around the gap;
* ``spline``: a cubic spline (SciPy's ``CubicSpline``, not-a-knot) through every present
  sample of the marker in the window;
* ``pca``: the principal-component fill of Gløersen & Federolf (2016, PLoS ONE 11(3):
  e0152616): principal components of the frames where every chosen marker is present, and
  the missing markers of a frame reconstructed from the coordinates of those present, by least
  squares on the components (as many as explain 99 % of the variance, at most the number of
  present coordinates). Each frame is taken relative to the centroid of its present markers
  (the same markers in the complete frames), so that the components describe the shape, not
  where the body is in the room.

Their uncertainty (:func:`self_test`) is measured, not assumed: the same fill of artificial
gaps of the same length placed where the marker is present, the RMS error (3-D distance) at
each position in the gap over up to ``TRIALS`` placements.

:func:`apply_fill` writes filled values into the recording and lists every sample of every gap
of the chosen markers, filled or left (:func:`record_csv`: the sidecar CSV).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

import numpy as np

from activebonds.data.coverage import present_windows
from activebonds.data.trajectory import Trajectory
from activebonds.errors import InputError

BASELINES = ("linear", "spline", "pca")
TRIALS = 10  # artificial gaps per (marker, length) of the self-test
PCA_VARIANCE = 0.99  # share of the variance the principal components keep
PCA_MIN_FRAMES = 3  # complete frames the PCA fill needs at least


@dataclass(frozen=True)
class Gap:
    """Frames ``start:stop`` (in the recording) missing for one chosen marker."""

    column: int  # of the marker among the chosen markers
    marker: str
    start: int
    stop: int
    reason: str | None = None  # why it is left; None: it is filled

    @property
    def length(self) -> int:
        return self.stop - self.start

    @property
    def frames(self) -> str:
        return f"{self.start}:{self.stop}"


@dataclass(frozen=True, eq=False)
class FillPlan:
    """The chosen markers of a recording in a frame window, and their gaps."""

    traj: Trajectory  # the whole recording, every marker
    columns: tuple[int, ...]  # of the chosen markers in ``traj``
    window: tuple[int, int]  # frames start, stop of the recording used
    gaps: tuple[Gap, ...]

    @property
    def markers(self) -> tuple[str, ...]:
        return tuple(self.traj.markers[c] for c in self.columns)

    @property
    def positions(self) -> np.ndarray:
        """[F, M, D] of the chosen markers in the window (NaN where missing)."""
        a, b = self.window
        return np.array(self.traj.positions[a:b][:, list(self.columns)])

    @property
    def mask(self) -> np.ndarray:
        a, b = self.window
        return np.array(self.traj.mask[a:b][:, list(self.columns)])

    @property
    def to_fill(self) -> tuple[Gap, ...]:
        return tuple(g for g in self.gaps if g.reason is None)

    @property
    def left(self) -> tuple[Gap, ...]:
        return tuple(g for g in self.gaps if g.reason is not None)

    def local(self, gaps=None) -> list[Gap]:
        """The gaps to fill (or ``gaps``) with frames counted from the window's start."""
        a = self.window[0]
        return [
            Gap(g.column, g.marker, g.start - a, g.stop - a, g.reason)
            for g in (self.to_fill if gaps is None else gaps)
        ]


def plan_fill(
    traj: Trajectory,
    markers: tuple[str, ...] | list[str],
    frames: tuple[int, int | None] = (0, None),
    max_gap: int | None = None,
) -> FillPlan:
    """The gaps of ``markers`` in ``traj`` and which of them a fill of the window may touch.

    Raises:
        InputError: a marker not in the recording (naming every one missing), a window out of
            range, a marker never present in the window.
    """
    src = traj.source or "trajectory"
    absent = [m for m in markers if m not in traj.markers]
    if absent:
        raise InputError(
            src,
            f"the model's marker(s) {', '.join(absent)} are not in the recording "
            f"(it has {', '.join(traj.markers)}); give --markers A,B,C, one per particle",
        )
    if len(set(markers)) != len(markers):
        raise InputError("--markers", f"a marker is named twice in {', '.join(markers)}")
    n = traj.n_frames
    start, stop = frames
    stop = n if stop is None else stop
    start, stop = (start + n if start < 0 else start), (stop + n if stop < 0 else stop)
    if not 0 <= start < stop <= n:
        raise InputError("--frames", f"{frames[0]}:{frames[1] or ''} is not a window of {n} frames")
    if stop - start < 3:
        raise InputError("--frames", f"the window holds {stop - start} frames; at least 3 needed")
    columns = tuple(traj.markers.index(m) for m in markers)
    never = [m for m, c in zip(markers, columns, strict=True) if not traj.mask[start:stop, c].any()]
    if never:
        raise InputError(
            src,
            f"marker(s) {', '.join(never)} never present in frames {start}:{stop}: "
            "nothing to fill from",
        )
    if max_gap is not None and max_gap < 1:
        raise InputError("--max-gap", f"expected a positive number of frames, got {max_gap}")
    gaps = []
    for j, c in enumerate(columns):
        for a, b in present_windows(~traj.mask[:, c]):
            if b <= start or a >= stop or a < start or b > stop:
                reason = "outside --frames"
            elif a == start:
                reason = "at the start (filling it would be extrapolation)"
            elif b == stop:
                reason = "at the end (filling it would be extrapolation)"
            elif max_gap is not None and b - a > max_gap:
                reason = f"longer than --max-gap {max_gap}"
            else:
                reason = None
            gaps.append(Gap(j, markers[j], a, b, reason))
    gaps.sort(key=lambda g: (g.start, g.column))
    return FillPlan(traj, columns, (start, stop), tuple(gaps))


# ----------------------------------------------------------------------------- baselines


def fill_linear(positions: np.ndarray, mask: np.ndarray, gaps) -> np.ndarray:
    """Straight lines from the sample before each gap to the sample after it."""
    out = np.array(positions, dtype=np.float64)
    for g in gaps:
        before, after = positions[g.start - 1, g.column], positions[g.stop, g.column]
        w = (np.arange(g.start, g.stop) - (g.start - 1)) / (g.length + 1)
        out[g.start : g.stop, g.column] = before + w[:, None] * (after - before)
    return out


def fill_spline(positions: np.ndarray, mask: np.ndarray, gaps) -> np.ndarray:
    """A cubic spline through every present sample of the marker, at the gap's frames."""
    from scipy.interpolate import CubicSpline

    out = np.array(positions, dtype=np.float64)
    frames = np.arange(positions.shape[0])
    splines: dict[int, CubicSpline] = {}
    for g in gaps:
        if g.column not in splines:
            ok = mask[:, g.column]
            if ok.sum() < 4:  # a cubic needs four samples; a line between two
                out[g.start : g.stop, g.column] = fill_linear(positions, mask, [g])[
                    g.start : g.stop, g.column
                ]
                continue
            splines[g.column] = CubicSpline(frames[ok], positions[ok, g.column], axis=0)
        out[g.start : g.stop, g.column] = splines[g.column](frames[g.start : g.stop])
    return out


def fill_pca(positions: np.ndarray, mask: np.ndarray, gaps) -> np.ndarray:
    """Gløersen & Federolf's principal-component fill (see the module docstring)."""
    out = np.array(positions, dtype=np.float64)
    n_frames, n_markers, dim = positions.shape
    complete = mask.all(axis=1)
    if complete.sum() < PCA_MIN_FRAMES:
        raise InputError(
            "--method pca",
            f"needs frames where every chosen marker is present; the window has "
            f"{int(complete.sum())} (at least {PCA_MIN_FRAMES})",
        )
    wanted = np.zeros(mask.shape, bool)
    for g in gaps:
        wanted[g.start : g.stop, g.column] = True
    train = positions[complete]  # [N, M, D]
    frames = np.flatnonzero(wanted.any(axis=1))
    patterns: dict[bytes, list[int]] = {}
    for f in frames:
        patterns.setdefault(mask[f].tobytes(), []).append(int(f))
    for key, rows in patterns.items():
        present = np.frombuffer(key, dtype=bool)
        if not present.any():
            continue  # nothing to reconstruct from
        x = train - train[:, present].mean(axis=1, keepdims=True)
        x = x.reshape(len(x), -1)
        mean = x.mean(axis=0)
        _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
        share = np.cumsum(s**2) / max(float(np.sum(s**2)), 1e-300)
        coords = np.repeat(present, dim)
        k = int(np.searchsorted(share, PCA_VARIANCE) + 1)
        k = max(1, min(k, int(coords.sum()), len(s)))
        basis = vt[:k].T  # [M D, k]
        target = positions[rows]  # [R, M, D]
        centre = target[:, present].mean(axis=1, keepdims=True)
        y = (target - centre).reshape(len(rows), -1)
        coef, *_ = np.linalg.lstsq(basis[coords], (y[:, coords] - mean[coords]).T, rcond=None)
        recon = (mean[:, None] + basis @ coef).T.reshape(len(rows), n_markers, dim) + centre
        for i, f in enumerate(rows):
            cols = wanted[f]
            out[f, cols] = recon[i, cols]
    return out


FILLS = {"linear": fill_linear, "spline": fill_spline, "pca": fill_pca}


def fill_baseline(method: str, positions: np.ndarray, mask: np.ndarray, gaps) -> np.ndarray:
    """Positions [F, M, D] with the samples of ``gaps`` (window frames) filled by ``method``."""
    if method not in FILLS:
        raise InputError("--method", f"expected model or {', '.join(BASELINES)}, got '{method}'")
    return FILLS[method](positions, mask, list(gaps))


def self_test_errors(
    fill, positions: np.ndarray, mask: np.ndarray, column: int, length: int, others: bool = False
) -> np.ndarray:
    """The errors [trials, length, D] (filled less recorded, metres) of ``fill(positions,
    mask, gaps)`` on up to ``TRIALS`` artificial gaps of ``length`` frames placed evenly where
    the marker is present with a present frame on each side (``others``: where every marker
    is, as the PCA fill needs them); no trial where there is no room for one."""
    complete = mask.all(axis=1) if others else mask[:, column]
    room = [
        (a + 1, b - 1)
        for a, b in present_windows(complete)
        if b - a >= length + 2  # a present frame on each side
    ]
    starts = [s for a, b in room for s in range(a, b - length + 1)]
    if not starts:
        return np.zeros((0, length, positions.shape[-1]))
    pick = np.unique(np.linspace(0, len(starts) - 1, min(TRIALS, len(starts))).round().astype(int))
    errors = []
    for i in pick:
        s = starts[i]
        m = mask.copy()
        m[s : s + length, column] = False
        p = np.where(m[..., None], positions, np.nan)
        gap = Gap(column, "", s, s + length)
        got = fill(p, m, [gap])[s : s + length, column]
        errors.append(got - positions[s : s + length, column])
    return np.asarray(errors)


def self_test(
    fill, positions: np.ndarray, mask: np.ndarray, column: int, length: int, others: bool = False
):
    """The RMS error (3-D distance, metres) of ``fill`` at each of the ``length`` positions of
    a gap over the artificial gaps of :func:`self_test_errors`; NaN where there is no room for
    one."""
    errors = self_test_errors(fill, positions, mask, column, length, others)
    if not len(errors):
        return np.full(length, np.nan)
    return np.sqrt(np.mean(np.sum(np.square(errors), axis=-1), axis=0))


def baseline_uncertainty(method: str, positions: np.ndarray, mask: np.ndarray, gaps):
    """Per gap (window frames), the self-test's error at each of its samples (metres)."""
    cache: dict[tuple[int, int], np.ndarray] = {}
    out = []
    for g in gaps:
        key = (g.column, g.length)
        if key not in cache:
            cache[key] = self_test(
                FILLS[method], positions, mask, g.column, g.length, others=method == "pca"
            )
        out.append(cache[key])
    return out


# ----------------------------------------------------------------------------- the result


@dataclass(frozen=True)
class FilledSample:
    """One sample of a gap, as the sidecar CSV lists it."""

    frame: int  # in the recording, from 0
    time: float
    marker: str
    status: str  # "filled" or "left"
    method: str  # the fill's method, "" when left
    gap: str  # the gap's frames START:STOP
    uncertainty_mm: float  # NaN when left or unknown
    reason: str = ""


def apply_fill(
    plan: FillPlan,
    values: np.ndarray,
    uncertainty: list[np.ndarray],
    method: str,
    denoised: bool = False,
) -> tuple[Trajectory, list[FilledSample]]:
    """The recording with the planned gaps filled from ``values`` [F, M, D] (window frames,
    chosen markers) and every sample of every gap listed; ``uncertainty``: per gap to fill,
    metres per sample. ``denoised``: ``values`` replace every present sample of the chosen
    markers in the window too."""
    traj = plan.traj
    positions = np.array(traj.positions)
    mask = np.array(traj.mask)
    a, b = plan.window
    if denoised:
        cols = list(plan.columns)
        seen = mask[a:b][:, cols]
        block = positions[a:b][:, cols]
        block[seen] = values[seen]
        positions[a:b, cols] = block
    times = traj.times
    records = []
    fill_index = 0
    for g in plan.gaps:
        c = plan.columns[g.column]
        if g.reason is None:
            sigma = uncertainty[fill_index]
            fill_index += 1
            positions[g.start : g.stop, c] = values[g.start - a : g.stop - a, g.column]
            mask[g.start : g.stop, c] = True
        for i, f in enumerate(range(g.start, g.stop)):
            filled = g.reason is None
            records.append(
                FilledSample(
                    f,
                    float(times[f]),
                    g.marker,
                    "filled" if filled else "left",
                    method if filled else "",
                    g.frames,
                    float(sigma[i]) * 1000.0 if filled else float("nan"),
                    g.reason or "",
                )
            )
    if not np.all(np.isfinite(positions[mask])):
        raise InputError("--method", f"the {method} fill gave non-finite positions")
    return traj.with_positions(positions, mask), records


RECORD_COLUMNS = ("frame", "time", "marker", "status", "method", "gap", "uncertainty_mm", "reason")


def record_csv(records: list[FilledSample]) -> bytes:
    """The sidecar CSV: one row per sample of a gap (frames from 0, as ``--frames`` counts)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(RECORD_COLUMNS)
    for r in records:
        unc = "" if not np.isfinite(r.uncertainty_mm) else f"{r.uncertainty_mm:.6g}"
        w.writerow([r.frame, repr(r.time), r.marker, r.status, r.method, r.gap, unc, r.reason])
    return out.getvalue().encode("utf-8")
