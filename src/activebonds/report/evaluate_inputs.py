"""``activebonds evaluate``'s inputs to an :class:`~activebonds.report.evaluate.Evaluation`: the
integration a fit's model was fitted with (:func:`run_integration`), and the model file, the
recording and the options' texts loaded and checked (:func:`evaluate_from_options`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from .evaluate import Evaluation


def run_integration(model: Path, substeps: int | None, integrator: str | None):
    """(substeps, integrator): as given, else the run's where ``model`` is a fit's
    RUN/best_model.toml (so that evaluate scores it as the fit and its report did), else 1
    and euler."""
    if substeps is None or integrator is None:
        from ..identify.rundir import RunDir

        run = RunDir(model.parent)
        if model.name == "best_model.toml" and run.is_run():
            settings = run.settings()
            substeps = settings.substeps if substeps is None else substeps
            integrator = settings.integrator if integrator is None else integrator
    return (1 if substeps is None else substeps), (integrator or "euler")


def _names(text: str | None) -> list[str] | None:
    """'A, B,C' -> ['A', 'B', 'C']; None or '' -> None."""
    return [n.strip() for n in text.split(",") if n.strip()] if text else None


def evaluate_from_options(
    model: Path,
    traj: Path,
    *,
    frames: tuple[int, int | None],
    markers: Sequence[str] | None,
    substeps: int,
    integrator: str,
    horizon: int,
    gait: bool,
    feet: str | None,
    up: str | None,
    body: str | None,
    origin: int | None,
    burn_in: int | None = None,
) -> Evaluation:
    """:func:`~activebonds.report.evaluate.evaluate` of the model file ``model`` on the
    recording ``traj``, with the command's options: ``feet`` and ``body`` names separated by
    commas, ``up`` an axis or three numbers (``--up``); the model file's errors first, then
    the recording's, then the options'."""
    from ..data import read_trajectory
    from ..data.orientation import parse_up
    from ..model import load_model
    from .evaluate import evaluate

    loaded = load_model(model)
    return evaluate(
        loaded,
        read_trajectory(traj),
        markers=markers,
        frames=frames,
        substeps=substeps,
        integrator=integrator,
        horizon=horizon,
        gait=gait,
        feet=_names(feet),
        up=parse_up(up, loaded.dimension, numbers=True) if up else None,
        body=_names(body),
        origin=origin,
        burn_in=burn_in,
    )
