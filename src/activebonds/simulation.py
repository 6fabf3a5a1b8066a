"""Free-run simulation of a model into a trajectory file (the ``simulate`` command)."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .atomic import output_path
from .data import Trajectory, read_trajectory, write_trajectory
from .errors import DivergenceError, InputError
from .model import Model, build, load_model
from .physics import advance, integrators, phase, rollout, start_velocity
from .runtime import float64


@float64
def simulate(
    model: Model,
    n_frames: int,
    rate: float,
    start: Trajectory | None = None,
    substeps: int = 1,
    integrator: str = "euler",
) -> Trajectory:
    """Free-run a model: positions of ``n_frames`` frames at ``rate`` Hz.

    Args:
        model: the model (e.g. ``load_model(path)`` or a fit's ``result.model``).
        n_frames: frames to return, including the first.
        rate: frame rate in Hz (the step is ``1 / rate``, divided by ``substeps``).
        start: where to start. ``None`` (default): the model file's initial state, the
            ``position`` (required for every particle) and ``velocity`` (default zero) of
            each ``[[particle]]``. A :class:`Trajectory` holding every model marker in its
            first two frames: those two frames are the first two written, and the run goes
            on from frame 1 with the velocity the integrator carries there given frames 0
            and 1 (see :func:`~activebonds.physics.start_velocity`).
        substeps: integration steps per frame.
        integrator: ``"euler"`` (semi-implicit) or ``"verlet"``.

    Time (for forces that depend on it) is 0 at the first frame written, and an entrained
    drive's phase is its start phase there (:mod:`~activebonds.physics.phase`; from a
    recording, tracked to frame 1 along its first two frames).

    Raises:
        InputError: a bad rate or integrator, a particle without ``position`` when ``start``
            is None, or a ``start`` without the model's markers in its first two frames.
        DivergenceError: the run became non-finite (names the frame, particle and bonds).
    """
    if not (np.isfinite(rate) and rate > 0):
        raise InputError("--rate", f"must be a positive number of Hz, got {rate}")
    if integrator not in integrators.names():
        known = " or ".join(integrators.names())
        raise InputError("--integrator", f"expected {known}, got '{integrator}'")
    dt = 1.0 / rate
    psi_first = psi_second = None  # an entrained drive's phase at the first two frames
    if phase.entrained(model.topology):
        psi_first = phase.start_phase(model.params, model.topology)
    if start is None:
        require_initial_state(model)  # before any computation
        x0, v0 = model.initial_state()
        first = None
        t0 = 0.0
    else:
        first, x0, v0, psi_second = _recorded_start(
            model, start, dt, substeps, integrator, psi_first
        )
        t0 = dt  # frame 1
    n_run = n_frames if first is None else n_frames - 1
    run = rollout(
        model.params,
        model.topology,
        jnp.asarray(x0),
        jnp.asarray(v0),
        dt,
        n_run,
        substeps,
        integrator,
        t0,
        psi_first if first is None else psi_second,
    )
    xs = np.asarray(run[0] if phase.entrained(model.topology) else run)
    if first is not None:
        xs = np.concatenate([first[None], xs])
    check_finite(model, xs, rate)
    return Trajectory(
        positions=xs,
        mask=np.ones(xs.shape[:2], bool),
        markers=model.markers,
        rate=rate,
        source_units="m",
    )


def _recorded_start(model: Model, start: Trajectory, dt, substeps, integrator, psi_first):
    """(frame 0, frame 1, the velocity at frame 1, the drive's phase there) of ``start``'s
    first two frames, the run going on from frame 1 (time ``dt``); InputError where they miss
    a model marker."""
    data = start.select(list(model.markers))
    if data.n_frames < 2 or not data.mask[:2].all():
        raise InputError(start.source, "the first two frames must hold every model marker")
    first = data.positions[0]
    x0 = data.positions[1]
    psi_second = None
    if psi_first is not None:  # the phase of frame 1 tracked along the record
        s = phase.recorded_signal(model.topology, data.positions[:2])
        psi_second = phase.track(model.params, model.topology, s, dt, substeps)[1]
    v0 = start_velocity(
        model.params,
        model.topology,
        jnp.asarray(first),
        jnp.asarray(x0),
        dt,
        substeps,
        integrator,
        t=dt,
        psi=psi_first,
        newton=True,
    )
    return first, x0, v0, psi_second


def require_initial_state(model: Model, where="model") -> None:
    """Refuse (InputError) a free run from the model file when some particle has no
    ``position``: its start would be made up (the origin), not the model's."""
    unplaced = model.unplaced()
    if unplaced is None:
        return
    raise InputError(
        where,
        f"the model has no initial state: {unplaced}; give each [[particle]] a position = "
        f"[...] "
        f"(and optionally velocity = [...]), or start from a recording's first two frames "
        f"with --from TRAJ (Python: simulate(..., start=trajectory))",
    )


def check_finite(model: Model, xs: np.ndarray, rate: float) -> None:
    """Report divergence with the first bad frame, the particle and its bonds; never clamp."""
    bad = ~np.isfinite(xs).all(axis=-1)
    if not bad.any():
        return
    frame, particle = map(int, np.argwhere(bad)[0])
    name = model.particle_names[particle]
    bonds = [
        f"bond[{i}] ({b.kind} {'-'.join(b.particles)})"
        for i, b in enumerate(model.spec.bond)
        if name in b.particles
    ]
    raise DivergenceError(
        f"simulation diverged at frame {frame} (t = {frame / rate:.4g} s): particle '{name}' "
        f"became non-finite; bonds involved: {', '.join(bonds) or 'none'} "
        f"(stiffness too high for the step? try --substeps)"
    )


def simulate_to_file(
    model_path, n_frames, rate, out, start_path=None, substeps=1, integrator="euler"
):
    out = output_path(out)
    model = load_model(model_path)
    start = read_trajectory(start_path) if start_path is not None else None
    if start is None:
        require_initial_state(model, model_path)
    traj = simulate(model, n_frames, rate, start, substeps, integrator)
    write_trajectory(traj, Path(out))
    return traj.n_frames


START_ROUNDS = 50  # fixed-point rounds of the start velocity
START_TOLERANCE = 1e-9  # of the frame's displacement: the start velocity's step lands there
NEWTON_ROUNDS = 10  # Newton rounds of the start velocity, where the fixed point fails


def landing_velocity(step, x0: np.ndarray, x1: np.ndarray, dt: float):
    """(v, how): the velocity from which ``step(v)`` (the model's step over one frame from
    ``x0``) lands on ``x1``, and how it was found, in words. First the fixed point
    ``v <- v + (x1 - step(v)) / dt`` from the forward difference (cheap: no Jacobian; it
    converges while the step's damping is weak, ``dt c / m < 1``); where it does not, Newton's
    method on ``step(v) = x1`` (the step's Jacobian in v, forward mode): a damping strong for
    the frame rate, or stiff contacts. Converged means landing within
    :data:`START_TOLERANCE` of the frame's displacement (1e-3 of it at least). Where neither
    converges: the forward difference ``(x1 - x0) / dt``, and ``how`` says so."""
    forward = (x1 - x0) / dt
    scale = float(np.sqrt(np.sum((x1 - x0) ** 2))) + 1e-12

    def miss_of(v):
        return x1 - np.asarray(step(jnp.asarray(v)), np.float64)

    def landed(miss, tolerance):
        return bool(np.all(np.isfinite(miss)) and np.sqrt(np.sum(miss**2)) <= tolerance * scale)

    with jax.enable_x64(True):
        v = forward
        for _ in range(START_ROUNDS):
            miss = miss_of(v)
            if not np.all(np.isfinite(miss)):
                break
            v = v + miss / dt
            if landed(miss, START_TOLERANCE):
                break
        if np.all(np.isfinite(v)) and landed(miss_of(v), 1e-3):
            return v, "the velocity from which the model's step lands on the next frame"
        v = forward
        jacobian = jax.jacfwd(lambda u: step(u).reshape(-1))
        for _ in range(NEWTON_ROUNDS):
            miss = miss_of(v)
            if not np.all(np.isfinite(miss)) or landed(miss, START_TOLERANCE):
                break
            jac = np.asarray(jacobian(jnp.asarray(v)), np.float64).reshape(v.size, v.size)
            try:
                v = v + np.linalg.solve(jac, miss.reshape(-1)).reshape(v.shape)
            except np.linalg.LinAlgError:
                break
        if np.all(np.isfinite(v)) and landed(miss_of(v), 1e-3):
            return v, (
                "the velocity from which the model's step lands on the next frame (by Newton's "
                "method: the step's damping is strong for the frame rate)"
            )
    return forward, (
        "the forward difference to the next frame (the model's step lands there from no "
        "velocity found: it diverges or does not converge)"
    )


@partial(jax.jit, static_argnames=("topo", "substeps", "method"))
def _advance(params, topo, x, v, dt, substeps, method, psi):
    """:func:`advance` over one frame from time 0, compiled once per shape and structure
    (run op by op, its hundred operations each compiled a program of their own: 2-3 s)."""
    return advance(params, topo, x, v, dt, substeps, method, 0.0, psi)


def start_at(
    model: Model,
    recording: Trajectory,
    frame: int = 0,
    substeps: int = 1,
    integrator: str = "euler",
    where: str = "--frame",
    notes: list[str] | None = None,
) -> Model:
    """The model with every particle's ``position`` and ``velocity`` at ``frame`` of
    ``recording`` (its markers, the model's): the position recorded there, and the velocity
    from which the model's own step (``substeps``, ``integrator``) lands on the next frame
    (:func:`landing_velocity`). So ``simulate`` from the model file reproduces the recording's
    next frame, and ``export`` starts there. Time in the model's forces starts at 0 at that
    frame. ``notes``: a list that gets one line saying how the velocity was found. InputError
    (naming ``where``) when the frame or the next one misses a model marker or is outside the
    recording."""
    data = recording.select(list(model.markers))
    n = data.n_frames
    if not 0 <= frame < n - 1:
        raise InputError(
            where, f"frame {frame} is not one of the {n} frames with a next one (0..{n - 2})"
        )
    if not (data.mask[frame].all() and data.mask[frame + 1].all()):
        raise InputError(
            where,
            f"frames {frame} and {frame + 1} of {recording.source or 'the recording'} must "
            "hold every model marker",
        )
    x0 = np.asarray(data.positions[frame], np.float64)
    x1 = np.asarray(data.positions[frame + 1], np.float64)
    dt = data.dt

    psi = None  # an entrained drive starts at its start phase
    if phase.entrained(model.topology):
        psi = phase.start_phase(model.params, model.topology)

    def step(v):  # one program per shape and structure, reused at every checkpoint
        return _advance(model.params, model.topology, x0, v, dt, substeps, integrator, psi)[0]

    v, how = landing_velocity(step, x0, x1, dt)
    if notes is not None:
        notes.append(f"initial velocities at frame {frame}: {how}")
    particles = [
        p.model_copy(
            update={"position": [float(a) for a in x0[i]], "velocity": [float(a) for a in v[i]]}
        )
        for i, p in enumerate(model.spec.particle)
    ]
    spec = model.spec.model_copy(update={"particle": particles})
    return build(spec, disable=model.disabled)
