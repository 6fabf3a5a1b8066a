"""The package's import graph, from its source (every ``import`` and ``from ... import``,
relative or absolute, at module level or inside functions): no import cycle between modules,
no arrow from a layer of the architecture up to a higher one, and no bond kind named in the
code of any module outside ``bonds/`` (the kinds are found through the registry, and each
declares what the rest of the package needs to know of it)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from activebonds import bonds

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "activebonds"
ROOT = "__init__"  # the package's own __init__.py: its public face, imported lazily

# Bottom to top: a module may import modules of its own layer and of the layers below.
LAYERS = (
    (
        "errors",
        "atomic",
        "nanstats",
        "runtime",
        "document",
        "lazy",
        "notebook",
        "registry",
        "axes",
    ),  # foundation: no module of the package below them
    ("bonds",),  # the force laws, one module per bond kind, and their registry
    ("model",),  # model files, topology, parameters, genome layout
    ("physics", "data"),  # forces summed and integrated; recordings read and written
    ("identify", "simulation"),  # what is done with a model and recordings
    ("report", "export"),  # results shown, or written for other tools
    ("experiments",),  # the paper's studies, built on fits and reports
    ("sweep",),  # many fits from a manifest
    ("auto",),  # a recording to an evaluated model, in one call: a search over candidates
    ("cli", ROOT),  # the command line; the package's public face
)
# Arrows up that are known and to be removed: (importer, imported). Skipped by the layering
# test until they are gone; empty this set then.
KNOWN_TO_FIX: set[tuple[str, str]] = set()


def module_files() -> dict[str, Path]:
    """Every module of the package by its dotted name (a package by its ``__init__.py``)."""
    out = {}
    for path in sorted((SRC / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def imports_of(name: str, path: Path, modules: set[str]) -> set[str]:
    """The package's modules that module ``name`` imports: ``from X import n`` counts as
    importing ``X.n`` where that is a module, ``X`` otherwise."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            targets = [
                f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source
                for alias in node.names
            ]
        else:
            continue
        for target in targets:
            while target and target not in modules:  # import a.b.c of a name: its module
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph() -> dict[str, set[str]]:
    files = module_files()
    return {name: imports_of(name, path, set(files)) for name, path in files.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle [a, b, ..., a], or None (depth-first search)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def part(module: str) -> str:
    """The top-level part of the package a module belongs to ("identify", "errors", ...)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ROOT


def layer(module: str) -> int:
    return next(i for i, names in enumerate(LAYERS) if part(module) in names)


def upward_arrows(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    return {(a, b) for a, targets in graph.items() for b in targets if layer(b) > layer(a)}


# ----------------------------------------------------------------------------- the graph


def test_the_graph_is_read_from_every_kind_of_import():
    graph = import_graph()
    assert "activebonds.bonds.registry" in graph["activebonds.bonds"]  # from .registry import
    assert "activebonds.identify.rundir" in graph["activebonds.identify.driver"]  # from . import
    assert (
        "activebonds.bonds" in graph["activebonds.identify.search.population_cost"]
    )  # from .. import
    assert "activebonds.errors" in graph["activebonds.data.readers"]  # from ..errors import X
    assert "activebonds.runtime" in graph["activebonds.sweep.run"]  # inside a function
    assert "activebonds.identify.judge.metrics" in graph["activebonds.sweep.summary"]
    cycle = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycle(cycle) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_no_import_cycle_between_modules():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_every_part_of_the_package_has_a_layer():
    parts = {part(m) for m in module_files()}
    placed = [p for names in LAYERS for p in names]
    assert len(placed) == len(set(placed)), "a part in two layers"
    assert parts == set(placed), f"unplaced: {parts - set(placed)}, gone: {set(placed) - parts}"


def test_no_module_imports_a_module_of_a_higher_layer():
    found = upward_arrows(import_graph()) - KNOWN_TO_FIX
    listed = "\n".join(f"  {a} -> {b}" for a, b in sorted(found))
    assert not found, f"imports up the layers ({' < '.join(map('/'.join, LAYERS))}):\n{listed}"


def test_the_layering_check_sees_an_arrow_up():
    graph = {"activebonds.bonds.binary": {"activebonds.identify.costs.windows"}}
    assert upward_arrows(graph) == {
        ("activebonds.bonds.binary", "activebonds.identify.costs.windows")
    }
    assert (
        upward_arrows({"activebonds.identify.costs.windows": {"activebonds.bonds.binary"}}) == set()
    )


# ----------------------------------------------------------------------------- bond kinds


def kind_names_in_code(path: Path, kinds: set[str]) -> list[tuple[int, str]]:
    """(line, text) of every string constant of ``path`` that is a bond kind's name or holds
    one in quotes (``'kind = "binary"'``, a model file's text), other than docstrings
    (comments are not in the syntax tree)."""
    tree = ast.parse(path.read_text(), str(path))
    docstrings = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            if isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
                docstrings.add(id(body[0].value))
    return [
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in docstrings
        and (
            node.value.strip() in kinds
            or any(f"{q}{k}{q}" in node.value for k in kinds for q in "\"'")
        )
    ]


# Words of another program that happen to be a kind's name: (module, the exact string).
OTHER_VOCABULARY = {("export/mjcf.py", "contact")}  # MJCF's <contact> section (its pairs)


def outside_bonds() -> list[Path]:
    """Every module of the package but those of ``bonds/``."""
    return [
        path
        for name, path in module_files().items()
        if not name.startswith(f"{PACKAGE}.bonds.") and name != f"{PACKAGE}.bonds"
    ]


def test_every_module_outside_bonds_is_checked_for_kind_names():
    checked = {path.relative_to(SRC / PACKAGE).as_posix() for path in outside_bonds()}
    assert {"model/names.py", "model/variants.py", "export/mjcf.py"} <= checked
    assert {
        "experiments/springs.py",
        "identify/costs/windows.py",
        "cli/__init__.py",
        "__init__.py",
    } <= checked
    assert not any(p.startswith("bonds/") for p in checked)


@pytest.mark.parametrize(
    "path", outside_bonds(), ids=lambda p: p.relative_to(SRC / PACKAGE).as_posix()
)
def test_no_module_outside_bonds_names_a_bond_kind_in_its_code(path):
    assert {"unary", "binary", "ternary", "contact"} <= set(bonds.names())
    found = kind_names_in_code(path, set(bonds.names()))
    where = path.relative_to(SRC / PACKAGE).as_posix()
    found = [f for f in found if (where, f[1]) not in OTHER_VOCABULARY]
    assert not found, f"{where} names bond kinds (use the registry): {found}"


def test_the_kind_check_sees_a_name_in_code_and_not_in_a_docstring(tmp_path):
    path = tmp_path / "m.py"
    path.write_text('"""binary"""\n\n\ndef f(k):\n    """binary"""\n    return k == "binary"\n')
    assert kind_names_in_code(path, {"binary"}) == [(6, "binary")]


def test_the_kind_check_sees_a_kind_quoted_in_a_model_file_text(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("LINES = ['kind = \"binary\"', \"kind = 'unary'\", 'binary springs']\n")
    assert kind_names_in_code(path, {"binary", "unary"}) == [
        (1, 'kind = "binary"'),
        (1, "kind = 'unary'"),
    ]
