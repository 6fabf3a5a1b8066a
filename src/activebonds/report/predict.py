"""What an identified model predicts along a recording, for the report: the predictions of
:mod:`activebonds.identify.judge.predictions` over the fitted window and beyond, and its neurons.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .. import bonds
from ..data import Trajectory
from ..identify.judge.predictions import (
    StaticTopology,
    float64_params,
    free_run,
    neural_bonds,
    neural_kinds,
    one_step,
    rms_mm,
)
from ..model import Model
from ..physics import neuron_activity, phase
from ..runtime import float64
from .runs import RunRecord, load_run, original_window

SATURATION = 0.95  # |a| above this: a saturated neuron
NEAR_ZERO = 0.01  # |w| below this fraction of the weight range: a near-zero weight


@partial(jax.jit, static_argnames=("topo",))
def _activations(params, xs, vs, ts, topo: StaticTopology, psis=None):
    if psis is not None:  # an entrained drive's phase at each state

        def phased(x, v, t, psi):
            return neuron_activity(phase.at_phase(params, psi), topo.topo, x, v, t)

        return jax.vmap(phased)(xs, vs, ts, psis)
    return jax.vmap(lambda x, v, t: neuron_activity(params, topo.topo, x, v, t))(xs, vs, ts)


@float64
def activations(
    model: Model, xs: np.ndarray, vs: np.ndarray, dt: float = 0.0, phases=None, offset: int = 0
) -> np.ndarray:
    """Neuron activations at each state (x, v) of frames 0, 1, ... (time ``(offset + frame)
    dt``, for a rhythmic drive; an entrained drive's phase ``phases`` [F]), [F, B]; 0 for non-neural
    bonds, NaN where the state (or an entrained drive's phase) is unknown."""
    xs = np.asarray(xs, np.float64)
    vs = np.asarray(vs, np.float64)
    n_b = len(neural_bonds(model.topology)[1])
    out = np.full((xs.shape[0], n_b), np.nan)
    if n_b == 0:
        return out
    ok = np.isfinite(xs).all(axis=(1, 2)) & np.isfinite(vs).all(axis=(1, 2))
    psis = None
    if phase.entrained(model.topology):
        phases = np.full(xs.shape[0], np.nan) if phases is None else np.asarray(phases)
        ok &= np.isfinite(phases)
        psis = jnp.asarray(phases[ok])
    if not ok.any():
        return out
    ts = jnp.asarray((np.arange(xs.shape[0])[ok] + max(int(offset), 0)) * float(dt))
    act = _activations(
        float64_params(model),
        jnp.asarray(xs[ok]),
        jnp.asarray(vs[ok]),
        ts,
        topo=StaticTopology(model.topology),
        psis=psis,
    )
    out[ok] = np.asarray(act, np.float64)
    return out


def saturation_share(act: np.ndarray, neural: np.ndarray, limit: float = SATURATION):
    """Share of (frame, neuron) samples with |a| > ``limit`` among neural bonds' known
    activations (NaN if none), and the share per neuron [B] (NaN for non-neural bonds)."""
    neural = np.asarray(neural, bool)
    if neural.size == 0:  # no binary bond (e.g. springs to anchors only)
        return float("nan"), np.full(0, np.nan)
    act = np.asarray(act, np.float64).reshape(-1, len(neural))
    known = np.isfinite(act) & neural[None, :]
    sat = (np.abs(np.where(known, act, 0.0)) > limit) & known
    per = np.full(len(neural), np.nan)
    counts = known.sum(axis=0)
    per[counts > 0] = sat.sum(axis=0)[counts > 0] / counts[counts > 0]
    total = known.sum()
    return (float(sat.sum() / total) if total else float("nan")), per


def neural_weights(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Input weights of the neural bonds: length weights [B, B], rate weights [B, B] (NaN on
    the unused diagonal and in rows of non-neural bonds) and each row's weight range [B]."""
    p, topo = model.params, model.topology
    _, neural = neural_bonds(topo)
    n_b = len(neural)
    w_len = np.full((n_b, n_b), np.nan)
    w_rate = np.full((n_b, n_b), np.nan)
    span = np.full(n_b, np.nan)
    start = 0
    for k in neural_kinds(topo):
        kind = bonds.get(k)
        n = topo.count(k)
        block = slice(start, start + n)
        for par in kind.parameters:
            if par.form != "weights":
                continue
            target = w_len if par.part == "length" else w_rate
            target[block, block] = np.array(p.bonds[k][par.field], np.float64).reshape(n, n)
            for i, b in enumerate(bond for bond in model.spec.bond if bond.kind == k):
                w = getattr(b, par.key)
                if w is not None and (par.when is None or getattr(b, par.when)):
                    span[start + i] = w.max - w.min
        start += n
    unused = np.eye(n_b, dtype=bool) | ~neural[:, None]
    w_len[unused] = np.nan
    w_rate[unused] = np.nan
    return w_len, w_rate, span


def near_zero_share(model: Model, fraction: float = NEAR_ZERO) -> float:
    """Share of neural input weights with |w| < ``fraction`` x (max - min) of their bond's
    weight bounds (NaN for a model without neural inputs)."""
    w_len, w_rate, span = neural_weights(model)
    w = np.stack([w_len, w_rate])  # [2, B, B]
    known = np.isfinite(w)
    if not known.any():
        return float("nan")
    small = np.abs(np.where(known, w, 0.0)) < fraction * span[None, :, None]
    return float((small & known).sum() / known.sum())


@dataclass(frozen=True, eq=False)
class Prediction:
    """A model's predictions along a recording (SI units, NaN where unknown).

    Frames ``[0, fit_frames)`` are the fitted window; later frames (if any) test
    generalisation."""

    names: tuple[str, ...]  # particle names
    markers: tuple[str, ...]
    bonds: np.ndarray  # [B, 2] particle indices of the binary bonds (neural_bonds)
    neural: np.ndarray  # [B] bool
    times: np.ndarray  # [F] seconds from the first frame
    dt: float
    fit_frames: int
    recorded: np.ndarray  # [F, P, D]
    one_step: np.ndarray  # [F, P, D]
    free_run: np.ndarray  # [F, P, D]
    activation: np.ndarray  # [F, B] along the free run
    one_step_rms_mm: np.ndarray  # [P] over the fitted window
    free_run_rms_mm: np.ndarray  # [P] over the fitted window (:func:`free_run_rms_mm`)
    one_step_rms_mm_beyond: np.ndarray | None  # [P] beyond the fitted window
    # [P] beyond the fitted window: a free run of their own, from their first two frames, as
    # ``evaluate --frames`` scores them (:func:`free_run_rms_mm`)
    free_run_rms_mm_beyond: np.ndarray | None
    saturated_share: float  # NaN without neurons
    saturated_per_neuron: np.ndarray  # [B]
    near_zero_weight_share: float  # NaN without neural weights
    diverged_at: int | None  # first frame where the free run went non-finite (its RMS: inf)

    @property
    def n_frames(self) -> int:
        return int(self.recorded.shape[0])

    @property
    def extended(self) -> bool:
        return self.n_frames > self.fit_frames


@float64
def predict(
    model: Model,
    traj: Trajectory,
    *,
    fit_frames: int | None = None,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
    before: np.ndarray | None = None,
) -> Prediction:
    """One-step and free-run predictions of ``model`` along ``traj`` (markers already in the
    model's particle order). ``fit_frames``: length of the fitted window at the start of
    ``traj`` (default: all of it); ``offset``: frames from the model's time origin to
    ``traj``'s first frame (:func:`~activebonds.identify.judge.predictions.one_step`),
    ``before`` the recorded frames between."""
    if traj.n_markers != model.topology.n_particles:
        raise ValueError(
            f"{traj.n_markers} markers for a model of {model.topology.n_particles} particles"
        )
    rec = np.asarray(traj.positions, np.float64)
    n = rec.shape[0]
    fit = n if fit_frames is None else max(1, min(int(fit_frames), n))
    dt = traj.dt
    one = one_step(model, rec, dt, substeps, method, offset, before)
    xs, vs, psis = free_run(
        model, rec, dt, n, substeps, method, with_phases=True, offset=offset, before=before
    )
    act = activations(model, xs, vs, dt, psis, offset)
    pairs_of_bonds, neural = neural_bonds(model.topology)
    sat, per = saturation_share(act, neural)
    complete = np.isfinite(rec).all(axis=(1, 2))
    pairs = complete[1:] & complete[:-1]
    first_run = int(np.argmax(pairs)) + 1 if pairs.any() else n
    # predictions that should exist but went non-finite count as infinite errors
    free_failed = (np.arange(n) > first_run) & ~np.isfinite(xs).all(axis=(1, 2))
    diverged = int(np.argmax(free_failed)) if free_failed.any() else None
    one_failed = np.zeros(n, bool)
    one_failed[2:] = pairs[:-1] & ~np.isfinite(one[2:]).all(axis=(1, 2))

    def one_rms(lo, hi):
        return _counted_rms(one, rec, lo, hi, one_failed)

    def free_rms(lo, hi):  # the frames' own free run, as evaluate scores them
        return free_run_rms_mm(model, rec[lo:hi], dt, substeps, method)

    return Prediction(
        names=model.particle_names,
        markers=tuple(traj.markers),
        bonds=pairs_of_bonds,
        neural=neural,
        times=np.arange(n) * dt,
        dt=dt,
        fit_frames=fit,
        recorded=rec,
        one_step=one,
        free_run=xs,
        activation=act,
        one_step_rms_mm=one_rms(0, fit),
        free_run_rms_mm=free_rms(0, fit),
        one_step_rms_mm_beyond=one_rms(fit, n) if n > fit else None,
        free_run_rms_mm_beyond=free_rms(fit, n) if n > fit else None,
        saturated_share=sat,
        saturated_per_neuron=per,
        near_zero_weight_share=near_zero_share(model),
        diverged_at=diverged,
    )


@float64
def free_run_rms_mm(
    model: Model, positions: np.ndarray, dt: float, substeps: int = 1, method: str = "euler"
) -> np.ndarray:
    """Per particle, the RMS error (mm) of the model's free run along ``positions`` [F, P, D]
    (markers in the model's particle order): one run from their first two complete frames,
    time 0 at their first frame, over the frames after those two; a prediction that went
    non-finite where the particle was recorded counts as infinite. The one function behind
    ``evaluate``'s per-particle free run and the report's (the fitted frames, and the frames
    beyond them: a run of their own, as ``evaluate --frames`` starts one)."""
    rec = np.asarray(positions, np.float64)
    n = rec.shape[0]
    xs, _ = free_run(model, rec, dt, n, substeps, method)
    complete = np.isfinite(rec).all(axis=(1, 2))
    pairs = complete[1:] & complete[:-1]
    first_run = int(np.argmax(pairs)) + 1 if pairs.any() else n
    failed = (np.arange(n) > first_run) & ~np.isfinite(xs).all(axis=(1, 2))
    return _counted_rms(_model_only(xs, first_run), rec, 0, n, failed)


def _counted_rms(pred, rec, lo: int, hi: int, failed: np.ndarray) -> np.ndarray:
    """RMS over frames [lo, hi); a particle with a recorded target at a failed (non-finite)
    prediction gets +inf, as in the cost."""
    out = rms_mm(pred, rec, slice(lo, hi))
    known = np.isfinite(rec[lo:hi]).all(axis=-1)  # [f, P]
    out[(failed[lo:hi, None] & known).any(axis=0)] = np.inf
    return out


def _model_only(xs: np.ndarray, first_run: int) -> np.ndarray:
    """The free run without its copied start frames (they are not predictions)."""
    out = xs.copy()
    out[: first_run + 1] = np.nan
    return out


def default_frames(record: RunRecord) -> int:
    """Default length of the window shown in a report: twice the fitted window."""
    return 2 * record.window.n_frames


@float64
def predict_run(
    run: str | Path | RunRecord, frames: int | None = None
) -> tuple[Prediction, RunRecord]:
    """Predictions of a run's best model along its fitted window, extended to ``frames``
    frames of the original recording when it is still there and unchanged (``frames`` <= the
    window's length or None: the fitted window only)."""
    record = run if isinstance(run, RunRecord) else load_run(run)
    traj = record.window
    if frames is not None and frames > record.window.n_frames:
        traj = original_window(record, frames) or record.window
    s = record.settings
    pred = predict(
        record.model,
        traj,
        fit_frames=record.window.n_frames,
        substeps=s.substeps,
        method=s.integrator,
    )
    return pred, record
