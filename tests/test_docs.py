"""The documentation site's generated pages follow the code, and its figures agree with it.

``docs/gen_reference.py`` (the MkDocs hook) writes the model-file reference from the bond-kind
registry and the command-line reference from the commands: a kind registered here, known to no
package file, appears in the generated page with its key, default, bounds and check. The
hand-written pages name the same kinds and commands as the code, and state no test-suite size
(that figure drifts; ``.ci/run`` runs the whole suite).
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from activebonds import bonds
from activebonds.bonds.accumulate import accumulate
from helpers import ROOT

DOCS = ROOT / "docs"
_spec = importlib.util.spec_from_file_location("gen_reference", DOCS / "gen_reference.py")
gen = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gen)


def _pages() -> dict[str, str]:
    return {str(p.relative_to(DOCS)): p.read_text() for p in DOCS.rglob("*.md")}


def _drag(params, topology, x, v):
    idx = topology["particles"][:, 0]
    return accumulate(x.shape[0], [(idx, 1, -params["viscosity"][:, None] * v[idx])])


TOY = bonds.BondKind(
    name="toydrag",
    arity=1,
    parameters=(
        bonds.Parameter(
            "viscosity", "viscosity", None, bonds.spread(10, (0.0, 5.0)), check=bonds.POSITIVE
        ),
    ),
    forces=_drag,
    internal=False,
    what="toy drags",
)


def test_a_kind_registered_in_a_test_appears_in_the_model_file_reference():
    before = gen.model_file_reference()
    assert "toydrag" not in before
    with bonds.registered(TOY):
        page = gen.model_file_reference()
    assert "### `toydrag`" in page
    row = next(line for line in page.splitlines() if line.startswith("| `viscosity` |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    # key, form, default, bounds at 0, 1 and 10, check, scaling, taken by
    assert cells[2] == "required"
    assert cells[3] == "0 → [0, 5]; 1 → [0.1, 10]; 10 → [1, 100]"
    assert cells[4] == "must be > 0"
    assert f"{len(bonds.names()) + 1} bond kinds are registered" in page
    assert "external forces" in page.split("### `toydrag`")[1]
    assert gen.model_file_reference() == before  # unregistered again


def test_every_registered_kind_and_key_is_in_the_reference():
    page = gen.model_file_reference()
    for kind in bonds.kinds():
        section = page.split(f"### `{kind.name}`")[1].split("\n### ")[0]
        for p in (*kind.parameters, *kind.shared):
            assert f"| `{p.key}` |" in section, (kind.name, p.key)


def test_the_hook_replaces_the_markers():
    text = gen.on_page_markdown("a\n<!-- generated: model-file -->\nb")
    assert "<!-- generated" not in text and "### `contact`" in text
    cli = gen.on_page_markdown("<!-- generated: cli -->")
    for name, command in gen.commands().items():
        assert f"## `{name}`" in cli
        for param in command.params:
            if param.param_type_name == "option":
                assert f"`{param.opts[0]}`" in cli, (name, param.opts)


def test_the_pages_name_the_registered_kinds():
    """Every list of kinds in the hand-written pages ('unary | binary | ...', '`unary`,
    `binary`, ...') is the registry's, in its order."""
    names = list(bonds.names())
    pages = _pages()
    design = pages["DESIGN.md"]
    listed = re.search(r"`\[\[bond\]\]` tables with `kind` \(([^)]*)\)", design).group(1)
    assert re.findall(r"`(\w+)`", listed) == names
    model_file = pages["reference/model-file.md"]
    comment = re.search(r'kind = "binary"\s+# ([\w |]+)', model_file).group(1)
    assert [w.strip() for w in comment.split("|")] == names
    architecture = pages["ARCHITECTURE.md"]
    modules = re.search(r"bonds/\s+one module per bond kind \(([^)]*)\)", architecture).group(1)
    assert [w.strip() for w in modules.split(",")] == names
    for name in names:
        assert (ROOT / "src" / "activebonds" / "bonds" / f"{name}.py").is_file(), name
    # every kind a page's example or prose writes in a model file is a registered one
    for page, text in {**pages, "README.md": (ROOT / "README.md").read_text()}.items():
        for used in re.findall(r'\bkind = "(\w+)"', text):
            assert used in names, f"{page}: kind {used!r} is not registered"


def test_the_pages_name_existing_commands_and_state_no_suite_size():
    commands = set(gen.commands())
    for name, text in _pages().items():
        for used in re.findall(r"`activebonds (\w[\w-]*)", text):
            if used in ("COMMAND",):
                continue
            assert used in commands, f"docs/{name} names 'activebonds {used}'"
        assert not re.search(r"(default suite|suite of|suite is)\s+\d+", text), name
        size = re.search(r"\b\d+ (?:passed|tests (?:pass|run|in)|test functions)\b", text)
        assert size is None, f"docs/{name} states a test-suite size: {size.group(0)}"
        counted = re.search(r"(\d+) (?:bond kinds|commands)\b", text)
        assert counted is None, f"docs/{name} states a count the code owns: {counted.group(0)}"


@pytest.mark.parametrize(
    "page", ["tutorial.md", "howto/auto.md", "howto/sweeps.md", "howto/gap-filling.md"]
)
def test_the_pages_commands_use_existing_options(page):
    commands = gen.commands()
    text = (DOCS / page).read_text()
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s#\s.*$", "", line).strip()
            m = re.match(r"activebonds (\w+)(.*)", line)
            if not m:
                continue
            opts = {o for p in commands[m.group(1)].params for o in (*p.opts, *p.secondary_opts)}
            for used in re.findall(r"(?<!\S)(--[\w-]+)", m.group(2)):
                assert used in opts, (page, line, used)


def _python_files() -> dict[str, list]:
    """Every .py file of the repository by name (not the virtual environments)."""
    out: dict[str, list] = {}
    for folder in ("src", "tests", "benchmarks", "scripts", "docs"):
        for path in (ROOT / folder).rglob("*.py"):
            out.setdefault(path.name, []).append(path)
    return out


def test_the_pages_name_python_files_and_folders_that_exist():
    """A module or script a page names (``identify/solvers/lsq.py``, ``tests/test_x.py``, a bare
    ``springs.py`` in the architecture's tree) exists: under the repository, ``src/`` or
    ``src/activebonds/``, or, without a folder, somewhere in it; the package folders the
    architecture's tree names exist."""
    files = _python_files()
    bases = (ROOT, ROOT / "src", ROOT / "src" / "activebonds")
    pages = {**_pages(), "README.md": (ROOT / "README.md").read_text()}
    for name, text in pages.items():
        for path in re.findall(r"(?<![\w./-])((?:[\w-]+/)*[\w-]+\.py)\b", text):
            if "/" in path:
                found = any((b / path).is_file() for b in bases) or any(
                    str(f).endswith("/" + path) for f in files.get(Path(path).name, [])
                )
            else:
                found = path in files
            assert found, f"{name} names {path}, which does not exist"
    tree = re.search(r"## Layers\s+```\n(.*?)```", pages["ARCHITECTURE.md"], re.S).group(1)
    for folder in re.findall(r"^(\w+)/\s", tree, re.M):
        assert (ROOT / "src" / "activebonds" / folder).is_dir(), folder


def test_the_pages_name_python_objects_that_exist():
    """Every ``activebonds.a.b.c`` a page names is a module or an attribute of one."""
    import importlib

    pages = {**_pages(), "README.md": (ROOT / "README.md").read_text()}
    for page, text in pages.items():
        for dotted in set(re.findall(r"\b(activebonds(?:\.\w+)+)", text)):
            parts = dotted.split(".")
            for i in range(len(parts), 0, -1):
                try:
                    obj = importlib.import_module(".".join(parts[:i]))
                except ImportError:
                    continue
                break
            for name in parts[i:]:
                assert hasattr(obj, name), f"{page} names {dotted}, which does not exist"
                obj = getattr(obj, name)
