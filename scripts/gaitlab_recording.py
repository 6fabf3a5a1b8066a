"""A gait-lab-like recording made from the bundled human walk (OpenSim subject01_walk1.trc,
41 markers at 60 Hz): resampled to a camera rate, with measurement noise and the gaps a lab's
cameras leave, written as C3D and TRC.

    python scripts/gaitlab_recording.py --out /tmp/gaitlab            # /tmp/gaitlab.c3d + .trc
    python scripts/gaitlab_recording.py --rate 200 --markers 20 --seed 3 --out walk.c3d

How the recording is made, in this order (every random draw from one generator seeded by
``--seed``, default 1):

1. **Markers.** ``--markers N`` keeps N of the recording's markers, evenly spaced in file
   order (indices ``round(linspace(0, P - 1, N))``): a rule on positions in the file, never
   on names. Without it, all of them.
2. **Resampling.** The new frames are at ``t0 + k / rate`` (``--rate``, Hz, default 250) for
   every k with that time within the recorded span. Each marker's coordinates there are a
   cubic spline (:class:`scipy.interpolate.CubicSpline`, not-a-knot ends) through that
   marker's recorded samples (all 151 frames of the bundled walk; a marker's own missing
   samples are skipped, and new frames outside its recorded span are left missing).
3. **Noise.** Independent Gaussian noise of standard deviation ``--noise-mm`` (default 0.3)
   on every coordinate of every sample.
4. **Long occlusions.** A share ``--occluded`` (default 1/3) of the markers, drawn at
   random, are hidden together, as when a body part turns away from the cameras: one
   contiguous stretch of ``--occluded-span`` (default 0.3) of the trial's frames, its start
   uniform over the frames where it fits; each hidden marker's own stretch has its two edges
   moved independently by up to ``--jitter`` s (default 0.08, uniform).
5. **Dropouts.** Per marker, independently, short losses whose starts are a Poisson process
   of ``--dropout-rate`` per second (default 0.25; the number of starts is Poisson with mean
   rate x duration, their times uniform over the trial), and whose lengths are lognormal
   with median ``--dropout-median`` s (default 0.05) and log-sd 0.6, rounded to frames and
   clipped to [2 frames, 0.3 s]. Dropouts may overlap each other and the long occlusions.

With the defaults on the full 41-marker walk at 250 Hz (626 frames), every marker is present
together in 34 % of the frames (seeds 0-9: 27-44 %, mean 34 %; the figure is printed). The recording is written as ``PATH.c3d`` and
``PATH.trc`` (``--out PATH``, any suffix replaced) with the package's writers; the script
prints the frame count, the share of frames with every marker present, and each marker's
presence.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

MAX_DROPOUT_S = 0.3  # the longest short dropout
DROPOUT_LOG_SD = 0.6


def kept_markers(n_markers: int, keep: int | None) -> np.ndarray:
    """Indices of ``keep`` markers of ``n_markers``, evenly spaced in file order (all of them
    for None)."""
    if keep is None or keep >= n_markers:
        return np.arange(n_markers)
    if keep < 1:
        raise ValueError(f"--markers must be at least 1, not {keep}")
    return np.unique(np.round(np.linspace(0, n_markers - 1, keep)).astype(int))


def resample_spline(positions: np.ndarray, mask: np.ndarray, times: np.ndarray, new_times):
    """Positions [F', P, D] at ``new_times``: per marker a cubic spline through its recorded
    samples; NaN outside a marker's recorded span (or where it has fewer than 2 samples)."""
    from scipy.interpolate import CubicSpline

    out = np.full((len(new_times), positions.shape[1], positions.shape[2]), np.nan)
    for m in range(positions.shape[1]):
        seen = mask[:, m]
        if seen.sum() < 2:
            continue
        t = times[seen]
        spline = CubicSpline(t, positions[seen, m], axis=0)
        inside = (new_times >= t[0] - 1e-12) & (new_times <= t[-1] + 1e-12)
        out[inside, m] = spline(new_times[inside])
    return out


def gap_mask(
    n_frames: int,
    n_markers: int,
    rate: float,
    rng: np.random.Generator,
    occluded: float = 1 / 3,
    occluded_span: float = 0.3,
    jitter: float = 0.08,
    dropout_rate: float = 0.25,
    dropout_median: float = 0.05,
) -> np.ndarray:
    """[F, P] True where a marker is seen: the long occlusions and the dropouts of the module
    docstring (steps 4 and 5)."""
    seen = np.ones((n_frames, n_markers), bool)
    n_hidden = int(round(occluded * n_markers))
    span = int(round(occluded_span * n_frames))
    if n_hidden and span:
        hidden = rng.choice(n_markers, size=n_hidden, replace=False)
        start = int(rng.integers(0, n_frames - span + 1))
        shift = int(round(jitter * rate))
        for m in hidden:
            a = start + int(rng.integers(-shift, shift + 1))
            b = start + span + int(rng.integers(-shift, shift + 1))
            seen[max(a, 0) : max(b, 0), m] = False
    duration = n_frames / rate
    longest = max(2, int(round(MAX_DROPOUT_S * rate)))
    for m in range(n_markers):
        n = rng.poisson(dropout_rate * duration)
        starts = rng.uniform(0.0, duration, n)
        lengths = dropout_median * np.exp(DROPOUT_LOG_SD * rng.standard_normal(n))
        for t, length in zip(starts, lengths, strict=True):
            a = int(t * rate)
            k = int(np.clip(round(length * rate), 2, longest))
            seen[a : a + k, m] = False
    return seen


def gaitlab(
    traj,
    rate: float = 250.0,
    noise_mm: float = 0.3,
    seed: int = 1,
    markers: int | None = None,
    **gaps,
):
    """The gait-lab-like :class:`~activebonds.data.trajectory.Trajectory` of ``traj`` (see
    the module docstring); ``gaps``: :func:`gap_mask`'s keywords."""
    from activebonds.data.trajectory import Trajectory

    rng = np.random.default_rng(seed)
    keep = kept_markers(traj.n_markers, markers)
    times = traj.times
    n_new = int(np.floor((times[-1] - times[0]) * rate + 1e-9)) + 1
    new_times = times[0] + np.arange(n_new) / rate
    x = resample_spline(traj.positions[:, keep], traj.mask[:, keep], times, new_times)
    x = x + rng.normal(0.0, noise_mm / 1000.0, x.shape)
    seen = gap_mask(n_new, len(keep), rate, rng, **gaps) & np.all(np.isfinite(x), axis=-1)
    x = np.where(seen[..., None], x, np.nan)
    return Trajectory(
        positions=x,
        mask=seen,
        markers=tuple(traj.markers[i] for i in keep),
        rate=float(rate),
        start_time=float(times[0]),
    )


def main(argv=None) -> int:
    from activebonds.data.bundled import dataset
    from activebonds.data.readers import read_trajectory
    from activebonds.data.writers import write_trajectory

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rate", type=float, default=250.0, help="frame rate, Hz")
    p.add_argument("--noise-mm", type=float, default=0.3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--markers", type=int, default=None, help="keep N markers (file order)")
    p.add_argument("--occluded", type=float, default=1 / 3, help="share of markers hidden long")
    p.add_argument("--occluded-span", type=float, default=0.3, help="share of the trial")
    p.add_argument("--jitter", type=float, default=0.08, help="s, the hidden stretch's edges")
    p.add_argument("--dropout-rate", type=float, default=0.25, help="per marker per second")
    p.add_argument("--dropout-median", type=float, default=0.05, help="s")
    p.add_argument("--out", required=True, help="PATH: writes PATH.c3d and PATH.trc")
    a = p.parse_args(argv)
    walk = read_trajectory(dataset("human-walk").path)
    traj = gaitlab(
        walk,
        a.rate,
        a.noise_mm,
        a.seed,
        a.markers,
        occluded=a.occluded,
        occluded_span=a.occluded_span,
        jitter=a.jitter,
        dropout_rate=a.dropout_rate,
        dropout_median=a.dropout_median,
    )
    out = Path(a.out)
    for suffix in (".c3d", ".trc"):
        write_trajectory(traj, out.with_suffix(suffix))
    complete = traj.mask.all(axis=1).mean()
    print(
        f"{out.with_suffix('.c3d')}, {out.with_suffix('.trc')}: {traj.n_frames} frames at "
        f"{a.rate:g} Hz ({traj.duration:.3f} s), {traj.n_markers} markers, seed {a.seed}"
    )
    print(f"frames with every marker present: {complete:.1%}")
    print(f"samples present: {traj.mask.mean():.1%}; per marker:")
    for name, share in zip(traj.markers, traj.mask.mean(axis=0), strict=True):
        print(f"  {name:<16} {share:6.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
