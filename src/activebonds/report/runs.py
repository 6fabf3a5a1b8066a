"""Read a run directory for reporting: settings, status, history, best model, fitted window.

Nothing here writes to the run; a run with no best model yet (it failed before its first
checkpoint) is reported with the model file's starting values.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data import Trajectory, read_trajectory
from ..errors import InputError
from ..identify import rundir
from ..identify.problem import variant
from ..identify.settings import FitSettings
from ..model import Model


@dataclass(frozen=True, eq=False)
class RunRecord:
    """Everything the report reads from one run directory."""

    path: Path
    meta: dict  # run.json
    status: dict  # status.json ({} if missing)
    settings: FitSettings
    history: dict[str, np.ndarray]  # history.csv columns (empty arrays if none)
    model: Model  # best model (or the starting model if there is none)
    has_best: bool  # best_model.toml was found
    window: Trajectory  # the fitted window (data.npz)
    validation: dict | None = None  # validation.json (fit --validate), if any
    refinement: dict | None = None  # refine.json (fit --refine lm), if any
    uncertainty: dict | None = None  # uncertainty.json, if any

    @property
    def label(self) -> str:
        return self.path.name


def load_run(run: str | Path) -> RunRecord:
    """Read RUN/ through :mod:`activebonds.identify.rundir` (raises :class:`InputError`, one
    line, for a missing or invalid run)."""
    run = Path(run)
    if not run.is_dir():
        raise InputError(run, "no such run directory")
    meta = rundir.read_meta(run)
    try:
        settings = FitSettings(**meta["settings"])
    except Exception as err:  # noqa: BLE001 - any bad settings as one line
        raise InputError(run / "run.json", f"settings are not valid ({err})") from None
    window = rundir.read_window(run)
    model = rundir.read_best_model(run)
    has_best = model is not None
    if model is None:
        model = variant(rundir.read_input_model(run), settings.bonds)
    if window.n_markers != model.topology.n_particles:
        raise InputError(
            run / "data.npz",
            f"{window.n_markers} markers for a model of {model.topology.n_particles} particles",
        )
    return RunRecord(
        path=run,
        meta=meta,
        status=rundir.read_status(run),
        settings=settings,
        history=rundir.read_history(run, meta),
        model=model,
        has_best=has_best,
        window=window,
        validation=rundir.read_validation(run),
        refinement=rundir.read_refinement_record(run),
        uncertainty=rundir.read_uncertainty(run),
    )


def original_window(record: RunRecord, n_frames: int) -> Trajectory | None:
    """``n_frames`` frames of the original recording from the fitted window's first frame
    (same markers), or None if the recording is gone or no longer matches the fitted window."""
    source = record.meta.get("inputs", {}).get("data", {}).get("path")
    if not source or not Path(source).is_file():
        return None
    try:
        full = read_trajectory(source).select(list(record.window.markers))
    except InputError:
        return None
    start = record.settings.frames[0]
    stop = min(start + max(int(n_frames), record.window.n_frames), full.n_frames)
    if stop - start < record.window.n_frames:
        return None
    longer = full.window(start, stop)
    head = longer.positions[: record.window.n_frames]
    same_mask = np.array_equal(longer.mask[: record.window.n_frames], record.window.mask)
    if not same_mask or not np.allclose(
        np.nan_to_num(head), np.nan_to_num(record.window.positions), rtol=0, atol=1e-9
    ):
        return None
    return longer


def history_rms_mm(history: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Best, median and worst cost of each generation as the run stored them for people
    (RMS position errors, mm); NaN where a cost was not finite (failed evaluations)."""
    out = {}
    for key in ("best", "median", "worst"):
        values = np.asarray(history.get(f"{key}_rms_mm", []), dtype=np.float64)
        out[key] = np.where(np.isfinite(values), values, np.nan)
    return out
