"""Read and write model files (TOML, DESIGN.md §4); every problem is one line naming the field."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import tomli_w
from pydantic import ValidationError

from .. import bonds
from ..atomic import write_text_atomic
from ..errors import InputError
from .forms import PARAMETER_EXPECTED, form_of
from .model import Model, build
from .schema import ModelSpec

_NOISE = {"float_type", "float_parsing", "list_type", "model_type", "dict_type", "is_instance_of"}
_EXPECTED = {
    "length": "expected a number or a list of numbers (one per bond of the kind)",
    "rate": "expected a number or a list of numbers (one per bond of the kind)",
    "gravity": "expected a list of numbers or a table { value = .., min = .., max = .., "
    "direction = [..] }",
    "position": "expected a list of numbers",
    "velocity": "expected a list of numbers",
    "mass": PARAMETER_EXPECTED,
    "frequency": PARAMETER_EXPECTED,
    "drive": "expected a table { frequency = .. } (Hz: a number or { value, min, max }; "
    "optionally coupling = { particle = .., gain = .. })",
    "coupling": "expected a table { particle = .., gain = .., offset = .., start_phase = .. }",
    "quadrature": "expected a table { particle = .., gain = .., offset = .. } (a second signal)",
}


def _expected(key: str, otherwise: str) -> str:
    """What a field takes, for a value none of its forms accepted."""
    for kind in bonds.kinds():
        for p in kind.parameters:
            if p.key == key:
                return form_of(p).expected
    return _EXPECTED.get(key, otherwise)


_LEADING_FIELD = re.compile(r"^([A-Za-z_][\w\[\]\.]*): (.*)$", re.S)


def _field_path(loc: tuple) -> str:
    """('bond', 2, 'stiffness', 'Param', 'value') -> 'bond[2].stiffness.value' (union tags out)."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif str(part)[:1].isupper() or str(part).startswith(("function-", "list[", "float")):
            continue
        else:
            out += ("." if out else "") + str(part)
    return out


_TABLE_HEADER = re.compile(r"^[ \t]*\[\[[ \t]*(bond|particle)[ \t]*\]\][ \t]*(?:#.*)?$", re.M)
_BLOCK = re.compile(r"^(bond|particle)\[(\d+)\]")


def _ordinal(n: int) -> str:
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def block_lines(text: str, data: dict) -> dict[str, list[int]]:
    """The line (from 1) of each ``[[bond]]`` and ``[[particle]]`` header of a model file's
    ``text``, per table name, where their count is the parsed ``data``'s (else not given)."""
    found: dict[str, list[int]] = {}
    for m in _TABLE_HEADER.finditer(text):
        found.setdefault(m.group(1), []).append(text.count("\n", 0, m.start()) + 1)
    return {
        k: v for k, v in found.items() if isinstance(data.get(k), list) and len(data[k]) == len(v)
    }


def _placed(problem: str, lines: dict[str, list[int]] | None) -> str:
    """``bond[6].stifness: ..`` led by where that block starts in the file, ``line 57 (the
    7th [[bond]]): bond[6].stifness: ..`` (people count the blocks from 1, the path from 0)."""
    m = _BLOCK.match(problem)
    if not lines or m is None:
        return problem
    table, i = m.group(1), int(m.group(2))
    at = lines.get(table, [])
    if i >= len(at):
        return problem
    return f"line {at[i]} (the {_ordinal(i + 1)} [[{table}]]): {problem}"


def _explain(
    err: ValidationError, source: str, lines: dict[str, list[int]] | None = None
) -> InputError:
    """Every problem on one line, each as 'field.path: what is wrong' (led by the line of its
    bond or particle block where ``lines``, :func:`block_lines`, has it). The errors of the
    alternatives a union did not take ('a number or a table') are dropped when a real
    problem was found at or below the same field."""
    found = []
    for e in err.errors():
        where = _field_path(tuple(e["loc"]))
        msg = e["msg"].removeprefix("Value error, ")
        m = _LEADING_FIELD.match(msg)
        if e["type"] == "value_error" and m:
            where = f"{where}.{m.group(1)}" if where else m.group(1)
            msg = m.group(2)
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        elif e["type"] == "missing":
            msg = "required key is missing"
        found.append((where, msg, e["type"] in _NOISE))
    real = [w for w, _, noise in found if not noise]
    problems: list[str] = []
    for where, msg, noise in found:
        if noise and any(
            r == where or r.startswith(where + ".") or r.startswith(where + "[") for r in real
        ):
            continue
        if noise:  # every alternative of a union failed: say what the field takes
            msg = _expected(where.rsplit(".", 1)[-1].split("[")[0], msg)
        text = _placed(f"{where}: {msg}", lines) if where else msg
        if text not in problems:
            problems.append(text)
    return InputError(source, "; ".join(problems[:4]))


def parse_model(data: dict, source: str = "<model>", text: str | None = None) -> Model:
    """The model of a parsed model file (``text``: the file's text, for the line of a bond or
    particle block a message names)."""
    lines = block_lines(text, data) if text is not None else None
    try:
        spec = ModelSpec.model_validate(data)
    except ValidationError as err:
        raise _explain(err, source, lines) from None
    try:
        return build(spec)
    except ValueError as err:
        raise InputError(source, _placed(str(err), lines)) from None


def loads_model(text: str, source: str = "<model>") -> Model:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise InputError(source, f"not valid TOML ({err})") from None
    return parse_model(data, source, text)


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
    data["particle"] = [{k: v for k, v in p.items() if v is not None} for p in data["particle"]]
    return tomli_w.dumps(data)


def save_model(model: Model | ModelSpec, path: str | Path) -> None:
    """Write atomically: a temporary file in the same folder, then rename."""
    path = Path(path)
    if not path.parent.exists():
        raise InputError(path, "the folder does not exist")
    write_text_atomic(path, dumps_model(model))
