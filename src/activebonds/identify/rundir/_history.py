"""history.csv (private to :class:`~.RunDir`): one row per generation, the columns recorded
in run.json; a format-1 history is read in the columns of format 2."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ...errors import InputError
from ._meta import display_of, history_columns


def render(history: dict[str, np.ndarray], integer: set[str]) -> str:
    """history.csv: the columns in the order of ``history`` (integers as such)."""
    names = list(history)
    lines = [",".join(names)]
    for row in zip(*(history[c] for c in names), strict=True):
        lines.append(
            ",".join(
                str(int(v)) if name in integer else repr(float(v))
                for name, v in zip(names, row, strict=True)
            )
        )
    return "\n".join(lines) + "\n"


def read(path: Path, meta: dict) -> dict[str, np.ndarray]:
    """history.csv at ``path`` as columns by header name; the recorded columns empty for a
    missing file or a header with no row (a run that failed before its first generation)."""
    empty = {c: np.zeros(0) for c in history_columns(meta)}
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
    history = upgrade({name: data[:, i] for i, name in enumerate(header)}, meta)
    return {**empty, **history}


def upgrade(history: dict[str, np.ndarray], meta: dict) -> dict[str, np.ndarray]:
    """A format-1 history (from history.csv or a checkpoint) in the columns of ``meta``; any
    other history unchanged."""
    if "trials_v1" not in history:
        return history
    from ..costs.windows import Display
    from ..search.operators import VARIANTS

    out = dict(history)
    for i, v in enumerate(VARIANTS):
        for field in ("trials", "successes"):
            out[f"{field}_{v.name}"] = out.pop(f"{field}_v{i + 1}")
    display = Display(int(display_of(meta)["terms"]))
    for key in ("median", "worst"):
        out[f"{key}_rms_mm"] = display(out[f"{key}_cost"])
    return {c: out[c] for c in history_columns(meta)}
