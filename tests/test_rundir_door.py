"""One door to a run directory: every module of the package outside ``identify/rundir/`` reaches
RUN/ through :class:`RunDir` (and the few public names listed in :data:`PUBLIC`), never through
a module-level function of the run directory's modules or one of its private modules. Read from
the source with ``ast`` (imports inside functions too), as tests/test_import_graph.py reads the
import graph; the scan is shown to find a violation in a made-up module."""

from __future__ import annotations

import ast
from pathlib import Path

import activebonds.identify.rundir as rundir

SRC = Path(__file__).resolve().parents[1] / "src"
DOOR = "activebonds.identify.rundir"
# The run directory's public names: the door, the error of a failed write, the creation lock.
PUBLIC = {"RunDir", "RunWriteError", "CREATING"}
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted((SRC / "activebonds").rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _inside(module: str) -> bool:
    return module == DOOR or module.startswith(DOOR + ".")


def violations(name: str, source: str, is_package: bool = False) -> list[str]:
    """What module ``name`` (of ``source``) takes from the run directory's modules besides
    :data:`PUBLIC`: names imported from them, their private modules imported, and attributes
    read off the run directory module where it is imported as a module."""
    package = name if is_package else name.rpartition(".")[0]
    found, aliases = [], set()
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                source_module = ".".join(base + ([node.module] if node.module else []))
            else:
                source_module = node.module or ""
            for alias in node.names:
                if f"{source_module}.{alias.name}" == DOOR:  # from ..identify import rundir
                    aliases.add(alias.asname or alias.name)
                elif _inside(source_module) and (source_module != DOOR or alias.name not in PUBLIC):
                    found.append(f"{name}: from {source_module} import {alias.name}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if _inside(alias.name) and alias.name != DOOR:
                    found.append(f"{name}: import {alias.name}")
                elif alias.name == DOOR:
                    aliases.add(alias.asname or alias.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _dotted(node.value) in aliases:
            if node.attr not in PUBLIC:
                found.append(f"{name}: {_dotted(node.value)}.{node.attr}")
    return found


def _dotted(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute) and (inner := _dotted(node.value)) is not None:
        return f"{inner}.{node.attr}"
    return None


def test_every_module_goes_through_the_door():
    found = []
    for name, path in _modules().items():
        if not _inside(name):
            found += violations(name, path.read_text(), path.name == "__init__.py")
    assert found == []


def test_the_scan_finds_a_made_up_violation():
    made_up = (
        "from ..identify.rundir import RunDir, read_meta\n"
        "from ..identify import rundir\n"
        "from activebonds.identify.rundir._files import write_atomic\n"
        "import activebonds.identify.rundir._checkpoints\n"
        "def f(run):\n"
        "    return rundir.sha256_file(run), rundir.RunDir(run), RunDir(run).meta()\n"
    )
    found = violations("activebonds.sweep.made_up", made_up)
    assert found == [
        "activebonds.sweep.made_up: from activebonds.identify.rundir import read_meta",
        "activebonds.sweep.made_up: from activebonds.identify.rundir._files import write_atomic",
        "activebonds.sweep.made_up: import activebonds.identify.rundir._checkpoints",
        "activebonds.sweep.made_up: rundir.sha256_file",
    ]
    clean = "from ..identify.rundir import CREATING, RunDir, RunWriteError\n"
    assert violations("activebonds.sweep.made_up", clean) == []


def test_the_door_shows_only_its_public_names():
    assert set(rundir.__all__) == PUBLIC
    tree = ast.parse((SRC / "activebonds/identify/rundir/__init__.py").read_text())
    defined = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            defined.add(node.name)
        elif isinstance(node, ast.Assign):
            defined |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.ImportFrom) and node.level == 1:
            defined |= {a.asname or a.name for a in node.names}
    assert {n for n in defined if not n.startswith("_")} <= PUBLIC
    parts = [p.stem for p in (SRC / "activebonds/identify/rundir").glob("*.py")]
    assert all(p.startswith("_") for p in parts)  # every part private behind the door


def test_the_run_directory_modules_are_small():
    for path in sorted((SRC / "activebonds/identify/rundir").glob("*.py")):
        text = path.read_text()
        assert len(text.splitlines()) <= MAX_MODULE_LINES, path.name
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                assert lines <= MAX_FUNCTION_LINES, f"{path.name}: {node.name}, {lines} lines"
