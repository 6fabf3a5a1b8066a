"""A free run judged as system identification judges it: the state estimated from a burn-in
window of recorded frames, then the simulation (the convention of the nonlinear
system-identification benchmarks: a state-initialisation window, then a free run).

From each start s, the model's state at frame s - N is estimated from the N + 1 recorded
frames s - N ... s with its parameters held (single shooting over the burn-in window: the
initial positions and velocities are the unknowns, fitted by Gauss-Newton to every recorded
position of the window, :data:`ITERATIONS` damped steps from the recorded positions and
their central differences); the model then runs from that state through the burn-in and on,
and its predictions of frames s + 1 ... s + H are scored against the recording. Zero force
gets the same estimator with no force: its state is the least-squares line through the
burn-in window (exact for a body moving at constant velocity), carried on.

Unlike a free run from two recorded frames (:mod:`.metrics`), whose start velocity carries
the markers' noise times 1 / dt, the burn-in state averages the noise over the window, so
the score says what the model's dynamics predict, not how noisy two frames were. An
entrained drive's phase starts at its tracked value (:func:`.predictions.tracked_phases`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ...model import Model
from ...physics import linsolve, rollout_states
from ...runtime import float64
from .metrics import THRESHOLD_MM, frames_within
from .predictions import StaticTopology, float64_params, tracked_phases
from .verdict import plain

ITERATIONS = 8  # Gauss-Newton steps of the burn-in's state estimate
DAMPING = 1e-9  # of J^T J's largest diagonal entry: a step near Gauss-Newton's, always solvable
DEFAULT_STARTS = 20  # starts spread evenly over the frames that have a burn-in before them


@dataclass(frozen=True)
class BurnIn:
    """The free runs after an N-frame burn-in, the model beside zero force (errors in mm)."""

    frames: int  # N, the burn-in window's frames before each start (N + 1 recorded frames)
    horizon: int  # frames predicted after each start
    starts: tuple[int, ...]  # the start frames s (indices into the window scored)
    model_mm: tuple[float, ...]  # RMS error k frames after the start, k = 1 ... horizon
    zero_force_mm: tuple[float, ...]
    model_within: float  # median frames before a marker is off by more than threshold_mm
    zero_force_within: float
    threshold_mm: float = THRESHOLD_MM
    # the recording's mean gait played from the phase the burn-in shows (report.gait's
    # template_runs), where the recording is rhythmic: the baseline a gait model must beat
    template_mm: tuple[float, ...] | None = None
    template_within: float | None = None

    def lines(self) -> list[str]:
        """The verdict in words: the error at the horizon and the frames within the
        threshold, the model beside zero force."""
        # the farthest frame ahead that some start has recorded
        scored = [k for k, z in enumerate(self.zero_force_mm) if np.isfinite(z)]
        at = scored[-1] if scored else self.horizon - 1
        h = at + 1
        m, z = self.model_mm[at], self.zero_force_mm[at]
        word = "better" if m < z else "worse"
        out = [
            f"free runs after a {self.frames}-frame burn-in ({len(self.starts)} starts): "
            f"{h} frames ahead {m:.4g} mm, zero force {z:.4g} mm ({word} than zero force); "
            f"within {self.threshold_mm:g} mm for {self.model_within:g} frames (median), zero "
            f"force {self.zero_force_within:g}"
        ]
        if self.template_mm is not None:
            g = self.template_mm[at]
            beats = "better" if m < g else "worse"
            out.append(
                f"the recording's mean gait from the burn-in's phase: {h} frames ahead "
                f"{g:.4g} mm, within {self.threshold_mm:g} mm for {self.template_within:g} "
                f"frames (the model is {beats} than this template {h} frames ahead)"
            )
        return out

    @classmethod
    def from_record(cls, record: dict) -> BurnIn:
        """Back from :meth:`record` (non-finite numbers as their text)."""

        def curve(key):
            values = record.get(key)
            return None if values is None else tuple(float(x) for x in values)

        return cls(
            frames=int(record["frames"]),
            horizon=int(record["horizon"]),
            starts=tuple(int(s) for s in record["starts"]),
            model_mm=curve("model_mm"),
            zero_force_mm=curve("zero_force_mm"),
            model_within=float(record["model_within"]),
            zero_force_within=float(record["zero_force_within"]),
            threshold_mm=float(record["threshold_mm"]),
            template_mm=curve("template_mm"),
            template_within=(
                None if record.get("template_within") is None else float(record["template_within"])
            ),
        )

    def record(self) -> dict:
        return {
            "frames": self.frames,
            "horizon": self.horizon,
            "starts": list(self.starts),
            "model_mm": [plain(x) for x in self.model_mm],
            "zero_force_mm": [plain(x) for x in self.zero_force_mm],
            "model_within": self.model_within,
            "zero_force_within": self.zero_force_within,
            "threshold_mm": self.threshold_mm,
            **(
                {
                    "template_mm": [plain(x) for x in self.template_mm],
                    "template_within": self.template_within,
                }
                if self.template_mm is not None
                else {}
            ),
        }


def burn_in_starts(positions: np.ndarray, frames: int, horizon: int, count: int) -> list[int]:
    """Start frames s whose burn-in window s - ``frames`` ... s is complete and with at least
    one frame after them, ``count`` of them spread evenly (all where there are fewer)."""
    x = np.asarray(positions, np.float64)
    complete = np.isfinite(x).all(axis=(1, 2))
    n = x.shape[0]
    possible = [s for s in range(frames, n - 1) if complete[s - frames : s + 1].all()]
    if len(possible) <= count:
        return possible
    picks = np.linspace(0, len(possible) - 1, count).round().astype(int)
    return [possible[i] for i in sorted(set(picks.tolist()))]


@float64
def burn_in(
    model: Model,
    positions: np.ndarray,
    dt: float,
    frames: int,
    horizon: int,
    *,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
    starts: int = DEFAULT_STARTS,
    threshold_mm: float = THRESHOLD_MM,
    before: np.ndarray | None = None,
) -> BurnIn:
    """The model's free runs of ``horizon`` frames after a ``frames``-frame burn-in, from
    starts spread over ``positions`` [F, P, D] (the model's particle order, NaN where
    missing), beside zero force's (see the module's docstring). ``offset``: frames from the
    model's time origin to the first of ``positions``; ``before``: the recorded ones between
    (:func:`~.predictions.before_window`)."""
    if frames < 1 or horizon < 1:
        raise ValueError(
            f"the burn-in and the horizon need at least 1 frame, got {frames}, {horizon}"
        )
    x = np.asarray(positions, np.float64)
    picked = burn_in_starts(x, frames, horizon, starts)
    if not picked:
        raise ValueError(f"no start has {frames + 1} complete frames before it")
    window = np.stack([x[s - frames : s + 1] for s in picked])  # [S, N + 1, P, D]
    times = (np.asarray(picked) - frames + offset) * dt
    psis = None
    phases = tracked_phases(model, x, dt, substeps, offset, before)
    if phases is not None:
        psis = jnp.asarray(phases[np.asarray(picked) - frames])
    runs = np.asarray(
        _burn_in_runs(
            float64_params(model),
            jnp.asarray(window),
            jnp.asarray(times),
            psis,
            float(dt),
            StaticTopology(model.topology),
            int(frames),
            int(horizon),
            int(substeps),
            method,
        ),
        np.float64,
    )
    zero = _line_runs(window, horizon)
    target = targets(x, picked, horizon)
    model_curve, model_within = score(runs, target, threshold_mm)
    zero_curve, zero_within = score(zero, target, threshold_mm)
    return BurnIn(
        frames=int(frames),
        horizon=int(horizon),
        starts=tuple(int(s) for s in picked),
        model_mm=model_curve,
        zero_force_mm=zero_curve,
        model_within=model_within,
        zero_force_within=zero_within,
        threshold_mm=float(threshold_mm),
    )


def targets(positions: np.ndarray, starts, horizon: int) -> np.ndarray:
    """The recorded frames s + 1 ... s + ``horizon`` after each start [S, horizon, P, D]
    (NaN past the recording's end)."""
    x = np.asarray(positions, np.float64)
    out = np.full((len(starts), horizon, *x.shape[1:]), np.nan)
    for i, s in enumerate(starts):
        ahead = x[s + 1 : s + 1 + horizon]
        out[i, : len(ahead)] = ahead
    return out


def score(runs: np.ndarray, target: np.ndarray, threshold_mm: float = THRESHOLD_MM):
    """(the RMS error curve k = 1 ... horizon frames on, the median frames within
    ``threshold_mm``) of runs [S, horizon, P, D] against :func:`targets`."""
    return _curve(runs, target), _within(runs, target, threshold_mm)


def _curve(runs: np.ndarray, target: np.ndarray) -> tuple[float, ...]:
    """RMS position error (mm) k frames after the start, over the starts and markers
    recorded there; a non-finite prediction of a recorded marker makes it infinite."""
    err2 = np.sum((runs - target) ** 2, axis=-1)  # [S, H, P]
    recorded = np.isfinite(target).all(axis=-1)
    out = []
    for k in range(err2.shape[1]):
        terms = err2[:, k][recorded[:, k]]
        if not terms.size:
            out.append(float("nan"))
        elif not np.all(np.isfinite(terms)):
            out.append(float("inf"))
        else:
            out.append(float(np.sqrt(terms.mean()) * 1000.0))
    return tuple(out)


def _within(runs: np.ndarray, target: np.ndarray, threshold_mm: float) -> float:
    """Median over the starts of the frames before a marker is off by more than the
    threshold (:func:`.metrics.frames_within`)."""
    counts = [frames_within(r, t, threshold_mm)[0] for r, t in zip(runs, target, strict=True)]
    return float(np.median(counts))


def _line_runs(window: np.ndarray, horizon: int) -> np.ndarray:
    """Zero force after the burn-in: the least-squares line through each window's frames
    (position and velocity at its first frame), carried on ``horizon`` frames after its
    last. [S, horizon, P, D]."""
    n = window.shape[1]
    k = np.arange(n, dtype=np.float64)
    design = np.stack([np.ones(n), k], axis=1)  # [N + 1, 2]
    flat = window.reshape(window.shape[0], n, -1)  # [S, N + 1, P D]
    coef = np.einsum("ij,sjc->sic", np.linalg.pinv(design), flat)  # [S, 2, P D]
    ahead = np.arange(n, n + horizon, dtype=np.float64)
    runs = coef[:, :1] + ahead[None, :, None] * coef[:, 1:]
    return runs.reshape(window.shape[0], horizon, *window.shape[2:])


@partial(jax.jit, static_argnames=("dt", "topo", "frames", "horizon", "substeps", "method"))
def _burn_in_runs(params, window, times, psis, dt, topo, frames, horizon, substeps, method):
    """Each window's state at its first frame estimated with the parameters held, then the
    run from it through the burn-in and ``horizon`` frames on: the last [S, horizon, P, D]."""
    shape = window.shape[2:]

    def run(y, t0, psi, n_steps):
        x0, v0 = y[: y.size // 2].reshape(shape), y[y.size // 2 :].reshape(shape)
        extra = () if psi is None else (psi,)
        out = rollout_states(params, topo.topo, x0, v0, dt, n_steps, substeps, method, t0, *extra)
        return jnp.concatenate([x0[None], out[0]])  # [n_steps + 1, P, D]

    def estimate(recorded, t0, psi):
        def residuals(y):
            return (run(y, t0, psi, frames) - recorded).ravel()

        v = (
            (recorded[1] - recorded[0]) / dt
            if frames == 1
            else (recorded[2] - recorded[0]) / (2 * dt)
        )
        y0 = jnp.concatenate([recorded[0].ravel(), v.ravel()])

        def step(_, y):
            r, j = residuals(y), jax.jacfwd(residuals)(y)
            jtj = j.T @ j
            damp = DAMPING * jnp.max(jnp.diagonal(jtj))
            # XLA operations, not LAPACK (physics.linsolve: batched LAPACK kernels deadlocked)
            dy = linsolve.solve(jtj + damp * jnp.eye(y.size), -(j.T @ r))
            return jnp.where(jnp.all(jnp.isfinite(dy)), y + dy, y)

        y = jax.lax.fori_loop(0, ITERATIONS, step, y0)
        return run(y, t0, psi, frames + horizon)[frames + 1 :]

    if psis is None:
        return jax.vmap(lambda w, t: estimate(w, t, None))(window, times)
    return jax.vmap(estimate)(window, times, psis)


__all__ = ["BurnIn", "burn_in", "burn_in_starts"]
