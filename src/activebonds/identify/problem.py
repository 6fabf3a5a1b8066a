"""From (model, trajectory, settings) to the ES's :class:`~activebonds.identify.search.es.Problem`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ..data.trajectory import Trajectory
from ..errors import InputError
from ..model import Model, as_neural, as_standard
from .costs.windows import Windows, join_windows, make_cost, make_windows, neighbours_of
from .search.es import Problem
from .search.population_cost import make_population_cost
from .settings import FitSettings
from .solvers.lsq import least_squares


@dataclass(frozen=True, eq=False)
class Identification:
    """The model to fit, the recorded window it is fitted to, and the ES problem."""

    model: Model
    data: Trajectory  # selected markers (model particle order), frame window; the first
    windows: Windows  # of every recording, one after the other
    problem: Problem
    recordings: tuple[Trajectory, ...] = ()  # every recording fitted (data is the first)

    @property
    def all_data(self) -> tuple[Trajectory, ...]:
        return self.recordings or (self.data,)


def variant(model: Model, bonds: str) -> Model:
    if bonds == "standard":
        return as_standard(model)
    if bonds == "neural":
        return as_neural(model)
    return model


def particle_markers(model: Model, markers: Sequence[str] | None) -> tuple[str, ...]:
    """The markers the model's particles follow, in order: ``markers`` (the model's own
    without them), one per particle, or an InputError naming ``--markers``."""
    markers = tuple(markers or model.markers)
    if len(markers) != len(model.particle_names):
        raise InputError(
            "--markers",
            f"{len(markers)} markers given for a model of {len(model.particle_names)} particles "
            f"({', '.join(model.particle_names)}); give one marker per particle, in order",
        )
    return markers


def select_data(model: Model, traj: Trajectory, settings: FitSettings) -> Trajectory:
    """The trajectory cut to the model's markers (or ``settings.markers``) and frame window."""
    markers = particle_markers(model, settings.markers)
    data = traj.select(list(markers))
    start, stop = settings.frames
    data = data.window(start, stop if stop is not None else data.n_frames)
    if data.dimension != model.dimension:
        raise InputError(
            traj.source, f"the data are {data.dimension}D but the model is {model.dimension}D"
        )
    if data.n_frames < 3:
        raise InputError("--frames", f"the window holds {data.n_frames} frames; at least 3 needed")
    return data


def select_recordings(
    model: Model, recordings: Sequence[Trajectory], settings: FitSettings
) -> tuple[Trajectory, ...]:
    """Each recording cut to the model's markers and the frame window; one model fitted on
    several recordings needs them at one frame rate."""
    data = tuple(select_data(model, t, settings) for t in recordings)
    for d in data[1:]:
        if abs(d.dt - data[0].dt) > 1e-9 * data[0].dt:
            raise InputError(
                d.source or "trajectory",
                f"recorded at {d.rate:g} Hz but {data[0].source or 'the first'} at "
                f"{data[0].rate:g} Hz; one fit needs one frame rate (resample first)",
            )
    return data


def identification(
    model: Model, traj: Trajectory | Sequence[Trajectory], settings: FitSettings
) -> Identification:
    """The problem of fitting ``model`` to one recording or to several at once (their costs
    add up; each is cut to the same markers and frame window)."""
    model = variant(model, settings.bonds)
    if model.layout.n_genes == 0:
        raise InputError(model.name, "the model has no free parameter to identify")
    recordings = (traj,) if isinstance(traj, Trajectory) else tuple(traj)
    data = select_recordings(model, recordings, settings)

    acting = neighbours_of(model)

    def cut(horizon):
        return join_windows(
            [
                make_windows(d.positions, d.mask, d.dt, horizon, settings.smooth, acting)
                for d in data
            ]
        )

    windows = cut(settings.es_horizon)
    if windows.n_terms == 0:
        raise InputError(
            recordings[0].source, "no frame of the window can be predicted (gaps everywhere)"
        )
    cost = make_cost(model, windows, settings.es_substeps, settings.es_integrator)
    layout = model.layout
    start = None
    if settings.init == "lsq":
        try:
            start = least_squares(model, cut(1)).genome[None, :]
        except InputError as err:
            raise InputError("--init lsq", err.message) from None
    elif settings.init == "model":
        start = np.asarray(layout.initial(), np.float64)[None, :]
    problem = Problem(
        evaluate=cost,
        evaluate_population=make_population_cost(
            model,
            windows,
            settings.es_substeps,
            settings.es_integrator,
            jnp.float32 if settings.precision == "mixed" else None,
        ),
        lower=layout.lower,
        upper=layout.upper,
        gene_group=layout.gene_group,
        group_slots=np.asarray(layout.group_slots),
        start=start,
    )
    return Identification(
        model=model,
        data=data[0],
        windows=windows,
        problem=problem,
        recordings=data if len(data) > 1 else (),
    )


def check_predictions(spec: Model, recordings: Sequence[Trajectory], settings: FitSettings) -> str:
    """'gaps removed 17 of 144 predictions (12 %) in frames 0:50', counted like the ES's cost
    (:func:`~activebonds.identify.costs.windows.count_predictions`), for ``spec`` (the bond variant
    fitted) on ``recordings``.

    Too few left is an InputError naming the gap-free windows that would do: none, or fewer
    predicted coordinates (predictions x dimension, the cost's residuals) than the model has
    free parameters (genes), which the data could then not determine."""
    from ..data.coverage import longest, present_windows, window_text
    from .costs.windows import count_predictions

    data = select_recordings(spec, recordings, settings)
    acting = neighbours_of(spec)
    counts = [count_predictions(d.mask, settings.es_horizon, acting) for d in data]
    kept, possible = sum(k for k, _ in counts), sum(p for _, p in counts)
    removed = possible - kept
    frames = range(recordings[0].n_frames)[slice(*settings.frames)]
    where = f"frames {frames.start}:{frames.stop}"
    if len(data) > 1:
        where += f" of {len(data)} recordings"
    pct = 100 * removed / possible if possible else 0.0
    share = f"{pct:.0f}" if pct >= 1 or pct == 0 else f"{pct:.1g}"
    line = f"gaps removed {removed} of {possible} predictions ({share} %) in {where}"
    genes, dim = spec.layout.n_genes, spec.dimension
    if kept > 0 and kept * dim >= genes:
        return line
    # a window of L frames with every marker present holds (L - 2) x P predictions at any
    # horizon (each frame from the third on is predicted once)
    names = data[0].markers
    need = 2 + max(1, -(-genes // (len(names) * dim)))
    full = recordings[0].select(list(names))
    windows = present_windows(full.mask)
    good = longest([w for w in windows if w[1] - w[0] >= need], 3)
    listed = ", ".join(window_text(w) for w in good)
    source = f" of {full.source}" if len(data) > 1 and full.source else ""
    if good:
        hint = f"windows{source} where {', '.join(names)} are all present that would do: {listed}"
    elif windows:
        hint = (
            f"no window{source} where {', '.join(names)} are all present holds {need} frames; "
            f"the longest: {window_text(longest(windows, 1)[0])}"
        )
    else:
        hint = f"{', '.join(names)} are never all present in one frame{source}"
    raise InputError(
        "--frames",
        f"{line}: the {kept} left give {kept * dim} coordinates for the model's {genes} free "
        f"parameters, too few (gap-free windows need {need} frames); {hint}",
    )
