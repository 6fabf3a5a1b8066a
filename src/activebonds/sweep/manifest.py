"""A sweep manifest (TOML): many fits, checked and expanded before any of them runs.

Layout::

    [defaults]                  # optional: keys every [[fit]] starts from
    population = 50
    generations = 2000

    [[fit]]
    name = "walk"               # optional: fit-1, fit-2, ... (the entry's place, from 1)
    model = "triangle.toml"     # a model file, relative to the manifest
    data = "walk.csv"           # a recording, or a list of them fitted at once
    seed = [1, 2, 3]            # a list of values: one fit per value

Keys: ``name``, ``model``, ``data`` and every field of
:class:`~activebonds.identify.settings.FitSettings`, written as in a run's ``run.json``;
``frames`` may also be ``"START:STOP"`` and ``markers`` ``"A,B,C"``, as on the command line.
Defaults are those of ``activebonds fit`` (so ``refine = "lm"``).

**Expansion.** A list given for a key that takes one value (``seed = [1, 2, 3]``) makes one
fit per value; several such keys make the cartesian product, in the order the keys are
written (``[defaults]`` first). The keys that take a list themselves (``data``: several
recordings, ``markers``, ``horizon``: a curriculum, ``frames``: ``[start, stop]``) expand
only on a list of lists (``horizon = [[1], [1, 5]]``), and ``frames`` also on a list of
``"START:STOP"`` strings (or of both forms). Each fit's run directory is named after its entry and the values it
takes from expanded keys, ``walk-seed1``, ``walk-seed2``, ... (letters, digits and
``._+-`` kept, anything else made ``_``); two fits with one name are refused.

**Checks.** Every fit is checked before any runs: keys, files (each model loaded, each
recording read), setting values, the markers and frames against the data (as ``fit`` checks
them), and names. A problem is one :class:`~activebonds.errors.InputError` naming the manifest,
the entry (its place from 1 and its name) and the field.
"""

from __future__ import annotations

import difflib
import itertools
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError

from ..data import Trajectory, read_trajectory
from ..errors import InputError, first_problem
from ..identify.problem import identification
from ..identify.settings import FitSettings, parse_frames, parse_markers
from ..model import Model, load_model

INPUT_KEYS = ("model", "data")
SETTING_KEYS = tuple(FitSettings.model_fields)
LIST_KEYS = ("data", "markers", "horizon", "frames")  # a list is one value of these
FIT_DEFAULTS = {"refine": "lm"}  # where activebonds fit's defaults differ from FitSettings'
RESERVED = ("summary.csv", "summary.html")  # the sweep's own files beside the runs


@dataclass(frozen=True)
class Job:
    """One fit of a sweep, checked: its run directory's name, inputs and settings."""

    name: str  # the run directory's name under the sweep's folder
    entry: int  # the [[fit]] it comes from, counted from 1
    model: Path  # absolute
    data: tuple[Path, ...]  # absolute; several recordings are fitted at once
    settings: FitSettings

    @property
    def data_arg(self) -> Path | list[Path]:
        """``data`` as :func:`~activebonds.identify.fit` takes it."""
        return self.data[0] if len(self.data) == 1 else list(self.data)


class _Layout(BaseModel):
    """The manifest's top level: the tables it may hold."""

    model_config = ConfigDict(extra="forbid")

    defaults: dict[str, Any] = {}
    fit: list[dict[str, Any]]


def load_manifest(path: str | Path) -> list[Job]:
    """Every fit of the manifest at ``path``, expanded and checked (raises
    :class:`InputError`, one line, on the first problem)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, "no such manifest file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(path, f"cannot read the manifest ({err})") from None
    except tomllib.TOMLDecodeError as err:
        raise InputError(path, f"not valid TOML ({err})") from None
    try:
        layout = _Layout(**raw)
    except ValidationError as err:
        first = first_problem(err)
        message = {
            "extra_forbidden": "unknown table; a manifest holds [defaults] and [[fit]] entries",
            "missing": "no [[fit]] entry",
        }.get(first.kind, first.message)
        raise InputError(path, message, where=first.path) from None
    if not layout.fit:
        raise InputError(path, "no [[fit]] entry", where="fit")
    _check_keys(path, layout.defaults, "[defaults]", allowed=(*INPUT_KEYS, *SETTING_KEYS))
    inputs = _Inputs(path)
    jobs: list[Job] = []
    seen: dict[str, str] = {}
    for i, entry in enumerate(layout.fit, 1):
        label = _entry_label(path, i, entry)
        _check_keys(path, entry, label, allowed=("name", *INPUT_KEYS, *SETTING_KEYS))
        for job in _expand(path, i, label, {**FIT_DEFAULTS, **layout.defaults, **entry}, inputs):
            if job.name in RESERVED:
                raise InputError(
                    path, f"{job.name!r} is the sweep's summary; choose another name", where=label
                )
            if job.name in seen:
                raise InputError(
                    path,
                    f"the run name {job.name!r} is also that of {seen[job.name]}; give the "
                    "entries different names",
                    where=f"{label}, field name",
                )
            seen[job.name] = label
            jobs.append(job)
    return jobs


def _entry_label(path: Path, i: int, entry: dict) -> str:
    name = entry.get("name", f"fit-{i}")
    if not isinstance(name, str) or not sanitize(name):
        raise InputError(
            path, "expected a name made of letters, digits, ._+-", where=f"[[fit]] {i}, field name"
        )
    return f"[[fit]] {i} ({name})"


def _check_keys(path: Path, table: dict, label: str, allowed: tuple[str, ...]) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise InputError(
                path,
                f"unknown key; {hint}expected name, model, data or a fit setting "
                f"({', '.join(SETTING_KEYS)})",
                where=f"{label}, field {key}",
            )


def sanitize(name: str) -> str:
    """A run directory name: letters, digits and ``._+-`` kept, anything else ``_``, no
    leading dot."""
    return re.sub(r"[^A-Za-z0-9._+-]+", "_", name).lstrip(".")


# ----------------------------------------------------------------------------- expansion


def _choices(key: str, value: Any) -> list | None:
    """The values a key sweeps over, or None if ``value`` is one value (module docstring)."""
    if not isinstance(value, list) or not value:
        return None
    if key not in LIST_KEYS:
        return value
    if all(isinstance(v, list) for v in value):
        return value
    if key == "frames" and all(isinstance(v, str | list) for v in value):
        return value
    return None


def _label(key: str, value: Any) -> str:
    """How one expanded value shows in a run's name."""
    if key == "data":
        items = value if isinstance(value, list) else [value]
        return "+".join(Path(str(v)).stem for v in items)
    if key == "model":
        return Path(str(value)).stem
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list):
        return "-".join(_label(key, v) for v in value)
    return str(value).replace(":", "-").replace(",", "-")


def _expand(path: Path, i: int, label: str, merged: dict, inputs: _Inputs) -> list[Job]:
    base = sanitize(str(merged.pop("name", f"fit-{i}")))
    for key in INPUT_KEYS:
        if key not in merged:
            raise InputError(path, "required key is missing", where=f"{label}, field {key}")
    swept = {k: c for k, v in merged.items() if (c := _choices(k, v)) is not None}
    jobs = []
    for combo in itertools.product(*swept.values()):
        chosen = dict(zip(swept, combo, strict=True))
        name = sanitize(base + "".join(f"-{k}{_label(k, v)}" for k, v in chosen.items()))
        where = label if not swept else f"{label} (run {name})"
        values = {**merged, **chosen}
        model = inputs.model(values["model"], where)
        data = inputs.data(values["data"], where)
        settings = _settings(path, where, values)
        _check_markers(path, where, settings, data)
        try:
            identification(model.loaded, [d.loaded for d in data], settings)
        except InputError as err:
            raise _as_field(path, where, err, data) from None
        jobs.append(Job(name, i, model.path, tuple(d.path for d in data), settings))
    return jobs


def _settings(path: Path, where: str, values: dict) -> FitSettings:
    options = {k: v for k, v in values.items() if k in SETTING_KEYS}
    try:
        if isinstance(options.get("frames"), str):
            options["frames"] = parse_frames(options["frames"])
        if isinstance(options.get("markers"), str):
            options["markers"] = parse_markers(options["markers"])
    except ValueError as err:
        raise InputError(path, str(err), where=f"{where}, field frames") from None
    try:
        return FitSettings(**options)
    except ValidationError as err:
        first = first_problem(err)
        field = first.field or "settings"
        raise InputError(path, first.message, where=f"{where}, field {field}") from None


def _check_markers(path: Path, where: str, settings: FitSettings, data: list[_Loaded]):
    for d in data:
        missing = [m for m in settings.markers or () if m not in d.loaded.markers]
        if missing:
            raise InputError(
                path,
                f"{', '.join(map(repr, missing))} not in {d.path} (its markers: "
                f"{', '.join(d.loaded.markers)})",
                where=f"{where}, field markers",
            )


def _as_field(path: Path, where: str, err: InputError, data) -> InputError:
    """An error of the fit's own checks (named after a command-line option or a file) as
    one naming the manifest's field."""
    source = err.source or ""
    if source.startswith("--"):
        field = source[2:].split()[0].replace("-", "_")
        return InputError(path, err.message, where=f"{where}, field {field}")
    field = "data" if any(source == str(d.path) for d in data) else "model"
    return InputError(path, err.line(), where=f"{where}, field {field}")


# ----------------------------------------------------------------------------- input files


@dataclass(frozen=True)
class _Loaded:
    path: Path
    loaded: Model | Trajectory


class _Inputs:
    """The manifest's files, each loaded once (paths relative to the manifest)."""

    def __init__(self, manifest: Path):
        self.manifest = manifest
        self.folder = manifest.absolute().parent
        self.cache: dict[Path, _Loaded] = {}

    def _file(self, value: Any, where: str, field: str, load) -> _Loaded:
        if not isinstance(value, str) or not value:
            raise InputError(
                self.manifest, "expected a file path (a string)", where=f"{where}, field {field}"
            )
        path = (self.folder / value).resolve()
        if path not in self.cache:
            if not path.is_file():
                raise InputError(
                    self.manifest, f"no such file {path}", where=f"{where}, field {field}"
                )
            try:
                self.cache[path] = _Loaded(path, load(path))
            except InputError as err:
                raise InputError(
                    self.manifest, err.line(), where=f"{where}, field {field}"
                ) from None
        return self.cache[path]

    def model(self, value: Any, where: str) -> _Loaded:
        return self._file(value, where, "model", load_model)

    def data(self, value: Any, where: str) -> list[_Loaded]:
        items = value if isinstance(value, list) else [value]
        if not items:
            raise InputError(
                self.manifest,
                "expected a file path or a list of them",
                where=f"{where}, field data",
            )
        return [self._file(v, where, "data", read_trajectory) for v in items]
