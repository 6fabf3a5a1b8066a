"""From (model, trajectory, settings) to the ES's :class:`~activebonds.identify.es.Problem`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.trajectory import Trajectory
from ..errors import InputError
from ..model import Model, as_neural, as_standard
from .cost import Windows, make_cost, make_windows
from .es import Problem
from .lsq import least_squares
from .settings import FitSettings


@dataclass(frozen=True, eq=False)
class Identification:
    """The model to fit, the recorded window it is fitted to, and the ES problem."""

    model: Model
    data: Trajectory  # selected markers (model particle order), frame window
    windows: Windows
    problem: Problem


def variant(model: Model, bonds: str) -> Model:
    if bonds == "standard":
        return as_standard(model)
    if bonds == "neural":
        return as_neural(model)
    return model


def select_data(model: Model, traj: Trajectory, settings: FitSettings) -> Trajectory:
    """The trajectory cut to the model's markers (or ``settings.markers``) and frame window."""
    markers = settings.markers or model.markers
    if len(markers) != len(model.particle_names):
        raise InputError(
            "--markers",
            f"{len(markers)} markers given for a model of {len(model.particle_names)} particles "
            f"({', '.join(model.particle_names)}); give one marker per particle, in order",
        )
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


def identification(model: Model, traj: Trajectory, settings: FitSettings) -> Identification:
    model = variant(model, settings.bonds)
    if model.layout.n_genes == 0:
        raise InputError(model.name, "the model has no free parameter to identify")
    data = select_data(model, traj, settings)
    windows = make_windows(data.positions, data.mask, data.dt, settings.es_horizon, settings.smooth)
    if windows.n_terms == 0:
        raise InputError(traj.source, "no frame of the window can be predicted (gaps everywhere)")
    cost = make_cost(model, windows, settings.substeps, settings.integrator)
    layout = model.layout
    start = None
    if settings.init == "lsq":
        one_step = make_windows(data.positions, data.mask, data.dt, 1, settings.smooth)
        try:
            start = least_squares(model, one_step).genome[None, :]
        except InputError as err:
            raise InputError("--init lsq", err.message) from None
    problem = Problem(
        evaluate=cost,
        lower=layout.lower,
        upper=layout.upper,
        gene_group=layout.gene_group,
        group_slots=np.asarray(layout.group_slots),
        start=start,
    )
    return Identification(model=model, data=data, windows=windows, problem=problem)
