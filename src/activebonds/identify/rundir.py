"""The run directory (DESIGN.md §4): settings, input hashes, versions, history, checkpoints.

Layout of RUN/::

    run.json            settings, seed, input files and their sha256, software versions, backend
    model.toml          the input model file as given (for the record and for resume --force)
    data.npz            the recorded window that is fitted (selected markers and frames)
    history.csv         one row per generation (deterministic: no wall-clock fields)
    status.json         state, generation, best RMS, wall times (not part of the result)
    best_model.toml     the best model so far, in the model-file format
    checkpoints/gen-XXXXXXXXX.npz   ES state + history, written atomically; the two newest kept

Nothing is ever unpickled: checkpoints and data are read with ``allow_pickle=False``.
"""

from __future__ import annotations

import hashlib
import io
import json
import platform
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from ..atomic import remove_leftovers, staged_directory, write_atomic, write_text_atomic
from ..errors import InputError

FORMAT = 1
HISTORY_COLUMNS = (
    "generation",
    "best_cost",
    "median_cost",
    "worst_cost",
    "best_rms_mm",
    "failed",
    *(f"trials_v{i}" for i in range(1, 5)),
    *(f"successes_v{i}" for i in range(1, 5)),
)
STATE_KEYS = ("genes", "sigma", "cost", "local", "variant_probs", "generation", "failed_total")
KEEP_CHECKPOINTS = 2


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


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


def _safe_run_path(out: str | Path) -> Path:
    out = Path(out)
    if ".." in out.parts:
        raise InputError(out, "a run directory path may not contain '..'")
    if out.name in ("", ".", "/"):
        raise InputError(out, "give a new folder name for the run")
    return out


def create(out: str | Path, files: dict[str, bytes], meta: dict, overwrite: bool) -> Path:
    """Create RUN/ atomically: everything is written into a hidden sibling first, then renamed.
    An existing run is never replaced unless ``overwrite``."""
    out = _safe_run_path(out)
    if out.exists() and not overwrite:
        raise InputError(out, "already exists; choose another --out or pass --overwrite")
    if out.exists() and not (out.is_dir() and (out / "run.json").is_file()):
        raise InputError(out, "exists and is not a run directory; --overwrite only replaces runs")
    parent = out.absolute().parent
    if not parent.is_dir():
        raise InputError(out, f"the parent folder {parent} does not exist")
    with staged_directory(out) as tmp:
        (tmp / "checkpoints").mkdir()
        for name, data in files.items():
            (tmp / name).write_bytes(data)
        (tmp / "run.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return out


def read_meta(run: Path) -> dict:
    path = run / "run.json"
    if not path.is_file():
        raise InputError(run, "not a run directory (no run.json)")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(path, f"unreadable run.json ({err})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError(path, f"unsupported run format (expected format {FORMAT})")
    return meta


def write_status(run: Path, **fields) -> None:
    fields.setdefault("updated", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    write_text_atomic(run / "status.json", json.dumps(fields, indent=2, sort_keys=True) + "\n")


def read_status(run: Path) -> dict:
    try:
        return json.loads((run / "status.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def history_csv(history: dict[str, np.ndarray]) -> str:
    lines = [",".join(HISTORY_COLUMNS)]
    cols = [history[c] for c in HISTORY_COLUMNS]
    ints = {"generation", "failed"} | {
        c for c in HISTORY_COLUMNS if c.startswith(("trials", "succ"))
    }
    for row in zip(*cols, strict=True):
        lines.append(
            ",".join(
                str(int(v)) if name in ints else repr(float(v))
                for name, v in zip(HISTORY_COLUMNS, row, strict=True)
            )
        )
    return "\n".join(lines) + "\n"


def save_checkpoint(run: Path, state: dict[str, np.ndarray], history: dict[str, np.ndarray]):
    """ES state and history up to ``state['generation']``, atomically; keep the two newest."""
    folder = run / "checkpoints"
    gen = int(state["generation"])
    arrays = {f"state_{k}": np.asarray(v) for k, v in state.items()}
    arrays.update({f"history_{k}": np.asarray(v) for k, v in history.items()})
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    write_atomic(folder / f"gen-{gen:09d}.npz", lambda fh: fh.write(buf.getvalue()))
    # Keep this one and the newest older one; files of later generations (foreign or from a
    # run that went further before an overwrite) are left alone.
    older = [
        p
        for p in folder.glob("gen-*.npz")
        if _generation_of(p) is not None and _generation_of(p) < gen
    ]
    for old in sorted(older, key=_generation_of)[: -(KEEP_CHECKPOINTS - 1)]:
        old.unlink(missing_ok=True)


def _generation_of(path: Path) -> int | None:
    try:
        return int(path.stem.removeprefix("gen-"))
    except ValueError:
        return None


def load_checkpoint(run: Path, shapes: dict[str, tuple]):
    """The newest checkpoint that loads completely and has the expected shapes; torn,
    truncated or foreign files are skipped (and reported), leftovers of writes removed."""
    folder = run / "checkpoints"
    remove_leftovers(folder)
    remove_leftovers(run)
    for stray in run.glob(".*.tmp"):  # left by an interrupted save_model of an older version
        stray.unlink(missing_ok=True)
    skipped = []
    for path in sorted(folder.glob("gen-*.npz"), reverse=True):
        try:
            raw = path.read_bytes()  # np.load on a path leaks the handle of a corrupt file
            with np.load(io.BytesIO(raw), allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            state = {k: arrays[f"state_{k}"] for k in STATE_KEYS}
            history = {k: arrays[f"history_{k}"] for k in HISTORY_COLUMNS}
            for k, shape in shapes.items():
                if state[k].shape != shape:
                    raise ValueError(f"{k} has shape {state[k].shape}, expected {shape}")
            gen = int(state["generation"])
            if any(len(v) != gen for v in history.values()):
                raise ValueError("history length does not match the generation")
            return state, history, skipped
        except Exception as err:  # noqa: BLE001 - any unreadable checkpoint is skipped
            skipped.append(f"{path.name}: {type(err).__name__}")
    return None, None, skipped


def python_command() -> str:
    return " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])
