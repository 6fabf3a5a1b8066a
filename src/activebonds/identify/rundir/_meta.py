"""run.json (private to :class:`~.RunDir`): what decides a run and how its history is read,
the software it ran on, and the migration of format-1 runs."""

from __future__ import annotations

import platform
import sys
import time
from importlib import metadata
from pathlib import Path

from ...errors import InputError

FORMAT = 2  # 2: the strategy, history columns and cost display are recorded in run.json


def versions() -> dict:
    out = {"python": platform.python_version()}
    for pkg in ("activebonds", "jax", "jaxlib", "numpy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "unknown"
    return out


def backend() -> dict:
    import jax

    dev = jax.devices()[0]
    return {
        "backend": jax.default_backend(),
        "device": str(dev.device_kind),
        "x64": bool(jax.config.jax_enable_x64),
        "platform": f"{platform.system()} {platform.machine()}",
    }


def python_command(command: list[str] | None = None) -> str:
    """``command`` (default ``sys.argv``) as run.json records it: the program's name, then
    its arguments."""
    argv = sys.argv if command is None else command
    return " ".join([Path(argv[0]).name, *argv[1:]])


def _history_record(columns, display) -> dict:
    """run.json's ``history``: the columns in order, which are integers, the cost's display."""
    return {
        "columns": [c.name for c in columns],
        "integer": [c.name for c in columns if c.integer],
        "display": display.record(),
    }


def new_meta(
    settings, inputs: dict, strategy: str, columns, display, command: list[str] | None = None
) -> dict:
    """run.json of a new run: what decides it, and how its history is to be read.
    ``command``: the command line that made it (default: this process's, ``sys.argv``)."""
    return {
        "format": FORMAT,
        "settings": settings.model_dump(mode="json"),
        "seed": settings.seed,
        "inputs": inputs,
        "strategy": strategy,
        "history": _history_record(columns, display),
        "versions": versions(),
        "backend": backend(),
        "command": python_command(command),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def display_of(meta: dict) -> dict:
    """How the run's costs are shown: {name, label, unit, terms}."""
    return dict(meta.get("history", {}).get("display", {}))


def history_columns(meta: dict) -> list[str]:
    return list(meta.get("history", {}).get("columns", []))


# Format 1 (activebonds 0.2): the paper's ES only, no strategy, columns or display in run.json,
# variants numbered (trials_v1 ...), costs shown in mm for the best only. Read as format 2.
def upgrade(run: Path, meta: dict, window) -> dict:
    """A format-1 ``meta`` as format 2; ``window()`` reads the run's fitted window."""
    from ..costs.windows import Display, make_windows
    from ..search.es import PaperES
    from ..search.evolve import history_columns as es_columns

    try:
        horizon = meta["settings"].get("horizon", 1)  # an int in format 1; a curriculum later
        horizon = int(horizon[0] if isinstance(horizon, list) else horizon)
        fitted = window()
        n_terms = make_windows(fitted.positions, fitted.mask, fitted.dt, horizon).n_terms
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise InputError(run / "run.json", f"cannot read this format-1 run ({err})") from None
    display = Display(n_terms)
    columns = es_columns(PaperES, display)
    # format 1 had no refinement: its settings are the ES alone (FitSettings' default is lm)
    settings = {"refine": "none", **meta.get("settings", {})}
    meta = {**meta, "settings": settings, "format": FORMAT, "strategy": "es", "upgraded_from": 1}
    meta["history"] = _history_record(columns, display)
    return meta
