"""The run directory (DESIGN.md §4): settings, input hashes, versions, history, checkpoints.

Layout of RUN/::

    run.json            settings, seed, input files and their sha256, software versions,
                        backend, the strategy, the history's columns and the cost's display
    model.toml          the input model file as given (for the record and for resume --force)
    data.npz            the recorded window that is fitted (selected markers and frames)
    history.csv         one row per generation (deterministic: no wall-clock fields)
    status.json         state, generation, best RMS, the run's wall time over every session
                        (``wall_seconds``: reading, compiling, search, post-fit stages; not
                        part of the result)
    best_model.toml     the best model so far, in the model-file format
    held_out.npz        the validation frames (``fit --validate``), optional
    data-2.npz, ...     further recordings fitted at once (``fit MODEL A B ...``)
    NAME.json           the record of each post-fit stage (identify/stages): refine.json,
                        baselines.json, uncertainty.json, validation.json, ...
    NAME.npz            a stage's record with its arrays, one atomic write (refine.npz: the
                        last shooting stage's frame states, for resume)
    NAME.csv            a stage's table for people (uncertainty.csv)
    checkpoints/gen-XXXXXXXXX.npz   loop state + history, written atomically; the two newest kept

This module (:class:`RunDir`) is the only one that writes or reads these files. A checkpoint stores the loop
state pytree by its paths (``state_generation``, ``state_failed_total``, then the strategy's
state: ``state_genes``, ``state_sigma``, ... for the paper's ES) and the history by column
(``history_best_cost``, ...), so any strategy's state round-trips. Nothing is ever unpickled:
checkpoints and data are read with ``allow_pickle=False``.
"""

from __future__ import annotations

import hashlib
import io
import json
import platform
import shutil
import sys
import threading
import time
import warnings
from importlib import metadata
from pathlib import Path

import jax
import numpy as np

from .. import atomic
from ..atomic import remove_leftovers, staged_directory
from ..errors import InputError

FORMAT = 2  # 2: the strategy, history columns and cost display are recorded in run.json
KEEP_CHECKPOINTS = 2
LOOP_KEYS = ("generation", "failed_total")  # the loop's own entries of a checkpointed state
# Held while this process creates a run directory or probes the folder it goes in: the
# command line's interrupt handler (cli/interrupts.py) waits for it, so an interrupt never
# leaves a half-made run or a probe file behind.
CREATING = threading.Lock()
SMALL_FILES = 256 * 1024  # run.json, status, best model, refinement, uncertainty: at most


class RunWriteError(OSError):
    """A file of a run directory could not be written (a full disk, a lost permission): the
    OSError of the write, with the file's path. The atomic writes leave the file they were to
    replace, and every older checkpoint, as they were."""

    def __init__(self, path: str | Path, error: OSError):
        super().__init__(error.errno, error.strerror or str(error), str(path))
        self.path, self.error = Path(path), error


def write_atomic(path: str | Path, write) -> Path:
    """:func:`activebonds.atomic.write_atomic`; a failure is a :class:`RunWriteError`."""
    try:
        return atomic.write_atomic(path, write)
    except OSError as err:
        raise RunWriteError(path, err) from err


def write_text_atomic(path: str | Path, text: str) -> Path:
    return write_atomic(path, lambda fh: fh.write(text.encode("utf-8")))


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
    out = atomic.output_path(out)
    if out.name in ("", ".", "/"):
        raise InputError(out, "give a new folder name for the run")
    return out


def check_new(out: str | Path, overwrite: bool) -> Path:
    """Refuse (:class:`InputError`) a run directory path that :func:`create` would refuse:
    an existing run without ``overwrite``, anything else that exists, a parent folder
    that does not exist or is a file."""
    out = _safe_run_path(out)
    if out.exists() and not overwrite:
        raise InputError(out, "already exists; choose another --out or pass --overwrite")
    if out.exists() and not (out.is_dir() and (out / "run.json").is_file()):
        raise InputError(out, "exists and is not a run directory; --overwrite only replaces runs")
    parent = out.absolute().parent
    for above in (parent, *parent.parents):
        if above.exists() and not above.is_dir():
            raise InputError(out, f"{above} is a file, not a folder")
    if not parent.is_dir():
        raise InputError(out, f"the parent folder {parent} does not exist")
    return out


def create(
    out: str | Path, files: dict[str, bytes], meta: dict, overwrite: bool, need_bytes: int = 0
) -> Path:
    """Create RUN/ atomically: everything is written into a hidden sibling first, then renamed.
    An existing run is never replaced unless ``overwrite``. With ``need_bytes`` (what the run
    will write besides ``files``), a folder with less free space is refused up front."""
    out = check_new(out, overwrite)
    need = need_bytes + sum(len(data) for data in files.values())
    check_space(out, out.absolute().parent, need, "the run writes")
    try:
        with CREATING, staged_directory(out) as tmp:
            (tmp / "checkpoints").mkdir()
            for name, data in files.items():
                (tmp / name).write_bytes(data)
            (tmp / "run.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    except OSError as err:
        raise RunWriteError(out, err) from err
    return out


def expected_bytes(state_bytes: int, columns: int, generations: int) -> int:
    """What a run writes besides the copies of its inputs, estimated from above: its
    checkpoints (two kept, a third being written: the loop state of ``state_bytes`` and the
    history, ``columns`` numbers per generation), history.csv and the small files."""
    history = generations * columns * 8
    return 3 * (state_bytes + history + 4096) + generations * columns * 25 + SMALL_FILES


def state_bytes(shapes: dict[str, tuple]) -> int:
    """Bytes of a checkpointed state of these shapes (:func:`state_shapes`), 8 per number."""
    return sum(8 * int(np.prod(shape)) for shape in shapes.values())


def check_space(run: Path, folder: Path, need: int, what: str) -> None:
    """One line (:class:`InputError`) if ``folder`` has less than ``need`` bytes free."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return  # unknown: the writes themselves will tell
    if free < need:
        raise InputError(
            run,
            f"not enough free space: {what} about {_megabytes(need)} and {folder} has "
            f"{_megabytes(free)} free; free some space or choose another folder",
        )


def _megabytes(n: int) -> str:
    return f"{n / 1e6:.2g} MB" if n < 1e7 else f"{n / 1e6:.0f} MB"


def used_bytes(run: Path) -> int:
    """Bytes the files of RUN/ (and RUN/checkpoints/) take now."""
    total = 0
    for folder in (run, run / "checkpoints"):
        for p in folder.glob("*"):
            if p.is_file():
                total += p.stat().st_size
    return total


def newest_checkpoint(run: Path) -> int | None:
    """The generation of the newest checkpoint file in RUN/checkpoints (checkpoints are
    renamed into place complete), or None."""
    gens = [
        g for p in (run / "checkpoints").glob("gen-*.npz") if (g := _generation_of(p)) is not None
    ]
    return max(gens) if gens else None


def read_meta(run: Path) -> dict:
    path = run / "run.json"
    if not path.is_file():
        raise InputError(run, "not a run directory (no run.json)")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(path, f"unreadable run.json ({err})") from None
    if isinstance(meta, dict) and meta.get("format") == 1:
        return _upgrade_meta(run, meta)
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError(path, f"unsupported run format (expected format {FORMAT})")
    return meta


def write_meta(run: Path, meta: dict) -> None:
    write_text_atomic(run / "run.json", json.dumps(meta, indent=2, sort_keys=True) + "\n")


# Format 1 (activebonds 0.2): the paper's ES only, no strategy, columns or display in run.json,
# variants numbered (trials_v1 ...), costs shown in mm for the best only. Read as format 2.
def _upgrade_meta(run: Path, meta: dict) -> dict:
    from .costs.windows import Display, make_windows
    from .search.es import PaperES
    from .search.evolve import history_columns

    try:
        horizon = meta["settings"].get("horizon", 1)  # an int in format 1; a curriculum later
        horizon = int(horizon[0] if isinstance(horizon, list) else horizon)
        window = read_window(run)
        n_terms = make_windows(window.positions, window.mask, window.dt, horizon).n_terms
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise InputError(run / "run.json", f"cannot read this format-1 run ({err})") from None
    display = Display(n_terms)
    columns = history_columns(PaperES, display)
    # format 1 had no refinement: its settings are the ES alone (FitSettings' default is lm)
    settings = {"refine": "none", **meta.get("settings", {})}
    meta = {**meta, "settings": settings, "format": FORMAT, "strategy": "es", "upgraded_from": 1}
    meta["history"] = {
        "columns": [c.name for c in columns],
        "integer": [c.name for c in columns if c.integer],
        "display": display.record(),
    }
    return meta


def upgrade_history(history: dict[str, np.ndarray], meta: dict) -> dict[str, np.ndarray]:
    """A format-1 history (from history.csv or a checkpoint) in the columns of ``meta``; any
    other history unchanged."""
    if "trials_v1" not in history:
        return history
    from .costs.windows import Display
    from .search.operators import VARIANTS

    out = dict(history)
    for i, v in enumerate(VARIANTS):
        for field in ("trials", "successes"):
            out[f"{field}_{v.name}"] = out.pop(f"{field}_v{i + 1}")
    display = Display(int(display_of(meta)["terms"]))
    for key in ("median", "worst"):
        out[f"{key}_rms_mm"] = display(out[f"{key}_cost"])
    return {c: out[c] for c in history_columns(meta)}


def write_status(run: Path, **fields) -> None:
    fields.setdefault("updated", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    write_text_atomic(run / "status.json", json.dumps(fields, indent=2, sort_keys=True) + "\n")


def read_status(run: Path) -> dict:
    try:
        return json.loads((run / "status.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def write_history(run: Path, history: dict[str, np.ndarray], integer: set[str]) -> None:
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
    write_text_atomic(run / "history.csv", "\n".join(lines) + "\n")


def history_columns(meta: dict) -> list[str]:
    return list(meta.get("history", {}).get("columns", []))


def read_history(run: Path, meta: dict | None = None) -> dict[str, np.ndarray]:
    """history.csv as columns by header name; the recorded columns empty for a missing
    file or a header with no row (a run that failed before its first generation)."""
    meta = read_meta(run) if meta is None else meta
    empty = {c: np.zeros(0) for c in history_columns(meta)}
    path = run / "history.csv"
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
    history = upgrade_history({name: data[:, i] for i, name in enumerate(header)}, meta)
    return {**empty, **history}


def flatten_state(state) -> dict[str, np.ndarray]:
    """The loop state (evolve.Run) as arrays by path: the loop's entries, then the
    strategy's (their paths without the 'strategy' prefix, joined by '.')."""
    out = {k: np.asarray(getattr(state, k)) for k in LOOP_KEYS}
    leaves = jax.tree_util.tree_flatten_with_path(state.strategy)[0]
    for path, leaf in leaves:
        name = _path_name(path)
        if name in out:
            raise ValueError(f"a strategy state may not have an entry named {name!r}")
        out[name] = np.asarray(leaf)
    return out


def unflatten_state(arrays: dict[str, np.ndarray], template):
    """Arrays by path back into the structure (and dtypes) of ``template``."""
    import jax.numpy as jnp

    leaves = jax.tree_util.tree_flatten_with_path(template.strategy)
    strategy = [jnp.asarray(arrays[_path_name(path)], leaf.dtype) for path, leaf in leaves[0]]
    loop = {k: jnp.asarray(arrays[k], getattr(template, k).dtype) for k in LOOP_KEYS}
    return template._replace(strategy=jax.tree_util.tree_unflatten(leaves[1], strategy), **loop)


def state_shapes(template) -> dict[str, tuple]:
    """The shape of every entry of a checkpointed state, from a template (eval_shape)."""
    flat = {k: getattr(template, k) for k in LOOP_KEYS}
    for path, leaf in jax.tree_util.tree_flatten_with_path(template.strategy)[0]:
        flat[_path_name(path)] = leaf
    return {k: tuple(v.shape) for k, v in flat.items()}


def _path_name(path) -> str:
    """A strategy-state leaf's checkpoint name: its pytree path joined by '.'."""
    return ".".join(_key_name(k) for k in path) or "strategy"


def _key_name(key) -> str:
    for attr in ("name", "key", "idx"):
        if hasattr(key, attr):
            return str(getattr(key, attr))
    return str(key)


def save_checkpoint(run: Path, state: dict[str, np.ndarray], history: dict[str, np.ndarray]):
    """A flattened loop state (:func:`flatten_state`) and the history up to
    ``state['generation']``, atomically; keep the two newest."""
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
    """The newest checkpoint that loads completely and holds every entry of ``shapes`` with
    that shape; torn, truncated or foreign files are skipped (and reported), leftovers of
    writes removed. Returns (state arrays by path, history by column, skipped files)."""
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
            state = {k[6:]: v for k, v in arrays.items() if k.startswith("state_")}
            history = {k[8:]: v for k, v in arrays.items() if k.startswith("history_")}
            for k in (*LOOP_KEYS, *shapes):
                if k not in state:
                    raise ValueError(f"no entry {k}")
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
        "history": {
            "columns": [c.name for c in columns],
            "integer": [c.name for c in columns if c.integer],
            "display": display.record(),
        },
        "versions": versions(),
        "backend": backend(),
        "command": python_command(command),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def display_of(meta: dict) -> dict:
    """How the run's costs are shown: {name, label, unit, terms}."""
    return dict(meta.get("history", {}).get("display", {}))


def save_best_model(run: Path, model) -> None:
    from ..model import save_model

    try:
        save_model(model, run / "best_model.toml")
    except OSError as err:
        raise RunWriteError(run / "best_model.toml", err) from err


def read_best_model(run: Path):
    """The best model so far, or None before the first checkpoint."""
    from ..model import load_model

    path = run / "best_model.toml"
    return load_model(path) if path.is_file() else None


def read_input_model(run: Path):
    """The model file the run was started from (its copy in the run)."""
    from ..model import loads_model

    path = run / "model.toml"
    if not path.is_file():
        raise InputError(run, "not a complete run directory (no model.toml)")
    return loads_model(path.read_text(encoding="utf-8"), str(path))


def read_window(run: Path):
    """The recorded window that is fitted (the first, if there are several)."""
    return read_windows(run)[0]


def read_windows(run: Path) -> list:
    """Every recorded window that is fitted: data.npz, then data-2.npz, data-3.npz, ..."""
    from ..data import read_trajectory

    if not (run / "data.npz").is_file():
        raise InputError(run, "not a complete run directory (no data.npz)")
    out = [read_trajectory(run / "data.npz")]
    while (run / data_name(len(out))).is_file():
        out.append(read_trajectory(run / data_name(len(out))))
    return out


HELD_OUT = "held_out.npz"  # the validation frames (settings.validate), beside data.npz


def read_held_out(run: Path):
    """The validation frames stored with the run, or None."""
    from ..data import read_trajectory

    path = run / HELD_OUT
    return read_trajectory(path) if path.is_file() else None


def data_name(i: int) -> str:
    """The run's copy of recording i (0-based): data.npz, data-2.npz, ..."""
    return "data.npz" if i == 0 else f"data-{i + 1}.npz"


# ----------------------------------------------------------------------------- stage records


def _record_path(run: Path, name: str) -> Path:
    return run / f"{name}.json"


def save_record(
    run: Path,
    name: str,
    record: dict,
    *,
    arrays: dict[str, np.ndarray] | None = None,
    files: dict[str, str | None] | None = None,
) -> None:
    """A post-fit stage's record: RUN/NAME.json (for people and the report), each write
    atomic. With ``arrays``, RUN/NAME.npz first: the record and the arrays in one atomic
    write (what :func:`load_record` reads back to resume). ``files``: further files of the
    stage by suffix (``{"csv": text}`` is RUN/NAME.csv); ``None`` removes one left by an
    earlier record."""
    text = json.dumps(record, indent=2, sort_keys=True, allow_nan=True) + "\n"
    if arrays is not None:
        packed = {"record": np.frombuffer(text.encode(), np.uint8)}
        packed.update({k: np.asarray(v) for k, v in arrays.items()})
        buf = io.BytesIO()
        np.savez(buf, **packed)
        write_atomic(run / f"{name}.npz", lambda fh: fh.write(buf.getvalue()))
    for suffix, content in (files or {}).items():
        path = run / f"{name}.{suffix}"
        if content is None:
            path.unlink(missing_ok=True)
        else:
            write_text_atomic(path, content)
    write_text_atomic(_record_path(run, name), text)


def load_record(run: Path, name: str) -> tuple[dict | None, dict[str, np.ndarray]]:
    """(record, arrays) of stage ``name``: from RUN/NAME.npz where the stage saved arrays
    (an unreadable one reads as no record: the stage then runs again), else RUN/NAME.json
    (no arrays); (None, {}) if there is none."""
    path = run / f"{name}.npz"
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                record = json.loads(bytes(z["record"]).decode())
                arrays = {k: z[k] for k in z.files if k != "record"}
        except (OSError, ValueError, KeyError, UnicodeDecodeError, json.JSONDecodeError):
            return None, {}
        return (record, arrays) if isinstance(record, dict) else (None, {})
    return read_record(run, name), {}


def read_record(run: Path, name: str) -> dict | None:
    """RUN/NAME.json of a stage, or None if there is none; one line (:class:`InputError`) if
    it is unreadable or not an object."""
    path = _record_path(run, name)
    if not path.is_file():
        return None
    what = f"{name} record"
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(path, f"unreadable {what} ({err})") from None
    if not isinstance(record, dict):
        raise InputError(path, f"unreadable {what} (not a JSON object)")
    return record


def python_command(command: list[str] | None = None) -> str:
    """``command`` (default ``sys.argv``) as run.json records it: the program's name, then
    its arguments."""
    argv = sys.argv if command is None else command
    return " ".join([Path(argv[0]).name, *argv[1:]])


def remove_partial(run: Path) -> None:
    """Remove what a :func:`create` of ``run`` that was killed left: its hidden staging
    folders beside ``run`` (never renamed into place)."""
    for partial in Path(run).parent.glob(f"{atomic.staged_prefix(run)}*"):
        shutil.rmtree(partial, ignore_errors=True)


def check_unchanged(run: Path, meta: dict) -> None:
    """Refuse (one line, naming what changed) a run whose model or data file, software
    versions or settings changed since it started."""
    from .settings import FitSettings

    for name, rec in meta.get("inputs", {}).items():
        path = Path(rec["path"])
        if not path.is_file():
            raise InputError(
                run, f"the {name} file {path} is gone; pass --force to use the copy in the run"
            )
        if sha256_file(path) != rec["sha256"]:
            raise InputError(
                run,
                f"the {name} file {path} changed since the run started; pass --force to continue anyway",
            )
    now = versions()
    for pkg, version in meta.get("versions", {}).items():
        if now.get(pkg) != version:
            raise InputError(
                run,
                f"{pkg} version changed ({version} -> {now.get(pkg)}); pass --force to continue anyway",
            )
    stored = read_status(run).get("job")
    if stored is not None and meta.get("upgraded_from") == 1:
        stored = {"optimizer": "es", **stored}  # format 1 had the paper's ES only
    current = FitSettings(**meta["settings"]).job()
    if stored is not None and stored != current:
        changed = sorted(k for k in set(stored) | set(current) if stored.get(k) != current.get(k))
        detail = ", ".join(f"{k} {stored.get(k)!r} -> {current.get(k)!r}" for k in changed)
        raise InputError(
            run / "run.json",
            f"settings changed since the run started ({detail}); pass --force to continue anyway",
        )


class RunDir:
    """One run directory: the only object that knows its files' names. It creates the run
    (with the provenance given), checkpoints it, checks its inputs are unchanged, and saves
    and loads the post-fit stages' records (``save_record(name, ...)``, ``record(name)``)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def __fspath__(self) -> str:
        return str(self.path)

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"

    def _repr_html_(self) -> str:
        """A small table for notebooks: status, generations, best error, baselines, verdict
        (read from the run's files; a folder that is not a run says so)."""
        from ..notebook import html_table

        if not self.is_run():
            return html_table(f"RunDir {str(self.path)!r}", [("status", "not a run directory")])
        from . import stages

        try:
            settings = self.meta().get("settings", {})
            records = {n: r for n in stages.names() if (r := self.record(n)) is not None}
            best = self.best_model() if self.best_model_path.is_file() else None
        except Exception as err:  # noqa: BLE001 - a notebook's table never raises
            return html_table(f"RunDir {str(self.path)!r}", [("unreadable", str(err))])
        rows = run_rows(self.status(), settings, records, best)
        return html_table(f"RunDir {str(self.path)!r}", rows)

    @classmethod
    def create(
        cls,
        out: str | Path,
        files: dict[str, bytes],
        meta: dict,
        overwrite: bool,
        need_bytes: int = 0,
        held_out=None,
    ) -> RunDir:
        """:func:`create`, with the validation frames ``held_out`` stored beside the data."""
        if held_out is not None:
            from ..data.writers import render_npz

            files = {**files, HELD_OUT: render_npz(held_out, Path(HELD_OUT))}
        return cls(create(out, files, meta, overwrite, need_bytes))

    @property
    def best_model_path(self) -> Path:
        return self.path / "best_model.toml"

    def is_run(self) -> bool:
        """Whether the folder holds a run (its run.json)."""
        return (self.path / "run.json").is_file()

    def settings(self, meta: dict | None = None):
        """The run's :class:`~activebonds.identify.settings.FitSettings` (one line,
        :class:`InputError`, if they are not valid)."""
        from .settings import FitSettings

        meta = self.meta() if meta is None else meta
        try:
            return FitSettings(**meta["settings"])
        except Exception as err:  # noqa: BLE001 - any bad settings as one line
            raise InputError(self.path / "run.json", f"settings are not valid ({err})") from None

    def window_error(self, message: str) -> InputError:
        """An error about the run's copy of the fitted window."""
        return InputError(self.path / data_name(0), message)

    def meta(self) -> dict:
        return read_meta(self.path)

    def check_unchanged(self, meta: dict) -> None:
        check_unchanged(self.path, meta)

    def write_meta(self, meta: dict) -> None:
        write_meta(self.path, meta)

    def status(self) -> dict:
        return read_status(self.path)

    def write_status(self, **fields) -> None:
        write_status(self.path, **fields)

    def update_status(self, **fields) -> None:
        """status.json with ``fields`` changed, the others kept."""
        write_status(self.path, **{**read_status(self.path), **fields})

    def history(self, meta: dict | None = None) -> dict[str, np.ndarray]:
        return read_history(self.path, meta)

    def write_history(self, history: dict[str, np.ndarray], integer: set[str]) -> None:
        write_history(self.path, history, integer)

    def save_checkpoint(self, state: dict, history: dict) -> None:
        save_checkpoint(self.path, state, history)

    def load_checkpoint(self, shapes: dict):
        return load_checkpoint(self.path, shapes)

    def used_bytes(self) -> int:
        return used_bytes(self.path)

    def save_best_model(self, model) -> None:
        save_best_model(self.path, model)

    def best_model(self):
        return read_best_model(self.path)

    def input_model(self):
        return read_input_model(self.path)

    def windows(self) -> list:
        return read_windows(self.path)

    def window(self):
        return read_window(self.path)

    def held_out(self):
        return read_held_out(self.path)

    def save_record(self, name: str, record: dict, **extra) -> None:
        save_record(self.path, name, record, **extra)

    def load_record(self, name: str):
        return load_record(self.path, name)

    def record(self, name: str) -> dict | None:
        return read_record(self.path, name)

    def file(self, name: str, suffix: str) -> Path:
        """RUN/NAME.SUFFIX of a stage (its CSV), for people to open."""
        return self.path / f"{name}.{suffix}"


def run_rows(status: dict, settings: dict, records: dict, model=None) -> list[tuple[str, object]]:
    """What a notebook shows of a run (status.json, run.json's settings, the post-fit stages'
    records, the best model or None): (name, value) rows."""
    from ..notebook import number
    from .judge.verdict import fit_verdict
    from .stages.baselines import ZERO

    g, total = status.get("generation"), status.get("generations", settings.get("generations"))
    rows: list[tuple[str, object]] = [
        ("status", status.get("status", "unknown")),
        ("generations", f"{g if g is not None else '?'} of {total}"),
        (
            "search",
            f"{settings.get('optimizer', '?')}, population {settings.get('population', '?')}",
        ),
        ("best RMS one-step error", number(status.get("best_rms_mm"), "mm")),
    ]
    zero = (records.get("baselines") or {}).get("zero_force_rms_mm")
    if zero is not None:
        rows.append((ZERO, number(zero, "mm")))
    if (found := fit_verdict(records)) is not None:
        rows.append((f"verdict, {found[0]}, one step", found[1].text()))
    rows.append(("best model", repr(model) if model is not None else "none yet"))
    return rows
