"""Read a run directory for reporting: settings, status, history, best model, fitted window.

Nothing here writes to the run; a run with no best model yet (it failed before its first
checkpoint) is reported with the model file's starting values.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data import Trajectory, read_trajectory
from ..errors import InputError
from ..identify import rundir
from ..identify.problem import variant
from ..identify.settings import FitSettings
from ..model import Model, load_model, loads_model


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

    @property
    def label(self) -> str:
        return self.path.name


def load_run(run: str | Path) -> RunRecord:
    """Read RUN/ (raises :class:`InputError`, one line, for a missing or invalid run)."""
    run = Path(run)
    if not run.is_dir():
        raise InputError(run, "no such run directory")
    meta = rundir.read_meta(run)
    try:
        settings = FitSettings(**meta["settings"])
    except Exception as err:  # noqa: BLE001 - any bad settings as one line
        raise InputError(run / "run.json", f"settings are not valid ({err})") from None
    if not (run / "data.npz").is_file():
        raise InputError(run, "not a complete run directory (no data.npz)")
    window = read_trajectory(run / "data.npz")
    best = run / "best_model.toml"
    if best.is_file():
        model = load_model(best)
        has_best = True
    elif (run / "model.toml").is_file():
        text = (run / "model.toml").read_text(encoding="utf-8")
        model = variant(loads_model(text, str(run / "model.toml")), settings.bonds)
        has_best = False
    else:
        raise InputError(run, "not a complete run directory (no model.toml)")
    if window.n_markers != model.topology.n_particles:
        raise InputError(
            run / "data.npz",
            f"{window.n_markers} markers for a model of {model.topology.n_particles} particles",
        )
    history = read_history(run / "history.csv")
    return RunRecord(
        path=run,
        meta=meta,
        status=rundir.read_status(run),
        settings=settings,
        history=history,
        model=model,
        has_best=has_best,
        window=window,
    )


def read_history(path: Path) -> dict[str, np.ndarray]:
    """history.csv as columns by header name; empty columns for a missing file or a header
    with no row (a run that failed before its first generation)."""
    empty = {c: np.zeros(0) for c in rundir.HISTORY_COLUMNS}
    if not path.is_file():
        return empty
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(path, f"unreadable history ({err})") from None
    if len(lines) < 2:
        return empty
    header = [h.strip() for h in lines[0].split(",")]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    except ValueError as err:
        raise InputError(path, f"unreadable history ({err})") from None
    if data.shape[1] != len(header):
        raise InputError(path, f"{data.shape[1]} values per row for {len(header)} columns")
    out = {name: data[:, i] for i, name in enumerate(header)}
    return {**empty, **out}


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
    """Best, median and worst cost of each generation as RMS position errors (mm).

    The history stores summed squared errors (m^2) and the best one as RMS mm; their ratio
    gives the number of terms, so every cost column can be shown in mm."""
    best_cost = np.asarray(history.get("best_cost", []), dtype=np.float64)
    best_mm = np.asarray(history.get("best_rms_mm", []), dtype=np.float64)
    ok = np.isfinite(best_cost) & (best_cost > 0) & np.isfinite(best_mm)
    scale = float(np.median(best_mm[ok] / np.sqrt(best_cost[ok]))) if ok.any() else np.nan
    out = {"best": np.where(np.isfinite(best_mm), best_mm, np.nan)}
    for key in ("median", "worst"):
        cost = np.asarray(history.get(f"{key}_cost", []), dtype=np.float64)
        with np.errstate(invalid="ignore"):
            rms = np.sqrt(cost) * scale
        out[key] = np.where(np.isfinite(rms), rms, np.nan)  # inf: failed evaluations
    return out
