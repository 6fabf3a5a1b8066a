"""The package's sizes, from its source: no module over 600 lines, no function over 80 (a
command's typer option list aside: its body, after the docstring, under 60)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from test_import_graph import SRC, module_files

MODULE_LINES = 600
FUNCTION_LINES = 80
COMMAND_BODY_LINES = 60


def long_parts(path: Path) -> list[str]:
    """What in ``path`` is over the limits, one line each."""
    text = path.read_text()
    out = []
    if len(text.splitlines()) > MODULE_LINES:
        out.append(f"module of {len(text.splitlines())} lines")
    for node in ast.walk(ast.parse(text, str(path))):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        body = node.body
        if (
            len(body) > 1
            and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant)
        ):
            body = body[1:]  # the docstring
        whole = node.end_lineno - node.lineno + 1
        inside = node.end_lineno - body[0].lineno + 1
        command = any(
            isinstance(d, ast.Call | ast.Attribute) and "command" in ast.unparse(d)
            for d in node.decorator_list
        )
        if command and inside >= COMMAND_BODY_LINES:  # under 60
            out.append(f"command {node.name}: a body of {inside} lines")
        elif not command and whole > FUNCTION_LINES:
            out.append(f"function {node.name}: {whole} lines")
    return out


@pytest.mark.parametrize(
    "path", list(module_files().values()), ids=lambda p: p.relative_to(SRC).as_posix()
)
def test_no_module_or_function_of_the_package_is_too_long(path):
    found = long_parts(path)
    assert not found, f"{path.relative_to(SRC)}: {'; '.join(found)}"


def test_the_size_check_sees_a_long_function_and_a_long_command(tmp_path):
    long = "\n".join(f"    x{i} = {i}" for i in range(FUNCTION_LINES))
    body = "\n".join(f"    y{i} = {i}" for i in range(COMMAND_BODY_LINES))
    options = "\n".join(f"    o{i}: int = {i}," for i in range(40))
    path = tmp_path / "m.py"
    path.write_text(
        f"def f():\n{long}\n\n\n@app.command()\ndef cmd(\n{options}\n):\n"
        f'    """Doc."""\n{body}\n\n\n@app.command()\ndef fine(\n{options}\n):\n    return 1\n'
    )
    assert long_parts(path) == ["function f: 81 lines", "command cmd: a body of 60 lines"]
