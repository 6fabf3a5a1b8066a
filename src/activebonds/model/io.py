"""Read and write model files (TOML, DESIGN.md §4); every problem is one line naming the field."""

from __future__ import annotations

import os
import tempfile
import tomllib
from pathlib import Path

import tomli_w
from pydantic import ValidationError

from ..errors import InputError
from .model import Model, build
from .schema import ModelSpec


def _field_path(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("float", "Param", "VectorParam", "list[float]", "function-after[_check_bounds(), Param]"):
            continue
        elif str(part).startswith(("function-", "list[", "float", "Param", "VectorParam", "Weights")):
            continue
        else:
            out += ("." if out else "") + str(part)
    return out


def _explain(err: ValidationError, source: str) -> InputError:
    problems = []
    seen = set()
    for e in err.errors():
        where = _field_path(tuple(e["loc"]))
        msg = e["msg"].removeprefix("Value error, ")
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        elif e["type"] == "missing":
            msg = "required key is missing"
        if (where, msg) in seen:
            continue
        seen.add((where, msg))
        problems.append(f"{where}: {msg}" if where else msg)
    # Union types report one error per alternative; keep the first few, distinct.
    return InputError(source, "; ".join(problems[:4]))


def parse_model(data: dict, source: str = "<model>") -> Model:
    try:
        spec = ModelSpec.model_validate(data)
    except ValidationError as err:
        raise _explain(err, source) from None
    return build(spec)


def loads_model(text: str, source: str = "<model>") -> Model:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise InputError(source, f"not valid TOML ({err})") from None
    return parse_model(data, source)


def load_model(path: str | Path) -> Model:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError(path, "no such model file") from None
    except OSError as err:
        raise InputError(path, f"cannot read ({err.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(path, "not a UTF-8 text file (expected a TOML model file)") from None
    return loads_model(text, str(path))


def dumps_model(model: Model | ModelSpec) -> str:
    spec = model.spec if isinstance(model, Model) else model
    data = spec.model_dump(exclude_none=True, exclude_defaults=False)
    data["particle"] = [
        {k: v for k, v in p.items() if v is not None} for p in data["particle"]
    ]
    return tomli_w.dumps(data)


def save_model(model: Model | ModelSpec, path: str | Path) -> None:
    """Write atomically: a temporary file in the same folder, then rename."""
    path = Path(path)
    text = dumps_model(model)
    if not path.parent.exists():
        raise InputError(path, "the folder does not exist")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
