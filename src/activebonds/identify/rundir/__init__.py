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

:class:`RunDir` is the only door to these files: nothing else reads or writes them, and this
package's other names are :class:`RunWriteError` (a write that failed) and :data:`CREATING`
(the lock held while a run is created). Its parts are private modules behind it: ``_files``
(atomic writes, hashes), ``_create`` (a new run and the space it needs), ``_meta`` (run.json),
``_history`` (history.csv), ``_checkpoints`` (the loop state by its pytree paths) and
``_rows`` (what a notebook shows). Nothing is ever unpickled: checkpoints and data are read
with ``allow_pickle=False``.
"""

from __future__ import annotations

import io
import json
import shutil
import time
from pathlib import Path

import numpy as np

from ... import atomic
from ...errors import InputError
from . import _checkpoints, _create, _files, _history, _meta, _rows
from ._create import CREATING
from ._files import RunWriteError

__all__ = ["CREATING", "RunDir", "RunWriteError"]

_HELD_OUT = "held_out.npz"  # the validation frames (settings.validate), beside data.npz


class RunDir:
    """One run directory: the only object that knows its files' names. It creates the run
    (with the provenance given), checkpoints it, checks its inputs are unchanged, and saves
    and loads the post-fit stages' records (``save_record(name, ...)``, ``record(name)``).

    Its static members are what a run's maker needs before the folder exists: the file
    names (:meth:`data_name`), run.json's contents (:meth:`new_meta`), the checks of the
    folder and the space (:meth:`check_new`, :meth:`expected_bytes`, :meth:`state_bytes`),
    the checkpointed form of the loop state (:meth:`flatten_state`, :meth:`unflatten_state`,
    :meth:`state_shapes`, :meth:`upgrade_history`) and the inputs' hashes (:meth:`sha256`)."""

    FORMAT = _meta.FORMAT  # the format of run.json this version writes

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def __fspath__(self) -> str:
        return str(self.path)

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"

    def _repr_html_(self) -> str:
        """A small table for notebooks: status, generations, best error, baselines, verdict
        (read from the run's files; a folder that is not a run says so)."""
        from ...notebook import html_table

        if not self.is_run():
            return html_table(f"RunDir {str(self.path)!r}", [("status", "not a run directory")])
        from .. import stages

        try:
            settings = self.meta().get("settings", {})
            records = {n: r for n in stages.names() if (r := self.record(n)) is not None}
            best = self.best_model() if self.best_model_path.is_file() else None
        except Exception as err:  # noqa: BLE001 - a notebook's table never raises
            return html_table(f"RunDir {str(self.path)!r}", [("unreadable", str(err))])
        rows = _rows.run_rows(self.status(), settings, records, best)
        return html_table(f"RunDir {str(self.path)!r}", rows)

    # ------------------------------------------------------------------------- a new run

    check_new = staticmethod(_create.check_new)
    new_meta = staticmethod(_meta.new_meta)
    expected_bytes = staticmethod(_create.expected_bytes)
    state_bytes = staticmethod(_create.state_bytes)
    sha256 = staticmethod(_files.sha256_file)
    notebook_rows = staticmethod(_rows.run_rows)

    @staticmethod
    def data_name(i: int) -> str:
        """The run's copy of recording i (0-based): data.npz, data-2.npz, ..."""
        return "data.npz" if i == 0 else f"data-{i + 1}.npz"

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
        """Create RUN/ atomically: everything is written into a hidden sibling first, then
        renamed. An existing run is never replaced unless ``overwrite``. With ``need_bytes``
        (what the run will write besides ``files``), a folder with less free space is refused
        up front. The validation frames ``held_out`` are stored beside the data."""
        if held_out is not None:
            from ...data.writers import render_npz

            files = {**files, _HELD_OUT: render_npz(held_out, Path(_HELD_OUT))}
        return cls(_create.create(out, files, meta, overwrite, need_bytes))

    def remove_partial(self) -> None:
        """Remove what a :meth:`create` of this run that was killed left: its hidden staging
        folders beside it (never renamed into place)."""
        for partial in self.path.parent.glob(f"{atomic.staged_prefix(self.path)}*"):
            shutil.rmtree(partial, ignore_errors=True)

    def used_bytes(self) -> int:
        """Bytes the files of RUN/ (and RUN/checkpoints/) take now."""
        total = 0
        for folder in (self.path, self.path / "checkpoints"):
            for p in folder.glob("*"):
                if p.is_file():
                    total += p.stat().st_size
        return total

    def check_space(self, need: int, what: str) -> None:
        """One line (:class:`InputError`) if the run's folder has less than ``need`` bytes
        free."""
        _create.check_space(self.path, self.path, need, what)

    # ------------------------------------------------------------------------- run.json

    @property
    def best_model_path(self) -> Path:
        return self.path / "best_model.toml"

    def is_run(self) -> bool:
        """Whether the folder holds a run (its run.json)."""
        return (self.path / "run.json").is_file()

    def meta(self) -> dict:
        """run.json (a format-1 run's read as format 2); one line (:class:`InputError`) for a
        folder that is not a run or an unreadable or unknown run.json."""
        path = self.path / "run.json"
        if not path.is_file():
            raise InputError(self.path, "not a run directory (no run.json)")
        try:
            meta = json.loads(path.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise InputError(path, f"unreadable run.json ({err})") from None
        if isinstance(meta, dict) and meta.get("format") == 1:
            return _meta.upgrade(self.path, meta, self.window)
        if not isinstance(meta, dict) or meta.get("format") != _meta.FORMAT:
            raise InputError(path, f"unsupported run format (expected format {_meta.FORMAT})")
        return meta

    def write_meta(self, meta: dict) -> None:
        text = json.dumps(meta, indent=2, sort_keys=True) + "\n"
        _files.write_text_atomic(self.path / "run.json", text)

    def settings(self, meta: dict | None = None):
        """The run's :class:`~activebonds.identify.settings.FitSettings` (one line,
        :class:`InputError`, if they are not valid)."""
        from ..settings import FitSettings

        meta = self.meta() if meta is None else meta
        try:
            return FitSettings(**meta["settings"])
        except Exception as err:  # noqa: BLE001 - any bad settings as one line
            raise InputError(self.path / "run.json", f"settings are not valid ({err})") from None

    def check_unchanged(self, meta: dict) -> None:
        """Refuse (one line, naming what changed) a run whose model or data file, software
        versions or settings changed since it started."""
        from ..settings import FitSettings

        run = self.path
        for name, rec in meta.get("inputs", {}).items():
            path = Path(rec["path"])
            if not path.is_file():
                raise InputError(
                    run, f"the {name} file {path} is gone; pass --force to use the copy in the run"
                )
            if _files.sha256_file(path) != rec["sha256"]:
                raise InputError(
                    run,
                    f"the {name} file {path} changed since the run started; pass --force to continue anyway",
                )
        now = _meta.versions()
        for pkg, version in meta.get("versions", {}).items():
            if now.get(pkg) != version:
                raise InputError(
                    run,
                    f"{pkg} version changed ({version} -> {now.get(pkg)}); pass --force to continue anyway",
                )
        stored = self.status().get("job")
        if stored is not None and meta.get("upgraded_from") == 1:
            stored = {"optimizer": "es", **stored}  # format 1 had the paper's ES only
        current = FitSettings(**meta["settings"]).job()
        if stored is not None and stored != current:
            changed = sorted(
                k for k in set(stored) | set(current) if stored.get(k) != current.get(k)
            )
            detail = ", ".join(f"{k} {stored.get(k)!r} -> {current.get(k)!r}" for k in changed)
            raise InputError(
                run / "run.json",
                f"settings changed since the run started ({detail}); pass --force to continue anyway",
            )

    # ------------------------------------------------------------------------- status, history

    def status(self) -> dict:
        """status.json, or {} if it is missing or unreadable."""
        try:
            return json.loads((self.path / "status.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}

    def write_status(self, **fields) -> None:
        fields.setdefault("updated", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
        text = json.dumps(fields, indent=2, sort_keys=True) + "\n"
        _files.write_text_atomic(self.path / "status.json", text)

    def update_status(self, **fields) -> None:
        """status.json with ``fields`` changed, the others kept."""
        self.write_status(**{**self.status(), **fields})

    def history(self, meta: dict | None = None) -> dict[str, np.ndarray]:
        """history.csv as columns by header name; the recorded columns empty for a missing
        file or a header with no row (a run that failed before its first generation)."""
        meta = self.meta() if meta is None else meta
        return _history.read(self.path / "history.csv", meta)

    def write_history(self, history: dict[str, np.ndarray], integer: set[str]) -> None:
        """history.csv: the columns in the order of ``history`` (integers as such)."""
        _files.write_text_atomic(self.path / "history.csv", _history.render(history, integer))

    # ------------------------------------------------------------------------- checkpoints

    flatten_state = staticmethod(_checkpoints.flatten_state)
    unflatten_state = staticmethod(_checkpoints.unflatten_state)
    state_shapes = staticmethod(_checkpoints.state_shapes)
    upgrade_history = staticmethod(_history.upgrade)

    def save_checkpoint(self, state: dict, history: dict) -> None:
        """A flattened loop state (:meth:`flatten_state`) and the history up to
        ``state['generation']``, atomically; the two newest checkpoints are kept."""
        _checkpoints.save(self.path, state, history)

    def load_checkpoint(self, shapes: dict):
        """The newest checkpoint that loads completely and holds every entry of ``shapes``
        (:meth:`state_shapes`) with that shape; torn, truncated or foreign files are skipped
        (and reported), leftovers of writes removed. Returns (state arrays by path, history
        by column, skipped files)."""
        return _checkpoints.load(self.path, shapes)

    def newest_checkpoint(self) -> int | None:
        """The generation of the newest checkpoint file (checkpoints are renamed into place
        complete), or None."""
        return _checkpoints.newest(self.path)

    # ------------------------------------------------------------------------- models, data

    def save_best_model(self, model) -> None:
        from ...model import save_model

        try:
            save_model(model, self.best_model_path)
        except OSError as err:
            raise RunWriteError(self.best_model_path, err) from err

    def best_model(self):
        """The best model so far, or None before the first checkpoint."""
        from ...model import load_model

        path = self.best_model_path
        return load_model(path) if path.is_file() else None

    def input_model(self):
        """The model file the run was started from (its copy in the run)."""
        from ...model import loads_model

        path = self.path / "model.toml"
        if not path.is_file():
            raise InputError(self.path, "not a complete run directory (no model.toml)")
        return loads_model(path.read_text(encoding="utf-8"), str(path))

    def windows(self) -> list:
        """Every recorded window that is fitted: data.npz, then data-2.npz, data-3.npz, ..."""
        from ...data import read_trajectory

        if not (self.path / "data.npz").is_file():
            raise InputError(self.path, "not a complete run directory (no data.npz)")
        out = [read_trajectory(self.path / "data.npz")]
        while (self.path / self.data_name(len(out))).is_file():
            out.append(read_trajectory(self.path / self.data_name(len(out))))
        return out

    def window(self):
        """The recorded window that is fitted (the first, if there are several)."""
        return self.windows()[0]

    def window_error(self, message: str) -> InputError:
        """An error about the run's copy of the fitted window."""
        return InputError(self.path / self.data_name(0), message)

    def held_out(self):
        """The validation frames stored with the run, or None."""
        from ...data import read_trajectory

        path = self.path / _HELD_OUT
        return read_trajectory(path) if path.is_file() else None

    # ------------------------------------------------------------------------- stage records

    def save_record(
        self,
        name: str,
        record: dict,
        *,
        arrays: dict[str, np.ndarray] | None = None,
        files: dict[str, str | None] | None = None,
    ) -> None:
        """A post-fit stage's record: RUN/NAME.json (for people and the report), each write
        atomic. With ``arrays``, RUN/NAME.npz first: the record and the arrays in one atomic
        write (what :meth:`load_record` reads back to resume). ``files``: further files of the
        stage by suffix (``{"csv": text}`` is RUN/NAME.csv); ``None`` removes one left by an
        earlier record."""
        text = json.dumps(record, indent=2, sort_keys=True, allow_nan=True) + "\n"
        if arrays is not None:
            packed = {"record": np.frombuffer(text.encode(), np.uint8)}
            packed.update({k: np.asarray(v) for k, v in arrays.items()})
            buf = io.BytesIO()
            np.savez(buf, **packed)
            _files.write_atomic(self.file(name, "npz"), lambda fh: fh.write(buf.getvalue()))
        for suffix, content in (files or {}).items():
            if content is None:
                self.file(name, suffix).unlink(missing_ok=True)
            else:
                _files.write_text_atomic(self.file(name, suffix), content)
        _files.write_text_atomic(self.file(name, "json"), text)

    def load_record(self, name: str) -> tuple[dict | None, dict[str, np.ndarray]]:
        """(record, arrays) of stage ``name``: from RUN/NAME.npz where the stage saved arrays
        (an unreadable one reads as no record: the stage then runs again), else RUN/NAME.json
        (no arrays); (None, {}) if there is none."""
        path = self.file(name, "npz")
        if path.is_file():
            try:
                with np.load(path, allow_pickle=False) as z:
                    record = json.loads(bytes(z["record"]).decode())
                    arrays = {k: z[k] for k in z.files if k != "record"}
            except (OSError, ValueError, KeyError, UnicodeDecodeError, json.JSONDecodeError):
                return None, {}
            return (record, arrays) if isinstance(record, dict) else (None, {})
        return self.record(name), {}

    def record(self, name: str) -> dict | None:
        """RUN/NAME.json of a stage, or None if there is none; one line (:class:`InputError`)
        if it is unreadable or not an object."""
        path = self.file(name, "json")
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

    def file(self, name: str, suffix: str) -> Path:
        """RUN/NAME.SUFFIX of a stage (its CSV), for people to open."""
        return self.path / f"{name}.{suffix}"
