"""Read a run directory for reporting: settings, status, history, best model, fitted window.

Nothing here writes to the run; a run with no best model yet (it failed before its first
checkpoint) is reported with the model file's starting values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data import Trajectory, read_trajectory
from ..errors import InputError
from ..identify import stages
from ..identify.problem import variant
from ..identify.rundir import RunDir
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
    records: dict[str, dict] = field(default_factory=dict)  # post-fit stages' records by name

    @property
    def label(self) -> str:
        return self.path.name

    def __repr__(self) -> str:
        """One line: the run's folder, status, generations and best error, no arrays."""
        rms = self.status.get("best_rms_mm")
        best = f", best {rms:.4g} mm" if isinstance(rms, int | float) else ""
        return (
            f"RunRecord({str(self.path)!r}, {self.status.get('status', 'unknown')}, "
            f"{self.status.get('generation', '?')} of {self.settings.generations} "
            f"generations{best}, {self.model!r})"
        )

    def _repr_html_(self) -> str:
        """A small table for notebooks (as the run directory's)."""
        from ..notebook import html_table

        settings = self.settings.model_dump()
        rows = RunDir.notebook_rows(
            self.status, settings, self.records, self.model if self.has_best else None
        )
        return html_table(f"RunRecord {str(self.path)!r}", rows)


def load_run(run: str | Path) -> RunRecord:
    """Read RUN/ through :class:`~activebonds.identify.rundir.RunDir` (raises
    :class:`InputError`, one line, for a missing or invalid run)."""
    path = Path(run)
    if not path.is_dir():
        raise InputError(path, "no such run directory")
    run = RunDir(path)
    meta = run.meta()
    settings = run.settings(meta)
    window = run.window()
    model = run.best_model()
    has_best = model is not None
    if model is None:
        model = variant(run.input_model(), settings.bonds)
    if window.n_markers != model.topology.n_particles:
        raise run.window_error(
            f"{window.n_markers} markers for a model of {model.topology.n_particles} particles",
        )
    records = {name: rec for name in stages.names() if (rec := run.record(name)) is not None}
    return RunRecord(
        path=path,
        meta=meta,
        status=run.status(),
        settings=settings,
        history=run.history(meta),
        model=model,
        has_best=has_best,
        window=window,
        records=records,
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
